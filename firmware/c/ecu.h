/* The odometry ECU's main loop: a receive ISR, a bounded mailbox and a periodic tick
 * (firmware/ecu.py, which composes one module per job; its docstring gives the tick's fixed
 * order). */
#ifndef ODOCAN_ECU_H
#define ODOCAN_ECU_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config.h"
#include "e2e.h"
#include "errors.h"
#include "hal.h"
#include "nav.h"
#include "odometry.h"
#include "secoc.h"

#define POSE_PERIOD_TICKS 2u
#define STATUS_PERIOD_TICKS 10u
#define WATCHDOG_TICKS 10u
#define RECOVERY_FRAMES 5
#define TICKS_PER_SECOND (1000000u / TICK_PERIOD_US)
#define LOST_TIME_PERIODS WATCHDOG_TICKS /* a tick this many periods after the last: time lost */
/* The plausibility bound of a robot whose parameters state none (robot_params) */
#define MAX_WHEEL_SPEED_MM_S MAX_WHEEL_SPEED_DEFAULT_MM_S
#define RESYNC_FRAMES 3 /* frames consistent with each other, not with the last: restarted */
#define STEP_PERIODS_MAX 0xFFFFu /* the twist's dt and the plausibility bound saturate (655 s) */
#define TWO_PI_Q30 ((TWO_PI_Q60 + (INT64_C(1) << 29)) >> 30) /* one turn in Q30 rad (< 2^33) */
#define TWIST_SUM_MAX (INT64_C(1) << 32) /* one tick's summed steps: 4096 m (Q20), 4 rad (Q30) */
#define PERIODS_PER_S 100u /* encoder periods in one second (1 s / ENCODER_PERIOD_US) */
#define CTRL_UPTIME_MAX 15u /* CTRL_UPTIME saturates here (u4) */
#define RESTART_SLACK_PERIODS 16u /* periods two frames' queueing may shorten their samples' gap */
#define TX_IDS 8u /* the messages this node sends: one E2E counter each */

/* Firmware state (the STATE signal of ODOM_STATUS). */
enum ecu_state { STATE_INIT = 0, STATE_OK = 1, STATE_DEGRADED = 2, STATE_FAULT = 3 };

/* The receive mailbox: a ring of MAILBOX_SLOTS frames, filled in ISR context. */
struct mailbox {
    uint32_t ids[MAILBOX_SLOTS];
    uint8_t data[MAILBOX_SLOTS][8];
    size_t len[MAILBOX_SLOTS];
    unsigned head;
    unsigned count;
    uint32_t overflows; /* wrapping */
};

