/* SecOC-style authenticated commands: firmware/secoc.py, same names and order (docs/secoc.md). */
#include "secoc.h"

#include <string.h>

#include "frames.h"

const uint32_t SECURED_IDS[SECURED_COUNT] = {NAV_GOAL_ID, ODOM_SET_POSE_ID, ODOM_CONFIG_ID};

/* The 16-byte DataToAuthenticator: DataID (u16 BE) || PDU (8 bytes) || FV (u48 BE). */
void authenticator_input(uint32_t data_id, const uint8_t pdu[8], uint64_t fv, uint8_t block[16])
{
    block[0] = (uint8_t)(data_id >> 8);
    block[1] = (uint8_t)data_id;
    for (unsigned i = 0; i < 8u; i++) {
        block[2u + i] = pdu[i];
    }
    for (unsigned i = 0; i < 6u; i++) {
        block[10u + i] = (uint8_t)(fv >> (40u - 8u * i));
    }
}

/* MSB_32 of AES-CMAC over one complete block: AES(K, M XOR K1), the first 4 bytes BE. */
uint32_t authenticator(const cmac_key_t *key, uint32_t data_id, const uint8_t pdu[8], uint64_t fv)
{
    uint8_t block[16];
    uint32_t s[4];
    authenticator_input(data_id, pdu, fv, block);
    for (unsigned i = 0; i < 4u; i++) {
        s[i] = load_be32(block, 4u * i) ^ key->k1[i];
    }
    aes128_encrypt_words(key->rk, s);
    return s[0];
}

uint32_t truncate_mac(uint32_t mac32, unsigned mac_bits)
{
    return mac_bits >= 32u ? mac32 : mac32 >> (MAC_BITS - mac_bits);
}

static void advance_epoch(struct secoc_receiver *rx, uint32_t previous,
                          enum freshness_cause cause)
{
    if (!rx->key_valid || previous >= EPOCH_MAX ||
        !rx->nvm.write_epoch(rx->nvm.ctx, previous + 1u)) {
        rx->epoch = 0; /* unavailable: every secured command is refused */
        rx->sync_cause = CAUSE_UNAVAILABLE;
        return;
    }
    rx->epoch = previous + 1u;
    rx->last_fv = (uint64_t)rx->epoch << COUNT_BITS;
    rx->sync_cause = cause;
}

void secoc_receiver_init(struct secoc_receiver *rx, const uint8_t *key, unsigned key_len,
                         struct freshness_nvm nvm, unsigned mac_bits)
{
    memset(rx, 0, sizeof *rx);
    rx->nvm = nvm;
    rx->mac_bits = mac_bits;
    rx->key_valid = key != NULL && key_len == AES128_KEY_BYTES;
    if (rx->key_valid) {
        cmac_key(key, &rx->key);
    }
    rx->sync_cause = CAUSE_NONE;
    secoc_boot(rx);
}

/* Reset and power-on: EPOCH <- NVM + 1, written back before anything is accepted. */
void secoc_boot(struct secoc_receiver *rx)
{
    advance_epoch(rx, rx->nvm.read_epoch(rx->nvm.ctx), CAUSE_BOOT);
}

enum auth_status secoc_verify(struct secoc_receiver *rx, uint32_t data_id, const uint8_t pdu[8],
                              uint16_t freshness, uint32_t mac)
{
    if (!rx->key_valid || rx->epoch == 0u) {
        return AUTH_UNAVAILABLE;
    }
    uint32_t delta = (uint16_t)(freshness - (uint16_t)rx->last_fv);
    uint64_t fv = rx->last_fv + delta;
    if (delta == 0u || delta > FRESHNESS_WINDOW || (fv >> COUNT_BITS) != rx->epoch) {
        rx->count_freshness++;
        rx->sync_cause = CAUSE_REFUSED;
        return AUTH_FRESHNESS;
    }
    uint32_t expected = truncate_mac(authenticator(&rx->key, data_id, pdu, fv), rx->mac_bits);
    if ((expected ^ mac) != 0u) { /* a full-word compare, no early exit */
        rx->count_failed++;
        return AUTH_FAILED;
    }
    rx->count_ok++;
    rx->last_fv = fv;
    if ((fv & COUNT_MASK) > ROLLOVER_COUNT) {
        advance_epoch(rx, rx->epoch, CAUSE_ROLLOVER);
    }
    return AUTH_OK;
}

/* ODOM_FRESHNESS carrying last_fv (0 when unavailable) and cause. */
void secoc_freshness_frame(const struct secoc_receiver *rx, uint8_t counter,
                           enum freshness_cause cause, uint8_t out[8])
{
    uint32_t errors = 0;
    pack_odom_freshness(out, counter, (int64_t)cause, rx->epoch ? rx->last_fv : 0u, &errors);
}

void secured_init(struct secured_commands *sc, struct secoc_receiver *rx)
{
    memset(sc, 0, sizeof *sc);
    sc->receiver = rx;
}

bool secured_hold(struct secured_commands *sc, enum auth_request request, const uint8_t pdu[8],
                  uint32_t tick, struct held *displaced)
{
    struct held *slot = &sc->slots[request];
    bool was = slot->valid;
    if (was) {
        *displaced = *slot;
    }
    slot->valid = true;
    slot->can_id = SECURED_IDS[request];
    memcpy(slot->pdu, pdu, 8u);
    slot->tick = tick;
    return was;
}

bool secured_authenticate(struct secured_commands *sc, const struct odom_auth *auth,
                          enum auth_status *status, struct held *out)
{
    if (auth->request >= SECURED_COUNT || !sc->slots[auth->request].valid) {
        sc->orphans++;
        return false;
    }
    *out = sc->slots[auth->request];
    sc->slots[auth->request].valid = false;
    *status = secoc_verify(sc->receiver, out->can_id, out->pdu, auth->freshness,
                           auth->authenticator);
    return true;
}

bool secured_expire(struct secured_commands *sc, uint32_t tick, struct held *out)
{
    for (unsigned i = 0; i < SECURED_COUNT; i++) {
        struct held *slot = &sc->slots[i];
        if (slot->valid && (uint32_t)(tick - slot->tick) > AUTH_TIMEOUT_TICKS) {
            *out = *slot;
            slot->valid = false;
            return true;
        }
    }
    return false;
}
