"""`odocan replay` must not re-anchor the logged positions for free across a gap or a stall
(issue #11, rule 5: a PASS must never hide a wrong pose).

Found by the outside trial: replay PASSed 16 of 30 logs with ODOM_POSE_X's X raised by 10 mm
(re-signed, ``tests/log_edit``) from the first pose after a gap of the encoder frames (a bus-off,
a burst of drops) or a stall on. Replay compared the positions after the log's first gap only by
their drift *between* gaps, re-anchored at each, so a step that began at a gap was absorbed; and
where the log's firmware merged frames on board (a stall: TIME_LOST), not at all ("positions not
compared"). Across a gap the offset log - replay may move only as far as the firmware could
have stepped differently there (``host.judge.replay_jumps``: none where its E2E pages prove it
missed the gap whole, as the replay did; else the analysis judge's ``gapbound`` allowance), and
where it merged frames, between any two poses by twice the allowance of their span.

The untampered twins, and lossy drives of both robots, still PASS. Which frame starts the edit
is read from the log with python-can and cantools (not odocan).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import cantools
import pytest
from cantools.database.can import Database

from odocan.sim import contract
from tests.judges_cli import raise_x_10_mm

DRIVES = {  # the trial's drives: a bus-off, a burst of drops, a stall with drops
    "busoff": ["--robot", "kobuki", "--scenario", "random", "--seed", "11", "--duration", "10",
               "--faults", "busoff=2:0.5"],
    "burst": ["--robot", "kobuki", "--scenario", "random", "--seed", "12", "--duration", "10",
              "--faults", "burst=0.01:12"],
    "stall": ["--robot", "kobuki", "--scenario", "random", "--seed", "185", "--duration", "10",
              "--faults", "stall=3:1,drop=0.05"],
}


def _odocan(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, check=False)


def _first_pose_after_a_break_s(log: Path) -> float:
    """The time (from the log's first frame) of the first ODOM_POSE_X after the log's first
    break: more than 35 ms without an encoder frame, or 100 ms without a pose (a stall)."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    pose = db.get_message_by_name("ODOM_POSE_X").frame_id
    encoder = db.get_message_by_name("WHEEL_ENCODERS").frame_id
    first, last_enc, last_pose, broke = None, None, None, False
    for msg in can.LogReader(str(log)):
        first = msg.timestamp if first is None else first
        t = msg.timestamp - first
        if msg.arbitration_id == encoder:
            broke |= last_enc is not None and t - last_enc > 0.035
            last_enc = t
        elif msg.arbitration_id == pose:
            broke |= last_pose is not None and t - last_pose > 0.1
            if broke:
                return t
            last_pose = t
    raise AssertionError(f"{log}: no break in the log")


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Path]:
    log = tmp_path_factory.mktemp(request.param) / "drive.log"
    done = _odocan("run", *DRIVES[request.param], "--log", str(log))
    assert done.returncode == 0, done.stdout[-2000:]
    return request.param, log


def test_plus_10_mm_from_the_first_pose_after_a_gap_or_stall_is_no_pass(
        drive: tuple[str, Path], tmp_path: Path) -> None:
    """The stall's (kobuki 185, from the first pose after a 1 s stall) PASSed within the whole
    span's gap allowance (738 mm); it is caught since a life identical to the log before its
    stall and off it as it is after is not judged PASS (``replay_lives._raw_departs``)."""
    name, log = drive
    out = tmp_path / "raised.log"
    from_s = _first_pose_after_a_break_s(log)
    assert raise_x_10_mm(log, out, from_s - 1e-4) > 100
    done = _odocan("replay", str(out), "--robot", "kobuki")
    assert done.returncode == 1, f"{name} from {from_s:.3f} s: {done.stdout[-2000:]}"


def test_plus_10_mm_from_mid_drive_is_no_pass(drive: tuple[str, Path], tmp_path: Path) -> None:
    name, log = drive
    out = tmp_path / "raised.log"
    assert raise_x_10_mm(log, out, 5.0) > 100
    done = _odocan("replay", str(out), "--robot", "kobuki")
    assert done.returncode == 1, f"{name} from 5 s: {done.stdout[-2000:]}"


def test_the_untampered_drive_passes(drive: tuple[str, Path]) -> None:
    name, log = drive
    done = _odocan("replay", str(log), "--robot", "kobuki")
    assert done.returncode == 0, f"{name}: {done.stdout[-2000:]}"
