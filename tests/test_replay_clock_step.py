"""`odocan replay` of a log whose recorder's clock was set back mid-drive.

Found by the user trial (eleventh pass): a 20 s kobuki log whose times go back 100 s after its
3000th frame (a recorder whose clock was stepped back: `analyze` warns and judges every pose)
replayed with "time -80.00 s simulated (-87x real time)" and compared only the 416 poses before
the step; the 584 after it were silently left out, so a log whose firmware is 1 mm off from 10 s
on (`analyze` FAILs it) replayed as PASS, exit 0. The replayed bus carried the log's frames at
their logged times and its own firmware's at the replay clock's, so after the step every pose
was 100 s "younger" than the encoder frame it names and none was paired. The log's frames now go
on the replayed bus with the step taken out (``replay.clock_steps_s``).

The departing firmware is made independently: the clean drive's ODOM_POSE_X.X raised by 10 LSB
from 10 s on with cantools, its Profile 2 CRC re-signed with cantools' own implementation.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from odocan.host.cli.app import main
from tests.log_edit import raise_raw

STEP_LINE = 3000  # the clock goes back after this many frames (8.3 s into the drive)
STEP_S = -100.0
_LINE = re.compile(r"\((\d+\.\d+)\) (.*)")


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 20 s kobuki drive from power-up (seed 0)."""
    log = tmp_path_factory.mktemp("clockstep") / "r.log"
    assert main(["run", "--robot", "kobuki", "--duration", "20", "--log", str(log)]) == 0
    return log


def _raise_x(src: Path, dst: Path, lsb: int, from_s: float) -> int:
    """Copy ``src`` with ODOM_POSE_X.X ``lsb`` higher from ``from_s`` on; frames changed."""
    return raise_raw(src, dst, "ODOM_POSE_X", (2, 4), lsb, from_s)  # X: 16|32


def _step_back(src: Path, dst: Path) -> None:
    """``src`` with every time after line ``STEP_LINE`` moved by ``STEP_S``."""
    lines = []
    for number, line in enumerate(src.read_text().splitlines()):
        match = _LINE.fullmatch(line)
        assert match is not None, line
        t_s = float(match.group(1)) + (STEP_S if number >= STEP_LINE else 0.0)
        lines.append(f"({t_s:.6f}) {match.group(2)}\n")
    dst.write_text("".join(lines))


def _replay(log: Path, report: Path) -> tuple[int, dict[str, Any]]:
    code = main(["replay", str(log), "--robot", "kobuki", "--report", str(report)])
    return code, json.loads(report.read_text())


def test_a_clock_step_back_compares_every_pose(drive: Path, tmp_path: Path) -> None:
    stepped = tmp_path / "stepped.log"
    _step_back(drive, stepped)
    code, report = _replay(stepped, tmp_path / "r.json")
    vs_log = report["replay"]["onboard_vs_log"]
    assert code == 0
    assert vs_log["samples"] >= vs_log["logged"] - 2  # was 416 of 1000
    assert vs_log["identical"] == vs_log["samples"]
    assert report["sim_seconds"] > 0  # was -80 s


def test_a_departed_firmware_behind_a_clock_step_fails(drive: Path, tmp_path: Path) -> None:
    edited, stepped = tmp_path / "edited.log", tmp_path / "stepped.log"
    assert _raise_x(drive, edited, 10, 10.0) > 400  # 1 mm off for the last 10 s
    assert main(["analyze", str(edited), "--robot", "kobuki"]) == 1
    _step_back(edited, stepped)
    assert main(["analyze", str(stepped), "--robot", "kobuki"]) == 1
    code, report = _replay(stepped, tmp_path / "r.json")
    assert code == 1  # was PASS, exit 0
    assert report["replay"]["passed"] is False
