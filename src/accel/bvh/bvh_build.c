/* Binned SAH builder (Wald 2007): per node, primitives are binned by centroid along each axis and
 * the split of least SAH cost among bin borders is taken. The top of the tree is split level by
 * level (large nodes binned by all threads, then a node per thread) until there are enough
 * subtrees, which the device's threads then build. */
#include <math.h>
#include <string.h>

#include "accel/bvh/bvh.h"
#include "simd/simd.h"

#define MAX_BINS 64
#define PAR_MIN 65536u     /* nodes this large (at the top of the tree) are binned by all threads */
#define PAR_CHUNKS 32u
#define MEDIAN_DEPTH 64 /* past this depth, split at the median to bound the depth */

/* A primitive box in SIMD form (w lanes unused), so unions are two min/max instructions. */
typedef struct pbox {
    vf4 lo, hi;
} pbox;

typedef struct build_ctx {
    pbox *boxes; /* permuted with prims, so every pass over a node's range reads memory in order */
    uint32_t *prims;
    bvh_node *nodes;
    _Atomic uint32_t node_count;
    int bins;
    int max_leaf;
    uint32_t block;    /* primitives per intersection block */
    double trav_cost;  /* of one node, in block intersections */
    /* the threads, while the top of the tree is split (NULL after) */
    sys_pool *top_pool;
    const sys_allocator *alloc;
    /* subtrees deferred to the threads */
    struct task *tasks;
    uint32_t task_count, task_capacity;
    _Atomic uint32_t depth;
} build_ctx;

typedef struct task {
    uint32_t node, begin, end, depth;
} task;


static inline vf4 centroid_of(const pbox *b) { return b->lo * 0.5f + b->hi * 0.5f; }

static inline box3 box_of(vf4 lo, vf4 hi) { return (box3){v3(lo[0], lo[1], lo[2]), v3(hi[0], hi[1], hi[2])}; }

/* Box and centroid box of [begin, end) as four vectors: lo, hi, centroid lo, centroid hi. */
static void range_boxes(const build_ctx *c, uint32_t begin, uint32_t end, vf4 out[4]) {
    vf4 lo = vf4_splat(INFINITY), hi = vf4_splat(-INFINITY), clo = lo, chi = hi;
    for (uint32_t i = begin; i < end; i++) {
        const pbox *b = &c->boxes[i];
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

static void par_range(const par_job *j, uint32_t index, uint32_t *b, uint32_t *e) {
    uint64_t n = j->end - j->begin;
    *b = j->begin + (uint32_t)(n * index / PAR_CHUNKS), *e = j->begin + (uint32_t)(n * (index + 1) / PAR_CHUNKS);
}

static void boxes_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const par_job *j = user;
    uint32_t b, e;
    par_range(j, index, &b, &e);
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

static void depth_max(build_ctx *c, uint32_t d) {
    uint32_t cur = atomic_load_explicit(&c->depth, memory_order_relaxed);
    while (d > cur && !atomic_compare_exchange_weak(&c->depth, &cur, d)) {
    }
}

/* Bin indices of a centroid on the three axes; clamped in float before the conversion so
 * huge coordinates (or an extent that overflowed) cannot make it undefined, and NaN goes to 0
 * (maxps returns its second operand on NaN). Counting and partitioning both use it, so they
 * always agree. */
static inline vi4 bins_of(vf4 centroid, vf4 lo, vf4 scale, vf4 last) {
    vf4 f = vf4_min(vf4_max((centroid - lo) * scale, vf4_splat(0.0f)), last);
    return __builtin_convertvector(f, vi4);
}

static double half_area4(vf4 lo, vf4 hi) {
    if (!(lo[0] <= hi[0])) return 0.0;
    double dx = (double)hi[0] - lo[0], dy = (double)hi[1] - lo[1], dz = (double)hi[2] - lo[2];
    return dx * dy + dy * dz + dz * dx;
}

/* Bins of the three axes: the union of the boxes and the count of the primitives whose centroid
 * falls in each. */
typedef struct bins {
    vf4 lo[3][MAX_BINS], hi[3][MAX_BINS];
    uint32_t count[3][MAX_BINS];
} bins;

static void bin_range(const build_ctx *c, uint32_t begin, uint32_t end, vf4 lo, vf4 scale, vf4 last, int nb,
                      bins *out) {
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < nb; k++) out->lo[a][k] = vf4_splat(INFINITY), out->hi[a][k] = vf4_splat(-INFINITY), out->count[a][k] = 0;
    for (uint32_t i = begin; i < end; i++) {
        const pbox *p = &c->boxes[i];
        vi4 b = bins_of(centroid_of(p), lo, scale, last);
        for (int a = 0; a < 3; a++) {
            int k = b[a];
            out->lo[a][k] = vf4_min(out->lo[a][k], p->lo);
            out->hi[a][k] = vf4_max(out->hi[a][k], p->hi);
            out->count[a][k]++;
        }
    }
}

static void bins_merge(bins *dst, const bins *src, int nb) {
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < nb; k++) {
            dst->lo[a][k] = vf4_min(dst->lo[a][k], src->lo[a][k]);
            dst->hi[a][k] = vf4_max(dst->hi[a][k], src->hi[a][k]);
            dst->count[a][k] += src->count[a][k];
        }
}

