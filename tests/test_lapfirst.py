"""``host.judge.lapfirst``'s choice of a first pose's lap, value by value: the older lap only
when all four values of the tick fit it and not the newest (a wrong pose matching an older lap
in part is not excused)."""

from __future__ import annotations

import numpy as np

from odocan.host.judge.lapfirst import Said, lap_candidates, older_lap
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

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
