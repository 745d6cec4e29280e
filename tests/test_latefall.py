"""``host.judge.latefall``: which DISTANCE falls tie late to a looked-ahead boot summary.

Hand-worked from the rule's words (summary at 1.0 s, pose period 20 ms, second summary 200 ms
on), not from the module's constants."""

from __future__ import annotations

import numpy as np
import pytest

from odocan.host.judge.distfall import Falls
from odocan.host.judge.latefall import continues_twice, fell_late, tied_late

SUMMARY_S = 1.0


@pytest.mark.parametrize(("t_s", "counter", "before_s", "tied"), [
    (1.12, 6, 0.98, True),    # 6 twists lost: COUNTER 6, 120 ms on, the old life's before it
    (1.16, 8, 0.98, True),    # 8 lost
    (1.20, 10, 0.98, True),   # 10 lost: heard by the second summary
    (1.24, 12, 0.98, False),  # after the second summary: not read
    (1.12, 9, 0.98, False),   # COUNTER 9 needs 180 ms: sooner than one life counts
    (1.12, 6, 1.02, False),   # the twist before it is the new life's: another life's fall
    (0.99, 0, 0.97, False),   # before the summary (``tied_to_boot``'s, not this rule's)
])
def test_a_fall_ties_late_only_after_the_summary_by_the_second_one(
    t_s: float, counter: int, before_s: float, tied: bool
) -> None:
    assert tied_late(t_s, counter, before_s, SUMMARY_S) is tied


def test_a_late_fall_is_read_by_the_second_summary_only() -> None:
    falls = Falls(np.array([1.12]), np.array([6]), np.array([0.98]))
    assert fell_late(falls, SUMMARY_S, 1.2)
    assert not fell_late(falls, SUMMARY_S, 1.1)  # not heard yet by then
    assert not fell_late(Falls(np.array([0.5]), np.array([6]), np.array([0.4])), SUMMARY_S, 1.2)


@pytest.mark.parametrize(("t_s", "uptime_s", "counter", "ok"), [
    (1.2, 0, 4, True), (1.2, 0, 2, False), (1.2, 1, 4, False), (1.2, 0, 0, False),
    (1.31, 0, 4, False),
])
def test_the_second_summary_continues_the_boot_summarys_sequence(
    t_s: float, uptime_s: int, counter: int, ok: bool
) -> None:
    assert continues_twice(SUMMARY_S, t_s, uptime_s, counter) is ok
