/* Bounding volume hierarchies: one canonical binary BVH, built by binned SAH from primitive boxes
 * (centroids are the box centres), converted to wide layouts (4, 8 or 16 children per node) for
 * traversal. Builders and layouts vary independently (tinybvh's ConvertFrom). */
#ifndef RP_BVH_H
#define RP_BVH_H

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "math/vec.h"
#include "simd/simd.h"
#include "sys/sys.h"

/* Binary node, 32 bytes. Inner: children at index and index + 1 (count == 0).
 * Leaf: primitives prims[index .. index + count). */
typedef struct bvh_node {
    float lo[3];
    uint32_t index;
    float hi[3];
    uint32_t count;
} bvh_node;

typedef struct bvh2 {
    bvh_node *nodes;     /* nodes[0] is the root */
    uint32_t node_count; /* including unused nodes (count 0, index 0, never a child): 2 leaf_count - 1 are used */
    uint32_t node_capacity;
    uint32_t *prims;     /* primitive ids in leaf order */
    uint32_t prim_count;
    uint32_t depth;      /* number of levels (a single leaf: 1) */
    uint32_t leaf_count;
    double sah_cost;     /* traversal cost 1, intersection cost 1 per primitive, relative to root */
} bvh2;

typedef struct bvh_build_desc {
    int bins;          /* per axis, 4..64 (twice as many, up to 64, in nodes of over 256 primitives) */
    int max_leaf_size; /* most primitives per leaf, 1..60; the SAH decides below it */
    int block_size;    /* primitives intersected together (4 for tri4 leaves); 0: 1 */
    float trav_cost;   /* cost of a node relative to one block intersection; 0: 1 */
} bvh_build_desc;

/* A primitive's box in the form the builder bins and partitions, SIMD vectors so a union is two
 * min/max instructions: lo x, y, z, 0 and hi x, y, z, -inf (the w lanes are the builder's, see its
 * bins). Made where the boxes are computed, so a build reads no second copy of them. */
typedef struct bvh_prim {
    vf4 lo, hi;
} bvh_prim;

static inline bvh_prim bvh_prim_of(box3 b) {
    return (bvh_prim){{b.lo.x, b.lo.y, b.lo.z, 0.0f}, {b.hi.x, b.hi.y, b.hi.z, -INFINITY}};
}

/* Builds over n primitive boxes (none empty or non-finite), which it reorders (out->prims says
 * where each went); uses the pool's threads when pool != NULL. Returns false when out of memory.
 * n == 0 gives a single empty leaf. */
bool bvh_build(const sys_allocator *alloc, sys_pool *pool, bvh_prim *boxes, uint32_t n, const bvh_build_desc *desc,
               bvh2 *out);
void bvh2_free(const sys_allocator *alloc, bvh2 *bvh);
/* SAH cost of a binary BVH whose leaves are ranges of tri4 blocks: inner nodes trav_cost, leaves
 * their blocks, each weighted by its half area over the root's. */
double bvh2_blocks_cost(const bvh2 *bvh, double trav_cost);
/* Refits such a BVH to its blocks' vertices (topology unchanged) and returns its new cost. */
struct tri4;
double bvh2_refit_blocks(bvh2 *bvh, const struct tri4 *blocks, double trav_cost);
/* Widens every box of the tree outward by 2^-22 of each coordinate's size plus 2^-32 of the root's
 * largest side, before the traversal layouts are made from it. The kernels' slab test takes a
 * direction component of 0 as +-1e-18 (safe_rcp): a ray lying in a box's face plane (an axis-parallel
 * ray through a vertex) then leaves the exact box at t = 0 and misses hits the watertight triangle test
 * gives it on that face; with the margin it stays inside for t up to about 2e8 scene sizes (distances
 * in units of the ray's direction). The absolute part was 2^-20 of the side (t up to 1e12 scene
 * sizes): a small object on a ground 10^5 times its size then had every triangle's box grown by the
 * object's own size, and every structure traced it 100-1000x slower. */
