"""``livepose.StepGate`` reads its count steps with ``wrap_delta``'s arithmetic in line (``&``
for ``%``, per frame): the same delta for every width and every pair of raw counts, the step
it returns included."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.judge.livepose import RestartLog, StepGate
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.sim import robot

counts = st.integers(0, (1 << 24) - 1)


@settings(max_examples=3000, deadline=None)
@given(st.integers(2, 24), counts, counts, counts, counts)
def test_delta_in_line_is_wrap_delta(bits: int, a_left: int, a_right: int, b_left: int,
                                     b_right: int) -> None:
    mask = (1 << bits) - 1
    a, b = (0, a_left & mask, a_right & mask), (1, b_left & mask, b_right & mask)
    gate = StepGate(Geometry.of(robot.load("pmir")), bits, RestartLog(lambda _s, _u: None))
    assert gate._delta(a, b) == (wrap_delta(b[1] - a[1], bits), wrap_delta(b[2] - a[2], bits))


@settings(max_examples=500, deadline=None)
@given(st.sampled_from([16, 24]), counts, counts, st.integers(-40, 40), st.integers(-40, 40))
def test_step_returns_wrap_delta(bits: int, left: int, right: int, d_left: int,
                                 d_right: int) -> None:
    mask = (1 << bits) - 1
    gate = StepGate(Geometry.of(robot.load("pmir")), bits, RestartLog(lambda _s, _u: None))
    first = (0, 0, left & mask, right & mask, 1, 0, 0.0)
    second = (1, 1, (left + d_left) & mask, (right + d_right) & mask, 1, 0, 0.01)
    assert gate.step(first) is None  # primes
    assert gate.step(second) == (d_left, d_right)  # across the wrap too
