/* raypack: a real-time ray tracing core.
 *
 * Shape follows Embree's API: a device owns threads and memory hooks; scenes hold geometries; a
 * scene is edited, then committed (which builds its acceleration structure), then queried. All
 * handles are opaque and reference counted (_new, _retain, _release).
 *
 * Ownership: buffers passed with rp_geometry_set_buffer stay owned by the caller and must outlive
 * every commit of every scene the geometry is attached to; rp_geometry_new_buffer returns memory
 * owned by the geometry, valid until the geometry is released or the buffer slot is replaced.
 *
 * Thread safety: queries on a committed scene may run concurrently from any number of threads.
 * Editing and committing a scene must not overlap with queries on it.
 */
#ifndef RAYPACK_H
#define RAYPACK_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(_WIN32)
#define RP_API __declspec(dllexport)
#else
#define RP_API __attribute__((visibility("default")))
#endif

#if defined(__cplusplus)
#define RP_ALIGN(n) alignas(n)
#else
#define RP_ALIGN(n) _Alignas(n)
#endif

#define RP_VERSION_MAJOR 0
#define RP_VERSION_MINOR 1
#define RP_VERSION_PATCH 0

/* The geom_id / prim_id of a ray that hit nothing. */
#define RP_INVALID_ID 0xFFFFFFFFu

/* Every error code and its message, in one table. */
#define RP_ERROR_LIST(X)                                                            \
    X(RP_ERROR_NONE, "no error")                                                   \
    X(RP_ERROR_UNKNOWN, "unknown error")                                           \
    X(RP_ERROR_INVALID_ARGUMENT, "invalid argument")                               \
    X(RP_ERROR_INVALID_OPERATION, "invalid operation")                             \
    X(RP_ERROR_OUT_OF_MEMORY, "out of memory")                                     \
    X(RP_ERROR_UNSUPPORTED_CPU, "the CPU lacks an instruction set raypack needs")  \
    X(RP_ERROR_NOT_COMMITTED, "the scene was edited and not committed since")      \
    X(RP_ERROR_INVALID_GEOMETRY, "a geometry lacks a buffer or its buffers disagree")

#define RP_ERROR_ENUM_(code, msg) code,
typedef enum rp_error { RP_ERROR_LIST(RP_ERROR_ENUM_) RP_ERROR_COUNT } rp_error;
#undef RP_ERROR_ENUM_

typedef struct rp_device rp_device;
typedef struct rp_scene rp_scene;
typedef struct rp_geometry rp_geometry;

/* ---- device ---------------------------------------------------------------------------------- */

/* Allocator hook, Lua style: new_size == 0 frees ptr (of old_size bytes) and returns NULL;
 * ptr == NULL allocates. Returned memory must be aligned to `align` (a power of two, <= 4096). */
typedef void *(*rp_alloc_fn)(void *user, void *ptr, size_t old_size, size_t new_size, size_t align);
/* Called on the thread where an API call failed, before the call returns. */
typedef void (*rp_error_fn)(void *user, rp_error code, const char *message);
typedef enum rp_log_level { RP_LOG_ERROR = 0, RP_LOG_WARNING = 1, RP_LOG_INFO = 2 } rp_log_level;
/* Receives the library's warnings (e.g. rejected primitives); the library prints nothing itself. */
typedef void (*rp_log_fn)(void *user, rp_log_level level, const char *message);

typedef struct rp_device_desc {
    int threads;            /* worker threads incl. the caller; 0: all hardware threads */
    rp_alloc_fn alloc;      /* NULL: aligned malloc/free */
    void *alloc_user;
    rp_error_fn error;      /* NULL: errors are only kept for rp_device_get_error */
    void *error_user;
    rp_log_fn log;          /* NULL: silent */
    void *log_user;
    int isa;                /* 0: auto (the widest the CPU has, but AVX2 on Intel CPUs that clock down under
                             * AVX-512: Skylake-SP to Ice Lake); 1: scalar, 4: SSE-width, 8: AVX2, 16: AVX-512 */
} rp_device_desc;

