/* Binned SAH builder (Wald 2007): per node, primitives are binned by centroid along each axis and
 * the split of least SAH cost among bin borders is taken. The top of the tree is split level by
 * level (large nodes binned by all threads, then a node per thread) until there are enough
 * subtrees, which the device's threads then build. */
#include <math.h>
#include <string.h>

#include "accel/bvh/bvh.h"
#include "simd/simd.h"

#define MAX_BINS 64
#define LARGE_NODE 256u /* nodes larger than this are binned with twice the bins */
#define PAR_MIN 65536u     /* nodes this large (at the top of the tree) are binned by all threads */
#define PAR_CHUNKS 32u
#define MEDIAN_DEPTH 64 /* past this depth, split at the median to bound the depth */
#define BIN_PAIR_MIN 64u   /* nodes this large are binned into two sets of bins, merged after */

typedef struct build_ctx {
    bvh_prim *boxes; /* permuted with prims, so every pass over a node's range reads memory in order */
    uint32_t *prims;
    bvh_node *nodes;
    _Atomic uint32_t node_count; /* nodes handed out, in chunks */
    struct node_chunk *chunks;     /* per thread: the rest of its chunk */
    int bins;
    int max_leaf;
    uint32_t block;    /* primitives per intersection block */
    int block_shift;   /* log2(block) when block is a power of two, else -1 */
    double trav_cost;  /* of one node, in block intersections */
    double inv_root_area; /* for the SAH cost's terms; 0 when the root has no area */
    /* the threads, while the top of the tree is split (NULL after) */
    sys_pool *top_pool;
    const sys_allocator *alloc;
    /* subtrees deferred to the threads */
    struct task *tasks;
    struct tree_stats *task_stats; /* one per task */
    uint32_t task_count, task_capacity;
} build_ctx;

/* Nodes are handed to the threads in chunks of NODE_CHUNK (one atomic per chunk, and no two threads
 * writing the same cache line: sibling pairs start at even indices, 64 bytes apart). The unused
 * rest of each chunk is zeroed at the end: a node with count 0 and index 0 that no node points at. */
#define NODE_CHUNK 64u

typedef struct node_chunk {
    uint32_t next, end;
    uint8_t pad[RP_CACHE_LINE - 8];
} node_chunk;

/* An open node: its range of primitives and the box of their centroids (its own box is in the
 * node), which the partition that made it computed. */
typedef struct task {
    uint32_t node, begin, end, depth;
    box3 cbox;
} task;

static inline uint32_t task_size(const task *t) { return t->end - t->begin; }

/* The tree's SAH cost (inner nodes' half areas and leaves' half area x primitives, relative to
 * the root's), leaves and depth, gathered while building. The cost is summed in fixed point
 * (2^-32), so it does not depend on how the threads split the sum. */
typedef struct tree_stats {
    unsigned __int128 cost;
    uint32_t leaves, depth;
} tree_stats;

static inline uint64_t cost_fixed(double area, double count, double inv_root) {
    return (uint64_t)(area * count * inv_root * 0x1p32 + 0.5);
}

static void stats_merge(tree_stats *dst, const tree_stats *src) {
    dst->cost += src->cost;
    dst->leaves += src->leaves;
    if (src->depth > dst->depth) dst->depth = src->depth;
}

/* Makes the task's node (box b) a leaf and counts it. */
static int make_leaf(bvh_node *node, const task *t, box3 b, double inv_root, tree_stats *st) {
    node->index = t->begin;
    node->count = t->end - t->begin;
    st->cost += cost_fixed(box3_half_area(b), (double)node->count, inv_root);
    st->leaves++;
    if (t->depth + 1 > st->depth) st->depth = t->depth + 1;
    return 0;
}

static inline vf4 centroid_of(const bvh_prim *b) { return b->lo * 0.5f + b->hi * 0.5f; }

static inline box3 box_of(vf4 lo, vf4 hi) { return (box3){v3(lo[0], lo[1], lo[2]), v3(hi[0], hi[1], hi[2])}; }

/* Box and centroid box of [begin, end) as four vectors: lo, hi, centroid lo, centroid hi. */
static void range_boxes(const build_ctx *c, uint32_t begin, uint32_t end, vf4 out[4]) {
    vf4 lo = vf4_splat(INFINITY), hi = vf4_splat(-INFINITY), clo = lo, chi = hi;
    for (uint32_t i = begin; i < end; i++) {
        const bvh_prim *b = &c->boxes[i];
        vf4 ce = centroid_of(b);
        lo = vf4_min(lo, b->lo), hi = vf4_max(hi, b->hi);
        clo = vf4_min(clo, ce), chi = vf4_max(chi, ce);
    }
    out[0] = lo, out[1] = hi, out[2] = clo, out[3] = chi;
}

/* A reduction over the primitives of a large node, as PAR_CHUNKS tasks on the pool. */
typedef struct par_job {
    const build_ctx *c;
    uint32_t begin, end;
    vf4 lo, scale, last; /* binning */
    int nb;
    void *out;           /* PAR_CHUNKS results */
} par_job;

