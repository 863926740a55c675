/* BIH build (Waechter, Keller 2006, sec. 2.2-2.3): the global heuristic splits the node's split
 * box (not the objects' box) in the middle of its longest side and keeps each side's extreme bound
 * as its clip plane; when one side is empty the split box is halved towards the other and the
 * step repeated, so no node is made. The paper sorts the primitives to the two sides at each node
 * (a quicksort-like pass over the boxes, about 24 passes over spd_tree_s12's boxes); this builder
 * finds the same planes from one radix sort of the centroids (the radix build below). Every inner
 * node has two non-empty children; with the clip nodes at most 4n - 2 nodes are written, into an
 * allocation sized from the tree's entries, and copied to one of their count when the leaves are
 * filled. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "accel/accel.h"
#include "accel/bih/bih.h"

/* Subtrees of at most 1 / (BIH_TASK_SHARE x threads) of the primitives are tasks. */
#define BIH_TASK_SHARE 8u

/* Nodes are handed to the threads in chunks of BIH_NODE_CHUNK, one atomic per chunk: an atomic
 * add per node, and the leaves' and the depth's counters, on lines both threads wrote, held about a
 * third of the partition build's own samples (perf annotate, spd_tree_s12, two threads). A chunk
 * too short for a pair of children leaves at most
 * one node unused, and each thread's last chunk its rest; those are empty leaves (make_unused). */
#define BIH_NODE_CHUNK 256u
typedef struct bih_local {
    uint32_t next, end; /* the rest of this thread's chunk */
    uint32_t depth, unused;
    uint64_t leaves;
    uint8_t pad[RP_CACHE_LINE - 24];
} bih_local;

typedef struct bih_ctx {
    const accel_tri_input *in;
    bvh_prim *p;               /* the boxes (sorted by code by the radix build); lo[3] holds each one's id */
    bih_node *nodes;           /* node_bytes: sized from the radix tree's entries */
    size_t node_bytes;
    _Atomic uint32_t next;     /* first free node */
    bih_local *local;          /* per thread */
    float abs_pad;             /* the planes' margin (pad_lo, pad_hi); 0: none */
    /* leaf packing */
    uint32_t *block_of;        /* per position: its leaf's count at a leaf's first, else 0; then its block */
    tri4 *blocks;
    bih_node *out;             /* the nodes, copied to an allocation of their final count */
} bih_ctx;

/* A plane moved outward by the BVH's margin (bvh2_pad_boxes), as each node is written: an
 * axis-parallel ray lying in a plane, as through a vertex, then stays inside the child that plane
 * bounds instead of leaving it at t = 0 (the traversal takes a direction component of 0 as 1e-18),
 * and meets the triangles in that plane as the watertight test does. */
static inline float pad_lo(const bih_ctx *c, float x) {
    return c->abs_pad != 0.0f && fabsf(x) < INFINITY ? box_pad_lo(x, c->abs_pad) : x;
}
static inline float pad_hi(const bih_ctx *c, float x) {
    return c->abs_pad != 0.0f && fabsf(x) < INFINITY ? box_pad_hi(x, c->abs_pad) : x;
}

/* Writes a leaf of positions [begin, end) and marks its first position with its count for
 * plan_blocks (each position belongs to one leaf, so the threads' writes never meet). */
static void make_leaf(bih_ctx *c, bih_local *l, uint32_t node, uint32_t begin, uint32_t end, uint32_t depth) {
    bih_node *n = &c->nodes[node];
    uint32_t first = begin, count = end - begin;
    if (count) {
        c->block_of[begin] = count;
        for (uint32_t i = begin + 1; i < end; i++) c->block_of[i] = 0;
    }
    memcpy(&n->clip[0], &first, 4);
    memcpy(&n->clip[1], &count, 4);
    n->meta = BIH_LEAF;
    l->leaves++;
    if (depth > l->depth) l->depth = depth;
}

/* Nodes [b, e) that no node points at: empty leaves, so the copy in fill_task reads them as such. */
static void make_unused(bih_ctx *c, bih_local *l, uint32_t b, uint32_t e) {
    uint32_t zero = 0;
    for (uint32_t i = b; i < e; i++) {
        memcpy(&c->nodes[i].clip[0], &zero, 4), memcpy(&c->nodes[i].clip[1], &zero, 4);
        c->nodes[i].meta = BIH_LEAF;
    }
    l->unused += e - b;
}

/* k (1 or 2) consecutive nodes from the thread's chunk. */
static uint32_t node_alloc(bih_ctx *c, bih_local *l, uint32_t k) {
    if (l->end - l->next < k) {
        make_unused(c, l, l->next, l->end);
        l->next = atomic_fetch_add_explicit(&c->next, BIH_NODE_CHUNK, memory_order_relaxed);
        l->end = l->next + BIH_NODE_CHUNK;
    }
    uint32_t r = l->next;
    l->next += k;
    return r;
}