/* Fills in the defaults of every zero field of desc (NULL gives all defaults). */
RP_API rp_device_desc rp_device_desc_defaults(const rp_device_desc *desc);
/* Creates a device; NULL desc means all defaults. Returns NULL if out of memory. */
RP_API rp_device *rp_device_new(const rp_device_desc *desc);
/* Adds a reference. */
RP_API void rp_device_retain(rp_device *device);
/* Drops a reference; the last one joins the threads and frees the device. */
RP_API void rp_device_release(rp_device *device);
/* Returns the first error raised on the calling thread since the last call, and clears it. */
RP_API rp_error rp_device_get_error(rp_device *device);
/* Returns the message of an error code (a static string). */
RP_API const char *rp_error_string(rp_error code);
/* Number of threads the device runs work on, the caller included. */
RP_API int rp_device_thread_count(const rp_device *device);
/* SIMD width of the kernels the device picked: 1, 4, 8 or 16. */
RP_API int rp_device_isa(const rp_device *device);

/* Work item for rp_device_parallel_for: `thread` is in [0, rp_device_thread_count). */
typedef void (*rp_task_fn)(void *user, uint32_t index, uint32_t thread);
/* Runs fn(user, i, thread) for every i in [0, count) on the device's threads, the calling thread
 * included, handing out indices dynamically; returns when all are done. Not reentrant. */
RP_API void rp_device_parallel_for(rp_device *device, uint32_t count, rp_task_fn fn, void *user);

/* ---- geometry -------------------------------------------------------------------------------- */

typedef enum rp_geometry_type {
    RP_GEOMETRY_TRIANGLE = 0, /* vertex buffer (FLOAT3) + index buffer (UINT3) */
    RP_GEOMETRY_SPHERE = 1,   /* vertex buffer (FLOAT4: center xyz, radius) */
    RP_GEOMETRY_USER = 2,     /* bounds and intersect callbacks */
    RP_GEOMETRY_INSTANCE = 3  /* a committed scene placed by an affine transform (rp_geometry_set_instance) */
} rp_geometry_type;

/* Instances nest to this depth: a scene holding instances of scenes that hold instances ... of
 * scenes without any is RP_MAX_INSTANCE_DEPTH deep at most (a commit past it fails). */
#define RP_MAX_INSTANCE_DEPTH 4

typedef enum rp_buffer_type { RP_BUFFER_VERTEX = 0, RP_BUFFER_INDEX = 1 } rp_buffer_type;

typedef enum rp_format {
    RP_FORMAT_FLOAT3 = 0, /* 3 x float */
    RP_FORMAT_FLOAT4 = 1, /* 4 x float */
    RP_FORMAT_UINT3 = 2   /* 3 x uint32_t */
} rp_format;

/* Axis-aligned box. */
typedef struct rp_bounds {
    float lower_x, lower_y, lower_z, align0;
    float upper_x, upper_y, upper_z, align1;
} rp_bounds;

/* ---- rays and hits (Embree's field meanings) ------------------------------------------------- */

typedef struct rp_ray {
    RP_ALIGN(16) float org_x;
    float org_y, org_z;
    float tnear; /* start of the ray segment */
    float dir_x, dir_y, dir_z;
    float time;  /* unused for now, kept for layout compatibility */
    float tfar;  /* end of the segment; set to the hit distance by intersect, -inf by occluded */
    uint32_t mask; /* a geometry is skipped when (mask & geometry mask) == 0 */
    uint32_t id;
    uint32_t flags;
} rp_ray;

typedef struct rp_hit {
    RP_ALIGN(16) float Ng_x;
    float Ng_y, Ng_z; /* geometric normal, not normalized; faces the side (v1-v0)x(v2-v0) */
    float u, v;             /* barycentrics: p = (1-u-v) v0 + u v1 + v v2 */
    uint32_t prim_id;
    uint32_t geom_id;       /* RP_INVALID_ID when nothing was hit */
    uint32_t inst_id;       /* the outermost instance's geom_id, RP_INVALID_ID outside instances */
} rp_hit;

