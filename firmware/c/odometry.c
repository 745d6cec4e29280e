/* Integer-only dead reckoning from raw wheel encoder counters (firmware/odometry.py).
 *
 * State: x_q40_m, y_q40_m (i64, Q40 metres), heading_bam64 (u64, a turn is 2^64: the exact sum
 * of per-count constants, never rounded), distance_q40_m (u64, Q40 metres). Per step, dS is held
 * as the Q48 sum dS_R + dS_L (dS in Q49, unrounded), dtheta = k_R dR - k_L dL in BAM64 (exact mod
 * 2^64). EULER: heading first, then x += dS cos(phi). RK2: x += dS cos(phi + dtheta/2). EXACT:
 * the RK2 step scaled by the chord factor sin(u)/u, u = dtheta/2, with the straight (|u| < 2^-21
 * rad: factor 1) and spin (|dS| < 2^-41 m: no move) cases. A step turning more than half a turn
 * is integrated whole: the exact 97-bit dtheta's high word gives the whole turns n beyond the
 * signed read; heading_turns takes them, RK2's midpoint moves by n pi, EXACT's chord is scaled by
 * dtheta_w / dtheta. See the Python module's docstring.
 */
#include "odometry.h"

#include "fixmath.h"
#include "trig.h"

/* (2k)(2k+1): the Horner denominators of sin(u)/u = 1 - u^2/(2*3) (1 - u^2/(4*5) (...)). */
static const uint64_t SINC_DENOMINATORS[8] = {6u, 20u, 42u, 72u, 110u, 156u, 210u, 272u};

static void advance(struct odometry *odo, int64_t ds_q49_m, uint64_t direction_bam64);
static int64_t scale_q62(int64_t value, int64_t factor_q62);

void odometry_init(struct odometry *odo, const struct odom_constants *consts, uint32_t *errors)
{
    odo->consts = *consts;
    odo->errors = errors;
    odo->primed = false;
    odo->left_prev = 0u;
    odo->right_prev = 0u;
    odo->x_q40_m = 0;
    odo->y_q40_m = 0;
    odo->heading_bam64 = 0u;
    odo->heading_turns = 0;
    odo->distance_q40_m = 0u;
    odo->last_ds_q49_m = 0;
    odo->last_dheading_bam64 = 0;
    odo->last_dheading_turns = 0;
}

/* Use new constants from the next step on; the pose and the counter history are kept. */
void odometry_reconfigure(struct odometry *odo, const struct odom_constants *consts)
{
    odo->consts = *consts;
}

/* Overwrite the pose (ODOM_SET_POSE); distance travelled and counters are kept. */
void odometry_set_pose(struct odometry *odo, int64_t x_q40_m, int64_t y_q40_m,
                       uint64_t heading_bam64)
{
    odo->x_q40_m = x_q40_m;
    odo->y_q40_m = y_q40_m;
    odo->heading_bam64 = heading_bam64;
    odo->heading_turns = 0;
}

/* Forget the last counters: the next step_counts only re-primes (after a gap). */
void odometry_unprime(struct odometry *odo)
{
    odo->primed = false;
}

/* Integrate from raw wrapping counters (counter_bits wide, unsigned). The first call after start
 * only primes; deltas are wrap_signed(now - prev, bits), the ODrive way. True when integrated. */
bool odometry_step_counts(struct odometry *odo, uint32_t left_count, uint32_t right_count)
{
    unsigned bits = odo->consts.counter_bits;
    if (!odo->primed) {
        odo->left_prev = left_count;
        odo->right_prev = right_count;
        odo->primed = true;
        return false;
    }
    int32_t d_left = wrap_signed(left_count - odo->left_prev, bits);
    int32_t d_right = wrap_signed(right_count - odo->right_prev, bits);
    odo->left_prev = left_count;
    odo->right_prev = right_count;
    odometry_step_deltas(odo, d_left, d_right);
    return true;
}

