/* Internals shared by the parts of `raypack bench`: options, the triangle mesh both engines trace,
 * ray sets laid out in 4x4 screen tiles, the timing loop and the hit comparison.
 *
 * Ownership: a bench_mesh, bench_rays and bench_hits own their arrays (freed by their _free).
 */
#ifndef RP_CLI_BENCH_H
#define RP_CLI_BENCH_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

#include <raypack.h>

/* Rays of a set are stored by 32x32 pixel blocks (one chunk of work), in Morton (Z) order inside a
 * block (bench_block_slot), so every aligned square is a run of slots: 4 consecutive slots are a
 * 2x2 quad, 8 a 4x2, 16 a 4x4 tile (Embree's 16-ray packets), 64 to 1024 the 8x8 to 32x32 packets
 * of raypack's large-packet modes, which read their rays in order. (Tiles in raster order made the
 * 16x16 packets read 2 KB runs 2 KB apart, and with a scalar copy their copy into the packet took
 * 3x as long as Embree's into rtcIntersect16's packets; kitchen's primary rays, 1 thread, the copies
 * alone: 125 against 370-400 Mrays/s, now 410-440.) Slots outside the image or without a ray (a
 * primary miss) are not valid. */
#define BENCH_BLOCK 32
#define BENCH_CHUNK (BENCH_BLOCK * BENCH_BLOCK)

typedef struct bench_opts {
    const char *scene_path;  /* NULL: the generated sphere field */
    const char *json_path;   /* NULL: no JSON */
    bool vs_embree;
    bool cuda;               /* --engine cuda: the GPU kernels on the same sets (bench_cuda.c) */
    bool grid;               /* --grid: the experiment grid of Overbeck et al. 2008, sec. 5 */
    bool accel_grid;         /* --accel-grid: every acceleration structure on the same rays */
    bool builds;             /* --builds: build times alone, every structure in turns */
    rp_accel_type accel;     /* --accel: the structure raypack's scene is built with */
    float grid_density;      /* --density: the grid's voxels per triangle (0: the default) */
    bool repeats_set;        /* --repeats was given (the grid's default differs) */
    int threads;             /* >= 1 */
    int isa;                 /* --isa: rp_device_desc.isa, 0 auto (sys_cpu_simd_auto) */
    int repeats;             /* timed repeats per mode */
    int warmup;              /* untimed passes per mode before timing */
    int width, height;
    double bad_rays;         /* --bad-rays: fraction of each set made NaN/Inf/degenerate, 0: off */
    bool has_eye, has_look, has_up, has_fov;
    float eye[3], look[3], up[3];
    float fov_deg;
} bench_opts;

/* The triangles both engines trace: one geometry, the loader's order, minus triangles with
 * non-finite vertices or bad indices (raypack rejects those; Embree is fed the same list). */
typedef struct bench_mesh {
    size_t vertex_count;
    float *positions;        /* 3 * vertex_count + 1 floats: Embree reads the last vertex as 16 bytes */
    size_t triangle_count;
    uint32_t *indices;       /* 3 * triangle_count */
    size_t dropped;          /* triangles left out (NaN/Inf or indices out of range) */
    size_t degenerate;       /* zero-area triangles kept */
    float lower[3], upper[3];
} bench_mesh;

typedef struct bench_camera {
    float eye[3], look[3], up[3];
    float fov_deg;
} bench_camera;

typedef enum bench_kind {
    BENCH_PRIMARY = 0,
    BENCH_SHADOW = 1,
    BENCH_REFLECTION = 2,
    BENCH_DIFFUSE = 3,
    BENCH_BOUNCE1 = 4,       /* the path tracer's bounce rays of depth 1 and 2 (bench_path.c) */
    BENCH_BOUNCE2 = 5,
    BENCH_KIND_COUNT = 6
} bench_kind;

/* One ray; the same numbers go into rp_ray and RTCRay. */
typedef struct bench_ray {
    float org[3];
    float tnear;
    float dir[3];
    float tfar;
} bench_ray;

typedef struct bench_rays {
    bench_kind kind;
    bool occlusion;          /* shadow rays: any hit */
    size_t slots;            /* a multiple of BENCH_CHUNK */
    size_t count;            /* valid slots */
    bench_ray *rays;         /* slots */
    int32_t *valid;          /* slots: -1 live, 0 not (passed straight to packet calls) */
} bench_rays;

/* Results of tracing a set: t is the hit distance (+inf on a miss; -inf for an occluded shadow
 * ray), prim the primitive (RP_INVALID_ID on a miss or for shadow rays). */
typedef struct bench_hits {
    float *t;
    uint32_t *prim;
} bench_hits;

