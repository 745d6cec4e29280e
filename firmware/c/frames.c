/* The ECU's frames (firmware/frames.py) on the cantools-generated dbc/odocan.c: saturation into
 * the error mask, raw values of unknown multiplexers, the E2E Profile 2 seal. */
#include "frames.h"

#include "config.h"
#include "errors.h"
#include "fixmath.h"
#include "nav.h"
#include "secoc.h"

/* Profile 2 DataIDList of E2E slot `slot` (1..15): DataID[c] = (slot << 4) | c. */
void data_ids_of_slot(unsigned slot, uint8_t ids[DATA_ID_COUNT])
{
    for (unsigned c = 0u; c < DATA_ID_COUNT; ++c) {
        ids[c] = (uint8_t)((slot << 4) | c);
    }
}

/* The CHECKSUM of a packed frame (its COUNTER already in byte 1): frames.py's seal_frame. */
static void seal(uint8_t frame[8], unsigned slot)
{
    uint8_t ids[DATA_ID_COUNT];
    data_ids_of_slot(slot, ids);
    frame[0] = p02_crc(frame, ids[frame[1] & COUNTER_MASK]);
}

/* Bits 16..47 of the frame, the raw u32 payload of a multiplexed request. */
static uint32_t raw_u32(const uint8_t data[8])
{
    return (uint32_t)data[2] | ((uint32_t)data[3] << 8) | ((uint32_t)data[4] << 16)
           | ((uint32_t)data[5] << 24);
}

static int32_t sat_i32_field(int64_t value, uint32_t *errors)
{
    return (int32_t)sat_range(value, I32_MIN, I32_MAX, errors);
}

static int16_t sat_i16_field(int64_t value, uint32_t *errors)
{
    return (int16_t)sat_range(value, I16_MIN, I16_MAX, errors);
}

/* WHEEL_ENCODERS: u24 counts and CTRL_UPTIME (u4 s, saturated at 15; 0: not reported). */
void unpack_wheel_encoders(const uint8_t data[8], uint8_t *counter, uint32_t *left_count,
                           uint32_t *right_count, uint8_t *ctrl_uptime_s)
{
    struct odocan_wheel_encoders_t m;
    (void)odocan_wheel_encoders_unpack(&m, data, 8u);
    *counter = m.counter;
    *left_count = m.left_count;
    *right_count = m.right_count;
    *ctrl_uptime_s = m.ctrl_uptime;
}

/* ODOM_SET_POSE: value i32 for X/Y, u16 for HEADING, 0 for APPLY, raw u32 otherwise. */
void unpack_odom_set_pose(const uint8_t data[8], struct mux_record *out)
{
    struct odocan_odom_set_pose_t m;
    (void)odocan_odom_set_pose_unpack(&m, data, 8u);
    out->counter = m.counter;
    out->field = m.field;
    switch (m.field) {
    case SET_POSE_X: out->value = m.x; break;
    case SET_POSE_Y: out->value = m.y; break;
    case SET_POSE_HEADING: out->value = m.heading; break;
    case SET_POSE_APPLY: out->value = 0; break;
    default: out->value = raw_u32(data); break;
    }
}

/* ODOM_CONFIG: value u32, u8 for COUNTER_BITS / INTEGRATOR, 0 for APPLY, raw u32 otherwise. */
void unpack_odom_config(const uint8_t data[8], struct mux_record *out)
{
    struct odocan_odom_config_t m;
    (void)odocan_odom_config_unpack(&m, data, 8u);
    out->counter = m.counter;
    out->field = m.param;
    switch (m.param) {
    case PARAM_COUNTS_PER_REV: out->value = m.counts_per_rev; break;
    case PARAM_WHEEL_RADIUS_LEFT: out->value = m.wheel_radius_left; break;
    case PARAM_WHEEL_RADIUS_RIGHT: out->value = m.wheel_radius_right; break;
    case PARAM_WHEELBASE: out->value = m.wheelbase; break;
    case PARAM_COUNTER_BITS: out->value = m.counter_bits; break;
    case PARAM_INTEGRATOR: out->value = m.integrator; break;
    case PARAM_MAX_WHEEL_SPEED: out->value = m.max_wheel_speed; break;
    case PARAM_APPLY: out->value = 0; break;
    default: out->value = raw_u32(data); break;
    }
}

