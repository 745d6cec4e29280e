/* C integer widths: wrap, saturate and rounding helpers (firmware/fixmath.py, same order).
 *
 * wrap_u16/u32/u64 and wrap_i16/i64 of the Python module are plain C conversions (or `to_i64`,
 * fixmath.h); the helpers below are those that need code.
 */
#include "fixmath.h"

/* (int16_t)(uint16_t)value: two's-complement reinterpretation of the low 16 bits. */
int16_t wrap_i16(int64_t value)
{
    uint32_t bits = (uint32_t)((uint64_t)value & 0xFFFFu);
    return (int16_t)(bits >= 0x8000u ? (int32_t)bits - 0x10000 : (int32_t)bits);
}

/* (int32_t)(uint32_t)value: two's-complement reinterpretation of the low 32 bits. */
int32_t wrap_i32(int64_t value)
{
    return to_i32((uint32_t)((uint64_t)value & 0xFFFFFFFFu));
}

/* Two's-complement reinterpretation of the low `bits` bits (16 or 32: counter deltas).
 * `value` is the u32 difference of two counters (mod 2^32, which keeps the low `bits` bits). */
int32_t wrap_signed(uint32_t value, unsigned bits)
{
    uint32_t half = (uint32_t)1u << (bits - 1u);
    uint32_t mask = bits >= 32u ? UINT32_MAX : ((uint32_t)1u << bits) - 1u;
    return (int32_t)((int64_t)((value + half) & mask) - (int64_t)half);
}

/* Clamp to [low, high] (a raw signal's range); set SATURATION when clamped. */
int64_t sat_range(int64_t value, int64_t low, int64_t high, uint32_t *errors)
{
    if (value > high) {
        *errors |= ERROR_SATURATION;
        return high;
    }
    if (value < low) {
        *errors |= ERROR_SATURATION;
        return low;
    }
    return value;
}

/* sat_i64(round((a * b) / 2^shift)), 1 <= shift <= 127: the full 128-bit product, rounded half
 * up, then saturated (the rounding add cannot overflow 128 bits: |a * b| <= 2^126). */
int64_t mul_shr_round_i64(int64_t a, int64_t b, unsigned shift, uint32_t *errors)
{
    wide128_t half;
    if (shift > 64u) {
        half.hi = (uint64_t)1u << (shift - 65u);
        half.lo = 0u;
    } else {
        half = wide_from_u64((uint64_t)1u << (shift - 1u));
    }
    wide128_t rounded = wide_asr(wide_add(wide_mul_i64(a, b), half), shift);
    return wide_sat_i64(rounded, errors);
}

/* num * 2^62 / den rounded half away from zero, for the i128 den = den_hi * 2^64 + den_lo with
 * 2^63 <= |den| < 2^126 and |num| <= |den|: the result is in [-2^62, 2^62]. |den| normalized to
 * its top 64 bits (truncated: relative error below 2^-63), the numerator scaled by 2^(62 - sh):
 * the quotient fits (<= 2^62), so the muldiv never saturates. */
int64_t div_q62_i128(int64_t num, int64_t den_hi, uint64_t den_lo)
{
    wide128_t den;
    den.hi = (uint64_t)den_hi;
    den.lo = den_lo;
    if (den_hi < 0) {
        den = wide_sub(wide_from_u64(0u), den);
    }
    unsigned sh = bit_length_u64(den.hi);
    uint64_t top = sh == 0u ? den.lo : (den.hi << (64u - sh)) | (den.lo >> sh);
    uint32_t scratch = 0u;
    uint64_t quotient = muldiv_round_u64(abs_u64(num), (uint64_t)1u << (62u - sh), top, &scratch);
    return (num < 0) != (den_hi < 0) ? -(int64_t)quotient : (int64_t)quotient;
}

/* round(a * b / c) with a 128-bit intermediate; saturates to u64; c == 0 gives U64_MAX.
 * Configuration time only: a bit-serial 128/64 restoring division (64 steps), as Linux's
 * mul_u64_u64_div_u64 plus rounding. a * b + c/2 < 2^128, so the dividend never overflows. */
uint64_t muldiv_round_u64(uint64_t a, uint64_t b, uint64_t c, uint32_t *errors)
{
    if (c == 0u) {
        *errors |= ERROR_SATURATION;
        return U64_MAX;
    }
    wide128_t n = wide_add(wide_mul_u64(a, b), wide_from_u64(c >> 1));
    if (n.hi >= c) { /* the quotient is >= 2^64 */
        *errors |= ERROR_SATURATION;
        return U64_MAX;
    }
    uint64_t rem = n.hi; /* < c */
    uint64_t quotient = 0u;
    for (int bit = 63; bit >= 0; --bit) {
        uint64_t carry = rem >> 63; /* the 65th bit of rem << 1 */
        rem = (rem << 1) | ((n.lo >> bit) & 1u);
        quotient <<= 1;
        if (carry != 0u || rem >= c) {
            rem -= c; /* mod 2^64: exact, the true remainder is < c */
            quotient |= 1u;
        }
    }
    return quotient;
}

/* Signed division rounding half away from zero, denominator > 0 (C: truncating `/` on the
 * magnitudes, in u64 so that |I64_MIN| and the rounding add cannot overflow). */
int64_t div_round_i64(int64_t numerator, int64_t denominator)
{
    uint64_t den = (uint64_t)denominator;
    uint64_t half = den >> 1;
    if (numerator >= 0) {
        return (int64_t)(((uint64_t)numerator + half) / den);
    }
    return to_i64(0u - (abs_u64(numerator) + half) / den); /* -q, q <= 2^63 */
}

/* The number of significant bits of a u64 (Python's int.bit_length; C: 64 - clz). */
unsigned bit_length_u64(uint64_t value)
{
    unsigned bits = 0u;
    for (unsigned step = 32u; step != 0u; step >>= 1) {
        if ((value >> step) != 0u) {
            value >>= step;
            bits += step;
        }
    }
    return bits + (unsigned)value; /* value is now 0 or 1 */
}

/* floor(sqrt(n)) of a u64 (result u32), by Newton's method on integers: the start
 * 2^ceil(bits(n)/2) >= sqrt(n), then x <- (x + n/x) / 2 until it stops decreasing. */
uint32_t isqrt_u64(uint64_t n)
{
    if (n < 2u) {
        return (uint32_t)n;
    }
    uint64_t x = (uint64_t)1u << ((bit_length_u64(n) + 1u) >> 1); /* <= 2^32 */
    uint64_t y = (x + n / x) >> 1;
    while (y < x) {
        x = y;
        y = (x + n / x) >> 1;
    }
    return (uint32_t)x;
}
