"""C integer widths, two's-complement wrap and saturate helpers, rounding shifts.

Python integers never overflow; C integers do. Every firmware value has a C width, named by the
type aliases below (documentation only: they are all ``int`` to Python). Every result that could
leave its width goes through one of these helpers, each of which behaves exactly as the C it stands
for on a 32-bit two's-complement MCU with a 64-bit multiply (Cortex-M3/M4: ``SMULL``/``UMULL``).

* ``wrap_*``: the value modulo 2^N, read back in the type (C's conversion to a fixed-width type).
* ``sat_*``: clamp to the type's range; on clamping, the SATURATION bit is set in the error mask
  that the caller passes in. The loop never raises.
* ``mul_sub_wrap_i64``: ``a*b - c*d`` mod 2^64 (C's ``uint64_t`` multiply and subtract).
* ``mul_shr_i64``, ``mul_round_i64``: the exact 128-bit product of two i64, shifted right
  (floor, or rounded half up), read back as an i64.
* ``mul_add_hi_i64``: the high 64 bits of ``a*b + c*d`` (a 2x2 rotation's rows in Q126).
* ``mul_sat_i64``, ``mul_shr_round_i64``: the product, or its rounded shift, saturated to i64.
* ``div_q62_i128``: ``num / den`` in Q62 for an i64 ``num`` and an i128 ``den`` (hi, lo words).
* ``muldiv_round_u64``: round(a*b/c) for u64 a, b, c with a 128-bit intermediate, as Linux's
  ``mul_u64_u64_div_u64`` (plus rounding). Configuration time only, never in the loop.
* ``isqrt_u64``: floor(sqrt(n)) of a u64 by Newton's method (navigation distances).

The 128-bit product, in C without ``__int128`` (the target is a 32-bit MCU). Each u64 is two u32
halves, ``a = a1*2^32 + a0``; four ``UMULL`` give the partial products ``pXY = (uint64_t)aX*bY``:

    mid = (p00 >> 32) + (uint32_t)p01 + (uint32_t)p10;        /* < 3*2^32: no overflow */
    lo  = (mid << 32) | (uint32_t)p00;
    hi  = p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);      /* < 2^64: no overflow */

For signed i64 operands (``smul_128``) the same is done on ``(uint64_t)a``, ``(uint64_t)b``, then
``hi -= (a < 0 ? (uint64_t)b : 0) + (b < 0 ? (uint64_t)a : 0)`` (mod 2^64): (hi, lo) is the
product in two's complement. An arithmetic right shift of (hi, lo) by ``0 < s < 64`` keeps
``(lo >> s) | (hi << (64 - s))`` as its low word; by ``64 <= s < 128``, ``(int64_t)hi >> (s - 64)``.
``tests/test_fixmath.py`` holds this construction, written with 64-bit operations only, and proves
every helper below equal to it (edge values exhaustively, then hypothesis).

The sanitizer of ``tests/width_sanitizer.py`` checks every arithmetic result of the firmware
against its C width, except inside the helpers here whose docstring gives their C form on a line
starting ``C:``: those are the audited primitives.
"""

from __future__ import annotations

from typing import TypeAlias

from odocan.firmware.errors import ErrorFlag, ErrorMask

u8: TypeAlias = int
u16: TypeAlias = int
u32: TypeAlias = int
u64: TypeAlias = int
i16: TypeAlias = int
i32: TypeAlias = int
i64: TypeAlias = int

U8_MAX = 0xFF
U16_MAX = 0xFFFF
U32_MAX = 0xFFFF_FFFF
U64_MAX = 0xFFFF_FFFF_FFFF_FFFF
I16_MIN = -0x8000
I16_MAX = 0x7FFF
I32_MIN = -0x8000_0000
I32_MAX = 0x7FFF_FFFF
I64_MIN = -0x8000_0000_0000_0000
I64_MAX = 0x7FFF_FFFF_FFFF_FFFF


def wrap_u16(value: int) -> u16:
    """C: ``(uint16_t)value``."""
    return value & U16_MAX


def wrap_u32(value: int) -> u32:
    """C: ``(uint32_t)value``."""
    return value & U32_MAX


def wrap_i16(value: int) -> i16:
    """Two's-complement reinterpretation of the low 16 bits.

    C: ``(int16_t)(uint16_t)value``.
    """
    return ((value + 0x8000) & U16_MAX) - 0x8000


def wrap_i32(value: int) -> i32:
    """C: ``(int32_t)(uint32_t)value``."""
    return ((value + 0x8000_0000) & U32_MAX) - 0x8000_0000