/* NAV_GOAL: value per field as ODOM_SET_POSE (0 for STOP/GO); GO's MODE, APPEND,
 * NO_FINAL_HEADING and GOAL_ID (0 for the other fields). */
void unpack_nav_goal(const uint8_t data[8], struct mux_record *out, uint8_t *mode,
                     uint8_t *append, uint8_t *no_final_heading, uint8_t *goal_id)
{
    struct odocan_nav_goal_t m;
    (void)odocan_nav_goal_unpack(&m, data, 8u);
    out->counter = m.counter;
    out->field = m.field;
    *mode = 0u;
    *append = 0u;
    *no_final_heading = 0u;
    *goal_id = 0u;
    switch (m.field) {
    case ODOCAN_NAV_GOAL_FIELD_X_CHOICE: out->value = m.x; break;
    case ODOCAN_NAV_GOAL_FIELD_Y_CHOICE: out->value = m.y; break;
    case ODOCAN_NAV_GOAL_FIELD_HEADING_CHOICE: out->value = m.heading; break;
    case ODOCAN_NAV_GOAL_FIELD_STOP_CHOICE: out->value = 0; break;
    case ODOCAN_NAV_GOAL_FIELD_GO_CHOICE:
        out->value = 0;
        *mode = m.mode;
        *append = m.append;
        *no_final_heading = m.no_final_heading;
        *goal_id = m.goal_id;
        break;
    default: out->value = raw_u32(data); break;
    }
}

/* MOTOR_CMD: rim speed setpoints in mm/s, saturated to i16. */
void pack_motor_cmd(uint8_t out[8], uint8_t counter, int64_t left_speed_mm_s,
                    int64_t right_speed_mm_s, uint32_t *errors)
{
    struct odocan_motor_cmd_t m;
    (void)odocan_motor_cmd_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.left_speed = sat_i16_field(left_speed_mm_s, errors);
    m.right_speed = sat_i16_field(right_speed_mm_s, errors);
    (void)odocan_motor_cmd_pack(out, &m, 8u);
    seal(out, MOTOR_CMD_E2E_SLOT);
}

/* ODOM_POSE_X: x (0.1 mm, saturated to i32) and heading (u16 binary angle, wraps). */
void pack_odom_pose_x(uint8_t out[8], uint8_t counter, uint8_t enc_counter, int64_t x_100um,
                      uint32_t heading_bam16, uint32_t *errors)
{
    struct odocan_odom_pose_x_t m;
    (void)odocan_odom_pose_x_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.enc_counter = (uint8_t)(enc_counter & 0x0Fu);
    m.x = sat_i32_field(x_100um, errors);
    m.heading = (uint16_t)heading_bam16;
    (void)odocan_odom_pose_x_pack(out, &m, 8u);
    seal(out, ODOM_POSE_X_E2E_SLOT);
}

/* ODOM_POSE_Y: y (0.1 mm, saturated to i32) and whole heading turns (i16, wraps). */
void pack_odom_pose_y(uint8_t out[8], uint8_t counter, uint8_t enc_counter, int64_t y_100um,
                      int32_t turns, uint32_t *errors)
{
    struct odocan_odom_pose_y_t m;
    (void)odocan_odom_pose_y_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.enc_counter = (uint8_t)(enc_counter & 0x0Fu);
    m.y = sat_i32_field(y_100um, errors);
    m.turns = wrap_i16(turns);
    (void)odocan_odom_pose_y_pack(out, &m, 8u);
    seal(out, ODOM_POSE_Y_E2E_SLOT);
}

/* ODOM_TWIST: velocities saturated to i16; distance (mm) keeps its low 16 bits. */
void pack_odom_twist(uint8_t out[8], uint8_t counter, uint8_t enc_counter,
                     int64_t linear_vel_mm_s, int64_t angular_vel_mrad_s, uint64_t distance_mm,
                     uint32_t *errors)
{
    struct odocan_odom_twist_t m;
    (void)odocan_odom_twist_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.enc_counter = (uint8_t)(enc_counter & 0x0Fu);
    m.linear_vel = sat_i16_field(linear_vel_mm_s, errors);
    m.angular_vel = sat_i16_field(angular_vel_mrad_s, errors);
    m.distance = (uint16_t)distance_mm;
    (void)odocan_odom_twist_pack(out, &m, 8u);
    seal(out, ODOM_TWIST_E2E_SLOT);
}

