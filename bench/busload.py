"""odocan.dbc's bus load and worst slack at the usual bitrates, and the analysis' own speed.

For each bitrate the utilization (all messages; cyclic ones only) and the least slack D - R by the
revised analysis of Davis et al. (2007), under two assumptions for the four event messages (no
GenMsgCycleTime in the DBC): the default (sporadic at the DBC's shortest cycle, 10 ms) and
``--sporadic-ms 100``. Sender ticks are the defaults (shortest cycle per sender), queue jitter 0.
Then the time one analysis of the DBC takes.

Then the closing figures of issue #16: a bit-timed lockstep run at 500 kbit/s (10 simulated
minutes by default, ``--minutes``), per message the measured worst latency (queued to end of
frame, the wire's own records) against the analysis' R, and the rig's speed (simulated seconds
per CPU second, ``time.process_time``) with the bit-timed bus on and off, on the same scenario and
seed. Prints figures; asserts nothing.
Run: ``.venv/bin/python bench/busload.py [--minutes 10] [--speed-seconds 60]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from odocan.host.judge import busstats  # noqa: E402
from odocan.host.judge.schedulability import NS_PER_MS, analyse_bus, messages_from_dbc  # noqa: E402
from odocan.sim import robot  # noqa: E402
from odocan.sim.contract import database  # noqa: E402
from odocan.sim.rig import LockstepRig, RigConfig  # noqa: E402

BITRATES = (125_000, 250_000, 500_000, 1_000_000)


def _row(bitrate: int, sporadic_ms: str | None) -> str:
    load = analyse_bus(messages_from_dbc(database(), sporadic_ms=sporadic_ms), bitrate)
    name, slack_ns = load.worst_slack()
    cyclic = load.as_dict()["utilization_cyclic"]
    slack = "unbounded" if slack_ns is None else f"{slack_ns / NS_PER_MS:+8.3f} ms"
    verdict = "OK  " if load.schedulable else "MISS"
    return (
        f"{bitrate:>9}  {load.utilization:6.1%}  {cyclic:6.1%}  {verdict}  "
        f"least slack {slack} ({name})"
    )


def _rig(bitrate: int | None, duration_s: float, channel: str) -> tuple[LockstepRig, float]:
    """Run the random scenario (seed 0) for ``duration_s``; the rig (closed) and the CPU s."""
    config = RigConfig(robot=robot.load("pmir"), integrator="exact", scenario="random", seed=0,
                       duration_s=duration_s, bitrate=bitrate, channel=channel)
    rig = LockstepRig(config)
    start = time.process_time()
    try:
        rig.run(duration_s)
        cpu_s = time.process_time() - start
    finally:
        rig.close()
    return rig, cpu_s


def measured_vs_computed(minutes: float) -> None:
    """The long bit-timed run at 500 kbit/s: measured max and p99 against R, per message."""
    duration_s = 60 * minutes
    config = RigConfig(robot=robot.load("pmir"), integrator="exact", scenario="random", seed=0,
                       duration_s=duration_s, bitrate=500_000, channel="bench-busload-long")
    rig = LockstepRig(config)
    wire = rig.host_bus.timing
    assert wire is not None
    start = time.process_time()
    try:
        rig.run(duration_s)
        cpu_s = time.process_time() - start
        still = busstats.pending_by_id(wire)
    finally:
        rig.close()
    stats = busstats.from_wire(wire, database(), still_queued=still)
    print(f"bit-timed run, 500 kbit/s, random scenario seed 0, {duration_s:g} s simulated "
          f"in {cpu_s:.1f} CPU s: {stats.frames} frames, measured load {stats.load:.2%}")
    print("  message          frames   max us   p99 us   R (analysis) us   max/R")
    for m in stats.messages:
        ratio = "-" if not m.bound_us or m.max_us is None else f"{m.max_us / m.bound_us:5.1%}"
        print(f"  {m.name:<15} {m.frames:>7} {m.max_us or 0:>8.0f} {m.p99_us or 0:>8.0f} "
              f"{m.bound_us or 0:>17.0f}   {ratio}")
    print(f"  every maximum within R: {stats.within_bounds}; starved: {stats.as_dict()['starved']}")


def rig_speed(seconds: float) -> None:
    """Simulated seconds per CPU second, the bus instant and bit-timed at each bitrate."""
    print(f"rig speed, random scenario seed 0, {seconds:g} s simulated each (CPU time):")
    for bitrate in (None, 125_000, 500_000, 1_000_000):
        _, cpu_s = _rig(bitrate, seconds, f"bench-busload-{bitrate}")
        label = "instant bus" if bitrate is None else f"bit-timed {bitrate // 1000} kbit/s"
        print(f"  {label:<22} {seconds / cpu_s:6.0f}x real time ({cpu_s:.2f} CPU s)")


def main() -> None:
    """Print the table for both sporadic assumptions, the analysis time, the closing figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="the long run (default 10)")
    parser.add_argument("--speed-seconds", type=float, default=60.0,
                        help="simulated seconds per speed run (default 60)")
    args = parser.parse_args()
    for label, sporadic_ms in (("event messages at 10 ms (default)", None), ("at 100 ms", "100")):
        print(f"odocan.dbc, {label}:")
        print("  bit/s    util.   cyclic  verdict")
        for bitrate in BITRATES:
            print(_row(bitrate, sporadic_ms))
        print()
    messages = messages_from_dbc(database())
    runs = 200
    start = time.perf_counter()
    for _ in range(runs):
        analyse_bus(messages, 125_000)
    per_run_ms = (time.perf_counter() - start) / runs * 1e3
    print(f"one analysis of odocan.dbc (12 messages) at 125 kbit/s: {per_run_ms:.2f} ms")
    print()
    measured_vs_computed(args.minutes)
    print()
    rig_speed(args.speed_seconds)


if __name__ == "__main__":
    main()
