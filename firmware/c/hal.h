/* The firmware's hardware abstraction layer: all it knows of the world (firmware/hal.py).
 *
 * A board support package implements can_tx_fn and calls the ECU: ecu_isr_can_rx from the CAN
 * receive interrupt, ecu_tick every TICK_PERIOD_US from a periodic timer, ecu_isr_bus_state when
 * the controller enters or leaves bus-off. */
#ifndef ODOCAN_HAL_H
#define ODOCAN_HAL_H

#include <stdbool.h>
#include <stdint.h>

#define TICK_PERIOD_US 10000 /* the periodic tick: 100 Hz, the WHEEL_ENCODERS cycle */
#define MAILBOX_SLOTS 32u    /* receive mailbox depth (frames) */

/* Queue one classic CAN data frame (11-bit ID, 8 bytes). false when the TX queue is full or the
 * controller is bus-off: the frame is dropped and the firmware counts it. */
typedef bool (*can_tx_fn)(void *ctx, uint32_t can_id, const uint8_t data[8]);

#endif