/* While set, every mode does all its work but the engine's call: it copies the rays into the
 * engine's layout and writes the (missed) hits back. Timing that gives each mode's harness cost,
 * paid by the engine's Mrays/s as well (bench --vs embree prints it for both engines' best). */
extern bool bench_harness_only;
#define BENCH_TRACE(call)                                                                          \
    do {                                                                                           \
        if (!bench_harness_only) call;                                                             \
    } while (0)

/* Traces slots [first, first + n) of a set into out; `scratch` is the calling thread's buffer. */
typedef void (*bench_trace_fn)(void *engine, const bench_rays *set, size_t first, size_t n,
                               bench_hits *out, void *scratch);

/* A way of tracing a set with one engine (a raypack query mode or an Embree API). */
typedef struct bench_mode {
    const char *name;
    bench_trace_fn trace;
    void *engine;
} bench_mode;

/* Hits of one mode against the reference. */
typedef struct bench_diff {
    size_t hit_miss;         /* one hit (or was occluded), the other did not */
    size_t distance;         /* both hit, t differs by more than the tolerance (bench_compare) */
    size_t primitive;        /* both hit at the same t, different triangle, not a tie */
    size_t ties;             /* different triangles, each met by the ray at both distances (coplanar
                              * duplicates, shared edges): both closest hits, not counted in total */
    size_t total;
} bench_diff;

/* Median, min and max of a mode's timed repeats. */
typedef struct bench_stat {
    double median, min, max;
} bench_stat;

/* Per-thread scratch for the modes that need an array of rays (rp_intersect_array, rtcIntersect1M). */
typedef struct bench_scratch {
    void **per_thread;
    int threads;
} bench_scratch;

/* How a large-packet mode traces a set: n x n packets of screen tiles (n = 4, 8, 16 or 32 divides
 * BENCH_BLOCK, so a chunk is a whole number of packets), with one rp_query_n_desc. Packet p of a
 * chunk is its slots [p*n*n, (p+1)*n*n); every run of 16 entries of a packet (rp_packet_n_index
 * order) is one 4x4 tile, 16 consecutive slots in the same order, and the k-th 16 slots of the
 * chunk are entries tile_at[k] * 16 .. + 15 of their packet. */
typedef struct bench_n_engine {
    rp_scene *scene;
    uint32_t n;
    rp_query_n_desc desc;    /* counters: ignored (see count) */
    bool count;              /* add the work to the tracing thread's bench_scratch_counters */
    uint16_t tile_at[BENCH_CHUNK / 16];
} bench_n_engine;

/* Slot within its block of the block's pixel (lx, ly), 0 <= lx, ly < BENCH_BLOCK: the bits of lx
 * and ly interleaved, lx's lowest. */
static inline uint32_t bench_block_slot(uint32_t lx, uint32_t ly) {
    uint32_t s = 0;
    for (uint32_t b = 0; (1u << b) < BENCH_BLOCK; b++) s |= ((lx >> b) & 1u) << (2 * b) | ((ly >> b) & 1u) << (2 * b + 1);
    return s;
}

/* Inverse of bench_block_slot. */
static inline void bench_block_pixel(uint32_t slot, uint32_t *lx, uint32_t *ly) {
    *lx = *ly = 0;
    for (uint32_t b = 0; (1u << b) < BENCH_BLOCK; b++) {
        *lx |= ((slot >> (2 * b)) & 1u) << b;
        *ly |= ((slot >> (2 * b + 1)) & 1u) << b;
    }
}

/* Large-packet modes each set gets in bench_raypack_modes: 16x16 and 8x8 auto, 32x32 and 16x16
 * MLRT, frustum on. */
#define BENCH_N_MODES 4

/* How bench_make_next makes a ray from the hit of its parent. */
typedef enum bench_next {
    BENCH_NEXT_SHADOW = 0,   /* to the light, ending just before it; none when the light is behind */
    BENCH_NEXT_REFLECT = 1,  /* mirror reflection */
    BENCH_NEXT_REFRACT = 2,  /* refraction only, ior 1.5 (none on total internal reflection) */
    BENCH_NEXT_DIFFUSE = 3   /* cosine-distributed, random from (pixel, dimension) */
} bench_next;