/* Cuts the empty space around a node's boxes off: where the node's box (the root box cut by its
 * ancestors' planes, nb) is more than BIH_CLIP_RATIO times as wide on an axis as the boxes'
 * bounds, a clip node with both planes on that axis (Sunflow's BVH2 node) goes in front of it.
 * The global heuristic never makes a node where a halving of the split box leaves one side empty,
 * so without them a node's box only shrinks on the axes its ancestors split: on spd_tree_s12 the
 * nodes' boxes had 100 times the surface area of their triangles' bounds and a ray visited
 * hundreds of leaves. At most BIH_CLIP_AXES per node, the widest gaps first; returns the node
 * the subtree goes on in. Clip nodes push nothing on a traversal's stack: they do not count
 * towards BIH_MAX_DEPTH. */
#ifndef BIH_CLIP_RATIO
#define BIH_CLIP_RATIO 1.3f
#endif
#ifndef BIH_CLIP_AXES
#define BIH_CLIP_AXES 1
#endif
static uint32_t clip_empty(bih_ctx *c, bih_local *l, uint32_t node, float nb[6], vf4 blo, vf4 bhi) {
    for (int n = 0; n < BIH_CLIP_AXES; n++) {
        int best = -1;
        float best_ratio = BIH_CLIP_RATIO;
        for (int k = 0; k < 3; k++) {
            float w = nb[3 + k] - nb[k], bw = bhi[k] - blo[k];
            if (!(blo[k] > nb[k] || bhi[k] < nb[3 + k])) continue;
            if (w > best_ratio * bw) best = k, best_ratio = bw > 0.0f ? w / bw : INFINITY;
        }
        if (best < 0) break;
        uint32_t child = node_alloc(c, l, 1);
        c->nodes[node] = (bih_node){{pad_lo(c, blo[best]), pad_hi(c, bhi[best])}, child << BIH_TAG_BITS | BIH_CLIP | (uint32_t)best};
        nb[best] = blo[best], nb[3 + best] = bhi[best];
        node = child;
    }
    return node;
}

/* ---- the radix build -------------------------------------------------------------------------
 *
 * The global heuristic's planes form a fixed sequence: the split box is halved in the middle of its
 * longest side, and every split box at the same number of halvings has the same extents, so the
 * axis of the k-th halving is the same on every path (skipped halvings included). A centroid's side
 * of each halving is then one bit of a code (the centroid quantized on each axis to as many bits as
 * that axis is halved, its bits interleaved in the halvings' order; 63 halvings), and a node's
 * plane is the highest bit in which its centroids' codes differ: the BIH is the binary radix tree
 * of the sorted codes (as an LBVH's over Morton codes). So the boxes are sorted once by code (a
 * most-significant-digit radix sort: about three passes over the boxes where the partitions took
 * 24), the tree's splits are found by binary search in the sorted codes, the boxes' bounds are
 * taken bottom-up, and the nodes (with their clip nodes, which need the ancestors' planes) are
 * written top-down. Waechter and Keller's bucket-sort preprocess (sec. 2.3) carried to the end. */

#define RX_SMALL 32u        /* ranges sorted by insertion */
#define RX_CHUNK 1024u      /* tree entries handed to a thread at a time */
#define RX_LEAF 3u
#define RX_TASK_ROOT 4u     /* flag on a subtree built (and written) by a task */
#define RX_BUCKETS 2048u   /* ranges left to the sort's tasks */
#ifndef RX_TASKS
#define RX_TASKS 4096u      /* subtrees built by tasks */
#endif

/* An entry of the radix tree: the bounds of its boxes; inner: its children's entries and the
 * plane's axis; leaf: its positions [a, b). */
typedef struct rx_node {
    float lo[3], hi[3];
    uint32_t a, b, axis;
} rx_node;

typedef struct rx_local {
    uint32_t next, end;
    uint8_t pad[RP_CACHE_LINE - 8];
} rx_local;

typedef struct rx_task {
    uint32_t entry, begin, end; /* phase 1: the range; phase 2: the node (begin) and depth (end) */
    float nb[6];
} rx_task;

/* A box's code and its position in the gathered boxes. */
typedef struct rx_key {
    uint64_t code;
    uint32_t id, pad;
} rx_key;