struct odom_ecu {
    can_tx_fn transmit;
    void *tx_ctx;
    uint32_t errors;
    enum ecu_state state;
    enum reason reason;
    struct robot_params params;
    uint32_t profile_crc; /* ODOM_STATUS PROFILE_CRC of params */
    struct odometry odometry;
    uint32_t max_wheel_speed_mm_s;     /* u16: an encoder step beyond it is implausible */
    uint64_t max_counts_per_period[2]; /* per wheel, at max_wheel_speed_mm_s */
    uint32_t ambiguous_periods; /* the fewest step periods whose bound reaches half the range */
    struct mailbox mailbox;
    uint8_t data_ids[4][DATA_ID_COUNT];
    struct e2e_receiver rx_encoders;
    struct e2e_receiver rx_set_pose;
    struct e2e_receiver rx_config;
    uint8_t config_taken[8]; /* the last ODOM_CONFIG frame accepted (commands.py _config_taken) */
    struct e2e_receiver rx_nav_goal;
    struct navigator nav;
    bool motor_cmd_due;
    uint32_t ticks;
    uint32_t frames_filtered;
    uint32_t frames_bad_length;
    uint32_t tx_dropped;
    uint8_t tx_counters[TX_IDS];
    uint8_t enc_counter;
    int enc_prev_counter; /* -1: none yet */
    bool wire_prev_valid;
    uint32_t wire_prev[2];
    uint32_t counts_u32[2];
    bool counts_prev_valid;
    uint32_t counts_prev[2];  /* counters of the last accepted frame */
    uint8_t uptime_prev;      /* CTRL_UPTIME of the last accepted frame (0: not reported) */
    uint8_t uptime_now;       /* CTRL_UPTIME of the frame being handled */
    uint32_t time_periods;    /* 10 ms periods since reset, by the timer (ticks run or not) */
    bool timer_prev_valid;
    uint32_t timer_prev_us;   /* the timer at the previous tick */
    int32_t timer_rest_us;    /* within +-TICK_PERIOD_US/2: time not yet counted */
    uint32_t periods_lost;    /* periods the firmware did not run (stalls), wrapping */
    uint32_t frames_implausible; /* WHEEL_ENCODERS refused by the plausibility bound, wrapping */
    uint32_t overflows_seen;
    uint32_t overflows_before; /* overflows_seen at the previous tick (health.py overflows_before) */
    uint32_t enc_overflows_at_accept; /* overflows_before when the last encoder frame was accepted */
    /* WHEEL_ENCODERS frames the mailbox dropped (wrapping; the ISR writes it), its value at this
     * tick's start, at the previous tick's start and when the last frame was accepted
     * (encoders.py frames_dropped, _dropped_seen, _dropped_before, _dropped_at_accept). */
    uint32_t enc_frames_dropped;
    uint32_t enc_dropped_seen;
    uint32_t enc_dropped_before;
    uint32_t enc_dropped_at_accept;
    /* Refused frames consistent among themselves: counters and COUNTER of the first, the last. */
    bool resync_first_valid;
    uint32_t resync_first[2];
    uint8_t resync_first_counter;
    uint32_t resync_last[2];
    uint8_t resync_last_counter;
    int resync_frames;
    /* A frame saying its controller restarted, held until the next one confirms it
     * (restarthold.py): its COUNTER, CTRL_UPTIME and wire counts. */
    bool hold_valid;
    uint8_t hold_counter;
    uint8_t hold_uptime;
    uint32_t hold_wire[2];
    uint32_t ticks_since_encoder; /* periods (firmware time) since the last accepted frame, sat. */
    uint32_t reason_tick;         /* the tick that set reason */
    bool unreported; /* no ODOM_STATUS summary has carried the last cause yet (health.py) */
    bool released;   /* a set-pose released the latched reason (health.py) */
    /* Periods since the last accepted frame's sample is known to have been taken (u16, sat.). */
    uint32_t periods_since_sample;
    bool time_lost_now;  /* this tick came LOST_TIME_PERIODS periods or more late */
    bool samples_stale;  /* the last accepted frame was taken in a tick that lost time */
    uint32_t sample_doubt; /* periods its sample may lie before the last frame's tick (u16) */
    uint32_t tick_budget; /* periods_since_sample at the start of this tick */
    /* The steps since the last twist update (one tick; two after a tick that lost time). */
    int64_t tick_ds_q20_m;         /* saturated to +-2^32 (4096 m) */
    int64_t tick_dheading_q30_rad; /* saturated to +-2^32 (4 rad) */
    unsigned tick_steps;
    uint32_t tick_periods; /* the sample periods the summed steps span (u16, saturated) */
    bool tick_carried;     /* the sums hold steps of a tick that lost time */
    uint32_t this_step_periods; /* the sample periods of the step being accepted */
    /* The merged steps' summed worst-case position error since the last set-pose (um,
     * saturated) and its tolerance (uncertainty.py). */
    uint32_t uncertainty_um;
    uint32_t uncertainty_tolerance_um;
    uint32_t tick_late;         /* periods this tick came after its due time */
    int good_in_a_row;
    int64_t twist_mm_s;
    int64_t twist_mrad_s;
    unsigned page_index;
    unsigned staged_pose;      /* bit per SET_POSE field */
    int64_t staged_pose_value[3];
    unsigned staged_config;    /* bit per CONFIG parameter */
    uint32_t staged_config_value[7];
    /* SecOC (firmware/secoc.py, docs/secoc.md): off unless ecu_provision_secoc was called */
    bool secoc_on;
    struct secoc_receiver secoc_rx;
    struct secured_commands secoc;
    uint8_t auth_data_ids[DATA_ID_COUNT];
    struct e2e_receiver rx_auth;
};

void ecu_init(struct odom_ecu *ecu, can_tx_fn transmit, void *tx_ctx,
              const struct robot_params *params);
/* Provision the SecOC key (key_len 16; anything else fails closed) and the EPOCH cell: boots the
 * freshness (EPOCH + 1 written first). Call once, right after ecu_init. */
void ecu_provision_secoc(struct odom_ecu *ecu, const uint8_t *key, unsigned key_len,
                         struct freshness_nvm nvm);
void ecu_isr_can_rx(struct odom_ecu *ecu, uint32_t can_id, const uint8_t *data, size_t len);
void ecu_isr_rx_overrun(struct odom_ecu *ecu);
void ecu_isr_bus_state(struct odom_ecu *ecu, bool bus_off);
void ecu_tick(struct odom_ecu *ecu);
void ecu_tick_at(struct odom_ecu *ecu, uint32_t now_us);
uint32_t ecu_frames_rejected(const struct odom_ecu *ecu);

#endif
