/* The odometry ECU's main loop (firmware/ecu.py, same order): the receive ISR copies a frame into
 * the mailbox; tick() runs every TICK_PERIOD_US: 1. drain the mailbox; 2. E2E check; 3. odometry
 * on WHEEL_ENCODERS, staged ODOM_SET_POSE / ODOM_CONFIG / NAV_GOAL writes answered by ODOM_ACK;
 * 4. navigation every 20 ms; 5. scheduled transmissions at the DBC's cycle times; 6. the watchdog.
 *
 * Time: time_periods (10 ms periods since reset) advances at the start of every tick by the
 * periods elapsed on the board's microsecond timer (ecu_tick_at; ecu_tick: one period). A tick
 * LOST_TIME_PERIODS or more late sets TIME_LOST and goes DEGRADED. DEGRADED always carries a
 * reason: ENCODER_TIMEOUT, TIME_LOST, MAILBOX_OVERFLOW, IMPLAUSIBLE_STEP (a step beyond
 * MAX_WHEEL_SPEED_MM_S, not integrated) or COUNTER_RESET (RESYNC_FRAMES refused frames consistent
 * with each other: re-primed on the first of them, the jump never integrated; or a frame whose
 * CTRL_UPTIME is below the last accepted one's, both non-zero: the motor controller restarted,
 * re-primed on that frame when the next one confirms it (restarthold.py); it stays until
 * ODOM_SET_POSE APPLY). The module docstring of firmware/ecu.py says why.
 *
 * One file here, one Python module per job there (firmware/ecu.py composes them); each section
 * below names its module: mailbox.py, clock.py (advance_time), health.py (check_overflows,
 * degrade, watchdog), reception.py (e2e), encoders.py, twist.py, auth.py (SecOC), commands.py,
 * reports.py (step 5) and transmit.py (next_counter, send).
 */
#include "ecu.h"

#include <string.h>

#include "fixmath.h"
#include "frames.h"

enum tx_index { TX_MOTOR_CMD, TX_POSE_X, TX_POSE_Y, TX_TWIST, TX_ACK, TX_STATUS, TX_NAV_STATUS,
                TX_FRESHNESS };

#define ROTATING_PAGE_COUNT 6u
/* uncertainty.py: the rim acceleration bound (mm/s^2), the tolerance (um), the longest step the
 * acceleration bound is taken for, ceil(2 pi 10^6). */
#define MAX_WHEEL_ACCEL_MM_S2 UINT64_C(2000)
#define UNCERTAINTY_TOLERANCE_UM 50000u
#define ACCEL_PERIODS_MAX 64u
#define TWO_PI_URAD_CEIL UINT64_C(6283186)
static const enum status_page ROTATING_PAGES[ROTATING_PAGE_COUNT] = {
    PAGE_FRAME_TOTALS,    PAGE_E2E_WHEEL_ENCODERS, PAGE_E2E_ODOM_SET_POSE, PAGE_E2E_ODOM_CONFIG,
    PAGE_E2E_NAV_GOAL,    PAGE_PROFILE,
};

/* --- the mailbox (firmware/mailbox.py) --- */

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

