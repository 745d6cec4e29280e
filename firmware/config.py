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
# The fastest rim speed either wheel can reach (u16 mm/s, ODOM_CONFIG MAX_WHEEL_SPEED): an encoder
# step beyond it is implausible. A robot that states none is bounded at the default.
MAX_WHEEL_SPEED_DEFAULT_MM_S = 4_000
MAX_WHEEL_SPEED_MIN_MM_S = 1
MAX_WHEEL_SPEED_MAX_MM_S = 65_535  # the signal's u16
# One encoder count may turn the robot by at most 1/16 turn: beyond that the parameters are absurd.
BAM64_PER_COUNT_MAX = 1 << 60
ENCODER_PERIOD_US = 10_000  # WHEEL_ENCODERS GenMsgCycleTime (twist.py re-exports it)
WIRE_COUNTER_BITS = 24  # WHEEL_ENCODERS carries the low 24 bits of each counter (encoders.py)
# A step of this many periods (one late sample) at the maximum wheel speed must read unwrapped.
READABLE_PERIODS = 2


def unused_wire_bits(counter_bits: int) -> int:
    """The wire's count bits above the counters' width (u32; 0 for counters of 24 bits or
    more): (2^24 - 1) less (2^bits - 1). Configuration time (encoders.py)."""
    if counter_bits >= WIRE_COUNTER_BITS:
        return 0
    return ((1 << WIRE_COUNTER_BITS) - 1) ^ ((1 << counter_bits) - 1)


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
    WIRE_RANGE = 7  # a step at the maximum wheel speed could wrap the counters as read
    MAX_WHEEL_SPEED_OUT_OF_RANGE = 8  # outside MAX_WHEEL_SPEED_MIN_MM_S .. _MAX_MM_S


@dataclass(frozen=True, slots=True)
class RobotParams:
    """Robot parameters as raw integers (u32 each), exactly as ``ODOM_CONFIG`` carries them;
    ``max_wheel_speed_mm_s`` (u16 on the wire) bounds a plausible encoder step."""

    counts_per_rev: int
    wheel_radius_left_nm: int
    wheel_radius_right_nm: int
    wheelbase_nm: int
    counter_bits: int
    integrator: int
    max_wheel_speed_mm_s: int = MAX_WHEEL_SPEED_DEFAULT_MM_S


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
    if not MAX_WHEEL_SPEED_MIN_MM_S <= params.max_wheel_speed_mm_s <= MAX_WHEEL_SPEED_MAX_MM_S:
        return ConfigReason.MAX_WHEEL_SPEED_OUT_OF_RANGE
    scratch = ErrorMask()
    for radius_nm in (params.wheel_radius_left_nm, params.wheel_radius_right_nm):
        if _bam64_per_count(radius_nm, params, scratch) >= BAM64_PER_COUNT_MAX:
            return ConfigReason.GEOMETRY_ABSURD
    return ConfigReason.OK


def validate_at_speed(params: RobotParams, max_wheel_speed_mm_s: int) -> ConfigReason:
    """``validate``, then the counters' readable range at ``max_wheel_speed_mm_s`` (the ECU's
    plausibility bound, u16 mm/s): ``WIRE_RANGE`` when a step of ``READABLE_PERIODS`` periods
    at that speed could move a wheel half the range its counters are read with (the hardware
    width, at most the wire's 24 bits) or more. Such a step is read wrapped (``wrap_signed``),
    as a smaller or backward one that the plausibility bound cannot tell from a true step: the
    pose would go wrong silently, so the configuration is refused (e.g. 2^24 counts per 35 mm
    of wheel circumference: one period reads wrapped above 1.75 m/s, two above 0.87 m/s)."""
    reason = validate(params)
    if reason is not ConfigReason.OK:
        return reason
    half_range = 1 << (min(params.counter_bits, WIRE_COUNTER_BITS) - 1)
    scratch = ErrorMask()
    for radius_nm in (params.wheel_radius_left_nm, params.wheel_radius_right_nm):
        per_count_q48_m = _m_per_count_q48(radius_nm, params, scratch)
        most = max_counts_per_period(per_count_q48_m, max_wheel_speed_mm_s, scratch)
        if READABLE_PERIODS * most >= half_range:
            return ConfigReason.WIRE_RANGE
    return ConfigReason.OK


def max_counts_per_period(
    per_count_q48_m: int, max_wheel_speed_mm_s: int, errors: ErrorMask
) -> int:
    """The most counts one encoder period can hold at ``max_wheel_speed_mm_s``: ceil(v_max * T /
    travel per count) + 1 (a count edge may fall either side of a sample), as
    ``EncoderInput.step_bounds``. Configuration time: a 128-bit muldiv (travel < 2^44), then u64
    division (``per_count_q48_m`` >= 1 for valid parameters)."""
    travel_q48_m = muldiv_round_u64(
        max_wheel_speed_mm_s * ENCODER_PERIOD_US, 1 << 48, NM_PER_M, errors
    )
    return (travel_q48_m + per_count_q48_m - 1) // per_count_q48_m + 1


CRC32_POLY_REFLECTED = 0xEDB88320  # CRC-32/ISO-HDLC (zlib's), bit-reversed 0x04C11DB7
U32_ALL_ONES = 0xFFFFFFFF


def profile_bytes(params: RobotParams) -> bytes:
    """The 20-byte parameter set ODOM_STATUS PROFILE_CRC covers (the DBC comment): each field
    little-endian in ODOM_CONFIG PARAM order, COUNTS_PER_REV u32, WHEEL_RADIUS_LEFT u32 nm,
    WHEEL_RADIUS_RIGHT u32 nm, WHEELBASE u32 nm, COUNTER_BITS u8, INTEGRATOR u8, MAX_WHEEL_SPEED
    u16 mm/s (C: a uint8_t[20] filled byte by byte, so the MCU's own byte order does not matter).
    Each value keeps its field's width, as the configuration stores it."""
    fields = (
        (params.counts_per_rev, 4),
        (params.wheel_radius_left_nm, 4),
        (params.wheel_radius_right_nm, 4),
        (params.wheelbase_nm, 4),
        (params.counter_bits, 1),
        (params.integrator, 1),
        (params.max_wheel_speed_mm_s, 2),
    )
    out = bytearray()
    for value, size in fields:
        for k in range(size):
            out.append((value >> (8 * k)) & 0xFF)
    return bytes(out)


def profile_crc32(params: RobotParams) -> int:
    """u32: CRC-32/ISO-HDLC of ``profile_bytes(params)``, bit by bit (configuration time only:
    160 shift-and-xor steps, no table in flash). C: ``crc ^= byte; for 8 bits: crc = (crc >> 1)
    ^ (crc & 1u ? 0xEDB88320u : 0u);`` from ``crc = 0xFFFFFFFFu``, then ``crc ^ 0xFFFFFFFFu``."""
    crc = U32_ALL_ONES
    for byte in profile_bytes(params):
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (CRC32_POLY_REFLECTED if crc & 1 else 0)
    return crc ^ U32_ALL_ONES


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
