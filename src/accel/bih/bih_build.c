/* BIH build (Waechter, Keller 2006, sec. 2.2-2.3): the global heuristic splits the node's split
 * box (not the objects' box) in the middle of its longest side, sorts the primitives by centroid
 * to the two sides in place (one quicksort-like pass over the box array), and keeps each side's
 * extreme bound as its clip plane; when one side is empty the split box is halved towards the
 * other and the step repeated, so no node is made. Every inner node has two non-empty children,
 * so 2n - 1 nodes suffice: they are allocated once, from the primitive count. The top levels
 * run on the calling thread; their subtrees are built in parallel. */
#include <math.h>
#include <string.h>

#include "accel/accel.h"
#include "accel/bih/bih.h"

typedef struct bih_task {
    uint32_t node, begin, end, depth;
    float sb[6];
    vf4 clo, chi; /* twice the centroids' bounds */
} bih_task;

typedef struct bih_ctx {
    const accel_tri_input *in;
    bvh_prim *p;               /* the boxes, reordered in place; lo[3] holds each one's id */
    bih_node *nodes;
    _Atomic uint32_t next;     /* first free node */
    uint32_t spawn_depth;      /* subtrees at this depth are tasks (when tasks != NULL) */
    bih_task *tasks;
    uint32_t task_count, task_cap;
    _Atomic uint32_t depth;
    _Atomic uint64_t leaves;
    /* leaf packing */
    uint32_t *block_of;        /* per position: its block */
    tri4 *blocks;
} bih_ctx;

static void make_leaf(bih_ctx *c, uint32_t node, uint32_t begin, uint32_t end, uint32_t depth) {
    bih_node *n = &c->nodes[node];
    uint32_t first = begin, count = end - begin;
    memcpy(&n->clip[0], &first, 4);
    memcpy(&n->clip[1], &count, 4);
    n->meta = BIH_LEAF;
    atomic_fetch_add_explicit(&c->leaves, 1, memory_order_relaxed);
    uint32_t d = atomic_load_explicit(&c->depth, memory_order_relaxed);
    while (depth > d && !atomic_compare_exchange_weak(&c->depth, &d, depth)) {
    }
}

/* Twice the centroids' bounds of a range (lo + hi of each box), lanes x, y, z. */
typedef struct cbounds {
    vf4 lo, hi;
} cbounds;

static void split(bih_ctx *c, uint32_t node, uint32_t begin, uint32_t end, float sb[6], cbounds cb, uint32_t depth,
                  bool spawn) {
    for (;;) {
        if (end - begin <= BIH_LEAF_SIZE || depth >= BIH_MAX_DEPTH) {
            make_leaf(c, node, begin, end, depth);
            return;
        }
        if (spawn && depth == c->spawn_depth) {
            bih_task *t = &c->tasks[c->task_count++];
            *t = (bih_task){node, begin, end, depth, {0}, cb.lo, cb.hi};
            memcpy(t->sb, sb, sizeof t->sb);
            return;
        }
        /* Halve the split box until its plane parts the centroids. When every centroid lies on one
         * side the paper halves the box and partitions again; the centroids' bounds tell the
         * outcome of that pass in advance, so the same planes are found without it. */
        int axis = 0;
        float plane = 0.0f;
        for (int tries = 0;; tries++) {
            float e0 = sb[3] - sb[0], e1 = sb[4] - sb[1], e2 = sb[5] - sb[2];
            axis = e1 > e0 ? (e2 > e1 ? 2 : 1) : (e2 > e0 ? 2 : 0);
            plane = 0.5f * (sb[axis] + sb[3 + axis]);
            /* nothing left to halve (equal centroids): a leaf of them all */
            if (tries >= 64 || !(plane > sb[axis] && plane < sb[3 + axis])) {
                make_leaf(c, node, begin, end, depth);
                return;
            }
            float twice = 2.0f * plane;
            if (cb.lo[axis] >= twice) sb[axis] = plane;          /* all on the right */
            else if (cb.hi[axis] < twice) sb[3 + axis] = plane;  /* all on the left */
            else break;
        }
        float twice = 2.0f * plane;
        bvh_prim *p = c->p;
        uint32_t i = begin, j = end;
        vf4 inf = vf4_splat(INFINITY), ninf = vf4_splat(-INFINITY);
        vf4 lhi = ninf, rlo = inf; /* the sides' bounds: the clip planes */
        cbounds cl = {inf, ninf}, cr = {inf, ninf};
        while (i < j) {
            vf4 c2 = p[i].lo + p[i].hi;
            if (c2[axis] < twice) {
                lhi = vf4_max(lhi, p[i].hi);
                cl.lo = vf4_min(cl.lo, c2), cl.hi = vf4_max(cl.hi, c2);
                i++;
            } else {
                j--;
                bvh_prim t = p[i];
                p[i] = p[j], p[j] = t;
                rlo = vf4_min(rlo, t.lo);
                cr.lo = vf4_min(cr.lo, c2), cr.hi = vf4_max(cr.hi, c2);
            }
        }
        uint32_t child = atomic_fetch_add_explicit(&c->next, 2, memory_order_relaxed);
        c->nodes[node] = (bih_node){{lhi[axis], rlo[axis]}, child << 2 | (uint32_t)axis};
        float sl[6], sr[6];
        memcpy(sl, sb, sizeof sl), memcpy(sr, sb, sizeof sr);
        sl[3 + axis] = plane, sr[axis] = plane;
        split(c, child, begin, i, sl, cl, depth + 1, spawn);
        /* the right side in this frame (a loop, not a call: the recursion's depth is the left path) */
        node = child + 1, begin = i, depth = depth + 1, cb = cr;
        memcpy(sb, sr, sizeof sr);
    }
}

