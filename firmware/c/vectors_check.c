/* Replays the golden vectors of `odocan vectors` through the C port; exit 0 only when every
 * output matches bit for bit.
 *
 * usage: vectors_check DIR/vectors.json [DIR/case.csv ...]
 *
 * The JSON file gives the robot parameters (validated and derived here by config.c; the derived
 * constants must equal the file's "constants") and every case's rows; each CSV file is one case.
 * Both are replayed: every row's counter pair goes through odometry_step_counts and the five
 * state integers after it are compared. A host-side test driver (stdio), not firmware: the
 * firmware sources it links are those of the port.
 *
 * The JSON reader is a small streaming tokenizer for the shape `odocan vectors` writes (objects of
 * integer and string members, arrays): a number is assigned to the member key read before it.
 */
#include <errno.h>
#include <inttypes.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "odometry.h"

#define MAX_REPORTED 10
#define TOKEN_LEN 128

enum field {
    F_STEP,
    F_LEFT,
    F_RIGHT,
    F_X,
    F_Y,
    F_HEADING,
    F_TURNS,
    F_DISTANCE,
    FIELD_COUNT
};

/* The CSV columns of host/judge/vectors.py (CSV_COLUMNS), in order; also the JSON row keys. */
static const char *const FIELD_NAMES[FIELD_COUNT] = {
    "step", "left_count", "right_count", "x_q40_m", "y_q40_m",
    "heading_bam64", "heading_turns", "distance_q40_m",
};

struct row {
    int64_t value[FIELD_COUNT]; /* heading_bam64 is stored as the bits of its u64 */
    unsigned seen;              /* a bit per field read */
};

/* One case being replayed. */
struct replay {
    const char *path;
    char case_name[TOKEN_LEN];
    struct odometry odo;
    uint32_t errors;
    int64_t steps;
    int64_t mismatches;
};

static int64_t total_steps;
static int64_t total_mismatches;

static void replay_start(struct replay *r, const char *path, const struct odom_constants *consts)
{
    r->path = path;
    r->steps = 0;
    r->mismatches = 0;
    r->errors = 0u;
    odometry_init(&r->odo, consts, &r->errors);
}

static void report_mismatch(struct replay *r, int64_t step, const char *what, int64_t want,
                            int64_t got)
{
    if (total_mismatches < MAX_REPORTED) {
        fprintf(stderr, "%s: case %s, step %" PRId64 ": %s is %" PRId64 ", expected %" PRId64 "\n",
                r->path, r->case_name, step, what, got, want);
    }
    r->mismatches++;
    total_mismatches++;
}

/* One row: step the odometry with its counters, compare the five state integers. */
static void replay_row(struct replay *r, const struct row *row)
{
    int64_t step = row->value[F_STEP];
    if (step != r->steps) {
        report_mismatch(r, step, "step number", r->steps, step);
    }
    odometry_step_counts(&r->odo, (uint32_t)row->value[F_LEFT], (uint32_t)row->value[F_RIGHT]);
    const struct odometry *o = &r->odo;
    const int64_t got[FIELD_COUNT] = {
        step, row->value[F_LEFT], row->value[F_RIGHT], o->x_q40_m, o->y_q40_m,
        (int64_t)o->heading_bam64, o->heading_turns, (int64_t)o->distance_q40_m,
    };
    for (int f = F_X; f < FIELD_COUNT; ++f) {
        if (got[f] != row->value[f]) {
            report_mismatch(r, step, FIELD_NAMES[f], row->value[f], got[f]);
        }
    }
    r->steps++;
    total_steps++;
}

static void replay_end(const struct replay *r)
{
    printf("%s: case %s: %" PRId64 " steps, %s\n", r->path, r->case_name, r->steps,
           r->mismatches == 0 ? "bit-exact" : "MISMATCH");
}

/* A decimal integer of the vector files: an i64, or a u64 read back as its i64 bits. */
static bool parse_integer(const char *text, int64_t *out)
{
    char *end = NULL;
    errno = 0;
    if (text[0] == '-') {
        long long v = strtoll(text, &end, 10);
        *out = (int64_t)v;
    } else {
        unsigned long long v = strtoull(text, &end, 10);
        *out = (int64_t)(uint64_t)v; /* two's complement: heading_bam64 >= 2^63 */
    }
    return errno == 0 && end != text && *end == '\0';
}

static int field_of(const char *key)
{
    for (int f = 0; f < FIELD_COUNT; ++f) {
        if (strcmp(key, FIELD_NAMES[f]) == 0) {
            return f;
        }
    }
    return -1;
}

