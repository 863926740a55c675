/* The `raypack` command: subcommands and the helpers they share. */
#ifndef RP_CLI_H
#define RP_CLI_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include <raypack.h>
#include <raypack_io.h>
#include <raypack_render.h>

/* Exit statuses: success, a load/render/write failure, a usage error. */
enum { CLI_EXIT_OK = 0, CLI_EXIT_FAILURE = 1, CLI_EXIT_USAGE = 2 };
/* Most indices --lights takes. */
#define CLI_MAX_LIGHTS 256

/* Subcommands: argv[0] is the subcommand's name ("render", "info", "bench"). */
int cli_render(int argc, char **argv);
/* `raypack render --mpi` under mpirun (apps/mpi, built when MPI is found). */
int cli_render_mpi(int argc, char **argv);
/* Prints what a scene holds and what its acceleration structure looks like. */
int cli_info(int argc, char **argv);
/* Benchmarks (apps/cli/bench*.c). */
int cli_bench(int argc, char **argv);

/* The stream engine (apps/cli/stream_cli.c): render --engine stream, bench --stream. */
int cli_stream_render(int argc, char **argv);
/* `raypack render --engine cuda` (cuda_cli.c; without CUDA it says so and returns 2). */
int cli_cuda_render(int argc, char **argv);
int cli_stream_bench(int argc, char **argv);
/* True when argv holds flag (followed by value, unless value is NULL). */
bool cli_stream_wanted(int argc, char **argv, const char *flag, const char *value);
/* Monotonic wall clock in milliseconds. */
double cli_now_ms(void);
/* malloc's heap from here on grows by `reserve` bytes of address space at once, advised onto
 * 2 MiB pages (apps/cli/heap.c; RAYPACK_HUGE_HEAP=0 turns it off). True when the advice took. */
bool cli_heap_hugepages(size_t reserve);
/* CPU time of the whole process (all its threads) in milliseconds: what a frame costs whatever
 * else the machine runs. */
double cli_cpu_ms(void);
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
/* Parses an --accel value: bvh, kdtree, bih or grid (rp_accel_type); prints an error and returns false
 * on anything else. */
bool cli_parse_accel(const char *cmd, const char *flag, const char *text, rp_accel_type *out);
/* The volume flags of `raypack render` (view and render --mpi too): --density-scale, --albedo,
 * --hg-g, --medium-box and --vdb-grid. */
typedef struct cli_medium_opts {
    rp_medium_desc medium;   /* rp_medium_desc's zeros: the defaults */
    const char *vdb_grid;    /* --vdb-grid; NULL: density, else the first float grid */
    bool has_box;            /* --medium-box: a homogeneous medium in box (lo xyz, hi xyz) */
    float box[6];
    const char *volume;      /* --volume FILE.vdb: its volume added to the scene's surfaces */
    bool has_fit;            /* --volume-fit: the volume scaled (uniformly) and moved into fit */
    float fit[6];
} cli_medium_opts;
/* True when flag a is one of them (each takes a value). */
bool cli_is_medium_flag(const char *a);
/* Parses flag a's value v into m; false after printing why. */
bool cli_parse_medium_flag(const char *cmd, const char *a, const char *v, cli_medium_opts *m);
/* Applies --volume, --volume-fit and --medium-box to loaded data (the scene's own volume, if any,
 * replaced); false with the reason in err. */
bool cli_apply_medium(const cli_medium_opts *m, rp_scene_data *data, char *err, size_t err_size);
/* The name of an rp_device_desc.isa code ("avx512", ...). */
const char *cli_isa_name(int isa);
/* Returns the value following flag argv[*i], advancing *i, or NULL after printing an error. */
const char *cli_flag_value(const char *cmd, int argc, char **argv, int *i);
/* Writes `"traversal": {"auto": n, ..., "simd": n}`, the packets of c per traversal algorithm. */
void cli_json_traversal(FILE *f, const rp_counters_n *c);
/* What `raypack render`'s flags say about the scene, the camera and the rendering, for commands that
 * render as it does (`raypack view`): the same flags give the same pixels. */
typedef struct cli_render_setup {
    const char *scene;          /* NULL: the built-in room */
    int width, height;          /* 0: from the scene (cli_render_size) */
    int spp, threads, isa;      /* spp 0: not given */
    rp_render_desc desc;        /* integrator, depth, packets, traversal, frusta; no size or camera */
    rp_render_scene_desc scene_desc; /* --accel, --env, --env-scale */
    const char *integrator_name, *traversal_name;
    bool has_eye, has_look, has_up, has_fov;
    float eye[3], look[3], up[3], fov;
    bool has_anim_time;         /* --anim-time */
    float anim_time;
    float point_radius;         /* --point-radius; 0: automatic */
    cli_medium_opts vol;        /* --vdb-grid, --medium-box, --volume, --volume-fit (and the medium) */
    uint32_t lights[CLI_MAX_LIGHTS]; /* --lights */
    int light_count;            /* -1: all */
    const char *output;         /* -o (default raypack.png), checked writable */
    float exposure;             /* --exposure, for 8-bit outputs */
    rp_tonemap tonemap;         /* --tonemap, for 8-bit outputs */
    bool quiet;                 /* -q */
} cli_render_setup;
/* Parses argv (argv[0] the command's name) as `raypack render` does, into out; sets *help for -h.
 * Returns CLI_EXIT_OK, or the exit status after printing why. */
