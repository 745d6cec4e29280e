/* The shared-library ABI of the firmware: what a host board (odocan's sim/cboard.py, or a team's
 * own test harness) links against to run this firmware in the rig (README: "Bring your own
 * firmware").
 *
 * Plain C types only (no struct crosses the boundary), so that ctypes, cffi or another language
 * binds it without a header parser. The firmware allocates nothing: the host allocates
 * odocan_fw_state_size() bytes (aligned for uint64_t) and passes them to every call. One
 * instance is one ECU; a process may hold several. No call blocks or keeps a pointer to the
 * host's arguments beyond its return, except `tx` and `tx_ctx`, kept by odocan_fw_init, and the
 * NVM functions and `nvm_ctx`, kept by odocan_fw_provision_secoc.
 *
 * Calling order, from a single thread (the board serialises its "interrupts"):
 *   odocan_fw_init once; with SecOC, odocan_fw_provision_secoc right after it; then every
 *   TICK_PERIOD_US: odocan_fw_bus_state when the controller's
 *   bus-off state changed, odocan_fw_rx_isr for every received frame, then odocan_fw_tick.
 *
 * Versioning: ODOCAN_FW_ABI_VERSION changes whenever a function, an argument or a meaning below
 * changes; a host checks odocan_fw_abi_version() before any other call.
 *   1: init, rx_isr, bus_state, rx_overrun, tick, state, errors, ticks (no SecOC).
 *   2: 1 + odocan_fw_provision_secoc (a host with a key refuses a version-1 library).
 *   3: 2 + odocan_fw_init's seventh parameter, max_wheel_speed_mm_s. */
#ifndef ODOCAN_FW_H
#define ODOCAN_FW_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define ODOCAN_FW_ABI_VERSION 3u

/* The firmware's transmit: queue one classic CAN data frame (11-bit ID, 8 bytes), called from
 * inside odocan_fw_tick. Return false when the frame could not be queued (TX queue full,
 * controller bus-off): the firmware drops and counts it. `data` is valid only during the call.
 * Same type as hal.h's can_tx_fn. */
typedef bool (*odocan_fw_tx_fn)(void *tx_ctx, uint32_t can_id, const uint8_t data[8]);

/* ODOCAN_FW_ABI_VERSION of the library. */
uint32_t odocan_fw_abi_version(void);

/* Bytes of one firmware instance (the host allocates them, aligned for uint64_t). */
size_t odocan_fw_state_size(void);

/* Power-on reset of the instance at `fw` (`size` bytes) with the robot's integer parameters, in
 * the order of ODOM_CONFIG / RobotParams: counts_per_rev, wheel_radius_left_nm,
 * wheel_radius_right_nm, wheelbase_nm, counter_bits, integrator (0 euler, 1 rk2, 2 exact),
 * max_wheel_speed_mm_s (ABI 3: the plausibility bound of an encoder step, 1..65535).
 * Invalid parameters start the firmware in FAULT (state 3) until an ODOM_CONFIG fixes them.
 * Returns 0, or -1 (nothing done) when `size` is smaller than odocan_fw_state_size(). */
int odocan_fw_init(void *fw, size_t size, const uint32_t params[7], odocan_fw_tx_fn tx,
                   void *tx_ctx);

/* The SecOC EPOCH cell of non-volatile memory (data flash, EEPROM; docs/secoc.md): read the
 * stored u32 EPOCH (0: never written), write one (false: the write failed, the firmware then
 * refuses every secured command). Same types as secoc.h's struct freshness_nvm. */
typedef uint32_t (*odocan_fw_nvm_read_fn)(void *nvm_ctx);
typedef bool (*odocan_fw_nvm_write_fn)(void *nvm_ctx, uint32_t epoch);

/* ABI 2. Provision the SecOC key (`key_len` bytes at `key`, copied: 16 for AES-128; NULL or
 * another length: no usable key, every secured command refused AUTH_UNAVAILABLE) and the EPOCH
 * cell, then boot the freshness (EPOCH + 1 written to the cell before anything is accepted).
 * Without this call the firmware runs without SecOC, as under ABI 1. `read_epoch` or
 * `write_epoch` NULL: no NVM, the firmware fails closed. Returns 0, or -1 (nothing done) when the
 * instance was already provisioned or has ticked: a key is configuration, given at reset. */
int odocan_fw_provision_secoc(void *fw, const uint8_t *key, uint32_t key_len,
                              odocan_fw_nvm_read_fn read_epoch,
                              odocan_fw_nvm_write_fn write_epoch, void *nvm_ctx);

/* The CAN receive interrupt: one received 11-bit data frame of `len` bytes (`data` may be NULL
 * when len is 0). The firmware copies it into its mailbox and returns; frames of another length
 * than 8 are kept and rejected by the tick. The board filters error, remote and extended frames. */
void odocan_fw_rx_isr(void *fw, uint32_t can_id, uint32_t len, const uint8_t *data);

/* The CAN controller's status interrupt: bus-off entered (true) or left (false). */
void odocan_fw_bus_state(void *fw, bool bus_off);

/* The CAN controller's overrun interrupt: its receive FIFO dropped frames (a stalled MCU). */
void odocan_fw_rx_overrun(void *fw);

/* The periodic timer, every TICK_PERIOD_US (10 000 us): one period of the main loop; transmits
 * through `tx`. `now_us` is the board's clock at this tick (monotonic microseconds; the ECU
 * keeps its low 32 bits, a wrapping timer): the firmware's time, so a late tick is lost time. */
void odocan_fw_tick(void *fw, uint64_t now_us);

/* Read-only views for the board's summary: the firmware state (0 INIT, 1 OK, 2 DEGRADED,
 * 3 FAULT, the STATE signal of ODOM_STATUS), the sticky error mask (the ERRORS signal) and the
 * u32 tick count. */
uint32_t odocan_fw_state(const void *fw);
uint32_t odocan_fw_errors(const void *fw);
uint32_t odocan_fw_ticks(const void *fw);

#endif
