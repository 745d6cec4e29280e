/* Robot parameters as the firmware receives them, their validation, the derived Q constants
 * (firmware/config.py). */
#ifndef ODOCAN_CONFIG_H
#define ODOCAN_CONFIG_H

#include <stdint.h>

/* 2*pi in Q60 (i64), correctly rounded: round(2*pi * 2^60). */
#define TWO_PI_Q60 INT64_C(7244019458077122842)
#define NM_PER_M UINT64_C(1000000000)

#define COUNTS_PER_REV_MIN 1u
#define COUNTS_PER_REV_MAX (1u << 24)
#define WHEEL_RADIUS_MIN_NM 1000000u       /* 1 mm */
#define WHEEL_RADIUS_MAX_NM 2000000000u    /* 2 m */
#define WHEELBASE_MIN_NM 10000000u         /* 10 mm */
#define WHEELBASE_MAX_NM 4000000000u       /* 4 m (u32 holds 4.29 m) */
/* The fastest rim speed either wheel can reach (u16 mm/s, ODOM_CONFIG MAX_WHEEL_SPEED): an encoder
 * step beyond it is implausible. A robot that states none is bounded at the default. */
#define MAX_WHEEL_SPEED_DEFAULT_MM_S 4000u
#define MAX_WHEEL_SPEED_MIN_MM_S 1u
#define MAX_WHEEL_SPEED_MAX_MM_S 65535u /* the signal's u16 */
/* One encoder count may turn the robot by at most 1/16 turn: beyond that the parameters are absurd. */
#define BAM64_PER_COUNT_MAX (UINT64_C(1) << 60)
#define ENCODER_PERIOD_US 10000 /* WHEEL_ENCODERS GenMsgCycleTime */
#define WIRE_COUNTER_BITS 24u   /* WHEEL_ENCODERS carries the low 24 bits of each counter */
#define READABLE_PERIODS 2u /* a step of this many periods at the maximum speed reads unwrapped */

/* Odometry integrator (the INTEGRATOR signal). */
enum integrator {
    INTEGRATOR_EULER = 0, /* seed 000 eq. 15: heading first, then x += dS cos(phi_new) */
    INTEGRATOR_RK2 = 1,   /* seed 004: midpoint heading */
    INTEGRATOR_EXACT = 2  /* seeds 003/004: the arc about the ICC, straight and spin cases */
};

/* Why a configuration was accepted or refused (the ack/nack reason code). */
enum config_reason {
    CONFIG_OK = 0,
    CONFIG_COUNTS_PER_REV_OUT_OF_RANGE = 1,
    CONFIG_WHEEL_RADIUS_OUT_OF_RANGE = 2,
    CONFIG_WHEELBASE_OUT_OF_RANGE = 3,
    CONFIG_COUNTER_BITS_INVALID = 4,
    CONFIG_INTEGRATOR_INVALID = 5,
    CONFIG_GEOMETRY_ABSURD = 6, /* one count would turn the robot by more than 1/16 turn */
    CONFIG_WIRE_RANGE = 7,      /* a step at the maximum wheel speed could wrap the counters */
    CONFIG_MAX_WHEEL_SPEED_OUT_OF_RANGE = 8 /* outside MAX_WHEEL_SPEED_MIN_MM_S .. _MAX_MM_S */
};

/* Robot parameters as raw integers (u32 each), exactly as ODOM_CONFIG carries them;
 * max_wheel_speed_mm_s (u16 on the wire) bounds a plausible encoder step. */
struct robot_params {
    uint32_t counts_per_rev;
    uint32_t wheel_radius_left_nm;
    uint32_t wheel_radius_right_nm;
    uint32_t wheelbase_nm;
    uint32_t counter_bits;
    uint32_t integrator;
    uint32_t max_wheel_speed_mm_s;
};

/* Fixed-point constants derived once from robot_params. */
struct odom_constants {
    int64_t m_per_count_left_q48_m;
    int64_t m_per_count_right_q48_m;
    uint64_t bam64_per_count_left;  /* < 2^60 */
    uint64_t bam64_per_count_right; /* < 2^60 */
    uint32_t counter_bits;          /* 16 or 32 */
    enum integrator integrator;
};

enum config_reason validate(const struct robot_params *params);
enum config_reason validate_at_speed(const struct robot_params *params,
                                     uint32_t max_wheel_speed_mm_s);
uint64_t max_counts_per_period(uint64_t per_count_q48_m, uint32_t max_wheel_speed_mm_s,
                               uint32_t *errors);
void derive_constants(const struct robot_params *params, uint32_t *errors,
                      struct odom_constants *out);
uint32_t profile_crc32(const struct robot_params *params);

#endif
