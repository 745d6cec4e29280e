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
    if (params->max_wheel_speed_mm_s < MAX_WHEEL_SPEED_MIN_MM_S
        || params->max_wheel_speed_mm_s > MAX_WHEEL_SPEED_MAX_MM_S) {
        return CONFIG_MAX_WHEEL_SPEED_OUT_OF_RANGE;
    }
    uint32_t scratch = 0u;
    for (unsigned wheel = 0u; wheel < 2u; ++wheel) {
        if (bam64_per_count(radii_nm[wheel], params, &scratch) >= BAM64_PER_COUNT_MAX) {
            return CONFIG_GEOMETRY_ABSURD;
        }
    }
    return CONFIG_OK;
}

/* validate, then the counters' readable range at max_wheel_speed_mm_s (the ECU's plausibility
 * bound): CONFIG_WIRE_RANGE when a step of READABLE_PERIODS periods at that speed could move a
 * wheel half the range its counters are read with (min(counter_bits, 24) bits) or more: it would
 * read wrapped, silently (config.py validate_at_speed). */
enum config_reason validate_at_speed(const struct robot_params *params,
                                     uint32_t max_wheel_speed_mm_s)
{
    enum config_reason reason = validate(params);
    if (reason != CONFIG_OK) {
        return reason;
    }
    unsigned bits = params->counter_bits < WIRE_COUNTER_BITS ? params->counter_bits
                                                             : WIRE_COUNTER_BITS;
    uint64_t half_range = UINT64_C(1) << (bits - 1u);
    const uint32_t radii_nm[2] = {params->wheel_radius_left_nm, params->wheel_radius_right_nm};
    uint32_t scratch = 0u;
    for (unsigned wheel = 0u; wheel < 2u; ++wheel) {
        uint64_t per_count = (uint64_t)m_per_count_q48(radii_nm[wheel], params, &scratch);
        if (READABLE_PERIODS * max_counts_per_period(per_count, max_wheel_speed_mm_s, &scratch)
            >= half_range) {
            return CONFIG_WIRE_RANGE;
        }
    }
    return CONFIG_OK;
}

/* The most counts one encoder period can hold at max_wheel_speed_mm_s: ceil(v_max * T / travel
 * per count) + 1, as the ECU's step_bounds. Configuration time: a 128-bit muldiv (travel <
 * 2^44), then u64 division (per_count_q48_m >= 1 for valid parameters); the ceiling as quotient
 * + (remainder != 0), Python's (a + m - 1) // m. */
uint64_t max_counts_per_period(uint64_t per_count_q48_m, uint32_t max_wheel_speed_mm_s,
                               uint32_t *errors)
{
    uint64_t travel_q48_m = muldiv_round_u64((uint64_t)max_wheel_speed_mm_s * ENCODER_PERIOD_US,
                                             UINT64_C(1) << 48, NM_PER_M, errors);
    return travel_q48_m / per_count_q48_m + (travel_q48_m % per_count_q48_m != 0u ? 1u : 0u)
           + 1u;
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

/* CRC-32/ISO-HDLC of the 20-byte parameter set ODOM_STATUS PROFILE_CRC covers (the DBC comment):
 * each field little-endian in ODOM_CONFIG PARAM order, filled byte by byte (the MCU's own byte
 * order does not matter); bit by bit, configuration time only (config.py profile_crc32). */
uint32_t profile_crc32(const struct robot_params *params)
{
    const uint32_t values[7] = {
        params->counts_per_rev, params->wheel_radius_left_nm, params->wheel_radius_right_nm,
        params->wheelbase_nm,   params->counter_bits,         params->integrator,
        params->max_wheel_speed_mm_s,
    };
    static const unsigned sizes[7] = {4u, 4u, 4u, 4u, 1u, 1u, 2u};
    uint32_t crc = 0xFFFFFFFFu;
    for (unsigned f = 0u; f < 7u; ++f) {
        for (unsigned k = 0u; k < sizes[f]; ++k) {
            crc ^= (values[f] >> (8u * k)) & 0xFFu;
            for (unsigned bit = 0u; bit < 8u; ++bit) {
                crc = (crc >> 1) ^ ((crc & 1u) != 0u ? 0xEDB88320u : 0u);
            }
        }
    }
    return crc ^ 0xFFFFFFFFu;
}
