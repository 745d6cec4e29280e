"""A wrong --robot is named as such, never read as a firmware fault (house rule 5)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.independent_checker import crc8h2f


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
    assert main(["analyze", str(kobuki_log), "--robot", "pmir", "--report", str(report)]) == 1
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
    assert main(["analyze", str(kobuki_log), "--robot", "pmir", "--integrator", "rk2"]) == 1
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
    assert main(["analyze", str(kobuki_log), str(second), "--robot", "pmir",
                 "--report-dir", str(reports)]) == 1
    out = capsys.readouterr().out
    hint = "robot mismatch: the log's poses fit robot 'kobuki', not 'pmir' (--robot)"
    assert f"{second}: {hint}" in out
    assert f"{kobuki_log}: {hint}" in out
    page = ("profile mismatch: profile hash differs: the log's firmware runs with the parameters "
            "of robot 'kobuki', not 'pmir' (--robot)")  # its PROFILE page first, as analyze LOG
    for report in reports.glob("*.json"):
        assert json.loads(report.read_text())["diagnosis"] == [page, hint]
    assert len(list(reports.glob("*.json"))) == 2


def _crc8h2f(data: bytes, data_id: int) -> int:
    """AUTOSAR E2E Profile 2's CRC (the DBC's comment): CRC8H2F over bytes 1..7, then DataID."""
    return crc8h2f(bytes(data[1:8]) + bytes([data_id]))


def test_replay_of_a_log_with_one_pose_off_does_not_blame_only_the_profile(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One ODOM_POSE_X of a kobuki log moved by 2 LSB (its E2E CRC made good again): replay with
    the right --robot FAILs, and said only "the log's poses fit no known robot profile: give its
    profile with --robot", sending the user after a profile that was right. It must also name
    the other cause: the recording firmware itself off the reference (analyze says where)."""
    lines = kobuki_log.read_text().splitlines()
    index = [i for i, line in enumerate(lines) if " 200#" in line][100]
    stamp, channel, frame = lines[index].split(" ")[:3]
    data = bytearray.fromhex(frame.split("#")[1])
    x_lsb = int.from_bytes(data[2:6], "little", signed=True) + 2  # X: i32 at byte 2, 0.1 mm
    data[2:6] = x_lsb.to_bytes(4, "little", signed=True)
    data[0] = _crc8h2f(bytes(data), (3 << 4) | (data[1] & 0xF))  # ODOM_POSE_X: E2E slot 3
    rest = lines[index].split(" ")[3:]
    lines[index] = " ".join([stamp, channel, f"200#{data.hex().upper()}", *rest])
    edited = tmp_path / "edited.log"
    edited.write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    assert main(["replay", str(edited), "--robot", "kobuki"]) == 1
    out = capsys.readouterr().out
    assert "its position differs from the log's by up to 0.2000 mm" in out
    assert "the firmware that recorded it was off the float64 reference" in out
    assert f"odocan analyze {edited} --robot kobuki" in out
