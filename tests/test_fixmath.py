"""The wide fixmath helpers against their C form, written here with 64-bit operations only.

Each helper in ``firmware/fixmath.py`` that multiplies beyond 64 bits computes in Python with a wide
integer. Its docstring gives the C a 32-bit MCU runs instead: a 128-bit product built from four
32x32->64 partial products, carries, an arithmetic shift of a two-word value, a restoring 128/64
division. This module writes that C down (``Word``: every intermediate masked to u64, every
product one of two u32) and proves each helper equal to it, exhaustively on the edge values of
i64/u64 and their neighbours, then with hypothesis. It is the reference the C port is held to.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.firmware.errors import ErrorFlag, ErrorMask
from odocan.firmware.fixmath import (
    I64_MAX,
    I64_MIN,
    U64_MAX,
    div_q62_i128,
    mul_add_hi_i64,
    mul_round_i64,
    mul_sat_i64,
    mul_shr_i64,
    mul_shr_round_i64,
    mul_sub_wrap_i64,
    muldiv_round_u64,
)

M32 = 0xFFFF_FFFF
M64 = U64_MAX


# --- the C, with 64-bit operations only --------------------------------------------------------


def _u64(value: int) -> int:
    """``(uint64_t)value``: every intermediate below goes through it or provably fits."""
    assert -(1 << 64) < value < 1 << 65, "a reference intermediate left 64 bits (+ carry)"
    return value & M64


def _as_i64(word: int) -> int:
    """``(int64_t)word``."""
    return word - (1 << 64) if word >> 63 else word


def _umul32(a: int, b: int) -> int:
    """``(uint64_t)(uint32_t)a * (uint32_t)b`` (UMULL)."""
    assert 0 <= a <= M32
    assert 0 <= b <= M32
    return a * b


def umul_128(a: int, b: int) -> tuple[int, int]:
    """(hi, lo) of the u64 x u64 product, from four partial products (fixmath's docstring)."""
    a0, a1, b0, b1 = a & M32, a >> 32, b & M32, b >> 32
    p00, p01, p10, p11 = _umul32(a0, b0), _umul32(a0, b1), _umul32(a1, b0), _umul32(a1, b1)
    mid = _u64((p00 >> 32) + (p01 & M32) + (p10 & M32))
    lo = _u64((mid << 32) & M64 | (p00 & M32))
    hi = _u64(p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32))
    return hi, lo


def smul_128(a: int, b: int) -> tuple[int, int]:
    """(hi, lo) of the i64 x i64 product in two's complement: the unsigned one, corrected."""
    ua, ub = _u64(a), _u64(b)
    hi, lo = umul_128(ua, ub)
    if a < 0:
        hi = _u64(hi - ub)
    if b < 0:
        hi = _u64(hi - ua)
    return hi, lo


def add_128(x: tuple[int, int], y: tuple[int, int]) -> tuple[int, int]:
    """(hi, lo) + (hi, lo) mod 2^128, the carry from ``lo < x_lo``."""
    lo = _u64(x[1] + y[1])
    carry = int(lo < x[1])
    return _u64(x[0] + y[0] + carry), lo


def sar_128(x: tuple[int, int], shift: int) -> tuple[int, int]:
    """Arithmetic shift right of a two's-complement (hi, lo) by 0..127."""
    hi, lo = x
    if shift == 0:
        return hi, lo
    if shift < 64:
        return _u64(_as_i64(hi) >> shift), _u64((lo >> shift) | ((hi << (64 - shift)) & M64))
    return _u64(_as_i64(hi) >> 63), _u64(_as_i64(hi) >> (shift - 64))


def pow2_128(exponent: int) -> tuple[int, int]:
    """2^exponent (0..126) as (hi, lo)."""
    return (1 << (exponent - 64), 0) if exponent >= 64 else (0, 1 << exponent)


def c_mul_shr_i64(a: int, b: int, shift: int) -> int:
    return _as_i64(sar_128(smul_128(a, b), shift)[1])


def c_mul_round_i64(a: int, b: int, shift: int) -> int:
    return _as_i64(sar_128(add_128(smul_128(a, b), pow2_128(shift - 1)), shift)[1])


def c_mul_shr_round_i64(a: int, b: int, shift: int) -> tuple[int, bool]:
    """The rounded shift, saturated: (value, saturated)."""
    hi, lo = sar_128(add_128(smul_128(a, b), pow2_128(shift - 1)), shift)
    if hi == _u64(_as_i64(lo) >> 63):
        return _as_i64(lo), False
    return (I64_MIN, True) if hi >> 63 else (I64_MAX, True)


def c_mul_sat_i64(a: int, b: int) -> tuple[int, bool]:
    """The product, saturated: (value, saturated)."""
    hi, lo = smul_128(a, b)
    if hi == _u64(_as_i64(lo) >> 63):
        return _as_i64(lo), False
    return (I64_MIN, True) if hi >> 63 else (I64_MAX, True)


def c_mul_add_hi_i64(a: int, b: int, c: int, d: int) -> int:
    return _as_i64(add_128(smul_128(a, b), smul_128(c, d))[0])


