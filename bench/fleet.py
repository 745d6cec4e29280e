"""The largest fleet that runs in real time: deadline_miss_ratio <= 0.001 over a few seconds.

For each setting (bridged to mosquitto on loopback when installed, then to the embedded amqtt
broker in its own process; both with ``--workers`` worker processes as ``odocan fleet --workers``
runs them, plus the fleet without a bridge in one process) the number of robots is doubled until a
trial misses, then bisected. Every trial prints its figures, the load average (other work on the
machine shows up as misses) and the CPU it cost per robot and 10 ms tick: the workers' (their
process time while the clock ran, the report's ``cpu_s``: other processes on the machine do not
count) and the broker's (/proc/PID/stat). One idle core's worth of CPU is 10 000 us per tick:
robots per core is about 10 000 / (us per robot-tick).

    .venv/bin/python bench/fleet.py [--trial-s 3] [--start 8] [--max 256] [--workers 2]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.mqtt.broker import LOOPBACK, BrokerURL, free_loopback_port
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.host.mqtt.shards import BrokerProcess, run_sharded
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig

LIMIT = 0.001
TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def proc_cpu_s(pid: int | None) -> float:
    """User + system CPU seconds of process ``pid`` so far (0 when unknown)."""
    if pid is None:
        return 0.0
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def trial(n: int, seconds: float, bridge: bool, broker: BrokerURL | None, workers: int,
          broker_pid: int | None) -> float:
    """One run of ``n`` robots; prints and returns its deadline_miss_ratio."""
    run = FleetRun(fleet=FleetConfig(robots=n, robot=robot.load("pmir")), duration_s=seconds,
                   bridge=bridge, broker=broker, client_prefix=f"bench-{n}-{time.time_ns()}")
    broker0 = proc_cpu_s(broker_pid)
    report = run_sharded(run, min(workers, n)) if bridge else asyncio.run(run_fleet(run))
    broker_cpu = proc_cpu_s(broker_pid) - broker0  # includes the workers' connect and goodbye
    ratio: float = report["deadline_miss_ratio"]
    robot_ticks = sum(w["robots"] * w["ticks"] for w in _workers(report))
    extra = ""
    if report["bridge"]:
        extra = (f", bridge frames {report['bridge']['frames_in']}, "
                 f"dropped {report['bridge']['frames_dropped']}")
    print(f"  N={n:4d}: deadline_miss_ratio {ratio:.4f} ({report['late_ticks']} late of "
          f"{report['ticks']}, worst {report['max_lateness_ms']:.1f} ms, "
          f"{report['skipped_releases']} skipped{extra}); CPU per robot-tick: fleet+bridge "
          f"{report['cpu_s'] / robot_ticks * 1e6:.0f} us, broker "
          f"{broker_cpu / robot_ticks * 1e6:.0f} us; load {os.getloadavg()[0]:.2f}", flush=True)
    return ratio


def _workers(report: dict[str, Any]) -> list[dict[str, Any]]:
    return report.get("workers") or [report]


def largest(passes: Callable[[int], bool], start: int, maximum: int) -> int:
    """The largest N in [1, maximum] that passes (doubling from ``start``, then bisecting)."""
    good, bad = 0, maximum + 1
    n = start
    while n <= maximum:
        if passes(n):
            good = n
            n *= 2
        else:
            bad = n
            break
    if good == 0:  # even ``start`` failed: search below it
        bad, n = start, start // 2
        while n >= 1 and not passes(n):
            bad, n = n, n // 2
        good = max(n, 0)
    while bad - good > max(1, good // 16):
        mid = (good + bad) // 2
        if passes(mid):
            good = mid
        else:
            bad = mid
    return good


def start_mosquitto(workdir: Path) -> tuple[subprocess.Popen[bytes], BrokerURL] | None:
    """An anonymous mosquitto on a free loopback port (None when not installed)."""
    exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not Path(exe).exists():
        return None
    port = free_loopback_port()
    conf = workdir / "bench.conf"
    conf.write_text(f"listener {port} {LOOPBACK}\nallow_anonymous true\nlog_dest none\n")
    proc = subprocess.Popen([exe, "-c", str(conf)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    time.sleep(0.3)
    return proc, BrokerURL(host=LOOPBACK, port=port)


def cpu_cost_us(n: int = 10, ticks: int = 300) -> tuple[float, float]:
    """CPU time (process time, so other processes do not count) per robot and tick: the fleet
    step alone, and the bridge's frame handling (E2E, decode, reference) on top (us)."""
    from odocan.host.judge.reference import Geometry
    from odocan.host.mqtt.telemetry import RobotTelemetry
    from odocan.sim.fleet import Fleet

    p = robot.load("pmir")
    geometry = Geometry.of(p)
    with Fleet(FleetConfig(robots=n, robot=p)) as fleet:
        telemetry = [RobotTelemetry(name, geometry, "exact", counter_bits=p.counter_bits)
                     for name in fleet.names]
        step_s = bridge_s = 0.0
        for k in range(ticks):
            t0 = time.process_time()
            fleet.step(k)
            batch = fleet.take_batch()
            t1 = time.process_time()
            for i, msg in batch:
                telemetry[i].feed(msg)
            bridge_s += time.process_time() - t1
            step_s += t1 - t0
    return step_s / (n * ticks) * 1e6, bridge_s / (n * ticks) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trial-s", type=float, default=3.0)
    parser.add_argument("--start", type=int, default=8)
    parser.add_argument("--max", type=int, default=256)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--fixed", type=int, action="append", metavar="N",
                        help="one trial of N robots per setting, no search (repeatable): the CPU "
                        "figures on a machine too loaded for real time")
    parser.add_argument("--only", choices=("mosquitto", "embedded", "none"), action="append",
                        help="run only these settings (repeatable; default: all)")
    args = parser.parse_args()
    print(f"fleet bench: {os.cpu_count()} CPUs, {args.trial_s:.0f} s per trial, "
          f"limit deadline_miss_ratio <= {LIMIT}, {args.workers} workers, "
          f"load {os.getloadavg()[0]:.2f}")
    step_us, bridge_us = cpu_cost_us()
    print(f"CPU per robot and 10 ms tick, in process: step {step_us:.0f} us, bridge frame "
          f"handling {bridge_us:.0f} us -> one idle core fits about {10_000 / step_us:.0f} robots "
          f"without the bridge, {10_000 / (step_us + bridge_us):.0f} with it (before MQTT I/O)")
    wanted = set(args.only or ("mosquitto", "embedded", "none"))
    results: dict[str, int] = {}
    with tempfile.TemporaryDirectory() as tmp:
        mosquitto = start_mosquitto(Path(tmp)) if "mosquitto" in wanted else None
        embedded = BrokerProcess() if "embedded" in wanted else None
        settings: list[tuple[str, bool, BrokerURL | None, int | None]] = []
        if mosquitto is not None:
            settings.append((f"bridge -> mosquitto, {args.workers} workers", True, mosquitto[1],
                             mosquitto[0].pid))
        if embedded is not None:
            url = embedded.start()
            settings.append((f"bridge -> embedded amqtt process, {args.workers} workers", True,
                             url, embedded.pid))
        if "none" in wanted:
            settings.append(("no bridge, 1 process", False, None, None))
        try:
            for label, bridge, broker, pid in settings:
                print(f"{label}:")
                if args.fixed:
                    for n in args.fixed:
                        trial(n, args.trial_s, bridge, broker, args.workers, pid)
                    continue
                results[label] = largest(
                    lambda n, b=bridge, u=broker, p=pid:
                    trial(n, args.trial_s, b, u, args.workers, p) <= LIMIT,
                    args.start, args.max)
        finally:
            if embedded is not None:
                embedded.stop()
            if mosquitto is not None:
                mosquitto[0].terminate()
                mosquitto[0].wait()
    print_largest(results)


def print_largest(results: dict[str, int]) -> None:
    """The largest real-time fleet of each setting searched, against its target."""
    if results:
        print("largest real-time fleet (deadline_miss_ratio <= 0.001):")
    targets = {"mosquitto": 100, "embedded": 50}
    for label, n in results.items():
        target = next((t for key, t in targets.items() if key in label), None)
        note = "" if target is None or n >= target else f"  (target {target} not reached)"
        print(f"  {label:44s} {n:4d} robots{note}")


if __name__ == "__main__":
    main()