static void bins_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const par_job *j = user;
    uint32_t b, e;
    par_range(j, index, &b, &e);
    bin_range(j->c, b, e, j->lo, j->scale, j->last, j->nb, (bins *)j->out + index);
}

/* Splits [begin, end) in place; returns the first index of the right half and the two boxes, or
 * 0 when no split was found (all centroids in one bin on every axis). One pass bins all three
 * axes at once. */
static inline double blocks_of(const build_ctx *c, uint32_t n) { return (double)((n + c->block - 1) / c->block); }

static uint32_t split_sah(build_ctx *c, uint32_t begin, uint32_t end, box3 cbox, box3 *lbox, box3 *rbox,
                          double *split_cost) {
    /* small nodes: about one bin per primitive is as good, and the sweeps over empty bins
     * dominated the build's time near the leaves */
    int nb = c->bins;
    if ((uint32_t)nb > end - begin) nb = end - begin < 4 ? 4 : (int)(end - begin);
    vf4 lo = {cbox.lo.x, cbox.lo.y, cbox.lo.z, 0.0f}, scale = vf4_splat(0.0f);
    bool usable[3];
    for (int axis = 0; axis < 3; axis++) {
        double extent = (double)v3_get(cbox.hi, axis) - (double)v3_get(cbox.lo, axis);
        float sc = extent > 0.0 ? (float)((double)nb * (1.0 - 1e-6) / extent) : 0.0f;
        usable[axis] = sc > 0.0f && isfinite(sc);
        scale[axis] = usable[axis] ? sc : 0.0f;
    }
    if (!usable[0] && !usable[1] && !usable[2]) return 0;
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
    vf4 (*blo)[MAX_BINS] = acc.lo, (*bhi)[MAX_BINS] = acc.hi;
    uint32_t (*bcount)[MAX_BINS] = acc.count;
    double best_cost = INFINITY;
    int best_axis = -1, best_split = 0;
    vf4 best_llo = {0}, best_lhi = {0}, best_rlo = {0}, best_rhi = {0};
    for (int axis = 0; axis < 3; axis++) {
        if (!usable[axis]) continue;
        /* right-to-left sweep, then left-to-right with the cost of each border */
        double rarea[MAX_BINS];
        uint32_t rcount[MAX_BINS];
        vf4 rlo_acc = vf4_splat(INFINITY), rhi_acc = vf4_splat(-INFINITY), rlos[MAX_BINS], rhis[MAX_BINS];
        uint32_t rc = 0;
        for (int b = nb - 1; b > 0; b--) {
            rlo_acc = vf4_min(rlo_acc, blo[axis][b]), rhi_acc = vf4_max(rhi_acc, bhi[axis][b]);
            rc += bcount[axis][b];
            rarea[b] = half_area4(rlo_acc, rhi_acc);
            rcount[b] = rc;
            rlos[b] = rlo_acc, rhis[b] = rhi_acc;
        }
        vf4 llo = vf4_splat(INFINITY), lhi = vf4_splat(-INFINITY);
        uint32_t lc = 0;
        for (int b = 1; b < nb; b++) {
            llo = vf4_min(llo, blo[axis][b - 1]), lhi = vf4_max(lhi, bhi[axis][b - 1]);
            lc += bcount[axis][b - 1];
            if (lc == 0 || rcount[b] == 0) continue;
            double cost = half_area4(llo, lhi) * blocks_of(c, lc) + rarea[b] * blocks_of(c, rcount[b]);
            if (cost < best_cost) {
                best_cost = cost, best_axis = axis, best_split = b;
                best_llo = llo, best_lhi = lhi, best_rlo = rlos[b], best_rhi = rhis[b];
            }
        }
    }
    if (best_axis < 0) return 0;
    *split_cost = best_cost;
    /* Hoare partition by bin */
    uint32_t i = begin, j = end;
    while (i < j) {
        if (bins_of(centroid_of(&c->boxes[i]), lo, scale, last)[best_axis] < best_split) {
            i++;
        } else {
            j--;
            uint32_t p = c->prims[i];
            c->prims[i] = c->prims[j], c->prims[j] = p;
            pbox b = c->boxes[i];
            c->boxes[i] = c->boxes[j], c->boxes[j] = b;
        }
    }
    *lbox = box_of(best_llo, best_lhi), *rbox = box_of(best_rlo, best_rhi);
    return i;
}

