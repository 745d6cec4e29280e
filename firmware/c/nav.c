/* Navigation: a bounded path of goals, turn-go-turn or go-to-goal, in fixed point (firmware/nav.py,
 * same order). Positions Q40 m (i64), distances um (i64), angles BAM32 (i32 errors) and urad,
 * speeds mm/s and mrad/s (i32), gains in 1/1000 per second.
 */
#include "nav.h"

#include "fixmath.h"
#include "trig.h"

#define STAGED_X 1u
#define STAGED_Y 2u
#define STAGED_HEADING 4u

static bool is_active(enum nav_state state)
{
    return state == NAV_TURNING || state == NAV_DRIVING || state == NAV_FINAL_TURN;
}

/* --- the geometry, pure functions ------------------------------------------------------- */

/* The BAM64 heading rounded to BAM32 (u32). */
uint32_t heading_bam32_of(uint64_t heading_bam64)
{
    return (uint32_t)((heading_bam64 + (UINT64_C(1) << 31)) >> 32);
}

/* phi_r - phi: the bearing atan2(dy, dx) minus the heading, i32 BAM32 in [-pi, pi). */
int32_t bearing_error_bam32(int64_t dx_q40_m, int64_t dy_q40_m, uint32_t heading_bam32)
{
    return wrap_i32((int64_t)atan2_bam32(dy_q40_m, dx_q40_m) - (int64_t)heading_bam32);
}

/* sqrt(dx^2 + dy^2) in um (i64 >= 0): |dx|, |dy| truncated to Q20 m (u64 < 2^44), shifted right
 * together when the larger passes 2^31 - 1 so that the sum of squares fits a u64 (< 2^63). */
int64_t distance_um(int64_t dx_q40_m, int64_t dy_q40_m, uint32_t *errors)
{
    uint64_t ax = abs_u64(dx_q40_m) >> 20;
    uint64_t ay = abs_u64(dy_q40_m) >> 20;
    unsigned bits = bit_length_u64(ax > ay ? ax : ay);
    unsigned shift = bits > 31u ? bits - 31u : 0u;
    ax >>= shift;
    ay >>= shift;
    int64_t d_q20_m = (int64_t)((uint64_t)isqrt_u64(ax * ax + ay * ay) << shift); /* < 2^45 */
    return mul_shr_round_i64(d_q20_m, MICRO_PER_UNIT, 20u, errors);
}

/* Clamp to [-limit, limit]: a design limit (no SATURATION flag). */
static int64_t clamp(int64_t value, int64_t limit)
{
    if (value < -limit) {
        return -limit;
    }
    return value < limit ? value : limit;
}

/* omega = K e in mrad/s, clamped to +-OMEGA_MAX: e K (< 2^43) times urad per turn (Q20) in the
 * 128-bit product gives nrad/s, then one division by 10^6. */
int32_t turn_rate_mrad_s(int32_t error_bam32, int32_t gain_milli_per_s, uint32_t *errors)
{
    int64_t nrad_s = mul_shr_round_i64((int64_t)error_bam32 * gain_milli_per_s,
                                       URAD_PER_TURN_Q20, 52u, errors);
    int64_t omega = div_round_i64(nrad_s, MICRO_PER_UNIT);
    return (int32_t)clamp(omega, OMEGA_MAX_MRAD_S);
}

/* v = K d in mm/s, clamped to +-V_MAX (d: signed um, < 2^45; K in 1/1000 per second). */
int32_t speed_mm_s(int64_t distance_um_, int32_t gain_milli_per_s)
{
    return (int32_t)clamp(div_round_i64(distance_um_ * gain_milli_per_s, MICRO_PER_UNIT),
                          V_MAX_MM_S);
}

/* (left, right) rim speeds v -+ omega b/2 in mm/s (rounded; |omega b| < 2^44), the turn's share
 * clamped to +-RIM_TURN_MAX and, turning in place, at least MIN_RIM when omega != 0. */
void wheel_speeds_mm_s(int32_t v_mm_s, int32_t omega_mrad_s, uint32_t wheelbase_nm,
                       int32_t *left_mm_s, int32_t *right_mm_s)
{
    int32_t half_mm_s = (int32_t)clamp(
        div_round_i64((int64_t)omega_mrad_s * wheelbase_nm, HALF_WHEEL_DIVISOR), RIM_TURN_MAX_MM_S);
    if (v_mm_s == 0 && half_mm_s == 0 && omega_mrad_s != 0) {
        half_mm_s = (int32_t)clamp(omega_mrad_s, MIN_RIM_MM_S); /* omega != 0: its sign */
    }
    *left_mm_s = v_mm_s - half_mm_s;
    *right_mm_s = v_mm_s + half_mm_s;
}