void bvh2_pad_boxes(bvh2 *bvh);
/* That margin's absolute part for a scene of box lo..hi (2^-32 of its largest side; a tiny one
 * for a point or a flat scene; 0 for an infinite box, which is left as it is). */
static inline float box_pad_abs(const float lo[3], const float hi[3]) {
    float side = 0.0f;
    for (int k = 0; k < 3; k++)
        if (hi[k] - lo[k] > side) side = hi[k] - lo[k];
    if (!(side < INFINITY)) return 0.0f;
    float abs_pad = side * 0x1p-32f;
    return abs_pad > 0.0f ? abs_pad : 0x1p-100f;
}
/* A lower / upper plane moved outward by the margin (the kd-tree's and the BIH's boxes too). */
static inline float box_pad_lo(float x, float abs_pad) { return x - (fabsf(x) * 0x1p-22f + abs_pad); }
static inline float box_pad_hi(float x, float abs_pad) { return x + (fabsf(x) * 0x1p-22f + abs_pad); }

/* The binary BVH the large packets walk (and the refit and the CUDA layout start from), kept
 * beside the wide one in 16 bytes a node instead of 32: each box is quantized to 16 bits per plane
 * on a grid over its parent's decoded box (the root's on a grid over the scene's box), rounded
 * outward (lower planes down, upper planes up, checked when encoded, with one more step of margin),
 * so a decoded box holds the exact one and no ray loses a hit; a grid step is a little over 1/65535
 * of the parent's extent (bvh2q_child_grid). One grid over the whole scene, as before, made every
 * box at least 1/65535 of the scene wide: a bunny on a ground 10^4 times its size had its
 * triangles' boxes grow to a quarter of the bunny, and its n x n packets ran 20-30x slower. ic: BVH2Q_PAIR | index << 4 | count, as
 * bvh_node's index and count (a leaf's count is its tri4 blocks, at most 15). A pair is an inner
 * node of the float tree whose two children are leaves of one block each, in adjacent blocks:
 * stored as one leaf of those two blocks (the flag says so), which saves its two children's 32
 * bytes (2 in 5 of the binary nodes: bunny's 18326 leaves make 7363 such pairs) at the cost of
 * the packets' two child box tests there. Nodes are numbered from the root, an inner node's
 * children side by side, the pairs' children left out. */
typedef struct bvh2q_node {
    uint16_t lo[3], hi[3];
    uint32_t ic;
} bvh2q_node;

#define BVH2Q_MAX_INDEX ((1u << 27) - 1u) /* as BVHW_MAX_FIRST */
#define BVH2Q_PAIR 0x80000000u

typedef struct bvh2q {
    bvh2q_node *nodes;   /* 64-byte aligned; nodes[0] is the root */
    uint32_t node_count; /* no unused nodes */
    uint32_t depth, leaf_count; /* of the float tree, pairs as two leaves */
    float org[3], scale[3]; /* a plane q decodes to org + q * scale (no fused multiply-add) */
} bvh2q;

/* A node with its box decoded (conservative) and its index and count, on the grid org, scale: the
 * scene's for the root, bvh2q_child_grid of its parent's decoded box for the others. */
static inline bvh_node bvh2q_decode(const bvh2q_node *n, const float org[3], const float scale[3]) {
    bvh_node d;
    for (int a = 0; a < 3; a++) {
        d.lo[a] = org[a] + (float)n->lo[a] * scale[a];
        d.hi[a] = org[a] + (float)n->hi[a] * scale[a];
    }
    d.index = n->ic >> 4 & BVH2Q_MAX_INDEX;
    d.count = n->ic & 15u;
    return d;
}

/* The same decode, the six planes at once (zero extension, conversion, multiply, add: the same
 * IEEE results lane by lane); org and scale hold lo x y z, hi x y z, 0, 0 (bvh2q_grid8). The large
 * packets decode every node they visit and both children of each inner one: scalar, that had cost
 * 6.8% more instructions than the float nodes (AVX2, conference, 16x16 Span, callgrind). */
