"""``odocan fleet`` and ``odocan bridge`` through ``main()`` on the embedded amqtt broker: the
renamed count (-n/--count, --robots kept), the report written after the summary line, and the
wall-clock --duration honoured."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.fleet_run_until import pace_never_late


@pytest.mark.parametrize("count_option", ["-n", "--count", "--robots"])
def test_fleet_runs_and_reports(
    count_option: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """On a clock never late (``PacedClock``): a loaded machine's tick 95 ms late halts the
    boards, and a robot halted before any sample was judged is UNJUDGED, the run's exit 1 (the
    product's right answer, tests/test_fleet_overload.py's subject, not this one's)."""
    pace_never_late(monkeypatch)
    report = tmp_path / "fleet.json"
    code = main(["fleet", count_option, "2", "--duration", "1", "--seed", "7",
                 "--max-miss-ratio", "1", "--report", str(report)])
    out, err = capsys.readouterr()
    data = json.loads(report.read_text())
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
