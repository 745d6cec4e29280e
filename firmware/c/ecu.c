/* The odometry ECU's main loop (firmware/ecu.py, same order): the receive ISR copies a frame into
 * the mailbox; tick() runs every TICK_PERIOD_US: 1. drain the mailbox; 2. E2E check; 3. odometry
 * on WHEEL_ENCODERS, staged ODOM_SET_POSE / ODOM_CONFIG / NAV_GOAL writes answered by ODOM_ACK;
 * 4. navigation every 20 ms; 5. scheduled transmissions at the DBC's cycle times; 6. the watchdog.
 */
#include "ecu.h"

#include <string.h>

#include "fixmath.h"
#include "frames.h"

enum tx_index { TX_MOTOR_CMD, TX_POSE_X, TX_POSE_Y, TX_TWIST, TX_ACK, TX_STATUS, TX_NAV_STATUS };

static const enum status_page ROTATING_PAGES[5] = {
    PAGE_FRAME_TOTALS, PAGE_E2E_WHEEL_ENCODERS, PAGE_E2E_ODOM_SET_POSE, PAGE_E2E_ODOM_CONFIG,
    PAGE_E2E_NAV_GOAL,
};

/* --- the mailbox --- */

/* ISR context: store one frame (at most 8 bytes kept; the length is kept for the check), or
 * count an overflow. */
static bool mailbox_put(struct mailbox *mb, uint32_t can_id, const uint8_t *data, size_t len)
{
    if (mb->count == MAILBOX_SLOTS) {
        mb->overflows++;
        return false;
    }
    unsigned slot = (mb->head + mb->count) % MAILBOX_SLOTS;
    mb->ids[slot] = can_id;
    memset(mb->data[slot], 0, 8u);
    if (len > 0u) { /* memcpy from a NULL pointer is undefined even for 0 bytes */
        memcpy(mb->data[slot], data, len < 8u ? len : 8u);
    }
    mb->len[slot] = len;
    mb->count++;
    return true;
}

/* Thread context: the oldest frame's slot, or -1 when empty. */
static int mailbox_get(struct mailbox *mb)
{
    if (mb->count == 0u) {
        return -1;
    }
    unsigned slot = mb->head;
    mb->head = (slot + 1u) % MAILBOX_SLOTS;
    mb->count--;
    return (int)slot;
}

