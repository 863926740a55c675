/* Helpers shared by the subcommands: flag values, numbers, clock. */
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

double cli_now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

const char *cli_flag_value(const char *cmd, int argc, char **argv, int *i) {
    if (*i + 1 >= argc) {
        fprintf(stderr, "raypack %s: %s expects a value\n", cmd, argv[*i]);
        return NULL;
    }
    *i += 1;
    return argv[*i];
}

bool cli_parse_int(const char *cmd, const char *flag, const char *text, long lo, long hi, int *out) {
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (end == text || *end != '\0' || errno == ERANGE || v < lo || v > hi) {
        fprintf(stderr, "raypack %s: %s expects an integer in [%ld, %ld], got '%s'\n", cmd, flag, lo, hi, text);
        return false;
    }
    *out = (int)v;
    return true;
}

bool cli_parse_float(const char *cmd, const char *flag, const char *text, double lo, double hi, bool open,
                     float *out) {
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    bool in = open ? (v > lo && v < hi) : (v >= lo && v <= hi);
    if (end == text || *end != '\0' || errno == ERANGE || !isfinite(v) || !in) {
        fprintf(stderr, "raypack %s: %s expects a number in %c%g, %g%c, got '%s'\n", cmd, flag, open ? '(' : '[',
                lo, hi, open ? ')' : ']', text);
        return false;
    }
    *out = (float)v;
    return true;
}

bool cli_parse_vec3(const char *cmd, const char *flag, const char *text, float out[3]) {
    const char *p = text;
    for (int k = 0; k < 3; k++) {
        char *end;
        errno = 0;
        double v = strtod(p, &end);
        if (end == p || errno == ERANGE || !isfinite(v) || fabs(v) > 1e30 || *end != (k < 2 ? ',' : '\0')) {
            fprintf(stderr, "raypack %s: %s expects three numbers x,y,z, got '%s'\n", cmd, flag, text);
            return false;
        }
        out[k] = (float)v;
        p = end + 1;
    }
    return true;
}

static const struct {
    const char *name;
    int code;
} isa_names[] = {{"auto", 0}, {"scalar", 1}, {"sse", 4}, {"avx2", 8}, {"avx512", 16}};

bool cli_parse_isa(const char *cmd, const char *flag, const char *text, int *out) {
    for (size_t i = 0; i < sizeof isa_names / sizeof isa_names[0]; i++)
        if (strcmp(text, isa_names[i].name) == 0) {
            *out = isa_names[i].code;
            return true;
        }
    fprintf(stderr, "raypack %s: %s expects auto, scalar, sse, avx2 or avx512, got '%s'\n", cmd, flag, text);
    return false;
}

bool cli_parse_accel(const char *cmd, const char *flag, const char *text, rp_accel_type *out) {
    for (int k = 0; k < RP_ACCEL_COUNT; k++)
        if (strcmp(text, rp_accel_name((rp_accel_type)k)) == 0) {
            *out = (rp_accel_type)k;
            return true;
        }
    fprintf(stderr, "raypack %s: %s expects bvh, kdtree or bih, got '%s'\n", cmd, flag, text);
    return false;
}

const char *cli_isa_name(int isa) {
    for (size_t i = 0; i < sizeof isa_names / sizeof isa_names[0]; i++)
        if (isa_names[i].code == isa) return isa_names[i].name;
    return "?";
}

rp_device *cli_device_new(const char *cmd, int threads, int isa) {
    rp_device *d = rp_device_new(&(rp_device_desc){.threads = threads, .isa = isa});
    if (d) return d;
    rp_device *best = isa ? rp_device_new(&(rp_device_desc){.threads = 1}) : NULL;
    if (best && rp_device_isa(best) < isa)
        fprintf(stderr, "raypack %s: --isa %s: this CPU has up to %s\n", cmd, cli_isa_name(isa),
                cli_isa_name(rp_device_isa(best)));
    else
        fprintf(stderr, "raypack %s: cannot create the device\n", cmd);
    rp_device_release(best);
    return NULL;
}

void cli_json_traversal(FILE *f, const rp_counters_n *c) {
    static const char *const names[] = {"auto", "masked", "ranged", "partition", "span", "simd", "mlrt"};
    fputs("\"traversal\": {", f);
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        fprintf(f, "%s\"%s\": %llu", i ? ", " : "", names[i], (unsigned long long)c->traversal[i]);
    fputc('}', f);
}