static void tick(struct odom_ecu *ecu, bool timed, uint32_t now_us);
static void drain_mailbox(struct odom_ecu *ecu);
static uint32_t advance_time(struct odom_ecu *ecu, bool timed, uint32_t now_us);
static void check_overflows(struct odom_ecu *ecu);
static void degrade(struct odom_ecu *ecu, enum reason reason);
static void on_wheel_encoders(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void accept_encoders(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                            const uint32_t counts[2]);
static void extend_counters(const struct odom_ecu *ecu, const uint32_t wire[2],
                            uint32_t counts[2]);
static void commit_counters(struct odom_ecu *ecu, const uint32_t wire[2],
                            const uint32_t counts[2]);
static uint32_t counter_advance(const struct odom_ecu *ecu, uint8_t counter);
static bool mailbox_dropped(const struct odom_ecu *ecu);
static uint32_t step_periods(const struct odom_ecu *ecu, uint32_t advance);
static uint32_t periods_nearest(const struct odom_ecu *ecu, uint32_t advance, uint32_t since);
static uint32_t doubted_periods(const struct odom_ecu *ecu, uint32_t advance);
static uint32_t accepted_doubt(const struct odom_ecu *ecu);
static uint32_t bound_periods(const struct odom_ecu *ecu, uint32_t periods);
static void count_cycles_dropped(struct odom_ecu *ecu, uint8_t counter, uint32_t advance);
static void step_bounds(struct odom_ecu *ecu);
static void least_ambiguous_periods(struct odom_ecu *ecu);
static bool plausible(const struct odom_ecu *ecu, const uint32_t prev[2], const uint32_t counts[2],
                      uint32_t periods);
static void on_implausible(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                           const uint32_t counts[2]);
static bool beyond_width(const struct odom_ecu *ecu, const uint32_t wire[2]);
static void refuse_unused_bits(struct odom_ecu *ecu);
static void restart_counters(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                             const uint32_t counts[2]);
static bool controller_restarted(const struct odom_ecu *ecu, uint8_t uptime,
                                 const uint32_t wire[2], uint8_t counter);
static bool young_counts(const struct odom_ecu *ecu, const uint32_t wire[2], uint8_t uptime);
static uint8_t aged_uptime(const struct odom_ecu *ecu, uint8_t prev, uint8_t counter);
static void reprime(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                    const uint32_t counts[2]);
static void release_held(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                         uint8_t uptime, uint32_t counts[2]);
static bool hold_confirmed(const struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                           uint8_t uptime);
static void sum_step(struct odom_ecu *ecu);
static void add_merged_step(struct odom_ecu *ecu);
static void update_twist(struct odom_ecu *ecu, uint32_t periods);
static bool secured(struct odom_ecu *ecu, enum auth_request request, const uint8_t *data);
static void on_auth(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void expire_held(struct odom_ecu *ecu);
static void nack_held(struct odom_ecu *ecu, const struct held *held, enum auth_status status);
static void send_freshness(struct odom_ecu *ecu);
static void on_set_pose(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void act_set_pose(struct odom_ecu *ecu, const uint8_t *data);
static void on_config(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void act_config(struct odom_ecu *ecu, const uint8_t *data);
static void apply_config(struct odom_ecu *ecu, const struct mux_record *frame);
static void on_nav_goal(struct odom_ecu *ecu, const uint8_t *data, size_t len);
static void act_nav_goal(struct odom_ecu *ecu, const uint8_t *data);
static void ack(struct odom_ecu *ecu, uint32_t request_id, const struct mux_record *frame,
                enum ack_result result, enum ack_reason reason);
static void navigate(struct odom_ecu *ecu);
static void transmit_scheduled(struct odom_ecu *ecu);
static void send_nav_status(struct odom_ecu *ecu);
static void send_pose_and_twist(struct odom_ecu *ecu);
static void send_status(struct odom_ecu *ecu);
static uint8_t next_counter(struct odom_ecu *ecu, enum tx_index which);
static bool send(struct odom_ecu *ecu, uint32_t can_id, const uint8_t data[8]);
static void watchdog(struct odom_ecu *ecu);

void ecu_init(struct odom_ecu *ecu, can_tx_fn transmit, void *tx_ctx,
              const struct robot_params *params)
{
    memset(ecu, 0, sizeof *ecu);
    ecu->transmit = transmit;
    ecu->tx_ctx = tx_ctx;
    ecu->errors = 0u;
    ecu->state = STATE_INIT;
    ecu->reason = REASON_NONE;
    if (validate_at_speed(params, params->max_wheel_speed_mm_s) != CONFIG_OK) {
        ecu->errors |= ERROR_CONFIG_INVALID;
        ecu->state = STATE_FAULT;
        ecu->reason = REASON_CONFIG_INVALID;
    }
    ecu->params = *params;
    ecu->profile_crc = profile_crc32(params);
    struct odom_constants consts;
    derive_constants(params, &ecu->errors, &consts);
    odometry_init(&ecu->odometry, &consts, &ecu->errors);
    ecu->max_wheel_speed_mm_s = params->max_wheel_speed_mm_s;
    ecu->this_step_periods = 1u;
    ecu->uncertainty_um = 0u;
    ecu->uncertainty_tolerance_um = UNCERTAINTY_TOLERANCE_UM;
    step_bounds(ecu);
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
void ecu_provision_secoc(struct odom_ecu *ecu, const uint8_t *key, unsigned key_len,
                         struct freshness_nvm nvm)
{
    ecu->secoc_on = true;
    secoc_receiver_init(&ecu->secoc_rx, key, key_len, nvm, MAC_BITS);
    secured_init(&ecu->secoc, &ecu->secoc_rx);
    data_ids_of_slot(ODOM_AUTH_E2E_SLOT, ecu->auth_data_ids);
    e2e_receiver_init(&ecu->rx_auth, ecu->auth_data_ids, 15u, false);
}

void ecu_isr_can_rx(struct odom_ecu *ecu, uint32_t can_id, const uint8_t *data, size_t len)
{
    if (!mailbox_put(&ecu->mailbox, can_id, data, len)) {
        ecu->errors |= ERROR_MAILBOX_OVERFLOW;
        /* counted when it could be an encoder frame: its Profile 2 CRC holds (random payloads
         * pass 1 in 256; encoders.py isr_dropped) */
        if (can_id == WHEEL_ENCODERS_ID && len == FRAME_LEN
            && data[0] == p02_crc(data, ecu->rx_encoders.data_ids[data[1] & COUNTER_MASK])) {
            ecu->enc_frames_dropped++;
        }
    }
}

/* CAN controller overrun interrupt: its receive FIFO dropped frames (counted as one mailbox
 * overflow: the hardware flags the event, not the number). */
void ecu_isr_rx_overrun(struct odom_ecu *ecu)
{
    ecu->mailbox.overflows++;
    ecu->errors |= ERROR_MAILBOX_OVERFLOW;
}

/* CAN controller status interrupt: bus-off entered (true) or recovered (false). */
void ecu_isr_bus_state(struct odom_ecu *ecu, bool bus_off)
{
    if (bus_off) {
        ecu->errors |= ERROR_BUS_OFF;
    }
}

/* --- the periodic tick (firmware/ecu.py; advance_time: clock.py; check_overflows, degrade:
 * health.py) --- */

/* One period of the main loop on a board without a timer: one period has passed. */
void ecu_tick(struct odom_ecu *ecu)
{
    tick(ecu, false, 0u);
}

/* One period of the main loop; now_us: the board's free-running u32 microsecond timer when the
 * tick was released. */
void ecu_tick_at(struct odom_ecu *ecu, uint32_t now_us)
{
    tick(ecu, true, now_us);
}

/* The main loop, in the fixed order of the file comment. */
static void tick(struct odom_ecu *ecu, bool timed, uint32_t now_us)
{
    check_overflows(ecu);
    uint32_t periods = advance_time(ecu, timed, now_us); /* after: a stall's overrun is TIME_LOST */
    ecu->tick_late = periods > 0u ? periods - 1u : 0u; /* its frames may have queued so long */
    ecu->enc_dropped_before = ecu->enc_dropped_seen;
    ecu->enc_dropped_seen = ecu->enc_frames_dropped;
    /* The E2E window widens with time; fully after frames of unknown age (a stall's backlog) and
     * after frames the mailbox dropped (their count, not the window, bounds the step). */
    bool stale = ecu->samples_stale || mailbox_dropped(ecu);
    uint32_t widen = stale ? COUNTER_MASK : periods < COUNTER_MASK ? periods : COUNTER_MASK;
    for (uint32_t k = 0u; k < widen; ++k) {
        e2e_new_period(&ecu->rx_encoders);
    }
    ecu->tick_budget = ecu->periods_since_sample;
    drain_mailbox(ecu);
    expire_held(ecu);
    if (ecu->tick_steps != 0u && !ecu->time_lost_now) {
        /* a stall's backlog: its frames' periods are unknown, firmware time then */
        uint32_t budget = ecu->tick_budget > 1u ? ecu->tick_budget : 1u;
        update_twist(ecu, ecu->tick_carried ? budget : ecu->tick_periods);
    } else if (ecu->tick_steps != 0u) {
        ecu->tick_carried = true;
    }
    navigate(ecu);
    transmit_scheduled(ecu);
    watchdog(ecu);
    ecu->ticks++;
}

/* Steps 1-3: every frame in arrival order, to its handler. */
static void drain_mailbox(struct odom_ecu *ecu)
{
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
        } else if (can_id == ODOM_AUTH_ID && ecu->secoc_on) {
            on_auth(ecu, data, len);
        } else {
            ecu->frames_filtered++;
        }
        slot = mailbox_get(&ecu->mailbox);
    }
    if (!encoder_seen) {
        e2e_check(&ecu->rx_encoders, NULL, 0u);
    }
}

/* Firmware time: the periods elapsed on the timer since the previous tick, returned; rounded, the
 * remainder carried to the next tick so jitter never drifts the clock (u32 elapsed: the timer may
 * wrap, every 71.6 min). elapsed_us is in [-TICK/2, 2^32 + TICK/2): an i64; periods < 2^19. */
static uint32_t advance_time(struct odom_ecu *ecu, bool timed, uint32_t now_us)
{
    uint32_t periods = 1u;
    if (timed) {
        if (ecu->timer_prev_valid) {
            int64_t elapsed_us = (int64_t)(uint32_t)(now_us - ecu->timer_prev_us)
                                 + ecu->timer_rest_us;
            /* elapsed_us + TICK/2 >= 0: the rest is never below -TICK/2 */
            periods = (uint32_t)((elapsed_us + TICK_PERIOD_US / 2) / TICK_PERIOD_US);
            ecu->timer_rest_us = (int32_t)(elapsed_us - (int64_t)periods * TICK_PERIOD_US);
        }
        ecu->timer_prev_us = now_us;
        ecu->timer_prev_valid = true;
    }
    ecu->time_periods += periods;
    uint32_t since_encoder = ecu->ticks_since_encoder + periods; /* <= 2^16 + 2^19 */
    ecu->ticks_since_encoder = since_encoder < STEP_PERIODS_MAX ? since_encoder : STEP_PERIODS_MAX;
    uint32_t since_sample = ecu->periods_since_sample + periods;
    ecu->periods_since_sample = since_sample < STEP_PERIODS_MAX ? since_sample : STEP_PERIODS_MAX;
    ecu->time_lost_now = periods >= LOST_TIME_PERIODS;
    if (ecu->time_lost_now) {
        ecu->periods_lost += periods - 1u;
        ecu->errors |= ERROR_TIME_LOST;
        degrade(ecu, REASON_TIME_LOST);
    }
    return periods;
}

/* Frames the receive ISR dropped since the previous tick: DEGRADED (MAILBOX_OVERFLOW). */
static void check_overflows(struct odom_ecu *ecu)
{
    uint32_t overflows = ecu->mailbox.overflows;
    ecu->overflows_before = ecu->overflows_seen;
    if (overflows != ecu->overflows_seen) {
        ecu->overflows_seen = overflows;
        degrade(ecu, REASON_MAILBOX_OVERFLOW);
    }
}

/* OK or DEGRADED -> DEGRADED for reason (INIT and FAULT stay); recovery restarts.
 * POSE_UNCERTAIN is replaced by COUNTER_RESET alone (both latched until a set-pose).
 * COUNTER_RESET is never replaced by a later cause (those still set their error bits): only
 * ODOM_SET_POSE APPLY releases it, or a later cause would let the firmware report OK on a pose
 * that lost its continuity. A released reason is replaced by any cause. */
static void degrade(struct odom_ecu *ecu, enum reason reason)
{
    if (ecu->state == STATE_OK || ecu->state == STATE_DEGRADED) {
        ecu->state = STATE_DEGRADED;
        if (ecu->released
            || (ecu->reason != REASON_COUNTER_RESET
                && (ecu->reason != REASON_POSE_UNCERTAIN || reason == REASON_COUNTER_RESET))) {
            ecu->reason = reason;
            ecu->released = false;
        }
        ecu->good_in_a_row = 0;
        ecu->reason_tick = ecu->ticks;
        ecu->unreported = true;
    }
}

/* --- step 2-3: received frames (e2e: firmware/reception.py; WHEEL_ENCODERS:
 * firmware/encoders.py; sum_step, update_twist: firmware/twist.py) --- */

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
    uint8_t uptime;
    uint32_t wire[2];
    unpack_wheel_encoders(data, &counter, &wire[0], &wire[1], &uptime);
    if (beyond_width(ecu, wire)) {
        refuse_unused_bits(ecu);
        return;
    }
    uint32_t counts[2];
    extend_counters(ecu, wire, counts);
    ecu->uptime_now = uptime;
    if (ecu->hold_valid) {
        release_held(ecu, counter, wire, uptime, counts);
    }
    if (controller_restarted(ecu, uptime, wire, counter)) {
        ecu->hold_valid = true; /* taken when the next frame confirms it */
        ecu->hold_counter = counter;
        ecu->hold_uptime = uptime;
        ecu->hold_wire[0] = wire[0];
        ecu->hold_wire[1] = wire[1];
        return;
    }
    uint32_t advance = counter_advance(ecu, counter);
    uint32_t periods = step_periods(ecu, advance);
    uint32_t bound = bound_periods(ecu, periods);
    if (bound >= ecu->ambiguous_periods && ecu->counts_prev_valid) {
        reprime(ecu, counter, wire, counts); /* any step is as plausible as another */
        return;
    }
    const uint32_t *prev = ecu->counts_prev_valid ? ecu->counts_prev : NULL;
    if (!plausible(ecu, prev, counts, bound)) {
        periods = doubted_periods(ecu, advance);
        if (periods == 0u || !plausible(ecu, prev, counts, periods)) {
            on_implausible(ecu, counter, wire, counts);
            return;
        }
        if (periods >= ecu->ambiguous_periods) {
            reprime(ecu, counter, wire, counts);
            return;
        }
    }
    ecu->resync_first_valid = false;
    ecu->this_step_periods = periods;
    count_cycles_dropped(ecu, counter, advance);
    accept_encoders(ecu, counter, wire, counts);
}

/* ENC_E2E_LOST (the E2E receiver's lost_frames) also counts the whole COUNTER cycles of frames
 * the mailbox dropped, which the E2E check (the COUNTER mod 16) cannot see: advance less the
 * plain COUNTER advance (encoders.py _count_cycles_dropped). */
static void count_cycles_dropped(struct odom_ecu *ecu, uint8_t counter, uint32_t advance)
{
    int prev = ecu->enc_prev_counter;
    if (prev < 0) {
        return;
    }
    uint32_t plain = ((uint32_t)counter - (uint32_t)prev) & COUNTER_MASK;
    if (plain == 0u) {
        plain = COUNTER_MASK + 1u;
    }
    ecu->rx_encoders.lost_frames += advance - plain; /* wrapping */
}

/* Integrate an accepted WHEEL_ENCODERS frame; it feeds the watchdog's recovery. */
static void accept_encoders(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                            const uint32_t counts[2])
{
    commit_counters(ecu, wire, counts);
    ecu->uptime_prev = ecu->uptime_now;
    if (ecu->state != STATE_FAULT
        && odometry_step_counts(&ecu->odometry, counts[0], counts[1])) {
        sum_step(ecu);
    }
    ecu->enc_prev_counter = counter;
    ecu->enc_counter = counter;
    ecu->ticks_since_encoder = 0u;
    ecu->enc_overflows_at_accept = ecu->overflows_before;
    ecu->enc_dropped_at_accept = ecu->enc_dropped_before;
    ecu->samples_stale = ecu->time_lost_now;
    ecu->sample_doubt = accepted_doubt(ecu);
    if (!ecu->time_lost_now) {
        ecu->periods_since_sample = 0u;
    }
    if (ecu->good_in_a_row < RECOVERY_FRAMES) {
        ecu->good_in_a_row++;
    }
    if (ecu->state == STATE_INIT) {
        ecu->state = STATE_OK;
    }
}

/* The hardware counters from their low 24 bits on the wire (nothing is stored): a 16-bit counter
 * fits as it is; a 32-bit one is rebuilt by adding the wire's wrap-safe 24-bit delta to the last
 * accepted frame's counters. */
static void extend_counters(const struct odom_ecu *ecu, const uint32_t wire[2],
                            uint32_t counts[2])
{
    if (ecu->odometry.consts.counter_bits <= WIRE_COUNTER_BITS || !ecu->wire_prev_valid) {
        counts[0] = wire[0];
        counts[1] = wire[1];
        return;
    }
    for (unsigned side = 0u; side < 2u; ++side) {
        int32_t delta = wrap_signed(wire[side] - ecu->wire_prev[side], WIRE_COUNTER_BITS);
        counts[side] = ecu->counts_u32[side] + (uint32_t)delta; /* mod 2^32 */
    }
}

/* Take an accepted frame's counters as the base of the next deltas. */
static void commit_counters(struct odom_ecu *ecu, const uint32_t wire[2],
                            const uint32_t counts[2])
{
    for (unsigned side = 0u; side < 2u; ++side) {
        ecu->wire_prev[side] = wire[side];
        ecu->counts_u32[side] = counts[side];
        ecu->counts_prev[side] = counts[side];
    }
    ecu->wire_prev_valid = true;
    ecu->counts_prev_valid = true;
}

/* The frames from the last accepted one to this one (0: none accepted yet): the COUNTER advance
 * (mod 16, 1..16), or, when the mailbox dropped d frames on the WHEEL_ENCODERS ID between them,
 * the advance with that COUNTER nearest to d + 1 (d - 7 .. d + 8 frames between): d counts
 * only dropped frames whose CRC holds, yet a forged one that passes it (1 in 256) too, and
 * frames may also have been lost on the wire or refused after the drops (encoders.py _counter_advance). At most STEP_PERIODS_MAX + 16. */
static uint32_t counter_advance(const struct odom_ecu *ecu, uint8_t counter)
{
    int prev = ecu->enc_prev_counter;
    if (prev < 0) {
        return 0u;
    }
    uint32_t dropped = ecu->enc_dropped_before - ecu->enc_dropped_at_accept; /* wrapping */
    if (dropped > STEP_PERIODS_MAX) {
        dropped = STEP_PERIODS_MAX;
    }
    uint32_t beyond = ((uint32_t)counter - (uint32_t)prev - 1u - dropped) & COUNTER_MASK;
    uint32_t advance = dropped + 1u + beyond;
    if (beyond >= (COUNTER_MASK + 1u) / 2u && advance > COUNTER_MASK + 1u) {
        return advance - (COUNTER_MASK + 1u); /* d counted frames that were not the encoders' */
    }
    return advance;
}

/* The mailbox dropped frames (any, or an overrun) after the last accepted encoder frame and
 * before this tick's frames (encoders.py _mailbox_dropped). */
static bool mailbox_dropped(const struct odom_ecu *ecu)
{
    return ecu->enc_overflows_at_accept != ecu->overflows_before;
}

/* The encoder periods between this frame's sample and the last accepted one's: the COUNTER
 * advance n (counter_advance), plus the whole counter cycles that bring it nearest to the
 * periods since that frame was accepted (0 for a second frame in one tick), less the periods
 * this tick came late (its frames waited in the mailbox meanwhile). Exact while the two frames'
 * queueing differs by less than 8 periods; n in a regular stream (1). At most
 * 2 * STEP_PERIODS_MAX + 24. */
static uint32_t step_periods(const struct odom_ecu *ecu, uint32_t advance)
{
    if (advance == 0u) {
        return 1u;
    }
    return periods_nearest(ecu, advance, ecu->periods_since_sample);
}

/* advance (1..) plus the whole counter cycles nearest to since periods (u16) less this tick's
 * lateness (step_periods; sampledoubt.py periods_nearest). */
static uint32_t periods_nearest(const struct odom_ecu *ecu, uint32_t advance, uint32_t since)
{
    uint32_t budget = (since > ecu->tick_late ? since - ecu->tick_late : 0u) + 8u; /* <= 2^16 + 8 */
    if (budget <= advance) {
        return advance;
    }
    return advance + (((budget - advance) >> 4) << 4);
}

/* The periods of a step the bound refused, counted from the sample before the last accepted
 * frame's (step_periods with sample_doubt more periods since it); 0 when that frame came in the
 * period after it or none was accepted. That frame may have waited out the silence before it (a
 * delayed frame held in a bus-off sender's transmit buffer goes out first at the recovery): its
 * sample is no earlier than the one before it (sampledoubt.py doubted_periods). */
static uint32_t doubted_periods(const struct odom_ecu *ecu, uint32_t advance)
{
    uint32_t doubt = ecu->sample_doubt;
    if (doubt <= 1u || advance == 0u) {
        return 0u;
    }
    uint32_t since = ecu->periods_since_sample + doubt; /* < 2^17 */
    return periods_nearest(ecu, advance, since < STEP_PERIODS_MAX ? since : STEP_PERIODS_MAX);
}

/* The doubt of a frame accepted now: the periods since the last accepted frame was taken (its
 * sample is no earlier than that one's); that frame's doubt when it was taken in this same tick
 * (periods_since_sample 0: the held frames go out back to back, and this one's sample is no
 * earlier than that frame's, which may lie the whole silence back); 0 in a tick that lost time
 * (sampledoubt.py accepted_doubt). */
static uint32_t accepted_doubt(const struct odom_ecu *ecu)
{
    if (ecu->time_lost_now) {
        return 0u;
    }
    return ecu->periods_since_sample == 0u ? ecu->sample_doubt : ecu->periods_since_sample;
}

/* The periods the plausibility bound allows this step: periods, or, when the mailbox may have
 * dropped frames between the last accepted frame and this one (drops seen at a tick's start from
 * the accepting tick on, before this frame's tick: a full ring drops the newest), periods plus a
 * whole COUNTER cycle plus the periods since the last accepted frame's sample, saturated at
 * STEP_PERIODS_MAX (encoders.py _dropped_bound_periods: the advance counts the dropped frames
 * whose CRC holds; the cycle, frames lost on the wire beyond them; the time, frames no one
 * counted). Was STEP_PERIODS_MAX: any forged frame passing the CRC was integrated. */
static uint32_t bound_periods(const struct odom_ecu *ecu, uint32_t periods)
{
    if (!mailbox_dropped(ecu)) {
        return periods;
    }
    uint32_t bound = periods + (COUNTER_MASK + 1u) + ecu->periods_since_sample; /* < 2^18 */
    return bound < STEP_PERIODS_MAX ? bound : STEP_PERIODS_MAX;
}

/* True when the wire counts set bits above the counters' width (a 16-bit counter's top 8 of the
 * wire's 24): no controller sends them (encoders.py _unused_wire_bits). */
static bool beyond_width(const struct odom_ecu *ecu, const uint32_t wire[2])
{
    unsigned bits = (unsigned)ecu->odometry.consts.counter_bits;
    return bits < WIRE_COUNTER_BITS && ((wire[0] | wire[1]) >> bits) != 0u;
}

/* Refuse a frame beyond the counters' width, or a held restart frame the next one does not
 * confirm: DEGRADED, IMPLAUSIBLE_STEP, the resync state
 * untouched (encoders.py _refuse_unused_bits). */
static void refuse_unused_bits(struct odom_ecu *ecu)
{
    ecu->frames_implausible++;
    ecu->errors |= ERROR_IMPLAUSIBLE_STEP;
    degrade(ecu, REASON_IMPLAUSIBLE_STEP);
}

/* Per wheel, the most counts one encoder period can hold at max_wheel_speed_mm_s:
 * ceil(v_max * T / travel per count) + 1 (a count edge may fall either side of a sample).
 * Configuration time: a 128-bit muldiv (travel < 2^44), then u64 division; the ceiling as
 * quotient + (remainder != 0), which equals Python's (a + m - 1) // m without the u64 sum. The
 * per-count travel is a u64 (U64_MAX after an invalid boot configuration). */
static void step_bounds(struct odom_ecu *ecu)
{
    const struct odom_constants *c = &ecu->odometry.consts;
    uint64_t travel_q48_m =
        muldiv_round_u64((uint64_t)ecu->max_wheel_speed_mm_s * ENCODER_PERIOD_US,
                         UINT64_C(1) << 48, UINT64_C(1000000000), &ecu->errors);
    uint64_t per_count[2] = {(uint64_t)c->m_per_count_left_q48_m,
                             (uint64_t)c->m_per_count_right_q48_m};
    for (unsigned side = 0u; side < 2u; ++side) {
        uint64_t m = per_count[side]; /* >= 1: muldiv rounds a positive circumference */
        uint64_t ceil = travel_q48_m / m + (travel_q48_m % m != 0u ? 1u : 0u);
        ecu->max_counts_per_period[side] = ceil + 1u;
    }
    least_ambiguous_periods(ecu);
}

/* The fewest step periods whose plausibility bound reaches half the range the counts are read in
 * (the counters' width, at most the wire's 24 bits) on either wheel: every wire delta is then
 * as plausible as another, the step is ambiguous and never integrated (on_wheel_encoders
 * re-primes, COUNTER_RESET). ceil(half / counts per period) of the larger bound, saturated at
 * STEP_PERIODS_MAX (encoders.py _least_ambiguous_periods). Configuration time: u64 division. */
static void least_ambiguous_periods(struct odom_ecu *ecu)
{
    unsigned bits = (unsigned)ecu->odometry.consts.counter_bits;
    if (bits > WIRE_COUNTER_BITS) {
        bits = WIRE_COUNTER_BITS;
    }
    uint64_t half = UINT64_C(1) << (bits - 1u);
    uint64_t most = ecu->max_counts_per_period[0] > ecu->max_counts_per_period[1]
                        ? ecu->max_counts_per_period[0]
                        : ecu->max_counts_per_period[1]; /* >= 1 */
    uint64_t least = half / most + (half % most != 0u ? 1u : 0u);
    ecu->ambiguous_periods = least < STEP_PERIODS_MAX ? (uint32_t)least : STEP_PERIODS_MAX;
}

/* True when each wheel moved at most periods times its per-period bound since prev (NULL:
 * nothing to compare, plausible). periods <= 2^16 + 16 and the bound < 2^44: the product < 2^61. */
static bool plausible(const struct odom_ecu *ecu, const uint32_t prev[2], const uint32_t counts[2],
                      uint32_t periods)
{
    if (prev == NULL) {
        return true;
    }
    unsigned bits = (unsigned)ecu->odometry.consts.counter_bits;
    for (unsigned side = 0u; side < 2u; ++side) {
        int32_t delta = wrap_signed(counts[side] - prev[side], bits);
        if (abs_u64(delta) > (uint64_t)periods * ecu->max_counts_per_period[side]) {
            return false;
        }
    }
    return true;
}

/* Refuse the step (DEGRADED, IMPLAUSIBLE_STEP); RESYNC_FRAMES refused frames in a row that are
 * plausible among themselves are a counter restart (COUNTER_RESET): re-prime on the first of them
 * and integrate from there, never the jump. */
static void on_implausible(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                           const uint32_t counts[2])
{
    ecu->frames_implausible++;
    ecu->errors |= ERROR_IMPLAUSIBLE_STEP;
    degrade(ecu, REASON_IMPLAUSIBLE_STEP);
    uint32_t periods = ((uint32_t)counter - ecu->resync_last_counter) & COUNTER_MASK;
    if (ecu->resync_first_valid
        && plausible(ecu, ecu->resync_last, counts, periods != 0u ? periods : 1u)) {
        ecu->resync_frames++;
    } else {
        ecu->resync_first[0] = counts[0];
        ecu->resync_first[1] = counts[1];
        ecu->resync_first_counter = counter;
        ecu->resync_first_valid = true;
        ecu->resync_frames = 1;
    }
    ecu->resync_last[0] = counts[0];
    ecu->resync_last[1] = counts[1];
    ecu->resync_last_counter = counter;
    if (ecu->resync_frames >= RESYNC_FRAMES) {
        restart_counters(ecu, counter, wire, counts);
    }
}

/* The encoder counters restarted: prime on the first consistent frame, integrate from it up to
 * counts (its periods from the COUNTER advance). */
static void restart_counters(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                             const uint32_t counts[2])
{
    if (!ecu->resync_first_valid) {
        return;
    }
    ecu->errors |= ERROR_COUNTER_RESET;
    degrade(ecu, REASON_COUNTER_RESET);
    ecu->resync_first_valid = false;
    ecu->resync_frames = 0;
    odometry_unprime(&ecu->odometry);
    (void)odometry_step_counts(&ecu->odometry, ecu->resync_first[0], ecu->resync_first[1]);
    ecu->enc_prev_counter = -1;
    ecu->this_step_periods =
        ((uint32_t)counter - (uint32_t)ecu->resync_first_counter) & COUNTER_MASK;
    if (ecu->this_step_periods == 0u) {
        ecu->this_step_periods = COUNTER_MASK + 1u;
    }
    accept_encoders(ecu, counter, wire, counts);
}

/* True when uptime (this frame's CTRL_UPTIME, u4) is below what the last accepted frame's has
 * aged to since (aged_uptime; counter: this frame's COUNTER), both reported (non-zero), and wire
 * (its counts) near enough 0 for that age: the controller restarted, its counters from 0
 * (encoders.py _controller_restarted). */
static bool controller_restarted(const struct odom_ecu *ecu, uint8_t uptime,
                                 const uint32_t wire[2], uint8_t counter)
{
    uint8_t prev = ecu->uptime_prev;
    if (uptime == 0u || prev == 0u || uptime >= aged_uptime(ecu, prev, counter)) { /* >= prev */
        return false;
    }
    return young_counts(ecu, wire, uptime);
}

/* The least CTRL_UPTIME (u4) a controller that did not restart can report now, prev at the last
 * accepted frame: prev plus the whole seconds of firmware time since that frame, less the periods
 * this tick came late and RESTART_SLACK_PERIODS (the frames' queueing), saturated at
 * CTRL_UPTIME_MAX; prev after a tick that lost time or frames the mailbox dropped (a backlog's
 * frames were sampled at unknown times), and when counter is the E2E successor of the last
 * accepted frame's (it waited behind the silence, sampled as old: no frame lost, no restart
 * told by age; the proof and what it gives up: encoders.py _aged_uptime). */
static uint8_t aged_uptime(const struct odom_ecu *ecu, uint8_t prev, uint8_t counter)
{
    uint32_t since = ecu->ticks_since_encoder;                   /* u16, saturated */
    uint32_t late = ecu->tick_late + RESTART_SLACK_PERIODS;      /* < 2^19 + 16 */
    bool successor = counter == (uint8_t)((ecu->enc_counter + 1u) & COUNTER_MASK);
    if (since <= late || successor || ecu->time_lost_now || mailbox_dropped(ecu)) {
        return prev;
    }
    uint32_t aged = prev + (since - late) / PERIODS_PER_S;      /* at most 15 + 655 */
    return aged < CTRL_UPTIME_MAX ? (uint8_t)aged : (uint8_t)CTRL_UPTIME_MAX;
}

/* True when each wheel's count, read signed in the wire's bits, is within the counts a controller
 * uptime seconds old can have run from 0: uptime * PERIODS_PER_S periods of its per-period bound
 * (at most 1500 * 2^44 < 2^55). */
static bool young_counts(const struct odom_ecu *ecu, const uint32_t wire[2], uint8_t uptime)
{
    unsigned bits = (unsigned)ecu->odometry.consts.counter_bits;
    if (bits > WIRE_COUNTER_BITS) {
        bits = WIRE_COUNTER_BITS;
    }
    uint64_t periods = (uint64_t)uptime * PERIODS_PER_S;
    for (unsigned side = 0u; side < 2u; ++side) {
        int32_t count = wrap_signed(wire[side], bits);
        if (abs_u64(count) > periods * ecu->max_counts_per_period[side]) {
            return false;
        }
    }
    return true;
}

/* The controller restarted (CTRL_UPTIME went down): COUNTER_RESET as restart_counters sets it,
 * the odometry re-primed on this frame (its step from the last accepted frame, the restart's
 * jump, is never integrated). */
static void reprime(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                    const uint32_t counts[2])
{
    ecu->errors |= ERROR_COUNTER_RESET;
    degrade(ecu, REASON_COUNTER_RESET);
    ecu->resync_first_valid = false;
    ecu->resync_frames = 0;
    odometry_unprime(&ecu->odometry);
    ecu->enc_prev_counter = -1;
    ecu->this_step_periods = 1u;
    accept_encoders(ecu, counter, wire, counts);
}

/* The frame after a held one (counts: from the last accepted frame): if it confirms the held
 * frame, re-prime on the held frame and rebuild counts from it; else refuse the held frame
 * (encoders.py _release_held). */
static void release_held(struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                         uint8_t uptime, uint32_t counts[2])
{
    ecu->hold_valid = false;
    if (!hold_confirmed(ecu, counter, wire, uptime)) {
        refuse_unused_bits(ecu);
        return;
    }
    uint32_t held[2] = {ecu->hold_wire[0], ecu->hold_wire[1]};
    uint32_t held_counts[2];
    extend_counters(ecu, held, held_counts);
    ecu->uptime_now = ecu->hold_uptime;
    reprime(ecu, ecu->hold_counter, held, held_counts);
    ecu->uptime_now = uptime;
    extend_counters(ecu, wire, counts);
}

/* True when a frame confirms the held one: a COUNTER advance of n = 1..15 from it, CTRL_UPTIME
 * the held one's or one more, each wheel within n periods' bound of the held frame's (read signed
 * in the wire's bits; at most 15 * 2^44) and its counts young (restarthold.py
 * RestartHold.confirms). */
static bool hold_confirmed(const struct odom_ecu *ecu, uint8_t counter, const uint32_t wire[2],
                           uint8_t uptime)
{
    uint64_t periods = ((uint32_t)counter - (uint32_t)ecu->hold_counter) & COUNTER_MASK;
    if (periods == 0u || uptime < ecu->hold_uptime
        || (uint32_t)uptime > (uint32_t)ecu->hold_uptime + 1u) {
        return false;
    }
    unsigned bits = (unsigned)ecu->odometry.consts.counter_bits;
    if (bits > WIRE_COUNTER_BITS) {
        bits = WIRE_COUNTER_BITS;
    }
    for (unsigned side = 0u; side < 2u; ++side) {
        int32_t delta = wrap_signed(wire[side] - ecu->hold_wire[side], bits);
        if (abs_u64(delta) > periods * ecu->max_counts_per_period[side]) {
            return false;
        }
    }
    return young_counts(ecu, wire, uptime);
}

/* Add the step just integrated to this tick's sums (Q20 m, Q30 rad; i64, saturated). Each term
 * is below 2^34 (dS >> 29) and 2^62 (the heading: its signed read plus its whole turns), each
 * sum below 2^32 before: no overflow. */
static void sum_step(struct odom_ecu *ecu)
{
    const struct odometry *odo = &ecu->odometry;
    if (ecu->this_step_periods > 1u) {
        add_merged_step(ecu);
    }
    int64_t dheading_q30_rad =
        mul_shr_round_i64(odo->last_dheading_bam64, TWO_PI_Q60, 94u, &ecu->errors)
        + (int64_t)odo->last_dheading_turns * TWO_PI_Q30;
    ecu->tick_ds_q20_m = sat_range(ecu->tick_ds_q20_m + asr_i64(odo->last_ds_q49_m, 29u),
                                   -TWIST_SUM_MAX, TWIST_SUM_MAX, &ecu->errors);
    ecu->tick_dheading_q30_rad = sat_range(ecu->tick_dheading_q30_rad + dheading_q30_rad,
                                           -TWIST_SUM_MAX, TWIST_SUM_MAX, &ecu->errors);
    ecu->tick_steps++;
    uint32_t periods = ecu->tick_periods + ecu->this_step_periods; /* < 2^18 */
    ecu->tick_periods = periods < STEP_PERIODS_MAX ? periods : STEP_PERIODS_MAX;
}

/* ceil(num / den) of num >= 0, den > 0. */
static uint64_t ceil_div_u64(uint64_t num, uint64_t den)
{
    return (num + den - 1u) / den;
}

/* The worst-case position error (um) of one step of periods (>= 2) encoder periods: the smaller
 * of 2 V tau and the acceleration bound plus the integrator's distance from the arc
 * (firmware/uncertainty.py merged_step_bound_um, which derives it). Products < 2^63. */
static uint64_t merged_step_bound_um(const struct robot_params *params, uint32_t periods,
                                     int64_t ds_q49_m, int64_t dheading_bam64, int32_t turns)
{
    uint64_t speed_um = UINT64_C(20) * params->max_wheel_speed_mm_s * periods;
    if (turns != 0 || periods > ACCEL_PERIODS_MAX || ds_q49_m == INT64_MIN) {
        return speed_um;
    }
    uint64_t tau_us = (uint64_t)periods * ENCODER_PERIOD_US;
    uint64_t at2_um = ceil_div_u64(MAX_WHEEL_ACCEL_MM_S2 * tau_us * tau_us, UINT64_C(1000000000));
    uint64_t ds_abs = ds_q49_m < 0 ? (uint64_t)0 - (uint64_t)ds_q49_m : (uint64_t)ds_q49_m;
    uint64_t d_um = (((ds_abs >> 29) * UINT64_C(1000000)) >> 20) + 1u;
    uint64_t th_abs = dheading_bam64 < 0 ? (uint64_t)0 - (uint64_t)dheading_bam64
                                         : (uint64_t)dheading_bam64;
    uint64_t th_urad = (((th_abs >> 32) * TWO_PI_URAD_CEIL) >> 32) + 1u;
    uint64_t b_um = params->wheelbase_nm / 1000u;
    uint64_t bound = ceil_div_u64(at2_um * (d_um + (at2_um >> 1) + 1u), 6u * b_um);
    bound += ceil_div_u64(at2_um * th_urad, UINT64_C(12000000));
    if (params->integrator != INTEGRATOR_EXACT) {
        uint64_t d_th = ceil_div_u64(d_um * th_urad, UINT64_C(1000000));
        bound += ceil_div_u64(d_th * th_urad, UINT64_C(24000000));
        if (params->integrator == INTEGRATOR_EULER) {
            bound += ceil_div_u64(d_th, 2u);
        }
    }
    return bound < speed_um ? bound : speed_um;
}

/* A step of this_step_periods > 1 was integrated: add its bound to the uncertainty; past the
 * tolerance, DEGRADED (POSE_UNCERTAIN), latched until a set-pose (uncertainty.py). */
static void add_merged_step(struct odom_ecu *ecu)
{
    const struct odometry *odo = &ecu->odometry;
    uint64_t total = (uint64_t)ecu->uncertainty_um
        + merged_step_bound_um(&ecu->params, ecu->this_step_periods, odo->last_ds_q49_m,
                               odo->last_dheading_bam64, odo->last_dheading_turns);
    ecu->uncertainty_um = total < UINT32_MAX ? (uint32_t)total : UINT32_MAX;
    if (ecu->uncertainty_um > ecu->uncertainty_tolerance_um) {
        ecu->errors |= ERROR_POSE_UNCERTAIN;
        if (ecu->reason != REASON_POSE_UNCERTAIN || ecu->released) {
            degrade(ecu, REASON_POSE_UNCERTAIN);
        }
    }
}

/* Speeds over this tick's steps, which cover the periods (1 .. STEP_PERIODS_MAX): the steps'
 * sample periods (step_periods: the COUNTER advance, whole counter cycles from firmware time),
 * so lost frames and a late frame (one step in a tick of two periods, then two in a tick of one)
 * give the true mean speed; after a stall (summed over two ticks) the firmware time since the last
 * sample before it, as the backlog's sample times are unknown. Products < 2^32 * 10^9 < 2^62; dt_us < 2^30, so dt_us << 30 < 2^60. The
 * sums restart. */
static void update_twist(struct odom_ecu *ecu, uint32_t periods)
{
    int64_t dt_us = (int64_t)periods * ENCODER_PERIOD_US;
    ecu->twist_mm_s =
        div_round_i64(ecu->tick_ds_q20_m * INT64_C(1000000000), dt_us * (INT64_C(1) << 20));
    ecu->twist_mrad_s = div_round_i64(ecu->tick_dheading_q30_rad * INT64_C(1000000000),
                                      dt_us * (INT64_C(1) << 30));
    ecu->tick_ds_q20_m = 0;
    ecu->tick_dheading_q30_rad = 0;
    ecu->tick_steps = 0u;
    ecu->tick_periods = 0u;
    ecu->tick_carried = false;
}

/* --- SecOC: verify before acting (firmware/auth.py) --- */

/* True when the frame (E2E OK) was held for its ODOM_AUTH instead of acted on now; a frame it
 * displaced is refused (NACK AUTH_MISSING). */
static bool secured(struct odom_ecu *ecu, enum auth_request request, const uint8_t *data)
{
    if (!ecu->secoc_on) {
        return false;
    }
    struct held displaced;
    if (secured_hold(&ecu->secoc, request, data, ecu->ticks, &displaced)) {
        nack_held(ecu, &displaced, AUTH_MISSING);
    }
    return true;
}

/* ODOM_AUTH: verify the held frame it names; act on it, or NACK it with the verdict. */
static void on_auth(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (!ecu->secoc_on || !e2e(ecu, &ecu->rx_auth, data, len)) {
        return;
    }
    struct odom_auth auth;
    unpack_odom_auth(data, &auth);
    enum auth_status status;
    struct held held;
    if (!secured_authenticate(&ecu->secoc, &auth, &status, &held)) {
        return; /* nothing held for it: counted (orphans), no answer */
    }
    if (status != AUTH_OK) {
        nack_held(ecu, &held, status);
    } else if (held.can_id == ODOM_SET_POSE_ID) {
        act_set_pose(ecu, held.pdu);
    } else if (held.can_id == ODOM_CONFIG_ID) {
        act_config(ecu, held.pdu);
    } else {
        act_nav_goal(ecu, held.pdu);
    }
}

/* Held frames whose ODOM_AUTH did not come in time: NACK AUTH_MISSING. */
static void expire_held(struct odom_ecu *ecu)
{
    if (!ecu->secoc_on) {
        return;
    }
    struct held held;
    while (secured_expire(&ecu->secoc, ecu->ticks, &held)) {
        nack_held(ecu, &held, AUTH_MISSING);
    }
}

/* ODOM_ACK NACK for a held secured frame, REASON the AUTH verdict (7..10). */
static void nack_held(struct odom_ecu *ecu, const struct held *held, enum auth_status status)
{
    struct mux_record frame;
    if (held->can_id == ODOM_SET_POSE_ID) {
        unpack_odom_set_pose(held->pdu, &frame);
    } else if (held->can_id == ODOM_CONFIG_ID) {
        unpack_odom_config(held->pdu, &frame);
    } else {
        uint8_t mode, append, no_final_heading, goal_id;
        unpack_nav_goal(held->pdu, &frame, &mode, &append, &no_final_heading, &goal_id);
    }
    ack(ecu, held->can_id, &frame, ACK_RESULT_NACK, (enum ack_reason)status);
}

/* ODOM_FRESHNESS when due (boot, refusal, rollover, unavailable) and every second. */
static void send_freshness(struct odom_ecu *ecu)
{
    if (!ecu->secoc_on) {
        return;
    }
    enum freshness_cause cause = ecu->secoc_rx.sync_cause;
    if (cause == CAUSE_NONE && ecu->ticks % FRESHNESS_PERIOD_TICKS == 0u) {
        cause = CAUSE_PERIODIC;
    }
    if (cause != CAUSE_NONE) {
        uint8_t data[8];
        ecu->secoc_rx.sync_cause = CAUSE_NONE;
        secoc_freshness_frame(&ecu->secoc_rx, next_counter(ecu, TX_FRESHNESS), cause, data);
        send(ecu, ODOM_FRESHNESS_ID, data);
    }
}

/* --- the command handlers (firmware/commands.py) --- */

static void on_set_pose(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (e2e(ecu, &ecu->rx_set_pose, data, len) && !secured(ecu, AUTH_REQ_ODOM_SET_POSE, data)) {
        act_set_pose(ecu, data);
    }
}

static void act_set_pose(struct odom_ecu *ecu, const uint8_t *data)
{
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
        if (ecu->reason == REASON_COUNTER_RESET || ecu->reason == REASON_POSE_UNCERTAIN) {
            /* a pose given again: recovery may proceed; the reason stays until then (a
             * DEGRADED summary always carries its REASON) */
            ecu->released = true;
        }
        ecu->uncertainty_um = 0u; /* and the uncertainty restarts */
    } else if (frame.field <= SET_POSE_HEADING) {
        ecu->staged_pose_value[frame.field] = frame.value;
        ecu->staged_pose |= 1u << frame.field;
    } else {
        ack(ecu, ODOM_SET_POSE_ID, &frame, ACK_RESULT_NACK, ACK_UNKNOWN_FIELD);
        return;
    }
    ack(ecu, ODOM_SET_POSE_ID, &frame, ACK_RESULT_ACK, ACK_OK);
}

/* A REPEATED frame with other content than the last accepted one: NACK REPEATED (commands.py
 * on_config); a duplicate of it stays unanswered. */
static void on_config(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (e2e(ecu, &ecu->rx_config, data, len)) {
        memcpy(ecu->config_taken, data, 8u);
        if (!secured(ecu, AUTH_REQ_ODOM_CONFIG, data)) {
            act_config(ecu, data);
        }
    } else if (len == 8u && ecu->rx_config.status == E2E_REPEATED &&
               memcmp(ecu->config_taken, data, 8u) != 0) {
        struct mux_record frame;
        unpack_odom_config(data, &frame);
        ack(ecu, ODOM_CONFIG_ID, &frame, ACK_RESULT_NACK, ACK_REPEATED);
    }
}

static void act_config(struct odom_ecu *ecu, const uint8_t *data)
{
    struct mux_record frame;
    unpack_odom_config(data, &frame);
    if (frame.field == PARAM_APPLY) {
        apply_config(ecu, &frame);
    } else if (frame.field <= PARAM_MAX_WHEEL_SPEED) {
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
    uint32_t *fields[7] = {
        &candidate.counts_per_rev, &candidate.wheel_radius_left_nm,
        &candidate.wheel_radius_right_nm, &candidate.wheelbase_nm,
        &candidate.counter_bits, &candidate.integrator, &candidate.max_wheel_speed_mm_s,
    };
    for (unsigned param = 0u; param < 7u; ++param) {
        if ((ecu->staged_config & (1u << param)) != 0u) {
            *fields[param] = ecu->staged_config_value[param];
        }
    }
    ecu->staged_config = 0u;
    enum config_reason reason = validate_at_speed(&candidate, candidate.max_wheel_speed_mm_s);
    if (reason != CONFIG_OK) {
        ecu->errors |= ERROR_CONFIG_INVALID;
        enum ack_reason ack_reason = reason == CONFIG_GEOMETRY_ABSURD || reason == CONFIG_WIRE_RANGE
                                         ? ACK_INCONSISTENT
                                         : ACK_OUT_OF_RANGE;
        ack(ecu, ODOM_CONFIG_ID, frame, ACK_RESULT_NACK, ack_reason);
        return;
    }
    if (candidate.counter_bits != ecu->params.counter_bits) {
        odometry_unprime(&ecu->odometry);
        ecu->wire_prev_valid = false;
        ecu->counts_prev_valid = false;
        ecu->hold_valid = false;
    }
    ecu->params = candidate;
    ecu->profile_crc = profile_crc32(&candidate);
    struct odom_constants consts;
    derive_constants(&candidate, &ecu->errors, &consts);
    odometry_reconfigure(&ecu->odometry, &consts);
    ecu->max_wheel_speed_mm_s = candidate.max_wheel_speed_mm_s;
    step_bounds(ecu);
    if (ecu->state == STATE_FAULT) {
        ecu->state = STATE_INIT;
        ecu->reason = REASON_NONE;
        ecu->released = false;
    }
    ack(ecu, ODOM_CONFIG_ID, frame, ACK_RESULT_ACK, ACK_OK);
}

static void on_nav_goal(struct odom_ecu *ecu, const uint8_t *data, size_t len)
{
    if (e2e(ecu, &ecu->rx_nav_goal, data, len) && !secured(ecu, AUTH_REQ_NAV_GOAL, data)) {
        act_nav_goal(ecu, data);
    }
}

static void act_nav_goal(struct odom_ecu *ecu, const uint8_t *data)
{
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
        uint64_t count_left = odo->consts.bam64_per_count_left;
        uint64_t count_right = odo->consts.bam64_per_count_right;
        ecu->motor_cmd_due = nav_step(&ecu->nav, odo->x_q40_m, odo->y_q40_m, odo->heading_bam64,
                                      ecu->params.wheelbase_nm,
                                      count_left > count_right ? count_left : count_right,
                                      ecu->state == STATE_OK);
    }
}

/* --- step 5: scheduled transmissions (firmware/reports.py; next_counter, send:
 * firmware/transmit.py) --- */

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
    send_freshness(ecu);
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
                             ecu->time_periods / TICKS_PER_SECOND, &ecu->errors, ecu->reason);
    if (send(ecu, ODOM_STATUS_ID, data) && ecu->state == STATE_DEGRADED) {
        ecu->unreported = false; /* the bus has seen the episode: it may recover (health.py) */
    }
    enum status_page page = ROTATING_PAGES[ecu->page_index];
    ecu->page_index = (ecu->page_index + 1u) % ROTATING_PAGE_COUNT;
    uint8_t counter = next_counter(ecu, TX_STATUS);
    if (page == PAGE_PROFILE) {
        pack_odom_status_profile(data, counter, ecu->params.max_wheel_speed_mm_s,
                                 ecu->profile_crc);
    } else if (page == PAGE_FRAME_TOTALS) {
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

/* Frames refused by the E2E check, for their length or as implausible (u32, wrapping). */
uint32_t ecu_frames_rejected(const struct odom_ecu *ecu)
{
    const struct e2e_receiver *rxs[4] = {&ecu->rx_encoders, &ecu->rx_set_pose, &ecu->rx_config,
                                         &ecu->rx_nav_goal};
    uint32_t total = ecu->frames_bad_length + ecu->frames_implausible;
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

/* Hand one frame to the driver; count it when refused. True: the driver took it. */
static bool send(struct odom_ecu *ecu, uint32_t can_id, const uint8_t data[8])
{
    if (ecu->transmit(ecu->tx_ctx, can_id, data)) {
        return true;
    }
    ecu->tx_dropped++;
    return false;
}

/* --- step 6: the watchdog (firmware/health.py) --- */

/* Encoders silent for WATCHDOG_TICKS periods of firmware time -> DEGRADED; back to OK after
 * RECOVERY_FRAMES accepted frames with no new cause, once a summary page carried the episode. */
static void watchdog(struct odom_ecu *ecu)
{
    if (ecu->state == STATE_INIT || ecu->state == STATE_FAULT) {
        return;
    }
    if (ecu->ticks_since_encoder >= WATCHDOG_TICKS) {
        ecu->errors |= ERROR_ENCODER_TIMEOUT;
        if (ecu->state == STATE_OK || /* a cause raised in this very tick is kept */
            (ecu->reason != REASON_ENCODER_TIMEOUT && ecu->reason_tick != ecu->ticks)) {
            degrade(ecu, REASON_ENCODER_TIMEOUT);
        }
        ecu->good_in_a_row = 0;
    } else if (ecu->state == STATE_DEGRADED && ecu->good_in_a_row >= RECOVERY_FRAMES
               && (ecu->released /* the pose lost its continuity or its accuracy: latched */
                   || (ecu->reason != REASON_COUNTER_RESET
                       && ecu->reason != REASON_POSE_UNCERTAIN))
               && !ecu->unreported) { /* the bus has seen DEGRADED and why */
        ecu->state = STATE_OK;
        ecu->reason = REASON_NONE;
        ecu->released = false;
    }
}