def wrap_i64(value: int) -> i64:
    """C: ``(int64_t)(uint64_t)value``."""
    return ((value + 0x8000_0000_0000_0000) & U64_MAX) - 0x8000_0000_0000_0000


def wrap_signed(value: int, bits: int) -> int:
    """Two's-complement reinterpretation of the low ``bits`` bits (16 or 32: counter deltas).

    C: ``(int16_t)(uint16_t)value`` or ``(int32_t)(uint32_t)value``.
    """
    half = 1 << (bits - 1)
    return ((value + half) & ((1 << bits) - 1)) - half


def sat_i64(value: int, errors: ErrorMask) -> i64:
    """Clamp to int64_t; set SATURATION in ``errors`` when clamped."""
    if value > I64_MAX:
        errors.set(ErrorFlag.SATURATION)
        return I64_MAX
    if value < I64_MIN:
        errors.set(ErrorFlag.SATURATION)
        return I64_MIN
    return value


def sat_range(value: int, low: int, high: int, errors: ErrorMask) -> int:
    """Clamp to ``[low, high]`` (a raw signal's range); set SATURATION when clamped."""
    if value > high:
        errors.set(ErrorFlag.SATURATION)
        return high
    if value < low:
        errors.set(ErrorFlag.SATURATION)
        return low
    return value


def mul_sub_wrap_i64(a: i64, b: i64, c: i64, d: i64) -> i64:
    """``a * b - c * d`` mod 2^64 read as i64, for u64 or i64 operands (a BAM64 heading step).

    C: ``(int64_t)((uint64_t)a * (uint64_t)b - (uint64_t)c * (uint64_t)d)``; on a 32-bit MCU each
    product mod 2^64 is ``a0*b0`` (``UMULL``) plus ``(a0*b1 + a1*b0) << 32`` (two ``MLA``).
    """
    return ((a * b - c * d + 0x8000_0000_0000_0000) & U64_MAX) - 0x8000_0000_0000_0000  # wrap_i64


def mul_shr_i64(a: i64, b: i64, shift: int) -> i64:
    """``floor(a * b / 2^shift)`` of the exact 128-bit product, ``0 <= shift <= 127``, as an i64.

    The caller's ranges keep the result in i64; beyond them it wraps as C's conversion does.
    C: ``smul_128(a, b, &hi, &lo)``, then the arithmetic right shift of (hi, lo) by ``shift``, its
    low word read as ``int64_t`` (module docstring).
    """
    result = (a * b) >> shift
    return result if I64_MIN <= result <= I64_MAX else wrap_i64(result)


def mul_round_i64(a: i64, b: i64, shift: int) -> i64:
    """``round(a * b / 2^shift)``, half up, of the exact 128-bit product, ``1 <= shift <= 126``.

    The caller's ranges keep the result in i64 (no saturation: see ``mul_shr_round_i64``);
    beyond them it wraps as C's conversion does.
    C: ``smul_128(a, b, &hi, &lo)``; add ``2^(shift-1)`` to (hi, lo) with carry
    (``lo += r_lo; hi += r_hi + (lo < r_lo)``, r = 2^(shift-1) in two words; the sum stays below
    2^127 for ``shift <= 126``), then the arithmetic right shift by ``shift``, its low word read as
    ``int64_t``.
    """
    result = (a * b + (1 << (shift - 1))) >> shift
    return result if I64_MIN <= result <= I64_MAX else wrap_i64(result)


def mul_add_hi_i64(a: i64, b: i64, c: i64, d: i64) -> i64:
    """``floor((a * b + c * d) / 2^64)``: the high word of the i128 sum of two exact products.

    The sum wraps mod 2^128 as C's does (only ``a = b = c = d = I64_MIN`` reaches 2^127).
    C: ``smul_128(a, b, &h1, &l1); smul_128(c, d, &h2, &l2); lo = l1 + l2;``
    ``return (int64_t)(h1 + h2 + (lo < l1));``
    """
    result = (a * b + c * d) >> 64
    return result if I64_MIN <= result <= I64_MAX else wrap_i64(result)


def mul_sat_i64(a: i64, b: i64, errors: ErrorMask) -> i64:
    """``sat_i64(a * b)``: the exact 128-bit product clamped to i64 (SATURATION set if clamped).

    C: ``smul_128(a, b, &hi, &lo)``; it fits when ``hi == (uint64_t)((int64_t)lo >> 63)``, else
    it clamps by the sign of ``hi`` (INT64_MIN if ``(int64_t)hi < 0``, else INT64_MAX).
    """
    product = a * b
    return product if I64_MIN <= product <= I64_MAX else sat_i64(product, errors)


