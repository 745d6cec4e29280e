/* AUTOSAR E2E Profile 2 on classic CAN frames (firmware/e2e.py, same order).
 *
 * Header of every odocan frame: byte 0 CHECKSUM (CRC8H2F over bytes 1..7, then the data ID),
 * byte 1 bits 0-3 COUNTER (0..15, +1 per frame). The data ID is data_ids[COUNTER]. CRC8H2F:
 * width 8, polynomial 0x2F, init 0xFF, no reflection, final XOR 0xFF; check value 0xDF.
 * Receiver semantics: E2E_P02Check (R4.0, no SyncCounter); the first valid frame after init is
 * OK. Integer-only, allocation-free per frame.
 */
#include "e2e.h"

/* The 256-entry MSB-first table of polynomial 0x2F, in flash (Python: _crc8h2f_table(); the
 * C probe test compares every entry with it). */
static const uint8_t CRC8H2F_TABLE[256] = {
    0x00u, 0x2Fu, 0x5Eu, 0x71u, 0xBCu, 0x93u, 0xE2u, 0xCDu,
    0x57u, 0x78u, 0x09u, 0x26u, 0xEBu, 0xC4u, 0xB5u, 0x9Au,
    0xAEu, 0x81u, 0xF0u, 0xDFu, 0x12u, 0x3Du, 0x4Cu, 0x63u,
    0xF9u, 0xD6u, 0xA7u, 0x88u, 0x45u, 0x6Au, 0x1Bu, 0x34u,
    0x73u, 0x5Cu, 0x2Du, 0x02u, 0xCFu, 0xE0u, 0x91u, 0xBEu,
    0x24u, 0x0Bu, 0x7Au, 0x55u, 0x98u, 0xB7u, 0xC6u, 0xE9u,
    0xDDu, 0xF2u, 0x83u, 0xACu, 0x61u, 0x4Eu, 0x3Fu, 0x10u,
    0x8Au, 0xA5u, 0xD4u, 0xFBu, 0x36u, 0x19u, 0x68u, 0x47u,
    0xE6u, 0xC9u, 0xB8u, 0x97u, 0x5Au, 0x75u, 0x04u, 0x2Bu,
    0xB1u, 0x9Eu, 0xEFu, 0xC0u, 0x0Du, 0x22u, 0x53u, 0x7Cu,
    0x48u, 0x67u, 0x16u, 0x39u, 0xF4u, 0xDBu, 0xAAu, 0x85u,
    0x1Fu, 0x30u, 0x41u, 0x6Eu, 0xA3u, 0x8Cu, 0xFDu, 0xD2u,
    0x95u, 0xBAu, 0xCBu, 0xE4u, 0x29u, 0x06u, 0x77u, 0x58u,
    0xC2u, 0xEDu, 0x9Cu, 0xB3u, 0x7Eu, 0x51u, 0x20u, 0x0Fu,
    0x3Bu, 0x14u, 0x65u, 0x4Au, 0x87u, 0xA8u, 0xD9u, 0xF6u,
    0x6Cu, 0x43u, 0x32u, 0x1Du, 0xD0u, 0xFFu, 0x8Eu, 0xA1u,
    0xE3u, 0xCCu, 0xBDu, 0x92u, 0x5Fu, 0x70u, 0x01u, 0x2Eu,
    0xB4u, 0x9Bu, 0xEAu, 0xC5u, 0x08u, 0x27u, 0x56u, 0x79u,
    0x4Du, 0x62u, 0x13u, 0x3Cu, 0xF1u, 0xDEu, 0xAFu, 0x80u,
    0x1Au, 0x35u, 0x44u, 0x6Bu, 0xA6u, 0x89u, 0xF8u, 0xD7u,
    0x90u, 0xBFu, 0xCEu, 0xE1u, 0x2Cu, 0x03u, 0x72u, 0x5Du,
    0xC7u, 0xE8u, 0x99u, 0xB6u, 0x7Bu, 0x54u, 0x25u, 0x0Au,
    0x3Eu, 0x11u, 0x60u, 0x4Fu, 0x82u, 0xADu, 0xDCu, 0xF3u,
    0x69u, 0x46u, 0x37u, 0x18u, 0xD5u, 0xFAu, 0x8Bu, 0xA4u,
    0x05u, 0x2Au, 0x5Bu, 0x74u, 0xB9u, 0x96u, 0xE7u, 0xC8u,
    0x52u, 0x7Du, 0x0Cu, 0x23u, 0xEEu, 0xC1u, 0xB0u, 0x9Fu,
    0xABu, 0x84u, 0xF5u, 0xDAu, 0x17u, 0x38u, 0x49u, 0x66u,
    0xFCu, 0xD3u, 0xA2u, 0x8Du, 0x40u, 0x6Fu, 0x1Eu, 0x31u,
    0x76u, 0x59u, 0x28u, 0x07u, 0xCAu, 0xE5u, 0x94u, 0xBBu,
    0x21u, 0x0Eu, 0x7Fu, 0x50u, 0x9Du, 0xB2u, 0xC3u, 0xECu,
    0xD8u, 0xF7u, 0x86u, 0xA9u, 0x64u, 0x4Bu, 0x3Au, 0x15u,
    0x8Fu, 0xA0u, 0xD1u, 0xFEu, 0x33u, 0x1Cu, 0x6Du, 0x42u,
};