typedef struct rp_rayhit {
    rp_ray ray;
    rp_hit hit;
} rp_rayhit;

/* Packets: structures of arrays, one lane per ray. */
#define RP_DEFINE_PACKET_(W)                                                                     \
    typedef struct rp_ray##W {                                                      \
        RP_ALIGN(64) float org_x[W]; float org_y[W]; float org_z[W]; float tnear[W];             \
        float dir_x[W]; float dir_y[W]; float dir_z[W]; float time[W]; float tfar[W];            \
        uint32_t mask[W]; uint32_t id[W]; uint32_t flags[W];                                     \
    } rp_ray##W;                                                                                 \
    typedef struct rp_hit##W {                                                      \
        RP_ALIGN(64) float Ng_x[W]; float Ng_y[W]; float Ng_z[W]; float u[W]; float v[W];        \
        uint32_t prim_id[W]; uint32_t geom_id[W]; uint32_t inst_id[W];                           \
    } rp_hit##W;                                                                                 \
    typedef struct rp_rayhit##W {                                                   \
        rp_ray##W ray;                                                                           \
        rp_hit##W hit;                                                                           \
    } rp_rayhit##W;
RP_DEFINE_PACKET_(4)
RP_DEFINE_PACKET_(8)
RP_DEFINE_PACKET_(16)
#undef RP_DEFINE_PACKET_

/* User geometry callbacks. bounds writes the box of primitive prim. intersect tests one ray against
 * primitive prim; on a hit with ray->tnear <= t < ray->tfar it sets ray->tfar = t and fills hit
 * (geom_id and prim_id are filled in by raypack) and returns true. occluded returns true on any hit
 * in [tnear, tfar). They may be called concurrently from several threads. */
typedef void (*rp_user_bounds_fn)(void *user, uint32_t prim, rp_bounds *out);
typedef bool (*rp_user_intersect_fn)(void *user, uint32_t prim, rp_ray *ray, rp_hit *hit);
typedef bool (*rp_user_occluded_fn)(void *user, uint32_t prim, const rp_ray *ray);

/* Creates a geometry of the given type; NULL on a bad type or out of memory. */
RP_API rp_geometry *rp_geometry_new(rp_device *device, rp_geometry_type type);
/* Adds a reference. */
RP_API void rp_geometry_retain(rp_geometry *geometry);
/* Drops a reference. */
RP_API void rp_geometry_release(rp_geometry *geometry);
/* Shares a caller-owned buffer: `count` items of `format`, the first at data + byte_offset, each
 * byte_stride apart (0: tightly packed). The caller keeps it alive and unchanged while in use. */
RP_API void rp_geometry_set_buffer(rp_geometry *geometry, rp_buffer_type type, rp_format format,
                                   const void *data, size_t byte_offset, size_t byte_stride,
                                   size_t count);
/* Allocates a geometry-owned buffer of `count` items, byte_stride apart (0: packed), 16-byte
 * aligned and padded, and returns it for the caller to fill; NULL on error. */
RP_API void *rp_geometry_new_buffer(rp_geometry *geometry, rp_buffer_type type, rp_format format,
                                    size_t byte_stride, size_t count);
/* Sets the callbacks and primitive count of a RP_GEOMETRY_USER geometry. */
RP_API void rp_geometry_set_user(rp_geometry *geometry, uint32_t prim_count, rp_user_bounds_fn bounds,
                                 rp_user_intersect_fn intersect, rp_user_occluded_fn occluded,
                                 void *user);
/* Places a committed scene (retained) in an RP_GEOMETRY_INSTANCE geometry: xfm is the row-major
 * 3x4 affine map from the scene's space to its parent's (x' = xfm[0..2] . x + xfm[3], ...), which
 * must be invertible. Rays are mapped into the scene's space (their t unchanged); a hit reports
 * the instanced scene's geom_id and prim_id, the normal mapped back (inverse transpose) and
 * inst_id the geom_id of the outermost instance. Re-commit the parent when the scene changes. */