/* Processes one node: makes it a leaf or splits it and returns its two children as tasks. */
static int build_node(build_ctx *c, const task *t, task out[2]) {
    uint32_t n = t->end - t->begin;
    bvh_node *node = &c->nodes[t->node];
    depth_max(c, t->depth + 1);
    if (n <= 1) {
        node->index = t->begin;
        node->count = n;
        return 0;
    }
    box3 cbox;
    box3 lbox, rbox;
    uint32_t mid = 0;
    if (t->depth < MEDIAN_DEPTH) {
        box3 b = prim_range_box(c, t->begin, t->end, &cbox);
        double split_cost = INFINITY;
        mid = split_sah(c, t->begin, t->end, cbox, &lbox, &rbox, &split_cost);
        /* SAH termination (in block intersections, as Embree's builders): a leaf when it is
         * no costlier than the best split and small enough */
        double area = box3_half_area(b);
        if (n <= (uint32_t)c->max_leaf &&
            (mid == 0 || area * blocks_of(c, n) <= area * c->trav_cost + split_cost)) {
            /* the split may have permuted the range; a leaf does not care */
            node->index = t->begin;
            node->count = n;
            return 0;
        }
    } else if (n <= (uint32_t)c->max_leaf) {
        node->index = t->begin;
        node->count = n;
        return 0;
    }
    if (mid == 0) {
        /* identical centroids, or too deep: halve the range (order within it is arbitrary) */
        mid = t->begin + n / 2;
        box3 unused;
        lbox = prim_range_box(c, t->begin, mid, &unused);
        rbox = prim_range_box(c, mid, t->end, &unused);
    }
    uint32_t first = atomic_fetch_add_explicit(&c->node_count, 2, memory_order_relaxed);
    node->index = first;
    node->count = 0;
    set_node_box(&c->nodes[first], lbox);
    set_node_box(&c->nodes[first + 1], rbox);
    out[0] = (task){first, t->begin, mid, t->depth + 1};
    out[1] = (task){first + 1, mid, t->end, t->depth + 1};
    return 2;
}

