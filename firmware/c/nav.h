/* Navigation: a bounded path of goals, driven by turn-go-turn or go-to-goal, in fixed point
 * (firmware/nav.py; its docstring gives the modes, limits and gains). */
#ifndef ODOCAN_NAV_H
#define ODOCAN_NAV_H

#include <stdbool.h>
#include <stdint.h>

#define NAV_PERIOD_TICKS 2 /* 20 ms at the 10 ms tick: the MOTOR_CMD cycle */
#define NAV_PERIOD_MS 20
#define NAV_QUEUE_SLOTS 16u /* goals in the path, the active one included */
#define ZERO_CMD_PERIODS 5  /* zero MOTOR_CMDs after a path ends */

#define V_MAX_MM_S 500
#define OMEGA_MAX_MRAD_S 2000
#define ACCEL_MM_S2 1000
#define WHEEL_STEP_MM_S (ACCEL_MM_S2 * NAV_PERIOD_MS / 1000) /* 20 mm/s per period */
#define POSITION_TOL_UM 5000
#define HEADING_TOL_BAM32 5965232 /* (1 << 32) // 720: 0.5 degree */
#define RIM_TURN_MAX_MM_S 300 /* |omega b/2| <= 0.3 m/s: OMEGA_MAX's rim speed at b = 0.30 m */
#define MIN_RIM_MM_S 1 /* the least turn in place that moves the wheels: one MOTOR_CMD step */
#define HOLD_MIN_DISTANCE_UM 20000

#define K_TURN_MILLI_PER_S 3000
#define K_HOLD_MILLI_PER_S 3000
#define K_DRIVE_MILLI_PER_S 1500
#define K1_MILLI_PER_S 3000
#define K2_MILLI_PER_S 1000

#define MILLI_PER_UNIT 1000
#define MICRO_PER_UNIT 1000000
/* 2*pi*1e6 in Q20 (< 2^43): round(TWO_PI_Q60 * 10^6 / 2^40), a 83-bit product, evaluated once
 * (the probe test checks every function that uses it against the Python firmware). */
#define URAD_PER_TURN_Q20 INT64_C(6588397316661)
#define HALF_WHEEL_DIVISOR INT64_C(2000000000) /* omega[mrad/s] * b[nm] / 2e9 = mm/s */

/* NAV_GOAL FIELD, MODE; NAV_STATUS STATE; ODOM_ACK REASON (firmware/frames.py, the DBC). */
enum nav_goal_field { NAV_FIELD_X = 0, NAV_FIELD_Y = 1, NAV_FIELD_HEADING = 2,
                      NAV_FIELD_STOP = 14, NAV_FIELD_GO = 15 };
enum nav_mode { NAV_MODE_TURN_GO_TURN = 0, NAV_MODE_GO_TO_GOAL = 1 };
enum nav_state { NAV_IDLE = 0, NAV_TURNING = 1, NAV_DRIVING = 2, NAV_FINAL_TURN = 3,
                 NAV_REACHED = 4, NAV_STOPPED = 5, NAV_ABORTED = 6 };
enum ack_reason { ACK_OK = 0, ACK_OUT_OF_RANGE = 1, ACK_UNKNOWN_FIELD = 2, ACK_INCOMPLETE = 3,
                  ACK_BUSY = 4, ACK_INCONSISTENT = 5, ACK_QUEUE_FULL = 6,
                  /* SecOC verdicts (firmware/secoc.py AuthStatus) */
                  ACK_AUTH_FAILED = 7, ACK_AUTH_FRESHNESS = 8, ACK_AUTH_MISSING = 9,
                  ACK_AUTH_UNAVAILABLE = 10,
                  /* ODOM_CONFIG: the last accepted COUNTER again, other content (commands.py) */
                  ACK_REPEATED = 11 };

/* One NAV_GOAL frame's raw integers (the unpacker's record). */
struct nav_goal_frame {
    uint32_t field;
    int64_t value;    /* i32 for X/Y (0.1 mm), u16 bam16 for HEADING, 0 for STOP/GO */
    uint32_t mode;    /* u4, GO only */
    uint32_t append;  /* u1, GO only */
    uint32_t no_final_heading; /* u1, GO only */
    uint8_t goal_id;  /* GO only */
};

/* One slot of the path. */
struct goal {
    int64_t x_q40_m;
    int64_t y_q40_m;
    uint32_t heading_bam32;
    bool final_turn;
    enum nav_mode mode;
    uint8_t goal_id;
};

/* The path, its state machine and the wheel setpoints. */
struct navigator {
    uint32_t *errors;
    struct goal ring[NAV_QUEUE_SLOTS];
    unsigned head;
    unsigned depth; /* goals in the ring (the active one included) */
    enum nav_state state;
    uint8_t goal_id;
    int64_t distance_um;
    int32_t heading_error_bam32;
    uint32_t heading_tol_bam32; /* from the geometry, every period */
    int32_t left_mm_s; /* the last setpoints (the rate limiter's memory) */
    int32_t right_mm_s;
    bool changed; /* STATE or GOAL_ID changed since NAV_STATUS was last sent */
    int zero_periods;
    unsigned staged;
    int32_t staged_x_100um; /* i32: the X signal */
    int32_t staged_y_100um;
    uint64_t staged_heading_bam16;
};

uint32_t heading_bam32_of(uint64_t heading_bam64);
int32_t bearing_error_bam32(int64_t dx_q40_m, int64_t dy_q40_m, uint32_t heading_bam32);
int64_t distance_um(int64_t dx_q40_m, int64_t dy_q40_m, uint32_t *errors);
int32_t turn_rate_mrad_s(int32_t error_bam32, int32_t gain_milli_per_s, uint32_t *errors);
int32_t speed_mm_s(int64_t distance_um_, int32_t gain_milli_per_s);
void wheel_speeds_mm_s(int32_t v_mm_s, int32_t omega_mrad_s, uint32_t wheelbase_nm,
                       int32_t *left_mm_s, int32_t *right_mm_s);
void go_to_goal_law(int64_t dist_um, int32_t bearing_error, uint32_t *errors, int32_t *v_mm_s,
                    int32_t *omega_mrad_s);
void drive_straight_law(int64_t dist_um, int32_t bearing_error, uint32_t *errors,
                        int32_t *v_mm_s, int32_t *omega_mrad_s);
int32_t rate_limit(int32_t target_mm_s, int32_t previous_mm_s);
uint32_t heading_tol_bam32(uint64_t count_bam64);

void navigator_init(struct navigator *nav, uint32_t *errors);
enum ack_reason nav_request(struct navigator *nav, const struct nav_goal_frame *frame,
                            bool running);
bool nav_step(struct navigator *nav, int64_t x_q40_m, int64_t y_q40_m, uint64_t heading_bam64,
              uint32_t wheelbase_nm, uint64_t count_bam64, bool running);
int64_t q40_from_100um(int32_t value_100um);

#endif
