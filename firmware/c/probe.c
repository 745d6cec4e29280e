/* A line-oriented probe of the C port's functions, for tests/test_c_port.py: one command a line on
 * stdin, one answer a line on stdout, so a test can put the same inputs to the Python firmware
 * and to the C port (natively and under qemu-arm) and compare every answer.
 *
 *   sincos A                 -> sin cos               (A: u32 BAM32)
 *   atan2 Y X                -> angle                 (i64 each)
 *   chord DH                 -> chord_factor_q62      (i64 BAM64 step)
 *   muldiv A B C             -> quotient errors       (u64 each)
 *   mulshr A B S             -> result errors         (i64, i64, shift)
 *   div_round N D            -> result
 *   div_q62 N HI LO          -> result                (i64, i64, u64: N / (HI * 2^64 + LO))
 *   isqrt N                  -> result
 *   wrap_signed V BITS       -> result                (V: u32)
 *   config PPV RL RR B BITS I -> reason [m_l m_r k_l k_r errors]
 *   config_speed V PPV RL RR B BITS I -> validate_at_speed's reason (V: mm/s)
 *   crc HEX                  -> crc8h2f of the bytes ("-" for none)
 *   table                    -> the 256 CRC8H2F table entries
 *   rx IDS_HEX INIT WPP      -> ok                    (a new receiver: 16 data IDs)
 *   period | reset           -> ok
 *   check HEX|-              -> status ok oksomelost repeated wrongsequence error nonewdata
 *                               lost_frames last_valid_counter max_delta_counter lost_data
 *                               accepted
 *   protect HEX COUNTER      -> the frame after protect() (E2E_P02Protect on e2e.c's p02_crc,
 *                               with the receiver's data IDs)
 *   dist DX DY | bearing DX DY H32 | turn E K | speed D K | wheels V W B | gtg D E
 *   | straight D E | rate T P | q40 V  -> the nav.c function's results (and errors)
 *   nav_new                  -> ok                    (a new navigator)
 *   nav_req FIELD VALUE MODE APPEND NO_FINAL GOAL_ID RUNNING -> ack reason
 *   nav_step X Y H64 B COUNT64 RUNNING -> sent left right state goal_id depth distance_um
 *                               heading_error changed errors   (then changed is cleared)
 *   enc_unpack HEX           -> counter left right ctrl_uptime (cantools-generated dbc/odocan.c)
 *   enc_pack COUNTER L R | motor_pack COUNTER L R -> the sealed frame (generated pack + E2E)
 *   goal_unpack HEX          -> counter field value mode append no_final_heading goal_id
 *   ecu_new PPV RL RR B BITS I -> ok                  (a new ECU)
 *   ecu_rx ID HEX | ecu_bus OFF | ecu_txfull FULL | ecu_overrun -> ok (a frame into the ISR,
 *                            bus state, the driver refusing frames or not, a receive FIFO overrun)
 *   ecu_tick | ecu_tick_at NOW_US -> state reason errors tx_dropped then every frame sent, ID:HEX
 *                            (ecu_tick: no timer, one period; ecu_tick_at: the u32 timer value)
 *   cmac KEY MSG|-           -> the 16-byte AES-CMAC tag (hex)
 *   auth KEY DATA_ID PDU FV  -> the 32-bit SecOC authenticator
 *   nvm EPOCH FAIL           -> ok                    (the probe's EPOCH cell: value, writes fail)
 *   ecu_secoc KEY|-          -> ok                    (provision the ECU; "-": a bad key)
 *   ecu_secoc_counts         -> ok failed freshness orphans epoch last_fv
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "dbc/odocan.h"
#include "e2e.h"
#include "ecu.h"
#include "fixmath.h"
#include "nav.h"
#include "odometry.h"
#include "secoc.h"
#include "trig.h"

#define MAX_BYTES 64

static int64_t arg_i64(void)
{
    const char *tok = strtok(NULL, " \t\n");
    return tok == NULL ? 0 : (int64_t)strtoll(tok, NULL, 10);
}

static uint64_t arg_u64(void)
{
    const char *tok = strtok(NULL, " \t\n");
    return tok == NULL ? 0u : (uint64_t)strtoull(tok, NULL, 10);
}

/* The six robot parameters in struct robot_params order, from the rest of the line. */
static struct robot_params read_params(void)
{
    struct robot_params p;
    p.counts_per_rev = (uint32_t)arg_u64();
    p.wheel_radius_left_nm = (uint32_t)arg_u64();
    p.wheel_radius_right_nm = (uint32_t)arg_u64();
    p.wheelbase_nm = (uint32_t)arg_u64();
    p.counter_bits = (uint32_t)arg_u64();
    p.integrator = (uint32_t)arg_u64();
    p.max_wheel_speed_mm_s = (uint32_t)arg_u64();
    return p;
}