static void build_subtree(build_ctx *c, task root) {
    task stack[2 * BVHW_MAX_DEPTH + 8];
    uint32_t sp = 0;
    stack[sp++] = root;
    while (sp) {
        task t = stack[--sp];
        task kids[2];
        if (build_node(c, &t, kids) == 2) {
            stack[sp++] = kids[1];
            stack[sp++] = kids[0];
        }
    }
}

static void build_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    build_ctx *c = user;
    build_subtree(c, c->tasks[index]);
}

/* One level of the top of the tree: node `index` of `in` split into out[2 index], out[2 index + 1]. */
#define LEVEL_MAX 256u /* nodes split per level; 2 LEVEL_MAX + subtrees fit the task array */
typedef struct level_job {
    build_ctx *c;
    const task *in;
    task *out;
    uint8_t *split;
} level_job;

static void level_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    level_job *j = user;
    j->split[index] = build_node(j->c, &j->in[index], &j->out[2 * index]) == 2;
}

/* SAH cost and leaf count, recursively with an explicit stack. */
static void measure(bvh2 *b) {
    double root_area = box3_half_area(node_box(&b->nodes[0]));
    double cost = 0.0;
    uint32_t leaves = 0;
    uint32_t stack[2 * BVHW_MAX_DEPTH + 8], sp = 0;
    stack[sp++] = 0;
    while (sp) {
        const bvh_node *n = &b->nodes[stack[--sp]];
        double a = box3_half_area(node_box(n));
        if (n->count || n->index == 0) {
            leaves++;
            cost += a * n->count;
        } else {
            cost += a;
            stack[sp++] = n->index;
            stack[sp++] = n->index + 1;
        }
    }
    b->leaf_count = leaves;
    b->sah_cost = root_area > 0.0 ? cost / root_area : 0.0;
}

/* Primitive boxes in SIMD form, the identity permutation and the root box, by chunks. */
typedef struct init_job {
    const box3 *boxes;
    pbox *pboxes;
    uint32_t *prims;
    uint32_t n, chunks; /* at most PAR_CHUNKS */
    box3 part[PAR_CHUNKS];
} init_job;

static void init_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    init_job *j = user;
    uint64_t n = j->n;
    uint32_t b = (uint32_t)(n * index / j->chunks), e = (uint32_t)(n * (index + 1) / j->chunks);
    box3 r = box3_empty();
    for (uint32_t i = b; i < e; i++) {
        const box3 *x = &j->boxes[i];
        j->prims[i] = i;
        j->pboxes[i].lo = (vf4){x->lo.x, x->lo.y, x->lo.z, 0.0f};
        j->pboxes[i].hi = (vf4){x->hi.x, x->hi.y, x->hi.z, 0.0f};
        r = box3_union(r, *x);
    }
    j->part[index] = r;
}