RP_API void rp_geometry_set_instance(rp_geometry *geometry, rp_scene *scene, const float xfm[12]);
/* Sets the visibility mask tested against ray.mask (default 0xFFFFFFFF). */
RP_API void rp_geometry_set_mask(rp_geometry *geometry, uint32_t mask);
/* Says that the contents of a buffer changed in place (same count). Moved vertices of triangle
 * geometries let the next rp_scene_commit refit the BVH instead of rebuilding it (see
 * rp_scene_desc.refit_max_growth); a changed index buffer makes it rebuild. */
RP_API void rp_geometry_update(rp_geometry *geometry, rp_buffer_type type);
/* Marks the geometry's buffers as final; scenes holding it must be committed again. */
RP_API void rp_geometry_commit(rp_geometry *geometry);

/* ---- scene ----------------------------------------------------------------------------------- */

typedef enum rp_build_quality {
    RP_BUILD_QUALITY_MEDIUM = 0, /* binned SAH, 16 bins (32 in nodes of over 256 primitives) */
    RP_BUILD_QUALITY_LOW = 1,    /* binned SAH, 8 bins (16 in large nodes), larger leaves */
    RP_BUILD_QUALITY_HIGH = 2    /* binned SAH, 64 bins */
} rp_build_quality;

/* The acceleration structure a scene's triangles are committed into; every kind answers every
 * query with the same hits. Spheres and user primitives always go into a BVH of their own. */
typedef enum rp_accel_type {
    RP_ACCEL_BVH = 0,    /* binned SAH BVH, wide traversal layout (the default) */
    RP_ACCEL_KDTREE = 1, /* SAH kd-tree, O(n log n) sweep build (Wald, Havran 2006) */
    RP_ACCEL_BIH = 2,    /* bounding interval hierarchy (Waechter, Keller 2006) */
    RP_ACCEL_GRID = 3    /* uniform grid, 3D-DDA with mailboxing (Cleary, Wyvill 1988; Amanatides, Woo 1987) */
} rp_accel_type;
#define RP_ACCEL_COUNT 4

typedef struct rp_scene_desc {
    rp_build_quality quality;
    int bvh_width;      /* children per node of the traversal layout: 0 picks for the ISA, else 4, 8 or 16 */
    int max_leaf_size;  /* most primitives per leaf, 1..60 (0: 32); the SAH ends leaves below it */
    rp_accel_type accel; /* 0: RP_ACCEL_BVH */
    float refit_max_growth; /* a commit after only vertices moved refits the BVH, unless its SAH cost
                               grows past this times the last build's (then it rebuilds); 0: 1.5,
                               < 0: always rebuild */
    float grid_density; /* RP_ACCEL_GRID: about this many voxels per triangle (Cleary-Wyvill), at most
                           1000; 0: the default */
} rp_scene_desc;

/* Measurements of the last commit. */
typedef struct rp_scene_stats {
    uint64_t triangles;        /* valid triangles in the acceleration structure */
    uint64_t spheres;
    uint64_t user_prims;
    uint64_t rejected_prims;   /* primitives with NaN/Inf coordinates or bad indices, never traced */
    uint64_t binary_nodes;     /* nodes of the canonical binary BVH, leaves included */
    uint64_t wide_nodes;       /* inner nodes of the traversal layout */
    uint64_t leaves;
    uint32_t depth;            /* of the binary BVH */
    uint32_t bvh_width;        /* of the traversal layout */
    double sah_cost;           /* of the binary BVH: traversal 1, intersection 1, relative to root */
    double build_ms;           /* wall time of the last commit */
    size_t bytes;              /* memory held by the acceleration structures */
    uint64_t degenerate_prims; /* triangles with two equal vertices: never hit, left out */
    rp_accel_type accel;       /* the structure of the triangles (binary_nodes .. sah_cost describe it) */
    uint64_t tri_refs;         /* triangle references in its leaves (a kd-tree holds straddlers twice) */
    uint32_t refit;            /* 1 when the last commit refitted the BVH rather than rebuilding it */
} rp_scene_stats;

