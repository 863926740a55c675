/* BIH build (Waechter, Keller 2006, sec. 2.2-2.3): the global heuristic splits the node's split
 * box (not the objects' box) in the middle of its longest side, sorts the primitives by centroid
 * to the two sides in place (one quicksort-like pass over the box array), and keeps each side's
 * extreme bound as its clip plane; when one side is empty the split box is halved towards the
 * other and the step repeated, so no node is made. Every inner node has two non-empty children,
 * so 2n - 1 nodes suffice: they are allocated once, from the primitive count (with room for the
 * clip nodes and the threads' chunks of nodes, bih_build). Nodes larger than
 * a share of the primitives (BIH_TASK_SHARE per thread) are split on the calling thread, the
 * largest with a partition that all threads run (BIH_PAR_MIN); the subtrees below them are tasks,
 * handed to the threads largest first (spd_tree_s12's depth-4 subtrees, the tasks until then, held
 * a third of its triangles in one, and one thread built it while the other had finished). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "accel/accel.h"
#include "accel/bih/bih.h"

/* Subtrees of at most 1 / (BIH_TASK_SHARE x threads) of the primitives are tasks. */
#define BIH_TASK_SHARE 8u

typedef struct bih_task {
    uint32_t node, begin, end, depth;
    float sb[6], nb[6];
    vf4 clo, chi; /* twice the centroids' bounds */
    vf4 blo, bhi; /* the boxes' bounds */
} bih_task;

/* Nodes are handed to the threads in chunks of BIH_NODE_CHUNK, one atomic per chunk: an atomic
 * add per node, and the leaves' and the depth's counters, on lines both threads wrote, held about a
 * third of split's own samples (perf annotate, spd_tree_s12, two threads). A chunk too short for a pair of children leaves at most
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
    bvh_prim *p;               /* the boxes, reordered in place; lo[3] holds each one's id */
    bih_node *nodes;
    _Atomic uint32_t next;     /* first free node */
    uint32_t task_max;         /* subtrees of at most this many primitives are tasks (with a pool) */
    sys_pool *pool;            /* the threads, while the top of the tree is split */
    bih_task *tasks;
    uint32_t task_count, task_cap;
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

/* Twice the centroids' bounds of a range (lo + hi of each box), lanes x, y, z. */
typedef struct cbounds {
    vf4 lo, hi;
} cbounds;

/* What a partition found out about its two sides: the left side's upper bound and the right
 * side's lower bound (the clip planes, lane axis), the rest of their boxes, and the centroids'
 * bounds of the whole range. */
typedef struct sides {
    vf4 lhi, rlo, llo, rhi; /* the clip planes are lhi and rlo; llo and rhi complete the boxes */
    cbounds all;
} sides;

static inline sides sides_empty(void) {
    vf4 inf = vf4_splat(INFINITY), ninf = vf4_splat(-INFINITY);
    return (sides){ninf, inf, inf, ninf, {inf, ninf}};
}

static inline void sides_merge(sides *s, const sides *o) {
    s->lhi = vf4_max(s->lhi, o->lhi), s->rlo = vf4_min(s->rlo, o->rlo);
    s->llo = vf4_min(s->llo, o->llo), s->rhi = vf4_max(s->rhi, o->rhi);
    s->all.lo = vf4_min(s->all.lo, o->all.lo), s->all.hi = vf4_max(s->all.hi, o->all.hi);
}

/* Bounds of a side's centroids (twice) from what the partition tracked: within twice its boxes'
 * bounds (lo + hi rounds monotonically, so 2 lo <= fl(lo + hi) <= 2 hi) and the range's
 * centroids' bounds, and on the split axis below (left) or from (right) the plane. Not tight:
 * split partitions once more when a plane they allow leaves a side empty. */