typedef struct rx_ctx {
    bih_ctx *c;
    uint32_t n, threads, chunks;
    rx_key *key, *key2;         /* the keys, and the sort's second buffer */
    bvh_prim *box2;             /* the boxes in the keys' order */
    double qlo[3], qscale[3];   /* twice a centroid -> [0, 2^bits) on each axis */
    int bits[3];
    uint8_t axis_of_bit[64];
    uint64_t spread[3][8][256]; /* a byte of an axis' quantized value -> its code bits */
    uint32_t (*hist)[256];      /* per chunk: a parallel pass's counts, then offsets */
    uint32_t pb, pe;            /* a parallel pass's positions, its buffer and digit */
    int psrc, shift;
    uint32_t buckets[RX_BUCKETS][3]; /* the ranges left to sort: begin, end, buffer */
    uint32_t bucket_n;
    rx_node *t;
    uint32_t t_cap;
    _Atomic uint32_t t_next;
    rx_local *tl;
    rx_task *tasks;
    uint32_t task_n, task_cap, task_max;
} rx_ctx;

/* The halving sequence of the root split box and the tables that spread a quantized coordinate's
 * bits to their places in the code (bit 62 - k: the k-th halving). */
static void rx_setup(rx_ctx *x, const float sb[6]) {
    float e[3] = {sb[3] - sb[0], sb[4] - sb[1], sb[5] - sb[2]};
    int pos[3][64], count[3] = {0, 0, 0};
    memset(x->axis_of_bit, 0, sizeof x->axis_of_bit);
    for (int k = 0; k < 63; k++) {
        int axis = e[1] > e[0] ? (e[2] > e[1] ? 2 : 1) : (e[2] > e[0] ? 2 : 0);
        e[axis] *= 0.5f;
        pos[axis][count[axis]++] = 62 - k;
        x->axis_of_bit[62 - k] = (uint8_t)axis;
    }
    memset(x->spread, 0, sizeof x->spread);
    for (int a = 0; a < 3; a++) {
        int nb = count[a] > 53 ? 53 : count[a]; /* a double holds 53 bits of the coordinate */
        x->bits[a] = nb;
        double w = 2.0 * ((double)sb[3 + a] - (double)sb[a]);
        x->qlo[a] = 2.0 * (double)sb[a];
        x->qscale[a] = w > 0.0 ? ldexp(1.0, nb) / w : 0.0;
        /* bit i of the value (from the lowest) is the (nb - 1 - i)-th halving on this axis */
        for (int i = 0; i < nb; i++)
            for (int v = 0; v < 256; v++)
                if (v >> (i & 7) & 1) x->spread[a][i >> 3][v] |= 1ull << pos[a][nb - 1 - i];
    }
}

static inline uint64_t rx_code(const rx_ctx *x, const bvh_prim *p) {
    vf4 c = p->lo + p->hi;
    uint64_t code = 0;
    for (int a = 0; a < 3; a++) {
        if (!x->bits[a]) continue;
        double t = ((double)c[a] - x->qlo[a]) * x->qscale[a];
        uint64_t max = (1ull << x->bits[a]) - 1, q = t > 0.0 ? (uint64_t)t : 0;
        if (q > max) q = max;
        for (int byte = 0; byte < (x->bits[a] + 7) / 8; byte++) code |= x->spread[a][byte][(q >> (8 * byte)) & 255];
    }
    return code;
}

/* Chunk `index` of the positions [pb, pe) of the current parallel pass. */
static void rx_chunk(const rx_ctx *x, uint32_t index, uint32_t *b, uint32_t *e) {
    uint64_t n = x->pe - x->pb;
    *b = x->pb + (uint32_t)(n * index / x->chunks), *e = x->pb + (uint32_t)(n * (index + 1) / x->chunks);
}

/* Codes of a chunk of the boxes. */
static void rx_code_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    rx_ctx *x = user;
    uint32_t b, e;
    rx_chunk(x, index, &b, &e);
    for (uint32_t i = b; i < e; i++) x->key[i] = (rx_key){rx_code(x, &x->c->p[i]), i, 0};
}

/* The highest bit in which the codes of [b, e) differ; -1 when they are all equal. */
static int rx_high_bit(const rx_key *k, uint32_t b, uint32_t e) {
    uint64_t mn = k[b].code, mx = mn;
    for (uint32_t i = b + 1; i < e; i++) mn = k[i].code < mn ? k[i].code : mn, mx = k[i].code > mx ? k[i].code : mx;
    return mn == mx ? -1 : 63 - __builtin_clzll(mn ^ mx);
}

static void rx_hist_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    rx_ctx *x = user;
    uint32_t b, e, *h = x->hist[index];
    rx_chunk(x, index, &b, &e);
    const rx_key *k = x->psrc ? x->key2 : x->key;
    memset(h, 0, 256 * sizeof *h);
    for (uint32_t i = b; i < e; i++) h[(k[i].code >> x->shift) & 255]++;
}

