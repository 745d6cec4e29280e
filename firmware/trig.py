"""Fixed-point trigonometry on binary angles: ``sincos_q30`` and ``atan2_bam32``.

Binary angles (BAM32): a full turn is 2^32, so one LSB is 2*pi / 2^32 rad (about 1.46e-9 rad) and
wrap-around is free. The angle inputs may be given as u32 or i32: only the low 32 bits are read.
Results of sine and cosine are i32 in Q30 (1.0 == 1 << 30, exactly representable).

Both functions are straight-line integer code with no loop, written for speed in a pure-Python
odometry step (one ``if`` chain picks the quadrant or octant). The comments give the C type of every
intermediate. Every product wider than 64 bits (the u64 x u32 coefficient products, the sin/cos
recombination) goes through a ``fixmath`` helper (``mul_shr_i64``, ``mul_add_hi_i64``): in C a
128-bit product built from 32x32->64 partial products (``UMULL``), of which only the bits kept
are read. No value outside its C type exists in between (``tests/width_sanitizer.py``).

Error bounds (proven by ``tests/test_trig.py`` against float64 ``math``):

* ``sincos_q30``: |error| <= 2^-31 + 2^-41 for each component over the whole circle: the final
  rounding to Q30 plus at most ~2^-42 of table, coefficient and truncation error.
* ``atan2_bam32``: |error| <= pi * 2^-32 + 2^-36 rad, i.e. half a BAM32 LSB (the final rounding)
  plus at most ~2^-37 rad of internal error; well inside the 2^-24 rad requirement.

Exact identities (by construction, not by luck of rounding): sin(-a) == -sin(a),
cos(-a) == cos(a), sin(a + 2^30) == cos(a), cos(a + 2^30) == -sin(a), sin(2^29) == cos(2^29), and
atan2(-y, x) == -atan2(y, x) except where the result is -2^31 (+-pi).
"""

from __future__ import annotations

from odocan.firmware.fixmath import i32, i64, mul_add_hi_i64, mul_shr_i64, u32
from odocan.firmware.trig_tables import (
    ATAN_BAM48,
    ATAN_K1,
    ATAN_K1_SHIFT,
    ATAN_K3,
    SIN_K2,
    SIN_K2_SHIFT,
    SIN_K3,
    SIN_K3_SHIFT,
    SIN_K4,
    SIN_K4_SHIFT,
    SIN_Q62,
    SIN_STEP_Q64,
)

QUARTER_BAM32 = 1 << 30
HALF_BAM32 = 1 << 31

_HALF_Q30_IN_Q62 = 1 << 31  # half an LSB of the Q30 result, in Q62


def sincos_q30(angle_bam32: u32) -> tuple[i32, i32]:
    """Sine and cosine of a binary angle, both i32 in Q30, |error| <= 2^-31 + 2^-41.

    ``angle_bam32``: u32 (or i32) BAM32; only its low 32 bits are read. Method, with the C type of
    every intermediate:

    1. Quadrant ``q`` = bits 31..30; ``r`` (u32 < 2^30) = the angle within the quadrant.
    2. Nearest knot ``i`` (0..256) of the quarter-wave table, ties to the even knot so that the
       mirror r -> 2^30 - r maps (i, d) to (256 - i, -d) exactly; ``d = r - i*2^22`` (i32,
       |d| <= 2^21), the small angle theta = d * 2*pi/2^32, |theta| <= pi/1024.
    3. Taylor terms in Q64 from ``d2 = d*d`` (u64 <= 2^42): ``sin_t`` = theta - theta^3/6
       (i64, |.| < 2^56) and ``om`` = 1 - cos(theta) = theta^2/2 - theta^4/24 (u64 < 2^47); the
       products with the u32 coefficients are 74-bit, ``mul_shr_i64`` keeps their bits from the
       shift up (< 2^47). Dropped terms: theta^5/120 < 2^-48, theta^6/720 < 2^-59.
       cos(theta) = 1 - om is never formed (in Q64 it would be a u65).
    4. Angle addition with the Q62 table values s = sin(A), c = cos(A) = SIN_Q62[256 - i] (i64):
       sin = s*(1 - om) + c*sin_t and cos = c*(1 - om) - s*sin_t in Q126, rounded once (half
       up) to Q30: ``sin = (s*2^64 + Z + 2^95) >> 96`` with ``Z = c*sin_t - s*om``, i.e. exactly
       ``(s + 2^31 + floor(Z / 2^64)) >> 32`` (nested floors), where ``floor(Z / 2^64)`` (i64,
       |.| < 2^55) is ``mul_add_hi_i64(c, sin_t, -s, om)``; likewise cos with
       ``Z = -c*om - s*sin_t``. Each sum is an i64 below 2^63; the results are 0..2^30.
    5. The quadrant permutes and negates (sin, cos) exactly.
    """
    r = angle_bam32 & 0x3FFF_FFFF
    i = (r + 0x1F_FFFF + ((r >> 22) & 1)) >> 22
    d = r - (i << 22)
    d2 = d * d
    sin_t = d * (SIN_STEP_Q64 - mul_shr_i64(d2, SIN_K3, SIN_K3_SHIFT))
    om = mul_shr_i64(d2, SIN_K2 - mul_shr_i64(d2, SIN_K4, SIN_K4_SHIFT), SIN_K2_SHIFT)
    s = SIN_Q62[i]
    c = SIN_Q62[256 - i]
    sin_r = (s + _HALF_Q30_IN_Q62 + mul_add_hi_i64(c, sin_t, -s, om)) >> 32
    cos_r = (c + _HALF_Q30_IN_Q62 + mul_add_hi_i64(-c, om, -s, sin_t)) >> 32
    q = (angle_bam32 >> 30) & 3
    if q == 0:
        return sin_r, cos_r
    if q == 1:
        return cos_r, -sin_r
    if q == 2:
        return -sin_r, -cos_r
    return -cos_r, sin_r