int cli_render_parse(int argc, char **argv, cli_render_setup *out, bool *help);
/* Loads the scene of the setup (the built-in room when it has none); prints why on failure. */
bool cli_render_load(const char *cmd, const cli_render_setup *setup, rp_scene_data *data);
/* Applies the setup's --lights and --anim-time to loaded data; prints why and returns the exit
 * status when they do not fit the scene. */
int cli_render_scene_flags(const char *cmd, const cli_render_setup *setup, rp_scene_data *data);
/* Parses "a,b,c" (non-negative integers) into out (at most max); the count, or -1 after an error. */
int cli_parse_list(const char *cmd, const char *flag, const char *text, uint32_t *out, int max);
/* `raypack animate` (apps/cli/animate.c). */
int cli_animate(int argc, char **argv);
/* Frees what cli_render_load loaded. */
void cli_render_unload(const cli_render_setup *setup, rp_scene_data *data);
/* The scene's camera with the setup's --eye/--look/--up/--fov in place of its parts. */
rp_camera cli_render_camera(const cli_render_setup *setup, rp_render_scene *scene);
/* The image size: --width/--height, the other from the scene's aspect, else the scene's, else 512. */
void cli_render_size(const cli_render_setup *setup, const rp_scene_data *data, int *w, int *h);

/* True when a and b name one file: the same (st_dev, st_ino) when both exist, else the same folder
 * (after resolving links) and name. */
bool cli_same_file(const char *a, const char *b);
/* A file a command reads (input) or writes, and the flag that named it ("SCENE", "-o", ...). */
typedef struct cli_path {
    const char *flag;
    const char *path; /* NULL: not given */
    bool input;
} cli_path;
/* Usage check before any work: no output may be an input or another output; prints which flags
 * collide and returns false. */
bool cli_check_paths(const char *cmd, const cli_path *paths, int count);
/* True when the scene file exists, is no folder and may be read; else prints why (errno's text). Never
 * opens it (a FIFO is read once, by the loader). */
bool cli_scene_readable(const char *cmd, const char *path);
/* rp_scene_load_desc.warning for the commands: the loader's warning, a line on stderr. */
void cli_load_warning(void *user, const char *message);
/* Whether the scene has an alpha-tested material (map_d, glTF alphaMode). */
bool cli_has_cutouts(const rp_scene_data *data);
/* An output path that can be written (not a folder, its folder there and writable), checked before
 * the work so that a typo does not cost a whole render or benchmark; false after printing why. */
bool cli_output_writable(const char *cmd, const char *path);
/* Why a pinhole camera cannot be formed from eye, look-at point and up (DESIGN.md's frame): NaN/Inf,
 * eye == look, a zero up or one parallel to the view; NULL when it can. */
const char *cli_camera_problem(const float eye[3], const float look[3], const float up[3]);
/* The camera flags alone (NULL: not given): eye and look that no up can frame, eye, look and up that
 * make no frame, a zero up. Prints why; CLI_EXIT_USAGE, else CLI_EXIT_OK. */
int cli_camera_flags_check(const char *cmd, const float *eye, const float *look, const float *up);
/* A pinhole camera that cannot be formed (cli_camera_problem): prints why, naming the flags that made
 * it (CLI_EXIT_USAGE) or the scene's camera (CLI_EXIT_FAILURE); CLI_EXIT_OK when it can. */
int cli_camera_check(const char *cmd, const char *path, const float eye[3], const float look[3], const float up[3],
                     bool has_eye, bool has_look, bool has_up);
/* The float shading and intersection tests multiply coordinates relative to the eye (a normal is
 * the product of two edges, its squared length of four; the watertight test's t of three): a scene
 * 1e11 across rendered black (unit normals overflowed), 4e12 across with NaN pixels (hits lost),
 * with exit 0. Largest distance along an axis between two points of the scene, or one and the eye: */
#define CLI_MAX_REACH 1e9
/* False, after printing the error naming path, when the scene (its bounds) and the camera's eye
 * span more than CLI_MAX_REACH. */
bool cli_scene_in_reach(const char *cmd, const char *path, rp_render_scene *scene, const rp_camera *cam);
/* The same for a core scene and an eye (bench). */
bool cli_core_in_reach(const char *cmd, const char *path, rp_scene *scene, const float eye[3]);
/* Largest thread count accepted by --threads. */
#define CLI_MAX_THREADS 1024

/* `raypack bench --render`: frame times of the integrators (bench_render.c); argv[0] is "--render". */
int cli_bench_render(int argc, char **argv);

#endif