typedef uint16_t bvh2q_u16x8 __attribute__((vector_size(16)));
typedef int32_t bvh2q_i32x8 __attribute__((vector_size(32)));
typedef float bvh2q_f32x8 __attribute__((vector_size(32)));

/* A node's children's grid per axis: from its decoded box's lower plane in steps of its extent
 * over 65000 (so q = 65535 lies a little past its upper plane), as hi k - lo k, which does not
 * overflow; planes that decoded to infinity (boxes out to FLT_MAX) count as +-FLT_MAX. The scalar
 * and the vector forms make the same IEEE operations, so the encoder's checks hold for the
 * traversal. */
#define BVH2Q_CHILD_STEP (1.0f / 65000.0f)
static inline void bvh2q_child_grid(const bvh_node *parent, float org[3], float scale[3]) {
    for (int a = 0; a < 3; a++) {
        float lo = parent->lo[a] > -FLT_MAX ? parent->lo[a] : -FLT_MAX;
        float hi = parent->hi[a] < FLT_MAX ? parent->hi[a] : FLT_MAX;
        org[a] = lo;
        scale[a] = hi * BVH2Q_CHILD_STEP - lo * BVH2Q_CHILD_STEP;
    }
}

static inline void bvh2q_grid8(const float org[3], const float scale[3], bvh2q_f32x8 *o8, bvh2q_f32x8 *s8) {
    *o8 = (bvh2q_f32x8){org[0], org[1], org[2], org[0], org[1], org[2], 0.0f, 0.0f};
    *s8 = (bvh2q_f32x8){scale[0], scale[1], scale[2], scale[0], scale[1], scale[2], 0.0f, 0.0f};
}

/* A node's decoded box as lo x y z, hi x y z, 0, 0, on the grid o8, s8. */
static inline bvh2q_f32x8 bvh2q_box8(const bvh2q_node *n, bvh2q_f32x8 o8, bvh2q_f32x8 s8) {
    bvh2q_u16x8 q;
    memcpy(&q, n, sizeof q);
    return o8 + __builtin_convertvector(__builtin_convertvector(q, bvh2q_i32x8), bvh2q_f32x8) * s8;
}

/* The grid of the children of a node whose decoded box is b (bvh2q_child_grid, 8 lanes). */
static inline void bvh2q_child_grid8(bvh2q_f32x8 b, bvh2q_f32x8 *o8, bvh2q_f32x8 *s8) {
    const bvh2q_f32x8 big = {FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX};
    bvh2q_f32x8 lo = __builtin_shufflevector(b, b, 0, 1, 2, 0, 1, 2, 6, 7);
    bvh2q_f32x8 hi = __builtin_shufflevector(b, b, 3, 4, 5, 3, 4, 5, 6, 7);
    /* as the scalar form: lo > -FLT_MAX ? lo : -FLT_MAX, and hi likewise (the planes are finite or
     * infinite, never NaN) */
    bvh2q_i32x8 mlo = lo > -big, mhi = hi < big;
    lo = (bvh2q_f32x8)(((bvh2q_i32x8)lo & mlo) | ((bvh2q_i32x8)-big & ~mlo));
    hi = (bvh2q_f32x8)(((bvh2q_i32x8)hi & mhi) | ((bvh2q_i32x8)big & ~mhi));
    *o8 = lo;
    *s8 = hi * BVH2Q_CHILD_STEP - lo * BVH2Q_CHILD_STEP;
}

/* Node n with its decoded box b. */
static inline bvh_node bvh2q_node8(const bvh2q_node *n, bvh2q_f32x8 b) {
    bvh_node d = {{b[0], b[1], b[2]}, n->ic >> 4 & BVH2Q_MAX_INDEX, {b[3], b[4], b[5]}, n->ic & 15u};
    return d;
}

/* The root's decoded box, on the grid over the scene's box. */
static inline bvh2q_f32x8 bvh2q_root8(const bvh2q_node *nodes, const float org[3], const float scale[3]) {
    bvh2q_f32x8 o8, s8;
    bvh2q_grid8(org, scale, &o8, &s8);
    return bvh2q_box8(nodes, o8, s8);
}

