"""Where a fleet worker's late ticks come from: one worker, bridged to mosquitto, instrumented.

Runs ``n`` robots in this one process (what one ``odocan fleet --workers N`` worker runs) and
prints, besides the report's miss ratio and CPU per robot-tick (us):

- the CPU per robot-tick by part: the fleet step, the bridge's intake (``Bridge._handle``: E2E,
  decode, the live judge, the publications queued) and the rest (MQTT writes, the links' tasks,
  the event loop);
- the MQTT publications and socket writes per robot-tick (counted over the whole run, the
  connections' start and end included);
- the lateness distribution of the 10 ms ticks (ms: p50, p90, p99, p99.9, max);
- the cyclic GC's collections while the clock ran (``gc.callbacks``: count per generation, the
  longest pause) and how many late ticks had a collection in the period before them;
- late ticks by tick number modulo 10 (the 10 Hz telemetry lands on one tick in ten: a burst
  would show as one residue with more late ticks than the others);
- with ``--slow-ms X``: asyncio debug mode, and which callbacks ran longer than X ms (debug mode
  itself costs CPU: compare its miss ratio with a run without it);
- with ``--profile``: the top functions by own time (cProfile, over the whole run);
- with ``--flat-out``: no clock at all: the ticks of ``--seconds`` run back to back (the event
  loop gets a few turns between ticks, for the bridge and the MQTT I/O), so the CPU per
  robot-tick is measured without the wall clock (a shared machine's other load barely moves it;
  ``status``/``rates``, once a wall-clock second, land on fewer ticks).

    .venv/bin/python bench/fleet_jitter.py --robots 25 --seconds 10 [--slow-ms 2] [--profile]
    .venv/bin/python bench/fleet_jitter.py --robots 20 --seconds 20 --flat-out [--profile]
    .venv/bin/python bench/fleet_jitter.py --robots 20 --seconds 10 --flat-out --firmware c

Wall-clock figures depend on the machine's other load (printed: the load average); the CPU per
robot-tick barely does.
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import gc
import logging
import os
import pstats
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from fleet import start_mosquitto  # bench/fleet.py
from fleet_flat import run_flat  # bench/fleet_flat.py

import odocan.host.mqtt.bridge as bridge_module
import odocan.host.mqtt.client as client
import odocan.host.mqtt.fleetrun as fleetrun
import odocan.host.mqtt.link as link
import odocan.sim.fleet as fleet_module
import odocan.sim.realtime as realtime
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.fleet import Fleet, FleetConfig

LATE_S = 0.005  # a tick is late after half a 10 ms period (sim.realtime.DeadlineStats)


class Probe:
    """Per-tick lateness (s), GC pauses and slow-callback warnings, each with its perf time."""

    def __init__(self) -> None:
        self.ticks: list[tuple[float, float]] = []  # (perf_counter s, lateness s)
        self.gcs: list[tuple[float, float, int]] = []  # (start s, pause s, generation)
        self.slow: list[tuple[float, str]] = []
        self.senders: list[client.CoalescedSend] = []  # every link's socket writes
        self.publications = 0  # QoS 0 and QoS 1, every link
        self._gc_start_s = 0.0
        self.part_s: Counter[str] = Counter()  # process time in the fleet step, the intake

    def install(self) -> None:
        record = realtime.DeadlineStats.record
        ticks = self.ticks

        def recorded(stats: realtime.DeadlineStats, lateness_s: float) -> None:
            ticks.append((time.perf_counter(), lateness_s))
            record(stats, lateness_s)

        realtime.DeadlineStats.record = recorded  # type: ignore[method-assign]
        gc.callbacks.append(self._on_gc)
        probe = self
        made = client.CoalescedSend.__init__
        publish = link.RobotLink.publish

        def making(sender: client.CoalescedSend, paho: Any) -> None:
            made(sender, paho)
            probe.senders.append(sender)

        def publishing(robot_link: link.RobotLink, leaf: str, payload: dict[str, Any]) -> None:
            probe.publications += 1
            publish(robot_link, leaf, payload)

        self._time_part(fleet_module.Fleet, "step", "step")
        self._time_part(bridge_module.Bridge, "_handle", "intake")
        client.CoalescedSend.__init__ = making  # type: ignore[method-assign]
        link.RobotLink.publish = publishing  # type: ignore[method-assign]

        class SlowCallbacks(logging.Handler):
            def emit(self, rec: logging.LogRecord) -> None:
                probe.slow.append((time.perf_counter(), rec.getMessage()))

        logging.getLogger("asyncio").addHandler(SlowCallbacks())

    def _time_part(self, cls: Any, method: str, part: str) -> None:
        """Add the process time of ``cls.method`` to ``part_s[part]``."""
        original = getattr(cls, method)
        part_s = self.part_s

        def timed(*args: Any) -> Any:
            t0_s = time.process_time()
            try:
                return original(*args)
            finally:
                part_s[part] += time.process_time() - t0_s

        setattr(cls, method, timed)

    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        now_s = time.perf_counter()
        if phase == "start":
            self._gc_start_s = now_s
        else:
            self.gcs.append((self._gc_start_s, now_s - self._gc_start_s, info["generation"]))


async def flat_out(
    fleet: Fleet, *, duration_s: float | None, on_batch: Any = None, stop: Any = None,
    period_s: float = TICK_S, stats: realtime.DeadlineStats | None = None,
) -> realtime.DeadlineStats:
    """``sim.fleet.run_realtime`` without the clock: ``bench/fleet_flat.py``'s ``run_flat`` (a
    tick once the bridge handled the previous one's frames; before, four loop turns a tick let
    the bridge fall behind from ~75 robots a worker and drain after the clock stopped)."""
    assert duration_s is not None
    return await run_flat(fleet, duration_s=duration_s, on_batch=on_batch, stop=stop,
                          stats=stats)


def percentile_ms(sorted_s: list[float], q: float) -> float:
    """The ``q`` quantile (0..1, nearest rank) of sorted seconds, in ms."""
    return sorted_s[min(int(q * len(sorted_s)), len(sorted_s) - 1)] * 1e3


def callback_name(message: str) -> str:
    """A slow-callback warning shortened to what ran: the task's name or the handle's function."""
    for key in ("name='", "Handle "):
        if key in message:
            rest = message.split(key, 1)[1]
            return rest.split("'" if key == "name='" else "(", 1)[0]
    return message[:60]


def show(probe: Probe, report: dict[str, Any], robots: int) -> None:
    """Print the figures listed in the module docstring."""
    ticks = report["ticks"]
    print(f"{robots} robots, {ticks} ticks, load average {os.getloadavg()[0]:.2f}: "
          f"deadline_miss_ratio {report['deadline_miss_ratio']:.4f}, "
          f"CPU {report['cpu_s'] / robots / ticks * 1e6:.0f} us per robot-tick")
    per = robots * ticks / 1e6
    step_us, intake_us = probe.part_s["step"] / per, probe.part_s["intake"] / per
    print(f"parts per robot-tick (us): fleet step {step_us:.1f}, bridge intake (E2E, decode, "
          f"live judge, publications queued) {intake_us:.1f}, the rest (MQTT writes, the links' "
          f"tasks, the event loop) {report['cpu_s'] / per - step_us - intake_us:.1f}")
    writes = sum(sender.writes for sender in probe.senders)
    print(f"MQTT: {probe.publications / robots / ticks:.3f} publications and "
          f"{writes / robots / ticks:.3f} socket writes per robot-tick (the whole run)")
    late = sorted(lateness for _, lateness in probe.ticks)
    print("lateness ms: " + ", ".join(f"p{q * 100:g} {percentile_ms(late, q):.2f}"
                                       for q in (0.5, 0.9, 0.99, 0.999, 1.0)))
    start_s = probe.ticks[0][0]
    gcs = [g for g in probe.gcs if g[0] >= start_s]
    per_gen = Counter(gen for _, _, gen in gcs)
    print(f"gc while running: {dict(sorted(per_gen.items()))} collections by generation, "
          f"longest {max((p for _, p, _ in gcs), default=0.0) * 1e3:.2f} ms (with the full "
          f"pass after the clock, fleetrun.TickCollector)")
    late_ticks = [(i, t) for i, (t, lateness) in enumerate(probe.ticks) if lateness > LATE_S]
    with_gc = sum(any(t - 0.02 <= g <= t for g, _, _ in gcs) for _, t in late_ticks)
    print(f"late ticks: {len(late_ticks)}, {with_gc} with a collection in the 20 ms before")
    residues = Counter(i % 10 for i, _ in late_ticks)
    print("late ticks by tick mod 10: " + " ".join(f"{r}:{residues[r]}" for r in range(10)))
    if probe.slow:
        names = Counter(callback_name(m) for t, m in probe.slow if t >= start_s)
        print("slow callbacks: " + ", ".join(f"{n} x{c}" for n, c in names.most_common(6)))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, default=25)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--slow-ms", type=float, default=None)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--flat-out", action="store_true")
    parser.add_argument("--firmware", choices=("python", "c"), default="python")
    args = parser.parse_args()
    if args.flat_out:
        fleetrun.run_realtime = flat_out  # type: ignore[assignment]
    probe = Probe()
    probe.install()
    with tempfile.TemporaryDirectory() as tmp:
        started = start_mosquitto(Path(tmp))
        if started is None:
            print("error: mosquitto is not installed", file=sys.stderr)
            return 2
        broker, url = started
        run = FleetRun(FleetConfig(robots=args.robots, robot=robot.load("pmir"),
                                   firmware=args.firmware),
                       duration_s=args.seconds, broker=url)

        async def go() -> dict[str, Any]:
            if args.slow_ms is not None:
                loop = asyncio.get_running_loop()
                loop.set_debug(True)
                loop.slow_callback_duration = args.slow_ms / 1e3
            return await run_fleet(run)

        profiler = cProfile.Profile() if args.profile else None
        try:
            if profiler is not None:
                profiler.enable()
            report = asyncio.run(go())
        finally:
            if profiler is not None:
                profiler.disable()
            broker.terminate()
            broker.wait()
    show(probe, report, args.robots)
    if profiler is not None:
        pstats.Stats(profiler).sort_stats("tottime").print_stats(15)
    return 0


if __name__ == "__main__":
    sys.exit(main())