/* Chunk `index` of PAR_CHUNKS of [begin, end). */
static void par_chunk(uint32_t begin, uint32_t end, uint32_t index, uint32_t *b, uint32_t *e) {
    uint64_t n = end - begin;
    *b = begin + (uint32_t)(n * index / PAR_CHUNKS), *e = begin + (uint32_t)(n * (index + 1) / PAR_CHUNKS);
}

static void boxes_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const par_job *j = user;
    uint32_t b, e;
    par_chunk(j->begin, j->end, index, &b, &e);
    range_boxes(j->c, b, e, (vf4 *)j->out + 4 * index);
}

static box3 prim_range_box(const build_ctx *c, uint32_t begin, uint32_t end, box3 *cbox) {
    vf4 r[4];
    vf4 *parts = c->top_pool && end - begin >= PAR_MIN ? sys_alloc(c->alloc, PAR_CHUNKS * 4 * sizeof(vf4)) : NULL;
    if (parts) {
        par_job j = {.c = c, .begin = begin, .end = end, .out = parts};
        sys_pool_parallel_for(c->top_pool, PAR_CHUNKS, boxes_task, &j);
        for (int k = 0; k < 4; k++) r[k] = parts[k];
        for (uint32_t i = 1; i < PAR_CHUNKS; i++) {
            r[0] = vf4_min(r[0], parts[4 * i]), r[1] = vf4_max(r[1], parts[4 * i + 1]);
            r[2] = vf4_min(r[2], parts[4 * i + 2]), r[3] = vf4_max(r[3], parts[4 * i + 3]);
        }
        sys_free(c->alloc, parts, PAR_CHUNKS * 4 * sizeof(vf4));
    } else {
        range_boxes(c, begin, end, r);
    }
    *cbox = box_of(r[2], r[3]);
    return box_of(r[0], r[1]);
}

static void set_node_box(bvh_node *n, box3 b) {
    n->lo[0] = b.lo.x, n->lo[1] = b.lo.y, n->lo[2] = b.lo.z;
    n->hi[0] = b.hi.x, n->hi[1] = b.hi.y, n->hi[2] = b.hi.z;
}

static box3 node_box(const bvh_node *n) {
    return (box3){v3(n->lo[0], n->lo[1], n->lo[2]), v3(n->hi[0], n->hi[1], n->hi[2])};
}

/* Bin indices of a centroid on the three axes; clamped in float before the conversion so
 * huge coordinates (or an extent that overflowed) cannot make it undefined, and NaN goes to 0
 * (maxps returns its second operand on NaN). Counting and partitioning both use it, so they
 * always agree. */
static inline vi4 bins_of(vf4 centroid, vf4 lo, vf4 scale, vf4 last) {
    vf4 f = vf4_min(vf4_max((centroid - lo) * scale, vf4_splat(0.0f)), last);
    return __builtin_convertvector(f, vi4);
}

/* Bins of the three axes: per bin, for each axis, the union of the boxes, and in the w lane of
 * its upper corner the count of the primitives whose centroid falls in it (a float: exact up to
 * 2^24, and only the SAH reads it). A primitive's upper corner has w = -inf, so max keeps the count
 * and one add counts the primitive: a bin update is two loads and two stores (a separate count
 * array made it three of each). */
typedef struct bins {
    vf4 lo[MAX_BINS][3], hi[MAX_BINS][3];
} bins;

static void bins_clear(bins *b, int nb) {
    for (int k = 0; k < nb; k++)
        for (int a = 0; a < 3; a++) b->lo[k][a] = vf4_splat(INFINITY), b->hi[k][a] = (vf4){-INFINITY, -INFINITY, -INFINITY, 0.0f};
}

RP_INLINE void bin_one(bins *restrict out, const bvh_prim *p, vf4 lo, vf4 scale, vf4 last) {
    vi4 b = bins_of(centroid_of(p), lo, scale, last);
    const vf4 one_w = {0.0f, 0.0f, 0.0f, 1.0f};
    for (int a = 0; a < 3; a++) {
        int k = b[a];
        out->lo[k][a] = vf4_min(out->lo[k][a], p->lo);
        out->hi[k][a] = vf4_max(out->hi[k][a], p->hi) + one_w;
    }
}

/* The counts of bin k on the three axes (lanes x, y, z; w 0). */
static inline vf4 bin_counts(const bins *b, int k) {
    vf4 t = __builtin_shufflevector(b->hi[k][0], b->hi[k][1], 3, 7, 3, 7);
    return __builtin_shufflevector(t, b->hi[k][2], 0, 1, 7, 0) * (vf4){1.0f, 1.0f, 1.0f, 0.0f};
}

static void bins_merge(bins *dst, const bins *src, int nb) {
    for (int k = 0; k < nb; k++) {
        for (int a = 0; a < 3; a++) {
            dst->lo[k][a] = vf4_min(dst->lo[k][a], src->lo[k][a]);
            vf4 h = vf4_max(dst->hi[k][a], src->hi[k][a]);
            h[3] = dst->hi[k][a][3] + src->hi[k][a][3];
            dst->hi[k][a] = h;
        }
    }
}

