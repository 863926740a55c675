/* Conversion of the canonical binary BVH to a wide layout: each wide node takes a binary node's
 * children and keeps opening the inner child of largest surface area until it holds `width`
 * children (the usual BVH collapse, as in Embree's BVH4/8 and tinybvh's ConvertFrom). */
#include <math.h>
#include <string.h>

#include "accel/bvh/bvh.h"

typedef struct conv_ctx {
    const bvh2 *src;
    int width;
    uint8_t *nodes; /* NULL while counting */
    uint32_t stride;
    bvhw_leaf_fn leaf;
    void *leaf_user;
} conv_ctx;

static double node_area(const bvh_node *n) {
    box3 b = {v3(n->lo[0], n->lo[1], n->lo[2]), v3(n->hi[0], n->hi[1], n->hi[2])};
    return box3_half_area(b);
}

static bool is_leaf(const bvh_node *n) { return n->count != 0 || n->index == 0; }

/* Fills wide node `dst` from binary inner node `src_index` (only numbers its children while
 * counting); inner children take the ids *next, *next + 1, ... and are returned in `pending`
 * (pairs of wide node, binary node). False when a leaf does not fit. */
static bool fill_node(const conv_ctx *c, uint32_t dst, uint32_t src_index, uint32_t *next, uint32_t *pending,
                      uint32_t *pending_count) {
    const bvh_node *nodes = c->src->nodes;
    uint32_t kids[16];
    double area[16]; /* of each inner child; -1 for leaves */
    int count = 0;
    const bvh_node *root = &nodes[src_index];
    if (is_leaf(root)) {
        kids[count++] = src_index; /* a tree that is a single leaf */
    } else {
        for (int i = 0; i < 2; i++) {
            kids[count] = root->index + (uint32_t)i;
            const bvh_node *k = &nodes[kids[count]];
            area[count++] = is_leaf(k) ? -1.0 : node_area(k);
        }
        while (count < c->width) {
            int best = -1;
            double best_area = -1.0;
            for (int i = 0; i < count; i++)
                if (area[i] > best_area) best = i, best_area = area[i];
            if (best < 0) break;
            uint32_t open = kids[best];
            /* keep the tree's left-to-right order: replace by left, insert right after it */
            for (int i = count; i > best + 1; i--) kids[i] = kids[i - 1], area[i] = area[i - 1];
            for (int i = 0; i < 2; i++) {
                kids[best + i] = nodes[open].index + (uint32_t)i;
                const bvh_node *k = &nodes[kids[best + i]];
                area[best + i] = is_leaf(k) ? -1.0 : node_area(k);
            }
            count++;
        }
    }
    int w = c->width;
    if (!c->nodes) {
        for (int i = 0; i < count; i++) {
            if (is_leaf(&nodes[kids[i]])) continue;
            pending[(*pending_count)++] = (*next)++;
            pending[(*pending_count)++] = kids[i];
        }
        return true;
    }
    float *b = (float *)(c->nodes + (size_t)dst * c->stride);
    uint32_t *child = (uint32_t *)(b + 6 * w);
    bool ok = true;
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
                ok = false;
                child[i] = BVHW_EMPTY;
                continue;
            }
            child[i] = BVHW_LEAF | first << 4 | items;
        } else {
            uint32_t id = (*next)++;
            child[i] = id;
            pending[(*pending_count)++] = id;
            pending[(*pending_count)++] = kids[i];
        }
    }
    return ok;
}

/* Converts the subtree of binary node `src` into wide node `dst` and its descendants, depth
 * first (a subtree's nodes lie together in memory), numbering them from *next; counts only when
 * c->nodes is NULL. */
