/* BIH build (Waechter, Keller 2006, sec. 2.2-2.3): the global heuristic splits the node's split
 * box (not the objects' box) in the middle of its longest side and keeps each side's extreme bound
 * as its clip plane; when one side is empty the split box is halved towards the other and the
 * step repeated, so no node is made. The paper sorts the primitives to the two sides at each node
 * (a quicksort-like pass over the boxes, about 24 passes over spd_tree_s12's boxes); this builder
 * finds the same planes from one radix sort of the centroids (the radix build below). Every inner
 * node has two non-empty children; with the clip nodes at most 4n - 2 nodes are written, into an
 * allocation sized from the tree's entries, and copied to one of their count at the end. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "accel/accel.h"
#include "accel/bih/bih.h"

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
    bih_node *nodes;           /* node_bytes: sized from the radix tree's entries */
    size_t node_bytes;
    _Atomic uint32_t next;     /* first free node */
    bih_local *local;          /* per thread */
    float abs_pad;             /* the planes' margin (pad_lo, pad_hi); 0: none */
    /* leaf packing */
    uint32_t *block_of;        /* per position: its block (accel_tri_input.fill) */
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

/* Writes a leaf of positions [begin, end), its triangles in blocks from `block` on (four to a
 * block, in order), and each position's block for the fill (each position belongs to one leaf, so
 * the threads' writes never meet). */
static void make_leaf(bih_ctx *c, bih_local *l, uint32_t node, uint32_t begin, uint32_t end, uint32_t block, uint32_t depth) {
    bih_node *n = &c->nodes[node];
    uint32_t count = end - begin, blocks = (count + 3) / 4;
    for (uint32_t i = 0; i < count; i++) c->block_of[begin + i] = block + i / 4;
    if (!count) block = 0;
    memcpy(&n->clip[0], &block, 4);
    memcpy(&n->clip[1], &blocks, 4);
    n->meta = BIH_LEAF;
    l->leaves++;
    if (depth > l->depth) l->depth = depth;
}

/* Nodes [b, e) that no node points at: empty leaves, so the final copy holds no garbage. */
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
 * of the sorted codes (as an LBVH's over Morton codes). So the (code, id) keys are sorted once (a
 * most-significant-digit radix sort: about three passes where the partitions took 24 over the
 * boxes), the tree's splits are found by binary search in the sorted codes, the boxes' bounds are
 * taken bottom-up, and the nodes (with their clip nodes, which need the ancestors' planes) are
 * written top-down. Waechter and Keller's bucket-sort preprocess (sec. 2.3) carried to the end.
 *
 * The codes with a common prefix are one subtree of a radix tree (a node's entries are all the
 * codes that share the bits above its plane). Each bucket the sort leaves to a task (all the codes
 * with the prefix of the digits sorted so far) is therefore a subtree: the task sorts it and builds
 * its entries at once, while its keys are in cache, and then writes its nodes, its leaves' blocks
 * numbered from the bucket's first block (each entry counts its subtree's blocks) and filled by
 * the same task. The tree above the buckets is small and built on the calling thread. */

#define RX_SMALL 32u        /* ranges sorted by insertion */
#define RX_CHUNK 1024u      /* tree entries handed to a thread at a time */
#define RX_LEAF 3u
#define RX_TASK_ROOT 4u     /* flag on a bucket's root: its nodes are a task's */
#define RX_BUCKETS 2048u    /* ranges left to the sort's tasks */
#define RX_AHEAD 16u        /* positions whose boxes are prefetched ahead of the leaves' bounds */

/* An entry of the radix tree: the bounds of its boxes and the tri4 blocks of its leaves; inner:
 * its children's entries and the plane's axis; leaf: its positions [a, b). */
typedef struct rx_node {
    float lo[3], hi[3];
    uint32_t a, b;
    uint32_t axis;   /* or RX_LEAF; | RX_TASK_ROOT at a bucket's root */
    uint32_t blocks;
} rx_node;

typedef struct rx_local {
    uint32_t next, end; /* the rest of this thread's chunk of entries */
    uint32_t ahead;     /* the end of the range being built: boxes are prefetched up to it */
    uint8_t pad[RP_CACHE_LINE - 12];
} rx_local;

/* A range left to the sort's tasks (its keys in buffer src: 0 key, 1 key2) and, once sorted, the
 * root entry of its subtree. */