def sin_q30(angle_bam32: u32) -> i32:
    """Sine of a BAM32 angle in Q30 (i32); bit-identical to ``sincos_q30(angle_bam32)[0]``."""
    return sincos_q30(angle_bam32)[0]


def cos_q30(angle_bam32: u32) -> i32:
    """Cosine of a BAM32 angle in Q30 (i32); bit-identical to ``sincos_q30(angle_bam32)[1]``."""
    return sincos_q30(angle_bam32)[1]


def atan2_bam32(y: i64, x: i64) -> i32:
    """The angle of the vector (x, y) as a signed BAM32 in [-2^31, 2^31); atan2(0, 0) = 0.

    ``y``, ``x``: i64 in any common scale, I64_MIN included. +pi is returned as -2^31 (the same
    binary angle). |error| <= pi * 2^-32 + 2^-36 rad (half an LSB plus < 2^-37 rad). Method, with
    the C type of every intermediate:

    1. Octant reduction: ``m`` >= ``n`` >= 0 are the larger and smaller magnitude (u64 <= 2^63,
       so |I64_MIN| fits); phi = atan(n/m) in [0, pi/4].
    2. Normalise (C: ``clz``): shift both so that m is in [2^46, 2^47). Left shifts are exact; a
       right shift drops bits of relative weight < 2^-46 (angle error < 2^-45 rad).
    3. Knot ``k = (n << 8) // m`` (0..256; u64 / u64), then the exact identity
       atan(n/m) = atan(k/256) + atan(u), u = (256n - km) / (256m + kn), 0 <= u < 2^-8:
       ``num`` < 2^47 and ``den`` in [2^54, 2^56) are u64.
    4. ``u_q39`` = (num << 15) / (den >> 24): u64 / u32 (den truncated to 32 significant bits:
       relative error < 2^-30, absolute < 2^-38 rad); u_q39 <= 2^31 + 2.
    5. atan(u) = u*(1 - u^2/3) (dropped u^5/5 < 2^-42) straight into BAM48 (2^48 per turn):
       ``u2_q39`` < 2^24, the coefficient ``ATAN_K1 - ...`` < 2^33, the product u64 < 2^64.
    6. Add the table entry atan(k/256) (BAM48, u64 <= 2^45), round once to BAM32 (u32 <= 2^29),
       then unfold the octant exactly in i64 and wrap to i32.
    """
    ax = -x if x < 0 else x
    ay = -y if y < 0 else y
    swap = ay > ax
    if swap:
        m, n = ay, ax
    else:
        m, n = ax, ay
    if m == 0:
        return 0
    shift = m.bit_length() - 47
    if shift > 0:
        m >>= shift
        n >>= shift
    else:
        m <<= -shift
        n <<= -shift
    n8 = n << 8
    k = n8 // m
    # u = num / den with num = 256n - km (u64 < 2^47), den = 256m + kn (u64 in [2^54, 2^56))
    u_q39 = ((n8 - k * m) << 15) // (((m << 8) + k * n) >> 24)
    u2_q39 = (u_q39 * u_q39) >> 39
    phi_u_bam48 = (u_q39 * (ATAN_K1 - ((u2_q39 * ATAN_K3) >> 40))) >> ATAN_K1_SHIFT
    phi = (ATAN_BAM48[k] + phi_u_bam48 + 0x8000) >> 16
    if swap:
        phi = QUARTER_BAM32 - phi
    if x < 0:
        phi = HALF_BAM32 - phi
        if phi == HALF_BAM32:  # +pi: the i32 wrap gives -2^31
            return -HALF_BAM32
    if y < 0:
        return -phi
    return phi
