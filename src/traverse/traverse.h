/* What the traversal kernels see of a committed scene, and the per-ISA kernel table. */
#ifndef RP_TRAVERSE_H
#define RP_TRAVERSE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "raypack.h"

/* Four triangles in SoA form, the leaf item of triangle BVHs. v[3*vertex + axis][lane]; 176
 * bytes, as Embree's Triangle4. Unused lanes repeat lane 0, vertices and ids (tri4_pad): a test
 * of one finds at most lane 0's hit, the same (t, u, v, geom, prim), which cannot change a closest
 * or any hit, and loops over single triangles skip them (tri4_lanes). Geometry masks are not kept
 * per lane (they had been 16 bytes a block, 8% of the blocks): the rays that need the mask test
 * (rp_accel.tri_mask_and) look each lane's geometry up in rp_accel.geom_masks. */
typedef struct tri4 {
    float v[9][4];
    uint32_t geom[4];
    uint32_t prim[4];
} tri4;

/* Makes lanes used..3 of a block copies of lane 0 (used in 1..4). */
static inline void tri4_pad(tri4 *tr, uint32_t used) {
    for (uint32_t j = used; j < 4; j++) {
        for (int q = 0; q < 9; q++) tr->v[q][j] = tr->v[q][0];
        tr->geom[j] = tr->geom[0], tr->prim[j] = tr->prim[0];
    }
}

/* Bits of the lanes that hold a triangle of their own: lane 0 and those not repeating it. */
static inline uint32_t tri4_lanes(const tri4 *tr) {
    uint32_t m = 1;
    for (uint32_t j = 1; j < 4; j++) m |= (uint32_t)(tr->geom[j] != tr->geom[0] || tr->prim[j] != tr->prim[0]) << j;
    return m;
}

/* Bits of the lanes whose geometry's mask shares a bit with ray_mask (geom_masks: per geom_id,
 * rp_accel.geom_masks). */
static inline uint32_t tri4_mask_lanes(const uint32_t *geom_masks, const tri4 *tr, uint32_t ray_mask) {
    uint32_t m = 0;
    for (uint32_t j = 0; j < 4; j++) m |= (uint32_t)((geom_masks[tr->geom[j]] & ray_mask) != 0) << j;
    return m;
}

/* Geometric normal of a hit triangle: (v1 - v0) x (v2 - v0), as Embree's Ng. */
static inline void tri_normal(const tri4 *tr, uint32_t lane, float n[3]) {
    float e1[3], e2[3];
    for (int a = 0; a < 3; a++) {
        e1[a] = tr->v[3 + a][lane] - tr->v[a][lane];
        e2[a] = tr->v[6 + a][lane] - tr->v[a][lane];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
}

/* A primitive of a sphere or user geometry, the leaf item of the second BVH. */
typedef struct prim_ref {
    uint32_t geom;
    uint32_t prim;
} prim_ref;

typedef struct rp_accel rp_accel;
/* Exact intersection with one non-triangle primitive: closest-hit and any-hit forms. */
typedef bool (*prim_intersect_fn)(const rp_accel *acc, prim_ref ref, rp_ray *ray, rp_hit *hit);
typedef bool (*prim_occluded_fn)(const rp_accel *acc, prim_ref ref, const rp_ray *ray);

struct rp_accel {
    /* triangles: wide BVH of tri4 blocks */
    int width;                 /* 4, 8 or 16 */
    const void *nodes;         /* NULL when the scene has no triangles */
    const tri4 *tris;
    uint32_t tri_mask_and;     /* AND of the triangle geometries' masks: a ray sharing a bit with it
                                * passes every mask test, so its leaves skip them */
    const uint32_t *geom_masks; /* per geom_id: a triangle geometry's mask (others: 0), for the rest */
    const void *nodes2;        /* the binary BVH (bvh2q_node), leaves: tri4 blocks [index, index + count) */
    float q_org[3], q_scale[3]; /* its boxes' grid (bvh2q_decode) */
    /* spheres and user primitives: BVH4 of prim_refs */
    const void *pnodes;        /* NULL when there are none */
    const prim_ref *prims;
    prim_intersect_fn prim_intersect;
    prim_occluded_fn prim_occluded;
    const void *scene;         /* the rp_scene, for the primitive callbacks */
    float coherent_extent;     /* packets whose origins spread further are traced ray by ray */
    /* another structure holds the triangles (kd-tree, BIH: src/accel/accel.h), nodes is NULL */
    const void *alt;           /* its accel_built, or NULL (the BVH above) */
    const struct rp_kernels *base; /* the device's BVH kernels, for the spheres and user primitives */
};

typedef struct rp_kernels {
    const char *name;
    int isa;
    void (*intersect1)(const rp_accel *acc, rp_rayhit *rh);
    void (*occluded1)(const rp_accel *acc, rp_ray *ray);
    void (*intersect4)(const rp_accel *acc, const int32_t *valid, rp_rayhit4 *rh);
    void (*intersect8)(const rp_accel *acc, const int32_t *valid, rp_rayhit8 *rh);
    void (*intersect16)(const rp_accel *acc, const int32_t *valid, rp_rayhit16 *rh);
    void (*occluded4)(const rp_accel *acc, const int32_t *valid, rp_ray4 *ray);
    void (*occluded8)(const rp_accel *acc, const int32_t *valid, rp_ray8 *ray);
    void (*occluded16)(const rp_accel *acc, const int32_t *valid, rp_ray16 *ray);
    /* n x n packets of a structure other than the BVH (rp_accel.alt): closest hit, or any hit
     * (occluded rays get tfar = -inf); valid and the rays' intervals say which rays are live.
     * NULL: such packets go as SIMD rays; the BVH's go to rp_kernels_n. */
    void (*trace_n)(const rp_accel *acc, rp_rayhit_n *p, bool any);
} rp_kernels;

extern const rp_kernels rp_kernels_scalar, rp_kernels_sse, rp_kernels_avx2, rp_kernels_avx512;

/* Scalar reference: the watertight test of one ray against one triangle (Woop, Benthin, Wald
 * 2013), the same arithmetic as every kernel, so results agree bit for bit. Returns true on a hit
 * with tnear <= t <= tfar and writes t, u, v. */
bool tri_intersect_ref(const float org[3], const float dir[3], float tnear, float tfar, const float v0[3],
                       const float v1[3], const float v2[3], float *t, float *u, float *v);

/* Tie-break of equal distances: the lower (geom, prim) wins, so every traversal order gives the
 * same hit. */
/* Fetches the cache lines of [p, p + bytes) ahead of use: the packet traversals' children (a
 * node, or a leaf's first block of triangles) while the packet is busy with their siblings. */
static inline void prefetch_bytes(const void *p, size_t bytes) {
    const char *c = (const char *)p, *last = c + bytes - 1;
    for (c -= (uintptr_t)c & 63u; c <= last; c += 64) __builtin_prefetch(c);
}

static inline bool hit_key_less(uint32_t g0, uint32_t p0, uint32_t g1, uint32_t p1) {
    return g0 < g1 || (g0 == g1 && p0 < p1);
}

#endif