/* Neighbouring primitives often fall in the same bin, and each update of a bin waited for the
 * last one's store; two sets of bins, taking turns, halve those chains. */
static void bin_range(const build_ctx *c, uint32_t begin, uint32_t end, vf4 lo, vf4 scale, vf4 last, int nb,
                      bins *out) {
    bins_clear(out, nb);
    uint32_t i = begin;
    if (end - begin >= BIN_PAIR_MIN) {
        bins two;
        bins_clear(&two, nb);
        for (; i + 1 < end; i += 2) {
            bin_one(out, &c->boxes[i], lo, scale, last);
            bin_one(&two, &c->boxes[i + 1], lo, scale, last);
        }
        if (i < end) bin_one(out, &c->boxes[i], lo, scale, last);
        bins_merge(out, &two, nb);
        return;
    }
    for (; i < end; i++) bin_one(out, &c->boxes[i], lo, scale, last);
}

static void bins_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const par_job *j = user;
    uint32_t b, e;
    par_chunk(j->begin, j->end, index, &b, &e);
    bin_range(j->c, b, e, j->lo, j->scale, j->last, j->nb, (bins *)j->out + index);
}

static inline uint32_t blocks_of(const build_ctx *c, uint32_t n) {
    uint32_t m = n + c->block - 1;
    return c->block_shift >= 0 ? m >> c->block_shift : m / c->block;
}

/* Half the surface areas of three boxes (one per axis's sweep), given their extents d[a] (lanes
 * x, y, z), scaled by s: lane a of the result is box a's. Empty boxes (negative extents) give 0. */
static inline vf4 half_areas3(const vf4 d[3], vf4 s) {
    vf4 z = vf4_splat(0.0f);
    vf4 d0 = vf4_max(d[0], z) * s, d1 = vf4_max(d[1], z) * s, d2 = vf4_max(d[2], z) * s;
    vf4 t0 = __builtin_shufflevector(d0, d1, 0, 4, 1, 5), t1 = __builtin_shufflevector(d0, d1, 2, 6, 3, 7);
    vf4 x = __builtin_shufflevector(t0, d2, 0, 1, 4, 4), y = __builtin_shufflevector(t0, d2, 2, 3, 5, 5);
    vf4 w = __builtin_shufflevector(t1, d2, 0, 1, 6, 6);
    return x * y + y * w + w * x;
}

/* Blocks of `block` primitives needed for counts c, per lane, as floats. */
static inline vf4 blocks_v(const build_ctx *c, vi4 n) {
    vi4 m = n + vi4_splat((int32_t)c->block - 1);
    if (c->block_shift >= 0) return __builtin_convertvector(m >> c->block_shift, vf4);
    return (vf4){(float)((uint32_t)m[0] / c->block), (float)((uint32_t)m[1] / c->block),
                 (float)((uint32_t)m[2] / c->block), 0.0f};
}

/* The best binned SAH split of a node: the axis and the first bin of the right side, the binning
 * that numbered the bins (the partition must use the same), the children's boxes and the cost. */
typedef struct split_plan {
    int axis, bin;
    vf4 lo, scale, last;
    box3 lbox, rbox;
    double cost; /* half area x blocks, summed over the two sides */
} split_plan;

/* Finds the best split of [begin, end) whose centroids lie in cbox; false when there is none (all
 * centroids in one bin on every axis). One pass bins all three axes at once. */
