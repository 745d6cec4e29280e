"""Integer-only dead reckoning of a differential-drive robot from raw wheel encoder counters.

State (C widths):

* ``x_q40_m``, ``y_q40_m``: i64, Q40 metres (LSB 9.1e-13 m, range +-8388 km). Q40 rather than Q32:
  a constant-speed straight drive rounds each step's increment the same way, and 360 000 such
  roundings at Q32 would add up to 42 um; at Q40 they stay below 0.2 um.
* ``heading_bam64``: u64 binary angle, a full turn is 2^64. It is the exact integer sum of
  per-count constants (``firmware.config``), so wrap-around is free and no step rounds it.
* ``distance_q40_m``: u64, distance travelled (sum of |dS|), Q40 metres.

Per step, with dS_L, dS_R the wheel travels (Q48 m, exact products of counts and constants):

* dS = (dS_R + dS_L) / 2 (seed 000 eq. 1), held as the sum in Q48, i.e. dS in Q49 with no rounding;
* dtheta = k_R dR - k_L dL in BAM64 (seed 000 eq. 6), exact mod 2^64;
* ``EULER`` (seed 000 eq. 15): phi = phi + dtheta first, then x += dS cos(phi), y += dS sin(phi);
* ``RK2`` (seed 004): x += dS cos(phi + dtheta/2), y likewise, then phi += dtheta;
* ``EXACT`` (seeds 003/004, the ICC update): rotating the robot about the ICC by dtheta moves it
  along the chord, x += R (sin phi_new - sin phi) = 2R sin(dtheta/2) cos(phi + dtheta/2), with
  R = dS/dtheta; i.e. the RK2 step scaled by the chord factor sin(u)/u, u = dtheta/2. This form
  has no division by dtheta and no cancellation, so it keeps full precision at every step size.
  Seed 004's special cases become thresholds: *straight* (dS_R ~ dS_L) when |u| < 2^-21 rad, where
  the factor differs from 1 by less than 2^-44 and is taken as exactly 1; *spin in place*
  (dS_R ~ -dS_L) when |dS| < 2^-41 m, where the increment is below half an LSB of x and the
  position is left unchanged.

A step turning more than half a turn (a late sample on a narrow robot: 1 cm wheelbase at 4 m/s
turns 8 rad a period) is integrated whole, never along its wrapped angle: the exact difference
k_R dR - k_L dL is 97 bits wide, its low word the signed BAM64 dtheta_w (in [-pi, pi)) and its
high word the whole turns beyond it, dtheta = dtheta_w + 2 pi n. The heading and ``heading_turns``
take all of it; RK2's midpoint phi + dtheta/2 moves by n pi; EXACT's chord is sin(u)/u cos(phi +
u) with u = dtheta/2 = u_w + n pi, i.e. sinc(u_w) (dtheta_w / dtheta) cos(phi + u_w): the wrapped
chord scaled by the ratio of the two angles (``div_q62_i128``), so a step of whole turns does not
move the robot. EULER (phi_new) is exact mod 2 pi already.
"""

from __future__ import annotations

from odocan.firmware.config import TWO_PI_Q60, Integrator, OdomConstants
from odocan.firmware.errors import ErrorFlag, ErrorMask
from odocan.firmware.fixmath import (
    I64_MAX,
    I64_MIN,
    U32_MAX,
    U64_MAX,
    div_q62_i128,
    mul_add_hi_i64,
    mul_round_i64,
    mul_sat_i64,
    mul_shr_i64,
    mul_sub_wrap_i64,
    sat_i64,
    wrap_i32,
)
from odocan.firmware.trig import sincos_q30