/* The scatter of a chunk to the other buffer (hist holds the chunk's offsets). */
static void rx_scatter_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    rx_ctx *x = user;
    uint32_t b, e, *off = x->hist[index];
    rx_chunk(x, index, &b, &e);
    const rx_key *ks = x->psrc ? x->key2 : x->key;
    rx_key *kd = x->psrc ? x->key : x->key2;
    int shift = x->shift;
    for (uint32_t i = b; i < e; i++) kd[off[(ks[i].code >> shift) & 255]++] = ks[i];
}

/* Sorts positions [b, e), held in buffer src (0: key, 1: key2), by code into buffer 0: a digit
 * from the range's highest differing bit (8 bits, fewer for small ranges), then each bucket. */
static void rx_sort(rx_ctx *x, int src, uint32_t b, uint32_t e) {
    rx_key *ks = src ? x->key2 : x->key, *kd = src ? x->key : x->key2;
    if (e - b <= RX_SMALL) { /* insertion sort */
        for (uint32_t i = b + 1; i < e; i++) {
            rx_key k = ks[i];
            uint32_t j = i;
            for (; j > b && ks[j - 1].code > k.code; j--) ks[j] = ks[j - 1];
            ks[j] = k;
        }
    }
    int hb = e - b > RX_SMALL ? rx_high_bit(ks, b, e) : -1;
    if (hb < 0) { /* sorted: into buffer 0 */
        if (src) memcpy(kd + b, ks + b, (e - b) * sizeof *kd);
        return;
    }
    int bits = e - b > 4096 ? 8 : e - b > 512 ? 6 : 4;
    uint32_t nd = 1u << bits, mask = nd - 1;
    int shift = hb >= bits - 1 ? hb - (bits - 1) : 0;
    uint32_t cnt[256], off[256], start[256];
    memset(cnt, 0, nd * sizeof *cnt);
    for (uint32_t i = b; i < e; i++) cnt[(ks[i].code >> shift) & mask]++;
    for (uint32_t k = 0, o = b; k < nd; k++) start[k] = off[k] = o, o += cnt[k];
    for (uint32_t i = b; i < e; i++) kd[off[(ks[i].code >> shift) & mask]++] = ks[i];
    for (uint32_t k = 0; k < nd; k++)
        if (cnt[k]) rx_sort(x, !src, start[k], start[k] + cnt[k]);
}

/* The boxes of a chunk of the sorted keys, in their order. */
static void rx_gather_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    rx_ctx *x = user;
    uint32_t b, e;
    rx_chunk(x, index, &b, &e);
    const bvh_prim *p = x->c->p;
    for (uint32_t i = b; i < e; i++) {
        if (i + 16 < e) __builtin_prefetch(&p[x->key[i + 16].id]);
        x->box2[i] = p[x->key[i].id];
    }
}

static void rx_bucket_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    rx_ctx *x = user;
    rx_sort(x, (int)x->buckets[index][2], x->buckets[index][0], x->buckets[index][1]);
}

static int rx_bucket_larger(const void *a, const void *b) {
    const uint32_t *x = a, *y = b;
    uint32_t nx = x[1] - x[0], ny = y[1] - y[0];
    return nx > ny ? -1 : nx < ny ? 1 : (x[0] > y[0]) - (x[0] < y[0]);
}

/* One digit of positions [b, e) (held in buffer src) by all threads; the buckets of at most a share
 * of the positions become tasks, the larger ones get a pass of their own. */
static void rx_bucket(rx_ctx *x, uint32_t b, uint32_t e, int src) {
    x->buckets[x->bucket_n][0] = b, x->buckets[x->bucket_n][1] = e, x->buckets[x->bucket_n][2] = (uint32_t)src;
    x->bucket_n++;
}

static void rx_pass_par(rx_ctx *x, sys_pool *pool, int src, uint32_t b, uint32_t e) {
    int hb = rx_high_bit(src ? x->key2 : x->key, b, e);
    if (hb < 0 || x->bucket_n + 256 > RX_BUCKETS) {
        rx_bucket(x, b, e, src);
        return;
    }
    x->shift = hb >= 7 ? hb - 7 : 0, x->pb = b, x->pe = e, x->psrc = src;
    sys_pool_parallel_for(pool, x->chunks, rx_hist_task, x);
    uint32_t o = b, bounds[257], nb = 0;
    for (uint32_t k = 0; k < 256; k++) {
        uint32_t start = o;
        for (uint32_t i = 0; i < x->chunks; i++) {
            uint32_t c = x->hist[i][k];
            x->hist[i][k] = o, o += c;
        }
        if (o > start) bounds[nb++] = start;
    }
    bounds[nb] = e;
    sys_pool_parallel_for(pool, x->chunks, rx_scatter_task, x);
    for (uint32_t k = 0; k < nb; k++) {
        uint32_t bb = bounds[k], be = bounds[k + 1];
        if (be - bb > x->n / (4 * x->threads)) rx_pass_par(x, pool, !src, bb, be);
        else rx_bucket(x, bb, be, !src);
    }
}

