"""The float64 reference odometry: the firmware's three integrators, in plain floating point.

Independent of the firmware's arithmetic (``math``/numpy sin and cos, float robot parameters), it
answers "what should the on-board pose be for these encoder counts". Two APIs compute the same
thing: ``ReferenceOdometry`` steps one count pair at a time (live monitoring), ``integrate`` does a
whole array of count deltas at once with numpy (logs of millions of frames).

The heading is the exact linear function of the cumulative counts,
phi_k = phi_0 + k_R N_R - k_L N_L with k = 2 pi r / (PPV b) (seed 000 eq. 6 summed); the cumulative
counts are exact integers, so the reference heading carries no accumulated rounding. Per step:

* ``euler`` (seed 000 eq. 15): x += dS cos(phi_k)
* ``rk2`` (seed 004): x += dS cos((phi_{k-1} + phi_k) / 2)
* ``exact`` (seeds 003/004): x += dS sinc(dtheta/2) cos((phi_{k-1} + phi_k) / 2), the ICC rotation
  written as a chord (identical to R (sin phi_k - sin phi_{k-1}), R = dS/dtheta, without the
  0/0 at dtheta = 0: the straight case is sinc(0) = 1 and the spin case is dS = 0).

``ReferenceOdometry``, ``chord_factor`` and ``INTEGRATORS`` live in ``host.judge.refodometry``
(no numpy there: compiled by mypyc under ``ODOCAN_ACCEL=1``, the live judges' per-frame step) and
are re-exported here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Literal, TypeVar

import numpy as np
import numpy.typing as npt

from odocan.firmware.config import MAX_WHEEL_SPEED_DEFAULT_MM_S
from odocan.host.judge.refodometry import INTEGRATORS as INTEGRATORS  # re-exported
from odocan.host.judge.refodometry import ReferenceOdometry as ReferenceOdometry
from odocan.host.judge.refodometry import chord_factor as chord_factor
from odocan.host.protocol.busfacts import ENC_PERIOD_US as ENCODER_PERIOD_US
from odocan.sim.robot import RobotProfile

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
D = TypeVar("D", int, IntArray)
# A judge's plausibility bound on an encoder step: the robot profile's maximum wheel speed
# (PROFILE_SPEED), another one in mm/s (tests), or None: the steps are not bounded.
SpeedBound = int | None | Literal["profile"]
PROFILE_SPEED: Final = "profile"


@dataclass(frozen=True)
class Geometry:
    """Robot parameters in SI units (float64); ``max_wheel_speed_mm_s``: the firmware's
    plausibility bound on a wheel's rim speed, as the profile gives it (u16 mm/s)."""

    counts_per_rev: int
    wheel_radius_left_m: float
    wheel_radius_right_m: float
    wheelbase_m: float
    max_wheel_speed_mm_s: int = MAX_WHEEL_SPEED_DEFAULT_MM_S

    @classmethod
    def of(cls, robot: RobotProfile) -> Geometry:
        """The float parameters of a robot profile."""
        return cls(robot.counts_per_rev, robot.wheel_radius_left_m,
                   robot.wheel_radius_right_m, robot.wheelbase_m, robot.max_wheel_speed_mm_s)

    def speed_bound_mm_s(self, bound: SpeedBound) -> int | None:
        """``bound`` resolved: this robot's maximum wheel speed for ``PROFILE_SPEED``."""
        return self.max_wheel_speed_mm_s if isinstance(bound, str) else bound

    def period_counts(self, speed_mm_s: float) -> tuple[int, int]:
        """The most counts (left, right) a wheel moves in one encoder period at ``speed_mm_s``,
        one count of margin: the per-period step bound the firmware's plausibility rule uses."""
        travel_m = speed_mm_s * 1e-3 * ENCODER_PERIOD_US * 1e-6
        return (math.ceil(travel_m / self.m_per_count_left) + 1,
                math.ceil(travel_m / self.m_per_count_right) + 1)

    @property
    def m_per_count_left(self) -> float:
        """Left wheel travel per count (seed 002 eq. 5)."""
        return 2.0 * math.pi * self.wheel_radius_left_m / self.counts_per_rev

    @property
    def m_per_count_right(self) -> float:
        """Right wheel travel per count (seed 002 eq. 5)."""
        return 2.0 * math.pi * self.wheel_radius_right_m / self.counts_per_rev


@dataclass(frozen=True)
class PoseArrays:
    """Poses after each step (float64 arrays of equal length)."""

    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray  # unwrapped
    distance_m: FloatArray


def integrate(
    d_left: npt.ArrayLike,
    d_right: npt.ArrayLike,
    geometry: Geometry,
    integrator: str,
    *,
    x0_m: float = 0.0,
    y0_m: float = 0.0,
    heading0_rad: float = 0.0,
) -> PoseArrays:
    """Vectorised ``ReferenceOdometry``: the poses after each of a sequence of count deltas."""
    if integrator not in INTEGRATORS:
        raise ValueError(f"unknown integrator {integrator!r} (known: {', '.join(INTEGRATORS)})")
    dl = np.asarray(d_left, dtype=np.int64)
    dr = np.asarray(d_right, dtype=np.int64)
    g = geometry
    ds_left = dl * g.m_per_count_left
    ds = 0.5 * (ds_left + dr * g.m_per_count_right)
    cum_left = np.cumsum(dl)
    cum_right = np.cumsum(dr)
    heading = (
        heading0_rad
        + (g.m_per_count_right / g.wheelbase_m) * cum_right
        - (g.m_per_count_left / g.wheelbase_m) * cum_left
    )
    heading_old = np.concatenate(([heading0_rad], heading[:-1]))
    if integrator == "euler":
        direction = heading
    else:
        direction = 0.5 * (heading_old + heading)
        if integrator == "exact":
            ds = ds * np.sinc((heading - heading_old) / (2.0 * math.pi))
    x = x0_m + np.cumsum(ds * np.cos(direction))
    y = y0_m + np.cumsum(ds * np.sin(direction))
    distance = np.cumsum(np.abs(0.5 * (ds_left + dr * g.m_per_count_right)))
    return PoseArrays(x_m=x, y_m=y, heading_rad=heading, distance_m=distance)


def deltas_from_counts(counts: npt.ArrayLike, counter_bits: int) -> IntArray:
    """Wrap-safe per-step deltas of a raw wrapping counter sequence (length n -> n - 1)."""
    c = np.asarray(counts, dtype=np.int64)
    return wrap_delta(np.diff(c), counter_bits)


def wrap_delta(delta: D, bits: int) -> D:
    """A counter difference (int or int64 array) read back as the signed delta of a ``bits``-wide
    wrapping counter: exact while the true delta is below half the range."""
    half = 1 << (bits - 1)
    return ((delta + half) % (1 << bits)) - half
