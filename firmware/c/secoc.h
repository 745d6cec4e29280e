/* SecOC-style authenticated commands (firmware/secoc.py, same names and order): the freshness
 * manager and verifier, and the held slots of the secured commands (docs/secoc.md). */
#ifndef ODOCAN_SECOC_H
#define ODOCAN_SECOC_H

#include <stdbool.h>
#include <stdint.h>

#include "cmac.h"

#define MAC_BITS 32u
#define FRESHNESS_TX_BITS 16u
#define FRESHNESS_TX_MASK 0xFFFFu
#define COUNT_BITS 28u
#define EPOCH_BITS 20u
#define COUNT_MASK ((1u << COUNT_BITS) - 1u)
#define EPOCH_MAX ((1u << EPOCH_BITS) - 1u)
#define FRESHNESS_WINDOW 4096u
#define ROLLOVER_COUNT (COUNT_MASK - FRESHNESS_WINDOW)
#define AUTH_TIMEOUT_TICKS 2u
#define FRESHNESS_PERIOD_TICKS 100u
#define SECURED_COUNT 3u

enum auth_request { AUTH_REQ_NAV_GOAL = 0, AUTH_REQ_ODOM_SET_POSE = 1, AUTH_REQ_ODOM_CONFIG = 2 };
enum auth_status { AUTH_OK = 0, AUTH_FAILED = 7, AUTH_FRESHNESS = 8, AUTH_MISSING = 9,
                   AUTH_UNAVAILABLE = 10 };
enum freshness_cause { CAUSE_BOOT = 0, CAUSE_PERIODIC = 1, CAUSE_REFUSED = 2, CAUSE_ROLLOVER = 3,
                       CAUSE_UNAVAILABLE = 4, CAUSE_NONE = 15 };

/* ODOM_AUTH's raw fields (firmware/frames.py OdomAuth). */
struct odom_auth {
    uint8_t counter;
    uint8_t request;
    uint16_t freshness;
    uint32_t authenticator;
};

/* The HAL's NVM cell holding EPOCH (firmware/hal.py FreshnessNvm). */
struct freshness_nvm {
    uint32_t (*read_epoch)(void *ctx);
    bool (*write_epoch)(void *ctx, uint32_t epoch); /* false: the write failed */
    void *ctx;
};

struct secoc_receiver {
    bool key_valid;
    cmac_key_t key;
    struct freshness_nvm nvm;
    unsigned mac_bits;
    uint32_t epoch;
    uint64_t last_fv;
    uint32_t count_ok, count_failed, count_freshness; /* wrapping */
    enum freshness_cause sync_cause;                  /* CAUSE_NONE: nothing due */
};

struct held {
    bool valid;
    uint32_t can_id;
    uint8_t pdu[8];
    uint32_t tick;
};

struct secured_commands {
    struct secoc_receiver *receiver;
    struct held slots[SECURED_COUNT];
    uint32_t orphans; /* wrapping */
};

extern const uint32_t SECURED_IDS[SECURED_COUNT];

void authenticator_input(uint32_t data_id, const uint8_t pdu[8], uint64_t fv, uint8_t block[16]);
uint32_t authenticator(const cmac_key_t *key, uint32_t data_id, const uint8_t pdu[8], uint64_t fv);
uint32_t truncate_mac(uint32_t mac32, unsigned mac_bits);
/* key: 16 bytes, or NULL / another length (key_len) for "no valid key". Boots. */
void secoc_receiver_init(struct secoc_receiver *rx, const uint8_t *key, unsigned key_len,
                         struct freshness_nvm nvm, unsigned mac_bits);
void secoc_boot(struct secoc_receiver *rx);
enum auth_status secoc_verify(struct secoc_receiver *rx, uint32_t data_id, const uint8_t pdu[8],
                              uint16_t freshness, uint32_t mac);
void secoc_freshness_frame(const struct secoc_receiver *rx, uint8_t counter,
                           enum freshness_cause cause, uint8_t out[8]);

void secured_init(struct secured_commands *sc, struct secoc_receiver *rx);
/* Hold a frame; true (and *displaced filled) when it displaced a held one. */
bool secured_hold(struct secured_commands *sc, enum auth_request request, const uint8_t pdu[8],
                  uint32_t tick, struct held *displaced);
/* false: nothing held for it (an orphan, counted); else *status and *out filled. */
bool secured_authenticate(struct secured_commands *sc, const struct odom_auth *auth,
                          enum auth_status *status, struct held *out);
/* true and *out filled: one held frame older than AUTH_TIMEOUT_TICKS (removed). */
bool secured_expire(struct secured_commands *sc, uint32_t tick, struct held *out);

#endif
