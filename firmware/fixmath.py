"""C integer widths, two's-complement wrap and saturate helpers, rounding shifts.

Python integers never overflow; C integers do. Every firmware value has a C width, named by the
type aliases below (documentation only: they are all ``int`` to Python). Every result that could
leave its width goes through one of these helpers, each of which behaves exactly as the C it stands
for on a 32-bit two's-complement MCU with a 64-bit multiply (Cortex-M3/M4: ``SMULL``/``UMULL``).

* ``wrap_*``: the value modulo 2^N, read back in the type (C's conversion to a fixed-width type).
* ``sat_*``: clamp to the type's range; on clamping, the SATURATION bit is set in the error mask
  that the caller passes in. The loop never raises.
* ``shr_round``: arithmetic shift right rounding half up, ``(v + (1 << (n-1))) >> n`` in C.
* ``mul_shr_round_i64``: the exact product of two i64 rounded and shifted right, saturated to i64;
  in C the 128-bit intermediate is built from 32x32->64 partial products.
* ``muldiv_round_u64``: round(a*b/c) for u64 a, b, c with a 128-bit intermediate, as Linux's
  ``mul_u64_u64_div_u64`` (plus rounding). Configuration time only, never in the loop.
* ``isqrt_u64``: floor(sqrt(n)) of a u64 by Newton's method (navigation distances).
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
    """``(uint16_t)value``."""
    return value & U16_MAX


def wrap_u32(value: int) -> u32:
    """``(uint32_t)value``."""
    return value & U32_MAX


def wrap_u64(value: int) -> u64:
    """``(uint64_t)value``."""
    return value & U64_MAX


def wrap_i16(value: int) -> i16:
    """``(int16_t)(uint16_t)value``: two's-complement reinterpretation of the low 16 bits."""
    return ((value + 0x8000) & U16_MAX) - 0x8000


def wrap_i32(value: int) -> i32:
    """``(int32_t)(uint32_t)value``."""
    return ((value + 0x8000_0000) & U32_MAX) - 0x8000_0000


def wrap_i64(value: int) -> i64:
    """``(int64_t)(uint64_t)value``."""
    return ((value + 0x8000_0000_0000_0000) & U64_MAX) - 0x8000_0000_0000_0000


def wrap_signed(value: int, bits: int) -> int:
    """Two's-complement reinterpretation of the low ``bits`` bits (16 or 32: counter deltas)."""
    half = 1 << (bits - 1)
    return ((value + half) & ((1 << bits) - 1)) - half


def sat_i32(value: int, errors: ErrorMask) -> i32:
    """Clamp to int32_t; set SATURATION in ``errors`` when clamped."""
    if value > I32_MAX:
        errors.set(ErrorFlag.SATURATION)
        return I32_MAX
    if value < I32_MIN:
        errors.set(ErrorFlag.SATURATION)
        return I32_MIN
    return value


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


def shr_round(value: int, shift: int) -> int:
    """Arithmetic shift right by ``shift`` >= 1, rounding half up (toward +inf).

    C: ``(value + ((int64_t)1 << (shift - 1))) >> shift`` with an arithmetic ``>>``.
    """
    return (value + (1 << (shift - 1))) >> shift


def mul_shr_round_i64(a: i64, b: i64, shift: int, errors: ErrorMask) -> i64:
    """``sat_i64(round((a * b) / 2^shift))``: the full 128-bit product, rounded, then saturated."""
    return sat_i64((a * b + (1 << (shift - 1))) >> shift, errors)


def muldiv_round_u64(a: u64, b: u64, c: u64, errors: ErrorMask) -> u64:
    """``round(a * b / c)`` with a 128-bit intermediate; saturates to u64; ``c == 0`` gives U64_MAX.

    Configuration time only (a software 128/64 division is slow on an MCU).
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
