"""A fleet stopped by a signal reports the duration that ran, not the one asked for (#13)."""

from __future__ import annotations

import asyncio
import json
import os
import signal
from pathlib import Path
from typing import Any

import pytest

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


def test_a_fleet_stopped_before_its_first_pose_judged_nothing_and_blames_no_firmware(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGTERM as the clock starts: no on-board pose was paired with the reference, so the
    robot is UNJUDGED (nothing judged, as ``run`` and the monitor say it), never a FAIL that
    blames its correct firmware; the run says no FAIL and exits as the signal ends it (143),
    never 1 (issue #11; before: "1 of 1 robots failed their verdict (robot001: no on-board
    pose paired with the reference)" and "partial run FAIL")."""
    from odocan.host.cli import app
    from odocan.host.cli.subparsers import fleet as fleet_cli

    said = fleet_cli._say_started

    def started(*args: Any, **kwargs: Any) -> None:  # the signal handlers are installed now
        said(*args, **kwargs)
        asyncio.get_running_loop().call_soon(os.kill, os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(fleet_cli, "_say_started", started)
    path = tmp_path / "fleet.json"
    code = app.main(["fleet", "-n", "1", "--duration", "5", "--max-miss-ratio", "1",
                     "--report", str(path)])
    out, err = capsys.readouterr()
    data = json.loads(path.read_text())
    robot001 = data["per_robot"]["robot001"]
    assert robot001["pose_vs_reference"] is None  # the premise: nothing paired
    assert robot001["verdict"] == "UNJUDGED", robot001["reason"]
    assert "nothing judged" in robot001["reason"]
    assert code == 143, out + err
    assert "FAIL" not in out.splitlines()[-1], out
    assert not any("failed their verdict" in f for f in data["failures"]), data["failures"]