typedef struct rx_bucket {
    uint32_t b, e, src, entry;
} rx_bucket;

/* A bucket's nodes: its root entry, the node it goes in, its depth and first block, and its box
 * (the root box cut by its ancestors' planes). */
typedef struct rx_task {
    uint32_t entry, node, depth, block, blocks;
    float nb[6];
} rx_task;

/* A box's code and its position in the input. */
typedef struct rx_key {
    uint64_t code;
    uint32_t id, pad;
} rx_key;

typedef struct rx_ctx {
    bih_ctx *c;
    uint32_t n, threads, chunks;
    rx_key *key, *key2;         /* the keys, and the sort's second buffer */
    double qlo[3], qscale[3];   /* twice a centroid -> [0, 2^bits) on each axis */
    int bits[3];
    uint8_t axis_of_bit[64];
    uint64_t spread[3][8][256]; /* a byte of an axis' quantized value -> its code bits */
    uint32_t (*hist)[256];      /* per chunk: a parallel pass's counts, then offsets */
    uint64_t (*mm)[2];          /* per chunk: a parallel pass's lowest and highest code */
    uint32_t pb, pe;            /* a parallel pass's positions, its buffer and digit */
    int psrc, shift;
    rx_bucket buckets[RX_BUCKETS];
    uint32_t bucket_n, cursor;  /* cursor: the next bucket (by position) the tree above them meets */
    bool bad;                   /* a bucket that is not a subtree (never expected): the build fails */
    rx_node *t;
    uint32_t t_cap;
    _Atomic uint32_t t_next;
    rx_local *tl;
    rx_task *tasks;             /* RX_BUCKETS */
    uint32_t task_n;
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

/* Keys of a chunk of the boxes. */
static void rx_code_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    rx_ctx *x = user;
    uint32_t b, e;
    rx_chunk(x, index, &b, &e);
    const bvh_prim *p = x->c->in->boxes;
    for (uint32_t i = b; i < e; i++) x->key[i] = (rx_key){rx_code(x, &p[i]), i, 0};
}

/* The highest bit in which the codes of [b, e) differ; -1 when they are all equal. */
static int rx_high_bit(const rx_key *k, uint32_t b, uint32_t e) {
    uint64_t mn = k[b].code, mx = mn;
    for (uint32_t i = b + 1; i < e; i++) mn = k[i].code < mn ? k[i].code : mn, mx = k[i].code > mx ? k[i].code : mx;
    return mn == mx ? -1 : 63 - __builtin_clzll(mn ^ mx);
}

static void rx_minmax_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    rx_ctx *x = user;
    uint32_t b, e;
    rx_chunk(x, index, &b, &e);
    const rx_key *k = x->psrc ? x->key2 : x->key;
    uint64_t mn = UINT64_MAX, mx = 0;
    for (uint32_t i = b; i < e; i++) mn = k[i].code < mn ? k[i].code : mn, mx = k[i].code > mx ? k[i].code : mx;
    x->mm[index][0] = mn, x->mm[index][1] = mx;
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
 * from the range's highest differing bit (8 bits, fewer for small ranges), then each bucket. A
 * range of at most BIH_LEAF_SIZE keys is left as it is: its keys share the bits above the digit
 * that made it, so the tree makes one leaf of them (or of more) whatever their order, and a larger
 * range's first and last keys still differ in its highest differing bit, which is the same
 * throughout each such small range (rx_split). */