def mul_shr_round_i64(a: i64, b: i64, shift: int, errors: ErrorMask) -> i64:
    """``sat_i64(round((a * b) / 2^shift))``, ``1 <= shift <= 126``: the exact 128-bit product,
    rounded half up, then saturated (SATURATION set in ``errors`` when clamped).

    C: as ``mul_round_i64`` up to the shifted (hi, lo); it fits i64 when ``hi`` is the sign
    extension of ``lo`` (``hi == (uint64_t)((int64_t)lo >> 63)``), else it clamps by the sign
    of ``hi``. For ``shift >= 64`` the shifted value is ``(int64_t)hi >> (shift - 64)``: it fits.
    """
    result = (a * b + (1 << (shift - 1))) >> shift
    return result if I64_MIN <= result <= I64_MAX else sat_i64(result, errors)


def div_q62_i128(num: i64, den_hi: i64, den_lo: u64) -> i64:
    """``num * 2^62 / den`` rounded half away from zero, for an i64 ``num`` and the i128
    ``den = den_hi * 2^64 + den_lo`` (``den_lo`` the u64 low word), ``2^63 <= |den| < 2^126`` and
    ``|num| <= |den|``: the result is in [-2^62, 2^62] (a ratio in (-1, 1] as Q62).

    |den| is normalized to its top 64 bits (``sh`` the bit length of its high word, ``top = |den|
    >> sh``, truncated: relative error below 2^-63, ``top >= 2^63``), the numerator scaled by
    ``2^(62 - sh)``: the quotient then fits u64 (<= 2^62). In the loop only when a step turns more
    than half a turn (a software 128/64 division).
    C: ``wide128_t d = {(uint64_t)den_hi, den_lo}; if (den_hi < 0) d = wide_sub(wide_from_u64(0),
    d); sh = bit_length_u64(d.hi); top = sh ? (d.hi << (64 - sh)) | (d.lo >> sh) : d.lo;``
    ``q = muldiv_round_u64(abs_u64(num), (uint64_t)1 << (62 - sh), top, &scratch)`` (no
    saturation: q <= 2^62), negated when ``(num < 0) != (den_hi < 0)``.
    """
    den = (den_hi << 64) | den_lo
    magnitude = -den if den < 0 else den
    shift = max(magnitude.bit_length() - 64, 0)
    top = magnitude >> shift
    quotient = (abs(num) * (1 << (62 - shift)) + (top >> 1)) // top
    return -quotient if (num < 0) != (den < 0) else quotient


def muldiv_round_u64(a: u64, b: u64, c: u64, errors: ErrorMask) -> u64:
    """``round(a * b / c)`` with a 128-bit intermediate; saturates to u64; ``c == 0`` gives U64_MAX.

    Configuration time only (a software 128/64 division is slow on an MCU).
    C: ``umul_128(a, b, &hi, &lo)``; add ``c >> 1`` with carry (the sum stays below 2^128); if
    ``hi >= c`` the quotient needs more than 64 bits: saturate. Else a restoring 128/64 division:
    64 times ``top = hi >> 63; hi = (hi << 1) | (lo >> 63); lo <<= 1; q <<= 1;``
    ``if (top || hi >= c) { hi -= c; q |= 1; }``, the quotient ``q``.
    """
    if c == 0:
        errors.set(ErrorFlag.SATURATION)
        return U64_MAX
    quotient = (a * b + (c >> 1)) // c
    if quotient > U64_MAX:
        errors.set(ErrorFlag.SATURATION)
        return U64_MAX
    return quotient


def div_round_i64(numerator: i64, denominator: i64) -> i64:
    """Signed division rounding half away from zero, ``denominator > 0`` (C: truncating ``/``)."""
    half = denominator >> 1
    if numerator >= 0:
        return (numerator + half) // denominator
    return -((-numerator + half) // denominator)


def isqrt_u64(n: u64) -> u32:
    """``floor(sqrt(n))`` of a u64 (result u32), by Newton's method on integers.

    The start ``x0 = 2^ceil(bits(n)/2)`` (C: from ``64 - __builtin_clzll(n)``) is >= sqrt(n);
    each step ``x <- (x + n/x) / 2`` (u64 division, truncating) stays >= floor(sqrt(n)) and
    decreases strictly until it reaches it: at most 6 steps for a u64 (quadratic convergence
    from a start within a factor 2). ``n`` outside [0, 2^64) is reduced to its low 64 bits.
    """
    n &= U64_MAX
    if n < 2:
        return n
    x = 1 << ((n.bit_length() + 1) >> 1)  # u64 <= 2^32
    y = (x + n // x) >> 1
    while y < x:
        x = y
        y = (x + n // x) >> 1
    return x