/* Sorts the boxes by code: the codes and the digits of large ranges by all threads, then each
 * bucket by a task. */
static void rx_sort_all(rx_ctx *x, sys_pool *pool) {
    x->pb = 0, x->pe = x->n;
    if (pool) sys_pool_parallel_for(pool, x->chunks, rx_code_task, x);
    else rx_code_task(x, 0, 0);
    if (!pool) {
        rx_sort(x, 0, 0, x->n);
        rx_gather_task(x, 0, 0);
        return;
    }
    x->bucket_n = 0;
    rx_pass_par(x, pool, 0, 0, x->n);
    qsort(x->buckets, x->bucket_n, sizeof x->buckets[0], rx_bucket_larger);
    sys_pool_parallel_for(pool, x->bucket_n, rx_bucket_task, x);
    x->pb = 0, x->pe = x->n;
    sys_pool_parallel_for(pool, x->chunks, rx_gather_task, x);
}

static uint32_t rx_alloc(rx_ctx *x, rx_local *l) {
    if (l->next == l->end) {
        l->next = atomic_fetch_add_explicit(&x->t_next, RX_CHUNK, memory_order_relaxed);
        l->end = l->next + RX_CHUNK;
    }
    return l->next++;
}

/* The plane of positions [b, e) (codes sorted and not all equal): the first position with the
 * highest differing bit set; *axis: that halving's axis. */
static uint32_t rx_split(const rx_ctx *x, uint32_t b, uint32_t e, int *axis) {
    const rx_key *k = x->key;
    int hb = 63 - __builtin_clzll(k[b].code ^ k[e - 1].code);
    uint64_t bit = 1ull << hb;
    uint32_t lo = b + 1, hi = e - 1; /* k[b] has it clear, k[e - 1] set */
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (k[mid].code & bit) hi = mid;
        else lo = mid + 1;
    }
    *axis = x->axis_of_bit[hb];
    return lo;
}

static inline bool rx_is_leaf(const rx_ctx *x, uint32_t b, uint32_t e) {
    return e - b <= BIH_LEAF_SIZE || x->key[b].code == x->key[e - 1].code;
}

/* Builds the subtree of positions [b, e) in entry `entry`, bounds included. */
static void rx_tree(rx_ctx *x, rx_local *l, uint32_t entry, uint32_t b, uint32_t e) {
    rx_node *r = &x->t[entry];
    if (rx_is_leaf(x, b, e)) {
        const bvh_prim *p = x->c->p;
        vf4 lo = p[b].lo, hi = p[b].hi;
        for (uint32_t i = b + 1; i < e; i++) lo = vf4_min(lo, p[i].lo), hi = vf4_max(hi, p[i].hi);
        for (int k = 0; k < 3; k++) r->lo[k] = lo[k], r->hi[k] = hi[k];
        r->a = b, r->b = e, r->axis = RX_LEAF;
        return;
    }
    int axis;
    uint32_t m = rx_split(x, b, e, &axis);
    uint32_t left = rx_alloc(x, l), right = rx_alloc(x, l);
    rx_tree(x, l, left, b, m);
    rx_tree(x, l, right, m, e);
    const rx_node *L = &x->t[left], *R = &x->t[right];
    for (int k = 0; k < 3; k++) r->lo[k] = fminf(L->lo[k], R->lo[k]), r->hi[k] = fmaxf(L->hi[k], R->hi[k]);
    r->a = left, r->b = right, r->axis = (uint32_t)axis;
}

/* The top of the tree on the calling thread: subtrees of at most task_max positions are tasks. */
static void rx_tree_top(rx_ctx *x, uint32_t entry, uint32_t b, uint32_t e) {
    if (x->task_n == x->task_cap) { /* the list full: built here */
        rx_tree(x, &x->tl[0], entry, b, e);
        return;
    }
    if (e - b <= x->task_max || rx_is_leaf(x, b, e)) {
        x->tasks[x->task_n++] = (rx_task){entry, b, e, {0}};
        x->t[entry].axis = RX_TASK_ROOT; /* until the task writes it */
        return;
    }
    int axis;
    uint32_t m = rx_split(x, b, e, &axis);
    uint32_t left = rx_alloc(x, &x->tl[0]), right = rx_alloc(x, &x->tl[0]);
    x->t[entry].a = left, x->t[entry].b = right, x->t[entry].axis = (uint32_t)axis;
    rx_tree_top(x, left, b, m);
    rx_tree_top(x, right, m, e);
}

