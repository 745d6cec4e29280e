"""The largest fleet that runs in real time: deadline_miss_ratio <= 0.001 over a few seconds.

For each setting (no bridge; bridged to mosquitto on loopback when installed; bridged to the
embedded amqtt broker) the number of robots is doubled until a trial misses, then bisected.
Prints every trial and the load average (other work on the machine shows up as misses).

    .venv/bin/python bench/fleet.py [--trial-s 3] [--start 8] [--max 256]
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

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.mqtt.broker import LOOPBACK, BrokerURL, free_loopback_port
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig

LIMIT = 0.001


def trial(n: int, seconds: float, bridge: bool, broker: BrokerURL | None) -> float:
    """One run of ``n`` robots; prints and returns its deadline_miss_ratio."""
    run = FleetRun(fleet=FleetConfig(robots=n, robot=robot.load("pmir")), duration_s=seconds,
                   bridge=bridge, broker=broker, client_prefix=f"bench-{n}-{time.time_ns()}")
    report = asyncio.run(run_fleet(run))
    ratio: float = report["deadline_miss_ratio"]
    extra = ""
    if report["bridge"]:
        extra = (f", bridge frames {report['bridge']['frames_in']}, "
                 f"dropped {report['bridge']['frames_dropped']}")
    print(f"  N={n:4d}: deadline_miss_ratio {ratio:.4f} ({report['late_ticks']} late of "
          f"{report['ticks']}, worst {report['max_lateness_ms']:.1f} ms, "
          f"{report['skipped_releases']} skipped{extra}); load {os.getloadavg()[0]:.2f}",
          flush=True)
    return ratio


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
    args = parser.parse_args()
    print(f"fleet bench: {os.cpu_count()} CPUs, {args.trial_s:.0f} s per trial, "
          f"limit deadline_miss_ratio <= {LIMIT}")
    step_us, bridge_us = cpu_cost_us()
    print(f"CPU per robot and 10 ms tick: step {step_us:.0f} us, bridge frame handling "
          f"{bridge_us:.0f} us -> one idle core fits about {10_000 / step_us:.0f} robots "
          f"without the bridge, {10_000 / (step_us + bridge_us):.0f} with it (before MQTT I/O)")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        mosquitto = start_mosquitto(Path(tmp))
        settings: list[tuple[str, bool, BrokerURL | None]] = [("no bridge", False, None)]
        if mosquitto is not None:
            settings.append(("bridge -> mosquitto", True, mosquitto[1]))
        settings.append(("bridge -> embedded amqtt", True, None))
        try:
            for label, bridge, broker in settings:
                print(f"{label}:")
                results[label] = largest(
                    lambda n, b=bridge, u=broker: trial(n, args.trial_s, b, u) <= LIMIT,
                    args.start, args.max)
        finally:
            if mosquitto is not None:
                mosquitto[0].terminate()
                mosquitto[0].wait()
    print("largest real-time fleet (deadline_miss_ratio <= 0.001):")
    for label, n in results.items():
        print(f"  {label:28s} {n:4d} robots{'' if n >= 50 else '  (target 50 not reached)'}")


if __name__ == "__main__":
    main()
