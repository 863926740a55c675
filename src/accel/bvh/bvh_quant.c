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

/* An inner node whose children are leaves of one block each, the right one's next to the left's. */
static bool is_pair(const bvh2 *src, const bvh_node *n) {
    if (n->count) return false;
    const bvh_node *l = &src->nodes[n->index], *r = l + 1;
    return l->count == 1 && r->count == 1 && r->index == l->index + 1;
}

/* A node of the float tree and the place it goes to in the other tree. */
typedef struct quant_move {
    uint32_t from, to;
    float org[3], scale[3]; /* the grid it goes on: its parent's children's */
} quant_move;

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
    bool empty = root->count == 0 && root->index == 0; /* an empty tree: a root without a box */
    uint32_t pairs = 0;
    for (uint32_t i = 0; i < src->node_count && !empty; i++) {
        const bvh_node *n = &src->nodes[i];
        pairs += (i == 0 || n->index != 0) && is_pair(src, n); /* unused nodes: count 0, index 0 */
    }
    uint32_t count = empty ? 1u : 2u * src->leaf_count - 1u - 2u * pairs;
    size_t bytes = (size_t)count * sizeof(bvh2q_node);
    size_t stack_cap = (size_t)src->depth + 2; /* a walk holds at most one node a level and the root's pair */
    out->nodes = sys_alloc(alloc, bytes);
    out->node_count = count; /* bvh2q_free's size */
    quant_move *stack = sys_alloc(alloc, stack_cap * sizeof *stack);
    if (!out->nodes || !stack) goto fail;
    memset(out->nodes, 0, bytes);
    out->depth = src->depth;
    out->leaf_count = src->leaf_count;
    uint32_t sp = 0, next = 1;
    if (!empty) {
        stack[sp] = (quant_move){0, 0, {0}, {0}};
        memcpy(stack[sp].org, out->org, sizeof out->org);
        memcpy(stack[sp++].scale, out->scale, sizeof out->scale);
    }
    while (sp) {
        quant_move m = stack[--sp];
        const bvh_node *n = &src->nodes[m.from];
        uint32_t index = n->index, cnt = n->count, flag = 0;
        bool inner = false;
        if (is_pair(src, n)) {
            index = src->nodes[n->index].index, cnt = 2, flag = BVH2Q_PAIR;
        } else if (!cnt) {
            if (sp + 2 > stack_cap || next + 2 > count) goto fail;
            index = next, next += 2;
            inner = true;
        }
        if (index > BVH2Q_MAX_INDEX || cnt > 15u) goto fail;
        bvh2q_node *q = &out->nodes[m.to];
        q->ic = flag | index << 4 | cnt;
        for (int a = 0; a < 3; a++)
            if (!quant_lo(m.org[a], m.scale[a], n->lo[a], &q->lo[a]) || !quant_hi(m.org[a], m.scale[a], n->hi[a], &q->hi[a]))
                goto fail;
        if (inner) { /* the children go on the grid of this node's decoded box */
            bvh_node d = bvh2q_decode(q, m.org, m.scale);
            quant_move c = {n->index, index, {0}, {0}};
            bvh2q_child_grid(&d, c.org, c.scale);
            for (int a = 0; a < 3; a++)
                if (!isfinite(c.scale[a]) || c.scale[a] < 0.0f) goto fail;
            stack[sp] = c, stack[sp].from++, stack[sp++].to++;
            stack[sp++] = c;
        }
    }
    sys_free(alloc, stack, stack_cap * sizeof *stack);
    if (next == count) return true;
    stack = NULL; /* the tree was not what its leaf count says */
fail:
    sys_free(alloc, stack, stack_cap * sizeof *stack);
    bvh2q_free(alloc, out);
    return false;
}

bool bvh2q_to_bvh2(const sys_allocator *alloc, const bvh2q *src, bool split_pairs, bvh2 *out) {
    memset(out, 0, sizeof *out);
    uint32_t pairs = 0;
    for (uint32_t i = 0; i < src->node_count; i++) pairs += (src->nodes[i].ic & BVH2Q_PAIR) != 0;
    uint32_t count = src->node_count + (split_pairs ? 2 * pairs : 0);
    out->nodes = sys_alloc(alloc, (size_t)count * sizeof(bvh_node));
    if (!out->nodes) return false;
    bvh2q_decode_all(src, out->nodes);
    /* the nodes where they are, each pair's two leaves after them */
    uint32_t next = src->node_count;
    for (uint32_t i = 0; i < src->node_count; i++) {
        bvh_node d = out->nodes[i];
        if (split_pairs && (src->nodes[i].ic & BVH2Q_PAIR)) {
            for (uint32_t k = 0; k < 2; k++) {
                bvh_node *leaf = &out->nodes[next + k];
                *leaf = d;
                leaf->index = d.index + k, leaf->count = 1;
            }
            d.index = next, d.count = 0, next += 2;
        }
        out->nodes[i] = d;
    }
    out->node_count = out->node_capacity = count;
    out->depth = src->depth;
    out->leaf_count = split_pairs ? src->leaf_count : src->leaf_count - pairs;
    return true;
}

void bvh2q_decode_all(const bvh2q *q, bvh_node *out) {
    if (q->node_count == 0) return;
    out[0] = bvh2q_decode(&q->nodes[0], q->org, q->scale);
    for (uint32_t i = 0; i < q->node_count; i++) {
        const bvh_node *d = &out[i];
        if (d->count || (q->nodes[i].ic & BVH2Q_PAIR) || d->index <= i || d->index + 1 >= q->node_count) continue;
        float org[3], scale[3];
        bvh2q_child_grid(d, org, scale);
        out[d->index] = bvh2q_decode(&q->nodes[d->index], org, scale);
        out[d->index + 1] = bvh2q_decode(&q->nodes[d->index + 1], org, scale);
    }
}

void bvh2q_free(const sys_allocator *alloc, bvh2q *q) {
    if (q->nodes) sys_free(alloc, q->nodes, (size_t)q->node_count * sizeof(bvh2q_node));
    memset(q, 0, sizeof *q);
}
