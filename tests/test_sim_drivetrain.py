"""Motors (first-order response, acceleration limit, command timeout) and encoders."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.firmware.fixmath import wrap_i16
from odocan.sim.drivetrain import (
    Drivetrain,
    MotorConfig,
    angle_travelled,
    encoder_count,
    evolve,
    wrap_counter,
)
from odocan.sim.robot import RobotProfile, load

TAU = 0.05
ACCEL = 2.0
HZ = 1000


def nominal_drivetrain(profile: RobotProfile, quadrature: bool = False) -> Drivetrain:
    """A drivetrain whose actual radii are the nominal ones."""
    radii = (profile.wheel_radius_left_m, profile.wheel_radius_right_m)
    return Drivetrain(profile, radii, HZ, quadrature)


def rk4_reference(w0: float, wsp: float, alpha: float, t: float) -> tuple[float, float]:
    """Independent numerical solution of dw/dt = clip((wsp-w)/tau, +-alpha), angle alongside."""
    n = 20_000
    h = t / n

    def f(w: float) -> float:
        return max(-alpha, min(alpha, (wsp - w) / TAU))

    w, theta = w0, 0.0
    for _ in range(n):
        k1 = f(w)
        k2 = f(w + 0.5 * h * k1)
        k3 = f(w + 0.5 * h * k2)
        k4 = f(w + h * k3)
        theta += h * (w + h * (k1 + k2 + k3) / 6.0)  # RK4 for theta' = w
        w += h * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
    return w, theta


@settings(max_examples=15, deadline=None)
@given(
    w0=st.floats(-30.0, 30.0),
    wsp=st.floats(-30.0, 30.0),
    alpha=st.floats(5.0, 100.0),
    t=st.floats(0.0, 0.6),
)
def test_closed_form_matches_numerical_integration(
    w0: float, wsp: float, alpha: float, t: float
) -> None:
    w, theta = evolve(w0, wsp, alpha, TAU, t)
    w_ref, theta_ref = rk4_reference(w0, wsp, alpha, t)
    assert w == pytest.approx(w_ref, abs=1e-6)
    assert theta == pytest.approx(theta_ref, abs=1e-6)
    vector = angle_travelled(np.array([t]), np.array([w0]), np.array([wsp]), alpha, TAU)
    assert vector[0] == pytest.approx(theta, abs=1e-12)


def test_step_response_is_the_exponential_when_the_limit_is_inactive() -> None:
    """Steps of 0.05 and 0.08 m/s are below accel*tau = 0.1 m/s: pure first order."""
    profile = load("pmir")
    drive = nominal_drivetrain(profile)
    r = profile.wheel_radius_left_m
    drive.command(0.05, 0.08)
    for k in range(1, 50):
        t = k / 100
        drive.advance(k * 10)
        decay = math.exp(-t / TAU)
        v_left, v_right = drive.wheel_speeds_mps()
        assert v_left == pytest.approx(0.05 * (1 - decay), abs=1e-14)
        assert v_right == pytest.approx(0.08 * (1 - decay), abs=1e-14)
        assert drive.angle[0] == pytest.approx(0.05 / r * (t - TAU * (1 - decay)), abs=1e-13)


def test_acceleration_limit_ramps_then_approaches_exponentially() -> None:
    """A 1 m/s step: ramp at 2 m/s^2 until 0.1 m/s short (t1 = 0.45 s), then exponential (a
    kobuki whose controller saturates at 4 m/s: the real one's 0.7 would clamp the step)."""
    drive = nominal_drivetrain(dataclasses.replace(load("kobuki"), max_wheel_speed_m_s=4.0))
    t1 = (1.0 - ACCEL * TAU) / ACCEL
    previous = 0.0
    for k in range(1, 80):
        if k % 10 == 1:
            drive.command(1.0, -1.0)  # re-commanded each 0.1 s, as a controller would
        drive.advance(k * 10)
        t = k / 100
        ramp, tail = ACCEL * t, 1.0 - ACCEL * TAU * math.exp(-(t - t1) / TAU)
        expected = ramp if t <= t1 else tail
        v_left, v_right = drive.wheel_speeds_mps()
        assert v_left == pytest.approx(expected, abs=1e-12)
        assert v_right == pytest.approx(-expected, abs=1e-12)
        assert v_left - previous <= ACCEL * 0.01 + 1e-12  # never faster than the limit
        previous = v_left


def test_splitting_a_segment_does_not_change_the_motion() -> None:
    profile = load("pmir")
    whole, split = nominal_drivetrain(profile), nominal_drivetrain(profile)
    whole.command(0.7, 0.2)
    split.command(0.7, 0.2)
    whole.advance(400)
    for n in (1, 2, 37, 200, 399, 400):
        split.advance(n)
    assert whole.omega == pytest.approx(split.omega, abs=1e-12)
    assert whole.angle == pytest.approx(split.angle, abs=1e-12)
    travel_whole, travel_split = whole.take_travel(), split.take_travel()
    assert travel_whole.shape == travel_split.shape == (400, 2)
    np.testing.assert_allclose(travel_whole, travel_split, rtol=0, atol=1e-15)
    np.testing.assert_allclose(
        travel_whole.sum(axis=0), np.array(whole.angle) * 0.075, rtol=0, atol=1e-13
    )


def test_command_timeout_stops_the_motors() -> None:
    """No command for 0.5 s: setpoint 0 from that instant, then the same dynamics down to 0."""
    profile = load("pmir")
    drive = nominal_drivetrain(profile)
    alpha = ACCEL / profile.wheel_radius_left_m
    drive.command(0.3, 0.3)
    drive.advance(500)
    assert drive.setpoint == [0.0, 0.0]
    w_timeout = drive.omega[0]
    assert w_timeout == pytest.approx(evolve(0.0, 0.3 / 0.075, alpha, TAU, 0.5)[0], abs=1e-12)
    for k in (510, 600, 900):
        drive.advance(k)
        expected = evolve(w_timeout, 0.0, alpha, TAU, (k - 500) / HZ)[0]
        assert drive.omega[0] == pytest.approx(expected, abs=1e-12)
    assert drive.wheel_speeds_mps()[0] < 1e-3  # stopped


def test_a_fresh_command_restarts_the_timeout() -> None:
    drive = nominal_drivetrain(load("pmir"))
    drive.command(0.3, 0.3)
    drive.advance(400)
    drive.command(0.3, 0.3)
    drive.advance(899)
    assert drive.setpoint == [0.3 / 0.075, 0.3 / 0.075]
    drive.advance(900)
    assert drive.setpoint == [0.0, 0.0]


def test_motor_config_validation() -> None:
    with pytest.raises(ValueError, match="time_constant_s must be positive"):
        MotorConfig(time_constant_s=0.0)
    with pytest.raises(ValueError, match="accel_limit_mps2"):
        MotorConfig(accel_limit_mps2=math.inf)


def test_encoder_count_at_known_angles() -> None:
    step = 2 * math.pi / 500
    assert encoder_count(0.0, 500) == 0
    assert encoder_count(3.5 * step, 500) == 3
    assert encoder_count(-0.5 * step, 500) == -1
    assert encoder_count(2 * math.pi * 7 + 0.5 * step, 500) == 3500
    assert encoder_count(3.3 * step, 500, quadrature=True) == 13


@settings(max_examples=200)
@given(angle=st.floats(-1e5, 1e5))
def test_quadrature_is_four_times_finer(angle: float) -> None:
    x1, x4 = encoder_count(angle, 2578), encoder_count(angle, 2578, quadrature=True)
    assert x4 // 4 == x1


def test_counts_follow_the_closed_form_wheel_angle() -> None:
    profile = load("pmir")
    drive = nominal_drivetrain(profile)
    drive.command(0.05, -0.05)
    for k in range(1, 50):
        drive.advance(k * 10)
        t = k / 100
        angle = 0.05 / 0.075 * (t - TAU * (1 - math.exp(-t / TAU)))
        left = math.floor(angle / (2 * math.pi) * 500)
        right = math.floor(-angle / (2 * math.pi) * 500)
        assert drive.encoder_counts() == (left % 65536, right % 65536)


def test_wrap_counter() -> None:
    assert wrap_counter(65535, 16) == 65535
    assert wrap_counter(65536, 16) == 0
    assert wrap_counter(-1, 16) == 65535
    assert wrap_counter(2**32 + 5, 32) == 5
    assert wrap_counter(-2, 32) == 2**32 - 2


def test_16_bit_counters_wrap_and_deltas_recover_the_motion() -> None:
    """Kobuki at 1 m/s: ~11.7k counts/s wraps 16 bits every ~5.6 s; wrap_i16 deltas undo it."""
    profile = load("kobuki")
    drive = nominal_drivetrain(profile)
    previous = drive.encoder_counts()
    unwrapped = [0, 0]
    for k in range(1, 1201):
        if k % 10 == 1:
            drive.command(1.0, -1.0)
        drive.advance(k * 10)
        now = drive.encoder_counts()
        for j in (0, 1):
            unwrapped[j] += wrap_i16(now[j] - previous[j])
        previous = now
    exact = [encoder_count(a, 2578) for a in drive.angle]
    assert exact[0] > 65536
    assert exact[1] < -65536  # really wrapped
    assert unwrapped == exact
    assert drive.encoder_counts() == (exact[0] % 65536, exact[1] % 65536)


def test_32_bit_counters_wrap() -> None:
    """A tiny wheel with 2**24 x4 counts/rev passes 2**32 counts in well under a second."""
    profile = RobotProfile("tiny", 2**24, 0.001, 0.001, 0.1, 32)
    drive = nominal_drivetrain(profile, quadrature=True)
    for k in range(10):
        drive.command(1.0, -1.0)
        drive.advance((k + 1) * 100)
    exact = [encoder_count(a, 2**24, quadrature=True) for a in drive.angle]
    assert exact[0] > 2**32
    assert exact[1] < -(2**32)
    assert drive.encoder_counts() == (exact[0] % 2**32, exact[1] % 2**32)


_SPEED = st.sampled_from([0.0, -0.0, 1e-300]) | st.floats(-20.0, 20.0)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.tuples(st.integers(1, 12), _SPEED, _SPEED, _SPEED, _SPEED), min_size=1,
             max_size=12),
    st.booleans(),
)
def test_the_unlimited_fast_path_is_angle_travelled_bit_for_bit(
    raw: list[tuple[int, float, float, float, float]], equal: bool
) -> None:
    """``Drivetrain._unlimited_angles`` against ``angle_travelled`` (via ``_angles``) on batches
    no wheel of which is rate-limited: equal segments (the broadcast) and unequal ones (the
    repeat), signed zeros included."""
    drive = nominal_drivetrain(load("pmir"))
    limit = drive._alpha_l * drive.config.time_constant_s * 0.999  # pmir: equal wheels
    segments = [
        (raw[0][0] if equal else n, w0l, w0l + (spl - w0l) % limit, w0r, w0r + (spr - w0r) % limit)
        for n, w0l, spl, w0r, spr in raw
    ]
    segments = [s for s in segments if abs(s[1] - s[2]) <= limit and abs(s[3] - s[4]) <= limit]
    if not segments:
        return
    assert drive._all_unlimited(segments)
    fast = drive._unlimited_angles(segments)
    assert fast.tobytes() == drive._angles(segments).tobytes()


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-3.0, 3.0),
    st.floats(-3.0, 3.0),
    st.floats(-0.2, 0.2),
    st.floats(-0.2, 0.2),
    st.integers(1, 40),
)
def test_a_segment_is_evolve_s_closed_form_bit_for_bit(
    w0l: float, w0r: float, left_mps: float, right_mps: float, n: int
) -> None:
    """``_run_segment`` (its unlimited fast path included) against ``evolve`` per wheel."""
    profile = load("pmir")
    drivetrain = Drivetrain(profile, (0.03, 0.031))
    drivetrain.omega = [w0l, w0r]
    drivetrain.command(left_mps, right_mps)
    spl, spr = drivetrain.setpoint
    tau = drivetrain.config.time_constant_s
    t = n / drivetrain.substep_hz
    want_l = evolve(w0l, spl, drivetrain._alpha_l, tau, t)
    want_r = evolve(w0r, spr, drivetrain._alpha_r, tau, t)
    drivetrain._run_segment(n)
    assert drivetrain.omega == [want_l[0], want_r[0]]
    assert drivetrain.angle == [want_l[1], want_r[1]]
    # and the signs of zeros too (a wheel at rest commanded to rest)
    assert [math.copysign(1.0, a) for a in drivetrain.angle] == [
        math.copysign(1.0, want_l[1]), math.copysign(1.0, want_r[1])
    ]