/* Returns the defaults for every zero field of desc. */
RP_API rp_scene_desc rp_scene_desc_defaults(const rp_scene_desc *desc);
/* Creates an empty scene on a device. */
RP_API rp_scene *rp_scene_new(rp_device *device, const rp_scene_desc *desc);
/* Adds a reference. */
RP_API void rp_scene_retain(rp_scene *scene);
/* Drops a reference; the last one releases the scene's geometries. */
RP_API void rp_scene_release(rp_scene *scene);
/* Attaches a geometry (retaining it) and returns its geom_id, or RP_INVALID_ID on error. */
RP_API uint32_t rp_scene_attach(rp_scene *scene, rp_geometry *geometry);
/* Detaches and releases the geometry with this id. */
RP_API void rp_scene_detach(rp_scene *scene, uint32_t geom_id);
/* Returns the geometry with this id (not retained), or NULL. */
RP_API rp_geometry *rp_scene_get_geometry(rp_scene *scene, uint32_t geom_id);
/* Builds the acceleration structures on the device's threads; returns the error, if any. */
RP_API rp_error rp_scene_commit(rp_scene *scene);
/* Bounds of the committed scene (empty box if nothing valid). */
RP_API void rp_scene_get_bounds(const rp_scene *scene, rp_bounds *out);
/* Measurements of the last commit. */
RP_API void rp_scene_get_stats(const rp_scene *scene, rp_scene_stats *out);
/* Name of an acceleration structure kind ("bvh", "kdtree", "bih", "grid"), or NULL for an unknown one. */
RP_API const char *rp_accel_name(rp_accel_type type);

/* ---- queries --------------------------------------------------------------------------------- */

/* Hints for the array calls. */
typedef enum rp_query_flags {
    RP_QUERY_INCOHERENT = 0, /* rays go every way: traced one by one */
    RP_QUERY_COHERENT = 1    /* neighbouring rays are alike: traced in SIMD packets */
} rp_query_flags;

/* Closest hit in [tnear, tfar): on a hit sets ray.tfar and hit, else leaves hit.geom_id alone
 * (set it to RP_INVALID_ID before the call). Every query (1/4/8/16, _array, _n, occluded too)
 * treats a ray with NaN or Inf in its origin or direction, a zero direction, NaN in tnear or
 * tfar, tnear > tfar or tnear = +Inf as a miss: nothing of it is written. */
RP_API void rp_intersect1(rp_scene *scene, rp_rayhit *rayhit);
/* Any hit in [tnear, tfar): sets ray.tfar = -inf when occluded. */
RP_API void rp_occluded1(rp_scene *scene, rp_ray *ray);
/* Packet versions: valid[i] != 0 marks a live lane; lanes that are not live are never written. */
RP_API void rp_intersect4(rp_scene *scene, const int32_t *valid, rp_rayhit4 *rayhit);
/* See rp_intersect4. */
RP_API void rp_intersect8(rp_scene *scene, const int32_t *valid, rp_rayhit8 *rayhit);
/* See rp_intersect4. */
RP_API void rp_intersect16(rp_scene *scene, const int32_t *valid, rp_rayhit16 *rayhit);
/* See rp_occluded1 and rp_intersect4. */
RP_API void rp_occluded4(rp_scene *scene, const int32_t *valid, rp_ray4 *ray);
/* See rp_occluded1 and rp_intersect4. */
RP_API void rp_occluded8(rp_scene *scene, const int32_t *valid, rp_ray8 *ray);
/* See rp_occluded1 and rp_intersect4. */
RP_API void rp_occluded16(rp_scene *scene, const int32_t *valid, rp_ray16 *ray);
/* An array of rays, traced on the calling thread (flags: rp_query_flags). */
RP_API void rp_intersect_array(rp_scene *scene, rp_rayhit *rayhits, size_t count, uint32_t flags);
/* An array of occlusion rays, traced on the calling thread (flags: rp_query_flags). */
RP_API void rp_occluded_array(rp_scene *scene, rp_ray *rays, size_t count, uint32_t flags);