static bool split_find(build_ctx *c, uint32_t begin, uint32_t end, box3 cbox, box3 nbox, split_plan *out) {
    /* Nodes of more than LARGE_NODE primitives get twice the bins: their splits shape the tree
     * (kitchen, conference: single rays 5-15% faster than with 16 bins everywhere, as fast as 32
     * everywhere, at no measurable build cost; 64 was no better). A node of n primitives gets at
     * most 4 + n bins / 128 (4 + n / 8 at the default 16; Embree's builders give 4 + n / 20):
     * sweeping and clearing mostly empty bins near the leaves had been a sixth of a build, and
     * the shared scenes' SAH costs moved by -16% (museum) to +0.2% (teapot). */
    int nb = end - begin > LARGE_NODE ? 2 * c->bins : c->bins;
    if (nb > MAX_BINS) nb = MAX_BINS;
    uint64_t small_nb = 4u + (uint64_t)(end - begin) * (uint32_t)c->bins / 128u;
    if ((uint64_t)nb > small_nb) nb = (int)small_nb;
    vf4 lo = {cbox.lo.x, cbox.lo.y, cbox.lo.z, 0.0f}, scale = vf4_splat(0.0f);
    bool usable[3];
    for (int axis = 0; axis < 3; axis++) {
        double extent = (double)v3_get(cbox.hi, axis) - (double)v3_get(cbox.lo, axis);
        float sc = extent > 0.0 ? (float)((double)nb * (1.0 - 1e-6) / extent) : 0.0f;
        usable[axis] = sc > 0.0f && isfinite(sc);
        scale[axis] = usable[axis] ? sc : 0.0f;
    }
    if (!usable[0] && !usable[1] && !usable[2]) return false;
    vf4 last = vf4_splat((float)(nb - 1));
    bins acc;
    bins *parts = c->top_pool && end - begin >= PAR_MIN ? sys_alloc(c->alloc, PAR_CHUNKS * sizeof(bins)) : NULL;
    if (parts) {
        par_job j = {.c = c, .begin = begin, .end = end, .lo = lo, .scale = scale, .last = last, .nb = nb, .out = parts};
        sys_pool_parallel_for(c->top_pool, PAR_CHUNKS, bins_task, &j);
        acc = parts[0];
        for (uint32_t i = 1; i < PAR_CHUNKS; i++) bins_merge(&acc, &parts[i], nb);
        sys_free(c->alloc, parts, PAR_CHUNKS * sizeof(bins));
    } else {
        bin_range(c, begin, end, lo, scale, last, nb, &acc);
    }
    /* areas in float, relative to the node's largest extent (so no coordinates overflow them);
     * the three axes are swept together, a lane each */
    double ext = fmax((double)nbox.hi.x - nbox.lo.x, fmax((double)nbox.hi.y - nbox.lo.y, (double)nbox.hi.z - nbox.lo.z));
    float inv = ext > 0.0 && isfinite(1.0 / ext) ? (float)(1.0 / ext) : 1.0f;
    vf4 sinv = vf4_splat(inv), inf = vf4_splat(INFINITY), ninf = vf4_splat(-INFINITY);
    vi4 zero = vi4_splat(0);
    vf4 fzero = vf4_splat(0.0f);
    /* right-to-left sweep of areas and counts */
    vf4 rcost[MAX_BINS];
    vf4 blo[3] = {inf, inf, inf}, bhi[3] = {ninf, ninf, ninf}, d[3];
    vf4 cnt = fzero;
    for (int b = nb - 1; b > 0; b--) {
        for (int a = 0; a < 3; a++) {
            blo[a] = vf4_min(blo[a], acc.lo[b][a]), bhi[a] = vf4_max(bhi[a], acc.hi[b][a]);
            d[a] = bhi[a] - blo[a];
        }
        cnt += bin_counts(&acc, b);
        rcost[b] = vf4_select(cnt > fzero, half_areas3(d, sinv) * blocks_v(c, __builtin_convertvector(cnt, vi4)), inf);
    }
    /* left-to-right with the cost of each border: per axis, the first least cost */
    vi4 usable_m = {-(int)usable[0], -(int)usable[1], -(int)usable[2], 0};
    vf4 best = inf;
    vi4 best_b = zero;
    for (int a = 0; a < 3; a++) blo[a] = inf, bhi[a] = ninf;
    cnt = fzero;
    for (int b = 1; b < nb; b++) {
        for (int a = 0; a < 3; a++) {
            blo[a] = vf4_min(blo[a], acc.lo[b - 1][a]), bhi[a] = vf4_max(bhi[a], acc.hi[b - 1][a]);
            d[a] = bhi[a] - blo[a];
        }
        cnt += bin_counts(&acc, b - 1);
        vf4 cost = half_areas3(d, sinv) * blocks_v(c, __builtin_convertvector(cnt, vi4)) + rcost[b];
        vi4 better = (cost < best) & (cnt > fzero) & usable_m;
        best = vf4_select(better, cost, best);
        best_b = vi4_select(better, vi4_splat(b), best_b);
    }
    float best_cost = INFINITY;
    int best_axis = -1, best_bin = 0;
    for (int a = 0; a < 3; a++)
        if (best[a] < best_cost) best_cost = best[a], best_axis = a, best_bin = best_b[a];
    if (best_axis < 0) return false;
    /* the two sides' boxes, from the bins */
    vf4 llo = inf, lhi = ninf, rlo = inf, rhi = ninf;
    for (int b = 0; b < nb; b++) {
        if (b < best_bin) llo = vf4_min(llo, acc.lo[b][best_axis]), lhi = vf4_max(lhi, acc.hi[b][best_axis]);
        else rlo = vf4_min(rlo, acc.lo[b][best_axis]), rhi = vf4_max(rhi, acc.hi[b][best_axis]);
    }
    *out = (split_plan){.axis = best_axis, .bin = best_bin, .lo = lo, .scale = scale, .last = last,
                   .lbox = box_of(llo, lhi), .rbox = box_of(rlo, rhi),
                   .cost = (double)best_cost * ext * ext};
    return true;
}

/* Partitions [begin, end) by the split (branch-free: the side of a primitive is as good as random
 * to the branch predictor), gathering each side's centroid box on the way; returns the first
 * index of the right side. Inlined once per axis, so the lane is a constant. */
