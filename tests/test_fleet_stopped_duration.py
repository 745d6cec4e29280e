"""A fleet stopped by a signal reports the duration that ran, not the one asked for (#13)."""

from __future__ import annotations

import asyncio
import os
import signal

from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.host.mqtt.shards import aggregate
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.fleet import FleetConfig


def test_a_stopped_fleets_duration_is_what_ran_and_the_asked_one_is_kept() -> None:
    run = FleetRun(fleet=FleetConfig(robots=1, robot=robot.load("pmir"), seed=3),
                   duration_s=60.0, bridge=False)

    def started(robots: int, url: object) -> None:  # the signal handlers are installed now
        asyncio.get_running_loop().call_later(0.3, os.kill, os.getpid(), signal.SIGTERM)

    report = asyncio.run(run_fleet(run, on_start=started))
    assert report["stopped"]["signal"] == "SIGTERM"
    assert report["duration_asked_s"] == 60.0
    assert report["duration_s"] == report["stopped"]["done"]
    assert report["duration_s"] == round(report["ticks"] * TICK_S, 6)
    assert report["duration_s"] < 60.0


def test_the_fleets_duration_is_its_longest_workers() -> None:
    def worker(done_s: float) -> dict[str, object]:
        return {"robots": 1, "first_robot": "robot001", "duration_s": done_s,
                "duration_asked_s": 60.0, "deadline_miss_ratio": 0.0, "ticks": 1,
                "late_ticks": 0, "skipped_releases": 0, "max_lateness_ms": 0.0, "cpu_s": 0.1,
                "bridge": None, "per_robot": {}, "stopped": None}

    report = aggregate([worker(2.53), worker(2.54)])
    assert report["duration_s"] == 2.54
    assert report["duration_asked_s"] == 60.0