static void rx_sort(rx_ctx *x, int src, uint32_t b, uint32_t e) {
    rx_key *ks = src ? x->key2 : x->key, *kd = src ? x->key : x->key2;
    int hb = -1;
    if (e - b <= BIH_LEAF_SIZE) {
    } else if (e - b <= RX_SMALL) { /* insertion sort */
        for (uint32_t i = b + 1; i < e; i++) {
            rx_key k = ks[i];
            uint32_t j = i;
            for (; j > b && ks[j - 1].code > k.code; j--) ks[j] = ks[j - 1];
            ks[j] = k;
        }
    } else {
        hb = rx_high_bit(ks, b, e);
    }
    if (hb < 0) { /* sorted: into buffer 0 */
        if (src) memcpy(kd + b, ks + b, (e - b) * sizeof *kd);
        return;
    }
    int bits = e - b > 4096 ? 8 : e - b > 512 ? 6 : 4;
    uint32_t nd = 1u << bits, mask = nd - 1;
    int shift = hb >= bits - 1 ? hb - (bits - 1) : 0;
    /* four counters per digit, so that runs of one digit (clustered codes) do not wait on each
     * other's increments */
    uint32_t cnt[4][256], off[256], start[256];
    for (int r = 0; r < 4; r++) memset(cnt[r], 0, nd * sizeof cnt[r][0]);
    uint32_t i = b;
    for (; i + 4 <= e; i += 4) {
        cnt[0][(ks[i].code >> shift) & mask]++;
        cnt[1][(ks[i + 1].code >> shift) & mask]++;
        cnt[2][(ks[i + 2].code >> shift) & mask]++;
        cnt[3][(ks[i + 3].code >> shift) & mask]++;
    }
    for (; i < e; i++) cnt[0][(ks[i].code >> shift) & mask]++;
    for (uint32_t k = 0, o = b; k < nd; k++) {
        cnt[0][k] += cnt[1][k] + cnt[2][k] + cnt[3][k];
        start[k] = off[k] = o, o += cnt[0][k];
    }
    for (i = b; i < e; i++) kd[off[(ks[i].code >> shift) & mask]++] = ks[i];
    for (uint32_t k = 0; k < nd; k++)
        if (cnt[0][k]) rx_sort(x, !src, start[k], start[k] + cnt[0][k]);
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

static inline void rx_union(rx_node *r, const rx_node *L, const rx_node *R) {
    for (int k = 0; k < 3; k++) /* (fminf and fmaxf are calls) */
        r->lo[k] = L->lo[k] < R->lo[k] ? L->lo[k] : R->lo[k], r->hi[k] = L->hi[k] > R->hi[k] ? L->hi[k] : R->hi[k];
    r->blocks = L->blocks + R->blocks;
}

/* Builds the subtree of positions [b, e) (sorted) in entry `entry`, bounds and blocks included.
 * The leaves come in the positions' order; each prefetches the boxes RX_AHEAD positions on, up
 * to l->ahead. */
static void rx_tree(rx_ctx *x, rx_local *l, uint32_t entry, uint32_t b, uint32_t e) {
    rx_node *r = &x->t[entry];
    if (rx_is_leaf(x, b, e)) {
        const bvh_prim *p = x->c->in->boxes;
        const rx_key *k = x->key;
        for (uint32_t i = b + RX_AHEAD; i < e + RX_AHEAD && i < l->ahead; i++) __builtin_prefetch(&p[k[i].id]);
        vf4 lo = p[k[b].id].lo, hi = p[k[b].id].hi;
        for (uint32_t i = b + 1; i < e; i++) lo = vf4_min(lo, p[k[i].id].lo), hi = vf4_max(hi, p[k[i].id].hi);
        for (int j = 0; j < 3; j++) r->lo[j] = lo[j], r->hi[j] = hi[j];
        r->a = b, r->b = e, r->axis = RX_LEAF, r->blocks = (e - b + 3) / 4;
        return;
    }
    int axis;
    uint32_t m = rx_split(x, b, e, &axis);
    uint32_t left = rx_alloc(x, l), right = rx_alloc(x, l);
    rx_tree(x, l, left, b, m);
    rx_tree(x, l, right, m, e);
    rx_union(r, &x->t[left], &x->t[right]);
    r->a = left, r->b = right, r->axis = (uint32_t)axis;
}

/* A bucket: its keys sorted, then its subtree built while they are in cache. */
static void rx_bucket_task(void *user, uint32_t index, uint32_t thread) {
    rx_ctx *x = user;
    rx_bucket *k = &x->buckets[index];
    rx_sort(x, (int)k->src, k->b, k->e);
    rx_local *l = &x->tl[thread];
    const bvh_prim *p = x->c->in->boxes;
    for (uint32_t i = k->b; i < k->b + RX_AHEAD && i < k->e; i++) __builtin_prefetch(&p[x->key[i].id]);
    l->ahead = k->e;
    k->entry = rx_alloc(x, l);
    rx_tree(x, l, k->entry, k->b, k->e);
    x->t[k->entry].axis |= RX_TASK_ROOT;
}

/* Larger buckets first (the tasks' order), then by position. */
static int rx_bucket_larger(const void *a, const void *b) {
    const rx_bucket *x = a, *y = b;
    uint32_t nx = x->e - x->b, ny = y->e - y->b;
    return nx > ny ? -1 : nx < ny ? 1 : (x->b > y->b) - (x->b < y->b);
}

static int rx_bucket_first(const void *a, const void *b) {
    const rx_bucket *x = a, *y = b;
    return (x->b > y->b) - (x->b < y->b);
}

static void rx_push_bucket(rx_ctx *x, uint32_t b, uint32_t e, int src) {
    x->buckets[x->bucket_n++] = (rx_bucket){b, e, (uint32_t)src, 0};
}

/* One digit of positions [b, e) (held in buffer src) by all threads; the buckets of at most a share
 * of the positions are left to tasks, the larger ones get a pass of their own. */
static void rx_pass_par(rx_ctx *x, sys_pool *pool, int src, uint32_t b, uint32_t e) {
    x->pb = b, x->pe = e, x->psrc = src;
    sys_pool_parallel_for(pool, x->chunks, rx_minmax_task, x);
    uint64_t mn = UINT64_MAX, mx = 0;
    for (uint32_t i = 0; i < x->chunks; i++) mn = x->mm[i][0] < mn ? x->mm[i][0] : mn, mx = x->mm[i][1] > mx ? x->mm[i][1] : mx;
    int hb = mn == mx ? -1 : 63 - __builtin_clzll(mn ^ mx);
    if (hb < 0 || x->bucket_n + 256 > RX_BUCKETS) {
        rx_push_bucket(x, b, e, src);
        return;
    }
    x->shift = hb >= 7 ? hb - 7 : 0;
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
        else rx_push_bucket(x, bb, be, !src);
    }
}

