"""``odocan fleet`` and ``odocan bridge`` through ``main()`` on the embedded amqtt broker: the
renamed count (-n/--count, --robots kept), the report written after the summary line, and the
wall-clock --duration honoured."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main


@pytest.mark.parametrize("count_option", ["-n", "--count", "--robots"])
def test_fleet_runs_and_reports(
    count_option: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "fleet.json"
    code = main(["fleet", count_option, "2", "--duration", "1", "--seed", "7",
                 "--max-miss-ratio", "1", "--report", str(report)])
    out, err = capsys.readouterr()
    data = json.loads(report.read_text())
    # 0 even when a loaded machine made the loop skip releases: their samples are sent late
    # (sim.fleet.Fleet.step), the poses judged all the same
    assert code == 0, out + err
    assert out.startswith("fleet: 2 robots, ")
    assert data["robots"] == 2
    assert data["duration_s"] == 1.0
    assert [r["seed"] for r in data["per_robot"].values()] == [7, 8]
    assert all(r["frames_total"] > 0 for r in data["per_robot"].values())


def test_bridge_stops_after_its_wall_clock_duration(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["bridge", "-i", "virtual", "-c", "cli-bridge", "--name", "r1",
                 "--duration", "0.5"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert err.startswith("bridge r1: mqtt://127.0.0.1:")
    assert "(embedded)" in err
