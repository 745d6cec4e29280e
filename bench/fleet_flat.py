"""One fleet worker bridged to mosquitto, stepped flat out: CPU per robot-tick with MQTT, no skips.

``bench/fleet.py`` measures the fleet in real time; on a shared, loaded machine its trials skip
releases (a period or more behind), and a skip changes the work (steps spanning several ticks, a
drive run ahead falling back), so its CPU figures drift with the load. Here ``run_fleet`` (one
worker: the fleet, the bridge with its live judge, one MQTT connection per robot to a mosquitto
on loopback) runs under a clock that is never late: every tick is released at once, the MQTT
tasks get their loop turn between ticks as in real time, and the report's ``cpu_s`` (this
process, while the clock ran) over robots x ticks is the CPU per robot-tick of everything a
worker does. Verdicts are printed too (every robot judged: no skip). Pair trees in alternation:

    .venv/bin/python bench/fleet_flat.py [--robots 50] [--ticks 600] [--repeat 3]

The script runs unchanged on trees since the bridge's ``run_fleet`` (copy it there to pair).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from fleet import start_mosquitto  # bench/fleet.py

import odocan.sim.fleet as sim_fleet
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig

TICK_S = 0.01


class NeverLate:
    """``run_realtime``'s clock, never late: its two reads of tick k (the delay before the
    release, the lateness after) both say ``k * TICK_S``."""

    def __init__(self) -> None:
        self.reads = 0

    def now_s(self) -> float:
        self.reads += 1
        return (self.reads - 1) // 2 * TICK_S


def one_run(robots: int, ticks: int) -> str:
    """One flat-out run of ``robots`` for ``ticks`` ticks; its line of figures."""
    with tempfile.TemporaryDirectory() as tmp:
        started = start_mosquitto(Path(tmp))
        if started is None:
            raise SystemExit("mosquitto is not installed")
        proc, url = started
        try:
            run = FleetRun(fleet=FleetConfig(robots=robots, robot=robot.load("pmir")),
                           duration_s=ticks * TICK_S, broker=url,
                           client_prefix=f"bench-flat-{time.time_ns()}")
            report = asyncio.run(run_fleet(run))
        finally:
            proc.terminate()
            proc.wait()
    verdicts = Counter(r["verdict"] for r in report["per_robot"].values())
    per_us = report["cpu_s"] / (report["robots"] * report["ticks"]) * 1e6
    return (f"{robots} robots, {report['ticks']} ticks flat out: {per_us:.1f} us CPU per "
            f"robot-tick (fleet + bridge + MQTT), {report['skipped_releases']} skipped, "
            f"verdicts {dict(verdicts)}, load {os.getloadavg()[0]:.2f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=50)
    parser.add_argument("--ticks", type=int, default=600)
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    sim_fleet.RealTimeClock = NeverLate  # type: ignore[attr-defined, assignment]
    for _ in range(args.repeat):
        print(one_run(args.robots, args.ticks), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
