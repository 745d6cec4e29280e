/* A steps-per-second figure for the C odometry (bench/c_port.py runs and times it).
 *
 * usage: bench_odometry STEPS INTEGRATOR COUNTS_PER_REV RADIUS_L_NM RADIUS_R_NM WHEELBASE_NM BITS
 *
 * Feeds STEPS counter pairs from a u32 LCG (Numerical Recipes' 1664525, 1013904223; the Python
 * side of bench/c_port.py draws the same stream) and prints the final state, so that the work
 * cannot be optimised away and the Python firmware can be checked against it.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>

#include "config.h"
#include "odometry.h"

static uint32_t lcg_next(uint32_t *state)
{
    *state = *state * 1664525u + 1013904223u;
    return *state >> 16;
}

int main(int argc, char **argv)
{
    if (argc != 8) {
        fprintf(stderr, "usage: bench_odometry STEPS INTEGRATOR PPV R_L_NM R_R_NM B_NM BITS\n");
        return 2;
    }
    long long steps = strtoll(argv[1], NULL, 10);
    struct robot_params params = {
        (uint32_t)strtoul(argv[3], NULL, 10), (uint32_t)strtoul(argv[4], NULL, 10),
        (uint32_t)strtoul(argv[5], NULL, 10), (uint32_t)strtoul(argv[6], NULL, 10),
        (uint32_t)strtoul(argv[7], NULL, 10), (uint32_t)strtoul(argv[2], NULL, 10),
    };
    if (validate(&params) != CONFIG_OK) {
        fprintf(stderr, "error: invalid parameters (reason %d)\n", (int)validate(&params));
        return 2;
    }
    uint32_t errors = 0u;
    struct odom_constants consts;
    derive_constants(&params, &errors, &consts);
    struct odometry odo;
    odometry_init(&odo, &consts, &errors);
    uint32_t state = 1u;
    uint32_t mask = params.counter_bits == 32u ? UINT32_MAX : (1u << params.counter_bits) - 1u;
    uint32_t left = 0u;
    uint32_t right = 0u;
    odometry_step_counts(&odo, left, right);
    for (long long k = 0; k < steps; ++k) {
        int32_t d_left = (int32_t)(lcg_next(&state) % 601u) - 300;
        int32_t d_right = d_left + (int32_t)(lcg_next(&state) % 81u) - 40;
        left = (left + (uint32_t)d_left) & mask;
        right = (right + (uint32_t)d_right) & mask;
        odometry_step_counts(&odo, left, right);
    }
    printf("%" PRId64 " %" PRId64 " %" PRIu64 " %" PRId32 " %" PRIu64 " %" PRIu32 "\n",
           odo.x_q40_m, odo.y_q40_m, odo.heading_bam64, odo.heading_turns, odo.distance_q40_m,
           errors);
    return 0;
}