def _umul_lo(a: int, b: int) -> int:
    """``(uint64_t)a * (uint64_t)b``: a0*b0 plus the two cross products shifted (no high one)."""
    a0, a1, b0, b1 = a & M32, a >> 32, b & M32, b >> 32
    cross = _u64(_umul32(a0, b1) + _umul32(a1, b0))
    return _u64(_umul32(a0, b0) + ((cross << 32) & M64))


def c_mul_sub_wrap_i64(a: int, b: int, c: int, d: int) -> int:
    return _as_i64(_u64(_umul_lo(_u64(a), _u64(b)) - _umul_lo(_u64(c), _u64(d))))


def c_muldiv_round_u64(a: int, b: int, c: int) -> tuple[int, bool]:
    """round(a*b/c) by a restoring 128/64 division: (value, saturated)."""
    if c == 0:
        return M64, True
    hi, lo = add_128(umul_128(a, b), (0, c >> 1))
    if hi >= c:
        return M64, True
    quotient = 0
    for _ in range(64):
        top = hi >> 63
        hi = _u64(((hi << 1) & M64) | (lo >> 63))
        lo = (lo << 1) & M64
        quotient = (quotient << 1) & M64
        if top or hi >= c:
            hi = _u64(hi - c)
            quotient |= 1
    return quotient, False


def _bit_length_u64(value: int) -> int:
    """``bit_length_u64`` of fixmath.c: halving steps on a u64."""
    bits = 0
    for step in (32, 16, 8, 4, 2, 1):
        if value >> step:
            value >>= step
            bits += step
    return bits + value


def c_div_q62_i128(num: int, den_hi: int, den_lo: int) -> int:
    """div_q62_i128's C: negate the two-word divisor, normalize it to its top word, muldiv."""
    hi, lo = _u64(den_hi), den_lo
    if den_hi < 0:
        hi = _u64((~hi & M64) + int(lo == 0))  # 0 - (hi, lo): ~x + 1 with the carry of lo
        lo = _u64(-lo)
    shift = _bit_length_u64(hi)
    top = lo if shift == 0 else (((hi << (64 - shift)) & M64) | (lo >> shift))
    quotient, saturated = c_muldiv_round_u64(_u64(abs(num)), 1 << (62 - shift), top)
    assert not saturated
    return -quotient if (num < 0) != (den_hi < 0) else quotient


# --- the reference itself, against Python's exact integers (so it cannot be wrong in step) -----


def test_the_reference_128_bit_product_is_the_exact_product() -> None:
    for a, b in itertools.product(EDGES_I64, repeat=2):
        hi, lo = smul_128(a, b)
        assert (_as_i64(hi) << 64) | lo == a * b
    for a, b in itertools.product(EDGES_U64, repeat=2):
        hi, lo = umul_128(a, b)
        assert (hi << 64) | lo == a * b


# --- edge values ---------------------------------------------------------------------------------


def _edges(points: list[int], low: int, high: int) -> list[int]:
    out = {p + k for p in points for k in (-1, 0, 1)}
    return sorted(v for v in out if low <= v <= high)


EDGES_I64 = _edges(
    [0, 1 << 31, -(1 << 31), 1 << 32, -(1 << 32), I64_MIN, I64_MAX, 1 << 62, -(1 << 62)],
    I64_MIN,
    I64_MAX,
)
EDGES_U64 = _edges([0, 1 << 32, 1 << 63, M64, M32], 0, M64)
SHIFTS = [0, 1, 27, 31, 32, 33, 39, 58, 60, 62, 63, 64, 65, 96, 126, 127]


def _pairs() -> Iterator[tuple[int, int]]:
    return ((a, b) for a in EDGES_I64 for b in EDGES_I64)


def test_mul_shr_i64_edges() -> None:
    for (a, b), shift in itertools.product(_pairs(), SHIFTS):
        assert mul_shr_i64(a, b, shift) == c_mul_shr_i64(a, b, shift), (a, b, shift)


def test_mul_round_i64_edges() -> None:
    for (a, b), shift in itertools.product(_pairs(), [s for s in SHIFTS if 1 <= s <= 126]):
        assert mul_round_i64(a, b, shift) == c_mul_round_i64(a, b, shift), (a, b, shift)


def test_mul_shr_round_i64_edges_saturate_as_the_c() -> None:
    for (a, b), shift in itertools.product(_pairs(), [s for s in SHIFTS if 1 <= s <= 126]):
        errors = ErrorMask()
        value, saturated = c_mul_shr_round_i64(a, b, shift)
        assert mul_shr_round_i64(a, b, shift, errors) == value, (a, b, shift)
        assert errors.has(ErrorFlag.SATURATION) == saturated


def test_mul_sat_i64_edges() -> None:
    for a, b in _pairs():
        errors = ErrorMask()
        value, saturated = c_mul_sat_i64(a, b)
        assert mul_sat_i64(a, b, errors) == value, (a, b)
        assert errors.has(ErrorFlag.SATURATION) == saturated


