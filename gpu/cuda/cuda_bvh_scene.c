/* The canonical binary BVH of a committed scene (core/scene.c keeps it beside the wide layout, its
 * leaves ranges of tri4 blocks, quantized: decoded here, so its boxes are conservative) converted to the CUDA layout of cuda_bvh.h (tinybvh's ConvertFrom:
 * the builder stays the CPU's, only the layout changes). A node's children are numbered when it is
 * written and the left subtree is walked first, so siblings are adjacent and a leaf's triangles
 * follow its parent's other leaves'. Also the grid's arrays for the CUDA grid. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel/grid/grid.h"
#include "core/core.h"
#include "cuda_bvh.h"
#include "cuda_grid.h"

static void put_u32(float *f, uint32_t u) { memcpy(f, &u, sizeof u); }

/* Writes child slot `side` (0 left, 1 right) of GPU node `g`: its box and its reference. */
static void put_child(float *g, int side, const float lo[3], const float hi[3], uint32_t ref) {
    float *xy = g + 4 * side, *z = g + 8 + 2 * side;
    xy[0] = lo[0], xy[1] = hi[0], xy[2] = lo[1], xy[3] = hi[1];
    z[0] = lo[2], z[1] = hi[2];
    put_u32(g + 12 + side, ref);
}

static bool fail(char *err, size_t size, const char *msg) {
    if (err && size) snprintf(err, size, "cuda: %s", msg);
    return false;
}

/* Appends the live lanes of blocks [first, first + count) and returns the leaf's reference. */
static bool put_leaf(const rp_scene *s, const bvh_node *leaf, rp_cuda_bvh_src *out, uint32_t *ref) {
    uint32_t first = out->tri_count, n = 0;
    for (uint32_t b = leaf->index; b < leaf->index + leaf->count; b++) {
        const tri4 *tr = &s->tris[b];
        for (uint32_t lanes = tri4_lanes(tr); lanes; lanes &= lanes - 1) { /* not the padding lanes */
            uint32_t j = simd_ctz(lanes), mask = s->geom_masks[tr->geom[j]];
            if (!mask) continue; /* never hit */
            float *t = out->tris + 12 * (size_t)out->tri_count++;
            for (int v = 0; v < 3; v++)
                for (int a = 0; a < 3; a++) t[4 * v + a] = tr->v[3 * v + a][j];
            put_u32(t + 3, tr->geom[j]), put_u32(t + 7, tr->prim[j]), put_u32(t + 11, mask);
            n++;
        }
    }
    if (n > RP_CUDA_MAX_LEAF || out->tri_count > RP_CUDA_MAX_TRIS) return false;
    *ref = RP_CUDA_LEAF | first << RP_CUDA_COUNT_BITS | n;
    return true;
}

static bool src_from_tree(const rp_scene *s, const bvh2 *b, bool empty, rp_cuda_bvh_src *out, char *err,
                          size_t err_size);

bool rp_cuda_bvh_src_from_scene(const rp_scene *s, rp_cuda_bvh_src *out, char *err, size_t err_size) {
    memset(out, 0, sizeof *out);
    if (!s || !s->committed) return fail(err, err_size, "the scene is not committed");
    if (s->desc.accel != RP_ACCEL_BVH) return fail(err, err_size, "the GPU traces the BVH only (--accel bvh)");
    out->skipped = s->prim_count;
    bvh2 tree = {0};
    if (s->tri_bvh2q.nodes && !bvh2q_to_bvh2(&s->device->alloc, &s->tri_bvh2q, false, &tree))
        return fail(err, err_size, "out of memory");
    const bvh2 *b = &tree;
    bool empty = !b->nodes || !s->tris;
    bool ok = src_from_tree(s, b, empty, out, err, err_size);
    bvh2_free(&s->device->alloc, &tree);
    return ok;
}

