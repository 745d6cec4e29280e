/* AUTOSAR E2E Profile 2 on classic CAN frames: CRC8H2F, the sender's protect, the receiver's
 * check (firmware/e2e.py). */
#ifndef ODOCAN_E2E_H
#define ODOCAN_E2E_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define CRC8H2F_POLY 0x2Fu
#define CRC8H2F_INIT 0xFFu
#define CRC8H2F_XOR_OUT 0xFFu
#define CRC8H2F_CHECK 0xDFu /* CRC8H2F("123456789"), AUTOSAR SWS CRC Library, 7.2.1.2 */

#define FRAME_LEN 8u                /* Profile 2 DataLength, bytes: classic CAN */
#define COUNTER_MASK 0x0Fu          /* Profile 2 counter: 0..15 */
#define DATA_ID_COUNT 16u           /* entries of a Profile 2 DataIDList */
#define MAX_DELTA_COUNTER_LIMIT 15u /* MaxDeltaCounter saturates here */

/* Result of one Profile 2 check (values of AUTOSAR E2E_P02CheckStatusType). */
enum e2e_status {
    E2E_OK = 0x00,           /* valid, counter +1 (or the first valid frame after init) */
    E2E_NONEWDATA = 0x01,    /* the check ran with no frame received */
    E2E_ERROR = 0x02,        /* WRONGCRC: bad CRC (or not 8 bytes) */
    E2E_REPEATED = 0x08,     /* valid CRC, same counter as the last valid frame: drop it */
    E2E_OKSOMELOST = 0x20,   /* valid, counter +2..+MaxDeltaCounter: frames were lost */
    E2E_WRONGSEQUENCE = 0x40 /* valid CRC, counter jump beyond MaxDeltaCounter: drop it */
};

/* Profile 2 receiver check state of one message (E2E_P02CheckStateType plus counts). */
struct e2e_receiver {
    const uint8_t *data_ids; /* the message's 16-entry DataIDList */
    uint8_t max_delta_counter_init;
    bool window_per_period;
    uint32_t count_ok;
    uint32_t count_oksomelost;
    uint32_t count_repeated;
    uint32_t count_wrongsequence;
    uint32_t count_error;
    uint32_t count_nonewdata;
    uint32_t lost_frames;
    enum e2e_status status;
    uint8_t last_valid_counter;
    uint8_t max_delta_counter;
    uint8_t lost_data;
    bool wait_for_first_data;
};

uint8_t crc8h2f(const uint8_t *data, size_t len);
uint8_t p02_crc(const uint8_t frame[FRAME_LEN], uint8_t data_id);
void e2e_receiver_init(struct e2e_receiver *rx, const uint8_t data_ids[DATA_ID_COUNT],
                       uint8_t max_delta_counter_init, bool window_per_period);
void e2e_reset(struct e2e_receiver *rx);
void e2e_new_period(struct e2e_receiver *rx);
enum e2e_status e2e_check(struct e2e_receiver *rx, const uint8_t *frame, size_t len);
uint32_t e2e_accepted(const struct e2e_receiver *rx);

#endif