static void rx_tree_task(void *user, uint32_t index, uint32_t thread) {
    rx_ctx *x = user;
    rx_task t = x->tasks[index];
    rx_tree(x, &x->tl[thread], t.entry, t.begin, t.end);
    x->t[t.entry].axis |= RX_TASK_ROOT;
}

/* Bounds of the top of the tree, once its tasks are done. */
static void rx_tree_bounds(rx_ctx *x, uint32_t entry) {
    rx_node *r = &x->t[entry];
    if (r->axis & RX_TASK_ROOT || r->axis == RX_LEAF) return;
    rx_tree_bounds(x, r->a);
    rx_tree_bounds(x, r->b);
    const rx_node *L = &x->t[r->a], *R = &x->t[r->b];
    for (int k = 0; k < 3; k++) r->lo[k] = fminf(L->lo[k], R->lo[k]), r->hi[k] = fmaxf(L->hi[k], R->hi[k]);
}

/* Writes the BIH nodes of the subtree at entry `entry` into node `node`, as the partition build's
 * split did: the clip node in front (from the node's box nb, the root box cut by its ancestors'
 * planes), then the leaf, or the node with its two planes and its children. With stop, subtrees
 * that a task built are left to a task of their own. */
static void rx_emit(rx_ctx *x, bih_local *l, uint32_t entry, uint32_t node, float nb[6], uint32_t depth, bool stop) {
    bih_ctx *c = x->c;
    for (;;) {
        const rx_node *r = &x->t[entry];
        if (stop && (r->axis & RX_TASK_ROOT)) {
            rx_task *t = &x->tasks[x->task_n++];
            *t = (rx_task){entry, node, depth, {0}};
            memcpy(t->nb, nb, sizeof t->nb);
            return;
        }
        vf4 blo = {r->lo[0], r->lo[1], r->lo[2], 0.0f}, bhi = {r->hi[0], r->hi[1], r->hi[2], 0.0f};
        node = clip_empty(c, l, node, nb, blo, bhi);
        uint32_t axis = r->axis & ~RX_TASK_ROOT;
        if (axis == RX_LEAF || depth >= BIH_MAX_DEPTH) {
            make_leaf(c, l, node, r->a, r->b, depth);
            return;
        }
        const rx_node *L = &x->t[r->a], *R = &x->t[r->b];
        uint32_t child = node_alloc(c, l, 2);
        c->nodes[node] = (bih_node){{pad_hi(c, L->hi[axis]), pad_lo(c, R->lo[axis])}, child << BIH_TAG_BITS | axis};
        float nl[6];
        memcpy(nl, nb, sizeof nl);
        if (L->hi[axis] < nl[3 + axis]) nl[3 + axis] = L->hi[axis];
        if (R->lo[axis] > nb[axis]) nb[axis] = R->lo[axis];
        rx_emit(x, l, r->a, child, nl, depth + 1, stop);
        entry = r->b, node = child + 1, depth++;
    }
}

static void rx_emit_task(void *user, uint32_t index, uint32_t thread) {
    rx_ctx *x = user;
    rx_task t = x->tasks[index];
    rx_emit(x, &x->c->local[thread], t.entry, t.begin, t.nb, t.end, false);
}

/* Numbers the blocks: every position gets its block (a leaf's triangles fill blocks of four in
 * order, its first position starting one), as the BVH's tri_pack_plan; make_leaf has marked each
 * leaf's first position with its count. */
static uint32_t plan_blocks(bih_ctx *c, uint32_t n) {
    uint32_t next = 0, block = 0, k = 0; /* k: position in the current leaf */
    for (uint32_t p = 0; p < n; p++) {
        uint32_t count = c->block_of[p];
        if (count) block = next, next += (count + 3) / 4, k = 0;
        c->block_of[p] = block + k++ / 4;
    }
    return next;
}

typedef struct fill_ctx {
    bih_ctx *c;
    uint32_t node_count, n, chunks;
} fill_ctx;

/* First position of chunk `index`, moved on to the start of a block. */
static uint32_t fill_chunk_start(const fill_ctx *f, uint32_t index) {
    uint32_t p = (uint32_t)((uint64_t)f->n * index / f->chunks);
    while (p > 0 && p < f->n && f->c->block_of[p] == f->c->block_of[p - 1]) p++;
    return p;
}

/* Fills the blocks of a chunk of the positions (the scene's fill, accel_tri_input.fill, reading
 * each position's id from its box, lo's w lane) and copies a chunk of the nodes to their final
 * allocation, pointing the leaves at their blocks. */