/* Seed 003: (v, omega) = (K2 d, K1 (phi_r - phi)) in (mm/s, mrad/s), each limited. */
void go_to_goal_law(int64_t dist_um, int32_t bearing_error, uint32_t *errors, int32_t *v_mm_s,
                    int32_t *omega_mrad_s)
{
    *v_mm_s = speed_mm_s(dist_um, K2_MILLI_PER_S);
    *omega_mrad_s = turn_rate_mrad_s(bearing_error, K1_MILLI_PER_S, errors);
}

/* Turn-go-turn's straight leg: v = K_DRIVE d cos(e) (signed), the bearing held by
 * omega = K_HOLD e while d >= HOLD_MIN_DISTANCE (0 closer). */
void drive_straight_law(int64_t dist_um, int32_t bearing_error, uint32_t *errors,
                        int32_t *v_mm_s, int32_t *omega_mrad_s)
{
    int64_t along_um = mul_shr_round_i64(dist_um, cos_q30((uint32_t)bearing_error), 30u, errors);
    int32_t omega = 0;
    if (dist_um >= HOLD_MIN_DISTANCE_UM) {
        omega = turn_rate_mrad_s(bearing_error, K_HOLD_MILLI_PER_S, errors);
    }
    *v_mm_s = speed_mm_s(along_um, K_DRIVE_MILLI_PER_S);
    *omega_mrad_s = omega;
}

/* The heading tolerance: HEADING_TOL or one encoder count's heading step (BAM64, < 2^60,
 * rounded up to BAM32 by the + 1), whichever is larger. */
uint32_t heading_tol_bam32(uint64_t count_bam64)
{
    uint64_t count_bam32 = (count_bam64 >> 32) + 1u;
    return count_bam32 > HEADING_TOL_BAM32 ? (uint32_t)count_bam32 : HEADING_TOL_BAM32;
}

/* The wheel setpoint moved from previous toward target by at most WHEEL_STEP. */
int32_t rate_limit(int32_t target_mm_s, int32_t previous_mm_s)
{
    return previous_mm_s
           + (int32_t)clamp((int64_t)target_mm_s - previous_mm_s, WHEEL_STEP_MM_S);
}

/* --- the navigator ---------------------------------------------------------------------- */

static enum ack_reason nav_go(struct navigator *nav, const struct nav_goal_frame *frame,
                              bool running);
static void nav_enqueue(struct navigator *nav, const struct nav_goal_frame *frame);
static void nav_clear_path(struct navigator *nav);
static void nav_set_state(struct navigator *nav, enum nav_state state);
static void nav_start(struct navigator *nav);
static void nav_halt(struct navigator *nav, enum nav_state state);
static void nav_finish(struct navigator *nav);
static void nav_control(struct navigator *nav, int64_t x_q40_m, int64_t y_q40_m,
                        uint32_t heading_bam32, int32_t *v_mm_s, int32_t *omega_mrad_s);

void navigator_init(struct navigator *nav, uint32_t *errors)
{
    nav->errors = errors;
    for (unsigned k = 0u; k < NAV_QUEUE_SLOTS; ++k) {
        struct goal *g = &nav->ring[k];
        g->x_q40_m = 0;
        g->y_q40_m = 0;
        g->heading_bam32 = 0u;
        g->final_turn = true;
        g->mode = NAV_MODE_TURN_GO_TURN;
        g->goal_id = 0u;
    }
    nav->head = 0u;
    nav->depth = 0u;
    nav->state = NAV_IDLE;
    nav->goal_id = 0u;
    nav->distance_um = 0;
    nav->heading_error_bam32 = 0;
    nav->heading_tol_bam32 = HEADING_TOL_BAM32;
    nav->left_mm_s = 0;
    nav->right_mm_s = 0;
    nav->changed = true;
    nav->zero_periods = 0;
    nav->staged = 0u;
    nav->staged_x_100um = 0;
    nav->staged_y_100um = 0;
    nav->staged_heading_bam16 = 0u;
}

/* --- requests (NAV_GOAL frames, from the drain step) --- */