static void task_run(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    bih_ctx *c = user;
    bih_task t = c->tasks[index];
    split(c, t.node, t.begin, t.end, t.sb, (cbounds){t.clo, t.chi}, t.depth, false);
}

/* Numbers the blocks: every position gets its block (a leaf's triangles fill blocks of four in
 * order, its first position starting one), as the BVH's tri_pack_plan. */
static uint32_t plan_blocks(bih_ctx *c, uint32_t node_count, uint32_t n) {
    memset(c->block_of, 0, (size_t)n * sizeof(uint32_t));
    for (uint32_t i = 0; i < node_count; i++) {
        bih_node *nd = &c->nodes[i];
        if (nd->meta != BIH_LEAF) continue;
        uint32_t first, count;
        memcpy(&first, &nd->clip[0], 4), memcpy(&count, &nd->clip[1], 4);
        if (count) c->block_of[first] = count;
    }
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
 * each position's id from its box, lo's w lane) and points the leaves among a chunk of the nodes
 * at their blocks. */
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
        bih_node *nd = &c->nodes[i];
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
    size_t node_bytes = ((size_t)2 * n + 1) * sizeof(bih_node);
    c.nodes = sys_alloc(a, node_bytes);
    c.block_of = sys_alloc(a, (size_t)n * sizeof(uint32_t) + 4);
    uint32_t threads = pool && n >= 4096 ? (uint32_t)sys_pool_threads(pool) : 1;
    if (threads < 2) pool = NULL;
    c.spawn_depth = 3;
    while ((1u << c.spawn_depth) < 8 * threads && c.spawn_depth < 12) c.spawn_depth++;
    c.task_cap = 1u << c.spawn_depth;
    c.tasks = pool ? sys_alloc(a, c.task_cap * sizeof(bih_task)) : NULL;
    if (!c.nodes || !c.block_of || (pool && !c.tasks)) {
        sys_free(a, c.nodes, node_bytes), sys_free(a, c.block_of, (size_t)n * sizeof(uint32_t) + 4);
        sys_free(a, c.tasks, c.task_cap * sizeof(bih_task));
        return false;
    }
    stamp_ctx st = {in->boxes, n, pool ? threads * 4 : 1};
    if (pool) sys_pool_parallel_for(pool, st.chunks, stamp_task, &st);
    else stamp_task(&st, 0, 0);
    box3 b = in->bounds;
    float sb[6] = {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z};
    memcpy(out->bounds, sb, sizeof sb);
    atomic_store(&c.next, 1);
    cbounds cb = {vf4_splat(INFINITY), vf4_splat(-INFINITY)};
    for (uint32_t i = 0; i < n; i++) {
        vf4 c2 = in->boxes[i].lo + in->boxes[i].hi;
        cb.lo = vf4_min(cb.lo, c2), cb.hi = vf4_max(cb.hi, c2);
    }
    split(&c, 0, 0, n, sb, cb, 1, pool != NULL);
    if (pool && c.task_count) sys_pool_parallel_for(pool, c.task_count, task_run, &c);
    uint32_t node_count = atomic_load(&c.next);
    uint32_t blocks = plan_blocks(&c, node_count, n);
    c.blocks = accel_blocks_alloc(a, blocks);
    bool ok = c.blocks != NULL;
    if (ok) {
        fill_ctx f = {&c, node_count, n, pool ? threads * 8 : 1};
        if (pool) sys_pool_parallel_for(pool, f.chunks, fill_task, &f);
        else fill_task(&f, 0, 0);
    }
    sys_free(a, c.block_of, (size_t)n * sizeof(uint32_t) + 4);
    sys_free(a, c.tasks, c.task_cap * sizeof(bih_task));
    if (!ok) {
        sys_free(a, c.nodes, node_bytes);
        return false;
    }
    out->nodes = c.nodes;
    out->node_bytes = node_bytes;
    out->blocks = c.blocks;
    out->block_count = blocks;
    out->root_depth = atomic_load(&c.depth);
    out->nodes_total = node_count;
    out->leaves = atomic_load(&c.leaves);
    out->inner_nodes = node_count - out->leaves;
    out->tri_refs = n;
    out->sah_cost = 0.0; /* the global heuristic does not estimate it */
    return true;
}

RP_HIDDEN const accel_ops accel_bih = {"bih", bih_build, &bih_kernels};