/* Hex bytes into out; returns the count, or -1 for "-" (no frame) or a missing argument. */
static long arg_bytes(uint8_t *out)
{
    const char *tok = strtok(NULL, " \t\n");
    size_t n = 0u;
    if (tok == NULL || strcmp(tok, "-") == 0) {
        return -1;
    }
    while (tok[2u * n] != '\0' && tok[2u * n + 1u] != '\0' && n < MAX_BYTES) {
        char pair[3] = {tok[2u * n], tok[2u * n + 1u], '\0'};
        out[n] = (uint8_t)strtoul(pair, NULL, 16);
        ++n;
    }
    return (long)n;
}

/* Profile 2 DataIDList of E2E slot `slot`: DataID[c] = (slot << 4) | c (firmware/frames.py). */
static void data_ids_of_slot(unsigned slot, uint8_t ids[DATA_ID_COUNT])
{
    for (unsigned c = 0u; c < DATA_ID_COUNT; ++c) {
        ids[c] = (uint8_t)((slot << 4) | c);
    }
}

/* E2E_P02Protect, a sender's side the ECU never runs (it seals its frames in frames.c): write
 * COUNTER (byte 1 low nibble, taken mod 16), then CHECKSUM by e2e.c's p02_crc. */
static void protect(uint8_t frame[FRAME_LEN], uint8_t counter,
                    const uint8_t data_ids[DATA_ID_COUNT])
{
    counter &= COUNTER_MASK;
    frame[1] = (uint8_t)((frame[1] & 0xF0u) | counter);
    frame[0] = p02_crc(frame, data_ids[counter]);
}

static void print_frame(const uint8_t frame[FRAME_LEN])
{
    for (unsigned k = 0u; k < FRAME_LEN; ++k) {
        printf("%02X", (unsigned)frame[k]);
    }
    printf("\n");
}

/* The probe's CAN driver: collects the frames of one tick, or refuses them when full. */
struct tx_log {
    bool full;
    char text[4096];
    size_t used;
};

static bool probe_transmit(void *ctx, uint32_t can_id, const uint8_t data[8])
{
    struct tx_log *log = ctx;
    if (log->full) {
        return false;
    }
    int n = snprintf(log->text + log->used, sizeof log->text - log->used,
                     " %" PRIX32 ":%02X%02X%02X%02X%02X%02X%02X%02X", can_id, data[0], data[1],
                     data[2], data[3], data[4], data[5], data[6], data[7]);
    if (n > 0 && log->used + (size_t)n < sizeof log->text) {
        log->used += (size_t)n;
    }
    return true;
}

/* The probe's NVM cell: survives ecu_new (a reboot). */
struct nvm_cell {
    uint32_t epoch;
    bool fail;
};

static uint32_t cell_read(void *ctx)
{
    return ((struct nvm_cell *)ctx)->epoch;
}

static bool cell_write(void *ctx, uint32_t epoch)
{
    struct nvm_cell *cell = ctx;
    if (cell->fail) {
        return false;
    }
    cell->epoch = epoch;
    return true;
}

static void print_rx(const struct e2e_receiver *rx, enum e2e_status status)
{
    printf("%d %" PRIu32 " %" PRIu32 " %" PRIu32 " %" PRIu32 " %" PRIu32 " %" PRIu32 " %" PRIu32
           " %u %u %u %" PRIu32 "\n",
           (int)status, rx->count_ok, rx->count_oksomelost, rx->count_repeated,
           rx->count_wrongsequence, rx->count_error, rx->count_nonewdata, rx->lost_frames,
           (unsigned)rx->last_valid_counter, (unsigned)rx->max_delta_counter,
           (unsigned)rx->lost_data, e2e_accepted(rx));
}

