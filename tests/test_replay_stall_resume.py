"""``odocan replay`` holds the log's first pose after a stall to the poses its firmware can resume
at (``host.judge.replay_resume``; issue #11 item 4, rule 5: a PASS must never hide a wrong pose).

Found by the outside trial: kobuki circle 526, 11 s, ``stall=2.0:0.5,busoff=2.3:0.3,drop=0.05``
(the stall and the bus-off one silence of the firmware, 1.99 .. 2.62 s, the log's own hole
2.29 .. 2.61 s inside it) with ODOM_POSE_X raised 10 mm from 2.55 s replayed PASS: across the
stall the replay held the offset's jump to the gap bound of the whole span, 0.707 m, while
``odocan analyze`` FAILed it by its resume rule. The correct log still replays PASS.

The firmware is proven right by the tests' watch (every step integrated again in float64,
``tests.fw_watch``), not by the judges; the tamper is made with python-can and cantools
(``tests.log_edit``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.judges_cli import cli, correct_drive, raise_x_10_mm

DRIVE = ("kobuki", "circle", 526, 11, "stall=2.0:0.5,busoff=2.3:0.3,drop=0.05")


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The drive recorded by the Python firmware, watched: it must be right."""
    log = tmp_path_factory.mktemp("resume") / "drive.log"
    correct_drive(log, *DRIVE)
    return log


def test_the_correct_firmware_replays_pass(drive: Path) -> None:
    done = cli("replay", str(drive))
    assert done.returncode == 0, done.stdout[-2500:]


def test_plus_10_mm_from_inside_the_silence_fails(drive: Path, tmp_path: Path) -> None:
    out = tmp_path / "raised.log"
    assert raise_x_10_mm(drive, out, 2.55) > 50
    done = cli("replay", str(out))
    assert done.returncode == 1, done.stdout[-2500:]
    assert "beyond any its firmware can resume at" in done.stdout, done.stdout[-2500:]


def test_plus_10_mm_from_after_the_stall_is_no_pass(drive: Path, tmp_path: Path) -> None:
    """A jump of the offset well after the stall: UNJUDGED after the stall (replay_lives: which
    frames the FIFO kept), exit 1, as before; never a PASS."""
    out = tmp_path / "raised.log"
    assert raise_x_10_mm(drive, out, 3.0) > 50
    done = cli("replay", str(out))
    assert done.returncode == 1, done.stdout[-2500:]