static void on_wheel_encoders(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void extend_counters(struct odom_ecu *ecu, uint32_t left_wire, uint32_t right_wire,
                            uint32_t *left, uint32_t *right);
static void update_twist(struct odom_ecu *ecu, uint8_t counter);
static void on_set_pose(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void on_config(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void apply_config(struct odom_ecu *ecu, const struct mux_record *frame);
static void on_nav_goal(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void ack(struct odom_ecu *ecu, uint32_t request_id, const struct mux_record *frame,
                enum ack_result result, enum ack_reason reason);
static void navigate(struct odom_ecu *ecu);
static void transmit_scheduled(struct odom_ecu *ecu);
static void send_nav_status(struct odom_ecu *ecu);
static void send_pose_and_twist(struct odom_ecu *ecu);
static void send_status(struct odom_ecu *ecu);
static uint8_t next_counter(struct odom_ecu *ecu, enum tx_index which);
static void send(struct odom_ecu *ecu, uint32_t can_id, const uint8_t data[8]);
static void watchdog(struct odom_ecu *ecu);

void ecu_init(struct odom_ecu *ecu, can_tx_fn transmit, void *tx_ctx,
              const struct robot_params *params)
{
    memset(ecu, 0, sizeof *ecu);
    ecu->transmit = transmit;
    ecu->tx_ctx = tx_ctx;
    ecu->errors = 0u;
    ecu->state = STATE_INIT;
    if (validate(params) != CONFIG_OK) {
        ecu->errors |= ERROR_CONFIG_INVALID;
        ecu->state = STATE_FAULT;
    }
    ecu->params = *params;
    struct odom_constants consts;
    derive_constants(params, &ecu->errors, &consts);
    odometry_init(&ecu->odometry, &consts, &ecu->errors);
    data_ids_of_slot(WHEEL_ENCODERS_E2E_SLOT, ecu->data_ids[0]);
    data_ids_of_slot(ODOM_SET_POSE_E2E_SLOT, ecu->data_ids[1]);
    data_ids_of_slot(ODOM_CONFIG_E2E_SLOT, ecu->data_ids[2]);
    data_ids_of_slot(NAV_GOAL_E2E_SLOT, ecu->data_ids[3]);
    /* The window widens once per tick (not per frame): a replay cannot widen it. */
    e2e_receiver_init(&ecu->rx_encoders, ecu->data_ids[0], 0u, true);
    e2e_receiver_init(&ecu->rx_set_pose, ecu->data_ids[1], 15u, false);
    e2e_receiver_init(&ecu->rx_config, ecu->data_ids[2], 15u, false);
    e2e_receiver_init(&ecu->rx_nav_goal, ecu->data_ids[3], 15u, false);
    navigator_init(&ecu->nav, &ecu->errors);
    for (unsigned k = 0u; k < TX_IDS; ++k) {
        ecu->tx_counters[k] = COUNTER_MASK; /* the first frame of each message carries 0 */
    }
    ecu->enc_prev_counter = -1;
}

/* --- ISR context --- */

/* CAN receive interrupt: copy the frame into the mailbox (or count the overflow). */
void ecu_isr_can_rx(struct odom_ecu *ecu, uint32_t can_id, const uint8_t *data, size_t len)
{
    if (!mailbox_put(&ecu->mailbox, can_id, data, len)) {
        ecu->errors |= ERROR_MAILBOX_OVERFLOW;
    }
}

/* CAN controller status interrupt: bus-off entered (true) or recovered (false). */
void ecu_isr_bus_state(struct odom_ecu *ecu, bool bus_off)
{
    if (bus_off) {
        ecu->errors |= ERROR_BUS_OFF;
    }
}

/* --- the periodic tick --- */

/* One period of the main loop, in the fixed order of the file comment. */
void ecu_tick(struct odom_ecu *ecu)
{
    e2e_new_period(&ecu->rx_encoders);
    bool encoder_seen = false;
    int slot = mailbox_get(&ecu->mailbox);
    while (slot >= 0) {
        uint32_t can_id = ecu->mailbox.ids[slot];
        const uint8_t *data = ecu->mailbox.data[slot];
        size_t len = ecu->mailbox.len[slot];
        if (can_id == WHEEL_ENCODERS_ID) {
            encoder_seen = true;
            on_wheel_encoders(ecu, data, len);
        } else if (can_id == ODOM_SET_POSE_ID) {
            on_set_pose(ecu, data, len);
        } else if (can_id == ODOM_CONFIG_ID) {
            on_config(ecu, data, len);
        } else if (can_id == NAV_GOAL_ID) {
            on_nav_goal(ecu, data, len);
        } else {
            ecu->frames_filtered++;
        }
        slot = mailbox_get(&ecu->mailbox);
    }
    if (!encoder_seen) {
        e2e_check(&ecu->rx_encoders, NULL, 0u);
    }
    navigate(ecu);
    transmit_scheduled(ecu);
    watchdog(ecu);
    ecu->ticks++;
}

/* --- step 2-3: received frames --- */

/* The Profile 2 check; true when the frame may be used (OK or OKSOMELOST). */
static bool e2e(struct odom_ecu *ecu, struct e2e_receiver *receiver, const uint8_t *data,
                size_t len)
{
    if (len != 8u) {
        ecu->frames_bad_length++;
        ecu->errors |= ERROR_E2E_ERROR;
        return false;
    }
    enum e2e_status status = e2e_check(receiver, data, len);
    if (status == E2E_OK || status == E2E_OKSOMELOST) {
        return true;
    }
    if (status != E2E_REPEATED) {
        ecu->errors |= ERROR_E2E_ERROR;
    }
    return false;
}

static void on_wheel_encoders(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (!e2e(ecu, &ecu->rx_encoders, data, len)) {
        return;
    }
    uint8_t counter;
    uint32_t left_wire;
    uint32_t right_wire;
    unpack_wheel_encoders(data, &counter, &left_wire, &right_wire);
    uint32_t left;
    uint32_t right;
    extend_counters(ecu, left_wire, right_wire, &left, &right);
    if (ecu->state != STATE_FAULT && odometry_step_counts(&ecu->odometry, left, right)) {
        update_twist(ecu, counter);
    }
    ecu->enc_prev_counter = counter;
    ecu->enc_counter = counter;
    ecu->ticks_since_encoder = 0;
    if (ecu->good_in_a_row < RECOVERY_FRAMES) {
        ecu->good_in_a_row++;
    }
    if (ecu->state == STATE_INIT) {
        ecu->state = STATE_OK;
    }
}

/* The hardware counters from their low 24 bits on the wire: a 16-bit counter fits as it is; a
 * 32-bit one is rebuilt by adding the wire's wrap-safe 24-bit delta. */
static void extend_counters(struct odom_ecu *ecu, uint32_t left_wire, uint32_t right_wire,
                            uint32_t *left, uint32_t *right)
{
    if (ecu->odometry.consts.counter_bits <= WIRE_COUNTER_BITS) {
        *left = left_wire;
        *right = right_wire;
        return;
    }
    if (!ecu->wire_prev_valid) {
        ecu->counts_u32[0] = left_wire;
        ecu->counts_u32[1] = right_wire;
    } else {
        int32_t d_left = wrap_signed(left_wire - ecu->wire_prev[0], WIRE_COUNTER_BITS);
        int32_t d_right = wrap_signed(right_wire - ecu->wire_prev[1], WIRE_COUNTER_BITS);
        ecu->counts_u32[0] += (uint32_t)d_left;
        ecu->counts_u32[1] += (uint32_t)d_right;
    }
    ecu->wire_prev[0] = left_wire;
    ecu->wire_prev[1] = right_wire;
    ecu->wire_prev_valid = true;
    *left = ecu->counts_u32[0];
    *right = ecu->counts_u32[1];
}

/* Speeds over the last step: dt from the encoder counter's advance (lost frames count).
 * ds_q20_m * 10^9 is taken in 128 bits and saturated (exact below 8.6 m per step). */
static void update_twist(struct odom_ecu *ecu, uint8_t counter)
{
    int prev = ecu->enc_prev_counter;
    unsigned periods = prev < 0 ? 1u : ((unsigned)(counter - prev) & COUNTER_MASK);
    if (periods == 0u) {
        periods = 1u;
    }
    int64_t dt_us = (int64_t)periods * ENCODER_PERIOD_US;
    int64_t ds_q20_m = asr_i64(ecu->odometry.last_ds_q49_m, 29u);
    uint32_t scratch = 0u; /* Python sets no flag here: the twist's pack saturates later */
    int64_t ds_scaled = wide_sat_i64(wide_mul_i64(ds_q20_m, INT64_C(1000000000)), &scratch);
    ecu->twist_mm_s = div_round_i64(ds_scaled, dt_us * (INT64_C(1) << 20));
    int64_t dheading_q30_rad =
        mul_shr_round_i64(ecu->odometry.last_dheading_bam64, TWO_PI_Q60, 94u, &ecu->errors);
    ecu->twist_mrad_s =
        div_round_i64(dheading_q30_rad * INT64_C(1000000000), dt_us * (INT64_C(1) << 30));
}

static void on_set_pose(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (!e2e(ecu, &ecu->rx_set_pose, data, len)) {
        return;
    }
    struct mux_record frame;
    unpack_odom_set_pose(data, &frame);
    if (frame.field == SET_POSE_APPLY) {
        struct odometry *odo = &ecu->odometry;
        int64_t x_q40 = odo->x_q40_m;
        int64_t y_q40 = odo->y_q40_m;
        uint64_t heading = odo->heading_bam64;
        if ((ecu->staged_pose & (1u << SET_POSE_X)) != 0u) {
            x_q40 = q40_from_100um((int32_t)ecu->staged_pose_value[SET_POSE_X]);
        }
        if ((ecu->staged_pose & (1u << SET_POSE_Y)) != 0u) {
            y_q40 = q40_from_100um((int32_t)ecu->staged_pose_value[SET_POSE_Y]);
        }
        if ((ecu->staged_pose & (1u << SET_POSE_HEADING)) != 0u) {
            heading = (uint64_t)ecu->staged_pose_value[SET_POSE_HEADING] << 48;
        }
        odometry_set_pose(odo, x_q40, y_q40, heading);
        ecu->staged_pose = 0u;
    } else if (frame.field <= SET_POSE_HEADING) {
        ecu->staged_pose_value[frame.field] = frame.value;
        ecu->staged_pose |= 1u << frame.field;
    } else {
        ack(ecu, ODOM_SET_POSE_ID, &frame, ACK_RESULT_NACK, ACK_UNKNOWN_FIELD);
        return;
    }
    ack(ecu, ODOM_SET_POSE_ID, &frame, ACK_RESULT_ACK, ACK_OK);
}

static void on_config(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (!e2e(ecu, &ecu->rx_config, data, len)) {
        return;
    }
    struct mux_record frame;
    unpack_odom_config(data, &frame);
    if (frame.field == PARAM_APPLY) {
        apply_config(ecu, &frame);
    } else if (frame.field <= PARAM_INTEGRATOR) {
        ecu->staged_config_value[frame.field] = (uint32_t)frame.value;
        ecu->staged_config |= 1u << frame.field;
        ack(ecu, ODOM_CONFIG_ID, &frame, ACK_RESULT_ACK, ACK_OK);
    } else {
        ack(ecu, ODOM_CONFIG_ID, &frame, ACK_RESULT_NACK, ACK_UNKNOWN_FIELD);
    }
}

/* Validate the current parameters overwritten by the staged ones; commit all or nothing. */
static void apply_config(struct odom_ecu *ecu, const struct mux_record *frame)
{
    struct robot_params candidate = ecu->params;
    uint32_t *fields[6] = {
        &candidate.counts_per_rev, &candidate.wheel_radius_left_nm,
        &candidate.wheel_radius_right_nm, &candidate.wheelbase_nm,
        &candidate.counter_bits, &candidate.integrator,
    };
    for (unsigned param = 0u; param < 6u; ++param) {
        if ((ecu->staged_config & (1u << param)) != 0u) {
            *fields[param] = ecu->staged_config_value[param];
        }
    }
    ecu->staged_config = 0u;
    enum config_reason reason = validate(&candidate);
    if (reason != CONFIG_OK) {
        ecu->errors |= ERROR_CONFIG_INVALID;
        enum ack_reason ack_reason =
            reason == CONFIG_GEOMETRY_ABSURD ? ACK_INCONSISTENT : ACK_OUT_OF_RANGE;
        ack(ecu, ODOM_CONFIG_ID, frame, ACK_RESULT_NACK, ack_reason);
        return;
    }
    if (candidate.counter_bits != ecu->params.counter_bits) {
        odometry_unprime(&ecu->odometry);
        ecu->wire_prev_valid = false;
    }
    ecu->params = candidate;
    struct odom_constants consts;
    derive_constants(&candidate, &ecu->errors, &consts);
    odometry_reconfigure(&ecu->odometry, &consts);
    if (ecu->state == STATE_FAULT) {
        ecu->state = STATE_INIT;
    }
    ack(ecu, ODOM_CONFIG_ID, frame, ACK_RESULT_ACK, ACK_OK);
}

static void on_nav_goal(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (!e2e(ecu, &ecu->rx_nav_goal, data, len)) {
        return;
    }
    struct mux_record frame;
    struct nav_goal_frame goal;
    uint8_t mode;
    uint8_t append;
    uint8_t no_final_heading;
    unpack_nav_goal(data, &frame, &mode, &append, &no_final_heading, &goal.goal_id);
    goal.field = frame.field;
    goal.value = frame.value;
    goal.mode = mode;
    goal.append = append;
    goal.no_final_heading = no_final_heading;
    enum ack_reason reason = nav_request(&ecu->nav, &goal, ecu->state == STATE_OK);
    ack(ecu, NAV_GOAL_ID, &frame, reason == ACK_OK ? ACK_RESULT_ACK : ACK_RESULT_NACK, reason);
}

static void ack(struct odom_ecu *ecu, uint32_t request_id, const struct mux_record *frame,
                enum ack_result result, enum ack_reason reason)
{
    uint8_t data[8];
    pack_odom_ack(data, next_counter(ecu, TX_ACK), frame->counter, request_id, frame->field,
                  result, reason, &ecu->errors);
    send(ecu, ODOM_ACK_ID, data);
}

/* --- step 4: controllers --- */

/* Navigation every NAV_PERIOD_TICKS, from the on-board pose; it decides MOTOR_CMD. */
static void navigate(struct odom_ecu *ecu)
{
    ecu->motor_cmd_due = false;
    if (ecu->ticks % NAV_PERIOD_TICKS == 0u) {
        const struct odometry *odo = &ecu->odometry;
        ecu->motor_cmd_due = nav_step(&ecu->nav, odo->x_q40_m, odo->y_q40_m, odo->heading_bam64,
                                      ecu->params.wheelbase_nm, ecu->state == STATE_OK);
    }
}

/* --- step 5: scheduled transmissions --- */

static void transmit_scheduled(struct odom_ecu *ecu)
{
    if (ecu->motor_cmd_due) {
        uint8_t cmd[8];
        pack_motor_cmd(cmd, next_counter(ecu, TX_MOTOR_CMD), ecu->nav.left_mm_s,
                       ecu->nav.right_mm_s, &ecu->errors);
        send(ecu, MOTOR_CMD_ID, cmd);
    }
    if (ecu->ticks % POSE_PERIOD_TICKS == 0u && ecu->state != STATE_INIT) {
        send_pose_and_twist(ecu);
    }
    if (ecu->ticks % STATUS_PERIOD_TICKS == 0u) {
        send_status(ecu);
    }
    if (ecu->nav.changed || ecu->ticks % STATUS_PERIOD_TICKS == 0u) {
        send_nav_status(ecu);
    }
}

/* NAV_STATUS; DISTANCE is clamped to its 65.535 m range here (a display limit). */
static void send_nav_status(struct odom_ecu *ecu)
{
    struct navigator *nav = &ecu->nav;
    nav->changed = false;
    int64_t distance_mm = div_round_i64(nav->distance_um, 1000);
    if (distance_mm > U16_MAX) {
        distance_mm = U16_MAX;
    }
    int16_t heading_error_bam16 =
        wrap_i16(asr_i64((int64_t)nav->heading_error_bam32 + (1 << 15), 16u));
    uint8_t data[8];
    pack_nav_status(data, next_counter(ecu, TX_NAV_STATUS), nav->state, nav->goal_id,
                    nav->depth, distance_mm, heading_error_bam16, &ecu->errors);
    send(ecu, NAV_STATUS_ID, data);
}

static void send_pose_and_twist(struct odom_ecu *ecu)
{
    const struct odometry *odo = &ecu->odometry;
    uint8_t enc = ecu->enc_counter;
    int64_t x_100um = mul_shr_round_i64(odo->x_q40_m, 10000, 40u, &ecu->errors);
    int64_t y_100um = mul_shr_round_i64(odo->y_q40_m, 10000, 40u, &ecu->errors);
    uint64_t heading_rounded = odo->heading_bam64 + (UINT64_C(1) << 47);
    int64_t carry = heading_rounded < odo->heading_bam64 ? 1 : 0; /* a whole turn */
    uint32_t heading_bam16 = (uint32_t)(heading_rounded >> 48);
    int32_t turns = wrap_i32((int64_t)odo->heading_turns + carry);
    wide128_t distance_w = wide_add(wide_mul_u64(odo->distance_q40_m, 1000u),
                                    wide_from_u64(UINT64_C(1) << 39));
    uint64_t distance_mm = wide_asr(distance_w, 40u).lo; /* < 2^34 */
    uint8_t data[8];
    pack_odom_pose_x(data, next_counter(ecu, TX_POSE_X), enc, x_100um, heading_bam16,
                     &ecu->errors);
    send(ecu, ODOM_POSE_X_ID, data);
    pack_odom_pose_y(data, next_counter(ecu, TX_POSE_Y), enc, y_100um, turns, &ecu->errors);
    send(ecu, ODOM_POSE_Y_ID, data);
    pack_odom_twist(data, next_counter(ecu, TX_TWIST), enc, ecu->twist_mm_s, ecu->twist_mrad_s,
                    distance_mm, &ecu->errors);
    send(ecu, ODOM_TWIST_ID, data);
}

static void send_status(struct odom_ecu *ecu)
{
    uint8_t data[8];
    uint32_t error_bits = ecu->errors; /* read before the pack may add SATURATION */
    pack_odom_status_summary(data, next_counter(ecu, TX_STATUS), ecu->state,
                             ecu->odometry.consts.integrator, error_bits,
                             ecu->ticks / TICKS_PER_SECOND, &ecu->errors);
    send(ecu, ODOM_STATUS_ID, data);
    enum status_page page = ROTATING_PAGES[ecu->page_index];
    ecu->page_index = (ecu->page_index + 1u) % 5u;
    uint8_t counter = next_counter(ecu, TX_STATUS);
    if (page == PAGE_FRAME_TOTALS) {
        pack_odom_status_frame_totals(data, counter, ecu->rx_encoders.lost_frames,
                                      ecu_frames_rejected(ecu), ecu->mailbox.overflows);
    } else {
        const struct e2e_receiver *rx = page == PAGE_E2E_WHEEL_ENCODERS ? &ecu->rx_encoders
                                        : page == PAGE_E2E_ODOM_SET_POSE ? &ecu->rx_set_pose
                                        : page == PAGE_E2E_ODOM_CONFIG   ? &ecu->rx_config
                                                                         : &ecu->rx_nav_goal;
        pack_odom_status_e2e(data, counter, page, e2e_accepted(rx), rx->lost_frames,
                             rx->count_repeated, rx->count_error, rx->count_wrongsequence);
    }
    send(ecu, ODOM_STATUS_ID, data);
}

/* Frames refused by the E2E check or for their length (u32, wrapping). */
uint32_t ecu_frames_rejected(const struct odom_ecu *ecu)
{
    const struct e2e_receiver *rxs[4] = {&ecu->rx_encoders, &ecu->rx_set_pose, &ecu->rx_config,
                                         &ecu->rx_nav_goal};
    uint32_t total = ecu->frames_bad_length;
    for (unsigned k = 0u; k < 4u; ++k) {
        total += rxs[k]->count_error + rxs[k]->count_wrongsequence + rxs[k]->count_repeated;
    }
    return total;
}

static uint8_t next_counter(struct odom_ecu *ecu, enum tx_index which)
{
    ecu->tx_counters[which] = (uint8_t)((ecu->tx_counters[which] + 1u) & COUNTER_MASK);
    return ecu->tx_counters[which];
}

static void send(struct odom_ecu *ecu, uint32_t can_id, const uint8_t data[8])
{
    if (!ecu->transmit(ecu->tx_ctx, can_id, data)) {
        ecu->tx_dropped++;
    }
}

/* --- step 6: the watchdog --- */

static void watchdog(struct odom_ecu *ecu)
{
    if (ecu->state == STATE_INIT || ecu->state == STATE_FAULT) {
        return;
    }
    if (ecu->ticks_since_encoder >= WATCHDOG_TICKS) {
        if (ecu->state != STATE_DEGRADED) {
            ecu->state = STATE_DEGRADED;
            ecu->errors |= ERROR_ENCODER_TIMEOUT;
        }
        ecu->good_in_a_row = 0;
    } else if (ecu->state == STATE_DEGRADED && ecu->good_in_a_row >= RECOVERY_FRAMES) {
        ecu->state = STATE_OK;
    }
    if (ecu->ticks_since_encoder < WATCHDOG_TICKS) { /* Python counts on; only >= matters */
        ecu->ticks_since_encoder++;
    }
}
