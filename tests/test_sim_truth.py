"""Ground truth against closed forms (seed 000 eq. 22): straight line, circle, spin in place."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.sim.pose import Pose, wrap_angle
from odocan.sim.truth import GroundTruth, chord_factor

HZ = 1000


def constant_travel(n: int, v_left: float, v_right: float) -> np.ndarray:
    """Per-substep ground travel (m) of ``n`` substeps at constant wheel speeds (m/s)."""
    return np.tile([v_left / HZ, v_right / HZ], (n, 1))


def test_straight_line() -> None:
    truth = GroundTruth(0.3, HZ)
    truth.advance(constant_travel(5000, 0.4, 0.4))
    pose = truth.pose()
    assert pose.t_s == 5.0
    assert pose.x_m == pytest.approx(2.0, abs=1e-12)
    assert pose.y_m == 0.0
    assert pose.heading_rad == 0.0
    assert pose.distance_m == pytest.approx(2.0, abs=1e-12)


def test_backwards_counts_distance_as_positive() -> None:
    truth = GroundTruth(0.3, HZ)
    truth.advance(constant_travel(1000, -0.5, -0.5))
    assert truth.pose().x_m == pytest.approx(-0.5, abs=1e-13)
    assert truth.pose().distance_m == pytest.approx(0.5, abs=1e-13)


@settings(max_examples=40, deadline=None)
@given(
    v_left=st.floats(-1.0, 1.0),
    v_right=st.floats(-1.0, 1.0),
    wheelbase=st.floats(0.05, 1.0),
)
def test_constant_speeds_follow_the_closed_form_arc(
    v_left: float, v_right: float, wheelbase: float
) -> None:
    """Eq. 22: x = (v/w) sin(wt), y = (v/w)(1 - cos(wt)); exact arcs leave only rounding."""
    n = 2000
    truth = GroundTruth(wheelbase, HZ, trace_stride=1)
    truth.advance(constant_travel(n, v_left, v_right))
    tr = truth.trace()
    t = np.arange(n + 1) / HZ
    v, w = 0.5 * (v_left + v_right), (v_right - v_left) / wheelbase
    if abs(w) > 1e-9:
        x, y = v / w * np.sin(w * t), v / w * (1.0 - np.cos(w * t))
    else:
        x, y = v * t * np.cos(w * t), v * t * np.sin(w * t)
    np.testing.assert_allclose(tr.x_m, x, rtol=0, atol=1e-11)
    np.testing.assert_allclose(tr.y_m, y, rtol=0, atol=1e-11)
    expected_heading = np.array([wrap_angle(a) for a in w * t])
    dh = np.abs(np.angle(np.exp(1j * (tr.heading_rad - expected_heading))))
    assert dh.max() < 1e-11


def test_circle_of_known_radius_returns_to_start() -> None:
    """Radius R = (b/2)(vR+vL)/(vR-vL) (seed 001); one period 2*pi/omega brings it home."""
    b, v_left, v_right = 0.3, 0.35, 0.65  # R = 0.15 * 1.0 / 0.3 = 0.5 m, omega = 1 rad/s
    period_substeps = round(2 * math.pi * HZ)  # 6283 substeps = 6.283 s, 0.185 ms short
    truth = GroundTruth(b, HZ, trace_stride=1)
    truth.advance(constant_travel(period_substeps, v_left, v_right))
    tr = truth.trace()
    radius = 0.5
    # every sample lies on the circle centred at (0, R)
    np.testing.assert_allclose(np.hypot(tr.x_m, tr.y_m - radius), radius, rtol=0, atol=1e-12)
    short = 2 * math.pi - period_substeps / HZ  # time left to a full period
    pose = truth.pose()
    assert math.hypot(pose.x_m, pose.y_m) == pytest.approx(0.5 * short, rel=1e-6)
    assert pose.distance_m == pytest.approx(0.5 * period_substeps / HZ, abs=1e-12)


def test_spin_in_place() -> None:
    b, v = 0.23, 0.2
    truth = GroundTruth(b, HZ)
    truth.advance(constant_travel(3000, -v, v))
    pose = truth.pose()
    assert (pose.x_m, pose.y_m, pose.distance_m) == (0.0, 0.0, 0.0)
    assert pose.heading_rad == pytest.approx(wrap_angle(2 * v / b * 3.0), abs=1e-12)


def test_euler_integration_would_fail_the_arc_test() -> None:
    """The arc test is sharp: a heading-first Euler step (seed 000 eq. 15) is off by far more."""
    b, v_left, v_right = 0.3, 0.35, 0.65
    x = y = h = 0.0
    for _ in range(1000):
        h += (v_right - v_left) / b / HZ
        x += 0.5 * (v_left + v_right) / HZ * math.cos(h)
        y += 0.5 * (v_left + v_right) / HZ * math.sin(h)
    assert abs(x - 0.5 * math.sin(1.0)) > 1e-6 or abs(y - 0.5 * (1 - math.cos(1.0))) > 1e-6


def test_batching_is_bit_identical() -> None:
    rng = np.random.default_rng(7)
    ds = rng.uniform(-1e-3, 1e-3, size=(3000, 2))
    whole, parts = GroundTruth(0.3, HZ, trace_stride=10), GroundTruth(0.3, HZ, trace_stride=10)
    whole.advance(ds)
    for chunk in np.array_split(ds, [1, 17, 500, 501, 2999]):
        parts.advance(chunk)
    assert whole.pose() == parts.pose()
    for a, b in zip(vars(whole.trace()).values(), vars(parts.trace()).values(), strict=True):
        assert np.array_equal(a, b)


def test_trace_stride_and_times() -> None:
    truth = GroundTruth(0.3, HZ, trace_stride=10)
    truth.advance(constant_travel(25, 1.0, 1.0))
    truth.advance(constant_travel(20, 1.0, 1.0))
    tr = truth.trace()
    np.testing.assert_allclose(tr.t_s, [0.0, 0.01, 0.02, 0.03, 0.04])
    np.testing.assert_allclose(tr.x_m, tr.t_s, atol=1e-15)


def test_chord_factor_is_continuous_at_the_series_switch() -> None:
    angles = np.array([0.0, 1e-12, 1.999e-4, 2.001e-4, 0.1, -0.1, math.pi])
    expected = [1.0, 1.0] + [math.sin(a / 2) / (a / 2) for a in angles[2:]]
    np.testing.assert_allclose(chord_factor(angles), expected, rtol=1e-16, atol=0)


@pytest.mark.parametrize(
    ("angle", "wrapped"),
    [
        (0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi, math.pi), (-0.5, -0.5),
        # one ulp above pi: the angle just past -pi, never -pi itself (the old (pi - a) mod 2 pi
        # form rounded it to -pi, outside its own (-pi, pi])
        (math.nextafter(math.pi, 4.0), math.nextafter(math.pi, 4.0) - 2 * math.pi),
    ],
)
def test_wrap_angle_range(angle: float, wrapped: float) -> None:
    assert wrap_angle(angle) == pytest.approx(wrapped, abs=1e-15)
    assert -math.pi < wrap_angle(angle) <= math.pi


def test_the_truth_pose_carries_the_one_plain_pose() -> None:
    truth = GroundTruth(0.3, HZ)
    truth.advance(constant_travel(700, 0.2, 0.4))
    sample = truth.pose()
    assert sample.pose == Pose(sample.x_m, sample.y_m, sample.heading_rad)
    assert type(sample.pose) is Pose
    assert sample.pose.heading_rad == wrap_angle(truth.heading_unwrapped_rad)
