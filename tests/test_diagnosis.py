"""A wrong --robot is named as such, never read as a firmware fault (house rule 5)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main


@pytest.fixture(scope="module")
def kobuki_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("diagnosis") / "kobuki.log"
    assert main(["run", "--robot", "kobuki", "--duration", "3", "--log", str(log)]) == 0
    return log


def test_analyze_with_the_wrong_robot_names_the_robot_that_fits(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    report = tmp_path / "r.json"
    assert main(["analyze", str(kobuki_log), "--report", str(report)]) == 1  # pmir by default
    out = capsys.readouterr().out
    hint = "robot mismatch: the log's poses fit robot 'kobuki', not 'pmir' (--robot)"
    assert hint in out
    said = ("profile mismatch: profile hash differs: the log's firmware runs with the parameters "
            "of robot 'kobuki', not 'pmir' (--robot)")  # its ODOM_STATUS PROFILE page, first
    assert json.loads(report.read_text())["diagnosis"] == [said, hint]


def test_analyze_with_the_right_robot_says_nothing_of_the_kind(
    kobuki_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["analyze", str(kobuki_log), "--robot", "kobuki"]) == 0
    assert "mismatch" not in capsys.readouterr().out


def test_analyze_with_the_wrong_integrator_names_the_logged_one(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The log's firmware ran exact: ``--integrator euler`` FAILed with no word of why (the
    robot check, run with euler, found no profile that fits)."""
    capsys.readouterr()
    report = tmp_path / "r.json"
    assert main(["analyze", str(kobuki_log), "--robot", "kobuki", "--integrator", "euler",
                 "--report", str(report)]) == 1
    hint = "integrator mismatch: the log's ODOM_STATUS reports exact, not euler (--integrator)"
    assert hint in capsys.readouterr().out
    said = "profile mismatch: the log's firmware runs with integrator exact, not euler"
    assert json.loads(report.read_text())["diagnosis"] == [said, hint]


def test_analyze_with_the_wrong_integrator_and_robot_names_both(
    kobuki_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["analyze", str(kobuki_log), "--integrator", "rk2"]) == 1
    out = capsys.readouterr().out
    assert "integrator mismatch: the log's ODOM_STATUS reports exact, not rk2" in out
    assert "robot mismatch: the log's poses fit robot 'kobuki', not 'pmir' (--robot)" in out


def test_a_batch_names_the_robot_mismatch_of_each_log(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``analyze a.log b.log`` FAILed both with no word of why (the single-log path named the
    robot that fits; the batch did not look)."""
    second = tmp_path / "again.log"
    second.write_bytes(kobuki_log.read_bytes())
    reports = tmp_path / "reports"
    capsys.readouterr()
    assert main(["analyze", str(kobuki_log), str(second), "--report-dir", str(reports)]) == 1
    out = capsys.readouterr().out
    hint = "robot mismatch: the log's poses fit robot 'kobuki', not 'pmir' (--robot)"
    assert f"{second}: {hint}" in out
    assert f"{kobuki_log}: {hint}" in out
    for report in reports.glob("*.json"):
        assert json.loads(report.read_text())["diagnosis"] == [hint]
    assert len(list(reports.glob("*.json"))) == 2
