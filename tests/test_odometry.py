"""The firmware's integer odometry against closed forms and the float64 reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.firmware.config import (
    ConfigReason,
    Integrator,
    RobotParams,
    derive_constants,
    validate,
)
from odocan.firmware.errors import ErrorFlag, ErrorMask
from odocan.firmware.odometry import chord_factor_q62
from odocan.host.judge.reference import (
    ReferenceOdometry,
    chord_factor,
    deltas_from_counts,
    integrate,
)
from tests.odo_helpers import (
    angle_error,
    firmware,
    geometry,
    params,
    pose_m,
    smooth_random_counts,
)

INTEGRATORS = ("euler", "rk2", "exact")


# --- configuration -------------------------------------------------------------------------------


def test_constants_match_the_float_formulas() -> None:
    p = params("exact", wheel_radius_right_nm=75_150_000, counts_per_rev=2578)
    c = derive_constants(p, ErrorMask())
    g = geometry(p)
    assert c.m_per_count_left_q48_m / 2.0**48 == pytest.approx(g.m_per_count_left, rel=1e-14)
    assert c.m_per_count_right_q48_m / 2.0**48 == pytest.approx(g.m_per_count_right, rel=1e-14)
    turns_right = g.m_per_count_right / g.wheelbase_m / (2 * math.pi)
    assert c.bam64_per_count_right / 2.0**64 == pytest.approx(turns_right, rel=1e-14)
    assert c.integrator is Integrator.EXACT


@pytest.mark.parametrize(
    ("field", "value", "reason"),
    [
        ("counts_per_rev", 0, ConfigReason.COUNTS_PER_REV_OUT_OF_RANGE),
        ("counts_per_rev", (1 << 24) + 1, ConfigReason.COUNTS_PER_REV_OUT_OF_RANGE),
        ("wheel_radius_left_nm", 0, ConfigReason.WHEEL_RADIUS_OUT_OF_RANGE),
        ("wheel_radius_right_nm", 2_000_000_001, ConfigReason.WHEEL_RADIUS_OUT_OF_RANGE),
        ("wheelbase_nm", 9_999_999, ConfigReason.WHEELBASE_OUT_OF_RANGE),
        ("wheelbase_nm", 4_000_000_001, ConfigReason.WHEELBASE_OUT_OF_RANGE),
        ("counter_bits", 24, ConfigReason.COUNTER_BITS_INVALID),
        ("integrator", 3, ConfigReason.INTEGRATOR_INVALID),
    ],
)
def test_validate_names_the_bad_parameter(field: str, value: int, reason: ConfigReason) -> None:
    good = params("euler")
    assert validate(good) is ConfigReason.OK
    bad = RobotParams(**{**{f: getattr(good, f) for f in good.__dataclass_fields__}, field: value})
    assert validate(bad) is reason


def test_validate_refuses_a_geometry_where_one_count_turns_the_robot_a_lot() -> None:
    # 2 m wheels, 1 count per revolution, 1 cm wheelbase: one count is 200 turns.
    p = params("euler", counts_per_rev=1, wheel_radius_left_nm=2_000_000_000, wheelbase_nm=10**7)
    assert validate(p) is ConfigReason.GEOMETRY_ABSURD


# --- closed forms --------------------------------------------------------------------------------


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_straight_line(integrator: str) -> None:
    p = params(integrator)
    odo, errors = firmware(p)
    for _ in range(1000):
        odo.step_deltas(7, 7)
    x, y, heading = pose_m(odo)
    assert x == pytest.approx(7000 * geometry(p).m_per_count_left, abs=1e-9)
    assert (y, heading) == (0.0, 0.0)
    assert errors.bits == 0


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_spin_in_place(integrator: str) -> None:
    p = params(integrator)
    odo, _ = firmware(p)
    for _ in range(333):
        odo.step_deltas(-5, 5)
    g = geometry(p)
    expected_heading = 333 * 10 * g.m_per_count_left / g.wheelbase_m
    x, y, heading = pose_m(odo)
    assert (x, y) == (0.0, 0.0)
    assert angle_error(heading, expected_heading) < 1e-12
    assert odo.distance_q40_m == 0


def _arc_closed_form(p: RobotParams, d_left: int, d_right: int, steps: int) -> tuple[float, ...]:
    g = geometry(p)
    ds_l, ds_r = d_left * g.m_per_count_left, d_right * g.m_per_count_right
    dtheta = (ds_r - ds_l) / g.wheelbase_m
    radius = 0.5 * g.wheelbase_m * (ds_r + ds_l) / (ds_r - ds_l)
    theta = steps * dtheta
    return radius * math.sin(theta), radius * (1 - math.cos(theta)), theta, radius, dtheta


def test_exact_follows_the_closed_form_circle() -> None:
    p = params("exact")
    odo, _ = firmware(p)
    for _ in range(5123):  # 10.2 turns: not a whole number, so the end is away from the start
        odo.step_deltas(8, 12)
    x, y, theta, _radius, _ = _arc_closed_form(p, 8, 12, 5123)
    fx, fy, fh = pose_m(odo)
    assert math.hypot(fx - x, fy - y) < 1e-8
    assert angle_error(fh, theta) < 1e-12


@pytest.mark.parametrize("integrator", ["euler", "rk2"])
def test_euler_and_rk2_on_a_circle_match_their_own_closed_forms(integrator: str) -> None:
    """On a constant arc each step's chord is exact up to a known length and direction error.

    RK2 moves along the exact chord direction with the arc length ds instead of the chord
    c = ds sinc(dtheta/2), so its pose is the exact one scaled by ds/c about the start; Euler
    is additionally turned by dtheta/2. Both are closed forms of the step, checked to 1e-8 m.
    """
    p = params(integrator)
    odo, _ = firmware(p)
    steps = 1234  # 2.47 turns
    for _ in range(steps):
        odo.step_deltas(8, 12)
    x, y, _theta, _radius, dtheta = _arc_closed_form(p, 8, 12, steps)
    scale = 1.0 / chord_factor(dtheta)
    turn = dtheta / 2 if integrator == "euler" else 0.0
    ex = scale * (x * math.cos(turn) - y * math.sin(turn))
    ey = scale * (x * math.sin(turn) + y * math.cos(turn))
    fx, fy, _ = pose_m(odo)
    assert math.hypot(fx - ex, fy - ey) < 1e-8
    assert math.hypot(fx - x, fy - y) > 1e-6, "the integrator's own error must show at this step"


def test_one_big_step_of_the_exact_integrator() -> None:
    # Wheel separation 1 m, dS_L = 1 m, dS_R = 2 m in one step: 1 count = 1 mm.
    radius_nm = round(1000 / (2 * math.pi) * 1e6)
    p = params(
        "exact",
        counts_per_rev=1000,
        wheel_radius_left_nm=radius_nm,
        wheel_radius_right_nm=radius_nm,
        wheelbase_nm=10**9,
    )
    odo, _ = firmware(p)
    odo.step_deltas(1000, 2000)
    x, y, heading = pose_m(odo)
    assert x == pytest.approx(1.5 * math.sin(1), abs=2e-8)
    assert y == pytest.approx(1.5 * (1 - math.cos(1)), abs=2e-8)
    assert heading == pytest.approx(1.0, abs=1e-8)


def test_chord_factor_against_float() -> None:
    """Every branch (straight, short series, long series) within 2^-42 of float64 sin(u)/u."""
    angles = [0.0, 1e-9, 4e-7, 1e-6, -1e-3, 0.05, -0.2, 0.249, 0.251, 0.3, -1.0, 2.0, 3.0, 3.14159]
    angles += np.random.default_rng(1).uniform(-math.pi, math.pi, 2000).tolist()
    for dtheta in angles:
        bam = round(dtheta / (2 * math.pi) * 2.0**64)
        exact_dtheta = bam * (2 * math.pi / 2.0**64)
        got = chord_factor_q62(bam) / 2.0**62
        assert abs(got - chord_factor(exact_dtheta)) < 2**-42, dtheta


# --- convergence, wrap, saturation ---------------------------------------------------------------


def _drive(integrator: str, substeps: int) -> tuple[float, float, float]:
    """A fixed smooth path (high-resolution encoders), sampled at 1/substeps of 0.1 s."""
    p = params(integrator, counts_per_rev=1 << 22)
    g = geometry(p)
    odo, _ = firmware(p)
    n = 40 * substeps
    t = np.arange(n + 1) * (4.0 / n)
    left = np.floor((0.3 * t + 0.1 * np.sin(t)) / g.m_per_count_left).astype(np.int64)
    right = np.floor((0.5 * t - 0.2 * np.sin(0.7 * t)) / g.m_per_count_right).astype(np.int64)
    for dl, dr in zip(np.diff(left).tolist(), np.diff(right).tolist(), strict=True):
        odo.step_deltas(dl, dr)
    return pose_m(odo)


def test_integrators_converge_to_each_other_as_the_step_shrinks() -> None:
    gaps = {}
    for substeps in (1, 2, 4, 8):
        exact = _drive("exact", substeps)
        gaps[substeps] = {
            name: math.hypot(
                *(a - b for a, b in zip(_drive(name, substeps)[:2], exact[:2], strict=True))
            )
            for name in ("euler", "rk2")
        }
    for coarse, fine in ((1, 2), (2, 4), (4, 8)):
        assert 1.7 < gaps[coarse]["euler"] / gaps[fine]["euler"] < 2.3  # first order
        assert 3.4 < gaps[coarse]["rk2"] / gaps[fine]["rk2"] < 4.6  # second order


@pytest.mark.parametrize("bits", [16, 32])
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_wrapping_counters_give_the_true_deltas(bits: int, data: st.DataObject) -> None:
    half = 1 << (bits - 1)
    start_l = data.draw(st.integers(0, (1 << bits) - 1))
    start_r = data.draw(st.integers(0, (1 << bits) - 1))
    deltas = data.draw(
        st.lists(
            st.tuples(st.integers(-half + 1, half - 1), st.integers(-half + 1, half - 1)),
            min_size=1,
            max_size=20,
        )
    )
    p = params("rk2", counter_bits=bits)
    wrapped, _ = firmware(p)
    direct, _ = firmware(p)
    wrapped.step_counts(start_l, start_r)
    cl, cr = start_l, start_r
    for dl, dr in deltas:
        cl, cr = cl + dl, cr + dr
        assert wrapped.step_counts(cl % (1 << bits), cr % (1 << bits))
        direct.step_deltas(dl, dr)
    assert (wrapped.x_q40_m, wrapped.y_q40_m, wrapped.heading_bam64) == (
        direct.x_q40_m,
        direct.y_q40_m,
        direct.heading_bam64,
    )


def test_a_16_bit_counter_wrapping_mid_drive_loses_nothing() -> None:
    p = params("euler")
    odo, _ = firmware(p)
    odo.step_counts(65_530, 65_530)
    odo.step_counts(4, 4)  # +10 counts across the wrap
    assert pose_m(odo)[0] == pytest.approx(10 * geometry(p).m_per_count_left, abs=1e-12)


def test_absurd_deltas_saturate_and_flag_instead_of_raising() -> None:
    # Valid but coarse: 1.26 m per count, so 2^31 counts in one step leave every i64.
    p = params(
        "exact",
        counter_bits=32,
        counts_per_rev=1,
        wheel_radius_left_nm=200_000_000,
        wheel_radius_right_nm=200_000_000,
        wheelbase_nm=4_000_000_000,
    )
    odo, errors = firmware(p)
    for _ in range(3):
        odo.step_deltas(2**31 - 1, 2**31 - 1)
    assert errors.has(ErrorFlag.SATURATION)
    assert -(2**63) <= odo.x_q40_m < 2**63


# --- fidelity: one hour against the float64 reference --------------------------------------------


@pytest.fixture(scope="module")
def one_hour_counts() -> tuple[np.ndarray, np.ndarray]:
    p = params("euler")
    return smooth_random_counts(360_000, 0.01, geometry(p).m_per_count_left, seed=2)


@pytest.mark.slow
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_one_hour_fidelity_against_float64(
    integrator: str, one_hour_counts: tuple[np.ndarray, np.ndarray]
) -> None:
    """360 000 steps at 100 Hz, speeds up to 1 m/s: position <= 10 um, heading <= 1e-7 rad."""
    left, right = one_hour_counts
    p = params(integrator)
    odo, errors = firmware(p)
    xs, ys, hs = [], [], []
    step = odo.step_counts
    for cl, cr in zip((left & 0xFFFF).tolist(), (right & 0xFFFF).tolist(), strict=True):
        if step(cl, cr):
            xs.append(odo.x_q40_m)
            ys.append(odo.y_q40_m)
            hs.append(odo.heading_bam64)
    ref = integrate(
        deltas_from_counts(left, 16), deltas_from_counts(right, 16), geometry(p), integrator
    )
    fx = np.array(xs, dtype=np.float64) / 2.0**40
    fy = np.array(ys, dtype=np.float64) / 2.0**40
    fh = np.array([h * (2 * math.pi / 2.0**64) for h in hs])
    position_error = float(np.max(np.hypot(fx - ref.x_m, fy - ref.y_m)))
    heading_error = angle_error(fh, ref.heading_rad)
    assert ref.distance_m[-1] > 500.0, "the drive must be long enough to mean something"
    assert position_error <= 10e-6, position_error
    assert heading_error <= 1e-7, heading_error
    assert errors.bits == 0
    print(
        f"{integrator}: max position error {position_error:.3e} m, heading {heading_error:.3e} rad"
    )


# --- the reference's two APIs agree ---------------------------------------------------------------


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_reference_scalar_and_vectorised_agree(integrator: str) -> None:
    p = params(integrator)
    g = geometry(p)
    left, right = smooth_random_counts(3000, 0.01, g.m_per_count_left, seed=7)
    scalar = ReferenceOdometry(g, integrator, 32)
    xs = []
    for cl, cr in zip(left.tolist(), right.tolist(), strict=True):
        if scalar.step_counts(cl, cr):
            xs.append((scalar.x_m, scalar.y_m, scalar.heading_rad))
    vec = integrate(np.diff(left), np.diff(right), g, integrator)
    got = np.array(xs)
    assert np.max(np.abs(got[:, 0] - vec.x_m)) < 1e-12
    assert np.max(np.abs(got[:, 1] - vec.y_m)) < 1e-12
    assert np.max(np.abs(got[:, 2] - vec.heading_rad)) < 1e-12
