"""The poses the firmware sends while it works off a stall's backlog (issue #11, rule 5: a PASS
must never hide a wrong pose).

kobuki random seed 3, ``--faults stall=3:0.3`` (8 s and 12 s): the firmware is silent from
2.981 s to 3.301 s, then sends two poses that both name ENC_COUNTER 12 (3.301 s: the backlog's
frame of 3.00 s; 3.321 s: the live one of 3.32 s), neither of which the host resolves to one
encoder frame. On main, +1 m (and +10 mm) on the X of both PASSed ``analyze`` whole and
``--stream always`` ("judged 383 of 385", the first "not judged", the second never looked
at): the next sample (3.341 s) lay 0.04000000000000004 s after the first, past the
neighbours' 4 cycles of 10 ms, and the second pose was no silence's first. Now both are judged
by the samples around the silence (``host.judge.stallnext``): FAIL 999.9 mm / 9.917 mm beyond
at 3.321 s; the untampered drives PASS ("judged 385 of 385"). Which poses to edit is told here
from the log itself (python-can, cantools), the edits re-signed by cantools' CRC
(``tests/log_edit``).

The "held resends" reported around 10.57/10.59 s of the 12 s drive: this drive has no pose
naming its predecessor's ENC_COUNTER after 3.321 s; +1 m on the poses of 10.561 s and 10.581 s
(each alone and both) FAILs on main and here, kept below as a guard.

Each seed-3 drive runs once for the module (``drives``). tests.sweeps: a correct firmware keeps
every seed and both stalls once (seed 3 with ``3:0.3`` is ``stalled``'s 8 s drive).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import can
import cantools
import pytest
from cantools.database.can import Database

from odocan.sim import contract
from tests.log_edit import raise_raw_once
from tests.sweeps import sample

X_BYTES = (2, 4)  # ODOM_POSE_X's X: bytes 2..5, signed, 0.1 mm
ONE_M_LSB, TEN_MM_LSB = 10_000, 100
STREAMS = ("never", "always")


def _odocan(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, check=False)


def _drive(path: Path, seed: int, stall: str, duration_s: int = 8) -> Path:
    done = _odocan("run", "--robot", "kobuki", "--scenario", "random", "--seed", str(seed),
                   "--duration", str(duration_s), "--faults", f"stall={stall}", "--log",
                   str(path))
    assert path.exists(), done.stdout[-2000:] + done.stderr
    return path


def _verdicts(log: Path) -> list[int]:
    """``analyze --robot kobuki`` exit codes, whole then streamed."""
    codes = []
    for stream in STREAMS:
        done = _odocan("analyze", str(log), "--robot", "kobuki", "--stream", stream)
        assert done.returncode in (0, 1), done.stderr
        codes.append(done.returncode)
    return codes


def _poses_x(log: Path) -> list[tuple[float, int]]:
    """(time after the first frame, ENC_COUNTER) of each ODOM_POSE_X (its ID from cantools)."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    pose_x = db.get_message_by_name("ODOM_POSE_X")
    out, first = [], None
    for msg in can.LogReader(str(log)):
        first = msg.timestamp if first is None else first
        if msg.arbitration_id == pose_x.frame_id:
            out.append((msg.timestamp - first, msg.data[1] >> 4))  # ENC_COUNTER: bits 12..15
    return out


def _first_after_silence(log: Path, silence_s: float = 0.1) -> int:
    """The index of the first ODOM_POSE_X after a silence of ``silence_s`` or more."""
    poses = _poses_x(log)
    return next(i for i in range(1, len(poses)) if poses[i][0] - poses[i - 1][0] >= silence_s)


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> Callable[[int], Path]:
    """The seed-3 ``stall=3:0.3`` drive of that many seconds, driven once for the module."""
    made: dict[int, Path] = {}

    def drive(duration_s: int) -> Path:
        if duration_s not in made:
            made[duration_s] = _drive(tmp_path_factory.mktemp(f"stall{duration_s}") / "s.log",
                                      3, "3:0.3", duration_s)
        return made[duration_s]

    return drive


@pytest.fixture(scope="module", params=[8, 12], ids=["8s", "12s"])
def stalled(request: pytest.FixtureRequest, drives: Callable[[int], Path]) -> Path:
    return drives(request.param)


def test_the_first_two_poses_after_the_stall_name_one_counter(stalled: Path) -> None:
    """The case as found: 2.981 s -> 3.301 s silent, then two poses naming ENC_COUNTER 12."""
    poses = _poses_x(stalled)
    i = _first_after_silence(stalled)
    assert poses[i - 1][0] == pytest.approx(2.981, abs=2e-3)
    assert poses[i][0] == pytest.approx(3.301, abs=2e-3)
    assert poses[i][1] == poses[i + 1][1] == 12


def test_the_untampered_drive_passes(stalled: Path) -> None:
    assert _verdicts(stalled) == [0, 0]


@pytest.mark.parametrize("lsb", [ONE_M_LSB, TEN_MM_LSB], ids=["1m", "10mm"])
def test_the_first_two_poses_raised_fail(stalled: Path, tmp_path: Path, lsb: int) -> None:
    """+1 m / +10 mm on the X of both: PASS on main, FAIL now (999.9 / 9.917 mm beyond)."""
    start_s = _poses_x(stalled)[_first_after_silence(stalled)][0]
    out = tmp_path / "raised.log"
    times = raise_raw_once(stalled, out, "ODOM_POSE_X", X_BYTES, lsb, start_s - 5e-4, count=2)
    assert len(times) == 2
    assert _verdicts(out) == [1, 1]


@pytest.mark.parametrize("which", [0, 1], ids=["first", "second"])
def test_either_pose_alone_raised_10_mm_fails(stalled: Path, tmp_path: Path,
                                              which: int) -> None:
    poses = _poses_x(stalled)
    start_s = poses[_first_after_silence(stalled) + which][0]
    out = tmp_path / "raised.log"
    assert len(raise_raw_once(stalled, out, "ODOM_POSE_X", X_BYTES, TEN_MM_LSB,
                              start_s - 5e-4)) == 1
    assert _verdicts(out) == [1, 1]


@pytest.mark.parametrize("count", [1, 2])
def test_the_later_poses_near_10_57_s_raised_fail(drives: Callable[[int], Path], tmp_path: Path,
                                                  count: int) -> None:
    """The reported "held resends" (10.57 / 10.59 s of the 12 s drive): +1 m FAILs."""
    out = tmp_path / "raised.log"
    times = raise_raw_once(drives(12), out, "ODOM_POSE_X", X_BYTES, ONE_M_LSB, 10.555, count=count)
    assert times[0] == pytest.approx(10.561, abs=2e-3)
    assert _verdicts(out) == [1, 1]


@pytest.mark.parametrize(("stall", "seed"), sample(
    [(stall, seed) for stall in ("3:0.3", "2:0.5") for seed in (3, 4, 5)], 3, [("3:0.3", 4)]))
def test_a_correct_firmware_passes(tmp_path: Path, seed: int, stall: str) -> None:
    assert _verdicts(_drive(tmp_path / "s.log", seed, stall)) == [0, 0]