int main(void)
{
    static char line[1024];
    static uint8_t data_ids[DATA_ID_COUNT];
    static uint8_t bytes[MAX_BYTES];
    struct e2e_receiver rx;
    e2e_receiver_init(&rx, data_ids, 1u, false);
    static struct odom_ecu ecu;
    static struct tx_log tx_log;
    static struct robot_params ecu_params = {500u, 75000000u, 75000000u, 300000000u, 16u, 2u,
                                                MAX_WHEEL_SPEED_DEFAULT_MM_S};
    ecu_init(&ecu, probe_transmit, &tx_log, &ecu_params);
    static struct navigator nav;
    static uint32_t nav_errors;
    static struct nvm_cell nvm_cell;
    navigator_init(&nav, &nav_errors);
    while (fgets(line, sizeof line, stdin) != NULL) {
        const char *cmd = strtok(line, " \t\n");
        uint32_t errors = 0u;
        if (cmd == NULL) {
            continue;
        }
        if (strcmp(cmd, "sincos") == 0) {
            int32_t s;
            int32_t c;
            sincos_q30((uint32_t)arg_u64(), &s, &c);
            printf("%" PRId32 " %" PRId32 "\n", s, c);
        } else if (strcmp(cmd, "atan2") == 0) {
            int64_t y = arg_i64();
            printf("%" PRId32 "\n", atan2_bam32(y, arg_i64()));
        } else if (strcmp(cmd, "chord") == 0) {
            printf("%" PRId64 "\n", chord_factor_q62(arg_i64()));
        } else if (strcmp(cmd, "muldiv") == 0) {
            uint64_t a = arg_u64();
            uint64_t b = arg_u64();
            uint64_t q = muldiv_round_u64(a, b, arg_u64(), &errors);
            printf("%" PRIu64 " %" PRIu32 "\n", q, errors);
        } else if (strcmp(cmd, "div_q62") == 0) {
            int64_t num = arg_i64();
            int64_t hi = arg_i64();
            printf("%" PRId64 "\n", div_q62_i128(num, hi, arg_u64()));
        } else if (strcmp(cmd, "mulshr") == 0) {
            int64_t a = arg_i64();
            int64_t b = arg_i64();
            int64_t r = mul_shr_round_i64(a, b, (unsigned)arg_u64(), &errors);
            printf("%" PRId64 " %" PRIu32 "\n", r, errors);
        } else if (strcmp(cmd, "div_round") == 0) {
            int64_t n = arg_i64();
            printf("%" PRId64 "\n", div_round_i64(n, arg_i64()));
        } else if (strcmp(cmd, "isqrt") == 0) {
            printf("%" PRIu32 "\n", isqrt_u64(arg_u64()));
        } else if (strcmp(cmd, "wrap_signed") == 0) {
            uint32_t v = (uint32_t)arg_u64();
            printf("%" PRId32 "\n", wrap_signed(v, (unsigned)arg_u64()));
        } else if (strcmp(cmd, "config") == 0) {
            struct robot_params p = read_params();
            enum config_reason reason = validate(&p);
            if (reason != CONFIG_OK) {
                printf("%d\n", (int)reason);
                continue;
            }
            struct odom_constants k;
            derive_constants(&p, &errors, &k);
            printf("0 %" PRId64 " %" PRId64 " %" PRIu64 " %" PRIu64 " %" PRIu32 "\n",
                   k.m_per_count_left_q48_m, k.m_per_count_right_q48_m, k.bam64_per_count_left,
                   k.bam64_per_count_right, errors);
        } else if (strcmp(cmd, "config_speed") == 0) {
            uint32_t speed_mm_s = (uint32_t)arg_u64();
            struct robot_params p = read_params();
            printf("%d\n", (int)validate_at_speed(&p, speed_mm_s));
        } else if (strcmp(cmd, "crc") == 0) {
            long n = arg_bytes(bytes);
            printf("%u\n", (unsigned)crc8h2f(bytes, n < 0 ? 0u : (size_t)n));
        } else if (strcmp(cmd, "table") == 0) {
            for (unsigned b = 0u; b < 256u; ++b) { /* each entry is crc8h2f's step of one byte */
                uint8_t one = (uint8_t)(b ^ CRC8H2F_INIT);
                uint8_t crc_of_byte = (uint8_t)(crc8h2f(&one, 1u) ^ CRC8H2F_XOR_OUT);
                printf("%u%s", (unsigned)crc_of_byte, b == 255u ? "\n" : " ");
            }
        } else if (strcmp(cmd, "rx") == 0) {
            memset(data_ids, 0, sizeof data_ids);
            arg_bytes(bytes);
            memcpy(data_ids, bytes, sizeof data_ids);
            uint8_t init = (uint8_t)arg_u64();
            e2e_receiver_init(&rx, data_ids, init, arg_u64() != 0u);
            printf("ok\n");
        } else if (strcmp(cmd, "period") == 0) {
            e2e_new_period(&rx);
            printf("ok\n");
        } else if (strcmp(cmd, "reset") == 0) {
            e2e_reset(&rx);
            printf("ok\n");
        } else if (strcmp(cmd, "check") == 0) {
            long n = arg_bytes(bytes);
            enum e2e_status status =
                n < 0 ? e2e_check(&rx, NULL, 0u) : e2e_check(&rx, bytes, (size_t)n);
            print_rx(&rx, status);
        } else if (strcmp(cmd, "protect") == 0) {
            long n = arg_bytes(bytes);
            uint8_t counter = (uint8_t)arg_u64();
            if (n == (long)FRAME_LEN) {
                protect(bytes, counter, data_ids);
            }
            for (long k = 0; k < n; ++k) {
                printf("%02X", (unsigned)bytes[k]);
            }
            printf("\n");
        } else if (strcmp(cmd, "dist") == 0) {
            int64_t dx = arg_i64();
            int64_t d = distance_um(dx, arg_i64(), &errors);
            printf("%" PRId64 " %" PRIu32 "\n", d, errors);
        } else if (strcmp(cmd, "bearing") == 0) {
            int64_t dx = arg_i64();
            int64_t dy = arg_i64();
            printf("%" PRId32 "\n", bearing_error_bam32(dx, dy, (uint32_t)arg_u64()));
        } else if (strcmp(cmd, "turn") == 0) {
            int32_t e = (int32_t)arg_i64();
            int32_t w = turn_rate_mrad_s(e, (int32_t)arg_i64(), &errors);
            printf("%" PRId32 " %" PRIu32 "\n", w, errors);
        } else if (strcmp(cmd, "speed") == 0) {
            int64_t d = arg_i64();
            printf("%" PRId32 "\n", speed_mm_s(d, (int32_t)arg_i64()));
        } else if (strcmp(cmd, "wheels") == 0) {
            int32_t v = (int32_t)arg_i64();
            int32_t w = (int32_t)arg_i64();
            int32_t left;
            int32_t right;
            wheel_speeds_mm_s(v, w, (uint32_t)arg_u64(), &left, &right);
            printf("%" PRId32 " %" PRId32 "\n", left, right);
        } else if (strcmp(cmd, "gtg") == 0 || strcmp(cmd, "straight") == 0) {
            bool gtg = strcmp(cmd, "gtg") == 0;
            int64_t d = arg_i64();
            int32_t e = (int32_t)arg_i64();
            int32_t v;
            int32_t w;
            if (gtg) {
                go_to_goal_law(d, e, &errors, &v, &w);
            } else {
                drive_straight_law(d, e, &errors, &v, &w);
            }
            printf("%" PRId32 " %" PRId32 " %" PRIu32 "\n", v, w, errors);
        } else if (strcmp(cmd, "rate") == 0) {
            int32_t t = (int32_t)arg_i64();
            printf("%" PRId32 "\n", rate_limit(t, (int32_t)arg_i64()));
        } else if (strcmp(cmd, "q40") == 0) {
            printf("%" PRId64 "\n", q40_from_100um((int32_t)arg_i64()));
        } else if (strcmp(cmd, "nav_new") == 0) {
            nav_errors = 0u;
            navigator_init(&nav, &nav_errors);
            printf("ok\n");
        } else if (strcmp(cmd, "nav_req") == 0) {
            struct nav_goal_frame f;
            f.field = (uint32_t)arg_u64();
            f.value = arg_i64();
            f.mode = (uint32_t)arg_u64();
            f.append = (uint32_t)arg_u64();
            f.no_final_heading = (uint32_t)arg_u64();
            f.goal_id = (uint8_t)arg_u64();
            printf("%d\n", (int)nav_request(&nav, &f, arg_u64() != 0u));
        } else if (strcmp(cmd, "nav_step") == 0) {
            int64_t x = arg_i64();
            int64_t y = arg_i64();
            uint64_t h = arg_u64();
            uint32_t b = (uint32_t)arg_u64();
            uint64_t count = arg_u64();
            bool sent = nav_step(&nav, x, y, h, b, count, arg_u64() != 0u);
            printf("%d %" PRId32 " %" PRId32 " %d %u %u %" PRId64 " %" PRId32 " %d %" PRIu32 "\n",
                   (int)sent, nav.left_mm_s, nav.right_mm_s, (int)nav.state,
                   (unsigned)nav.goal_id, nav.depth, nav.distance_um, nav.heading_error_bam32,
                   (int)nav.changed, nav_errors);
            nav.changed = false;
        } else if (strcmp(cmd, "enc_unpack") == 0) {
            long n = arg_bytes(bytes);
            struct odocan_wheel_encoders_t m;
            odocan_wheel_encoders_unpack(&m, bytes, n < 0 ? 0u : (size_t)n);
            printf("%u %" PRIu32 " %" PRIu32 " %u\n", (unsigned)m.counter, m.left_count,
                   m.right_count, (unsigned)m.ctrl_uptime);
        } else if (strcmp(cmd, "enc_pack") == 0 || strcmp(cmd, "motor_pack") == 0) {
            uint8_t frame[FRAME_LEN];
            uint8_t ids[DATA_ID_COUNT];
            uint8_t counter = (uint8_t)(arg_u64() & COUNTER_MASK);
            int64_t left = arg_i64();
            int64_t right = arg_i64();
            if (cmd[0] == 'e') {
                struct odocan_wheel_encoders_t m;
                odocan_wheel_encoders_init(&m);
                m.counter = counter;
                m.left_count = (uint32_t)left & 0xFFFFFFu;
                m.right_count = (uint32_t)right & 0xFFFFFFu;
                odocan_wheel_encoders_pack(frame, &m, sizeof frame);
                data_ids_of_slot(1u, ids);
            } else {
                struct odocan_motor_cmd_t m;
                odocan_motor_cmd_init(&m);
                m.counter = counter;
                m.left_speed = (int16_t)left; /* the caller passes i16 values */
                m.right_speed = (int16_t)right;
                odocan_motor_cmd_pack(frame, &m, sizeof frame);
                data_ids_of_slot(2u, ids);
            }
            protect(frame, counter, ids);
            print_frame(frame);
        } else if (strcmp(cmd, "goal_unpack") == 0) {
            long n = arg_bytes(bytes);
            struct odocan_nav_goal_t m;
            odocan_nav_goal_unpack(&m, bytes, n < 0 ? 0u : (size_t)n);
            int64_t value = 0;
            unsigned mode = 0u;
            unsigned append = 0u;
            unsigned no_final = 0u;
            unsigned goal_id = 0u;
            switch (m.field) {
            case ODOCAN_NAV_GOAL_FIELD_X_CHOICE: value = m.x; break;
            case ODOCAN_NAV_GOAL_FIELD_Y_CHOICE: value = m.y; break;
            case ODOCAN_NAV_GOAL_FIELD_HEADING_CHOICE: value = m.heading; break;
            case ODOCAN_NAV_GOAL_FIELD_STOP_CHOICE: break;
            case ODOCAN_NAV_GOAL_FIELD_GO_CHOICE:
                mode = m.mode;
                append = m.append;
                no_final = m.no_final_heading;
                goal_id = m.goal_id;
                break;
            default: /* a field the DBC does not define: the raw u32 (firmware/frames.py) */
                value = (int64_t)(((uint32_t)bytes[2] | ((uint32_t)bytes[3] << 8)
                                   | ((uint32_t)bytes[4] << 16) | ((uint32_t)bytes[5] << 24)));
                break;
            }
            printf("%u %u %" PRId64 " %u %u %u %u\n", (unsigned)m.counter, (unsigned)m.field, value,
                   mode, append, no_final, goal_id);
        } else if (strcmp(cmd, "cmac") == 0) {
            uint8_t key[MAX_BYTES];
            long key_len = arg_bytes(key);
            long n = arg_bytes(bytes);
            cmac_key_t ck;
            uint8_t tag[16];
            if (key_len != AES128_KEY_BYTES) {
                printf("bad key\n");
                continue;
            }
            cmac_key(key, &ck);
            aes_cmac(&ck, bytes, n < 0 ? 0u : (uint32_t)n, tag);
            for (unsigned k = 0u; k < 16u; ++k) {
                printf("%02X", (unsigned)tag[k]);
            }
            printf("\n");
        } else if (strcmp(cmd, "auth") == 0) {
            uint8_t key[MAX_BYTES];
            long key_len = arg_bytes(key);
            uint32_t data_id = (uint32_t)arg_u64();
            (void)arg_bytes(bytes);
            uint64_t fv = arg_u64();
            cmac_key_t ck;
            if (key_len != AES128_KEY_BYTES) {
                printf("bad key\n");
                continue;
            }
            cmac_key(key, &ck);
            printf("%" PRIu32 "\n", authenticator(&ck, data_id, bytes, fv));
        } else if (strcmp(cmd, "nvm") == 0) {
            nvm_cell.epoch = (uint32_t)arg_u64();
            nvm_cell.fail = arg_u64() != 0u;
            printf("ok\n");
        } else if (strcmp(cmd, "ecu_secoc") == 0) {
            uint8_t key[MAX_BYTES];
            long key_len = arg_bytes(key);
            struct freshness_nvm nvm = {cell_read, cell_write, &nvm_cell};
            ecu_provision_secoc(&ecu, key, key_len < 0 ? 0u : (unsigned)key_len, nvm);
            printf("ok\n");
        } else if (strcmp(cmd, "ecu_secoc_counts") == 0) {
            printf("%" PRIu32 " %" PRIu32 " %" PRIu32 " %" PRIu32 " %" PRIu32 " %" PRIu64 "\n",
                   ecu.secoc_rx.count_ok, ecu.secoc_rx.count_failed, ecu.secoc_rx.count_freshness,
                   ecu.secoc.orphans, ecu.secoc_rx.epoch, ecu.secoc_rx.last_fv);
        } else if (strcmp(cmd, "ecu_new") == 0) {
            ecu_params.counts_per_rev = (uint32_t)arg_u64();
            ecu_params.wheel_radius_left_nm = (uint32_t)arg_u64();
            ecu_params.wheel_radius_right_nm = (uint32_t)arg_u64();
            ecu_params.wheelbase_nm = (uint32_t)arg_u64();
            ecu_params.counter_bits = (uint32_t)arg_u64();
            ecu_params.integrator = (uint32_t)arg_u64();
            ecu_params.max_wheel_speed_mm_s = (uint32_t)arg_u64();
            tx_log.full = false;
            ecu_init(&ecu, probe_transmit, &tx_log, &ecu_params);
            printf("ok\n");
        } else if (strcmp(cmd, "ecu_rx") == 0) {
            uint32_t can_id = (uint32_t)arg_u64();
            long n = arg_bytes(bytes);
            ecu_isr_can_rx(&ecu, can_id, bytes, n < 0 ? 0u : (size_t)n);
            printf("ok\n");
        } else if (strcmp(cmd, "ecu_bus") == 0) {
            ecu_isr_bus_state(&ecu, arg_u64() != 0u);
            printf("ok\n");
        } else if (strcmp(cmd, "ecu_txfull") == 0) {
            tx_log.full = arg_u64() != 0u;
            printf("ok\n");
        } else if (strcmp(cmd, "ecu_overrun") == 0) {
            ecu_isr_rx_overrun(&ecu);
            printf("ok\n");
        } else if (strcmp(cmd, "ecu_tick") == 0 || strcmp(cmd, "ecu_tick_at") == 0) {
            tx_log.used = 0u;
            tx_log.text[0] = '\0';
            if (strcmp(cmd, "ecu_tick_at") == 0) {
                ecu_tick_at(&ecu, (uint32_t)arg_u64());
            } else {
                ecu_tick(&ecu);
            }
            printf("%d %d %" PRIu32 " %" PRIu32 "%s\n", (int)ecu.state, (int)ecu.reason, ecu.errors,
                   ecu.tx_dropped, tx_log.text);
        } else {
            printf("unknown %s\n", cmd);
        }
    }
    return 0;
}
