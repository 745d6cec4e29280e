"""Robot parameters as the firmware receives them, their validation, and the derived Q constants.

The firmware never sees a float. Parameters arrive as integers, either as build-time ``#define``s
written by the host-side generator (``sim.robot.RobotProfile.firmware_params``) or over the bus in
``ODOM_CONFIG``. They become fixed-point constants once, at configuration, here:

* ``m_per_count_<wheel>_q48_m``: wheel travel per encoder count, Q48 metres (i64), from seed 002
  eq. 5, S = 2*pi*R*C/PPV. Relative error <= 2^-37 on the pmir robot.
* ``bam64_per_count_<wheel>``: heading change per count of that wheel, in BAM64 (a full turn is
  2^64), from seed 000 eq. 6, theta = (dS_R - dS_L)/wheelbase. Per count: 2*pi*R/(PPV*b) rad =
  R/(PPV*b) turns, so the constant is round(2^64 * R / (PPV * b)): pi cancels, and the heading is
  an exact integer sum of these constants (mod 2^64), with no per-step rounding at all.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from odocan.firmware.errors import ErrorMask
from odocan.firmware.fixmath import muldiv_round_u64

# 2*pi in Q60 (i64), correctly rounded: round(2*pi * 2^60).
TWO_PI_Q60 = 7244019458077122842
NM_PER_M = 1_000_000_000

COUNTS_PER_REV_MIN = 1
COUNTS_PER_REV_MAX = 1 << 24
WHEEL_RADIUS_MIN_NM = 1_000_000  # 1 mm
WHEEL_RADIUS_MAX_NM = 2_000_000_000  # 2 m
WHEELBASE_MIN_NM = 10_000_000  # 10 mm
WHEELBASE_MAX_NM = 4_000_000_000  # 4 m (u32 holds 4.29 m)
COUNTER_BITS_ALLOWED = (16, 32)
# One encoder count may turn the robot by at most 1/16 turn: beyond that the parameters are absurd.
BAM64_PER_COUNT_MAX = 1 << 60


class Integrator(IntEnum):
    """Odometry integrator (the ``INTEGRATOR`` signal)."""

    EULER = 0  # seed 000 eq. 15: heading first, then x += dS cos(phi_new)
    RK2 = 1  # seed 004: midpoint heading
    EXACT = 2  # seeds 003/004: the arc about the ICC, with the straight and spin cases


class ConfigReason(IntEnum):
    """Why a configuration was accepted or refused (the ack/nack reason code)."""

    OK = 0
    COUNTS_PER_REV_OUT_OF_RANGE = 1
    WHEEL_RADIUS_OUT_OF_RANGE = 2
    WHEELBASE_OUT_OF_RANGE = 3
    COUNTER_BITS_INVALID = 4
    INTEGRATOR_INVALID = 5
    GEOMETRY_ABSURD = 6  # one count would turn the robot by more than 1/16 turn


@dataclass(frozen=True, slots=True)
class RobotParams:
    """Robot parameters as raw integers (u32 each), exactly as ``ODOM_CONFIG`` carries them."""

    counts_per_rev: int
    wheel_radius_left_nm: int
    wheel_radius_right_nm: int
    wheelbase_nm: int
    counter_bits: int
    integrator: int


@dataclass(frozen=True, slots=True)
class OdomConstants:
    """Fixed-point constants derived once from ``RobotParams`` (see the module docstring)."""

    m_per_count_left_q48_m: int  # i64
    m_per_count_right_q48_m: int  # i64
    bam64_per_count_left: int  # u64, < 2^60
    bam64_per_count_right: int  # u64, < 2^60
    counter_bits: int  # 16 or 32
    integrator: Integrator


def validate(params: RobotParams) -> ConfigReason:
    """Check every parameter's range; ``ConfigReason.OK`` when the whole set is usable."""
    if not COUNTS_PER_REV_MIN <= params.counts_per_rev <= COUNTS_PER_REV_MAX:
        return ConfigReason.COUNTS_PER_REV_OUT_OF_RANGE
    for radius_nm in (params.wheel_radius_left_nm, params.wheel_radius_right_nm):
        if not WHEEL_RADIUS_MIN_NM <= radius_nm <= WHEEL_RADIUS_MAX_NM:
            return ConfigReason.WHEEL_RADIUS_OUT_OF_RANGE
    if not WHEELBASE_MIN_NM <= params.wheelbase_nm <= WHEELBASE_MAX_NM:
        return ConfigReason.WHEELBASE_OUT_OF_RANGE
    if params.counter_bits not in COUNTER_BITS_ALLOWED:
        return ConfigReason.COUNTER_BITS_INVALID
    if params.integrator not in (0, 1, 2):
        return ConfigReason.INTEGRATOR_INVALID
    scratch = ErrorMask()
    for radius_nm in (params.wheel_radius_left_nm, params.wheel_radius_right_nm):
        if _bam64_per_count(radius_nm, params, scratch) >= BAM64_PER_COUNT_MAX:
            return ConfigReason.GEOMETRY_ABSURD
    return ConfigReason.OK


def derive_constants(params: RobotParams, errors: ErrorMask) -> OdomConstants:
    """Q constants of a validated ``params`` (call ``validate`` first: ranges keep every width)."""
    return OdomConstants(
        m_per_count_left_q48_m=_m_per_count_q48(params.wheel_radius_left_nm, params, errors),
        m_per_count_right_q48_m=_m_per_count_q48(params.wheel_radius_right_nm, params, errors),
        bam64_per_count_left=_bam64_per_count(params.wheel_radius_left_nm, params, errors),
        bam64_per_count_right=_bam64_per_count(params.wheel_radius_right_nm, params, errors),
        counter_bits=params.counter_bits,
        integrator=Integrator(params.integrator),
    )


def _m_per_count_q48(radius_nm: int, params: RobotParams, errors: ErrorMask) -> int:
    """round(2*pi*R / PPV) in Q48 metres: circumference first (Q48, < 2^52), then per count."""
    circumference_q48_m = muldiv_round_u64(TWO_PI_Q60, radius_nm, NM_PER_M << 12, errors)
    return muldiv_round_u64(circumference_q48_m, 1, params.counts_per_rev, errors)


def _bam64_per_count(radius_nm: int, params: RobotParams, errors: ErrorMask) -> int:
    """round(2^64 * R / (PPV * b)) as ``muldiv(R << 32, 2^32, PPV * b)``: every operand fits u64."""
    return muldiv_round_u64(
        radius_nm << 32, 1 << 32, params.counts_per_rev * params.wheelbase_nm, errors
    )
