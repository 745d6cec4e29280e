/* The odometry ECU's main loop: a receive ISR, a bounded mailbox and a periodic tick
 * (firmware/ecu.py; its docstring gives the tick's fixed order). */
#ifndef ODOCAN_ECU_H
#define ODOCAN_ECU_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config.h"
#include "e2e.h"
#include "hal.h"
#include "nav.h"
#include "odometry.h"

#define ENCODER_PERIOD_US 10000
#define POSE_PERIOD_TICKS 2u
#define STATUS_PERIOD_TICKS 10u
#define WATCHDOG_TICKS 10
#define RECOVERY_FRAMES 5
#define TICKS_PER_SECOND (1000000u / TICK_PERIOD_US)
#define WIRE_COUNTER_BITS 24u
#define TX_IDS 7u /* the messages this node sends: one E2E counter each */

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
    struct robot_params params;
    struct odometry odometry;
    struct mailbox mailbox;
    uint8_t data_ids[4][DATA_ID_COUNT];
    struct e2e_receiver rx_encoders;
    struct e2e_receiver rx_set_pose;
    struct e2e_receiver rx_config;
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
    int ticks_since_encoder;
    int good_in_a_row;
    int64_t twist_mm_s;
    int64_t twist_mrad_s;
    unsigned page_index;
    unsigned staged_pose;      /* bit per SET_POSE field */
    int64_t staged_pose_value[3];
    unsigned staged_config;    /* bit per CONFIG parameter */
    uint32_t staged_config_value[6];
};

void ecu_init(struct odom_ecu *ecu, can_tx_fn transmit, void *tx_ctx,
              const struct robot_params *params);
void ecu_isr_can_rx(struct odom_ecu *ecu, uint32_t can_id, const uint8_t *data, size_t len);
void ecu_isr_bus_state(struct odom_ecu *ecu, bool bus_off);
void ecu_tick(struct odom_ecu *ecu);
uint32_t ecu_frames_rejected(const struct odom_ecu *ecu);

#endif