/* NAV_STATUS: STATE, GOAL_ID, QUEUE_DEPTH, DISTANCE saturate; the heading error wraps to i16. */
void pack_nav_status(uint8_t out[8], uint8_t counter, int64_t state, int64_t goal_id,
                     int64_t queue_depth, int64_t distance_mm, int32_t heading_error_bam16,
                     uint32_t *errors)
{
    struct odocan_nav_status_t m;
    (void)odocan_nav_status_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.state = (uint8_t)sat_range(state, 0, 6, errors);
    m.goal_id = (uint8_t)sat_range(goal_id, 0, 0xFF, errors);
    m.queue_depth = (uint8_t)sat_range(queue_depth, 0, NAV_QUEUE_DEPTH_MAX, errors);
    m.distance = (uint16_t)sat_range(distance_mm, 0, U16_MAX, errors);
    m.heading_error = wrap_i16(heading_error_bam16);
    (void)odocan_nav_status_pack(out, &m, 8u);
    seal(out, NAV_STATUS_E2E_SLOT);
}

/* ODOM_ACK: answer the request frame (its ID, COUNTER and multiplexer value). */
void pack_odom_ack(uint8_t out[8], uint8_t counter, uint8_t request_counter, int64_t request_id,
                   uint8_t request_field, int64_t result, int64_t reason, uint32_t *errors)
{
    struct odocan_odom_ack_t m;
    (void)odocan_odom_ack_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.request_counter = (uint8_t)(request_counter & 0x0Fu);
    m.request_id = (uint16_t)sat_range(request_id, 0, CAN_ID_MAX, errors);
    m.request_field = (uint8_t)(request_field & 0x0Fu);
    m.result = (uint8_t)sat_range(result, ACK_RESULT_ACK, ACK_RESULT_NACK, errors);
    m.reason = (uint8_t)sat_range(reason, 0, ACK_REPEATED, errors);
    (void)odocan_odom_ack_pack(out, &m, 8u);
    seal(out, ODOM_ACK_E2E_SLOT);
}

/* ODOM_STATUS page 0: state, integrator, reason (saturated to the DBC range), the low 16 bits of
 * the error mask, uptime (u24). */
void pack_odom_status_summary(uint8_t out[8], uint8_t counter, int64_t state, int64_t integrator,
                              uint32_t error_mask, int64_t uptime_s, uint32_t *errors,
                              int64_t reason)
{
    struct odocan_odom_status_t m;
    (void)odocan_odom_status_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.page = PAGE_SUMMARY;
    m.state = (uint8_t)sat_range(state, 0, 3, errors);
    m.integrator = (uint8_t)sat_range(integrator, INTEGRATOR_EULER, INTEGRATOR_EXACT, errors);
    m.reason = (uint8_t)sat_range(reason, REASON_NONE, REASON_POSE_UNCERTAIN, errors);
    m.error_mask = (uint16_t)error_mask;
    m.uptime = (uint32_t)sat_range(uptime_s, 0, 0xFFFFFF, errors);
    (void)odocan_odom_status_pack(out, &m, 8u);
    seal(out, ODOM_STATUS_E2E_SLOT);
}

/* ODOM_STATUS page 1: frame totals, each keeping its low 16 bits. */
void pack_odom_status_frame_totals(uint8_t out[8], uint8_t counter, uint32_t lost,
                                   uint32_t rejected, uint32_t overflowed)
{
    struct odocan_odom_status_t m;
    (void)odocan_odom_status_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.page = PAGE_FRAME_TOTALS;
    m.lost_frames = (uint16_t)lost;
    m.rejected_frames = (uint16_t)rejected;
    m.overflowed_frames = (uint16_t)overflowed;
    (void)odocan_odom_status_pack(out, &m, 8u);
    seal(out, ODOM_STATUS_E2E_SLOT);
}

