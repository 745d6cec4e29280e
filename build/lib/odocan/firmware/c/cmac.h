/* AES-CMAC (RFC 4493) over AES-128, integer-only: firmware/cmac.py, same names and order. */
#ifndef ODOCAN_CMAC_H
#define ODOCAN_CMAC_H

#include <stdint.h>

#include "aes.h"

#define CMAC_RB_128 0x87u

/* A provisioned AES-CMAC key: round keys and the subkeys K1, K2 (RFC 4493 2.3). */
typedef struct {
    uint32_t rk[AES128_ROUND_KEY_WORDS];
    uint32_t k1[4];
    uint32_t k2[4];
} cmac_key_t;

void cmac_key(const uint8_t key[AES128_KEY_BYTES], cmac_key_t *out);
void aes_cmac(const cmac_key_t *key, const uint8_t *msg, uint32_t len, uint8_t tag[16]);

#endif