# Angles anywhere, and at count edges (c counts of 4096 x1 or x4 a turn, and the doubles either
# side): where the floor turns on the last bit of the quotient.
_EDGE = st.builds(lambda c, k, side: math.nextafter(c * (2.0 * math.pi) / (4096 * k), side),
                  st.integers(-(2**30), 2**30), st.sampled_from([1, 4]),
                  st.sampled_from([-math.inf, 0.0, math.inf]))
_ANGLE = (st.floats(-1e7, 1e7) | _EDGE
          | st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e18, math.inf]))


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(_ANGLE, _ANGLE), max_size=20),
    st.booleans(),
    st.sampled_from([16, 32]),
    st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1)),
)
def test_counts_at_many_angles_are_encoder_counts_at_each(
    angles: list[tuple[float, float]], quadrature: bool, bits: int, offset: tuple[int, int]
) -> None:
    """``encoder_counts_at`` (a block's counts at once, in numpy) gives, angle for angle, what
    ``encoder_counts`` gives with the wheels there: the independent formula, floor(angle /
    2 pi * cpr * k) plus the offset, wrapped (beyond int64 or not finite: per angle, as it)."""
    profile = RobotProfile("p", 4096, 0.05, 0.05, 0.3, bits)
    radii = (profile.wheel_radius_left_m, profile.wheel_radius_right_m)
    drive = Drivetrain(profile, radii, HZ, quadrature, counter_offset=offset)
    k = 4 if quadrature else 1
    finite = [a for a in angles if math.isfinite(a[0]) and math.isfinite(a[1])]
    expected = [
        tuple((o + math.floor(x / (2.0 * math.pi) * 4096 * k)) % 2**bits
              for x, o in zip(a, offset, strict=True))
        for a in finite
    ]
    assert drive.encoder_counts_at([list(a) for a in finite]) == expected
    if len(finite) < len(angles):  # a NaN or an infinity: as encoder_counts, it raises
        with pytest.raises((OverflowError, ValueError)):
            drive.encoder_counts_at([list(a) for a in angles])