/* ODOM_STATUS pages 2..5: one received message's E2E counts (ok: 16 bits, the others 8). */
void pack_odom_status_e2e(uint8_t out[8], uint8_t counter, enum status_page page, uint32_t ok,
                          uint32_t lost, uint32_t repeated, uint32_t crc_error,
                          uint32_t wrong_sequence)
{
    struct odocan_odom_status_t m;
    (void)odocan_odom_status_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.page = (uint8_t)page;
    uint16_t ok16 = (uint16_t)ok;
    uint8_t lost8 = (uint8_t)lost;
    uint8_t rep8 = (uint8_t)repeated;
    uint8_t crc8 = (uint8_t)crc_error;
    uint8_t seq8 = (uint8_t)wrong_sequence;
    switch (page) {
    case PAGE_E2E_WHEEL_ENCODERS:
        m.enc_e2_e_ok = ok16; m.enc_e2_e_lost = lost8; m.enc_e2_e_repeated = rep8;
        m.enc_e2_e_crc_error = crc8; m.enc_e2_e_wrong_seq = seq8;
        break;
    case PAGE_E2E_ODOM_SET_POSE:
        m.set_pose_e2_e_ok = ok16; m.set_pose_e2_e_lost = lost8; m.set_pose_e2_e_repeated = rep8;
        m.set_pose_e2_e_crc_error = crc8; m.set_pose_e2_e_wrong_seq = seq8;
        break;
    case PAGE_E2E_ODOM_CONFIG:
        m.config_e2_e_ok = ok16; m.config_e2_e_lost = lost8; m.config_e2_e_repeated = rep8;
        m.config_e2_e_crc_error = crc8; m.config_e2_e_wrong_seq = seq8;
        break;
    default:
        m.nav_goal_e2_e_ok = ok16; m.nav_goal_e2_e_lost = lost8; m.nav_goal_e2_e_repeated = rep8;
        m.nav_goal_e2_e_crc_error = crc8; m.nav_goal_e2_e_wrong_seq = seq8;
        break;
    }
    (void)odocan_odom_status_pack(out, &m, 8u);
    seal(out, ODOM_STATUS_E2E_SLOT);
}

/* ODOM_AUTH's raw fields (run its E2E check first); REQUEST read as the raw nibble. */
void unpack_odom_auth(const uint8_t data[8], struct odom_auth *out)
{
    out->counter = (uint8_t)(data[1] & 0x0Fu);
    out->request = (uint8_t)(data[1] >> 4);
    out->freshness = (uint16_t)((unsigned)data[2] | ((unsigned)data[3] << 8));
    out->authenticator = (uint32_t)data[4] | ((uint32_t)data[5] << 8) |
                         ((uint32_t)data[6] << 16) | ((uint32_t)data[7] << 24);
}

/* ODOM_FRESHNESS: CAUSE (saturated to 0..4) and the u48 FV (COUNT bits 16-43, EPOCH 44-63). */
void pack_odom_freshness(uint8_t out[8], uint8_t counter, int64_t cause, uint64_t fv,
                         uint32_t *errors)
{
    struct odocan_odom_freshness_t m;
    (void)odocan_odom_freshness_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.cause = (uint8_t)sat_range(cause, 0, 4, errors);
    m.fv_count = (uint32_t)(fv & 0x0FFFFFFFu);
    m.fv_epoch = (uint32_t)((fv >> 28) & 0xFFFFFu);
    (void)odocan_odom_freshness_pack(out, &m, 8u);
    seal(out, ODOM_FRESHNESS_E2E_SLOT);
}

/* ODOM_STATUS page 6: the plausibility bound in use (u16 mm/s, as configured) and the CRC-32 of
 * the parameter set the firmware runs with (config.c profile_crc32). */
void pack_odom_status_profile(uint8_t out[8], uint8_t counter, uint32_t max_wheel_speed_mm_s,
                              uint32_t profile_crc)
{
    struct odocan_odom_status_t m;
    (void)odocan_odom_status_init(&m);
    m.counter = (uint8_t)(counter & COUNTER_MASK);
    m.page = PAGE_PROFILE;
    m.max_wheel_speed = (uint16_t)max_wheel_speed_mm_s;
    m.profile_crc = profile_crc;
    (void)odocan_odom_status_pack(out, &m, 8u);
    seal(out, ODOM_STATUS_E2E_SLOT);
}
