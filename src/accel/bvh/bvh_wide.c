/* Conversion of the canonical binary BVH to a wide layout: each wide node takes a binary node's
 * children and keeps opening the inner child of largest surface area until it holds `width`
 * children (the usual BVH collapse, as in Embree's BVH4/8 and tinybvh's ConvertFrom). */
#include <math.h>
#include <string.h>

#include "accel/bvh/bvh.h"

typedef struct conv_ctx {
    const bvh2 *src;
    int width;
    uint8_t *nodes;
    uint32_t node_count, node_capacity;
    uint32_t stride;
    bvhw_leaf_fn leaf;
    void *leaf_user;
    bool failed;
} conv_ctx;

static double node_area(const bvh_node *n) {
    box3 b = {v3(n->lo[0], n->lo[1], n->lo[2]), v3(n->hi[0], n->hi[1], n->hi[2])};
    return box3_half_area(b);
}

static bool is_leaf(const bvh_node *n) { return n->count != 0 || n->index == 0; }

/* Fills wide node `dst` from binary inner node `src_index`; returns the binary children that
 * became wide inner nodes in `pending` (pairs of wide node, slot). */
static void fill_node(conv_ctx *c, uint32_t dst, uint32_t src_index, uint32_t *pending, uint32_t *pending_count) {
    const bvh_node *nodes = c->src->nodes;
    uint32_t kids[16];
    int count = 0;
    const bvh_node *root = &nodes[src_index];
    if (is_leaf(root)) {
        kids[count++] = src_index; /* a tree that is a single leaf */
    } else {
        kids[count++] = root->index;
        kids[count++] = root->index + 1;
        while (count < c->width) {
            int best = -1;
            double best_area = -1.0;
            for (int i = 0; i < count; i++) {
                const bvh_node *k = &nodes[kids[i]];
                if (!is_leaf(k) && node_area(k) > best_area) best = i, best_area = node_area(k);
            }
            if (best < 0) break;
            uint32_t open = kids[best];
            /* keep the tree's left-to-right order: replace by left, insert right after it */
            for (int i = count; i > best + 1; i--) kids[i] = kids[i - 1];
            kids[best] = nodes[open].index;
            kids[best + 1] = nodes[open].index + 1;
            count++;
        }
    }
    int w = c->width;
    float *b = (float *)(c->nodes + (size_t)dst * c->stride);
    uint32_t *child = (uint32_t *)(b + 6 * w);
    for (int i = 0; i < w; i++) {
        if (i >= count) {
            b[0 * w + i] = INFINITY, b[1 * w + i] = -INFINITY;
            b[2 * w + i] = INFINITY, b[3 * w + i] = -INFINITY;
            b[4 * w + i] = INFINITY, b[5 * w + i] = -INFINITY;
            child[i] = BVHW_EMPTY;
            continue;
        }
        const bvh_node *k = &nodes[kids[i]];
        b[0 * w + i] = k->lo[0], b[1 * w + i] = k->hi[0];
        b[2 * w + i] = k->lo[1], b[3 * w + i] = k->hi[1];
        b[4 * w + i] = k->lo[2], b[5 * w + i] = k->hi[2];
        if (is_leaf(k)) {
            uint32_t first = 0, items = 0;
            if (k->count == 0) {
                child[i] = BVHW_EMPTY; /* empty scene: the box is empty too */
                b[0 * w + i] = INFINITY, b[1 * w + i] = -INFINITY;
                continue;
            }
            if (!c->leaf(c->leaf_user, k, &first, &items) || items == 0 || items > BVHW_MAX_ITEMS ||
                first > BVHW_MAX_FIRST) {
                c->failed = true;
                child[i] = BVHW_EMPTY;
                continue;
            }
            child[i] = BVHW_LEAF | first << 4 | items;
        } else {
            uint32_t id = c->node_count++;
            child[i] = id;
            pending[(*pending_count)++] = id;
            pending[(*pending_count)++] = kids[i];
        }
    }
}

bool bvhw_from_bvh2(const sys_allocator *alloc, const bvh2 *src, int width, bvhw_leaf_fn leaf,
                    void *leaf_user, bvhw *out) {
    memset(out, 0, sizeof *out);
    conv_ctx c = {.src = src, .width = width, .leaf = leaf, .leaf_user = leaf_user};
    c.stride = bvhw_node_bytes(width);
    uint32_t inner = src->node_count > src->leaf_count ? src->node_count - src->leaf_count : 0;
    c.node_capacity = inner + 1;
    size_t bytes = (size_t)c.node_capacity * c.stride;
    c.nodes = sys_alloc(alloc, bytes);
    /* depth-first, so a subtree's nodes lie together in memory */
    size_t pend_size = (size_t)2 * 16 * (BVHW_MAX_DEPTH + 2) * sizeof(uint32_t);
    uint32_t *pending = sys_alloc(alloc, pend_size);
    if (!c.nodes || !pending) {
        sys_free(alloc, c.nodes, bytes);
        sys_free(alloc, pending, pend_size);
        return false;
    }
    uint32_t pc = 0;
    c.node_count = 1;
    fill_node(&c, 0, 0, pending, &pc);
    while (pc) {
        /* pop the last pushed pair; order children so the first child is converted first */
        uint32_t src_index = pending[--pc];
        uint32_t dst = pending[--pc];
        uint32_t before = pc;
        fill_node(&c, dst, src_index, pending, &pc);
        /* reverse the newly pushed pairs so the leftmost child is popped next */
        uint32_t pairs = (pc - before) / 2;
        for (uint32_t i = 0; i < pairs / 2; i++) {
            uint32_t a = before + 2 * i, b = before + 2 * (pairs - 1 - i);
            uint32_t t0 = pending[a], t1 = pending[a + 1];
            pending[a] = pending[b], pending[a + 1] = pending[b + 1];
            pending[b] = t0, pending[b + 1] = t1;
        }
    }
    sys_free(alloc, pending, pend_size);
    if (c.failed) {
        sys_free(alloc, c.nodes, bytes);
        return false;
    }
    /* the array was sized for the binary tree's inner nodes; keep only the nodes made */
    size_t used = (size_t)c.node_count * c.stride;
    void *exact = sys_alloc(alloc, used);
    if (exact) {
        memcpy(exact, c.nodes, used);
        sys_free(alloc, c.nodes, bytes);
        c.nodes = exact, bytes = used;
    }
    out->width = width;
    out->nodes = c.nodes;
    out->node_count = c.node_count;
    out->bytes = bytes;
    return true;
}

void bvhw_free(const sys_allocator *alloc, bvhw *bvh) {
    if (bvh->nodes) sys_free(alloc, bvh->nodes, bvh->bytes);
    memset(bvh, 0, sizeof *bvh);
}
