"""The live E2E check's scalar period count against the log check's numpy one (the reference)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from odocan.host.protocol.e2e import period_count, periods_between

GAPS_S = st.floats(min_value=-1.0, max_value=1e6, allow_nan=False)
CYCLES_S = st.sampled_from([0.01, 0.02, 0.1, 1.0, 0.03])


@given(GAPS_S, CYCLES_S, st.sampled_from([0, 1]))
def test_period_count_is_periods_between_of_one_gap(
    dt_s: float, cycle_s: float, least: int
) -> None:
    assert period_count(dt_s, cycle_s, least) == int(
        periods_between(np.array([dt_s]), cycle_s, least)[0])


@given(st.integers(min_value=0, max_value=10**6), CYCLES_S)
def test_ties_round_to_even_as_numpy_does(half_periods: int, cycle_s: float) -> None:
    dt_s = (half_periods + 0.5) * cycle_s
    assert period_count(dt_s, cycle_s) == int(periods_between(np.array([dt_s]), cycle_s)[0])


def test_a_message_without_a_cycle_and_a_gap_that_is_no_number_count_one_period() -> None:
    assert period_count(5.0, None) == 1
    assert period_count(math.nan, 0.01) == 1
    assert period_count(math.inf, 0.01) == 1
    assert period_count(0.0, 0.01) == 1
    assert period_count(0.05, 0.01) == 5


def test_with_no_minimum_a_frame_within_half_a_period_closes_none() -> None:
    """WHEEL_ENCODERS, as the firmware's window, which widens once per tick: a second frame sent
    with a genuine one (a babbler's, a forger's) cannot widen it (tests/test_forged_pairing.py)."""
    assert period_count(0.0, 0.01, 0) == 0
    assert period_count(0.004, 0.01, 0) == 0
    assert period_count(0.006, 0.01, 0) == 1
    assert period_count(-0.001, 0.01, 0) == 0  # a timestamp out of order closes none either
    dt_s = np.array([0.0, 0.004, 0.006, -0.001, 0.05])
    assert periods_between(dt_s, 0.01, 0).tolist() == [0, 0, 1, 0, 5]
