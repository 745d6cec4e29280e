#define _POSIX_C_SOURCE 199309L
/* The C port's SecOC verification cost (firmware/c/secoc.c): secoc_verify on genuine commands,
 * each one AES block plus the freshness check, on this host's CPU (not an MCU). Prints figures.
 *   cc -O2 -std=c99 -Ifirmware/c bench/secoc_c_port.c firmware/c/{aes,cmac,secoc,frames,e2e,
 *      fixmath,config,nav,trig,odometry}.c firmware/c/dbc/odocan.c -o /tmp/secoc_c && /tmp/secoc_c
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "secoc.h"

static uint32_t epoch_cell;
static uint32_t read_cell(void *ctx) { (void)ctx; return epoch_cell; }
static bool write_cell(void *ctx, uint32_t epoch) { (void)ctx; epoch_cell = epoch; return true; }

int main(int argc, char **argv)
{
    const uint32_t calls = argc > 1 ? (uint32_t)strtoul(argv[1], NULL, 10) : 1000000u;
    static const uint8_t key[16] = {0x2b, 0x7e, 0x15, 0x16, 0x28, 0xae, 0xd2, 0xa6,
                                    0xab, 0xf7, 0x15, 0x88, 0x09, 0xcf, 0x4f, 0x3c};
    struct freshness_nvm nvm = {read_cell, write_cell, NULL};
    struct secoc_receiver rx;
    secoc_receiver_init(&rx, key, 16u, nvm, MAC_BITS);
    uint8_t pdu[8] = {0x36, 0x00, 0x39, 0x30, 0, 0, 0, 0};
    /* the signer: the same key, the authenticators precomputed so only the verify is timed */
    uint32_t *macs = malloc(sizeof *macs * calls);
    uint64_t fv = rx.last_fv;
    for (uint32_t i = 0; i < calls; i++) {
        macs[i] = authenticator(&rx.key, 0x300u, pdu, ++fv);
    }
    struct timespec t0, t1;
    uint32_t ok = 0;
    fv = rx.last_fv;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (uint32_t i = 0; i < calls; i++) {
        ok += secoc_verify(&rx, 0x300u, pdu, (uint16_t)++fv, macs[i]) == AUTH_OK;
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    double ns = ((double)(t1.tv_sec - t0.tv_sec) * 1e9 + (double)(t1.tv_nsec - t0.tv_nsec)) / calls;
    printf("C port secoc_verify (genuine, one AES block + freshness): %.0f ns per command over "
           "%" PRIu32 " commands, %" PRIu32 " accepted\n", ns, calls, ok);
    free(macs);
    return 0;
}