/* Everything a run needs once the scene is loaded. */
typedef struct bench_ctx {
    bench_opts opts;
    const char *scene_name;
    bench_mesh mesh;
    bench_camera camera;
    float light[3];
    bool have_camera, have_light; /* the file brought them */
    double load_ms;          /* rp_scene_data_load_ex on --threads threads; 0 for the built-in scene */
    size_t load_bytes;       /* text parsed, after decompression */
    struct rp_scene_data *data;   /* the file's scene (materials for the path-traced sets), or NULL */
    rp_device *device;
    rp_scene *scene;         /* raypack's committed scene */
    double build_cpu_ms;     /* the last bench_build_raypack's commit: the process's CPU time (all threads) */
    bench_rays sets[BENCH_KIND_COUNT];
    bench_hits ref[BENCH_KIND_COUNT]; /* raypack's single-ray hits */
    bench_scratch scratch;
    bench_n_engine n_engines[BENCH_KIND_COUNT][BENCH_N_MODES]; /* of bench_raypack_modes */
} bench_ctx;

/* Name of a ray set kind ("primary", ...). */
const char *bench_kind_name(bench_kind kind);
/* Allocates hit arrays for a set's slots; false when out of memory. */
bool bench_hits_alloc(bench_hits *hits, size_t slots);
/* Frees hit arrays. */
void bench_hits_free(bench_hits *hits);
/* Traces a whole set with a mode on `threads` threads (1: the calling thread only); returns
 * seconds of wall time. Sets flush-to-zero and denormals-are-zero on every tracing thread. */
double bench_trace_set(bench_ctx *ctx, int threads, const bench_mode *mode, const bench_rays *set,
                       bench_hits *out);
/* Compares hits to the reference on every valid slot: t within 1e-4 relative (or 16 ulps of the
 * origin's magnitude), the same triangle unless the two triangles tie at that distance. */
bench_diff bench_compare(const bench_mesh *mesh, const bench_rays *set, const bench_hits *ref,
                         const bench_hits *hits);
/* Prints (stderr) up to max rays on which hits and the reference disagree, with both answers. */
void bench_print_mismatches(const bench_mesh *mesh, const bench_rays *set, const bench_hits *ref,
                            const bench_hits *hits, const char *ref_name, const char *name, int max);
/* Median, min and max of n samples (sorted in place). */
bench_stat bench_stats(double *samples, int n);
/* Milliseconds of a monotonic clock. */
double bench_now_ms(void);
/* Sets flush-to-zero and denormals-are-zero on the calling thread (Embree recommends them). */
void bench_set_ftz(void);
/* Writes a JSON string literal. */
void bench_json_string(FILE *f, const char *s);
struct rp_atomic_file;
/* --json: opens ctx's JSON output (a temporary file until bench_json_end renames it into place) and
 * writes `{"scene": NAME`; NULL, after a message, when it cannot. */
FILE *bench_json_begin(const bench_ctx *ctx, struct rp_atomic_file **af);
/* Commits what bench_json_begin opened; false, after a message, when the write failed. */
bool bench_json_end(struct rp_atomic_file *af);

/* raypack's query modes for a set of ctx (single, packet4/8/16, array with each hint, then 16x16
 * and 8x8 large packets with auto traversal and the set's frustum); returns the count. */
int bench_raypack_modes(bench_ctx *ctx, const bench_rays *set, bench_mode *modes, int max);
/* Fills a large-packet engine; frustum RP_FRUSTUM_SHADOW heads to `point` (may be NULL otherwise). */
void bench_n_engine_init(bench_n_engine *e, rp_scene *scene, uint32_t n, rp_traversal traversal,
                         rp_frustum_kind frustum, const float *point);
/* Trace functions of a bench_n_engine: rp_intersect_n and rp_occluded_n on whole chunks. */
void bench_trace_n_intersect(void *engine, const bench_rays *set, size_t first, size_t n,
                             bench_hits *out, void *scratch);
/* See bench_trace_n_intersect. */
void bench_trace_n_occluded(void *engine, const bench_rays *set, size_t first, size_t n,
                            bench_hits *out, void *scratch);
/* The counters kept in a thread's scratch buffer, where counted large-packet modes add their work. */
rp_counters_n *bench_scratch_counters(void *scratch);
/* Allocates an empty set of a kind covering the image in whole 32x32 blocks. */
bool bench_rays_alloc(bench_rays *set, bench_kind kind, int width, int height);
/* Frees a set. */
void bench_rays_free(bench_rays *set);
/* Fills out (allocated, empty) with the rays leaving the hits of parent: one per slot whose parent
 * ray hit a triangle, from the hit point offset along the normal to the side the ray leaves to. */
void bench_make_next(const bench_ctx *ctx, const bench_rays *parent, const bench_hits *parent_hits,
                     bench_rays *out, bench_next how);
