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
    assert json.loads(report.read_text())["diagnosis"] == [hint]


def test_analyze_with_the_right_robot_says_nothing_of_the_kind(
    kobuki_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["analyze", str(kobuki_log), "--robot", "kobuki"]) == 0
    assert "mismatch" not in capsys.readouterr().out
