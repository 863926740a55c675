/* Acceleration structures other than the BVH (kd-tree, BIH, uniform grid): what their builders take, what they
 * produce, and the query table a scene picks at commit (STYLE.md: open sets are tables of
 * function pointers). Builders read primitive boxes and, through a callback, the triangles' vertices;
 * their leaves are ranges of tri4 blocks, tested with the project's watertight test (tri_leaf.h), so
 * every structure returns the BVH's hits. Spheres and user primitives stay in the scene's BVH4. */
#ifndef RP_ACCEL_H
#define RP_ACCEL_H

#include <stddef.h>
#include <stdint.h>

#include "accel/bvh/bvh.h"
#include "math/vec.h"
#include "sys/sys.h"
#include "traverse/traverse.h"

/* The valid triangles of a commit. */
typedef struct accel_tri_input {
    bvh_prim *boxes;        /* per triangle; a builder may reorder them (the BIH does, in place) */
    const prim_ref *refs;   /* per triangle, in the original order */
    uint32_t count;
    box3 bounds;            /* of all boxes */
    /* Writes triangle r's vertices (v0 xyz, v1 xyz, v2 xyz) and its geometry's mask. */
    void (*fetch)(const void *user, prim_ref r, float v[9], uint32_t *mask);
    /* Fills the blocks of positions [begin, end) of a leaf order, as the BVH's are filled (in
     * order, prefetching each triangle's reference, indices and vertices ahead): position p is
     * triangle refs[ids[p * stride]], in block block_of[p]; block_of[begin] starts a block, and
     * a block's unused lanes repeat lane 0 (tri4_pad). */
    void (*fill)(const void *user, const prim_ref *refs, const uint32_t *ids, size_t stride, const uint32_t *block_of,
                 uint32_t begin, uint32_t end, tri4 *blocks);
    const void *user;
    float grid_density;     /* the grid's voxels per triangle (rp_scene_desc.grid_density; 0: default) */
} accel_tri_input;

/* What a builder made: nodes (its own layout) and the tri4 blocks its leaves point at. */
typedef struct accel_built {
    void *nodes;
    size_t node_bytes;
    tri4 *blocks;           /* block_count blocks and one padding block (NaN vertices) */
    uint32_t block_count;
    uint32_t root_depth;    /* levels (a single leaf: 1) */
    uint64_t nodes_total, inner_nodes, leaves, tri_refs;
    double sah_cost;        /* traversal 1, triangle 1, relative to the root's area */
    float bounds[6];        /* lo xyz, hi xyz: the box the traversal starts from */
} accel_built;

/* One kind of structure: its builder and its queries. The query functions see rp_accel.alt (the
 * accel_built) and hand spheres and user primitives to rp_accel.base (the device's BVH kernels). */
typedef struct accel_ops {
    const char *name;
    bool (*build)(const sys_allocator *a, sys_pool *pool, accel_tri_input *in, accel_built *out);
    const rp_kernels *kernels;
    /* the queries compiled for the device's ISA (rp_kernels.isa: 1, 4, 8, 16), or NULL: kernels */
    const rp_kernels *(*kernels_for_isa)(int isa);
} accel_ops;

extern const accel_ops accel_kdtree, accel_bih, accel_grid;
/* The structures' queries (kdtree_trav.c, bih_trav.c, grid_accel.c). */
extern const rp_kernels kdtree_kernels, bih_kernels, grid_accel_kernels;

/* Frees what a builder made. */
void accel_built_free(const sys_allocator *a, accel_built *b);
/* Allocates count tri4 blocks and the padding block after them; NULL when out of memory. */
tri4 *accel_blocks_alloc(const sys_allocator *a, uint32_t count);
/* Fills block `dst` (lanes 0..n-1, n in 1..4) with triangles ids[0..n) of the input; unused lanes
 * repeat lane 0 (tri4_pad), as the BVH's blocks do. */
void accel_fill_block(const accel_tri_input *in, const uint32_t *ids, uint32_t n, tri4 *dst);

#endif
