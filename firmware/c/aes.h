/* AES-128 block encryption (FIPS-197), integer-only: the cipher under the SecOC authenticator
 * (firmware/aes.py, same names and order). */
#ifndef ODOCAN_AES_H
#define ODOCAN_AES_H

#include <stdint.h>

#define AES128_KEY_BYTES 16
#define AES_BLOCK_BYTES 16
#define AES128_ROUNDS 10
#define AES128_ROUND_KEY_WORDS (4 * (AES128_ROUNDS + 1))

uint32_t load_be32(const uint8_t *data, unsigned offset);
void store_be32(uint8_t *out, unsigned offset, uint32_t word);
void aes128_expand_key(const uint8_t key[AES128_KEY_BYTES], uint32_t rk[AES128_ROUND_KEY_WORDS]);
void aes128_encrypt_words(const uint32_t rk[AES128_ROUND_KEY_WORDS], uint32_t s[4]);

#endif