/* The parameters and constants of the JSON file, by key. */
struct vector_header {
    struct robot_params params;
    struct odom_constants constants;
    unsigned seen; /* a bit per key below */
};

static const char *const HEADER_KEYS[] = {
    "counts_per_rev",         "wheel_radius_left_nm",    "wheel_radius_right_nm",
    "wheelbase_nm",           "counter_bits",            "integrator",
    "m_per_count_left_q48_m", "m_per_count_right_q48_m", "bam64_per_count_left",
    "bam64_per_count_right",  "max_wheel_speed_mm_s",
};
#define HEADER_KEY_COUNT 11
#define HEADER_OPTIONAL (1u << 10) /* max_wheel_speed_mm_s: absent in older vector sets */
#define HEADER_ALL ((1u << HEADER_KEY_COUNT) - 1u - HEADER_OPTIONAL)

static void header_set(struct vector_header *h, const char *key, int64_t v)
{
    int k = 0;
    while (k < HEADER_KEY_COUNT && strcmp(key, HEADER_KEYS[k]) != 0) {
        ++k;
    }
    uint32_t v32 = (uint32_t)v;
    switch (k) {
    case 0: h->params.counts_per_rev = v32; break;
    case 1: h->params.wheel_radius_left_nm = v32; break;
    case 2: h->params.wheel_radius_right_nm = v32; break;
    case 3: h->params.wheelbase_nm = v32; break;
    case 4: h->params.counter_bits = v32; break;
    case 5: h->params.integrator = v32; break;
    case 6: h->constants.m_per_count_left_q48_m = v; break;
    case 7: h->constants.m_per_count_right_q48_m = v; break;
    case 8: h->constants.bam64_per_count_left = (uint64_t)v; break;
    case 9: h->constants.bam64_per_count_right = (uint64_t)v; break;
    case 10: h->params.max_wheel_speed_mm_s = v32; break;
    default: return;
    }
    h->seen |= 1u << k;
}

/* Validate and derive the constants with config.c; they must equal the file's. */
static bool header_constants(const struct vector_header *h, const char *path,
                             struct odom_constants *out)
{
    if ((h->seen & HEADER_ALL) != HEADER_ALL) {
        fprintf(stderr, "%s: the parameters or constants are missing\n", path);
        return false;
    }
    if (validate(&h->params) != CONFIG_OK) {
        fprintf(stderr, "%s: the parameters are invalid (reason %d)\n", path,
                (int)validate(&h->params));
        return false;
    }
    uint32_t errors = 0u;
    derive_constants(&h->params, &errors, out);
    const struct odom_constants *want = &h->constants;
    if (out->m_per_count_left_q48_m != want->m_per_count_left_q48_m
        || out->m_per_count_right_q48_m != want->m_per_count_right_q48_m
        || out->bam64_per_count_left != want->bam64_per_count_left
        || out->bam64_per_count_right != want->bam64_per_count_right || errors != 0u) {
        fprintf(stderr, "%s: derive_constants differs from the file's constants\n", path);
        total_mismatches++;
    }
    return true;
}

/* Read a JSON string (the opening quote consumed) into buf, truncated to TOKEN_LEN - 1. */
static bool read_string(FILE *f, char *buf)
{
    size_t n = 0u;
    for (;;) {
        int ch = getc(f);
        if (ch == EOF) {
            return false;
        }
        if (ch == '"') {
            break;
        }
        if (ch == '\\') {
            ch = getc(f);
            if (ch == EOF) {
                return false;
            }
        }
        if (n + 1u < TOKEN_LEN) {
            buf[n++] = (char)ch;
        }
    }
    buf[n] = '\0';
    return true;
}

static int next_nonspace(FILE *f)
{
    int ch;
    do {
        ch = getc(f);
    } while (ch == ' ' || ch == '\n' || ch == '\r' || ch == '\t');
    return ch;
}

/* Replay every case of a vectors.json, derive its constants into *consts; false when the file
 * cannot be read. */
