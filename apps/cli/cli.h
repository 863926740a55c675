/* The `raypack` command: subcommands and the helpers they share. */
#ifndef RP_CLI_H
#define RP_CLI_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include <raypack.h>

/* Exit statuses: success, a load/render/write failure, a usage error. */
enum { CLI_EXIT_OK = 0, CLI_EXIT_FAILURE = 1, CLI_EXIT_USAGE = 2 };

/* Subcommands: argv[0] is the subcommand's name ("render", "info", "bench"). */
int cli_render(int argc, char **argv);
/* Prints what a scene holds and what its acceleration structure looks like. */
int cli_info(int argc, char **argv);
/* Benchmarks (apps/cli/bench*.c). */
int cli_bench(int argc, char **argv);

/* The stream engine (apps/cli/stream_cli.c): render --engine stream, bench --stream. */
int cli_stream_render(int argc, char **argv);
int cli_stream_bench(int argc, char **argv);
/* True when argv holds flag (followed by value, unless value is NULL). */
bool cli_stream_wanted(int argc, char **argv, const char *flag, const char *value);
/* Monotonic wall clock in milliseconds. */
double cli_now_ms(void);
/* Parses an integer flag value in [lo, hi]; prints "raypack CMD: FLAG expects ..." and returns false
 * on a bad value. */
bool cli_parse_int(const char *cmd, const char *flag, const char *text, long lo, long hi, int *out);
/* Parses a float flag value in (lo, hi) (open bounds when open is true, else closed). */
bool cli_parse_float(const char *cmd, const char *flag, const char *text, double lo, double hi, bool open,
                     float *out);
/* Parses "x,y,z" into three finite floats. */
bool cli_parse_vec3(const char *cmd, const char *flag, const char *text, float out[3]);
/* Parses an --isa value: auto (0), scalar (1), sse (4), avx2 (8) or avx512 (16), the
 * rp_device_desc.isa codes; prints an error and returns false on anything else. */
bool cli_parse_isa(const char *cmd, const char *flag, const char *text, int *out);
/* Creates the device for --threads and --isa; prints why on failure (an ISA the CPU lacks). */
rp_device *cli_device_new(const char *cmd, int threads, int isa);
/* The name of an rp_device_desc.isa code ("avx512", ...). */
const char *cli_isa_name(int isa);
/* Returns the value following flag argv[*i], advancing *i, or NULL after printing an error. */
const char *cli_flag_value(const char *cmd, int argc, char **argv, int *i);
/* Writes `"traversal": {"auto": n, ..., "simd": n}`, the packets of c per traversal algorithm. */
void cli_json_traversal(FILE *f, const rp_counters_n *c);
/* Largest thread count accepted by --threads. */
#define CLI_MAX_THREADS 1024

#endif
