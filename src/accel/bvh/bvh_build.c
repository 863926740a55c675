/* Binned SAH builder (Wald 2007): per node, primitives are binned by centroid along each axis and
 * the split of least SAH cost among bin borders is taken. The top of the tree is split on the
 * calling thread until there are enough subtrees, which the device's threads then build. */
#include <math.h>
#include <string.h>

#include "accel/bvh/bvh.h"

#define MAX_BINS 64
#define MEDIAN_DEPTH 64 /* past this depth, split at the median to bound the depth */

typedef struct build_ctx {
    const box3 *boxes;
    vec3 *centroids;
    uint32_t *prims;
    bvh_node *nodes;
    _Atomic uint32_t node_count;
    int bins;
    int max_leaf;
    /* subtrees deferred to the threads */
    struct task *tasks;
    uint32_t task_count, task_capacity;
    _Atomic uint32_t depth;
} build_ctx;

typedef struct task {
    uint32_t node, begin, end, depth;
} task;

typedef struct bin {
    box3 box;
    uint32_t count;
} bin;

static box3 prim_range_box(const build_ctx *c, uint32_t begin, uint32_t end, box3 *cbox) {
    box3 b = box3_empty(), cb = box3_empty();
    for (uint32_t i = begin; i < end; i++) {
        uint32_t p = c->prims[i];
        b = box3_union(b, c->boxes[p]);
        cb = box3_extend(cb, c->centroids[p]);
    }
    *cbox = cb;
    return b;
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

/* Bin index of a centroid coordinate; clamped in float before the conversion so huge
 * coordinates (or an extent that overflowed) cannot make it undefined. */
static inline int bin_of(float x, float lo, float scale, int bins) {
    float f = (x - lo) * scale;
    if (!(f > 0.0f)) return 0;
    if (f >= (float)(bins - 1)) return bins - 1;
    return (int)f;
}

/* Splits [begin, end) in place; returns the first index of the right half and the two boxes, or
 * 0 when no split was found (all centroids in one bin on every axis). */
static uint32_t split_sah(build_ctx *c, uint32_t begin, uint32_t end, box3 cbox, box3 *lbox, box3 *rbox) {
    int nb = c->bins;
    double best_cost = INFINITY;
    int best_axis = -1, best_split = 0;
    float scale[3], lo[3];
    box3 best_l = box3_empty(), best_r = box3_empty();
    for (int axis = 0; axis < 3; axis++) {
        float clo = v3_get(cbox.lo, axis), chi = v3_get(cbox.hi, axis);
        lo[axis] = clo;
        double extent = (double)chi - (double)clo;
        scale[axis] = 0.0f;
        if (!(extent > 0.0)) continue;
        scale[axis] = (float)((double)nb * (1.0 - 1e-6) / extent);
        if (!(scale[axis] > 0.0f) || !isfinite(scale[axis])) continue;
        bin bins[MAX_BINS];
        for (int b = 0; b < nb; b++) bins[b].box = box3_empty(), bins[b].count = 0;
        for (uint32_t i = begin; i < end; i++) {
            uint32_t p = c->prims[i];
            int b = bin_of(v3_get(c->centroids[p], axis), clo, scale[axis], nb);
            bins[b].box = box3_union(bins[b].box, c->boxes[p]);
            bins[b].count++;
        }
        /* right-to-left sweep, then left-to-right with the cost of each border */
        double rarea[MAX_BINS];
        uint32_t rcount[MAX_BINS];
        box3 racc = box3_empty(), rboxes[MAX_BINS];
        uint32_t rc = 0;
        for (int b = nb - 1; b > 0; b--) {
            racc = box3_union(racc, bins[b].box);
            rc += bins[b].count;
            rarea[b] = box3_half_area(racc);
            rcount[b] = rc;
            rboxes[b] = racc;
        }
        box3 lacc = box3_empty();
        uint32_t lc = 0;
        for (int b = 1; b < nb; b++) {
            lacc = box3_union(lacc, bins[b - 1].box);
            lc += bins[b - 1].count;
            if (lc == 0 || rcount[b] == 0) continue;
            double cost = box3_half_area(lacc) * lc + rarea[b] * rcount[b];
            if (cost < best_cost) {
                best_cost = cost, best_axis = axis, best_split = b;
                best_l = lacc, best_r = rboxes[b];
            }
        }
    }
    if (best_axis < 0) return 0;
    /* Hoare partition by bin */
    uint32_t i = begin, j = end;
    while (i < j) {
        uint32_t p = c->prims[i];
        if (bin_of(v3_get(c->centroids[p], best_axis), lo[best_axis], scale[best_axis], nb) < best_split) {
            i++;
        } else {
            c->prims[i] = c->prims[--j];
            c->prims[j] = p;
        }
    }
    *lbox = best_l, *rbox = best_r;
    return i;
}

/* Processes one node: makes it a leaf or splits it and returns its two children as tasks. */
static int build_node(build_ctx *c, const task *t, task out[2]) {
    uint32_t n = t->end - t->begin;
    bvh_node *node = &c->nodes[t->node];
    depth_max(c, t->depth + 1);
    if (n <= (uint32_t)c->max_leaf) {
        node->index = t->begin;
        node->count = n;
        return 0;
    }
    box3 cbox;
    box3 lbox, rbox;
    uint32_t mid = 0;
    if (t->depth < MEDIAN_DEPTH) {
        box3 b = prim_range_box(c, t->begin, t->end, &cbox);
        (void)b;
        mid = split_sah(c, t->begin, t->end, cbox, &lbox, &rbox);
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

bool bvh_build(const sys_allocator *alloc, sys_pool *pool, const box3 *boxes, uint32_t n,
               const bvh_build_desc *desc, bvh2 *out) {
    memset(out, 0, sizeof *out);
    uint32_t cap = n ? 2 * n - 1 : 1;
    out->nodes = sys_alloc(alloc, (size_t)cap * sizeof(bvh_node));
    out->prims = sys_alloc(alloc, (size_t)(n ? n : 1) * sizeof(uint32_t));
    vec3 *centroids = sys_alloc(alloc, (size_t)(n ? n : 1) * sizeof(vec3));
    if (!out->nodes || !out->prims || !centroids) {
        sys_free(alloc, centroids, (size_t)(n ? n : 1) * sizeof(vec3));
        bvh2_free(alloc, out);
        return false;
    }
    out->node_capacity = cap;
    out->prim_count = n;
    box3 root = box3_empty();
    for (uint32_t i = 0; i < n; i++) {
        out->prims[i] = i;
        centroids[i] = v3_add(v3_mul(boxes[i].lo, 0.5f), v3_mul(boxes[i].hi, 0.5f));
        root = box3_union(root, boxes[i]);
    }
    build_ctx c = {
        .boxes = boxes, .centroids = centroids, .prims = out->prims, .nodes = out->nodes,
        .bins = desc->bins < 4 ? 4 : desc->bins > MAX_BINS ? MAX_BINS : desc->bins,
        .max_leaf = desc->max_leaf_size < 1 ? 1 : desc->max_leaf_size,
    };
    atomic_store(&c.node_count, 1);
    atomic_store(&c.depth, 0);
    set_node_box(&out->nodes[0], root);
    out->nodes[0].index = 0;
    out->nodes[0].count = n;

    int threads = pool ? sys_pool_threads(pool) : 1;
    if (threads > 1 && n > 4096) {
        /* split breadth first until the open subtrees are small enough to balance the threads */
        uint32_t grain = n / (uint32_t)(threads * 16);
        if (grain < 1024) grain = 1024;
        c.task_capacity = 1024;
        c.tasks = sys_alloc(alloc, c.task_capacity * sizeof(task));
        task *queue = sys_alloc(alloc, c.task_capacity * sizeof(task));
        if (!c.tasks || !queue) {
            sys_free(alloc, c.tasks, c.task_capacity * sizeof(task));
            sys_free(alloc, queue, c.task_capacity * sizeof(task));
            sys_free(alloc, centroids, (size_t)n * sizeof(vec3));
            bvh2_free(alloc, out);
            return false;
        }
        uint32_t qhead = 0, qtail = 0;
        queue[qtail++] = (task){0, 0, n, 0};
        while (qhead < qtail) {
            task t = queue[qhead++];
            if (t.end - t.begin <= grain || qtail + 2 > c.task_capacity || c.task_count + 2 > c.task_capacity) {
                c.tasks[c.task_count++] = t;
                continue;
            }
            task kids[2];
            if (build_node(&c, &t, kids) == 2) {
                queue[qtail++] = kids[0];
                queue[qtail++] = kids[1];
            }
        }
        sys_pool_parallel_for(pool, c.task_count, build_task, &c);
        sys_free(alloc, c.tasks, c.task_capacity * sizeof(task));
        sys_free(alloc, queue, c.task_capacity * sizeof(task));
    } else {
        build_subtree(&c, (task){0, 0, n, 0});
    }
    sys_free(alloc, centroids, (size_t)n * sizeof(vec3));
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