static inline cbounds side_cbounds(const sides *s, bool left, int axis, float twice) {
    vf4 two = vf4_splat(2.0f);
    cbounds b = left ? (cbounds){vf4_max(two * s->llo, s->all.lo), vf4_min(two * s->lhi, s->all.hi)}
                     : (cbounds){vf4_max(two * s->rlo, s->all.lo), vf4_min(two * s->rhi, s->all.hi)};
    if (left) b.hi[axis] = b.hi[axis] < twice ? b.hi[axis] : twice;
    else b.lo[axis] = b.lo[axis] > twice ? b.lo[axis] : twice;
    return b;
}

/* Partition of [i, j) by centroid (lo + hi < twice on axis: left), without a branch on the side
 * (Lomuto's scheme: each box swapped to the left side's end, which advances when it is a left
 * one): a Hoare partition's side tests are data-dependent branches that a processor mispredicts
 * about every other box (the partitions are most of a BIH build's own time: docs/bih.md). Each
 * side's bounds are taken with the box moved to +-infinity when it is on the other side (min and
 * max only, no select); returns the first right-side position. */
static uint32_t partition(bvh_prim *p, uint32_t i, uint32_t j, int axis, float twice, sides *s) {
    /* far[left]: where the box goes for the left side's minima (+inf: not left) */
    static const float far[2] = {INFINITY, -INFINITY};
    vf4 llo = s->llo, lhi = s->lhi, rlo = s->rlo, rhi = s->rhi, clo = s->all.lo, chi = s->all.hi;
    uint32_t k = i;
    for (uint32_t q = i; q < j; q++) {
        vf4 lo = p[q].lo, hi = p[q].hi, c = lo + hi;
        uint32_t left = c[axis] < twice;
        vf4 a = vf4_splat(far[left]), b = vf4_splat(far[left ^ 1u]); /* b = -a */
        llo = vf4_min(llo, vf4_max(lo, a)), lhi = vf4_max(lhi, vf4_min(hi, b));
        rlo = vf4_min(rlo, vf4_max(lo, b)), rhi = vf4_max(rhi, vf4_min(hi, a));
        clo = vf4_min(clo, c), chi = vf4_max(chi, c);
        bvh_prim t = p[k];
        p[k] = p[q], p[q] = t;
        k += left;
    }
    s->llo = llo, s->lhi = lhi, s->rlo = rlo, s->rhi = rhi;
    s->all = (cbounds){clo, chi};
    return k;
}

/* The partition of a large node by all threads: BIH_PAR_CHUNKS chunks partitioned in place, then
 * the right-side boxes before the node's middle swapped with the left-side ones after it (the
 * BVH's split_partition_par). The sides are the same sets as a serial partition's, so the tree
 * is the same. */
#define BIH_PAR_MIN 65536u
#define BIH_PAR_CHUNKS 16u
typedef struct par_job {
    bvh_prim *p;
    uint32_t begin, end, mid;
    int axis;
    float twice;
    uint32_t local_mid[BIH_PAR_CHUNKS];
    sides side[BIH_PAR_CHUNKS];
    /* the misplaced boxes: ranges of right-side ones before mid, left-side ones after it */
    uint32_t rb[BIH_PAR_CHUNKS], re[BIH_PAR_CHUNKS], lb[BIH_PAR_CHUNKS], le[BIH_PAR_CHUNKS];
    uint32_t rn, ln;
    uint64_t misplaced;
} par_job;

static void par_chunk(const par_job *j, uint32_t index, uint32_t *b, uint32_t *e) {
    uint64_t n = j->end - j->begin;
    *b = j->begin + (uint32_t)(n * index / BIH_PAR_CHUNKS), *e = j->begin + (uint32_t)(n * (index + 1) / BIH_PAR_CHUNKS);
}

static void par_local_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    par_job *j = user;
    uint32_t b, e;
    par_chunk(j, index, &b, &e);
    j->side[index] = sides_empty();
    j->local_mid[index] = partition(j->p, b, e, j->axis, j->twice, &j->side[index]);
}