bool bvh_build(const sys_allocator *alloc, sys_pool *pool, const box3 *boxes, uint32_t n,
               const bvh_build_desc *desc, bvh2 *out) {
    memset(out, 0, sizeof *out);
    uint32_t cap = n ? 2 * n - 1 : 1;
    out->nodes = sys_alloc(alloc, (size_t)cap * sizeof(bvh_node));
    out->prims = sys_alloc(alloc, (size_t)(n ? n : 1) * sizeof(uint32_t));
    size_t pbytes = (size_t)(n ? n : 1) * sizeof(pbox);
    pbox *pboxes = sys_alloc(alloc, pbytes);
    if (!out->nodes || !out->prims || !pboxes) {
        sys_free(alloc, pboxes, pbytes);
        bvh2_free(alloc, out);
        return false;
    }
    out->node_capacity = cap;
    out->prim_count = n;
    box3 root = box3_empty();
    /* large inputs on all threads: a serial pass (and its page faults) over millions of boxes
     * was a tenth of a large build on two threads */
    bool par_init = pool && sys_pool_threads(pool) > 1 && n >= PAR_MIN;
    init_job ij = {.boxes = boxes, .pboxes = pboxes, .prims = out->prims, .n = n,
                   .chunks = par_init ? PAR_CHUNKS : 1};
    if (par_init) sys_pool_parallel_for(pool, ij.chunks, init_task, &ij);
    else init_task(&ij, 0, 0);
    for (uint32_t i = 0; i < ij.chunks; i++) root = box3_union(root, ij.part[i]);
    build_ctx c = {
        .boxes = pboxes, .prims = out->prims, .nodes = out->nodes,
        .bins = desc->bins < 4 ? 4 : desc->bins > MAX_BINS ? MAX_BINS : desc->bins,
        .max_leaf = desc->max_leaf_size < 1 ? 1 : desc->max_leaf_size,
        .alloc = alloc,
        .block = desc->block_size < 1 ? 1u : (uint32_t)desc->block_size,
        .trav_cost = desc->trav_cost > 0.0f ? desc->trav_cost : 1.0,
    };
    atomic_store(&c.node_count, 1);
    atomic_store(&c.depth, 0);
    set_node_box(&out->nodes[0], root);
    out->nodes[0].index = 0;
    out->nodes[0].count = n;

    int threads = pool ? sys_pool_threads(pool) : 1;
    if (threads > 1 && n > 4096) {
        /* Split level by level until the open subtrees are small enough to balance the threads.
         * A level with fewer nodes than threads is split node by node, each binned by all
         * threads; a level with more is split a node per thread (the partitions of the top
         * levels had run on one thread while the others waited). */
        uint32_t grain = n / (uint32_t)(threads * 16);
        if (grain < 1024) grain = 1024;
        c.task_capacity = 1024;
        size_t qbytes = (size_t)LEVEL_MAX * 2 * sizeof(task);
        c.tasks = sys_alloc(alloc, c.task_capacity * sizeof(task));
        task *level = sys_alloc(alloc, qbytes), *kids = sys_alloc(alloc, qbytes);
        if (!c.tasks || !level || !kids) {
            sys_free(alloc, c.tasks, c.task_capacity * sizeof(task));
            sys_free(alloc, level, qbytes);
            sys_free(alloc, kids, qbytes);
            sys_free(alloc, pboxes, pbytes);
            bvh2_free(alloc, out);
            return false;
        }
        uint8_t split[LEVEL_MAX];
        uint32_t ln = 1;
        level[0] = (task){0, 0, n, 0};
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
            level_job job = {.c = &c, .in = level, .out = kids, .split = split};
            if (wn < (uint32_t)threads) {
                c.top_pool = pool;
                for (uint32_t i = 0; i < wn; i++) level_task(&job, i, 0);
            } else {
                c.top_pool = NULL;
                sys_pool_parallel_for(pool, wn, level_task, &job);
            }
            ln = 0;
            for (uint32_t i = 0; i < wn; i++)
                if (split[i]) level[ln++] = kids[2 * i], level[ln++] = kids[2 * i + 1];
        }
        c.top_pool = NULL; /* the subtrees run on the pool themselves */
        sys_pool_parallel_for(pool, c.task_count, build_task, &c);
        sys_free(alloc, c.tasks, c.task_capacity * sizeof(task));
        sys_free(alloc, level, qbytes);
        sys_free(alloc, kids, qbytes);
    } else {
        build_subtree(&c, (task){0, 0, n, 0});
    }
    sys_free(alloc, pboxes, pbytes);
    out->node_count = atomic_load(&c.node_count);
    out->depth = atomic_load(&c.depth);
    measure(out);
    return true;
}

void bvh2_free(const sys_allocator *alloc, bvh2 *bvh) {
    sys_free(alloc, bvh->nodes, (size_t)bvh->node_capacity * sizeof(bvh_node));
    sys_free(alloc, bvh->prims, (size_t)(bvh->prim_count ? bvh->prim_count : 1) * sizeof(uint32_t));
    memset(bvh, 0, sizeof *bvh);
}