/* Integrate one step of count deltas (i32 each) with the configured integrator. */
void odometry_step_deltas(struct odometry *odo, int32_t d_left, int32_t d_right)
{
    const struct odom_constants *c = &odo->consts;
    int64_t ds_left = wide_sat_i64(wide_mul_i64(d_left, c->m_per_count_left_q48_m), odo->errors);
    int64_t ds_right =
        wide_sat_i64(wide_mul_i64(d_right, c->m_per_count_right_q48_m), odo->errors);
    int64_t ds_q49_m =
        wide_sat_i64(wide_add(wide_from_i64(ds_left), wide_from_i64(ds_right)), odo->errors);
    /* (u64)d * k wraps mod 2^64 exactly as Python's wrap_i64 of the exact products */
    int64_t dheading = to_i64((uint64_t)(int64_t)d_right * c->bam64_per_count_right
                              - (uint64_t)(int64_t)d_left * c->bam64_per_count_left);
    /* the high word of the exact difference (< 2^93): the whole turns beyond the signed read
     * (|turns| < 2^29), non-zero only for a step turning more than half a turn */
    wide128_t exact = wide_sub(wide_mul_i64(d_right, (int64_t)c->bam64_per_count_right),
                               wide_mul_i64(d_left, (int64_t)c->bam64_per_count_left));
    int64_t dheading_hi = to_i64(exact.hi);
    int64_t turns = dheading < 0 ? dheading_hi + 1 : dheading_hi;
    uint64_t heading_old = odo->heading_bam64;
    odo->heading_bam64 = heading_old + (uint64_t)dheading;
    int64_t carry = 0;
    if (dheading >= 0 && odo->heading_bam64 < heading_old) { /* the unsigned add's carry */
        carry = 1;
    } else if (dheading < 0 && odo->heading_bam64 > heading_old) { /* its borrow */
        carry = -1;
    }
    if (carry != 0 || turns != 0) {
        odo->heading_turns = wrap_i32((int64_t)odo->heading_turns + carry + turns);
    }
    odo->last_ds_q49_m = ds_q49_m;
    odo->last_dheading_bam64 = dheading;
    odo->last_dheading_turns = (int32_t)turns; /* |turns| < 2^29 */
    if (ds_q49_m == 0) {
        return;
    }
    odo->distance_q40_m += (abs_u64(ds_q49_m) + (UINT64_C(1) << 8)) >> Q49_TO_Q40_SHIFT;
    if (c->integrator == INTEGRATOR_EULER) {
        advance(odo, ds_q49_m, odo->heading_bam64);
        return;
    }
    uint64_t midpoint_bam64 = heading_old + (uint64_t)asr_i64(dheading, 1);
    if (c->integrator == INTEGRATOR_EXACT) {
        if (-SPIN_LIMIT_Q49 < ds_q49_m && ds_q49_m < SPIN_LIMIT_Q49) {
            return;
        }
        int64_t factor_q62 = chord_factor_q62(dheading);
        if (turns != 0) { /* the arc of the whole step: the wrapped chord times dtheta_w/dtheta */
            factor_q62 = scale_q62(factor_q62, div_q62_i128(dheading, dheading_hi, exact.lo));
        }
        ds_q49_m = scale_q62(ds_q49_m, factor_q62);
    } else if (((uint64_t)turns & 1u) != 0u) { /* RK2: each whole turn moves the midpoint by pi */
        midpoint_bam64 ^= UINT64_C(1) << 63;
    }
    advance(odo, ds_q49_m, midpoint_bam64);
}

/* x += dS cos(direction), y += dS sin(direction); direction rounded to BAM32 for sincos.
 * ds_q49_m * cos_q30 is an i94 (wide); shifted to Q40 it is below 2^55, the sum saturates. */
static void advance(struct odometry *odo, int64_t ds_q49_m, uint64_t direction_bam64)
{
    int32_t sin_q30_v;
    int32_t cos_q30_v;
    sincos_q30((uint32_t)((direction_bam64 + (UINT64_C(1) << 31)) >> 32), &sin_q30_v, &cos_q30_v);
    wide128_t half = wide_from_u64(UINT64_C(1) << (DS_COS_TO_Q40_SHIFT - 1u));
    wide128_t dx = wide_asr(wide_add(wide_mul_i64(ds_q49_m, cos_q30_v), half), DS_COS_TO_Q40_SHIFT);
    wide128_t dy = wide_asr(wide_add(wide_mul_i64(ds_q49_m, sin_q30_v), half), DS_COS_TO_Q40_SHIFT);
    odo->x_q40_m = wide_sat_i64(wide_add(wide_from_i64(odo->x_q40_m), dx), odo->errors);
    odo->y_q40_m = wide_sat_i64(wide_add(wide_from_i64(odo->y_q40_m), dy), odo->errors);
}

/* sin(u)/u for u = dtheta/2, in Q62 (1.0 = 2^62), from a signed i64 BAM64 step.
 *
 * |u| < 2^-21 rad: exactly 1 (straight). Otherwise the Horner series in Q60: three terms while
 * |u| <= 1/8 rad, eight up to |u| = pi/2. Widths: dheading * TWO_PI_Q60 is an i127 (wide);
 * u_q60 <= pi/2 * 2^60 < 2^61; u_q60^2 < 2^122 (wide), u2_q60 < 2^62; u2_q60 * acc_q60 < 2^122
 * (wide), >> 60 below 2^62; acc_q60 stays in (0.58, 1] * 2^60 (each term is 1 - x, x <= 0.42).
 */
int64_t chord_factor_q62(int64_t dheading_bam64)
{
    wide128_t product = wide_mul_i64(dheading_bam64, TWO_PI_Q60);
    wide128_t one_q65 = {1u, 0u}; /* 2^64: half an LSB of the >> 65 */
    uint64_t u_q60 = abs_u64(wide_to_i64(wide_asr(wide_add(product, one_q65), 65)));
    if (u_q60 < (uint64_t)STRAIGHT_LIMIT_Q60) {
        return ONE_Q62;
    }
    wide128_t u2_round = wide_from_u64(UINT64_C(1) << 59);
    uint64_t u2_q60 = wide_asr(wide_add(wide_mul_u64(u_q60, u_q60), u2_round), 60).lo;
    unsigned terms = u_q60 <= (uint64_t)SERIES_SHORT_LIMIT_Q60 ? 3u : 8u;
    uint64_t acc_q60 = (uint64_t)ONE_Q60;
    for (unsigned k = terms; k-- > 0u;) {
        uint64_t term_q60 = wide_asr(wide_mul_u64(u2_q60, acc_q60), 60).lo;
        acc_q60 = (uint64_t)ONE_Q60 - term_q60 / SINC_DENOMINATORS[k];
    }
    return (int64_t)(acc_q60 << 2);
}

/* value * factor for a Q62 factor in (-1, 1]: rounds (half up), never leaves the width of value. */
static int64_t scale_q62(int64_t value, int64_t factor_q62)
{
    if (factor_q62 == ONE_Q62) {
        return value;
    }
    wide128_t half = wide_from_u64(UINT64_C(1) << 61);
    return wide_to_i64(wide_asr(wide_add(wide_mul_i64(value, factor_q62), half), 62));
}
