"""``host.judge.lapfirst``'s choice of a first pose's lap, value by value: the older lap only
when all four values of the tick fit it and not the newest (a wrong pose matching an older lap
in part is not excused)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from odocan.host.io.logs import read_log
from odocan.host.judge.lapfirst import Said, lagged, lap_candidates, older_lap
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import load
from tests.log_edit import raise_raw_once

FILES = Path(__file__).resolve().parent / "files"

NEWEST = Said(0.1833, 0.0081, 0.1251, 0.183)
OLDER = Said(0.1032, 0.0013, 0.0472, 0.103)


def test_the_older_lap_when_every_value_fits_it() -> None:
    said = Said(0.1032 + POSITION_LSB_M, 0.0013, 0.0472 + HEADING_LSB_RAD, 0.104)
    assert older_lap(said, [NEWEST, OLDER]) == 1


def test_the_plain_name_when_one_value_does_not_fit() -> None:
    for said in (OLDER._replace(x_m=0.1032 + 3 * POSITION_LSB_M),
                 OLDER._replace(y_m=0.0013 - 3 * POSITION_LSB_M),
                 OLDER._replace(heading_rad=0.0472 + 3 * HEADING_LSB_RAD),
                 OLDER._replace(distance_m=0.183)):
        assert older_lap(said, [NEWEST, OLDER]) is None, said


def test_the_newest_when_it_fits_too_and_none_when_two_older_do() -> None:
    assert older_lap(OLDER, [OLDER, OLDER]) is None  # standing still: the newest
    assert older_lap(OLDER, [NEWEST, OLDER, OLDER]) is None  # which older one: untold
    assert older_lap(NEWEST, [NEWEST, OLDER]) is None


def test_the_candidates_go_back_by_laps_to_the_life_s_first_frame() -> None:
    seq = np.array([3, 4, 5, 19, 20, 21, 35, 36, 37], dtype=np.int64)
    assert lap_candidates(seq, 8) == [8, 5, 2]  # seq 37, 21, 5
    assert lap_candidates(seq, 6) == [6, 3, 0]  # seq 35, 19, 3 (the life's first)
    assert lap_candidates(seq[1:], 5) == [5, 2]  # seq 35, 19 (3: before the life's first)
    assert lap_candidates(seq, 0) == [0]


def test_the_stream_reads_whole_a_life_whose_first_pose_may_lag(tmp_path: Path) -> None:
    """``lagged``: the streamed judge's gate (``stream_first``): the capture's first pose fits
    frame 53 by heading and DISTANCE (the streamed judge reads it whole, ``lapfirst.REFUSAL``);
    the other capture's, and the capture's with its first HEADING 3 LSBs off, do not."""
    assert _lagged(FILES / "restart_lagged_first_pose.blf")
    assert not _lagged(FILES / "restart_live_two_lsb.blf")
    tampered = tmp_path / "tampered.blf"
    raise_raw_once(FILES / "restart_lagged_first_pose.blf", tampered, "ODOM_POSE_X", (6, 2), 3,
                   0.0)
    assert not _lagged(tampered)


def _lagged(path: Path) -> bool:
    frames = read_log(path)
    db = default_plan()
    _, accepted = check_frames(frames, db)
    return lagged(frames, accepted, BulkDecoder(db), load("pmir"))