static bool convert_subtree(const conv_ctx *c, uint32_t dst, uint32_t src, uint32_t *next) {
    uint32_t pending[2 * 16 * (BVHW_MAX_DEPTH + 2)];
    uint32_t pc = 0;
    bool ok = fill_node(c, dst, src, next, pending, &pc);
    while (pc) {
        /* pop the last pushed pair; order children so the first child is converted first */
        uint32_t src_index = pending[--pc];
        uint32_t d = pending[--pc];
        uint32_t before = pc;
        ok &= fill_node(c, d, src_index, next, pending, &pc);
        /* reverse the newly pushed pairs so the leftmost child is popped next */
        uint32_t pairs = (pc - before) / 2;
        for (uint32_t i = 0; i < pairs / 2; i++) {
            uint32_t a = before + 2 * i, b = before + 2 * (pairs - 1 - i);
            uint32_t t0 = pending[a], t1 = pending[a + 1];
            pending[a] = pending[b], pending[a + 1] = pending[b + 1];
            pending[b] = t0, pending[b + 1] = t1;
        }
    }
    return ok;
}

/* The top of the tree is converted breadth first until there are enough open subtrees for the
 * threads; each subtree is then counted, given its range of ids after the top's, and converted,
 * all in parallel. The numbering depends only on the tree, not on the threads' timing. */
#define WIDE_SUBTREES 64u

typedef struct wide_job {
    const conv_ctx *c;
    const uint32_t *roots; /* pairs of wide node, binary node */
    uint32_t *base;        /* per subtree: its first descendant id; counting: its descendant count */
    bool *ok;
} wide_job;

static void count_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const wide_job *j = user;
    uint32_t next = 0;
    convert_subtree(j->c, j->roots[2 * index], j->roots[2 * index + 1], &next);
    j->base[index] = next;
}

static void convert_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const wide_job *j = user;
    uint32_t next = j->base[index];
    j->ok[index] = convert_subtree(j->c, j->roots[2 * index], j->roots[2 * index + 1], &next);
}

/* The top: breadth first from the root until WIDE_SUBTREES inner children are open; returns the
 * number of ids used (top nodes and open subtrees' roots) and the open subtrees in `roots`. */
static uint32_t convert_top(const conv_ctx *c, uint32_t *roots, uint32_t *root_count, bool *ok) {
    /* a FIFO that is never wrapped: it stops growing at its capacity (the rest are subtrees) */
    uint32_t queue[8 * (WIDE_SUBTREES + 16)];
    uint32_t head = 0, tail = 0, next = 1;
    uint32_t pc = 0;
    *ok = fill_node(c, 0, 0, &next, queue, &pc);
    tail = pc;
    while (head < tail && (tail - head) / 2 < WIDE_SUBTREES && tail + 2 * 16 <= 8 * (WIDE_SUBTREES + 16)) {
        uint32_t d = queue[head++], src = queue[head++];
        uint32_t add = 0;
        *ok &= fill_node(c, d, src, &next, queue + tail, &add);
        tail += add;
    }
    *root_count = (tail - head) / 2;
    memcpy(roots, queue + head, (size_t)(tail - head) * sizeof(uint32_t));
    return next;
}

bool bvhw_from_bvh2(const sys_allocator *alloc, sys_pool *pool, const bvh2 *src, int width, bvhw_leaf_fn leaf,
                    void *leaf_user, bvhw *out) {
    memset(out, 0, sizeof *out);
    conv_ctx c = {.src = src, .width = width, .leaf = leaf, .leaf_user = leaf_user};
    c.stride = bvhw_node_bytes(width);
    uint32_t roots[2 * (WIDE_SUBTREES + 16)], base[WIDE_SUBTREES + 16], count = 0;
    bool ok[WIDE_SUBTREES + 16], top_ok;
    wide_job j = {.c = &c, .roots = roots, .base = base, .ok = ok};
    /* count: the top, then each subtree's descendants */
    uint32_t total = convert_top(&c, roots, &count, &top_ok);
    if (pool) sys_pool_parallel_for(pool, count, count_task, &j);
    else
        for (uint32_t i = 0; i < count; i++) count_task(&j, i, 0);
    for (uint32_t i = 0; i < count; i++) {
        uint32_t n = base[i];
        base[i] = total;
        total += n;
    }
    size_t bytes = (size_t)total * c.stride;
    c.nodes = sys_alloc(alloc, bytes);
    if (!c.nodes) return false;
    /* convert: the top again (the same ids), then the subtrees */
    convert_top(&c, roots, &count, &top_ok);
    if (pool) sys_pool_parallel_for(pool, count, convert_task, &j);
    else
        for (uint32_t i = 0; i < count; i++) convert_task(&j, i, 0);
    bool all = top_ok;
    for (uint32_t i = 0; i < count; i++) all &= ok[i];
    if (!all) {
        sys_free(alloc, c.nodes, bytes);
        return false;
    }
    out->width = width;
    out->nodes = c.nodes;
    out->node_count = total;
    out->bytes = bytes;
    return true;
}

