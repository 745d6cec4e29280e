/* AES-128 block encryption (FIPS-197), integer-only: firmware/aes.py, same names and order.
 *
 * The S-box and the four round tables are static const tables in flash (4 x 1 KiB + 256 B,
 * aes_tables.h), generated at dev time by tools/gen_aes_tables.py from FIPS-197's definitions;
 * firmware/aes.py computes the same tables at import (tests/test_aes_tables.py compares them). */
#include "aes.h"

#include "aes_tables.h"

static const uint8_t RCON[10] = {0x01, 0x02, 0x04, 0x08, 0x10, 0x20, 0x40, 0x80, 0x1B, 0x36};

static uint32_t sub_word(uint32_t word)
{
    return ((uint32_t)SBOX[word >> 24] << 24) | ((uint32_t)SBOX[(word >> 16) & 0xFFu] << 16) |
           ((uint32_t)SBOX[(word >> 8) & 0xFFu] << 8) | SBOX[word & 0xFFu];
}

uint32_t load_be32(const uint8_t *data, unsigned offset)
{
    return ((uint32_t)data[offset] << 24) | ((uint32_t)data[offset + 1u] << 16) |
           ((uint32_t)data[offset + 2u] << 8) | data[offset + 3u];
}

void store_be32(uint8_t *out, unsigned offset, uint32_t word)
{
    out[offset] = (uint8_t)(word >> 24);
    out[offset + 1u] = (uint8_t)(word >> 16);
    out[offset + 2u] = (uint8_t)(word >> 8);
    out[offset + 3u] = (uint8_t)word;
}

/* FIPS-197 5.2 KeyExpansion: the 44 round-key words (provisioning time, once per key). */
void aes128_expand_key(const uint8_t key[AES128_KEY_BYTES], uint32_t rk[AES128_ROUND_KEY_WORDS])
{
    for (unsigned i = 0; i < 4u; i++) {
        rk[i] = load_be32(key, 4u * i);
    }
    for (unsigned i = 4; i < AES128_ROUND_KEY_WORDS; i++) {
        uint32_t temp = rk[i - 1u];
        if ((i & 3u) == 0u) {
            temp = sub_word((temp << 8) | (temp >> 24)) ^ ((uint32_t)RCON[(i >> 2) - 1u] << 24);
        }
        rk[i] = rk[i - 4u] ^ temp;
    }
}

static uint32_t last_round_word(uint32_t a, uint32_t b, uint32_t c, uint32_t d)
{
    return ((uint32_t)SBOX[a >> 24] << 24) | ((uint32_t)SBOX[(b >> 16) & 0xFFu] << 16) |
           ((uint32_t)SBOX[(c >> 8) & 0xFFu] << 8) | SBOX[d & 0xFFu];
}

/* AES-128 Cipher (FIPS-197 5.1) of the state columns s[0..3], in place. */
void aes128_encrypt_words(const uint32_t rk[AES128_ROUND_KEY_WORDS], uint32_t s[4])
{
    uint32_t s0 = s[0] ^ rk[0], s1 = s[1] ^ rk[1], s2 = s[2] ^ rk[2], s3 = s[3] ^ rk[3];
    for (unsigned r = 4; r < 4u * AES128_ROUNDS; r += 4u) {
        uint32_t a0 = TE0[s0 >> 24] ^ TE1[(s1 >> 16) & 0xFFu] ^ TE2[(s2 >> 8) & 0xFFu] ^
                      TE3[s3 & 0xFFu] ^ rk[r];
        uint32_t a1 = TE0[s1 >> 24] ^ TE1[(s2 >> 16) & 0xFFu] ^ TE2[(s3 >> 8) & 0xFFu] ^
                      TE3[s0 & 0xFFu] ^ rk[r + 1u];
        uint32_t a2 = TE0[s2 >> 24] ^ TE1[(s3 >> 16) & 0xFFu] ^ TE2[(s0 >> 8) & 0xFFu] ^
                      TE3[s1 & 0xFFu] ^ rk[r + 2u];
        uint32_t a3 = TE0[s3 >> 24] ^ TE1[(s0 >> 16) & 0xFFu] ^ TE2[(s1 >> 8) & 0xFFu] ^
                      TE3[s2 & 0xFFu] ^ rk[r + 3u];
        s0 = a0;
        s1 = a1;
        s2 = a2;
        s3 = a3;
    }
    const unsigned last = 4u * AES128_ROUNDS;
    s[0] = last_round_word(s0, s1, s2, s3) ^ rk[last];
    s[1] = last_round_word(s1, s2, s3, s0) ^ rk[last + 1u];
    s[2] = last_round_word(s2, s3, s0, s1) ^ rk[last + 2u];
    s[3] = last_round_word(s3, s0, s1, s2) ^ rk[last + 3u];
}