/* Encodes a binary BVH whose leaves are ranges of at most 15 tri4 blocks; false when out of
 * memory, when an index or a count does not fit, or when a box is not finite. */
bool bvh2q_from_bvh2(const sys_allocator *alloc, const bvh2 *src, bvh2q *out);
/* The float form of a quantized BVH (decoded, so conservative, boxes; no prims), for the refit
 * and the CUDA layout; free it with bvh2_free. split_pairs: each pair becomes the inner node and
 * two leaves it was (the leaves with the pair's box: the refit recomputes them), so the tree is
 * the encoded one again; else a pair is a leaf of two blocks. */
bool bvh2q_to_bvh2(const sys_allocator *alloc, const bvh2q *src, bool split_pairs, bvh2 *out);
/* Every node decoded into out[0 .. node_count) (parents come before their children). */
void bvh2q_decode_all(const bvh2q *q, bvh_node *out);
void bvh2q_free(const sys_allocator *alloc, bvh2q *q);

/* Wide node of width W (4, 8 or 16) is stored as floats bounds[6][W] (lo_x, hi_x, lo_y, hi_y,
 * lo_z, hi_z) followed by uint32_t child[W]. A child reference is either an inner node index or a
 * leaf: BVHW_LEAF | first_item << 4 | item_count (1..15). Empty slots have an empty box and the
 * reference BVHW_EMPTY. */
#define BVHW_LEAF 0x80000000u
#define BVHW_EMPTY 0x80000000u
#define BVHW_MAX_ITEMS 15u
#define BVHW_MAX_FIRST ((1u << 27) - 1u)
#define BVHW_MAX_DEPTH 100u /* the builder keeps binary trees shallower (median splits past 64) */

static inline uint32_t bvhw_node_bytes(int width) { return (uint32_t)width * 7u * 4u; }

/* Compact layout (the triangle BVH's): a node of width W that holds at most W / 2^s children is
 * stored W / 2^s wide (s = 0..3, at least 2 wide), in the same form, padded to 64 bytes. An inner
 * reference is then the node's byte offset / 64 << 2 | s; the root (reference 0) is full width.
 * BVH16 nodes had held 4.5 children on average (28-36% of their slots: most nodes near the leaves
 * hold 2-4), and their 448 bytes had been 28-31% of a scene's structure. */
#define BVHW_KIND_BITS 2u
#define BVHW_KIND_MASK 3u
/* Bytes past the last node that the kernels' full-width loads of a narrow node may read. */
#define BVHW_TAIL_PAD 64u

static inline uint32_t bvhw_kind_bytes(int width, uint32_t s) {
    return (bvhw_node_bytes(width >> s) + 63u) & ~63u;
}
static inline const char *bvhw_node_at(const void *nodes, uint32_t ref) {
    return (const char *)nodes + (size_t)(ref >> BVHW_KIND_BITS) * 64u;
}

typedef struct bvhw {
    int width;
    void *nodes;        /* 64-byte aligned array of node_count nodes; node 0 is the root */
    uint32_t node_count;
    size_t bytes;
    bool compact;       /* the compact layout above (bvhw_compact) */
} bvhw;

/* Maps a binary leaf to its payload: the first item and the number of items (1..15) holding its
 * primitives (e.g. blocks of 4 triangles). Returns false if the leaf does not fit. */
typedef bool (*bvhw_leaf_fn)(void *user, const bvh_node *leaf, uint32_t *first_item, uint32_t *items);

/* Collapses a binary BVH into a wide one, opening the child of largest area first; uses the pool's
 * threads when pool != NULL. */
bool bvhw_from_bvh2(const sys_allocator *alloc, sys_pool *pool, const bvh2 *src, int width, bvhw_leaf_fn leaf,
                    void *leaf_user, bvhw *out);
void bvhw_free(const sys_allocator *alloc, bvhw *bvh);
/* Rewrites a wide BVH in the compact layout (above); false (bvh unchanged) when out of memory or
 * past the references' reach. */
bool bvhw_compact(const sys_allocator *alloc, bvhw *bvh);

#endif
