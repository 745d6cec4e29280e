"""The pose fit after a FAIL takes the failed analysis's verdict for the profile it was made with
(``diagnosis.judged_before``), not made again: the same hints, one full analysis less.

A kobuki log (3 s) with ODOM_POSE_X raised by 100 LSB (10 mm) from 1 s on, each frame re-signed
by cantools (``tests.log_edit``): ``analyze --robot kobuki`` FAILs (10 mm off, tolerance 0.1 mm)
and names no robot mismatch, whole and in a batch, having analysed only pmir for the fit (before:
kobuki again, then pmir). Each verdict taken is the one a fresh analysis makes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

import odocan.host.judge.diagnosis as diagnosis
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import Tolerance, analyze
from odocan.sim import robot
from tests.log_edit import raise_raw


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("judged")
    clean, tampered = folder / "kobuki.log", folder / "tampered.log"
    assert main(["run", "--robot", "kobuki", "--duration", "3", "--log", str(clean)]) == 0
    assert raise_raw(clean, tampered, "ODOM_POSE_X", (2, 4), 100, 1.0) > 0
    return {"clean": clean, "tampered": tampered}


@pytest.fixture
def fitted(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The profiles the pose fit analyses (``diagnosis.analyze`` calls), in order."""
    made: list[str] = []

    def counted(*args: Any, **kwargs: Any) -> Any:
        made.append(args[1].name)
        return analyze(*args, **kwargs)

    monkeypatch.setattr(diagnosis, "analyze", counted)
    return made


def test_the_right_robots_tampered_log_names_no_robot_and_fits_pmir_only(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
    fitted: list[str],
) -> None:
    report = tmp_path / "r.json"
    capsys.readouterr()
    assert main(["analyze", str(logs["tampered"]), "--robot", "kobuki", "--stream", "never",
                 "--report", str(report)]) == 1
    out = capsys.readouterr().out
    assert "robot mismatch" not in out
    assert "robot mismatch" not in str(json.loads(report.read_text()).get("diagnosis"))
    assert fitted == ["pmir"]


def test_a_batch_fits_the_same_way(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
    fitted: list[str],
) -> None:
    second = tmp_path / "again.log"
    second.write_bytes(logs["tampered"].read_bytes())
    reports = tmp_path / "reports"
    capsys.readouterr()
    assert main(["analyze", str(logs["tampered"]), str(second), "--robot", "kobuki",
                 "--stream", "never", "--jobs", "1", "--report-dir", str(reports)]) == 1
    assert "robot mismatch" not in capsys.readouterr().out
    assert len(list(reports.glob("*.json"))) == 2
    for path in reports.glob("*.json"):
        assert "robot mismatch" not in str(json.loads(path.read_text()).get("diagnosis"))
    assert fitted == ["pmir", "pmir"]  # --jobs 1: in this process


@pytest.mark.parametrize(("log", "name", "integrator"), [
    ("tampered", "kobuki", None), ("tampered", "kobuki", "exact"), ("clean", "pmir", None),
    ("tampered", "pmir", "exact")])
def test_the_verdict_taken_is_a_fresh_analysiss(
    logs: dict[str, Path], log: str, name: str, integrator: str | None
) -> None:
    """Without --integrator the failed analysis resolved the log's; the fit asks with it by
    name: the same verdict (a FAIL here, 10 mm or a wrong robot's metres off)."""
    frames, profile, tolerance = read_log(logs[log]), robot.load(name), Tolerance()
    first = analyze(frames, profile, integrator, tolerance=tolerance)
    judged = diagnosis.judged_before(frames, profile, integrator, tolerance, first)
    assert judged is not None
    assert (judged.integrator, judged.passed) == ("exact", False)
    again = analyze(frames, profile, judged.integrator, tolerance=tolerance)
    assert judged.of(profile, judged.integrator, tolerance) is again.passed is False
    assert judged.of(profile, "euler", tolerance) is None
    assert judged.of(robot.load("pmir" if name == "kobuki" else "kobuki"), "exact",
                     tolerance) is None


def test_a_power_up_judged_from_each_frame_is_not_taken(logs: dict[str, Path]) -> None:
    """A re-run from a primed-on frame resolves the integrator of its own frames: no proof."""
    frames, profile = read_log(logs["tampered"]), robot.load("kobuki")
    first = analyze(frames, profile, tolerance=Tolerance())
    first.report["events"] = [*first.report["events"], {"kind": "power_up_primed_on"}]
    assert diagnosis.judged_before(frames, profile, None, Tolerance(), first) is None
    assert diagnosis.judged_before(frames, profile, "exact", Tolerance(), first) is not None