RP_INLINE uint32_t partition_axis(bvh_prim *restrict boxes, uint32_t *restrict prims, uint32_t begin, uint32_t end,
                                  const split_plan *s, const int axis, box3 *lcbox, box3 *rcbox) {
    vf4 inf = vf4_splat(INFINITY), ninf = vf4_splat(-INFINITY);
    vf4 lclo = inf, lchi = ninf, rclo = inf, rchi = ninf;
    vf4 lo = s->lo, scale = s->scale, last = s->last;
    int bin = s->bin;
    uint32_t i = begin;
    for (uint32_t k = begin; k < end; k++) {
        bvh_prim x = boxes[k];
        uint32_t p = prims[k];
        vf4 ce = centroid_of(&x);
        int left = bins_of(ce, lo, scale, last)[axis] < bin;
        vi4 m = vi4_splat(-left);
        lclo = vf4_min(lclo, vf4_select(m, ce, inf)), lchi = vf4_max(lchi, vf4_select(m, ce, ninf));
        rclo = vf4_min(rclo, vf4_select(m, inf, ce)), rchi = vf4_max(rchi, vf4_select(m, ninf, ce));
        /* Lomuto: swap with the first right-side element; i only advances past left ones */
        boxes[k] = boxes[i], prims[k] = prims[i];
        boxes[i] = x, prims[i] = p;
        i += (uint32_t)left;
    }
    *lcbox = box_of(lclo, lchi), *rcbox = box_of(rclo, rchi);
    return i;
}

static uint32_t split_partition(build_ctx *c, uint32_t begin, uint32_t end, const split_plan *s, box3 *lcbox,
                                box3 *rcbox) {
    switch (s->axis) {
    case 0: return partition_axis(c->boxes, c->prims, begin, end, s, 0, lcbox, rcbox);
    case 1: return partition_axis(c->boxes, c->prims, begin, end, s, 1, lcbox, rcbox);
    default: return partition_axis(c->boxes, c->prims, begin, end, s, 2, lcbox, rcbox);
    }
}

/* Partition of a large node in PAR_CHUNKS chunks (on the pool's threads when there is one): each
 * chunk is partitioned in place, then the right-side primitives left of the node's middle are
 * swapped with the left-side ones right of it. The chunks do not depend on the number of threads,
 * so neither does the tree (a serial partition of the top nodes had kept one thread busy while the
 * others waited: spd_tree's first two levels, 11 of a 157 ms commit on two threads). */
typedef struct part_job {
    build_ctx *c;
    const split_plan *s;
    uint32_t begin, end, mid;
    uint32_t local_mid[PAR_CHUNKS];
    box3 lc[PAR_CHUNKS], rc[PAR_CHUNKS];
    /* the misplaced primitives: ranges of right-side ones before mid, left-side ones after it */
    uint32_t rb[PAR_CHUNKS], re[PAR_CHUNKS], lb[PAR_CHUNKS], le[PAR_CHUNKS];
    uint32_t rn, ln;
    uint64_t misplaced;
} part_job;

static void part_local_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    part_job *j = user;
    uint32_t b, e;
    par_chunk(j->begin, j->end, index, &b, &e);
    j->local_mid[index] = split_partition(j->c, b, e, j->s, &j->lc[index], &j->rc[index]);
}

/* Position of the k-th element of the ranges [b[i], e[i]) taken in order; *i: the range. */
static uint32_t part_locate(const uint32_t *b, const uint32_t *e, uint32_t count, uint64_t k, uint32_t *i) {
    for (*i = 0; *i < count; (*i)++) {
        if (k < e[*i] - b[*i]) return b[*i] + (uint32_t)k;
        k -= e[*i] - b[*i];
    }
    return 0; /* not reached: k < the ranges' total */
}

static void part_swap_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    part_job *j = user;
    uint64_t k = j->misplaced * index / PAR_CHUNKS, kend = j->misplaced * (index + 1) / PAR_CHUNKS;
    if (k == kend) return;
    uint32_t ri, li;
    uint32_t r = part_locate(j->rb, j->re, j->rn, k, &ri), l = part_locate(j->lb, j->le, j->ln, k, &li);
    bvh_prim *boxes = j->c->boxes;
    uint32_t *prims = j->c->prims;
    for (; k < kend; k++) {
        bvh_prim x = boxes[r];
        uint32_t p = prims[r];
        boxes[r] = boxes[l], prims[r] = prims[l];
        boxes[l] = x, prims[l] = p;
        if (++r == j->re[ri] && ri + 1 < j->rn) r = j->rb[++ri];
        if (++l == j->le[li] && li + 1 < j->ln) l = j->lb[++li];
    }
}

