/* Fixed-point trigonometry on binary angles: sincos_q30 and atan2_bam32 (firmware/trig.py).
 *
 * BAM32: a full turn is 2^32. sin and cos are i32 in Q30 (1.0 == 1 << 30). Same method, same
 * names, same order as the Python module; the docstrings there give the error bounds. Every
 * product wider than 64 bits is a wide128_t from 32x32->64 partial products (fixmath.h).
 */
#include "trig.h"

#include "fixmath.h"
#include "trig_tables.h"

/* Half an LSB of the Q30 result in Q126: 2^95, i.e. 2^31 in the high word. */
#define ROUND_Q126_TO_Q30_HI ((uint64_t)1u << 31)

/* Sine and cosine of a binary angle, both i32 in Q30, |error| <= 2^-31 + 2^-41.
 *
 * 1. Quadrant q = bits 31..30; r (u32 < 2^30) = the angle within the quadrant.
 * 2. Nearest knot i (0..256), ties to the even knot; d = r - i*2^22 (i32, |d| <= 2^21).
 * 3. Taylor terms in Q64 from d2 = d*d (u64 <= 2^42): sin_t = theta - theta^3/6 (i64,
 *    |.| < 2^56), om = 1 - cos(theta) (u64 < 2^47); d2 * coefficient is a u96 (wide), shifted
 *    back below 2^64. cos_t = 2^64 - om is never materialised: s*cos_t = (s << 64) - s*om.
 * 4. sin = s*cos_t + c*sin_t, cos = c*cos_t - s*sin_t: i128 sums of Q126 products
 *    (0 <= sum < 2^126 + 2^86), rounded once (half up) to Q30 by >> 96: 0..2^30.
 * 5. The quadrant permutes and negates (sin, cos) exactly.
 */
void sincos_q30(uint32_t angle_bam32, int32_t *sin_out_q30, int32_t *cos_out_q30)
{
    uint32_t r = angle_bam32 & 0x3FFFFFFFu;
    uint32_t i = (r + 0x1FFFFFu + ((r >> 22) & 1u)) >> 22;
    int32_t d = (int32_t)r - (int32_t)(i << 22);
    uint64_t d2 = (uint64_t)((int64_t)d * d);
    uint64_t k3_term = wide_asr(wide_mul_u64(d2, SIN_K3), SIN_K3_SHIFT).lo; /* < 2^16 */
    int64_t sin_t = (int64_t)d * (int64_t)(SIN_STEP_Q64 - k3_term);
    uint64_t k4_term = wide_asr(wide_mul_u64(d2, SIN_K4), SIN_K4_SHIFT).lo; /* < 2^12 */
    uint64_t om = wide_asr(wide_mul_u64(d2, SIN_K2 - k4_term), SIN_K2_SHIFT).lo; /* < 2^47 */
    int64_t s = SIN_Q62[i];
    int64_t c = SIN_Q62[256u - i];
    wide128_t half = {ROUND_Q126_TO_Q30_HI, 0u};
    wide128_t sin_w = wide_sub(wide_shl64(s), wide_mul_u64((uint64_t)s, om));
    sin_w = wide_add(wide_add(sin_w, wide_mul_i64(c, sin_t)), half);
    wide128_t cos_w = wide_sub(wide_shl64(c), wide_mul_u64((uint64_t)c, om));
    cos_w = wide_add(wide_sub(cos_w, wide_mul_i64(s, sin_t)), half);
    int32_t sin_r = (int32_t)wide_to_i64(wide_asr(sin_w, 96)); /* 0..2^30 */
    int32_t cos_r = (int32_t)wide_to_i64(wide_asr(cos_w, 96));
    switch ((angle_bam32 >> 30) & 3u) {
    case 0u:
        *sin_out_q30 = sin_r;
        *cos_out_q30 = cos_r;
        return;
    case 1u:
        *sin_out_q30 = cos_r;
        *cos_out_q30 = -sin_r;
        return;
    case 2u:
        *sin_out_q30 = -sin_r;
        *cos_out_q30 = -cos_r;
        return;
    default:
        *sin_out_q30 = -cos_r;
        *cos_out_q30 = sin_r;
        return;
    }
}

/* Sine of a BAM32 angle in Q30 (i32); bit-identical to sincos_q30's sine. */
int32_t sin_q30(uint32_t angle_bam32)
{
    int32_t s;
    int32_t c;
    sincos_q30(angle_bam32, &s, &c);
    return s;
}

/* Cosine of a BAM32 angle in Q30 (i32); bit-identical to sincos_q30's cosine. */
int32_t cos_q30(uint32_t angle_bam32)
{
    int32_t s;
    int32_t c;
    sincos_q30(angle_bam32, &s, &c);
    return c;
}

/* The angle of the vector (x, y) as a signed BAM32 in [-2^31, 2^31); atan2(0, 0) = 0.
 *
 * 1. Octant reduction: m >= n >= 0 the larger and smaller magnitude (u64 <= 2^63).
 * 2. Normalise so that m is in [2^46, 2^47) (C: clz).
 * 3. Knot k = (n << 8) / m (0..256), atan(n/m) = atan(k/256) + atan(u),
 *    u = (256n - km) / (256m + kn): num < 2^47 and den in [2^54, 2^56), u64.
 * 4. u_q39 = (num << 15) / (den >> 24): u64 / u32; u_q39 <= 2^31 + 2.
 * 5. atan(u) = u*(1 - u^2/3) straight into BAM48: the product is a u64 < 2^64.
 * 6. Add atan(k/256) (BAM48), round once to BAM32, unfold the octant in i64, wrap to i32.
 */
int32_t atan2_bam32(int64_t y, int64_t x)
{
    uint64_t ax = abs_u64(x);
    uint64_t ay = abs_u64(y);
    int swap = ay > ax;
    uint64_t m = swap ? ay : ax;
    uint64_t n = swap ? ax : ay;
    if (m == 0u) {
        return 0;
    }
    int shift = (int)bit_length_u64(m) - 47;
    if (shift > 0) {
        m >>= shift;
        n >>= shift;
    } else {
        m <<= -shift;
        n <<= -shift;
    }
    uint64_t n8 = n << 8;
    uint64_t k = n8 / m;
    uint64_t u_q39 = ((n8 - k * m) << 15) / (((m << 8) + k * n) >> 24);
    uint64_t u2_q39 = (u_q39 * u_q39) >> 39;
    uint64_t phi_u_bam48 = (u_q39 * (ATAN_K1 - ((u2_q39 * ATAN_K3) >> 40))) >> ATAN_K1_SHIFT;
    int64_t phi = (int64_t)((ATAN_BAM48[k] + phi_u_bam48 + 0x8000u) >> 16);
    if (swap) {
        phi = QUARTER_BAM32 - phi;
    }
    if (x < 0) {
        phi = HALF_BAM32 - phi;
        if (phi == HALF_BAM32) { /* +pi: the i32 wrap gives -2^31 */
            return INT32_MIN;
        }
    }
    if (y < 0) {
        return (int32_t)-phi;
    }
    return (int32_t)phi;
}