static enum e2e_status e2e_error(struct e2e_receiver *rx);
static enum e2e_status e2e_sequence(struct e2e_receiver *rx, uint8_t counter);
static enum e2e_status e2e_accept(struct e2e_receiver *rx, uint8_t counter, uint8_t lost,
                                  enum e2e_status status);

/* CRC8H2F of data (any length): table-driven, one lookup per byte. */
uint8_t crc8h2f(const uint8_t *data, size_t len)
{
    uint8_t crc = CRC8H2F_INIT;
    for (size_t k = 0u; k < len; ++k) {
        crc = CRC8H2F_TABLE[crc ^ data[k]];
    }
    return (uint8_t)(crc ^ CRC8H2F_XOR_OUT);
}

/* The Profile 2 CRC of an 8-byte frame: CRC8H2F over bytes 1..7, then data_id. */
uint8_t p02_crc(const uint8_t frame[FRAME_LEN], uint8_t data_id)
{
    const uint8_t *t = CRC8H2F_TABLE;
    uint8_t crc = t[CRC8H2F_INIT ^ frame[1]];
    crc = t[crc ^ frame[2]];
    crc = t[crc ^ frame[3]];
    crc = t[crc ^ frame[4]];
    crc = t[crc ^ frame[5]];
    crc = t[crc ^ frame[6]];
    crc = t[crc ^ frame[7]];
    crc = t[crc ^ data_id];
    return (uint8_t)(crc ^ CRC8H2F_XOR_OUT);
}

void e2e_receiver_init(struct e2e_receiver *rx, const uint8_t data_ids[DATA_ID_COUNT],
                       uint8_t max_delta_counter_init, bool window_per_period)
{
    rx->data_ids = data_ids;
    rx->max_delta_counter_init = max_delta_counter_init;
    rx->window_per_period = window_per_period;
    rx->count_ok = 0u;
    rx->count_oksomelost = 0u;
    rx->count_repeated = 0u;
    rx->count_wrongsequence = 0u;
    rx->count_error = 0u;
    rx->count_nonewdata = 0u;
    rx->lost_frames = 0u;
    e2e_reset(rx);
}

/* E2E_P02CheckInit: forget the sequence (the counts are kept). */
void e2e_reset(struct e2e_receiver *rx)
{
    rx->last_valid_counter = 0u;
    rx->max_delta_counter = 0u;
    rx->lost_data = 0u;
    rx->wait_for_first_data = true;
    rx->status = E2E_NONEWDATA;
}

/* Start a receive period: the window widens by one (up to 15). */
void e2e_new_period(struct e2e_receiver *rx)
{
    if (rx->max_delta_counter < MAX_DELTA_COUNTER_LIMIT) {
        rx->max_delta_counter++;
    }
}

/* Check one received frame (NULL: the period ended with none); count and return. */
enum e2e_status e2e_check(struct e2e_receiver *rx, const uint8_t *frame, size_t len)
{
    if (!rx->window_per_period && rx->max_delta_counter < MAX_DELTA_COUNTER_LIMIT) {
        rx->max_delta_counter++;
    }
    if (frame == NULL) {
        rx->count_nonewdata++;
        rx->status = E2E_NONEWDATA;
        return E2E_NONEWDATA;
    }
    if (len != FRAME_LEN) {
        return e2e_error(rx);
    }
    uint8_t counter = (uint8_t)(frame[1] & COUNTER_MASK);
    if (frame[0] != p02_crc(frame, rx->data_ids[counter])) {
        return e2e_error(rx);
    }
    rx->status = e2e_sequence(rx, counter);
    return rx->status;
}

/* Frames accepted (OK or OKSOMELOST), u32 wrapping: the *_E2E_OK status signal. */
uint32_t e2e_accepted(const struct e2e_receiver *rx)
{
    return rx->count_ok + rx->count_oksomelost;
}

/* Count a frame with a bad CRC or length. */
static enum e2e_status e2e_error(struct e2e_receiver *rx)
{
    rx->count_error++;
    rx->status = E2E_ERROR;
    return E2E_ERROR;
}

/* The counter part of the check, for a frame whose CRC is valid. */
static enum e2e_status e2e_sequence(struct e2e_receiver *rx, uint8_t counter)
{
    if (rx->wait_for_first_data) {
        rx->wait_for_first_data = false;
        return e2e_accept(rx, counter, 0u, E2E_OK);
    }
    uint8_t delta = (uint8_t)((counter - rx->last_valid_counter) & COUNTER_MASK);
    if (delta == 1u) {
        return e2e_accept(rx, counter, 0u, E2E_OK);
    }
    if (delta == 0u) {
        rx->count_repeated++;
        return E2E_REPEATED;
    }
    if (delta <= rx->max_delta_counter) {
        rx->count_oksomelost++;
        rx->lost_frames += delta - 1u;
        return e2e_accept(rx, counter, (uint8_t)(delta - 1u), E2E_OKSOMELOST);
    }
    rx->count_wrongsequence++;
    return E2E_WRONGSEQUENCE;
}

/* Take counter as the last valid one and re-arm the delta window. */
static enum e2e_status e2e_accept(struct e2e_receiver *rx, uint8_t counter, uint8_t lost,
                                  enum e2e_status status)
{
    rx->last_valid_counter = counter;
    rx->max_delta_counter = rx->max_delta_counter_init;
    rx->lost_data = lost;
    if (status == E2E_OK) {
        rx->count_ok++;
    }
    return status;
}
