#define _POSIX_C_SOURCE 199309L
/* The SecOC authenticator of firmware/secoc.py, transliterated (table-driven AES-128, one-block
 * CMAC). bench/secoc.py compiles it (cc -O2 -std=c99) to time the C cost and to check it bit for bit. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static uint8_t SBOX[256];
static uint32_t TE0[256], TE1[256], TE2[256], TE3[256];
static const uint8_t RCON[10] = {0x01, 0x02, 0x04, 0x08, 0x10, 0x20, 0x40, 0x80, 0x1B, 0x36};

typedef struct { uint32_t rk[44], k1[4], k2[4]; } cmac_key_t;

static uint8_t xtime(uint8_t b) { return (uint8_t)((b << 1) ^ ((b & 0x80) ? 0x1B : 0)); }
static uint8_t rotl8(uint8_t b, int n) { return (uint8_t)((b << n) | (b >> (8 - n))); }
static uint32_t ror32(uint32_t w, int n) { return (w >> n) | (w << (32 - n)); }
static uint32_t be32(const uint8_t *p) {
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

static void tables(void) {
    uint8_t exp[256], log[256], v = 1;
    for (int i = 0; i < 255; i++) { exp[i] = v; log[v] = (uint8_t)i; v ^= xtime(v); }
    exp[255] = exp[0];
    for (int x = 0; x < 256; x++) {
        uint8_t inv = x ? exp[255 - log[x]] : 0;
        SBOX[x] = inv ^ rotl8(inv, 1) ^ rotl8(inv, 2) ^ rotl8(inv, 3) ^ rotl8(inv, 4) ^ 0x63;
        uint8_t s = SBOX[x], s2 = xtime(s);
        TE0[x] = (uint32_t)s2 << 24 | (uint32_t)s << 16 | (uint32_t)s << 8 | (uint8_t)(s2 ^ s);
        TE1[x] = ror32(TE0[x], 8); TE2[x] = ror32(TE0[x], 16); TE3[x] = ror32(TE0[x], 24);
    }
}

static uint32_t sub_word(uint32_t w) {
    return (uint32_t)SBOX[w >> 24] << 24 | (uint32_t)SBOX[(w >> 16) & 0xFF] << 16 |
           (uint32_t)SBOX[(w >> 8) & 0xFF] << 8 | SBOX[w & 0xFF];
}

static void expand_key(const uint8_t key[16], uint32_t rk[44]) {
    for (int i = 0; i < 4; i++) rk[i] = be32(key + 4 * i);
    for (int i = 4; i < 44; i++) {
        uint32_t t = rk[i - 1];
        if ((i & 3) == 0) t = sub_word(t << 8 | t >> 24) ^ (uint32_t)RCON[(i >> 2) - 1] << 24;
        rk[i] = rk[i - 4] ^ t;
    }
}

static void encrypt_words(const uint32_t rk[44], uint32_t s[4]) {
    uint32_t s0 = s[0] ^ rk[0], s1 = s[1] ^ rk[1], s2 = s[2] ^ rk[2], s3 = s[3] ^ rk[3];
    for (int r = 4; r < 40; r += 4) {
        uint32_t a0 = TE0[s0 >> 24] ^ TE1[(s1 >> 16) & 0xFF] ^ TE2[(s2 >> 8) & 0xFF] ^ TE3[s3 & 0xFF] ^ rk[r];
        uint32_t a1 = TE0[s1 >> 24] ^ TE1[(s2 >> 16) & 0xFF] ^ TE2[(s3 >> 8) & 0xFF] ^ TE3[s0 & 0xFF] ^ rk[r + 1];
        uint32_t a2 = TE0[s2 >> 24] ^ TE1[(s3 >> 16) & 0xFF] ^ TE2[(s0 >> 8) & 0xFF] ^ TE3[s1 & 0xFF] ^ rk[r + 2];
        uint32_t a3 = TE0[s3 >> 24] ^ TE1[(s0 >> 16) & 0xFF] ^ TE2[(s1 >> 8) & 0xFF] ^ TE3[s2 & 0xFF] ^ rk[r + 3];
        s0 = a0; s1 = a1; s2 = a2; s3 = a3;
    }
#define LAST(a, b, c, d) ((uint32_t)SBOX[(a) >> 24] << 24 | (uint32_t)SBOX[((b) >> 16) & 0xFF] << 16 | \
                          (uint32_t)SBOX[((c) >> 8) & 0xFF] << 8 | SBOX[(d) & 0xFF])
    s[0] = LAST(s0, s1, s2, s3) ^ rk[40];
    s[1] = LAST(s1, s2, s3, s0) ^ rk[41];
    s[2] = LAST(s2, s3, s0, s1) ^ rk[42];
    s[3] = LAST(s3, s0, s1, s2) ^ rk[43];
}

static void shl1(const uint32_t in[4], uint32_t out[4]) {
    uint32_t carry = in[0] >> 31;
    out[0] = in[0] << 1 | in[1] >> 31;
    out[1] = in[1] << 1 | in[2] >> 31;
    out[2] = in[2] << 1 | in[3] >> 31;
    out[3] = (in[3] << 1) ^ (0x87u & -carry);
}

static void cmac_key(const uint8_t key[16], cmac_key_t *k) {
    uint32_t ell[4] = {0, 0, 0, 0};
    expand_key(key, k->rk);
    encrypt_words(k->rk, ell);
    shl1(ell, k->k1);
    shl1(k->k1, k->k2);
}

/* MSB_32(AES-CMAC(K, DataID u16 BE || PDU[8] || FV u48 BE)): one complete block, one AES. */
static uint32_t authenticator(const cmac_key_t *k, uint16_t data_id, const uint8_t pdu[8], uint64_t fv) {
    uint8_t b[16];
    uint32_t s[4];
    b[0] = (uint8_t)(data_id >> 8); b[1] = (uint8_t)data_id;
    memcpy(b + 2, pdu, 8);
    for (int i = 0; i < 6; i++) b[10 + i] = (uint8_t)(fv >> (40 - 8 * i));
    for (int i = 0; i < 4; i++) s[i] = be32(b + 4 * i) ^ k->k1[i];
    encrypt_words(k->rk, s);
    return s[0];
}

int main(int argc, char **argv) {
    static const uint8_t key[16] = {0x2b, 0x7e, 0x15, 0x16, 0x28, 0xae, 0xd2, 0xa6,
                                    0xab, 0xf7, 0x15, 0x88, 0x09, 0xcf, 0x4f, 0x3c};
    static const uint8_t pdu[8] = {0x36, 0x00, 0x39, 0x30, 0x00, 0x00, 0x00, 0x00};
    long n = argc > 1 ? atol(argv[1]) : 1000000;
    cmac_key_t k;
    struct timespec t0, t1;
    uint32_t acc = 0;
    tables();
    cmac_key(key, &k);
    printf("%08x\n", authenticator(&k, 0x300, pdu, 0x000010000001ull));
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (long i = 0; i < n; i++) acc ^= authenticator(&k, 0x300, pdu, 0x000010000001ull + (uint64_t)i);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    printf("%08x %.1f\n", acc, ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / (double)n);
    return 0;
}
