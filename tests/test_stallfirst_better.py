"""``stallfirst.better``: which candidate frame a stall's first pose names, weighed in LSBs.

The (position m, heading rad) excesses of two candidates were compared as metres against
radians * 1000, so the heading counted about 1000x the position: a frame fitting 0.005 mm and
0.019 mrad beyond won less than a frame 17.8 mm beyond with a heading 1 mrad inside (the figures
of pmir figure8 seed 82, ``delay=0.3:55,busoff=1:1``, seen by the lone halves' candidates). The
judges weigh a pose's error in the wire's LSBs (POSITION_LSB_M, HEADING_LSB_RAD), so must this.
"""

from __future__ import annotations

import pytest

from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.stallfirst import FirstVerdict, better, decided

FITS = (0.005e-3, 0.019e-3)  # (m, rad) beyond the tolerance: a hair
OFF = (17.8e-3, -1e-3)  # 17.8 mm beyond, its heading 1 mrad inside


@pytest.mark.parametrize("order", ["fits_first", "off_first"])
def test_the_fitting_frame_wins(order: str) -> None:
    a, b = (FITS, OFF) if order == "fits_first" else (OFF, FITS)
    assert better(a, b) == FITS


def test_one_lsb_of_either_weighs_the_same() -> None:
    pos = (2.0 * POSITION_LSB_M, 0.0)
    head = (0.0, 3.0 * HEADING_LSB_RAD)
    assert better(pos, head) == pos
    assert better(head, pos) == pos
    assert better(None, pos) == pos
    assert better(pos, None) == pos


def test_the_reported_figures_are_the_fitting_frames() -> None:
    verdict = FirstVerdict()
    verdict.judge(3.0, decided(OFF, FITS))
    got = verdict.as_dict()
    assert got["max_position_beyond_m"] == pytest.approx(FITS[0])
    assert not got["passed"]  # beyond by a hair is still beyond


def test_a_frame_within_wins_whatever_the_weights() -> None:
    inside = (-0.5e-3, -0.001e-3)
    assert better(OFF, inside) == inside
    assert better(FITS, inside) == inside