static uint32_t split_partition_par(build_ctx *c, uint32_t begin, uint32_t end, const split_plan *s, box3 *lcbox,
                                    box3 *rcbox) {
    part_job job, *j = &job;
    j->c = c, j->s = s, j->begin = begin, j->end = end;
    if (c->top_pool) sys_pool_parallel_for(c->top_pool, PAR_CHUNKS, part_local_task, j);
    else
        for (uint32_t i = 0; i < PAR_CHUNKS; i++) part_local_task(j, i, 0);
    uint32_t mid = begin;
    *lcbox = box3_empty(), *rcbox = box3_empty();
    for (uint32_t i = 0; i < PAR_CHUNKS; i++) {
        uint32_t b, e;
        par_chunk(begin, end, i, &b, &e);
        mid += j->local_mid[i] - b;
        *lcbox = box3_union(*lcbox, j->lc[i]), *rcbox = box3_union(*rcbox, j->rc[i]);
    }
    j->rn = j->ln = 0;
    j->misplaced = 0;
    for (uint32_t i = 0; i < PAR_CHUNKS; i++) {
        uint32_t b, e, m = j->local_mid[i];
        par_chunk(begin, end, i, &b, &e);
        uint32_t r0 = m, r1 = e < mid ? e : mid; /* right side before mid */
        if (r0 < r1) j->rb[j->rn] = r0, j->re[j->rn++] = r1, j->misplaced += r1 - r0;
        uint32_t l0 = b > mid ? b : mid, l1 = m; /* left side after mid */
        if (l0 < l1) j->lb[j->ln] = l0, j->le[j->ln++] = l1;
    }
    if (j->misplaced) {
        if (c->top_pool) sys_pool_parallel_for(c->top_pool, PAR_CHUNKS, part_swap_task, j);
        else
            for (uint32_t i = 0; i < PAR_CHUNKS; i++) part_swap_task(j, i, 0);
    }
    return mid;
}

/* Processes one node: makes it a leaf or splits it and returns its two children as tasks. */
static uint32_t node_pair(build_ctx *c, uint32_t thread) {
    node_chunk *k = &c->chunks[thread];
    if (k->next == k->end) {
        k->next = atomic_fetch_add_explicit(&c->node_count, NODE_CHUNK, memory_order_relaxed);
        k->end = k->next + NODE_CHUNK;
    }
    uint32_t first = k->next;
    k->next += 2;
    return first;
}

static int build_node(build_ctx *c, uint32_t thread, const task *t, task out[2], tree_stats *st) {
    uint32_t n = t->end - t->begin;
    bvh_node *node = &c->nodes[t->node];
    /* the node's box is the union of its primitives' (the parent's bins gave it) */
    box3 b = node_box(node);
    /* a node of one intersection block is a leaf without binning (as Embree's minLeafSize): the
     * SAH had split almost none of them (kitchen's SAH cost 14.62 -> 14.72, 48 leaves fewer of
     * 28539), and binning them took 5-8% of a build (kitchen, rings; spd_tree 3%) */
    if (n <= 1 || (n <= c->block && n <= (uint32_t)c->max_leaf)) return make_leaf(node, t, b, c->inv_root_area, st);
    box3 lbox, rbox, lcbox, rcbox;
    uint32_t mid = 0;
    if (t->depth < MEDIAN_DEPTH) {
        split_plan sp;
        bool found = split_find(c, t->begin, t->end, t->cbox, b, &sp);
        /* SAH termination (in block intersections, as Embree's builders): a leaf when it is
         * no costlier than the best split and small enough */
        double area = box3_half_area(b);
        if (n <= (uint32_t)c->max_leaf && (!found || area * blocks_of(c, n) <= area * c->trav_cost + sp.cost))
            return make_leaf(node, t, b, c->inv_root_area, st);
        if (found) {
            mid = n >= PAR_MIN ? split_partition_par(c, t->begin, t->end, &sp, &lcbox, &rcbox)
                               : split_partition(c, t->begin, t->end, &sp, &lcbox, &rcbox);
            lbox = sp.lbox, rbox = sp.rbox;
        }
    } else if (n <= (uint32_t)c->max_leaf) {
        return make_leaf(node, t, b, c->inv_root_area, st);
    }
    if (mid == 0) {
        /* identical centroids, or too deep: halve the range (order within it is arbitrary) */
        mid = t->begin + n / 2;
        lbox = prim_range_box(c, t->begin, mid, &lcbox);
        rbox = prim_range_box(c, mid, t->end, &rcbox);
    }
    st->cost += cost_fixed(box3_half_area(b), 1.0, c->inv_root_area);
    uint32_t first = node_pair(c, thread);
    node->index = first;
    node->count = 0;
    set_node_box(&c->nodes[first], lbox);
    set_node_box(&c->nodes[first + 1], rbox);
    out[0] = (task){first, t->begin, mid, t->depth + 1, lcbox};
    out[1] = (task){first + 1, mid, t->end, t->depth + 1, rcbox};
    return 2;
}

static void build_subtree(build_ctx *c, uint32_t thread, task root, tree_stats *st) {
    task stack[2 * BVHW_MAX_DEPTH + 8];
    uint32_t sp = 0;
    stack[sp++] = root;
    while (sp) {
        task t = stack[--sp];
        task kids[2];
        if (build_node(c, thread, &t, kids, st) == 2) {
            stack[sp++] = kids[1];
            stack[sp++] = kids[0];
        }
    }
}