void bvhw_free(const sys_allocator *alloc, bvhw *bvh) {
    if (bvh->nodes) sys_free(alloc, bvh->nodes, bvh->bytes);
    memset(bvh, 0, sizeof *bvh);
}

bool bvhw_compact(const sys_allocator *alloc, bvhw *bvh) {
    const int w = bvh->width;
    const uint32_t n = bvh->node_count, stride = bvhw_node_bytes(w);
    if (bvh->compact || !bvh->nodes || n == 0) return true;
    uint32_t max_s = 0;
    while ((w >> (max_s + 1)) >= 2 && max_s < BVHW_KIND_MASK) max_s++;
    /* each node's kind and 64-byte offset, the nodes in the order they were numbered */
    uint32_t *ref = sys_alloc(alloc, (size_t)n * sizeof(uint32_t));
    if (!ref) return false;
    uint64_t units = 0;
    for (uint32_t i = 0; i < n; i++) {
        const uint32_t *child = (const uint32_t *)((const char *)bvh->nodes + (size_t)i * stride + 6u * 4u * (size_t)w);
        int k = 0;
        for (int q = 0; q < w; q++)
            if (child[q] != BVHW_EMPTY) k = q + 1;
        uint32_t s = 0;
        while (i != 0 && s < max_s && (w >> (s + 1)) >= k) s++;
        ref[i] = (uint32_t)units << BVHW_KIND_BITS | s;
        units += bvhw_kind_bytes(w, s) / 64u;
        if (units >= (1u << (31 - BVHW_KIND_BITS))) { /* past what a reference can address */
            sys_free(alloc, ref, (size_t)n * sizeof(uint32_t));
            return false;
        }
    }
    size_t bytes = (size_t)units * 64u + BVHW_TAIL_PAD;
    char *out = sys_alloc(alloc, bytes);
    if (!out) {
        sys_free(alloc, ref, (size_t)n * sizeof(uint32_t));
        return false;
    }
    memset(out, 0, bytes);
    for (uint32_t i = 0; i < n; i++) {
        const float *b = (const float *)((const char *)bvh->nodes + (size_t)i * stride);
        const uint32_t *child = (const uint32_t *)(b + 6 * w);
        const int kw = w >> (ref[i] & BVHW_KIND_MASK);
        float *d = (float *)(out + (size_t)(ref[i] >> BVHW_KIND_BITS) * 64u);
        uint32_t *dc = (uint32_t *)(d + 6 * kw);
        for (int p = 0; p < 6; p++) memcpy(d + p * kw, b + p * w, (size_t)kw * sizeof(float));
        for (int q = 0; q < kw; q++) dc[q] = (child[q] & BVHW_LEAF) ? child[q] : ref[child[q]];
    }
    sys_free(alloc, ref, (size_t)n * sizeof(uint32_t));
    sys_free(alloc, bvh->nodes, bvh->bytes);
    bvh->nodes = out;
    bvh->bytes = bytes;
    bvh->compact = true;
    return true;
}
