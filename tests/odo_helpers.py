"""Shared helpers of the odometry tests: build a firmware odometry and its float twin."""

from __future__ import annotations

import math

import numpy as np

from odocan.firmware.config import Integrator, RobotParams, derive_constants, validate
from odocan.firmware.errors import ErrorMask
from odocan.firmware.odometry import Odometry
from odocan.host.judge.reference import Geometry

INTEGRATOR_NAMES = {"euler": Integrator.EULER, "rk2": Integrator.RK2, "exact": Integrator.EXACT}
# Seed 002's robot (pmir): 0.15 m wheels, 500 counts/rev, wheelbase 0.30 m.
PMIR = dict(
    counts_per_rev=500,
    wheel_radius_left_nm=75_000_000,
    wheel_radius_right_nm=75_000_000,
    wheelbase_nm=300_000_000,
    counter_bits=16,
)
TWO_POW_40 = float(1 << 40)


def params(integrator: str, **overrides: int) -> RobotParams:
    """RobotParams of the pmir robot with ``overrides``."""
    values = {**PMIR, **overrides}
    return RobotParams(integrator=int(INTEGRATOR_NAMES[integrator]), **values)


def firmware(p: RobotParams) -> tuple[Odometry, ErrorMask]:
    """A firmware odometry configured with ``p`` (which must be valid)."""
    assert validate(p) == 0
    errors = ErrorMask()
    return Odometry(derive_constants(p, errors), errors), errors


def geometry(p: RobotParams) -> Geometry:
    """The float parameters of the same robot."""
    return Geometry(
        counts_per_rev=p.counts_per_rev,
        wheel_radius_left_m=p.wheel_radius_left_nm * 1e-9,
        wheel_radius_right_m=p.wheel_radius_right_nm * 1e-9,
        wheelbase_m=p.wheelbase_nm * 1e-9,
    )


def pose_m(odo: Odometry) -> tuple[float, float, float]:
    """(x m, y m, heading rad in [-pi, pi)) of a firmware odometry."""
    heading = odo.heading_bam64 * (2.0 * math.pi / 2.0**64)
    return odo.x_q40_m / TWO_POW_40, odo.y_q40_m / TWO_POW_40, _wrap(heading)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def angle_error(a: float | np.ndarray, b: float | np.ndarray) -> float:
    """Largest |a - b| wrapped to [-pi, pi)."""
    d = (np.asarray(a) - np.asarray(b) + math.pi) % (2.0 * math.pi) - math.pi
    return float(np.max(np.abs(d)))


def smooth_random_counts(
    steps: int, dt_s: float, m_per_count: float, seed: int, max_speed_mps: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative count sequences (length steps + 1) of random smooth wheel speeds <= max_speed.

    Each wheel's rim speed is a sum of five random sinusoids (periods 2 s .. 120 s), scaled so its
    peak over the drive is max_speed; counts are floor(travel / m_per_count) of the exactly
    integrated travel.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(steps + 1) * dt_s
    counts = []
    for _wheel in range(2):
        periods = rng.uniform(2.0, 120.0, 5)
        phases = rng.uniform(0.0, 2 * math.pi, 5)
        amps = rng.uniform(0.2, 1.0, 5)
        omega = 2 * math.pi / periods
        speed = np.sum(amps[:, None] * np.sin(omega[:, None] * t + phases[:, None]), axis=0)
        scale = max_speed_mps / float(np.max(np.abs(speed)))  # the peak speed is max_speed
        # travel = integral of scale * sum(a sin(w t + p)) dt, in closed form
        travel = scale * np.sum(
            (amps / omega)[:, None]
            * (np.cos(phases)[:, None] - np.cos(omega[:, None] * t + phases[:, None])),
            axis=0,
        )
        counts.append(np.floor(travel / m_per_count).astype(np.int64))
    return counts[0], counts[1]
