/* The quantized binary BVH (bvh.h, bvh2q): 16 bytes a node, boxes on a 16-bit grid over the
 * root's box, rounded outward and checked against the exact boxes when encoded. */
#include <math.h>
#include <string.h>

#include "accel/bvh/bvh.h"

static float decode1(float org, float scale, uint32_t q) { return org + (float)q * scale; }

/* The grid's lowest q whose plane is at most x (one step lower still, for margin). */
static bool quant_lo(float org, float scale, float x, uint16_t *out) {
    double f = scale > 0.0f ? floor(((double)x - org) / scale) : 0.0;
    int64_t q = f < 0.0 ? 0 : f > 65535.0 ? 65535 : (int64_t)f;
    while (q > 0 && decode1(org, scale, (uint32_t)q) > x) q--;
    if (decode1(org, scale, (uint32_t)q) > x) return false;
    if (q > 0) q--;
    *out = (uint16_t)q;
    return true;
}

/* The grid's highest q whose plane is at least x (one step higher still, for margin). */
static bool quant_hi(float org, float scale, float x, uint16_t *out) {
    double f = scale > 0.0f ? ceil(((double)x - org) / scale) : 0.0;
    int64_t q = f < 0.0 ? 0 : f > 65535.0 ? 65535 : (int64_t)f;
    while (q < 65535 && decode1(org, scale, (uint32_t)q) < x) q++;
    if (decode1(org, scale, (uint32_t)q) < x) return false;
    if (q < 65535) q++;
    *out = (uint16_t)q;
    return true;
}

static bool used(const bvh_node *n, uint32_t i) { return i == 0 || n->count != 0 || n->index != 0; }

bool bvh2q_from_bvh2(const sys_allocator *alloc, const bvh2 *src, bvh2q *out) {
    memset(out, 0, sizeof *out);
    if (!src->nodes || src->node_count == 0) return false;
    const bvh_node *root = &src->nodes[0];
    for (int a = 0; a < 3; a++) {
        float lo = root->lo[a], hi = root->hi[a];
        if (!isfinite(lo) || !isfinite(hi) || !(lo <= hi)) return false;
        out->org[a] = lo;
        /* a step a little over extent / 65535, so q = 65535 lies past the root's upper plane */
        float scale = (float)(((double)hi - lo) / 65535.0 * (1.0 + 0x1p-12));
        for (int k = 0; k < 64 && decode1(lo, scale, 65535) < hi; k++) scale = scale > 0.0f ? scale * 1.0009765625f : 0x1p-126f;
        if (decode1(lo, scale, 65535) < hi) return false;
        out->scale[a] = scale;
    }
    size_t bytes = (size_t)src->node_count * sizeof(bvh2q_node);
    out->nodes = sys_alloc(alloc, bytes);
    if (!out->nodes) return false;
    memset(out->nodes, 0, bytes);
    out->node_count = src->node_count;
    out->depth = src->depth;
    out->leaf_count = src->leaf_count;
    for (uint32_t i = 0; i < src->node_count; i++) {
        const bvh_node *n = &src->nodes[i];
        bvh2q_node *q = &out->nodes[i];
        if (!used(n, i)) continue; /* never a child: left zero, as the float tree's */
        if (n->index > BVH2Q_MAX_INDEX || n->count > 15u) goto fail;
        q->ic = n->index << 4 | n->count;
        if (n->count == 0 && n->index == 0) continue; /* an empty tree's root: no box */
        for (int a = 0; a < 3; a++)
            if (!quant_lo(out->org[a], out->scale[a], n->lo[a], &q->lo[a]) ||
                !quant_hi(out->org[a], out->scale[a], n->hi[a], &q->hi[a]))
                goto fail;
    }
    return true;
fail:
    bvh2q_free(alloc, out);
    return false;
}

bool bvh2q_to_bvh2(const sys_allocator *alloc, const bvh2q *src, bvh2 *out) {
    memset(out, 0, sizeof *out);
    out->nodes = sys_alloc(alloc, (size_t)src->node_count * sizeof(bvh_node));
    if (!out->nodes) return false;
    for (uint32_t i = 0; i < src->node_count; i++) out->nodes[i] = bvh2q_decode(&src->nodes[i], src->org, src->scale);
    out->node_count = out->node_capacity = src->node_count;
    out->depth = src->depth;
    out->leaf_count = src->leaf_count;
    return true;
}

void bvh2q_free(const sys_allocator *alloc, bvh2q *q) {
    if (q->nodes) sys_free(alloc, q->nodes, (size_t)q->node_count * sizeof(bvh2q_node));
    memset(q, 0, sizeof *q);
}