static void fill_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const fill_ctx *f = user;
    bih_ctx *c = f->c;
    uint32_t pb = fill_chunk_start(f, index), pe = fill_chunk_start(f, index + 1);
    const uint32_t *ids = (const uint32_t *)(const void *)&c->p[0].lo[3];
    c->in->fill(c->in->user, c->in->refs, ids, sizeof(bvh_prim) / sizeof(uint32_t), c->block_of, pb, pe, c->blocks);
    uint64_t nn = f->node_count;
    uint32_t b = (uint32_t)(nn * index / f->chunks), e = (uint32_t)(nn * (index + 1) / f->chunks);
    for (uint32_t i = b; i < e; i++) {
        bih_node *nd = &c->out[i];
        *nd = c->nodes[i];
        if (nd->meta != BIH_LEAF) continue;
        uint32_t first, count;
        memcpy(&first, &nd->clip[0], 4), memcpy(&count, &nd->clip[1], 4);
        uint32_t block = count ? c->block_of[first] : 0, blocks = (count + 3) / 4;
        memcpy(&nd->clip[0], &block, 4), memcpy(&nd->clip[1], &blocks, 4);
    }
}

/* Stamps each box with its id (lo's w lane, unused by the build). */
typedef struct stamp_ctx {
    bvh_prim *p;
    uint32_t n, chunks;
} stamp_ctx;

static void stamp_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const stamp_ctx *s = user;
    uint32_t b = (uint32_t)((uint64_t)s->n * index / s->chunks), e = (uint32_t)((uint64_t)s->n * (index + 1) / s->chunks);
    for (uint32_t i = b; i < e; i++) {
        float f;
        memcpy(&f, &i, 4);
        s->p[i].lo[3] = f;
    }
}

/* Sorts the boxes by code (into *sorted, which the caller frees: n boxes; c->p points at them),
 * then writes the nodes into c->nodes (allocated here, c->node_bytes, from node 0; c->local's
 * counters); false when out of memory. */
static bool rx_build(bih_ctx *c, const sys_allocator *a, sys_pool *pool, uint32_t threads, const float sb[6], float nb[6],
                     bvh_prim **sorted) {
    rx_ctx *x = sys_alloc(a, sizeof *x);
    if (!x) return false;
    memset(x, 0, sizeof *x);
    uint32_t n = c->in->count;
    x->c = c, x->n = n, x->threads = threads, x->chunks = pool ? threads * 4 : 1;
    rx_setup(x, sb);
    x->t_cap = 2 * n + RX_CHUNK * (threads + 1); /* 2n - 1 entries at most, and the threads' chunks */
    x->task_cap = pool ? RX_TASKS : 1;
    x->task_max = pool ? n / (BIH_TASK_SHARE * threads) : n;
    size_t key_bytes = (size_t)n * sizeof(rx_key), t_bytes = (size_t)x->t_cap * sizeof(rx_node);
    size_t tl_bytes = threads * sizeof(rx_local);
    size_t hist_bytes = x->chunks * sizeof *x->hist, task_bytes = x->task_cap * sizeof(rx_task);
    x->key = sys_alloc(a, key_bytes);
    x->key2 = sys_alloc(a, key_bytes);
    x->box2 = *sorted = sys_alloc(a, (size_t)n * sizeof(bvh_prim));
    x->t = sys_alloc(a, t_bytes);
    x->tl = sys_alloc(a, tl_bytes);
    x->hist = sys_alloc(a, hist_bytes);
    x->tasks = sys_alloc(a, task_bytes);
    bool ok = x->key && x->key2 && x->box2 && x->t && x->tl && x->hist && x->tasks;
    if (ok) {
        memset(x->tl, 0, tl_bytes);
        atomic_store(&x->t_next, 1);
        rx_sort_all(x, pool);
        c->p = x->box2;
        /* phase 1: the tree's entries and their bounds */
        rx_tree_top(x, 0, 0, n);
        if (pool && x->task_n > 1) sys_pool_parallel_for(pool, x->task_n, rx_tree_task, x);
        else
            for (uint32_t i = 0; i < x->task_n; i++) rx_tree_task(x, i, 0);
        rx_tree_bounds(x, 0);
        /* phase 2: the nodes, top-down. Each entry is a node, and may have a clip node in front
         * (clip_empty); a chunk of nodes (node_alloc) leaves at most one unused, and each
         * thread's last chunk its rest. */
        size_t entries = atomic_load(&x->t_next);
        c->node_bytes = (2 * entries + 2 * entries / (BIH_NODE_CHUNK - 1) + (size_t)BIH_NODE_CHUNK * (threads + 1) + 1) *
                        sizeof(bih_node);
        c->nodes = sys_alloc(a, c->node_bytes);
        ok = c->nodes != NULL;
    }
    if (ok) {
        x->task_n = 0;
        rx_emit(x, &c->local[0], 0, 0, nb, 1, pool != NULL);
        if (pool && x->task_n > 1) sys_pool_parallel_for(pool, x->task_n, rx_emit_task, x);
        else
            for (uint32_t i = 0; i < x->task_n; i++) rx_emit_task(x, i, 0);
    }
    sys_free(a, x->key, key_bytes), sys_free(a, x->key2, key_bytes);
    sys_free(a, x->t, t_bytes), sys_free(a, x->tl, tl_bytes);
    sys_free(a, x->hist, hist_bytes), sys_free(a, x->tasks, task_bytes);
    sys_free(a, x, sizeof *x);
    return ok;
}