ONE_Q62 = 1 << 62
ONE_Q60 = 1 << 60
HALF_TURN_BAM64 = 1 << 63  # pi
STRAIGHT_LIMIT_Q60 = 1 << 39  # |u| < 2^-21 rad: the factor is 1 to within 2^-44 (straight case)
SERIES_SHORT_LIMIT_Q60 = 1 << 57  # |u| <= 1/8 rad: three series terms suffice
# (2k)(2k+1): the Horner denominators of sin(u)/u = 1 - u^2/(2*3) (1 - u^2/(4*5) (...)).
SINC_DENOMINATORS = (6, 20, 42, 72, 110, 156, 210, 272)
_SINC_HORNER_SHORT = SINC_DENOMINATORS[2::-1]  # Horner's order (innermost first): three terms
_SINC_HORNER_LONG = SINC_DENOMINATORS[::-1]  # all eight
# Each series as (innermost denominator, the outer ones): no tuple sliced per step.
_SINC_SHORT_INNER, _SINC_LONG_INNER = _SINC_HORNER_SHORT[0], _SINC_HORNER_LONG[0]
_SINC_SHORT_OUTER: tuple[int, ...] = _SINC_HORNER_SHORT[1:]
_SINC_LONG_OUTER: tuple[int, ...] = _SINC_HORNER_LONG[1:]
SPIN_LIMIT_Q49 = 1 << 8  # |dS| < 2^-41 m: below half an LSB of x (spin-in-place case)
Q49_TO_Q40_SHIFT = 9
DS_COS_TO_Q40_SHIFT = 39  # Q49 * Q30 = Q79 -> Q40
_EULER = Integrator.EULER  # the enumerators as module constants (a 3.11 enum attribute
_EXACT = Integrator.EXACT  # read costs ~0.14 us, a global ~0.01 us)