/* ---- large ray packets (Overbeck, Ramamoorthi, Mark 2008) ------------------------------------ */

/* A large packet is n x n rays (n a multiple of 4, 4..32) grouped by screen-space ancestry, stored
 * as a structure of arrays of n*n entries. Ray (x, y) of the packet lives at rp_packet_n_index(n,
 * x, y): 2x2 quads, then 4x4 tiles, in row order, so every run of 4, 8 or 16 entries is a compact
 * SIMD ray of the paper. Arrays are caller-owned (or from rp_rayhit_n_alloc); rp_occluded_n reads
 * only the ray arrays, so the hit arrays may be NULL there. */
#define RP_PACKET_N_MAX 32
/* BVH depths the counters tell apart; deeper levels are added to the last one. */
#define RP_COUNTERS_N_DEPTH 64

typedef struct rp_rayhit_n {
    uint32_t n;                      /* rays per side: the packet holds n*n rays */
    const int32_t *valid;            /* nonzero marks a live ray; NULL: all live */
    float *org_x, *org_y, *org_z;    /* ray origins */
    float *tnear;                    /* start of each segment */
    float *dir_x, *dir_y, *dir_z;    /* ray directions (need not be normalized) */
    float *tfar;                     /* end of each segment; the hit distance / -inf on return */
    uint32_t *mask;                  /* NULL: 0xFFFFFFFF for every ray */
    float *Ng_x, *Ng_y, *Ng_z;       /* geometric normals of the hits */
    float *u, *v;                    /* barycentrics of the hits */
    uint32_t *prim_id, *geom_id, *inst_id; /* geom_id stays as set when nothing is hit */
} rp_rayhit_n;

/* How a large packet walks the BVH (sec. 3 of the paper). */
typedef enum rp_traversal {
    RP_TRAVERSAL_AUTO = 0,      /* per packet from its coherence (direction spread): span or partition */
    RP_TRAVERSAL_MASKED = 1,    /* per-ray masks (sec. 3.1) */
    RP_TRAVERSAL_RANGED = 2,    /* first active index, getFirstHit / getLastHit (sec. 3.2) */
    RP_TRAVERSAL_PARTITION = 3, /* ray index list partitioned in place (sec. 3.3) */
    RP_TRAVERSAL_SINGLE = 4,    /* every ray on its own, as rp_intersect1 */
    RP_TRAVERSAL_SIMD = 5,      /* every SIMD ray (4, 8 or 16 rays, the device's width) on its own */
    RP_TRAVERSAL_SPAN = 6,      /* Ranged narrowed from both ends, leaves tested on the rays that hit
                                   their box (beyond the paper; auto's choice for coherent packets) */
    RP_TRAVERSAL_MLRT = 7       /* multi-level ray tracing (Reshetov et al. 2005): the packet's frustum,
                                   then its quadrants', find the deepest node each must start from;
                                   Span from there. Needs a frustum kind; without one it is Span */
} rp_traversal;

/* Which bounding frustum culls boxes and triangles (sec. 4); the frustum is always conservative. */
typedef enum rp_frustum_kind {
    RP_FRUSTUM_NONE = 0,        /* no culling */
    RP_FRUSTUM_PRIMARY = 1,     /* common origin (pinhole camera): from the 4 corner rays */
    RP_FRUSTUM_SHADOW = 2,      /* common end point `point` (a point light); segments end before it */
    RP_FRUSTUM_SECONDARY = 3    /* any rays (reflection, refraction): near and far planes */
} rp_frustum_kind;

/* Work counters of large-packet traversal, summed over calls (Fig. 6 of the paper). Ray tests are
 * counted in SIMD rays (one test of 4, 8 or 16 rays at once). Not thread safe: one per thread. */
