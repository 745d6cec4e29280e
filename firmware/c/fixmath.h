/* C integer widths, two's-complement wrap and saturate helpers, rounding shifts (firmware/fixmath.py).
 *
 * C99, no floats, no __int128: a product wider than 64 bits is a `wide128_t` built from four
 * 32x32->64 partial products (UMULL/SMULL on a Cortex-M3/M4), exactly the Python integer result.
 *
 * Shifts of negative numbers: C99 leaves `>>` of a negative value implementation-defined and `<<`
 * of a negative value undefined. This port never relies on either: `asr_i64` and `wide_asr` are
 * the arithmetic floor shift (Python's `>>`) written with unsigned operations only, and signed
 * values are built from unsigned ones by `to_i64`/`to_i32`, which never use an out-of-range
 * conversion. The wide helpers are `static inline` here (the per-step path); the rest is in
 * fixmath.c, in the order of fixmath.py.
 */
#ifndef ODOCAN_FIXMATH_H
#define ODOCAN_FIXMATH_H

#include <stdint.h>

#include "errors.h"

#define U8_MAX UINT8_MAX
#define U16_MAX UINT16_MAX
#define U32_MAX UINT32_MAX
#define U64_MAX UINT64_MAX
#define I16_MIN INT16_MIN
#define I16_MAX INT16_MAX
#define I32_MIN INT32_MIN
#define I32_MAX INT32_MAX
#define I64_MIN INT64_MIN
#define I64_MAX INT64_MAX

/* A 128-bit two's-complement value hi * 2^64 + lo (hi read as signed where signed is meant). */
typedef struct {
    uint64_t hi;
    uint64_t lo;
} wide128_t;

/* (int64_t)value without an implementation-defined conversion: the bits of a u64 read as i64. */
static inline int64_t to_i64(uint64_t value)
{
    if (value <= (uint64_t)INT64_MAX) {
        return (int64_t)value;
    }
    return -(int64_t)(~value) - 1;
}

/* (int32_t)value, likewise, for a u32. */
static inline int32_t to_i32(uint32_t value)
{
    if (value <= (uint32_t)INT32_MAX) {
        return (int32_t)value;
    }
    return -(int32_t)(~value) - 1;
}

/* Python's `value >> shift` (floor) for an i64, 0 <= shift <= 63, with unsigned shifts only. */
static inline int64_t asr_i64(int64_t value, unsigned shift)
{
    if (value >= 0) {
        return value >> shift;
    }
    return to_i64(~((~(uint64_t)value) >> shift));
}

/* |value| as a u64 (|I64_MIN| = 2^63 fits). */
static inline uint64_t abs_u64(int64_t value)
{
    return value < 0 ? 0u - (uint64_t)value : (uint64_t)value;
}

static inline wide128_t wide_from_i64(int64_t value)
{
    wide128_t w;
    w.hi = value < 0 ? UINT64_MAX : 0u;
    w.lo = (uint64_t)value;
    return w;
}

static inline wide128_t wide_from_u64(uint64_t value)
{
    wide128_t w;
    w.hi = 0u;
    w.lo = value;
    return w;
}

/* hi * 2^64 + lo for hi an i64: `(int128)hi << 64` (Python `hi << 64`). */
static inline wide128_t wide_shl64(int64_t hi)
{
    wide128_t w;
    w.hi = (uint64_t)hi;
    w.lo = 0u;
    return w;
}

static inline wide128_t wide_add(wide128_t a, wide128_t b)
{
    wide128_t w;
    w.lo = a.lo + b.lo;
    w.hi = a.hi + b.hi + (w.lo < a.lo ? 1u : 0u);
    return w;
}

static inline wide128_t wide_sub(wide128_t a, wide128_t b)
{
    wide128_t w;
    w.lo = a.lo - b.lo;
    w.hi = a.hi - b.hi - (a.lo < b.lo ? 1u : 0u);
    return w;
}

/* The exact u64 x u64 product: four 32x32->64 partial products (UMULL), summed with carries. */
static inline wide128_t wide_mul_u64(uint64_t a, uint64_t b)
{
    uint64_t a_lo = a & 0xFFFFFFFFu;
    uint64_t a_hi = a >> 32;
    uint64_t b_lo = b & 0xFFFFFFFFu;
    uint64_t b_hi = b >> 32;
    uint64_t p0 = a_lo * b_lo;
    uint64_t p1 = a_lo * b_hi;
    uint64_t p2 = a_hi * b_lo;
    uint64_t p3 = a_hi * b_hi;
    uint64_t mid = (p0 >> 32) + (p1 & 0xFFFFFFFFu) + (p2 & 0xFFFFFFFFu); /* < 3 * 2^32 */
    wide128_t w;
    w.lo = (mid << 32) | (p0 & 0xFFFFFFFFu);
    w.hi = p3 + (p1 >> 32) + (p2 >> 32) + (mid >> 32);
    return w;
}

/* The exact i64 x i64 product: the unsigned product of the bit patterns, high half corrected. */
static inline wide128_t wide_mul_i64(int64_t a, int64_t b)
{
    wide128_t w = wide_mul_u64((uint64_t)a, (uint64_t)b);
    if (a < 0) {
        w.hi -= (uint64_t)b;
    }
    if (b < 0) {
        w.hi -= (uint64_t)a;
    }
    return w;
}

/* Python's `value >> shift` (floor) for a signed 128-bit value, 1 <= shift <= 127. */
static inline wide128_t wide_asr(wide128_t value, unsigned shift)
{
    uint64_t fill = (value.hi >> 63) != 0u ? UINT64_MAX : 0u;
    wide128_t w;
    if (shift >= 64u) {
        unsigned s = shift - 64u;
        w.lo = s == 0u ? value.hi : (value.hi >> s) | (fill << (64u - s));
        w.hi = fill;
    } else {
        w.lo = (value.lo >> shift) | (value.hi << (64u - shift));
        w.hi = (value.hi >> shift) | (fill << (64u - shift));
    }
    return w;
}

/* The low 64 bits as an i64, for a value the caller's bound proves fits (docstring of the use). */
static inline int64_t wide_to_i64(wide128_t value)
{
    return to_i64(value.lo);
}

/* sat_i64 of a 128-bit value: clamp to int64_t, set SATURATION in *errors when clamped. */
static inline int64_t wide_sat_i64(wide128_t value, uint32_t *errors)
{
    uint64_t sign_of_lo = (value.lo >> 63) != 0u ? UINT64_MAX : 0u;
    if (value.hi == sign_of_lo) {
        return to_i64(value.lo);
    }
    *errors |= ERROR_SATURATION;
    return (value.hi >> 63) != 0u ? INT64_MIN : INT64_MAX;
}

int16_t wrap_i16(int64_t value);
int32_t wrap_i32(int64_t value);
int32_t wrap_signed(uint32_t value, unsigned bits);
int64_t sat_range(int64_t value, int64_t low, int64_t high, uint32_t *errors);
int64_t mul_shr_round_i64(int64_t a, int64_t b, unsigned shift, uint32_t *errors);
int64_t div_q62_i128(int64_t num, int64_t den_hi, uint64_t den_lo);
uint64_t muldiv_round_u64(uint64_t a, uint64_t b, uint64_t c, uint32_t *errors);
int64_t div_round_i64(int64_t numerator, int64_t denominator);
unsigned bit_length_u64(uint64_t value);
uint32_t isqrt_u64(uint64_t n);

#endif