class Odometry:
    """The dead-reckoning state and its step. Runs in the periodic tick: no allocation per step."""

    __slots__ = (
        "_consts",
        "_count_half",
        "_delta_fits",
        "_errors",
        "_left_prev",
        "_primed",
        "_right_prev",
        "distance_q40_m",
        "heading_bam64",
        "heading_turns",
        "last_dheading_bam64",
        "last_dheading_turns",
        "last_ds_q49_m",
        "x_q40_m",
        "y_q40_m",
    )

    def __init__(self, consts: OdomConstants, errors: ErrorMask) -> None:
        self._consts = consts
        self._count_half = 1 << (consts.counter_bits - 1)  # half the counters' range
        self._delta_fits = _delta_fits(consts)
        self._errors = errors
        self._primed = False
        self._left_prev = 0
        self._right_prev = 0
        self.x_q40_m = 0
        self.y_q40_m = 0
        self.heading_bam64 = 0
        self.heading_turns = 0  # i32: whole turns of the unwrapped heading (carries of the BAM64)
        self.distance_q40_m = 0
        self.last_ds_q49_m = 0  # i64, dS of the last step (for the twist)
        self.last_dheading_bam64 = 0  # i64, signed dtheta of the last step (for the twist)
        self.last_dheading_turns = 0  # i32, the whole turns of that step beyond it (|.| < 2^29)

    @property
    def consts(self) -> OdomConstants:
        """The constants in use."""
        return self._consts

    def reconfigure(self, consts: OdomConstants) -> None:
        """Use new constants from the next step on; the pose and the counter history are kept."""
        self._consts = consts
        self._count_half = 1 << (consts.counter_bits - 1)
        self._delta_fits = _delta_fits(consts)

    def set_pose(self, x_q40_m: int, y_q40_m: int, heading_bam64: int) -> None:
        """Overwrite the pose (``ODOM_SET_POSE``); distance travelled and counters are kept."""
        self.x_q40_m = x_q40_m
        self.y_q40_m = y_q40_m
        self.heading_bam64 = heading_bam64 & U64_MAX
        self.heading_turns = 0

    def unprime(self) -> None:
        """Forget the last counters: the next ``step_counts`` only re-primes (after a gap)."""
        self._primed = False

    def step_counts(self, left_count: int, right_count: int) -> bool:
        """Integrate from raw wrapping counters (``counter_bits`` wide, unsigned).

        The first call after start only primes the previous counts. Deltas are wrap-safe, the
        ODrive way: ``wrap_signed(now - prev, bits)``, exact while the true per-step delta is below
        half the counter range. Returns True when a step was integrated.
        """
        if not self._primed:
            self._left_prev, self._right_prev, self._primed = left_count, right_count, True
            return False
        # wrap_signed(now - prev, bits) in line: (int16_t)(uint16_t) or (int32_t)(uint32_t)
        half = self._count_half
        mask = half + half - 1
        d_left = ((left_count - self._left_prev + half) & mask) - half
        d_right = ((right_count - self._right_prev + half) & mask) - half
        self._left_prev, self._right_prev = left_count, right_count
        self.step_deltas(d_left, d_right)
        return True

    def step_deltas(self, d_left: int, d_right: int) -> None:
        """Integrate one step of count deltas (i32 each) with the configured integrator."""
        c = self._consts
        fits = self._delta_fits
        if -fits <= d_left <= fits and -fits <= d_right <= fits:  # products and sums fit i64
            ds_q49_m = d_left * c.m_per_count_left_q48_m + d_right * c.m_per_count_right_q48_m
            dheading = d_right * c.bam64_per_count_right - d_left * c.bam64_per_count_left
            turns = dheading_hi = 0  # |dheading| < 2^63: no whole turn (the high word unused)
        else:
            ds_q49_m, dheading, dheading_hi, turns = self._wide_step(d_left, d_right)
        heading_old = self.heading_bam64
        heading_sum = heading_old + dheading
        self.heading_bam64 = heading_sum & U64_MAX
        if heading_sum != self.heading_bam64 or turns:  # C: the unsigned add's carry or borrow
            self.heading_turns = wrap_i32(self.heading_turns + (heading_sum >> 64) + turns)
        self.last_ds_q49_m = ds_q49_m
        self.last_dheading_bam64 = dheading
        self.last_dheading_turns = turns
        if ds_q49_m == 0:
            return
        self.distance_q40_m = (
            self.distance_q40_m + ((abs(ds_q49_m) + (1 << 8)) >> Q49_TO_Q40_SHIFT)
        ) & U64_MAX
        integrator = c.integrator
        if integrator is _EULER:
            self._advance(ds_q49_m, self.heading_bam64)
            return
        midpoint_bam64 = (heading_old + (dheading >> 1)) & U64_MAX
        if integrator is _EXACT:
            if -SPIN_LIMIT_Q49 < ds_q49_m < SPIN_LIMIT_Q49:
                return
            factor_q62 = chord_factor_q62(dheading)
            if turns:  # the arc of the whole step: the wrapped chord scaled by dtheta_w / dtheta
                ratio_q62 = div_q62_i128(dheading, dheading_hi, dheading & U64_MAX)
                factor_q62 = _scale_q62(factor_q62, ratio_q62)
            if factor_q62 != ONE_Q62:  # ``_scale_q62``, in line
                ds_q49_m = mul_round_i64(ds_q49_m, factor_q62, 62)
        elif turns & 1:  # RK2: each whole turn beyond the signed read moves the midpoint by pi
            midpoint_bam64 ^= HALF_TURN_BAM64
        self._advance(ds_q49_m, midpoint_bam64)

    def _wide_step(self, d_left: int, d_right: int) -> tuple[int, int, int, int]:
        """``step_deltas``' products for deltas beyond ``_delta_fits`` (a wild or long step):
        (dS Q49 saturated to i64, dtheta BAM64 read as i64, the high word of dtheta's exact
        value, the whole turns beyond the signed read)."""
        c = self._consts
        errors = self._errors
        ds_q49_m = _sat(  # i32 x i64 products (up to 2^83 for a wild 32-bit step), saturated
            mul_sat_i64(d_left, c.m_per_count_left_q48_m, errors)
            + mul_sat_i64(d_right, c.m_per_count_right_q48_m, errors),
            errors,
        )
        dheading = mul_sub_wrap_i64(  # exact mod 2^64, read as i64
            d_right, c.bam64_per_count_right, d_left, c.bam64_per_count_left
        )
        # The high word of the exact difference (< 2^93): the whole turns beyond the signed read
        # (``turns``, |.| < 2^29), non-zero only for a step turning more than half a turn.
        dheading_hi = mul_add_hi_i64(
            d_right, c.bam64_per_count_right, -d_left, c.bam64_per_count_left
        )
        turns = dheading_hi + 1 if dheading < 0 else dheading_hi
        return ds_q49_m, dheading, dheading_hi, turns

    def _advance(self, ds_q49_m: int, direction_bam64: int) -> None:
        """x += dS cos(direction), y += dS sin(direction); direction rounded to BAM32 for sincos.

        dS (i64, Q49) times cos (i32, Q30) is a 94-bit Q79 product: ``mul_round_i64`` rounds it to
        Q40 (|.| < 2^55); the sum with x is then saturated to i64.
        """
        sin_q30, cos_q30 = sincos_q30(((direction_bam64 + (1 << 31)) >> 32) & U32_MAX)
        x_q40_m = self.x_q40_m + mul_round_i64(ds_q49_m, cos_q30, DS_COS_TO_Q40_SHIFT)
        self.x_q40_m = x_q40_m if I64_MIN <= x_q40_m <= I64_MAX else _sat(x_q40_m, self._errors)
        y_q40_m = self.y_q40_m + mul_round_i64(ds_q49_m, sin_q30, DS_COS_TO_Q40_SHIFT)
        self.y_q40_m = y_q40_m if I64_MIN <= y_q40_m <= I64_MAX else _sat(y_q40_m, self._errors)


