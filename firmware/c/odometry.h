/* Integer-only dead reckoning of a differential-drive robot from raw wheel encoder counters
 * (firmware/odometry.py). */
#ifndef ODOCAN_ODOMETRY_H
#define ODOCAN_ODOMETRY_H

#include <stdbool.h>
#include <stdint.h>

#include "config.h"

#define ONE_Q62 (INT64_C(1) << 62)
#define ONE_Q60 (INT64_C(1) << 60)
#define STRAIGHT_LIMIT_Q60 (INT64_C(1) << 39) /* |u| < 2^-21 rad: the factor is 1 (straight) */
#define SERIES_SHORT_LIMIT_Q60 (INT64_C(1) << 57) /* |u| <= 1/8 rad: three series terms */
#define SPIN_LIMIT_Q49 (INT64_C(1) << 8) /* |dS| < 2^-41 m: below half an LSB of x (spin) */
#define Q49_TO_Q40_SHIFT 9u
#define DS_COS_TO_Q40_SHIFT 39u /* Q49 * Q30 = Q79 -> Q40 */

/* The dead-reckoning state. Runs in the periodic tick: no allocation. */
struct odometry {
    struct odom_constants consts;
    uint32_t *errors; /* the firmware's sticky u32 error mask */
    bool primed;
    uint32_t left_prev;
    uint32_t right_prev;
    int64_t x_q40_m;
    int64_t y_q40_m;
    uint64_t heading_bam64;
    int32_t heading_turns; /* whole turns of the unwrapped heading (carries of the BAM64) */
    uint64_t distance_q40_m;
    int64_t last_ds_q49_m;       /* dS of the last step (for the twist) */
    int64_t last_dheading_bam64; /* signed dtheta of the last step (for the twist) */
    int32_t last_dheading_turns; /* the whole turns of that step beyond it (|.| < 2^29) */
};

void odometry_init(struct odometry *odo, const struct odom_constants *consts, uint32_t *errors);
void odometry_reconfigure(struct odometry *odo, const struct odom_constants *consts);
void odometry_set_pose(struct odometry *odo, int64_t x_q40_m, int64_t y_q40_m,
                       uint64_t heading_bam64);
void odometry_unprime(struct odometry *odo);
bool odometry_step_counts(struct odometry *odo, uint32_t left_count, uint32_t right_count);
void odometry_step_deltas(struct odometry *odo, int32_t d_left, int32_t d_right);
int64_t chord_factor_q62(int64_t dheading_bam64);

#endif
