/* AES-CMAC (RFC 4493, NIST SP 800-38B) over AES-128: firmware/cmac.py, same names and order. */
#include "cmac.h"

#include <stdbool.h>

#define PAD_FIRST_BYTE 0x80u

/* RFC 4493 2.3: the 128-bit block shifted left by one, XOR Rb if its MSB was set (no branch). */
static void shift_left_1(const uint32_t in[4], uint32_t out[4])
{
    uint32_t carry_out = in[0] >> 31;
    out[0] = (in[0] << 1) | (in[1] >> 31);
    out[1] = (in[1] << 1) | (in[2] >> 31);
    out[2] = (in[2] << 1) | (in[3] >> 31);
    out[3] = (in[3] << 1) ^ (CMAC_RB_128 & (0u - carry_out));
}

/* Provision a 16-byte key: expand it and derive K1, K2 (RFC 4493 Generate_Subkey). */
void cmac_key(const uint8_t key[AES128_KEY_BYTES], cmac_key_t *out)
{
    uint32_t ell[4] = {0, 0, 0, 0};
    aes128_expand_key(key, out->rk);
    aes128_encrypt_words(out->rk, ell);
    shift_left_1(ell, out->k1);
    shift_left_1(out->k1, out->k2);
}

/* The 16-byte AES-CMAC tag of msg[0..len) (any length, 0 included): RFC 4493 2.4. */
void aes_cmac(const cmac_key_t *key, const uint8_t *msg, uint32_t len, uint8_t tag[16])
{
    uint32_t full_blocks = (len + AES_BLOCK_BYTES - 1u) >> 4;
    if (full_blocks == 0u) {
        full_blocks = 1u;
    }
    bool last_complete = len != 0u && (len & (AES_BLOCK_BYTES - 1u)) == 0u;
    uint32_t x[4] = {0, 0, 0, 0};
    uint32_t offset = 0;
    for (uint32_t b = 0; b + 1u < full_blocks; b++) {
        for (unsigned i = 0; i < 4u; i++) {
            x[i] ^= load_be32(msg, offset + 4u * i);
        }
        aes128_encrypt_words(key->rk, x);
        offset += AES_BLOCK_BYTES;
    }
    uint8_t last[AES_BLOCK_BYTES] = {0};
    uint32_t tail = len - offset;
    for (uint32_t i = 0; i < tail; i++) {
        last[i] = msg[offset + i];
    }
    if (!last_complete) {
        last[tail] = PAD_FIRST_BYTE;
    }
    const uint32_t *sub = last_complete ? key->k1 : key->k2;
    for (unsigned i = 0; i < 4u; i++) {
        x[i] ^= sub[i] ^ load_be32(last, 4u * i);
    }
    aes128_encrypt_words(key->rk, x);
    for (unsigned i = 0; i < 4u; i++) {
        store_be32(tag, 4u * i, x[i]);
    }
}