/* Handle one NAV_GOAL frame; the reason of its ODOM_ACK. running: odometry OK. */
enum ack_reason nav_request(struct navigator *nav, const struct nav_goal_frame *frame,
                            bool running)
{
    switch (frame->field) {
    case NAV_FIELD_X:
        nav->staged_x_100um = (int32_t)frame->value;
        nav->staged |= STAGED_X;
        break;
    case NAV_FIELD_Y:
        nav->staged_y_100um = (int32_t)frame->value;
        nav->staged |= STAGED_Y;
        break;
    case NAV_FIELD_HEADING:
        nav->staged_heading_bam16 = (uint64_t)frame->value;
        nav->staged |= STAGED_HEADING;
        break;
    case NAV_FIELD_STOP:
        nav->staged = 0u;
        nav_clear_path(nav);
        nav_halt(nav, NAV_STOPPED);
        break;
    case NAV_FIELD_GO:
        return nav_go(nav, frame, running);
    default:
        return ACK_UNKNOWN_FIELD;
    }
    return ACK_OK;
}

/* GO: validate the staged goal, then append it or replace the path with it. */
static enum ack_reason nav_go(struct navigator *nav, const struct nav_goal_frame *frame,
                              bool running)
{
    unsigned staged = nav->staged;
    nav->staged = 0u;
    unsigned needed = STAGED_X | STAGED_Y | (frame->no_final_heading != 0u ? 0u : STAGED_HEADING);
    if ((staged & needed) != needed) {
        return ACK_INCOMPLETE;
    }
    if (frame->mode > NAV_MODE_GO_TO_GOAL) {
        return ACK_OUT_OF_RANGE;
    }
    if (!running) {
        return ACK_BUSY;
    }
    if (frame->append != 0u) {
        if (nav->depth == NAV_QUEUE_SLOTS) {
            return ACK_QUEUE_FULL;
        }
    } else {
        nav_clear_path(nav);
    }
    nav_enqueue(nav, frame);
    if (frame->append == 0u || !is_active(nav->state)) {
        nav_start(nav);
    }
    return ACK_OK;
}

static void nav_enqueue(struct navigator *nav, const struct nav_goal_frame *frame)
{
    struct goal *goal = &nav->ring[(nav->head + nav->depth) % NAV_QUEUE_SLOTS];
    goal->x_q40_m = q40_from_100um(nav->staged_x_100um);
    goal->y_q40_m = q40_from_100um(nav->staged_y_100um);
    goal->heading_bam32 = (uint32_t)(nav->staged_heading_bam16 << 16);
    goal->final_turn = frame->no_final_heading == 0u;
    goal->mode = (enum nav_mode)frame->mode;
    goal->goal_id = frame->goal_id;
    nav->depth++;
}

static void nav_clear_path(struct navigator *nav)
{
    nav->head = 0u;
    nav->depth = 0u;
}

/* --- the state machine --- */

static void nav_set_state(struct navigator *nav, enum nav_state state)
{
    if (state != nav->state) {
        nav->state = state;
        nav->changed = true;
    }
}

/* Make the head of the path the active goal. */
static void nav_start(struct navigator *nav)
{
    const struct goal *goal = &nav->ring[nav->head];
    if (goal->goal_id != nav->goal_id) {
        nav->goal_id = goal->goal_id;
        nav->changed = true;
    }
    nav->zero_periods = 0;
    nav_set_state(nav, goal->mode == NAV_MODE_TURN_GO_TURN ? NAV_TURNING : NAV_DRIVING);
}

/* End the active goal (or the idle wait) in state: setpoints 0, then zero commands. */
static void nav_halt(struct navigator *nav, enum nav_state state)
{
    nav_set_state(nav, state);
    nav->left_mm_s = 0;
    nav->right_mm_s = 0;
    nav->zero_periods = ZERO_CMD_PERIODS;
}

/* The active goal is reached: drop it from the path. */
static void nav_finish(struct navigator *nav)
{
    nav->head = (nav->head + 1u) % NAV_QUEUE_SLOTS;
    nav->depth--;
    nav_halt(nav, NAV_REACHED);
}

/* One control period (step 4, every NAV_PERIOD_TICKS). True when a MOTOR_CMD with
 * (left_mm_s, right_mm_s) is to be sent this period. running: odometry OK. */