static bool src_from_tree(const rp_scene *s, const bvh2 *b, bool empty, rp_cuda_bvh_src *out, char *err,
                          size_t err_size) {
    if (!empty && b->depth > RP_CUDA_STACK) return fail(err, err_size, "BVH deeper than the GPU traversal stack");
    /* at most one GPU node per binary inner node, and one more when the root is a leaf */
    size_t inner = empty ? 1 : (b->leaf_count > 1 ? b->leaf_count - 1 : 1);
    size_t tris = empty ? 1 : (s->tri_block_count ? s->tri_block_count : 1) * 4;
    out->nodes = calloc(inner * 16, sizeof(float));
    out->tris = calloc(tris * 12, sizeof(float));
    uint32_t *stack = calloc(b->depth + 2, 2 * sizeof(uint32_t));
    if (!out->nodes || !out->tris || !stack) {
        free(stack);
        rp_cuda_bvh_src_free(out);
        return fail(err, err_size, "out of memory");
    }
    const float none_lo[3] = {INFINITY, INFINITY, INFINITY}, none_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    const uint32_t none_ref = RP_CUDA_LEAF; /* an empty leaf in an empty box */
    out->node_count = 1;
    out->depth = empty ? 1 : b->depth;
    bool ok = true;
    if (empty || b->nodes[0].count) { /* no triangles, or a single leaf: a root with one child */
        uint32_t ref = none_ref;
        if (!empty) ok = put_leaf(s, &b->nodes[0], out, &ref);
        put_child(out->nodes, 0, empty ? none_lo : b->nodes[0].lo, empty ? none_hi : b->nodes[0].hi, ref);
        put_child(out->nodes, 1, none_lo, none_hi, none_ref);
    } else {
        /* depth first: (binary node, its GPU node) pairs whose children are still to be written */
        uint32_t sp = 0;
        stack[sp++] = 0, stack[sp++] = 0;
        while (ok && sp) {
            uint32_t g = stack[--sp], bn = stack[--sp];
            const bvh_node *n = &b->nodes[bn];
            uint32_t refs[2];
            for (int side = 0; side < 2 && ok; side++) {
                const bvh_node *c = &b->nodes[n->index + (uint32_t)side];
                if (c->count) {
                    ok = put_leaf(s, c, out, &refs[side]);
                } else {
                    refs[side] = UINT32_MAX; /* numbered below, in depth-first order */
                }
            }
            if (!ok) break;
            for (int side = 0; side < 2; side++) {
                const bvh_node *c = &b->nodes[n->index + (uint32_t)side];
                if (refs[side] == UINT32_MAX) refs[side] = out->node_count++;
                put_child(out->nodes + 16 * (size_t)g, side, c->lo, c->hi, refs[side]);
            }
            for (int side = 1; side >= 0; side--)
                if (!(refs[side] & RP_CUDA_LEAF)) stack[sp++] = n->index + (uint32_t)side, stack[sp++] = refs[side];
        }
    }
    free(stack);
    if (!ok) {
        rp_cuda_bvh_src_free(out);
        return fail(err, err_size, "a BVH leaf holds more triangles than the GPU layout encodes");
    }
    return true;
}

void rp_cuda_bvh_src_free(rp_cuda_bvh_src *src) {
    free(src->nodes);
    free(src->tris);
    memset(src, 0, sizeof *src);
}

rp_cuda_grid *rp_cuda_grid_from_grid(const grid *g, char *err, size_t err_size) {
    float *tris = malloc(((size_t)g->tri_count + 1) * 16 * sizeof(float));
    if (!tris) {
        fail(err, err_size, "out of memory");
        return NULL;
    }
    for (uint32_t i = 0; i < g->tri_count; i++) {
        memcpy(&tris[16 * (size_t)i], g->tris[i].v, 9 * sizeof(float));
        memcpy(&tris[16 * (size_t)i + 9], &g->tris[i].geom, 3 * sizeof(uint32_t));
    }
    rp_cuda_grid_src src = {.voxel_count = g->voxel_count, .tri_count = g->tri_count, .item_count = g->item_count,
                            .offsets = g->offsets, .items = g->items, .tris = tris};
    for (int a = 0; a < 3; a++) {
        src.lo[a] = g->lo[a], src.hi[a] = g->hi[a], src.cell[a] = g->cell[a];
        src.inv_cell[a] = g->inv_cell[a], src.res[a] = g->res[a];
    }
    rp_cuda_grid *cg = rp_cuda_grid_upload(&src, err, err_size);
    free(tris);
    return cg;
}