/* Position of the k-th element of the ranges [b[i], e[i]) taken in order; *i: the range. */
static uint32_t par_locate(const uint32_t *b, const uint32_t *e, uint32_t count, uint64_t k, uint32_t *i) {
    for (*i = 0; *i < count; (*i)++) {
        if (k < e[*i] - b[*i]) return b[*i] + (uint32_t)k;
        k -= e[*i] - b[*i];
    }
    return 0; /* not reached: k < the ranges' total */
}

static void par_swap_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    par_job *j = user;
    uint64_t k = j->misplaced * index / BIH_PAR_CHUNKS, kend = j->misplaced * (index + 1) / BIH_PAR_CHUNKS;
    if (k == kend) return;
    uint32_t ri, li;
    uint32_t r = par_locate(j->rb, j->re, j->rn, k, &ri), l = par_locate(j->lb, j->le, j->ln, k, &li);
    for (; k < kend; k++) {
        bvh_prim x = j->p[r];
        j->p[r] = j->p[l], j->p[l] = x;
        if (++r == j->re[ri] && ri + 1 < j->rn) r = j->rb[++ri];
        if (++l == j->le[li] && li + 1 < j->ln) l = j->lb[++li];
    }
}

static uint32_t partition_par(sys_pool *pool, bvh_prim *p, uint32_t begin, uint32_t end, int axis, float twice,
                              sides *s) {
    par_job job = {.p = p, .begin = begin, .end = end, .axis = axis, .twice = twice}, *j = &job;
    sys_pool_parallel_for(pool, BIH_PAR_CHUNKS, par_local_task, j);
    uint32_t mid = begin;
    for (uint32_t i = 0; i < BIH_PAR_CHUNKS; i++) {
        uint32_t b, e;
        par_chunk(j, i, &b, &e);
        mid += j->local_mid[i] - b;
        sides_merge(s, &j->side[i]);
    }
    for (uint32_t i = 0; i < BIH_PAR_CHUNKS; i++) {
        uint32_t b, e, m = j->local_mid[i];
        par_chunk(j, i, &b, &e);
        uint32_t r0 = m, r1 = e < mid ? e : mid; /* right side before mid */
        if (r0 < r1) j->rb[j->rn] = r0, j->re[j->rn++] = r1, j->misplaced += r1 - r0;
        uint32_t l0 = b > mid ? b : mid, l1 = m; /* left side after mid */
        if (l0 < l1) j->lb[j->ln] = l0, j->le[j->ln++] = l1;
    }
    if (j->misplaced) sys_pool_parallel_for(pool, BIH_PAR_CHUNKS, par_swap_task, j);
    return mid;
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

static void split(bih_ctx *c, bih_local *l, uint32_t node, uint32_t begin, uint32_t end, float sb[6], cbounds cb, float nb[6],
                  vf4 blo, vf4 bhi, uint32_t depth, bool spawn) {
    for (;;) {
        node = clip_empty(c, l, node, nb, blo, bhi);
        if (end - begin <= BIH_LEAF_SIZE || depth >= BIH_MAX_DEPTH) {
            make_leaf(c, l, node, begin, end, depth);
            return;
        }
        /* a subtree small enough is a task (or, the task list full, built here) */
        if (spawn && end - begin <= c->task_max && c->task_count < c->task_cap) {
            bih_task *t = &c->tasks[c->task_count++];
            *t = (bih_task){node, begin, end, depth, {0}, {0}, cb.lo, cb.hi, blo, bhi};
            memcpy(t->sb, sb, sizeof t->sb), memcpy(t->nb, nb, sizeof t->nb);
            return;
        }
        /* Halve the split box until its plane parts the centroids. When every centroid lies on one
         * side the paper halves the box and partitions again; the centroids' bounds tell the
         * outcome of that pass in advance, so the same planes are found without it. The bounds a
         * parent's partition gives its children are not tight (side_cbounds); when a plane they
         * allow leaves a side empty, that pass gives the range's own bounds, and the halving goes on
         * from them. */
        int axis = 0;
        float plane = 0.0f, twice = 0.0f;
        sides sd;
        uint32_t i;
        for (;;) {
            for (int tries = 0;; tries++) {
                float e0 = sb[3] - sb[0], e1 = sb[4] - sb[1], e2 = sb[5] - sb[2];
                axis = e1 > e0 ? (e2 > e1 ? 2 : 1) : (e2 > e0 ? 2 : 0);
                plane = 0.5f * (sb[axis] + sb[3 + axis]);
                /* nothing left to halve (equal centroids): a leaf of them all */
                if (tries >= 64 || !(plane > sb[axis] && plane < sb[3 + axis])) {
                    make_leaf(c, l, node, begin, end, depth);
                    return;
                }
                twice = 2.0f * plane;
                if (cb.lo[axis] >= twice) sb[axis] = plane;          /* all on the right */
                else if (cb.hi[axis] < twice) sb[3 + axis] = plane;  /* all on the left */
                else break;
            }
            sd = sides_empty();
            i = spawn && c->pool && end - begin >= BIH_PAR_MIN ? partition_par(c->pool, c->p, begin, end, axis, twice, &sd)
                                                               : partition(c->p, begin, end, axis, twice, &sd);
            if (i != begin && i != end) break;
            cb = sd.all; /* tight now: the next halvings need no pass */
        }
        uint32_t child = node_alloc(c, l, 2);
        c->nodes[node] = (bih_node){{pad_hi(c, sd.lhi[axis]), pad_lo(c, sd.rlo[axis])}, child << BIH_TAG_BITS | (uint32_t)axis};
        float sl[6], sr[6], nl[6];
        memcpy(sl, sb, sizeof sl), memcpy(sr, sb, sizeof sr), memcpy(nl, nb, sizeof nl);
        sl[3 + axis] = plane, sr[axis] = plane;
        if (sd.lhi[axis] < nl[3 + axis]) nl[3 + axis] = sd.lhi[axis];
        if (sd.rlo[axis] > nb[axis]) nb[axis] = sd.rlo[axis];
        split(c, l, child, begin, i, sl, side_cbounds(&sd, true, axis, twice), nl, sd.llo, sd.lhi, depth + 1, spawn);
        /* the right side in this frame (a loop, not a call: the recursion's depth is the left path) */
        node = child + 1, begin = i, depth = depth + 1, cb = side_cbounds(&sd, false, axis, twice), blo = sd.rlo, bhi = sd.rhi;
        memcpy(sb, sr, sizeof sr);
    }
}

/* Tasks largest first: the pool hands them out in order, so the last to start are the shortest. */
static int task_larger(const void *a, const void *b) {
    const bih_task *x = a, *y = b;
    uint32_t nx = x->end - x->begin, ny = y->end - y->begin;
    return nx > ny ? -1 : nx < ny ? 1 : (x->begin > y->begin) - (x->begin < y->begin);
}

static void task_run(void *user, uint32_t index, uint32_t thread) {
    bih_ctx *c = user;
    bih_task t = c->tasks[index];
    split(c, &c->local[thread], t.node, t.begin, t.end, t.sb, (cbounds){t.clo, t.chi}, t.nb, t.blo, t.bhi, t.depth, false);
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

static bool bih_build(const sys_allocator *a, sys_pool *pool, accel_tri_input *in, accel_built *out) {
    memset(out, 0, sizeof *out);
    uint32_t n = in->count;
    bih_ctx c = {.in = in, .p = in->boxes};
    uint32_t threads = pool && n >= 4096 ? (uint32_t)sys_pool_threads(pool) : 1;
    if (threads < 2) pool = NULL, threads = 1;
    /* real nodes: 2n - 1; clip nodes: at most one in front of each (clip_empty); the chunks (each
     * gives at least BIH_NODE_CHUNK - 1 before the next, and each thread's last one). They are
     * copied to an allocation of their count (about n on the shared scenes) when the leaves are
     * filled. */
    size_t node_cap = 1 + (size_t)BIH_NODE_CHUNK * ((size_t)4 * n / (BIH_NODE_CHUNK - 1) + 1 + threads);
    size_t node_bytes = node_cap * sizeof(bih_node), local_bytes = threads * sizeof(bih_local);
    c.nodes = sys_alloc(a, node_bytes);
    c.block_of = sys_alloc(a, (size_t)n * sizeof(uint32_t) + 4);
    c.local = sys_alloc(a, local_bytes);
    if (c.local) memset(c.local, 0, local_bytes);
    c.task_max = n / (BIH_TASK_SHARE * threads);
    c.task_cap = 4096;
    c.pool = pool;
    c.tasks = pool ? sys_alloc(a, c.task_cap * sizeof(bih_task)) : NULL;
    if (!c.nodes || !c.block_of || !c.local || (pool && !c.tasks)) {
        sys_free(a, c.nodes, node_bytes), sys_free(a, c.block_of, (size_t)n * sizeof(uint32_t) + 4);
        sys_free(a, c.local, local_bytes);
        sys_free(a, c.tasks, c.task_cap * sizeof(bih_task));
        return false;
    }
    stamp_ctx st = {in->boxes, n, pool ? threads * 4 : 1};
    if (pool) sys_pool_parallel_for(pool, st.chunks, stamp_task, &st);
    else stamp_task(&st, 0, 0);
    box3 b = in->bounds;
    float sb[6] = {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z};
    memcpy(out->bounds, sb, sizeof sb);
    c.abs_pad = box_pad_abs(sb, sb + 3);
    atomic_store(&c.next, 1);
    float nb[6];
    memcpy(nb, sb, sizeof nb);
    vf4 blo = {b.lo.x, b.lo.y, b.lo.z, 0.0f}, bhi = {b.hi.x, b.hi.y, b.hi.z, 0.0f};
    cbounds cb = {vf4_splat(2.0f) * blo, vf4_splat(2.0f) * bhi}; /* not tight: see split */
    split(&c, &c.local[0], 0, 0, n, sb, cb, nb, blo, bhi, 1, pool != NULL);
    if (pool && c.task_count) {
        qsort(c.tasks, c.task_count, sizeof *c.tasks, task_larger);
        sys_pool_parallel_for(pool, c.task_count, task_run, &c);
    }
    uint32_t node_count = atomic_load(&c.next), depth = 0, unused = 0;
    uint64_t leaves = 0;
    for (uint32_t t = 0; t < threads; t++) {
        bih_local *l = &c.local[t];
        make_unused(&c, l, l->next, l->end);
        depth = l->depth > depth ? l->depth : depth, unused += l->unused, leaves += l->leaves;
    }
    if (c.abs_pad != 0.0f)
        for (int k = 0; k < 3; k++) out->bounds[k] = box_pad_lo(out->bounds[k], c.abs_pad), out->bounds[3 + k] = box_pad_hi(out->bounds[3 + k], c.abs_pad);
    uint32_t blocks = plan_blocks(&c, n);
    c.blocks = accel_blocks_alloc(a, blocks);
    size_t out_bytes = (size_t)node_count * sizeof(bih_node);
    c.out = sys_alloc(a, out_bytes);
    bool ok = c.blocks != NULL && c.out != NULL;
    if (ok) {
        fill_ctx f = {&c, node_count, n, pool ? threads * 8 : 1};
        if (pool) sys_pool_parallel_for(pool, f.chunks, fill_task, &f);
        else fill_task(&f, 0, 0);
    }
    sys_free(a, c.block_of, (size_t)n * sizeof(uint32_t) + 4);
    sys_free(a, c.tasks, c.task_cap * sizeof(bih_task));
    sys_free(a, c.nodes, node_bytes);
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