/* Fills the bounce1 and bounce2 sets from a path-traced frame of ctx's scene (bench_path.c). */
bool bench_make_path_sets(bench_ctx *ctx);
/* Builds raypack's scene over ctx->mesh on ctx->device; NULL (after a message) on error. */
rp_scene *bench_build_raypack(bench_ctx *ctx, double *wall_ms, rp_scene_stats *stats);
/* Generates the ray sets and raypack's single-ray reference hits (needs ctx->scene). */
bool bench_make_ray_sets(bench_ctx *ctx);
/* Prints the scene, camera, light and device lines. */
void bench_print_header(const bench_ctx *ctx);

/* `raypack bench --accel-grid`: every structure on the same rays (bench_accel.c); returns the exit code. */
int bench_accel_grid(bench_ctx *ctx);
int bench_builds(bench_ctx *ctx);
/* `raypack bench --grid`: the paper's experiment grid (bench_grid.c); returns the exit code. */
int bench_grid(bench_ctx *ctx);

#if defined(RP_HAVE_CUDA)
/* `raypack bench --engine cuda`: the CUDA BVH kernels on the bench's sets (bench_cuda.c). */
int bench_vs_cuda(bench_ctx *ctx);
#endif

#if defined(RP_HAVE_EMBREE)
/* `raypack bench --vs embree`: both engines on the same rays; returns the exit code. */
int bench_vs_embree(bench_ctx *ctx);
#endif

/* Asks for the rays of slots [first, first + count) ahead of their use (nothing past the set).
 * The large-packet modes ask for the next packet's rays while they copy the current one in: a
 * large packet's traversal runs long enough between two copies for the hardware prefetchers to
 * lose the stream (kitchen's primary rays, 16x16 packets, 1 thread: 86.7 -> 98.4 Mrays/s, the next
 * packet's tile fetched with each tile copied; its valid flags too, timed against the rays alone:
 * primary 85.8 -> 101.5, shadow 109.5 -> 128.9). The 4- to 16-ray packet modes of both engines,
 * which copy 16 rays between two traversals, do not: it changed neither (rtcIntersect16 85.8 ->
 * 84.5, raypack's packet16 51.7 -> 51.3). */
static inline void bench_prefetch_rays(const bench_rays *set, size_t first, size_t count) {
    if (first + count > set->slots) return;
    const char *p = (const char *)(set->rays + first);
    for (size_t b = 0; b < count * sizeof(bench_ray); b += 64) __builtin_prefetch(p + b);
}

/* Copies count rays (a multiple of 4) into eight arrays, four at a time with SSE transposes where
 * the compiler has SSE: the compiler transposes the Embree modes' fixed-size copies on its own, but
 * kept this one scalar, and 8 scalar loads and stores a ray made the copy into a 16x16 packet take as
 * long as raypack's traversal of it (kitchen's primary rays, 1 thread). */
static inline void bench_rays_to_soa(const bench_ray *src, size_t count, float *ox, float *oy, float *oz,
                                     float *tn, float *dx, float *dy, float *dz, float *tf) {
#if defined(__SSE2__)
    for (size_t i = 0; i < count; i += 4) {
        const float *r = src[i].org;
        __m128 a0 = _mm_loadu_ps(r), a1 = _mm_loadu_ps(r + 8), a2 = _mm_loadu_ps(r + 16),
               a3 = _mm_loadu_ps(r + 24);
        __m128 b0 = _mm_loadu_ps(r + 4), b1 = _mm_loadu_ps(r + 12), b2 = _mm_loadu_ps(r + 20),
               b3 = _mm_loadu_ps(r + 28);
        _MM_TRANSPOSE4_PS(a0, a1, a2, a3);
        _MM_TRANSPOSE4_PS(b0, b1, b2, b3);
        _mm_storeu_ps(ox + i, a0), _mm_storeu_ps(oy + i, a1), _mm_storeu_ps(oz + i, a2), _mm_storeu_ps(tn + i, a3);
        _mm_storeu_ps(dx + i, b0), _mm_storeu_ps(dy + i, b1), _mm_storeu_ps(dz + i, b2), _mm_storeu_ps(tf + i, b3);
    }
#else
    for (size_t i = 0; i < count; i++) {
        const bench_ray *b = &src[i];
        ox[i] = b->org[0], oy[i] = b->org[1], oz[i] = b->org[2], tn[i] = b->tnear;
        dx[i] = b->dir[0], dy[i] = b->dir[1], dz[i] = b->dir[2], tf[i] = b->tfar;
    }
#endif
}

/* True when any lane of a packet is live: packets of misses are skipped, by both engines alike. */
static inline bool bench_any_valid(const int32_t *valid, int width) {
    int32_t any = 0;
    for (int k = 0; k < width; k++) any |= valid[k];
    return any != 0;
}

#endif /* RP_CLI_BENCH_H */