def test_mul_add_hi_and_mul_sub_wrap_edges() -> None:
    for a, b, c, d in itertools.product(EDGES_I64[::2], repeat=4):
        assert mul_add_hi_i64(a, b, c, d) == c_mul_add_hi_i64(a, b, c, d), (a, b, c, d)
        assert mul_sub_wrap_i64(a, b, c, d) == c_mul_sub_wrap_i64(a, b, c, d), (a, b, c, d)
    assert mul_add_hi_i64(I64_MIN, I64_MIN, I64_MIN, I64_MIN) == I64_MIN  # 2^127 wraps, as in C


def test_muldiv_round_u64_edges() -> None:
    for a, b, c in itertools.product(EDGES_U64, EDGES_U64, [*EDGES_U64, 3, 7, 1 << 40]):
        errors = ErrorMask()
        value, saturated = c_muldiv_round_u64(a, b, c)
        assert muldiv_round_u64(a, b, c, errors) == value, (a, b, c)
        assert errors.has(ErrorFlag.SATURATION) == saturated


# --- hypothesis ----------------------------------------------------------------------------------

I64 = st.integers(I64_MIN, I64_MAX)
U64 = st.integers(0, M64)


@settings(max_examples=3000)
@given(I64, I64, st.integers(0, 127))
def test_mul_shr_i64_property(a: int, b: int, shift: int) -> None:
    assert mul_shr_i64(a, b, shift) == c_mul_shr_i64(a, b, shift)


@settings(max_examples=3000)
@given(I64, I64, st.integers(1, 126))
def test_mul_round_i64_property(a: int, b: int, shift: int) -> None:
    assert mul_round_i64(a, b, shift) == c_mul_round_i64(a, b, shift)
    errors = ErrorMask()
    assert mul_shr_round_i64(a, b, shift, errors) == c_mul_shr_round_i64(a, b, shift)[0]


@settings(max_examples=3000)
@given(I64, I64)
def test_mul_sat_i64_property(a: int, b: int) -> None:
    errors = ErrorMask()
    value, saturated = c_mul_sat_i64(a, b)
    assert mul_sat_i64(a, b, errors) == value
    assert errors.has(ErrorFlag.SATURATION) == saturated


@settings(max_examples=3000)
@given(I64, I64, I64, I64)
def test_mul_add_hi_and_mul_sub_wrap_property(a: int, b: int, c: int, d: int) -> None:
    assert mul_add_hi_i64(a, b, c, d) == c_mul_add_hi_i64(a, b, c, d)
    assert mul_sub_wrap_i64(a, b, c, d) == c_mul_sub_wrap_i64(a, b, c, d)


@settings(max_examples=1000)
@given(U64, U64, U64)
def test_muldiv_round_u64_property(a: int, b: int, c: int) -> None:
    assert muldiv_round_u64(a, b, c, ErrorMask()) == c_muldiv_round_u64(a, b, c)[0]


@pytest.mark.parametrize("shift", [1, 39, 60, 62, 65, 126])
def test_the_round_is_half_up_as_the_firmware_wrote_it(shift: int) -> None:
    """``mul_round_i64`` is ``(a*b + 2^(shift-1)) >> shift``, the expression it replaced: ties
    (``a*b`` an odd multiple of 2^(shift-1)) go up, for both signs."""
    half = 1 << (shift - 1)
    b = 1 << max(0, shift - 61)  # keeps a within i64
    unit = half // b  # a = unit gives a*b = half, a tie
    for k in (1, 3, -1, -3):
        for nudge in (-1, 0, 1):
            a = k * unit + nudge
            assert mul_round_i64(a, b, shift) == (a * b + half) >> shift
    assert mul_round_i64(unit, b, shift) == 1
    assert mul_round_i64(-unit, b, shift) == 0


DIV_Q62_DENS = [1 << 63, (1 << 64) - 1, 1 << 64, (1 << 64) + 1, (1 << 92) + 12345, (1 << 126) - 1]


@pytest.mark.parametrize("den", DIV_Q62_DENS + [-d for d in DIV_Q62_DENS])
def test_div_q62_i128_edges(den: int) -> None:
    for num in [0, 1, -1, I64_MAX, I64_MIN, 1 << 62, -(1 << 62) - 1]:
        if abs(num) > abs(den):
            continue
        got = div_q62_i128(num, den >> 64, den & M64)
        assert got == c_div_q62_i128(num, den >> 64, den & M64), (num, den)
        exact_q62 = Fraction(num << 62, den)
        assert abs(got - exact_q62) <= 1 + abs(exact_q62) / 2**62


@settings(max_examples=3000)
@given(I64, st.integers(-(1 << 29), 1 << 29).filter(bool))
def test_div_q62_i128_property(wrapped: int, turns: int) -> None:
    """The ratio a step turning n whole turns beyond its signed read takes: dtheta_w / dtheta,
    within one LSB plus the normalization's 2^-63 of the exact quotient."""
    den = wrapped + (turns << 64)
    got = div_q62_i128(wrapped, den >> 64, den & M64)
    assert got == c_div_q62_i128(wrapped, den >> 64, den & M64)
    exact_q62 = Fraction(wrapped << 62, den)
    assert abs(got - exact_q62) <= 1 + abs(exact_q62) / 2**62
    assert abs(got) <= 1 << 62