static bool check_json(const char *path, struct odom_constants *consts)
{
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        fprintf(stderr, "%s: %s\n", path, strerror(errno));
        return false;
    }
    static struct replay r;
    struct vector_header header;
    memset(&header, 0, sizeof header);
    header.params.max_wheel_speed_mm_s = MAX_WHEEL_SPEED_DEFAULT_MM_S; /* unless the file says */
    struct row row;
    memset(&row, 0, sizeof row);
    char key[TOKEN_LEN] = "";
    char token[TOKEN_LEN];
    char name[TOKEN_LEN] = "";
    bool in_case = false;
    bool ok = true;
    int ch = next_nonspace(f);
    while (ok && ch != EOF) {
        if (ch == '"') {
            ok = read_string(f, token);
            ch = next_nonspace(f);
            if (ch == ':') {
                memcpy(key, token, sizeof key);
                ch = next_nonspace(f);
                if (strcmp(key, "rows") == 0) {
                    if (!header_constants(&header, path, consts)) {
                        ok = false;
                        break;
                    }
                    replay_start(&r, path, consts);
                    memcpy(r.case_name, name, sizeof name);
                    in_case = true;
                }
            } else if (strcmp(key, "name") == 0) { /* a case's first member: the last one ends */
                if (in_case) {
                    replay_end(&r);
                    in_case = false;
                }
                memcpy(name, token, sizeof name);
            }
            continue;
        }
        if (ch == '-' || (ch >= '0' && ch <= '9')) {
            size_t n = 0u;
            while (ch == '-' || (ch >= '0' && ch <= '9')) {
                if (n + 1u < TOKEN_LEN) {
                    token[n++] = (char)ch;
                }
                ch = getc(f);
            }
            token[n] = '\0';
            int64_t value;
            if (!parse_integer(token, &value)) {
                fprintf(stderr, "%s: bad integer %s for %s\n", path, token, key);
                ok = false;
                break;
            }
            int fld = in_case ? field_of(key) : -1;
            if (fld >= 0) {
                row.value[fld] = value;
                row.seen |= 1u << fld;
            } else if (!in_case) {
                header_set(&header, key, value);
            }
            if (ch == ' ' || ch == '\n' || ch == '\r' || ch == '\t') {
                ch = next_nonspace(f);
            }
            continue;
        }
        if (ch == '}' && in_case && row.seen != 0u) {
            if (row.seen != (1u << FIELD_COUNT) - 1u) {
                fprintf(stderr, "%s: a row lacks a member\n", path);
                ok = false;
                break;
            }
            replay_row(&r, &row);
            row.seen = 0u;
        }
        ch = next_nonspace(f);
    }
    if (ferror(f)) {
        fprintf(stderr, "%s: read error\n", path);
        ok = false;
    }
    fclose(f);
    if (ok && !in_case) {
        fprintf(stderr, "%s: no case\n", path);
        ok = false;
    }
    if (ok) {
        replay_end(&r);
    }
    return ok && total_steps > 0;
}

/* Replay one case CSV (header line CSV_COLUMNS); false when the file cannot be read. */
static bool check_csv(const char *path, const struct odom_constants *consts)
{
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        fprintf(stderr, "%s: %s\n", path, strerror(errno));
        return false;
    }
    static struct replay r;
    replay_start(&r, path, consts);
    const char *base = strrchr(path, '/');
    snprintf(r.case_name, sizeof r.case_name, "%s", base == NULL ? path : base + 1);
    static char line[1024];
    bool ok = fgets(line, sizeof line, f) != NULL
              && strcmp(line, "step,left_count,right_count,x_q40_m,y_q40_m,heading_bam64,"
                              "heading_turns,distance_q40_m\n")
                     == 0;
    if (!ok) {
        fprintf(stderr, "%s: not a vector CSV (header)\n", path);
    }
    while (ok && fgets(line, sizeof line, f) != NULL) {
        struct row row;
        char *cursor = line;
        line[strcspn(line, "\r\n")] = '\0';
        for (int fld = 0; ok && fld < FIELD_COUNT; ++fld) {
            char *field_text = cursor;
            size_t len = strcspn(cursor, ",");
            bool last = cursor[len] == '\0';
            cursor[len] = '\0';
            cursor += len + (last ? 0u : 1u);
            ok = parse_integer(field_text, &row.value[fld]) && (last == (fld == FIELD_COUNT - 1));
        }
        if (!ok) {
            fprintf(stderr, "%s: bad row after step %" PRId64 "\n", path, r.steps);
            break;
        }
        replay_row(&r, &row);
    }
    fclose(f);
    if (ok) {
        replay_end(&r);
    }
    return ok && r.steps > 0;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: vectors_check DIR/vectors.json [DIR/case.csv ...]\n");
        return 2;
    }
    /* the CSVs use the constants derived from the JSON file's parameters (checked there) */
    struct odom_constants consts;
    if (!check_json(argv[1], &consts)) {
        return 2;
    }
    int64_t json_steps = total_steps;
    for (int i = 2; i < argc; ++i) {
        if (!check_csv(argv[i], &consts)) {
            return 2;
        }
    }
    printf("vectors_check: %" PRId64 " steps from JSON, %" PRId64 " from CSV, %" PRId64
           " mismatches\n",
           json_steps, total_steps - json_steps, total_mismatches);
    return total_mismatches == 0 && total_steps > 0 ? 0 : 1;
}
