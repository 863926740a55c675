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

#include <raypack.h>

/* Rays of a set are stored by 32x32 pixel blocks (one chunk of work), 4x4 tiles inside a block and
 * pixels in raster order inside a tile, so 16 consecutive slots are a 4x4 tile, 8 a 4x2 and 4 a row
 * of a tile. Slots outside the image or without a ray (a primary miss) are not valid. */
#define BENCH_TILE 4
#define BENCH_BLOCK 32
#define BENCH_CHUNK (BENCH_BLOCK * BENCH_BLOCK)

typedef struct bench_opts {
    const char *scene_path;  /* NULL: the generated sphere field */
    const char *json_path;   /* NULL: no JSON */
    bool vs_embree;
    int threads;             /* >= 1 */
    int repeats;             /* timed repeats per mode */
    int warmup;              /* untimed passes per mode before timing */
    int width, height;
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
    BENCH_KIND_COUNT = 4
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
    bool coherent;           /* primary and shadow rays: packets get the coherent hints */
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

/* Everything a run needs once the scene is loaded. */
typedef struct bench_ctx {
    bench_opts opts;
    const char *scene_name;
    bench_mesh mesh;
    bench_camera camera;
    float light[3];
    bool have_camera, have_light; /* the file brought them */
    rp_device *device;
    rp_scene *scene;         /* raypack's committed scene */
    bench_rays sets[BENCH_KIND_COUNT];
    bench_hits ref[BENCH_KIND_COUNT]; /* raypack's single-ray hits */
    bench_scratch scratch;
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

/* raypack's query modes for a set (single, packet4/8/16, array with each hint); returns the count. */
int bench_raypack_modes(rp_scene *scene, bool occlusion, bench_mode *modes, int max);
/* Builds raypack's scene over ctx->mesh on ctx->device; NULL (after a message) on error. */
rp_scene *bench_build_raypack(bench_ctx *ctx, double *wall_ms, rp_scene_stats *stats);
/* Generates the ray sets and raypack's single-ray reference hits (needs ctx->scene). */
bool bench_make_ray_sets(bench_ctx *ctx);
/* Prints the scene, camera, light and device lines. */
void bench_print_header(const bench_ctx *ctx);

#if defined(RP_HAVE_EMBREE)
/* `raypack bench --vs embree`: both engines on the same rays; returns the exit code. */
int bench_vs_embree(bench_ctx *ctx);
#endif

#endif /* RP_CLI_BENCH_H */