typedef struct rp_counters_n {
    uint64_t packets, rays;
    uint64_t box_tests;                   /* SIMD ray - box tests */
    uint64_t tri_tests;                   /* SIMD ray - triangle tests */
    uint64_t frustum_box_tests, frustum_box_culls;
    uint64_t frustum_tri_tests, frustum_tri_culls;
    uint64_t traversal[7];                /* packets traced by auto, masked, ranged, partition, span,
                                             SIMD rays (auto, incoherent packets), mlrt */
    uint64_t mlrt_entries;                /* mlrt: sub-packets started at an entry point */
    uint64_t mlrt_rays_below_root;        /* ... their live rays whose entry point is not the root */
    uint64_t mlrt_entry_depth;            /* ... the entry points' depths, summed over those rays */
    uint64_t box_tests_depth[RP_COUNTERS_N_DEPTH]; /* box_tests by depth of the box (root: 0) */
    uint64_t tri_tests_depth[RP_COUNTERS_N_DEPTH]; /* tri_tests by depth of the leaf */
} rp_counters_n;

/* What auto traversal learns about the packets its coherence measure cannot settle, two classes
 * with two ways each: [0] packets whose rays part (a direction spread too wide for Span), traced
 * with Partition [0][0] or Span [0][1]; [1] packets it finds too incoherent for a packet, traced as
 * a packet [1][0] or as SIMD rays one at a time [1][1]. Auto times them, sends each packet of a
 * class the way that has taken less time per ray and, every 16th, the other way, to keep both
 * figures current. Zero it before the first call; keep one per thread and per kind of packet
 * (one size and ray type: which way pays differs between them). The choice changes how long a
 * packet takes and the counters, never its hits. */
typedef struct rp_auto_tally {
    uint64_t seen[2];       /* packets of each class traced */
    uint64_t packets[2][2]; /* ... each way (the recent ones: a way's figures are halved as it goes) */
    uint64_t rays[2][2];    /* their live rays */
    uint64_t ticks[2][2];   /* the time they took, in the CPU's time-stamp ticks */
} rp_auto_tally;

typedef struct rp_query_n_desc {
    rp_traversal traversal;     /* 0: RP_TRAVERSAL_AUTO */
    rp_frustum_kind frustum;    /* 0: RP_FRUSTUM_NONE */
    float point[3];             /* RP_FRUSTUM_SHADOW: the point every ray heads to (the light) */
    rp_counters_n *counters;    /* NULL: nothing is counted (and nothing is paid for it) */
    rp_auto_tally *tally;       /* auto: what it learns as it goes; NULL: fixed ways (parting
                                   packets to Partition, incoherent ones ray by ray) */
} rp_query_n_desc;

/* Returns the defaults for every zero field of desc (NULL gives all defaults). */
RP_API rp_query_n_desc rp_query_n_desc_defaults(const rp_query_n_desc *desc);
/* Index in the packet's arrays of ray (x, y), 0 <= x, y < n. */
RP_API uint32_t rp_packet_n_index(uint32_t n, uint32_t x, uint32_t y);
/* Allocates every array of an n x n packet (64-byte aligned, one block from the device's
 * allocator; valid and mask are left NULL); false on a bad n or out of memory. */
RP_API bool rp_rayhit_n_alloc(rp_device *device, uint32_t n, rp_rayhit_n *out);
/* Frees the arrays of rp_rayhit_n_alloc and zeroes *packet. */
RP_API void rp_rayhit_n_free(rp_device *device, rp_rayhit_n *packet);
/* Closest hits of a large packet: the same hits as rp_intersect1 on each ray, whatever the mode. */
RP_API void rp_intersect_n(rp_scene *scene, const rp_query_n_desc *desc, rp_rayhit_n *packet);
/* Any hits of a large packet: sets tfar = -inf on occluded rays, as rp_occluded1. */
RP_API void rp_occluded_n(rp_scene *scene, const rp_query_n_desc *desc, rp_rayhit_n *packet);
/* Adds the counts of src to dst (to merge per-thread counters). */
RP_API void rp_counters_n_add(rp_counters_n *dst, const rp_counters_n *src);

#ifdef __cplusplus
}
#endif
#endif /* RAYPACK_H */