bool nav_step(struct navigator *nav, int64_t x_q40_m, int64_t y_q40_m, uint64_t heading_bam64,
              uint32_t wheelbase_nm, uint64_t count_bam64, bool running)
{
    nav->heading_tol_bam32 = heading_tol_bam32(count_bam64);
    if (is_active(nav->state) && !running) {
        nav_clear_path(nav);
        nav_halt(nav, NAV_ABORTED);
    } else if (nav->state == NAV_REACHED && nav->depth != 0u) {
        if (running) {
            nav_start(nav);
        } else {
            nav_clear_path(nav);
            nav_halt(nav, NAV_ABORTED);
        }
    }
    if (is_active(nav->state)) {
        int32_t v_mm_s;
        int32_t omega_mrad_s;
        nav_control(nav, x_q40_m, y_q40_m, heading_bam32_of(heading_bam64), &v_mm_s,
                    &omega_mrad_s);
        if (is_active(nav->state)) {
            int32_t left;
            int32_t right;
            wheel_speeds_mm_s(v_mm_s, omega_mrad_s, wheelbase_nm, &left, &right);
            nav->left_mm_s = rate_limit(left, nav->left_mm_s);
            nav->right_mm_s = rate_limit(right, nav->right_mm_s);
            return true;
        }
    }
    if (nav->zero_periods > 0) {
        nav->zero_periods--;
        return true;
    }
    return false;
}

static int64_t abs_i64(int64_t value)
{
    return value < 0 ? -value : value; /* only for i32 values here: no overflow */
}

/* The phase transitions, then the active phase's (v mm/s, omega mrad/s). */
static void nav_control(struct navigator *nav, int64_t x_q40_m, int64_t y_q40_m,
                        uint32_t heading_bam32, int32_t *v_mm_s, int32_t *omega_mrad_s)
{
    const struct goal *goal = &nav->ring[nav->head];
    uint32_t *e = nav->errors;
    int64_t dx = wide_sat_i64(wide_sub(wide_from_i64(goal->x_q40_m), wide_from_i64(x_q40_m)), e);
    int64_t dy = wide_sat_i64(wide_sub(wide_from_i64(goal->y_q40_m), wide_from_i64(y_q40_m)), e);
    int64_t dist_um = distance_um(dx, dy, e);
    int32_t bearing_error = bearing_error_bam32(dx, dy, heading_bam32);
    int32_t final_error = wrap_i32((int64_t)goal->heading_bam32 - (int64_t)heading_bam32);
    nav->distance_um = dist_um;
    if (nav->state == NAV_TURNING && abs_i64(bearing_error) < (int64_t)nav->heading_tol_bam32) {
        nav_set_state(nav, NAV_DRIVING);
    }
    if (nav->state != NAV_FINAL_TURN && dist_um < POSITION_TOL_UM) {
        nav_set_state(nav, NAV_FINAL_TURN);
    }
    *v_mm_s = 0;
    if (nav->state == NAV_FINAL_TURN) {
        nav->heading_error_bam32 = goal->final_turn ? final_error : 0;
        if (abs_i64(nav->heading_error_bam32) < (int64_t)nav->heading_tol_bam32) {
            nav_finish(nav);
            *omega_mrad_s = 0;
            return;
        }
        *omega_mrad_s = turn_rate_mrad_s(final_error, K_TURN_MILLI_PER_S, e);
        return;
    }
    nav->heading_error_bam32 = bearing_error;
    if (nav->state == NAV_TURNING) {
        *omega_mrad_s = turn_rate_mrad_s(bearing_error, K_TURN_MILLI_PER_S, e);
        return;
    }
    if (goal->mode == NAV_MODE_GO_TO_GOAL) {
        go_to_goal_law(dist_um, bearing_error, e, v_mm_s, omega_mrad_s);
        return;
    }
    drive_straight_law(dist_um, bearing_error, e, v_mm_s, omega_mrad_s);
}

/* 0.1 mm units (i32) to Q40 metres (i64), exactly rounded: whole metres (floor) times 2^40 (a
 * multiplication: C's << of a negative value is undefined), plus the remainder (< 10^4) scaled. */
int64_t q40_from_100um(int32_t value_100um)
{
    int32_t metres = value_100um / 10000;
    int32_t remainder_100um = value_100um % 10000; /* C truncates: make it Python's floor */
    if (remainder_100um < 0) {
        remainder_100um += 10000;
        metres -= 1;
    }
    return (int64_t)metres * (INT64_C(1) << 40)
           + div_round_i64((int64_t)remainder_100um << 40, 10000);
}
