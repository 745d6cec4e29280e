"""One wrong sample in a new start's hold does not make the later right samples wrong (issue
#11; ``host.judge.livefit``, ``host.judge.livenewstart``).

The straight 32-bit drive of ``tests/test_live_unseen_restart.py`` with the firmware's X 3 LSB
off at one pose (frame 420), 20 frames into the new start after the unseen controller restart
(frame 400), as ``tests/test_bridge_held_batch.py`` drives it. That sample leaves no overlap of
the start fit's rounding intervals, and the fit froze there, 10 samples in: the reference kept
that short lever arm's rotation, 0.82 LSB off the independent odometry 100 frames on, and the
correct samples there (frames 520-534) were latched as a second episode of 0.127 mm: a FAIL
that blamed correct samples. Now the sample is refused and the fit goes on with the later ones.

Right or wrong by this file's own float64 odometry (``tests.independent_checker`` through
``test_live_unseen_restart._fine_path``), not by the judges under test.
"""

from __future__ import annotations

import math
from pathlib import Path

from odocan.host.judge.samples import POSITION_LSB_M
from tests.test_live_unseen_restart import DRIVES, Live, _fine_path, _live, _log, _own_errors

DRIVE = DRIVES["straight32"]
WRONG_FRAME = 420  # inside the new start's hold (the restart: 400)


def _onboard_lsb(live: Live) -> dict[int, float]:
    """Each sampled frame after the restart: the on-board position's distance from the
    independent odometry (LSB)."""
    fine = _fine_path(DRIVE)
    out = {}
    for sample in live.samples:
        k = live.frames[sample.pose.seq]
        if k >= DRIVE.restart:
            fx, fy, _ = fine[k]
            out[k] = math.hypot(sample.pose.x_m - fx, sample.pose.y_m - fy) / POSITION_LSB_M
    return out


def _latched_frames(live: Live) -> list[tuple[int, int]]:
    """The monitor's episodes (all samples judged): (first frame, samples)."""
    wrongs = live.monitor.tracker.wrongs
    wrongs.finish(live.monitor.tracker.allowance_m)
    return [(live.frames[e.enc_seq], e.samples) for e in wrongs.latest]


def test_one_wrong_sample_in_the_hold_is_the_only_one_blamed(tmp_path: Path) -> None:
    live = _live(_log(tmp_path, DRIVE, "x_bias_100um", {WRONG_FRAME: 3}), DRIVE)
    assert live.monitor.tracker.newstart.holds_made == 1  # the premise: the new start's hold
    onboard = _onboard_lsb(live)
    assert onboard[WRONG_FRAME] > 2.0  # wrong by the independent odometry
    # every other within the rounding of X and Y (half an LSB each: 0.71 LSB apart at most)
    assert max(v for k, v in onboard.items() if k != WRONG_FRAME) <= 0.72
    assert _latched_frames(live) == [(WRONG_FRAME, 1)]  # and (520, 8) before
    published = {live.frames[p["enc_seq"]] for leaf, p in live.publications
                 if leaf == "error" and p["pose_wrong"]}
    assert published <= {WRONG_FRAME}  # the bridge's samples: none after it wrong either
    # the reference itself stays near the independent odometry (0.82 LSB at 515-535 before)
    assert max(max(e) for e in _own_errors(live, DRIVE, range(421, 535))) <= 0.5


def test_a_lasting_offset_from_there_is_still_latched(tmp_path: Path) -> None:
    """The guard: the refused samples are not taken in, so a firmware that stays 3 LSB off
    from that frame on is wrong at every sample (passes before the change too)."""
    bias = dict.fromkeys(range(WRONG_FRAME, DRIVE.until), 3)
    live = _live(_log(tmp_path, DRIVE, "x_bias_100um", bias), DRIVE)
    onboard = _onboard_lsb(live)
    wrong = sorted(k for k, v in onboard.items() if WRONG_FRAME <= k < DRIVE.until)
    assert min(onboard[k] for k in wrong) > 2.0
    latched = _latched_frames(live)
    assert latched[0][0] == WRONG_FRAME
    assert sum(n for _, n in latched) >= len(wrong)
