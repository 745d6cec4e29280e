/* Robot parameters, their validation, and the derived Q constants (firmware/config.py).
 *
 * m_per_count_<wheel>_q48_m = round(2*pi*R / PPV) in Q48 metres (seed 002 eq. 5);
 * bam64_per_count_<wheel> = round(2^64 * R / (PPV * b)): pi cancels, so the heading is an exact
 * integer sum of these constants mod 2^64.
 */
#include "config.h"

#include "fixmath.h"

static int64_t m_per_count_q48(uint32_t radius_nm, const struct robot_params *params,
                               uint32_t *errors);
static uint64_t bam64_per_count(uint32_t radius_nm, const struct robot_params *params,
                                uint32_t *errors);

/* Check every parameter's range; CONFIG_OK when the whole set is usable. */
enum config_reason validate(const struct robot_params *params)
{
    if (params->counts_per_rev < COUNTS_PER_REV_MIN
        || params->counts_per_rev > COUNTS_PER_REV_MAX) {
        return CONFIG_COUNTS_PER_REV_OUT_OF_RANGE;
    }
    const uint32_t radii_nm[2] = {params->wheel_radius_left_nm, params->wheel_radius_right_nm};
    for (unsigned wheel = 0u; wheel < 2u; ++wheel) {
        if (radii_nm[wheel] < WHEEL_RADIUS_MIN_NM || radii_nm[wheel] > WHEEL_RADIUS_MAX_NM) {
            return CONFIG_WHEEL_RADIUS_OUT_OF_RANGE;
        }
    }
    if (params->wheelbase_nm < WHEELBASE_MIN_NM || params->wheelbase_nm > WHEELBASE_MAX_NM) {
        return CONFIG_WHEELBASE_OUT_OF_RANGE;
    }
    if (params->counter_bits != 16u && params->counter_bits != 32u) {
        return CONFIG_COUNTER_BITS_INVALID;
    }
    if (params->integrator > 2u) {
        return CONFIG_INTEGRATOR_INVALID;
    }
    uint32_t scratch = 0u;
    for (unsigned wheel = 0u; wheel < 2u; ++wheel) {
        if (bam64_per_count(radii_nm[wheel], params, &scratch) >= BAM64_PER_COUNT_MAX) {
            return CONFIG_GEOMETRY_ABSURD;
        }
    }
    return CONFIG_OK;
}

/* Q constants of a validated params (call validate first: ranges keep every width). */
void derive_constants(const struct robot_params *params, uint32_t *errors,
                      struct odom_constants *out)
{
    out->m_per_count_left_q48_m = m_per_count_q48(params->wheel_radius_left_nm, params, errors);
    out->m_per_count_right_q48_m = m_per_count_q48(params->wheel_radius_right_nm, params, errors);
    out->bam64_per_count_left = bam64_per_count(params->wheel_radius_left_nm, params, errors);
    out->bam64_per_count_right = bam64_per_count(params->wheel_radius_right_nm, params, errors);
    out->counter_bits = params->counter_bits;
    out->integrator = (enum integrator)params->integrator;
}

/* round(2*pi*R / PPV) in Q48 metres: circumference first (Q48, < 2^52), then per count. */
static int64_t m_per_count_q48(uint32_t radius_nm, const struct robot_params *params,
                               uint32_t *errors)
{
    uint64_t circumference_q48_m =
        muldiv_round_u64((uint64_t)TWO_PI_Q60, radius_nm, NM_PER_M << 12, errors);
    return (int64_t)muldiv_round_u64(circumference_q48_m, 1u, params->counts_per_rev, errors);
}

/* round(2^64 * R / (PPV * b)) as muldiv(R << 32, 2^32, PPV * b): every operand fits u64. */
static uint64_t bam64_per_count(uint32_t radius_nm, const struct robot_params *params,
                                uint32_t *errors)
{
    return muldiv_round_u64((uint64_t)radius_nm << 32, UINT64_C(1) << 32,
                            (uint64_t)params->counts_per_rev * params->wheelbase_nm, errors);
}
