/* Devices, geometries and scenes: the objects behind the public handles. */
#ifndef RP_CORE_H
#define RP_CORE_H

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>

#include "accel/accel.h"
#include "accel/bvh/bvh.h"
#include "raypack.h"
#include "sys/sys.h"
#include "traverse/traverse.h"

struct rp_device {
    _Atomic int refs;
    rp_device_desc desc;
    sys_allocator alloc;
    sys_pool *pool;
    pthread_mutex_t pool_lock; /* parallel_for is not reentrant: one job at a time */
    const rp_kernels *kernels;
    pthread_key_t error_key;   /* first error per thread, until read */
};

typedef struct geom_buffer {
    const uint8_t *data;  /* first item */
    size_t stride;
    size_t count;
    rp_format format;
    void *owned;          /* geometry-owned storage, or NULL */
    size_t owned_bytes;
    bool set;
} geom_buffer;

struct rp_geometry {
    _Atomic int refs;
    rp_device *device;
    rp_geometry_type type;
    uint32_t mask;
    geom_buffer buffers[2];
    uint32_t user_count;
    rp_user_bounds_fn user_bounds;
    rp_user_intersect_fn user_intersect;
    rp_user_occluded_fn user_occluded;
    void *user;
    uint32_t topo;        /* bumped by every change but moved vertices: a scene refits only if unchanged */
    rp_scene *inst;       /* RP_GEOMETRY_INSTANCE: the placed scene (retained) */
    float xfm[12], inv[12]; /* its object-to-parent map and the inverse, row-major 3x4 */
    float box[6];         /* lower xyz, upper xyz: the placed scene's bounds in the parent's space,
                           * widened past the rounding of the map; set by the parent's commit */
};

struct rp_scene {
    _Atomic int refs;
    rp_device *device;
    rp_scene_desc desc;
    rp_geometry **geoms;  /* indexed by geom_id; NULL slots are free */
    uint32_t geom_count, geom_capacity;
    bool committed;       /* committed and not edited since */
    rp_accel accel;
    const rp_kernels *kernels; /* the queries of the committed structure (the device's for a BVH) */
    accel_built alt;      /* the triangles' kd-tree or BIH (desc.accel), else empty */
    /* storage behind accel */
    bvhw tri_bvh, prim_bvh;
    bvh2q tri_bvh2q;      /* binary BVH of the triangles, leaves rewritten to tri4 blocks (large packets),
                           * quantized (bvh.h) */
    tri4 *tris;
    size_t tri_block_count;
    uint32_t *geom_masks; /* rp_accel.geom_masks: per geom_id, a triangle geometry's mask */
    size_t geom_mask_count;
    prim_ref *prims;
    size_t prim_count;
    rp_scene_stats stats;
    rp_bounds bounds;
    /* what the last build saw, to tell whether the next commit may refit */
    bool attach_changed;  /* a geometry was attached or detached since */
    uint32_t *built_topo; /* rp_geometry.topo of each geom_id (RP_INVALID_ID: none) */
    uint32_t built_count, built_capacity;
    double built_cost;    /* bvh2_blocks_cost of the last build */
    uint32_t inst_depth;  /* levels of instances below this scene (0: none) */
};

/* Raises an error on the calling thread: keeps it if it is the first since the last read, and
 * calls the device's error callback. */
void device_error(rp_device *device, rp_error code, const char *message);
/* Sends a warning to the device's log callback, if any. */
void device_log(rp_device *device, rp_log_level level, const char *message);
/* Picks the kernel table for an ISA width (1, 4, 8 or 16). */
const rp_kernels *device_pick_kernels(int isa);

/* Builds the scene's acceleration structures (rp_scene_commit). */
rp_error scene_build(rp_scene *scene);
void scene_free_accel(rp_scene *scene);

/* Item i of a geometry buffer. */
static inline const void *geom_item(const geom_buffer *b, size_t i) { return b->data + i * b->stride; }

/* A ray the kernels may trace: a finite origin and direction, a nonzero direction and an interval
 * with tnear <= tfar (neither NaN) and tnear < +inf. Every other ray is a miss, decided once at
 * the API (raypack.h) so that no kernel meets NaN/Inf: an infinite direction component had hit at
 * t = 0. x - x is 0 exactly for finite x and NaN for NaN and +-Inf. */
static inline bool ray_usable(float ox, float oy, float oz, float dx, float dy, float dz, float tn, float tf) {
    float f = (ox - ox) + (oy - oy) + (oz - oz) + (dx - dx) + (dy - dy) + (dz - dz);
    return f == 0.0f && (dx != 0.0f || dy != 0.0f || dz != 0.0f) && tn <= tf && tn < INFINITY;
}

#endif