def chord_factor_q62(dheading_bam64: int) -> int:
    """sin(u)/u for u = dtheta/2, in Q62 (1.0 = 2^62), from a signed i64 BAM64 step.

    |u| < 2^-21 rad: exactly 1 (the straight case). Otherwise the Horner series
    1 - u^2/6 (1 - u^2/20 (1 - u^2/42 (...))) in Q60 (u^2 <= (pi/2)^2 fits i64 there): three
    terms while |u| <= 1/8 rad (truncation < u^8/9! < 2^-42), eight terms up to |u| = pi/2, the
    largest half-step a signed BAM64 can hold (truncation < (pi/2)^18/19! < 2^-44).
    Widths: u = dtheta * 2pi / 2^65 is an i64 x i64 product (126 bits) rounded to Q60 (< 2^61);
    u^2 and u^2 * acc (122 bits) are kept from bit 60 by ``mul_round_i64``/``mul_shr_i64``.
    """
    u_q60 = abs(mul_round_i64(dheading_bam64, TWO_PI_Q60, 65))
    if u_q60 < STRAIGHT_LIMIT_Q60:
        return ONE_Q62
    u2_q60 = mul_round_i64(u_q60, u_q60, 60)
    if u_q60 <= SERIES_SHORT_LIMIT_Q60:
        inner, outer = _SINC_SHORT_INNER, _SINC_SHORT_OUTER
    else:
        inner, outer = _SINC_LONG_INNER, _SINC_LONG_OUTER
    # The innermost term's product is u^2 * 1.0, i.e. u^2 itself (floor(u2 * 2^60 / 2^60) is
    # exact): taken as it is, the rest by ``mul_shr_i64`` (the C port's loop gives the same).
    acc_q60 = ONE_Q60 - u2_q60 // inner
    for denominator in outer:
        acc_q60 = ONE_Q60 - mul_shr_i64(u2_q60, acc_q60, 60) // denominator
    return acc_q60 << 2


def _delta_fits(consts: OdomConstants) -> int:
    """The largest count delta (u32) whose products with either wheel's travel and heading per
    count stay below 2^62 (their sum and difference then fit i64): up to it ``mul_sat_i64`` and
    the sum's saturation cannot clamp, ``mul_sub_wrap_i64`` does not wrap and the high word of
    dtheta is its sign (no whole turn), so plain 64-bit products give the same (C: four compares
    instead of four 128-bit products). Configuration time: one u64 division."""
    largest = max(
        consts.m_per_count_left_q48_m,
        consts.m_per_count_right_q48_m,
        consts.bam64_per_count_left,
        consts.bam64_per_count_right,
        1,
    )
    return ((1 << 62) - 1) // largest


def _scale_q62(value: int, factor_q62: int) -> int:
    """``value * factor`` for a Q62 factor in (-1, 1]: rounds (half up), never leaves the width
    of value (the 126-bit product is ``mul_round_i64``'s)."""
    if factor_q62 == ONE_Q62:
        return value
    return mul_round_i64(value, factor_q62, 62)


def _sat(value: int, errors: ErrorMask) -> int:
    """Inline-cheap i64 saturation (the common case is a pair of comparisons)."""
    if I64_MIN <= value <= I64_MAX:
        return value
    errors.set(ErrorFlag.SATURATION)
    return sat_i64(value, errors)