static bool bih_build(const sys_allocator *a, sys_pool *pool, accel_tri_input *in, accel_built *out) {
    memset(out, 0, sizeof *out);
    uint32_t n = in->count;
    bih_ctx c = {.in = in, .p = in->boxes};
    uint32_t threads = pool && n >= 4096 ? (uint32_t)sys_pool_threads(pool) : 1;
    if (threads < 2) pool = NULL, threads = 1;
    size_t local_bytes = threads * sizeof(bih_local), block_of_bytes = (size_t)n * sizeof(uint32_t) + 4;
    c.block_of = sys_alloc(a, block_of_bytes);
    c.local = sys_alloc(a, local_bytes);
    if (!c.block_of || !c.local) {
        sys_free(a, c.block_of, block_of_bytes), sys_free(a, c.local, local_bytes);
        return false;
    }
    memset(c.local, 0, local_bytes);
    stamp_ctx st = {in->boxes, n, pool ? threads * 4 : 1};
    if (pool) sys_pool_parallel_for(pool, st.chunks, stamp_task, &st);
    else stamp_task(&st, 0, 0);
    box3 b = in->bounds;
    float sb[6] = {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z}, nb[6];
    memcpy(out->bounds, sb, sizeof sb);
    memcpy(nb, sb, sizeof nb);
    c.abs_pad = box_pad_abs(sb, sb + 3);
    atomic_store(&c.next, 1);
    bvh_prim *sorted = NULL;
    bool ok = rx_build(&c, a, pool, threads, sb, nb, &sorted);
    uint32_t node_count = atomic_load(&c.next), depth = 0, unused = 0, blocks = 0;
    uint64_t leaves = 0;
    size_t out_bytes = 0;
    if (ok) {
        for (uint32_t t = 0; t < threads; t++) {
            bih_local *l = &c.local[t];
            make_unused(&c, l, l->next, l->end);
            depth = l->depth > depth ? l->depth : depth, unused += l->unused, leaves += l->leaves;
        }
        if (c.abs_pad != 0.0f)
            for (int k = 0; k < 3; k++)
                out->bounds[k] = box_pad_lo(out->bounds[k], c.abs_pad), out->bounds[3 + k] = box_pad_hi(out->bounds[3 + k], c.abs_pad);
        blocks = plan_blocks(&c, n);
        c.blocks = accel_blocks_alloc(a, blocks);
        out_bytes = (size_t)node_count * sizeof(bih_node);
        c.out = sys_alloc(a, out_bytes);
        ok = c.blocks != NULL && c.out != NULL;
    }
    if (ok) {
        fill_ctx f = {&c, node_count, n, pool ? threads * 8 : 1};
        if (pool) sys_pool_parallel_for(pool, f.chunks, fill_task, &f);
        else fill_task(&f, 0, 0);
    }
    sys_free(a, sorted, (size_t)n * sizeof(bvh_prim));
    sys_free(a, c.block_of, block_of_bytes);
    sys_free(a, c.nodes, c.node_bytes);
    sys_free(a, c.local, local_bytes);
    if (!ok) {
        sys_free(a, c.out, out_bytes);
        if (c.blocks) sys_free(a, c.blocks, ((size_t)blocks + 1) * sizeof(tri4));
        return false;
    }
    out->nodes = c.out;
    out->node_bytes = out_bytes;
    out->blocks = c.blocks;
    out->block_count = blocks;
    out->root_depth = depth;
    out->nodes_total = node_count - unused;
    out->leaves = leaves;
    out->inner_nodes = out->nodes_total - leaves;
    out->tri_refs = n;
    out->sah_cost = 0.0; /* the global heuristic does not estimate it */
    return true;
}

RP_HIDDEN const accel_ops accel_bih = {"bih", bih_build, &bih_kernels, NULL};