static void build_task(void *user, uint32_t index, uint32_t thread) {
    build_ctx *c = user;
    /* gathered locally: the tasks' stats share cache lines, and the threads, writing them at
     * every node, had slowed each other by a fifth */
    tree_stats st = {0};
    build_subtree(c, thread, c->tasks[index], &st);
    c->task_stats[index] = st;
}

/* One level of the top of the tree: node `index` of `in` split into out[2 index], out[2 index + 1]. */
#define LEVEL_MAX 256u /* nodes split per level; 2 LEVEL_MAX + subtrees fit the task array */
typedef struct level_job {
    build_ctx *c;
    const task *in;
    task *out;
    uint8_t *split;
    tree_stats *stats; /* one per node of the level */
    const uint32_t *index; /* the nodes of the level to split (NULL: index itself) */
} level_job;

static void level_task(void *user, uint32_t index, uint32_t thread) {
    level_job *j = user;
    if (j->index) index = j->index[index];
    j->split[index] = build_node(j->c, thread, &j->in[index], &j->out[2 * index], &j->stats[index]) == 2;
}

/* The identity permutation, the root box and the centroids' box, by chunks. */
typedef struct init_job {
    const bvh_prim *boxes;
    uint32_t *prims;
    uint32_t n, chunks; /* at most PAR_CHUNKS */
    box3 part[PAR_CHUNKS], cpart[PAR_CHUNKS]; /* boxes and centroid boxes */
} init_job;

static void init_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    init_job *j = user;
    uint64_t n = j->n;
    uint32_t b = (uint32_t)(n * index / j->chunks), e = (uint32_t)(n * (index + 1) / j->chunks);
    vf4 lo = vf4_splat(INFINITY), hi = vf4_splat(-INFINITY), clo = lo, chi = hi;
    for (uint32_t i = b; i < e; i++) {
        const bvh_prim *p = &j->boxes[i];
        j->prims[i] = i;
        vf4 ce = centroid_of(p);
        lo = vf4_min(lo, p->lo), hi = vf4_max(hi, p->hi);
        clo = vf4_min(clo, ce), chi = vf4_max(chi, ce);
    }
    j->part[index] = box_of(lo, hi), j->cpart[index] = box_of(clo, chi);
}

