"""A rebooted firmware that primed on a frame held back on the bus, judged live (issue #11: a
FAIL must never blame a correct firmware).

kobuki random 696, 10 s, ``reboot=0.2:0.2,delay=0.1:150``: the new firmware's first tick at
0.40 s found the WHEEL_ENCODERS frame of COUNTER 9 held back 150 ms from 0.25 s ahead of the
on-time COUNTER 8 in its mailbox; its fresh E2E check primed on the held-back one (its
power-up pose, COUNTER 0, names ENC_COUNTER 9 at 0.401 s), took the held-back COUNTER 10, then
the on-time COUNTER 11: a step of (66, -37) counts within its speed bound. Later held-back
frames it refused as implausible (DEGRADED, IMPLAUSIBLE_STEP). ``run`` and ``analyze`` (which
check each life's E2E afresh) PASSed; the monitor and the bridge reported POSE WRONG 46.97 mm,
65 mrad beyond from 1.541 s, when the wait for the boot's count page ran out and the life
started on the summary's frame of 0.55 s. Three rules the live judges lacked:

* the power-up pose's refused frame is retaken although the host's sequence took an older
  frame after it (``liveboottick.BootTick.taken``);
* a hold's verdicts after such a retake are judged again from it (``livesettle``);
* the pose halves' late scans start afresh at that pose (``livelatehalves.LateHalves.restart``):
  the new life's COUNTERs, behind the old life's, read 80 ms late, and the X halves paired with
  the Y halves 16 frames before theirs (1.58 mm beyond with the first two rules alone).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.judges_cli import both_analyses, correct_drive, live_judges, raise_x_10_mm

DRIVE = ("kobuki", "random", 696, 10, "reboot=0.2:0.2,delay=0.1:150")
TAMPER_FROM_S = 3.0


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The drive, its firmware watched within 1/1000 LSB (``correct_drive``)."""
    return correct_drive(tmp_path_factory.mktemp("m696") / "drive.log", *DRIVE)


def test_run_and_both_analyses_pass(log: Path) -> None:
    assert both_analyses(log) == [0, 0]


def test_the_live_judges_pass_the_correct_firmware(log: Path) -> None:
    """The monitor and the bridge: no POSE WRONG, within the 0.1 mm tolerance (46.97 mm
    beyond before)."""
    for judge in live_judges("kobuki", log):
        tracker = judge.tracker
        tracker.wrongs.finish(tracker.allowance_m)
        assert tracker.wrongs.count == 0, tracker.wrongs.as_dict()
        assert tracker.max_beyond_allowance_m <= 1e-4, tracker.max_beyond_allowance_m


def test_x_10_mm_off_from_3_s_fails_live(log: Path, tmp_path: Path) -> None:
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, TAMPER_FROM_S) > 100
    beyond_m = [j.tracker.max_beyond_allowance_m for j in live_judges("kobuki", tampered)]
    assert min(beyond_m) > 5e-3, beyond_m