/* Sorts the keys by code (the codes and the digits of large ranges by all threads, then each
 * bucket by a task, which builds its subtree too); the buckets end in the positions' order. */
static void rx_sort_all(rx_ctx *x, sys_pool *pool) {
    x->pb = 0, x->pe = x->n;
    x->bucket_n = 0;
    if (pool) {
        sys_pool_parallel_for(pool, x->chunks, rx_code_task, x);
        rx_pass_par(x, pool, 0, 0, x->n);
        qsort(x->buckets, x->bucket_n, sizeof x->buckets[0], rx_bucket_larger);
        sys_pool_parallel_for(pool, x->bucket_n, rx_bucket_task, x);
        qsort(x->buckets, x->bucket_n, sizeof x->buckets[0], rx_bucket_first);
    } else {
        rx_code_task(x, 0, 0);
        rx_push_bucket(x, 0, x->n, 0);
        rx_bucket_task(x, 0, 0);
    }
}

/* The tree above the buckets on the calling thread, left to right; returns the entry of positions
 * [b, e). The codes with a common prefix are one subtree, so a range is the next bucket or holds
 * several whole ones, unless the tree makes a leaf of them (a few positions, or equal codes):
 * buckets finer than a leaf are left unused, and the leaf made here as rx_tree makes it. */
static uint32_t rx_tree_top(rx_ctx *x, uint32_t b, uint32_t e) {
    const rx_bucket *k = x->cursor < x->bucket_n ? &x->buckets[x->cursor] : NULL;
    if (!k || k->b != b || k->e > e) {
        x->bad = true;
        return 0;
    }
    if (k->e == e) {
        x->cursor++;
        return k->entry;
    }
    rx_local *l = &x->tl[0];
    uint32_t entry = rx_alloc(x, l);
    if (rx_is_leaf(x, b, e)) {
        l->ahead = e;
        rx_tree(x, l, entry, b, e);
        while (x->cursor < x->bucket_n && x->buckets[x->cursor].e <= e) x->cursor++;
        return entry;
    }
    int axis;
    uint32_t m = rx_split(x, b, e, &axis);
    uint32_t left = rx_tree_top(x, b, m), right = rx_tree_top(x, m, e);
    rx_node *r = &x->t[entry];
    rx_union(r, &x->t[left], &x->t[right]);
    r->a = left, r->b = right, r->axis = (uint32_t)axis;
    return entry;
}

/* Fills the blocks of positions [b, e) (block_of written by their leaves). */
static void rx_fill(const rx_ctx *x, uint32_t b, uint32_t e) {
    const accel_tri_input *in = x->c->in;
    in->fill(in->user, in->refs, &x->key[0].id, sizeof(rx_key) / sizeof(uint32_t), x->c->block_of, b, e, x->c->blocks);
}