bool bvh_build(const sys_allocator *alloc, sys_pool *pool, bvh_prim *boxes, uint32_t n, const bvh_build_desc *desc,
               bvh2 *out) {
    memset(out, 0, sizeof *out);
    int threads = pool ? sys_pool_threads(pool) : 1;
    /* the root, an unused node 1 (so pairs start at even indices), the pairs, and the unused rest
     * of every thread's last chunk */
    uint32_t cap = (n ? 2 * n : 2) + (uint32_t)threads * NODE_CHUNK;
    size_t kbytes = (size_t)threads * sizeof(node_chunk);
    node_chunk *chunks = sys_calloc(alloc, kbytes);
    out->nodes = sys_alloc(alloc, (size_t)cap * sizeof(bvh_node));
    out->prims = sys_alloc(alloc, (size_t)(n ? n : 1) * sizeof(uint32_t));
    /* sizes first: bvh2_free hands them to the allocator hook, also on the failure path */
    out->node_capacity = cap;
    out->prim_count = n;
    if (!out->nodes || !out->prims || !chunks) {
        sys_free(alloc, chunks, kbytes);
        bvh2_free(alloc, out);
        return false;
    }
    box3 root = box3_empty();
    /* large inputs on all threads: a serial pass (and its page faults) over millions of boxes
     * was a tenth of a large build on two threads */
    bool par_init = pool && sys_pool_threads(pool) > 1 && n >= PAR_MIN;
    init_job ij = {.boxes = boxes, .prims = out->prims, .n = n,
                   .chunks = par_init ? PAR_CHUNKS : 1};
    if (par_init) sys_pool_parallel_for(pool, ij.chunks, init_task, &ij);
    else init_task(&ij, 0, 0);
    box3 croot = box3_empty();
    for (uint32_t i = 0; i < ij.chunks; i++) root = box3_union(root, ij.part[i]), croot = box3_union(croot, ij.cpart[i]);
    build_ctx c = {
        .boxes = boxes, .prims = out->prims, .nodes = out->nodes,
        .bins = desc->bins < 4 ? 4 : desc->bins > MAX_BINS ? MAX_BINS : desc->bins,
        .max_leaf = desc->max_leaf_size < 1 ? 1 : desc->max_leaf_size,
        .alloc = alloc,
        .block = desc->block_size < 1 ? 1u : (uint32_t)desc->block_size,
        .block_shift = -1,
        .trav_cost = desc->trav_cost > 0.0f ? desc->trav_cost : 1.0,
    };
    double root_area = box3_half_area(root);
    c.inv_root_area = root_area > 0.0 && isfinite(1.0 / root_area) ? 1.0 / root_area : 0.0;
    if ((c.block & (c.block - 1)) == 0) c.block_shift = __builtin_ctz(c.block);
    c.chunks = chunks;
    atomic_store(&c.node_count, 2);
    memset(&out->nodes[1], 0, sizeof(bvh_node));
    set_node_box(&out->nodes[0], root);
    out->nodes[0].index = 0;
    out->nodes[0].count = n;

    tree_stats st = {0};
    if (threads > 1 && n > 4096) {
        /* Split level by level until the open subtrees are small enough to balance the threads
         * (below: which nodes of a level all threads split together). */
        uint32_t grain = n / (uint32_t)(threads * 16);
        if (grain < 1024) grain = 1024;
        c.task_capacity = 1024;
        size_t qbytes = (size_t)LEVEL_MAX * 2 * sizeof(task);
        c.tasks = sys_alloc(alloc, c.task_capacity * sizeof(task));
        c.task_stats = sys_calloc(alloc, c.task_capacity * sizeof(tree_stats));
        task *level = sys_alloc(alloc, qbytes), *kids = sys_alloc(alloc, qbytes);
        if (!c.tasks || !c.task_stats || !level || !kids) {
            sys_free(alloc, c.tasks, c.task_capacity * sizeof(task));
            sys_free(alloc, c.task_stats, c.task_capacity * sizeof(tree_stats));
            sys_free(alloc, level, qbytes);
            sys_free(alloc, kids, qbytes);
            sys_free(alloc, chunks, kbytes);
            bvh2_free(alloc, out);
            return false;
        }
        uint8_t split[LEVEL_MAX];
        uint32_t ln = 1;
        level[0] = (task){0, 0, n, 0, croot};
        while (ln) {
            /* small nodes become subtree tasks, and so does any node whose two children might
             * not fit the task array (every open node still needs a slot there) */
            uint32_t wn = 0;
            for (uint32_t i = 0; i < ln; i++) {
                bool room = wn < LEVEL_MAX && c.task_count + 2 * (wn + 1) + (ln - i - 1) <= c.task_capacity;
                if (level[i].end - level[i].begin <= grain || !room) c.tasks[c.task_count++] = level[i];
                else level[wn++] = level[i];
            }
            if (!wn) break;
            tree_stats lstats[LEVEL_MAX] = {{0}};
            /* While the largest node left is large and over 5/4 of a thread's share of the nodes
             * left, it is split by all threads (binned and partitioned in chunks); the rest are
             * split a node per thread. Node per thread throughout, a level of kitchen's (100682
             * and 9496 primitives) had run on one thread. */
            uint64_t left = 0;
            uint32_t rest[LEVEL_MAX], rn = wn;
            for (uint32_t i = 0; i < wn; i++) left += task_size(&level[i]), rest[i] = i;
            level_job job = {.c = &c, .in = level, .out = kids, .split = split, .stats = lstats};
            c.top_pool = pool;
            while (rn) {
                uint32_t big = 0, size = task_size(&level[rest[0]]);
                for (uint32_t i = 1; i < rn; i++)
                    if (task_size(&level[rest[i]]) > size) big = i, size = task_size(&level[rest[i]]);
                uint32_t node = rest[big];
                if (size < PAR_MIN || (uint64_t)size * 4u * (uint32_t)threads <= left * 5u) break;
                level_task(&job, node, 0);
                left -= size;
                rest[big] = rest[--rn];
            }
            c.top_pool = NULL;
            if (rn) {
                job.index = rest;
                sys_pool_parallel_for(pool, rn, level_task, &job);
            }
            ln = 0;
            for (uint32_t i = 0; i < wn; i++) {
                stats_merge(&st, &lstats[i]);
                if (split[i]) level[ln++] = kids[2 * i], level[ln++] = kids[2 * i + 1];
            }
        }
        c.top_pool = NULL; /* the subtrees run on the pool themselves */
        sys_pool_parallel_for(pool, c.task_count, build_task, &c);
        for (uint32_t i = 0; i < c.task_count; i++) stats_merge(&st, &c.task_stats[i]);
        sys_free(alloc, c.tasks, c.task_capacity * sizeof(task));
        sys_free(alloc, c.task_stats, c.task_capacity * sizeof(tree_stats));
        sys_free(alloc, level, qbytes);
        sys_free(alloc, kids, qbytes);
    } else {
        build_subtree(&c, 0, (task){0, 0, n, 0, croot}, &st);
    }
    for (int i = 0; i < threads; i++)
        if (chunks[i].next < chunks[i].end)
            memset(&out->nodes[chunks[i].next], 0, (size_t)(chunks[i].end - chunks[i].next) * sizeof(bvh_node));
    sys_free(alloc, chunks, kbytes);
    out->node_count = atomic_load(&c.node_count);
    out->depth = st.depth;
    out->leaf_count = st.leaves;
    out->sah_cost = (double)st.cost * 0x1p-32;
    return true;
}

void bvh2_free(const sys_allocator *alloc, bvh2 *bvh) {
    sys_free(alloc, bvh->nodes, (size_t)bvh->node_capacity * sizeof(bvh_node));
    sys_free(alloc, bvh->prims, (size_t)(bvh->prim_count ? bvh->prim_count : 1) * sizeof(uint32_t));
    memset(bvh, 0, sizeof *bvh);
}
