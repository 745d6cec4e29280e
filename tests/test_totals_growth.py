"""``losses.totals_growth``: LOST_FRAMES' growth between ENC_E2E pages, worked out by hand.

Found from a wheel: a merged log of two robots cut before its first ENC_E2E page (the two
sources' cut, ``posestreams``) reached it with no page at power-up and raised IndexError out of
``odocan analyze`` (a traceback, not a verdict)."""

from __future__ import annotations

import numpy as np

from odocan.host.judge.losses import totals_growth


def test_no_page_has_no_growth_at_power_up_or_after() -> None:
    at, total = np.array([5, 9]), np.array([3, 7], dtype=np.int64)
    for power_up in (True, False):
        assert totals_growth(at, total, np.array([], dtype=np.int64), power_up).tolist() == []


def test_growth_from_the_totals_before_the_first_page_to_the_one_after_the_second() -> None:
    at, total = np.array([5, 9, 20]), np.array([3, 7, 65535], dtype=np.int64)
    pages = np.array([6, 12, 21])
    # (6, 12): from total 3 (at 5) to 65535 (at 20); (12, 21): from 7 (at 9) to the last, 65535
    assert totals_growth(at, total, pages, False).tolist() == [65532, 65528]
    # at power-up: 0 lost before the first page, to the totals after it (7 at 9)
    assert totals_growth(at, total, pages, True).tolist() == [7, 65532, 65528]


def test_no_totals_before_a_page_counts_no_growth() -> None:
    at, total = np.array([10]), np.array([4], dtype=np.int64)
    assert totals_growth(at, total, np.array([2, 5]), False).tolist() == [0]