/* Writes the BIH nodes of the subtree at entry `entry` into node `node`, its leaves' blocks from
 * `block` on, as the partition build's split did: the clip node in front (from the node's box nb,
 * the root box cut by its ancestors' planes), then the leaf, or the node with its two planes and
 * its children. With top, a bucket's subtree is left to a task, and a leaf above the buckets is
 * filled at once. Each inner entry's children differ in a lower bit of the code than it, so an
 * inner node is at most at depth 63 (the root: 1), within BIH_MAX_DEPTH. */
static void rx_emit(rx_ctx *x, bih_local *l, uint32_t entry, uint32_t node, float nb[6], uint32_t depth, uint32_t block,
                    bool top) {
    bih_ctx *c = x->c;
    for (;;) {
        const rx_node *r = &x->t[entry];
        if (top && (r->axis & RX_TASK_ROOT)) {
            rx_task *t = &x->tasks[x->task_n++];
            *t = (rx_task){entry, node, depth, block, r->blocks, {0}};
            memcpy(t->nb, nb, sizeof t->nb);
            return;
        }
        vf4 blo = {r->lo[0], r->lo[1], r->lo[2], 0.0f}, bhi = {r->hi[0], r->hi[1], r->hi[2], 0.0f};
        node = clip_empty(c, l, node, nb, blo, bhi);
        uint32_t axis = r->axis & ~RX_TASK_ROOT;
        if (axis == RX_LEAF) {
            make_leaf(c, l, node, r->a, r->b, block, depth);
            if (top) rx_fill(x, r->a, r->b);
            return;
        }
        const rx_node *L = &x->t[r->a], *R = &x->t[r->b];
        uint32_t child = node_alloc(c, l, 2);
        c->nodes[node] = (bih_node){{pad_hi(c, L->hi[axis]), pad_lo(c, R->lo[axis])}, child << BIH_TAG_BITS | axis};
        float nl[6];
        memcpy(nl, nb, sizeof nl);
        if (L->hi[axis] < nl[3 + axis]) nl[3 + axis] = L->hi[axis];
        if (R->lo[axis] > nb[axis]) nb[axis] = R->lo[axis];
        rx_emit(x, l, r->a, child, nl, depth + 1, block, top);
        entry = r->b, node = child + 1, depth++, block += L->blocks;
    }
}

/* Larger tasks first. */
static int rx_task_larger(const void *a, const void *b) {
    const rx_task *x = a, *y = b;
    return x->blocks > y->blocks ? -1 : x->blocks < y->blocks ? 1 : (x->block > y->block) - (x->block < y->block);
}

/* A bucket's nodes, then its blocks (its positions: from its first leaf's to its last leaf's). */
static void rx_emit_task(void *user, uint32_t index, uint32_t thread) {
    rx_ctx *x = user;
    rx_task t = x->tasks[index];
    uint32_t first = t.entry, last = t.entry;
    while ((x->t[first].axis & ~RX_TASK_ROOT) != RX_LEAF) first = x->t[first].a;
    while ((x->t[last].axis & ~RX_TASK_ROOT) != RX_LEAF) last = x->t[last].b;
    rx_emit(x, &x->c->local[thread], t.entry, t.node, t.nb, t.depth, t.block, false);
    rx_fill(x, x->t[first].a, x->t[last].b);
}

/* Sorts the keys, builds the tree and writes its nodes into c->nodes (allocated here,
 * c->node_bytes, from node 0; c->local's counters) and its *block_count blocks into c->blocks
 * (allocated here, filled); false when out of memory. */
