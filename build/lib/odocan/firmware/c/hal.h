/* The firmware's hardware abstraction layer: all it knows of the world (firmware/hal.py).
 *
 * A board support package implements can_tx_fn and calls the ECU: ecu_isr_can_rx from the CAN
 * receive interrupt; ecu_tick_at(ecu, now_us) every TICK_PERIOD_US from a periodic timer, now_us
 * the free-running u32 microsecond timer at its release (the firmware's clock: a late or stalled
 * tick is lost time, not one period; ecu_tick(ecu) on a board without a timer: one period);
 * ecu_isr_rx_overrun when the CAN controller's receive FIFO overran; ecu_isr_bus_state when the
 * controller enters or leaves bus-off. */
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