static bool rx_build(bih_ctx *c, const sys_allocator *a, sys_pool *pool, uint32_t threads, const float sb[6], float nb[6],
                     uint32_t *block_count) {
    rx_ctx *x = sys_alloc(a, sizeof *x);
    if (!x) return false;
    memset(x, 0, sizeof *x);
    uint32_t n = c->in->count;
    x->c = c, x->n = n, x->threads = threads, x->chunks = pool ? threads * 4 : 1;
    rx_setup(x, sb);
    /* the buckets' subtrees hold 2n - 1 entries at most, the tree above them one per bucket */
    x->t_cap = 2 * n + RX_BUCKETS + RX_CHUNK * (threads + 1);
    size_t key_bytes = (size_t)n * sizeof(rx_key), t_bytes = (size_t)x->t_cap * sizeof(rx_node);
    size_t tl_bytes = threads * sizeof(rx_local);
    size_t hist_bytes = x->chunks * (sizeof *x->hist + sizeof *x->mm), task_bytes = RX_BUCKETS * sizeof(rx_task);
    x->key = sys_alloc(a, key_bytes);
    x->key2 = sys_alloc(a, key_bytes);
    x->t = sys_alloc(a, t_bytes);
    x->tl = sys_alloc(a, tl_bytes);
    x->hist = sys_alloc(a, hist_bytes);
    x->tasks = sys_alloc(a, task_bytes);
    bool ok = x->key && x->key2 && x->t && x->tl && x->hist && x->tasks;
    if (ok) x->mm = (uint64_t(*)[2])(void *)(x->hist + x->chunks);
    if (ok) {
        memset(x->tl, 0, tl_bytes);
        atomic_store(&x->t_next, 0);
        /* phase 1: the keys sorted, the tree's entries, their bounds and blocks */
        rx_sort_all(x, pool);
        sys_free(a, x->key2, key_bytes), x->key2 = NULL;
        uint32_t root = rx_tree_top(x, 0, n);
        ok = !x->bad;
        /* phase 2: the nodes, top-down. Each entry is a node, and may have a clip node in front
         * (clip_empty); a chunk of nodes (node_alloc) leaves at most one unused, and each
         * thread's last chunk its rest. */
        size_t entries = atomic_load(&x->t_next);
        c->node_bytes = (2 * entries + 2 * entries / (BIH_NODE_CHUNK - 1) + (size_t)BIH_NODE_CHUNK * (threads + 1) + 1) *
                        sizeof(bih_node);
        c->nodes = ok ? sys_alloc(a, c->node_bytes) : NULL;
        *block_count = ok ? x->t[root].blocks : 0;
        c->blocks = ok ? accel_blocks_alloc(a, *block_count) : NULL;
        ok = ok && c->nodes && c->blocks;
        if (ok) {
            x->task_n = 0;
            rx_emit(x, &c->local[0], root, 0, nb, 1, 0, true);
            qsort(x->tasks, x->task_n, sizeof *x->tasks, rx_task_larger);
            if (pool && x->task_n > 1) sys_pool_parallel_for(pool, x->task_n, rx_emit_task, x);
            else
                for (uint32_t i = 0; i < x->task_n; i++) rx_emit_task(x, i, 0);
        }
    }
    sys_free(a, x->key, key_bytes), sys_free(a, x->key2, key_bytes);
    sys_free(a, x->t, t_bytes), sys_free(a, x->tl, tl_bytes);
    sys_free(a, x->hist, hist_bytes), sys_free(a, x->tasks, task_bytes);
    sys_free(a, x, sizeof *x);
    return ok;
}

/* The nodes copied to their final allocation. */
typedef struct copy_ctx {
    bih_ctx *c;
    uint32_t count, chunks;
} copy_ctx;

static void copy_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const copy_ctx *f = user;
    uint64_t nn = f->count;
    uint32_t b = (uint32_t)(nn * index / f->chunks), e = (uint32_t)(nn * (index + 1) / f->chunks);
    memcpy(&f->c->out[b], &f->c->nodes[b], (size_t)(e - b) * sizeof(bih_node));
}

static bool bih_build(const sys_allocator *a, sys_pool *pool, accel_tri_input *in, accel_built *out) {
    memset(out, 0, sizeof *out);
    uint32_t n = in->count;
    bih_ctx c = {.in = in};
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
    box3 b = in->bounds;
    float sb[6] = {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z}, nb[6];
    memcpy(out->bounds, sb, sizeof sb);
    memcpy(nb, sb, sizeof nb);
    c.abs_pad = box_pad_abs(sb, sb + 3);
    atomic_store(&c.next, 1);
    uint32_t blocks = 0;
    bool ok = rx_build(&c, a, pool, threads, sb, nb, &blocks);
    uint32_t node_count = atomic_load(&c.next), depth = 0, unused = 0;
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
        out_bytes = (size_t)node_count * sizeof(bih_node);
        c.out = sys_alloc(a, out_bytes);
        ok = c.out != NULL;
    }
    if (ok) {
        copy_ctx f = {&c, node_count, pool ? threads * 4 : 1};
        if (pool) sys_pool_parallel_for(pool, f.chunks, copy_task, &f);
        else copy_task(&f, 0, 0);
    }
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
