/* Scenes: geometry bookkeeping and commit, which gathers valid primitives, builds the canonical
 * binary BVH and converts it to the wide layout the kernels traverse. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "core/core.h"
#include "geometry/sphere.h"

static bool scene_refit(rp_scene *s);
/* The node cost of the SAH a refit is judged by (in tri4 block tests, as the medium build's) */
#define REFIT_TRAV_COST 0.5

rp_scene_desc rp_scene_desc_defaults(const rp_scene_desc *desc) {
    rp_scene_desc d = desc ? *desc : (rp_scene_desc){0};
    if (d.refit_max_growth == 0.0f) d.refit_max_growth = 1.5f;
    if (d.max_leaf_size <= 0) d.max_leaf_size = 32;
    if (d.max_leaf_size > 60) d.max_leaf_size = 60;
    return d;
}

rp_scene *rp_scene_new(rp_device *device, const rp_scene_desc *desc) {
    if (!device) return NULL;
    if (desc && ((unsigned)desc->quality > RP_BUILD_QUALITY_HIGH || (unsigned)desc->accel >= RP_ACCEL_COUNT ||
                 (desc->bvh_width != 0 && desc->bvh_width != 4 && desc->bvh_width != 8 && desc->bvh_width != 16) ||
                 desc->max_leaf_size < 0 || desc->max_leaf_size > 60 ||
                 !(desc->grid_density >= 0.0f && desc->grid_density <= 1000.0f))) {
        device_error(device, RP_ERROR_INVALID_ARGUMENT,
                     "rp_scene_new: bad quality, accel, bvh_width, max_leaf_size or grid_density");
        return NULL;
    }
    rp_scene *s = sys_calloc(&device->alloc, sizeof *s);
    if (!s) {
        device_error(device, RP_ERROR_OUT_OF_MEMORY, NULL);
        return NULL;
    }
    atomic_store(&s->refs, 1);
    s->device = device;
    s->desc = rp_scene_desc_defaults(desc);
    rp_device_retain(device);
    return s;
}

void rp_scene_retain(rp_scene *scene) {
    if (scene) atomic_fetch_add(&scene->refs, 1);
}

void scene_free_accel(rp_scene *s) {
    const sys_allocator *a = &s->device->alloc;
    bvhw_free(a, &s->tri_bvh);
    bvhw_free(a, &s->prim_bvh);
    bvh2q_free(a, &s->tri_bvh2q);
    sys_free(a, s->tris, s->tri_block_count * sizeof(tri4));
    sys_free(a, s->prims, s->prim_count * sizeof(prim_ref));
    sys_free(a, s->geom_masks, s->geom_mask_count * sizeof(uint32_t));
    accel_built_free(a, &s->alt);
    s->tris = NULL, s->prims = NULL, s->geom_masks = NULL;
    s->tri_block_count = s->prim_count = s->geom_mask_count = 0;
    memset(&s->accel, 0, sizeof s->accel);
}

void rp_scene_release(rp_scene *scene) {
    if (!scene || atomic_fetch_sub(&scene->refs, 1) != 1) return;
    rp_device *dev = scene->device;
    scene_free_accel(scene);
    for (uint32_t i = 0; i < scene->geom_count; i++) rp_geometry_release(scene->geoms[i]);
    sys_free(&dev->alloc, scene->geoms, scene->geom_capacity * sizeof(rp_geometry *));
    sys_free(&dev->alloc, scene->built_topo, scene->built_capacity * sizeof(uint32_t));
    sys_free(&dev->alloc, scene, sizeof *scene);
    rp_device_release(dev);
}

uint32_t rp_scene_attach(rp_scene *scene, rp_geometry *geometry) {
    if (!scene) return RP_INVALID_ID;
    if (!geometry || geometry->device != scene->device) {
        device_error(scene->device, RP_ERROR_INVALID_ARGUMENT, "rp_scene_attach: NULL geometry or another device's");
        return RP_INVALID_ID;
    }
    uint32_t id = scene->geom_count;
    for (uint32_t i = 0; i < scene->geom_count; i++)
        if (!scene->geoms[i]) {
            id = i;
            break;
        }
    if (id == scene->geom_count) {
        if (scene->geom_count == scene->geom_capacity) {
            uint32_t cap = scene->geom_capacity ? scene->geom_capacity * 2 : 8;
            rp_geometry **g = sys_calloc(&scene->device->alloc, cap * sizeof *g);
            if (!g) {
                device_error(scene->device, RP_ERROR_OUT_OF_MEMORY, NULL);
                return RP_INVALID_ID;
            }
            if (scene->geoms) memcpy(g, scene->geoms, scene->geom_count * sizeof *g);
            sys_free(&scene->device->alloc, scene->geoms, scene->geom_capacity * sizeof *g);
            scene->geoms = g;
            scene->geom_capacity = cap;
        }
        scene->geom_count++;
    }
    rp_geometry_retain(geometry);
    scene->geoms[id] = geometry;
    scene->committed = false;
    scene->attach_changed = true;
    return id;
}

void rp_scene_detach(rp_scene *scene, uint32_t geom_id) {
    if (!scene) return;
    if (geom_id >= scene->geom_count || !scene->geoms[geom_id]) {
        device_error(scene->device, RP_ERROR_INVALID_ARGUMENT, "rp_scene_detach: no geometry with this id");
        return;
    }
    rp_geometry_release(scene->geoms[geom_id]);
    scene->geoms[geom_id] = NULL;
    scene->committed = false;
    scene->attach_changed = true;
}

rp_geometry *rp_scene_get_geometry(rp_scene *scene, uint32_t geom_id) {
    if (!scene || geom_id >= scene->geom_count) return NULL;
    return scene->geoms[geom_id];
}

/* Remembers what this build saw (scene_refit compares the next commit with it). */
static void scene_record_build(rp_scene *s) {
    const sys_allocator *a = &s->device->alloc;
    if (s->geom_count > s->built_capacity) {
        uint32_t *t = sys_alloc(a, (size_t)s->geom_count * sizeof *t);
        if (!t) {
            s->built_count = 0, s->attach_changed = true; /* no record: the next commit rebuilds */
            return;
        }
        sys_free(a, s->built_topo, s->built_capacity * sizeof *t);
        s->built_topo = t, s->built_capacity = s->geom_count;
    }
    for (uint32_t i = 0; i < s->geom_count; i++) s->built_topo[i] = s->geoms[i] ? s->geoms[i]->topo : RP_INVALID_ID;
    s->built_count = s->geom_count;
    s->attach_changed = false;
}

/* Each instance's box in this scene's space (rp_geometry.box), for the packets that go into the
 * instances one at a time (api_n.c); empty (lower > upper) for an instance of an empty scene. */
static void instance_boxes(rp_scene *s) {
    for (uint32_t gi = 0; gi < s->geom_count; gi++) {
        rp_geometry *g = s->geoms[gi];
        if (!g || g->type != RP_GEOMETRY_INSTANCE || !g->inst) continue;
        const rp_bounds *cb = &g->inst->bounds;
        float *lo = g->box, *hi = g->box + 3;
        for (int r = 0; r < 3; r++) lo[r] = INFINITY, hi[r] = -INFINITY;
        if (!(cb->lower_x <= cb->upper_x)) continue;
        for (int corner = 0; corner < 8; corner++) {
            float c[3] = {corner & 1 ? cb->upper_x : cb->lower_x, corner & 2 ? cb->upper_y : cb->lower_y,
                          corner & 4 ? cb->upper_z : cb->lower_z};
            for (int r = 0; r < 3; r++) {
                const float *x = g->xfm + 4 * r;
                float v = x[0] * c[0] + x[1] * c[1] + x[2] * c[2] + x[3];
                lo[r] = fminf(lo[r], v), hi[r] = fmaxf(hi[r], v);
            }
        }
        for (int r = 0; r < 3; r++) {
            float e = (fmaxf(fabsf(lo[r]), fabsf(hi[r])) + (hi[r] - lo[r])) * 1e-5f;
            lo[r] -= e, hi[r] += e;
        }
    }
}

rp_error rp_scene_commit(rp_scene *scene) {
    if (!scene) return RP_ERROR_INVALID_ARGUMENT;
    double t0 = sys_seconds();
    instance_boxes(scene);
    if (scene_refit(scene)) {
        scene->stats.build_ms = (sys_seconds() - t0) * 1e3;
        scene->committed = true;
        return RP_ERROR_NONE;
    }
    scene_free_accel(scene);
    scene->committed = false;
    rp_error e = scene_build(scene);
    if (e != RP_ERROR_NONE) {
        scene_free_accel(scene);
        device_error(scene->device, e, "rp_scene_commit failed");
        return e;
    }
    scene_record_build(scene);
    scene->stats.build_ms = (sys_seconds() - t0) * 1e3;
    scene->committed = true;
    return RP_ERROR_NONE;
}

void rp_scene_get_bounds(const rp_scene *scene, rp_bounds *out) {
    if (!scene || !out) return;
    *out = scene->bounds;
}

void rp_scene_get_stats(const rp_scene *scene, rp_scene_stats *out) {
    if (!scene || !out) return;
    *out = scene->stats;
}

const char *rp_accel_name(rp_accel_type type) {
    switch (type) {
    case RP_ACCEL_BVH: return "bvh";
    case RP_ACCEL_KDTREE: return "kdtree";
    case RP_ACCEL_BIH: return "bih";
    case RP_ACCEL_GRID: return "grid";
    }
    return NULL;
}

/* The structures other than the BVH, by rp_accel_type (NULL: the BVH, built below). */
static const accel_ops *accel_ops_of(rp_accel_type type) {
    switch (type) {
    case RP_ACCEL_KDTREE: return &accel_kdtree;
    case RP_ACCEL_BIH: return &accel_bih;
    case RP_ACCEL_GRID: return &accel_grid;
    case RP_ACCEL_BVH: return NULL;
    }
    return NULL;
}

/* ---- commit ------------------------------------------------------------------------------- */

typedef struct gather {
    bvh_prim *boxes;
    prim_ref *refs;
    uint32_t count, capacity;
} gather;

static bool gather_push(const sys_allocator *a, gather *g, box3 b, uint32_t geom, uint32_t prim) {
    if (g->count == g->capacity) {
        uint32_t cap = g->capacity ? g->capacity * 2 : 1024;
        bvh_prim *nb = sys_alloc(a, (size_t)cap * sizeof *nb);
        prim_ref *nr = sys_alloc(a, (size_t)cap * sizeof *nr);
        if (!nb || !nr) {
            sys_free(a, nb, (size_t)cap * sizeof *nb);
            sys_free(a, nr, (size_t)cap * sizeof *nr);
            return false;
        }
        if (g->count) {
            memcpy(nb, g->boxes, g->count * sizeof *nb);
            memcpy(nr, g->refs, g->count * sizeof *nr);
        }
        sys_free(a, g->boxes, (size_t)g->capacity * sizeof *nb);
        sys_free(a, g->refs, (size_t)g->capacity * sizeof *nr);
        g->boxes = nb, g->refs = nr, g->capacity = cap;
    }
    g->boxes[g->count] = bvh_prim_of(b);
    g->refs[g->count] = (prim_ref){geom, prim};
    g->count++;
    return true;
}

static void gather_free(const sys_allocator *a, gather *g) {
    sys_free(a, g->boxes, (size_t)g->capacity * sizeof *g->boxes);
    sys_free(a, g->refs, (size_t)g->capacity * sizeof *g->refs);
    memset(g, 0, sizeof *g);
}

static vec3 load_vertex(const rp_geometry *g, uint32_t i) {
    const float *p = geom_item(&g->buffers[RP_BUFFER_VERTEX], i);
    return v3(p[0], p[1], p[2]);
}

/* Loads triangle prim of geometry g; false if its indices or coordinates are invalid. */
static bool load_triangle(const rp_geometry *g, uint32_t prim, vec3 v[3]) {
    const uint32_t *idx = geom_item(&g->buffers[RP_BUFFER_INDEX], prim);
    size_t nv = g->buffers[RP_BUFFER_VERTEX].count;
    for (int k = 0; k < 3; k++) {
        if (idx[k] >= nv) return false;
        v[k] = load_vertex(g, idx[k]);
        if (!v3_finite(v[k])) return false;
    }
    return true;
}

/* accel_tri_input.fetch: a gathered (so valid) triangle's vertices and its geometry's mask. */
static void tri_fetch(const void *user, prim_ref r, float v[9], uint32_t *mask) {
    const rp_scene *s = user;
    const rp_geometry *g = s->geoms[r.geom];
    vec3 p[3] = {{0}};
    load_triangle(g, r.prim, p);
    for (int k = 0; k < 3; k++) v[3 * k] = p[k].x, v[3 * k + 1] = p[k].y, v[3 * k + 2] = p[k].z;
    *mask = g->mask;
}

/* Packing of the triangle BVH's leaves into tri4 blocks. A leaf's first block comes from a prefix
 * sum over the leaves in primitive order, so the blocks are allocated exactly and filled by all
 * threads at once. The fill goes in primitive order (the blocks are then written in order) and
 * prefetches each triangle's reference, indices and vertices a few triangles ahead: the builder's
 * order sends every triangle to a random place in the index buffer, and the fill, reading them one
 * after another, had waited on memory (spd_tree: 24 of a commit's 157 ms on two threads). */
typedef struct tri_pack_ctx {
    const rp_scene *scene;
    const bvh2 *bvh;
    const prim_ref *refs;
    tri4 *blocks;
    uint32_t *block_of;    /* per primitive position: its block */
    uint32_t block_count;
    uint32_t chunks;       /* of the primitives and of the nodes, one task each */
    double inv_diag;       /* 1 / the scene's diagonal, for the leaf sides below */
    uint64_t *side_sum;    /* per chunk: the leaves' longest sides, in 2^-24 of the diagonal */
    uint32_t *leaf_count;  /* per chunk */
} tri_pack_ctx;

static inline bool tri_is_leaf(const bvh_node *n) { return n->count != 0; }

/* Prefetch distances, in triangles, of a triangle's reference, its indices and its vertices. */
#define PACK_AHEAD_REF 24u
#define PACK_AHEAD_INDEX 16u
#define PACK_AHEAD_VERTEX 8u

static inline const uint32_t *tri_indices(const rp_scene *s, prim_ref r) {
    return geom_item(&s->geoms[r.geom]->buffers[RP_BUFFER_INDEX], r.prim);
}

/* First position of chunk `index`: the nominal start moved on to the start of a block, so no block
 * is shared by two chunks. */
static uint32_t pack_chunk_start(const tri_pack_ctx *c, uint32_t index) {
    uint64_t n = c->bvh->prim_count;
    uint32_t p = (uint32_t)(n * index / c->chunks);
    while (p > 0 && p < n && c->block_of[p] == c->block_of[p - 1]) p++;
    return p;
}

/* Fills the blocks of primitive positions [b, e) (block_of[b] starts a block): position p holds
 * triangle refs[ids[p * stride]] and goes to block block_of[p]. Unused lanes repeat lane 0
 * (tri4_pad): zeroed lanes made every edge function exactly 0, so each test of a partly filled
 * block took the watertight test's double-precision refinement. */
static inline void tri_fill_range(const rp_scene *s, const prim_ref *refs, const uint32_t *ids, size_t stride,
                                  const uint32_t *block_of, tri4 *blocks, uint32_t b, uint32_t e) {
    uint32_t lane = 0;
    for (uint32_t p = b; p < e; p++) {
        if (p + PACK_AHEAD_REF < e) __builtin_prefetch(&refs[ids[(p + PACK_AHEAD_REF) * stride]]);
        if (p + PACK_AHEAD_INDEX < e) __builtin_prefetch(tri_indices(s, refs[ids[(p + PACK_AHEAD_INDEX) * stride]]));
        if (p + PACK_AHEAD_VERTEX < e) {
            prim_ref r = refs[ids[(p + PACK_AHEAD_VERTEX) * stride]];
            const uint32_t *idx = tri_indices(s, r);
            const geom_buffer *vb = &s->geoms[r.geom]->buffers[RP_BUFFER_VERTEX];
            for (int k = 0; k < 3; k++) __builtin_prefetch(geom_item(vb, idx[k]));
        }
        uint32_t blk = block_of[p];
        lane = p > b && blk == block_of[p - 1] ? lane + 1 : 0;
        tri4 *t = &blocks[blk];
        prim_ref r = refs[ids[p * stride]];
        const rp_geometry *g = s->geoms[r.geom];
        vec3 v[3] = {{0}};
        load_triangle(g, r.prim, v); /* validated when gathered */
        for (int q = 0; q < 3; q++) {
            t->v[3 * q + 0][lane] = v[q].x;
            t->v[3 * q + 1][lane] = v[q].y;
            t->v[3 * q + 2][lane] = v[q].z;
        }
        t->geom[lane] = r.geom, t->prim[lane] = r.prim;
        if (p + 1 < e && block_of[p + 1] == blk) continue;
        tri4_pad(t, lane + 1);
    }
}

/* Fills the blocks of a chunk of the BVH's primitive positions. */
static void tri_pack_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const tri_pack_ctx *c = user;
    uint32_t b = pack_chunk_start(c, index), e = pack_chunk_start(c, index + 1);
    tri_fill_range(c->scene, c->refs, c->bvh->prims, 1, c->block_of, c->blocks, b, e);
}

/* accel_tri_input.fill: the same fill for the other structures. */
static void tri_fill(const void *user, const prim_ref *refs, const uint32_t *ids, size_t stride,
                     const uint32_t *block_of, uint32_t begin, uint32_t end, tri4 *blocks) {
    tri_fill_range(user, refs, ids, stride, block_of, blocks, begin, end);
}

/* Points each leaf of a chunk of the nodes at its blocks (count: blocks, index: the first block),
 * summing the leaves' sides for coherent_extent on the way; the sums are fixed point, so they do
 * not depend on the number of chunks. */
static void tri_leaf_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const tri_pack_ctx *c = user;
    uint64_t n = c->bvh->node_count, sum = 0;
    uint32_t begin = (uint32_t)(n * index / c->chunks), end = (uint32_t)(n * (index + 1) / c->chunks), leaves = 0;
    for (uint32_t i = begin; i < end; i++) {
        bvh_node *leaf = &c->bvh->nodes[i];
        if (!tri_is_leaf(leaf)) continue;
        double side = fmax((double)leaf->hi[0] - leaf->lo[0], fmax((double)leaf->hi[1] - leaf->lo[1], (double)leaf->hi[2] - leaf->lo[2]));
        sum += (uint64_t)(fmin(side * c->inv_diag, 1.0) * 0x1p24 + 0.5);
        leaves++;
        leaf->index = c->block_of[leaf->index];
        leaf->count = (leaf->count + 3) / 4;
    }
    c->side_sum[index] = sum, c->leaf_count[index] = leaves;
}

/* Numbers the blocks: every primitive position gets its block; false when out of memory. */
static bool tri_pack_plan(const sys_allocator *a, tri_pack_ctx *c) {
    const bvh2 *b = c->bvh;
    c->block_of = sys_alloc(a, (size_t)b->prim_count * sizeof(uint32_t));
    if (!c->block_of) return false;
    memset(c->block_of, 0, (size_t)b->prim_count * sizeof(uint32_t));
    for (uint32_t i = 0; i < b->node_count; i++)
        if (tri_is_leaf(&b->nodes[i])) c->block_of[b->nodes[i].index] = b->nodes[i].count;
    uint32_t next = 0, block = 0, k = 0; /* k: position in the current leaf */
    for (uint32_t p = 0; p < b->prim_count; p++) {
        uint32_t count = c->block_of[p];
        if (count) block = next, next += (count + 3) / 4, k = 0;
        c->block_of[p] = block + k++ / 4;
    }
    c->block_count = next;
    return true;
}

/* Leaf payload for the wide collapse: the leaf's own range. Triangle leaves point at their tri4
 * blocks by then (tri_pack_task), primitive leaves at their range of the reordered prim_refs. */
static bool leaf_range(void *user, const bvh_node *leaf, uint32_t *first, uint32_t *items) {
    (void)user;
    *first = leaf->index;
    *items = leaf->count;
    return true;
}

static bool sphere_intersect_cb(const rp_accel *acc, prim_ref ref, rp_ray *ray, rp_hit *hit);
static bool sphere_occluded_cb(const rp_accel *acc, prim_ref ref, const rp_ray *ray);

/* Levels of instances from scene c down, walking the geometries as they are now (a cycle of
 * instances reads as too deep, so a commit never makes one). */
static uint32_t instance_depth(const rp_scene *c, uint32_t level) {
    if (level > RP_MAX_INSTANCE_DEPTH) return level;
    uint32_t d = level;
    for (uint32_t i = 0; i < c->geom_count; i++) {
        const rp_geometry *g = c->geoms[i];
        if (!g || g->type != RP_GEOMETRY_INSTANCE || !g->inst) continue;
        uint32_t k = instance_depth(g->inst, level + 1);
        if (k > d) d = k;
        if (d > RP_MAX_INSTANCE_DEPTH) break;
    }
    return d;
}

#define SMALL_BUILD 4096u /* primitives */

/* As wide as the kernels' SIMD rays: a node's planes are one vector each. On AVX-512, BVH16 took
 * single rays 8-21% faster than BVH8 (diffuse rays, seven shared scenes, interleaved pairs) for
 * 10-16% more memory; spd_tree's 16-ray shadow packets lost 8%. */
static int pick_width(const rp_scene *s) {
    if (s->desc.bvh_width) return s->desc.bvh_width;
    int isa = s->device->kernels->isa;
    return isa >= 16 ? 16 : isa >= 8 ? 8 : 4;
}

static int quality_bins(rp_build_quality q) {
    switch (q) {
    case RP_BUILD_QUALITY_LOW: return 8;
    case RP_BUILD_QUALITY_HIGH: return 64;
    case RP_BUILD_QUALITY_MEDIUM: return 16;
    }
    return 16;
}

/* How far apart a small packet's origins may lie for its interval traversal to stay tight: 1% of
 * the scene's diagonal, but no more than twice the mean size (longest side) of the triangle
 * leaves. A large ground plane made the diagonal 30x the size of spd_tree's branches, and the
 * intervals of packets spread over the tree then covered most of it (shadow packets 4x slower
 * than single rays). */
static double diagonal(box3 b) {
    vec3 e = v3_sub(b.hi, b.lo);
    return sqrt((double)e.x * e.x + (double)e.y * e.y + (double)e.z * e.z);
}

/* mean_side: the triangle leaves' mean longest side (0: no triangles). */
static float coherent_extent(box3 bounds, double mean_side) {
    double ext = 0.01 * diagonal(bounds);
    if (mean_side > 0.0 && 2.0 * mean_side < ext) ext = 2.0 * mean_side;
    return (float)ext;
}

/* The triangles of every triangle geometry, gathered by all threads: each task takes a range of
 * the triangles (numbered geometry after geometry), writes its valid ones at the start of its
 * range, and the ranges are then closed up in order, so the result is the serial one. */
typedef struct tri_gather_job {
    const rp_scene *s;
    const uint32_t *geom_ids; /* the triangle geometries, in order */
    const uint64_t *first;    /* first triangle number of each, and the total last */
    uint64_t total;
    uint32_t chunks;
    gather *out;              /* capacity total */
    uint32_t *valid;          /* per task: triangles kept */
    uint64_t *rejected, *degenerate;
    box3 *bounds;
} tri_gather_job;

static void tri_gather_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    const tri_gather_job *j = user;
    uint64_t b = j->total * index / j->chunks, e = j->total * (index + 1) / j->chunks;
    uint32_t k = 0; /* the geometry of triangle q, advanced in the loop */
    uint64_t w = b, rejected = 0, degenerate = 0;
    box3 bounds = box3_empty();
    for (uint64_t q = b; q < e; q++) {
        while (q >= j->first[k + 1]) k++;
        const rp_geometry *g = j->s->geoms[j->geom_ids[k]];
        uint32_t p = (uint32_t)(q - j->first[k]);
        vec3 v[3];
        if (!load_triangle(g, p, v)) {
            rejected++;
            continue;
        }
        /* two equal vertices: zero area, never hit by the watertight test (one edge function and
         * the determinant are exactly 0), so it is left out */
        if (v3_eq(v[0], v[1]) || v3_eq(v[1], v[2]) || v3_eq(v[2], v[0])) {
            degenerate++;
            continue;
        }
        box3 box = {v3_min(v[0], v3_min(v[1], v[2])), v3_max(v[0], v3_max(v[1], v[2]))};
        bounds = box3_union(bounds, box);
        j->out->boxes[w] = bvh_prim_of(box);
        j->out->refs[w] = (prim_ref){j->geom_ids[k], p};
        w++;
    }
    j->valid[index] = (uint32_t)(w - b);
    j->rejected[index] = rejected, j->degenerate[index] = degenerate, j->bounds[index] = bounds;
}

static rp_error gather_triangles(const rp_scene *s, sys_pool *pool, gather *out, rp_scene_stats *st, box3 *bounds) {
    const sys_allocator *a = &s->device->alloc;
    uint32_t geoms = 0;
    for (uint32_t gi = 0; gi < s->geom_count; gi++) {
        const rp_geometry *g = s->geoms[gi];
        if (!g || g->type != RP_GEOMETRY_TRIANGLE) continue;
        if (!g->buffers[0].set || !g->buffers[1].set || g->buffers[RP_BUFFER_INDEX].count > 0xFFFFFFF0u)
            return RP_ERROR_INVALID_GEOMETRY;
        geoms++;
    }
    if (!geoms) return RP_ERROR_NONE;
    uint32_t threads = pool ? (uint32_t)sys_pool_threads(pool) : 1;
    tri_gather_job j = {.s = s, .out = out};
    size_t idb = (size_t)geoms * sizeof(uint32_t), fb = ((size_t)geoms + 1) * sizeof(uint64_t);
    uint32_t *ids = sys_alloc(a, idb);
    uint64_t *first = sys_alloc(a, fb);
    if (!ids || !first) {
        sys_free(a, ids, idb), sys_free(a, first, fb);
        return RP_ERROR_OUT_OF_MEMORY;
    }
    uint32_t k = 0;
    uint64_t total = 0;
    for (uint32_t gi = 0; gi < s->geom_count; gi++) {
        const rp_geometry *g = s->geoms[gi];
        if (!g || g->type != RP_GEOMETRY_TRIANGLE) continue;
        ids[k] = gi, first[k] = total, k++;
        total += g->buffers[RP_BUFFER_INDEX].count;
    }
    first[k] = total;
    rp_error err = RP_ERROR_NONE;
    if (total > 0xFFFFFFF0u) err = RP_ERROR_OUT_OF_MEMORY; /* more than a gather can count */
    j.geom_ids = ids, j.first = first, j.total = total;
    j.chunks = total >= 65536 ? threads * 8 : 1;
    size_t cb = (size_t)j.chunks * (2 * sizeof(uint64_t) + sizeof(uint32_t) + sizeof(box3));
    char *per = err == RP_ERROR_NONE && total ? sys_alloc(a, cb) : NULL;
    if (err == RP_ERROR_NONE && total) {
        out->capacity = (uint32_t)total;
        out->boxes = sys_alloc(a, (size_t)total * sizeof *out->boxes);
        out->refs = sys_alloc(a, (size_t)total * sizeof *out->refs);
        if (!per || !out->boxes || !out->refs) err = RP_ERROR_OUT_OF_MEMORY;
    }
    if (err == RP_ERROR_NONE && total) {
        j.rejected = (uint64_t *)per, j.degenerate = j.rejected + j.chunks;
        j.bounds = (box3 *)(j.degenerate + j.chunks);
        j.valid = (uint32_t *)(j.bounds + j.chunks);
        if (j.chunks > 1) sys_pool_parallel_for(pool, j.chunks, tri_gather_task, &j);
        else tri_gather_task(&j, 0, 0);
        uint32_t pos = 0;
        for (uint32_t c = 0; c < j.chunks; c++) {
            uint64_t b = total * c / j.chunks;
            memmove(&out->boxes[pos], &out->boxes[b], (size_t)j.valid[c] * sizeof *out->boxes);
            memmove(&out->refs[pos], &out->refs[b], (size_t)j.valid[c] * sizeof *out->refs);
            pos += j.valid[c];
            st->rejected_prims += j.rejected[c], st->degenerate_prims += j.degenerate[c];
            *bounds = box3_union(*bounds, j.bounds[c]);
        }
        out->count = pos;
    }
    sys_free(a, per, cb);
    sys_free(a, ids, idb), sys_free(a, first, fb);
    return err;
}

rp_error scene_build(rp_scene *s) {
    const sys_allocator *a = &s->device->alloc;
    rp_scene_stats st = {0};
    s->built_cost = 0.0;
    gather tris = {0}, prims = {0};
    rp_error err = RP_ERROR_NONE;
    box3 bounds = box3_empty();
    double mean_side = 0.0; /* of the triangle leaves, for coherent_extent */
    uint32_t inst_depth = 0;
    /* share the device's threads unless a parallel_for is running (commit called from a task) */
    bool locked = pthread_mutex_trylock(&s->device->pool_lock) == 0;
    sys_pool *pool = locked ? s->device->pool : NULL;
    /* collect valid primitives */
    err = gather_triangles(s, pool, &tris, &st, &bounds);
    box3 tri_bounds = bounds;
    for (uint32_t gi = 0; gi < s->geom_count && err == RP_ERROR_NONE; gi++) {
        rp_geometry *g = s->geoms[gi];
        if (!g) continue;
        switch (g->type) {
        case RP_GEOMETRY_TRIANGLE: break; /* gathered above */
        case RP_GEOMETRY_SPHERE: {
            if (!g->buffers[0].set) {
                err = RP_ERROR_INVALID_GEOMETRY;
                break;
            }
            size_t n = g->buffers[RP_BUFFER_VERTEX].count;
            for (uint32_t p = 0; p < (uint32_t)n && p < 0xFFFFFFF0u; p++) {
                const float *c = geom_item(&g->buffers[RP_BUFFER_VERTEX], p);
                if (!isfinite(c[0]) || !isfinite(c[1]) || !isfinite(c[2]) || !isfinite(c[3]) || !(c[3] >= 0.0f)) {
                    st.rejected_prims++;
                    continue;
                }
                box3 b = {v3(c[0] - c[3], c[1] - c[3], c[2] - c[3]), v3(c[0] + c[3], c[1] + c[3], c[2] + c[3])};
                bounds = box3_union(bounds, b);
                if (!gather_push(a, &prims, b, gi, p)) {
                    err = RP_ERROR_OUT_OF_MEMORY;
                    break;
                }
                st.spheres++;
            }
            break;
        }
        case RP_GEOMETRY_INSTANCE: {
            const rp_scene *c = g->inst;
            uint32_t depth = c ? instance_depth(c, 1) : 0;
            if (!c || !c->committed || depth > RP_MAX_INSTANCE_DEPTH) {
                err = RP_ERROR_INVALID_GEOMETRY;
                break;
            }
            if (depth > inst_depth) inst_depth = depth;
            rp_bounds cb = c->bounds;
            if (!(cb.lower_x <= cb.upper_x)) break; /* an empty scene: nothing to place */
            box3 b = box3_empty();
            for (int corner = 0; corner < 8; corner++) {
                float p[3] = {corner & 1 ? cb.upper_x : cb.lower_x, corner & 2 ? cb.upper_y : cb.lower_y,
                              corner & 4 ? cb.upper_z : cb.lower_z};
                const float *m = g->xfm;
                vec3 q = v3(m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3], m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
                            m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11]);
                b = box3_extend(b, q);
            }
            /* widened by a few ulps: the ray's mapping into the scene rounds */
            vec3 e = v3_mul(v3_add(v3_max(v3(fabsf(b.lo.x), fabsf(b.lo.y), fabsf(b.lo.z)),
                                          v3(fabsf(b.hi.x), fabsf(b.hi.y), fabsf(b.hi.z))), v3_sub(b.hi, b.lo)), 1e-6f);
            b.lo = v3_sub(b.lo, e), b.hi = v3_add(b.hi, e);
            if (!v3_finite(b.lo) || !v3_finite(b.hi)) {
                st.rejected_prims++;
                break;
            }
            bounds = box3_union(bounds, b);
            if (!gather_push(a, &prims, b, gi, 0)) err = RP_ERROR_OUT_OF_MEMORY;
            else st.user_prims++;
            break;
        }
        case RP_GEOMETRY_USER: {
            if (!g->user_bounds) {
                err = RP_ERROR_INVALID_GEOMETRY;
                break;
            }
            for (uint32_t p = 0; p < g->user_count; p++) {
                rp_bounds ub = {0};
                g->user_bounds(g->user, p, &ub);
                box3 b = {v3(ub.lower_x, ub.lower_y, ub.lower_z), v3(ub.upper_x, ub.upper_y, ub.upper_z)};
                if (!v3_finite(b.lo) || !v3_finite(b.hi) || box3_is_empty(b) || b.lo.y > b.hi.y || b.lo.z > b.hi.z) {
                    st.rejected_prims++;
                    continue;
                }
                bounds = box3_union(bounds, b);
                if (!gather_push(a, &prims, b, gi, p)) {
                    err = RP_ERROR_OUT_OF_MEMORY;
                    break;
                }
                st.user_prims++;
            }
            break;
        }
        }
    }
    if (err == RP_ERROR_NONE && st.rejected_prims) {
        char msg[160];
        snprintf(msg, sizeof msg, "rp_scene_commit: %llu primitives rejected (NaN/Inf coordinates or bad indices)",
                 (unsigned long long)st.rejected_prims);
        device_log(s->device, RP_LOG_WARNING, msg);
    }
    bvh_build_desc bd = {.bins = quality_bins(s->desc.quality), .max_leaf_size = s->desc.max_leaf_size};
    /* leaves end where the SAH says (a node costs half a tri4 block, a whole one at low quality), up to max_leaf_size: long
     * thin triangles whose boxes overlap (spd_rings' cylinders, spd_tree's branches) are
     * cheaper to test together than to split; 4 per leaf made those scenes 1.4-1.7x slower */
    bd.block_size = 4;
    bd.trav_cost = s->desc.quality == RP_BUILD_QUALITY_LOW ? 1.0f : 0.5f;
    int width = pick_width(s);
    const accel_ops *ops = accel_ops_of(s->desc.accel);
    if (err == RP_ERROR_NONE && tris.count && ops) {
        sys_pool *tpool = tris.count >= SMALL_BUILD ? pool : NULL;
        accel_tri_input in = {.boxes = tris.boxes, .refs = tris.refs, .count = tris.count, .bounds = tri_bounds,
                              .fetch = tri_fetch, .fill = tri_fill, .user = s, .grid_density = s->desc.grid_density};
        if (!ops->build(a, tpool, &in, &s->alt)) {
            err = RP_ERROR_OUT_OF_MEMORY;
        } else {
            st.triangles = tris.count;
            st.binary_nodes = s->alt.nodes_total;
            st.wide_nodes = s->alt.inner_nodes;
            st.leaves = s->alt.leaves;
            st.depth = s->alt.root_depth;
            st.sah_cost = s->alt.sah_cost;
            st.bytes = s->alt.node_bytes + ((size_t)s->alt.block_count + 1) * sizeof(tri4);
            st.tri_refs = s->alt.tri_refs;
        }
    } else if (err == RP_ERROR_NONE && tris.count) {
        /* small meshes on the calling thread: waking the others took longer than the work */
        sys_pool *tpool = tris.count >= SMALL_BUILD ? pool : NULL;
        bvh2 b2;
        if (!bvh_build(a, tpool, tris.boxes, tris.count, &bd, &b2)) {
            err = RP_ERROR_OUT_OF_MEMORY;
        } else {
            double diag = diagonal(bounds);
            tri_pack_ctx pc = {.scene = s, .bvh = &b2, .refs = tris.refs,
                               .inv_diag = diag > 0.0 && isfinite(1.0 / diag) ? 1.0 / diag : 0.0};
            pc.chunks = tpool ? (uint32_t)sys_pool_threads(tpool) * 8 : 1;
            size_t sbytes = (size_t)pc.chunks * (sizeof(uint64_t) + sizeof(uint32_t));
            uint64_t *sums = sys_alloc(a, sbytes);
            pc.side_sum = sums, pc.leaf_count = sums ? (uint32_t *)(sums + pc.chunks) : NULL;
            bool ok = sums && tri_pack_plan(a, &pc);
            /* one padding block past the end: the 8-lane leaf tests read a pair of blocks, and a
             * leaf's odd last block is paired with whatever follows it (those lanes masked off);
             * NaN vertices, so no edge function is exactly 0 there (no refinement) and no hit */
            size_t alloc_blocks = (size_t)pc.block_count + 1;
            if (ok) pc.blocks = sys_alloc(a, alloc_blocks * sizeof(tri4));
            ok = ok && pc.blocks;
            if (ok) {
                tri4 *pad = &pc.blocks[pc.block_count];
                memset(pad, 0, sizeof *pad);
                for (int q = 0; q < 9; q++)
                    for (int j = 0; j < 4; j++) pad->v[q][j] = NAN;
                if (tpool) {
                    sys_pool_parallel_for(tpool, pc.chunks, tri_pack_task, &pc);
                    sys_pool_parallel_for(tpool, pc.chunks, tri_leaf_task, &pc);
                } else {
                    tri_pack_task(&pc, 0, 0);
                    tri_leaf_task(&pc, 0, 0);
                }
                uint64_t sum = 0;
                uint64_t leaves = 0;
                for (uint32_t i = 0; i < pc.chunks; i++) sum += pc.side_sum[i], leaves += pc.leaf_count[i];
                mean_side = leaves ? (double)sum / (double)leaves * 0x1p-24 * diag : 0.0;
            }
            sys_free(a, sums, sbytes);
            if (ok) bvh2_pad_boxes(&b2); /* every layout below is made from the widened boxes */
            if (!ok || !bvhw_from_bvh2(a, tpool, &b2, width, leaf_range, NULL, &s->tri_bvh) ||
                !bvhw_compact(a, &s->tri_bvh) || !bvh2q_from_bvh2(a, &b2, &s->tri_bvh2q)) {
                bvhw_free(a, &s->tri_bvh);
                sys_free(a, pc.blocks, alloc_blocks * sizeof(tri4));
                err = RP_ERROR_OUT_OF_MEMORY;
            } else {
                /* keep the binary BVH for large packets, its leaves pointing at the tri4 blocks */
                sys_free(a, b2.prims, (size_t)(b2.prim_count ? b2.prim_count : 1) * sizeof(uint32_t));
                b2.prims = NULL; /* the leaves no longer index it */
                s->tris = pc.blocks;
                s->tri_block_count = alloc_blocks;
                st.triangles = tris.count;
                st.binary_nodes = 2ull * b2.leaf_count - 1; /* node_count also counts unused nodes */
                st.wide_nodes = s->tri_bvh.node_count;
                st.leaves = b2.leaf_count;
                st.depth = b2.depth;
                st.sah_cost = b2.sah_cost;
                st.tri_refs = tris.count;
                st.bytes = s->tri_bvh.bytes + (size_t)pc.block_count * sizeof(tri4) +
                           (size_t)s->tri_bvh2q.node_count * sizeof(bvh2q_node);
                s->built_cost = bvh2_blocks_cost(&b2, REFIT_TRAV_COST); /* for scene_refit (the margin changes it by 1e-6) */
            }
            sys_free(a, pc.block_of, (size_t)b2.prim_count * sizeof(uint32_t));
            bvh2_free(a, &b2);
        }
    }
    if (err == RP_ERROR_NONE && prims.count) {
        bvh2 b2;
        bvh_build_desc pd = {.bins = bd.bins, .max_leaf_size = 4};
        if (!bvh_build(a, pool, prims.boxes, prims.count, &pd, &b2)) {
            err = RP_ERROR_OUT_OF_MEMORY;
        } else {
            s->prims = sys_alloc(a, (size_t)prims.count * sizeof(prim_ref));
            if (s->prims) {
                s->prim_count = prims.count;
                for (uint32_t i = 0; i < prims.count; i++) s->prims[i] = prims.refs[b2.prims[i]];
            }
            if (!s->prims || !bvhw_from_bvh2(a, pool, &b2, 4, leaf_range, NULL, &s->prim_bvh)) {
                err = RP_ERROR_OUT_OF_MEMORY;
            } else {
                st.binary_nodes += 2ull * b2.leaf_count - 1;
                st.wide_nodes += s->prim_bvh.node_count;
                st.leaves += b2.leaf_count;
                if (b2.depth > st.depth) st.depth = b2.depth;
                st.bytes += s->prim_bvh.bytes + prims.count * sizeof(prim_ref);
            }
            bvh2_free(a, &b2);
        }
    }
    if (locked) pthread_mutex_unlock(&s->device->pool_lock);
    gather_free(a, &tris);
    gather_free(a, &prims);
    if (err != RP_ERROR_NONE) return err;
    /* the triangle geometries' masks by geom_id, for the rays that need the mask test (the blocks
     * keep none, traverse.h) */
    s->geom_mask_count = s->geom_count ? s->geom_count : 1;
    s->geom_masks = sys_alloc(a, s->geom_mask_count * sizeof(uint32_t));
    if (!s->geom_masks) return RP_ERROR_OUT_OF_MEMORY;
    s->geom_masks[0] = 0;
    uint32_t tri_mask_and = 0xFFFFFFFFu;
    for (uint32_t gi = 0; gi < s->geom_count; gi++) {
        const rp_geometry *g = s->geoms[gi];
        bool tri = g && g->type == RP_GEOMETRY_TRIANGLE;
        s->geom_masks[gi] = tri ? g->mask : 0u;
        if (tri) tri_mask_and &= g->mask;
    }
    if (st.triangles) st.bytes += s->geom_mask_count * sizeof(uint32_t);
    s->inst_depth = inst_depth;
    st.bvh_width = ops ? 2u : (uint32_t)width;
    st.accel = s->desc.accel;
    s->stats = st;
    s->bounds = (rp_bounds){bounds.lo.x, bounds.lo.y, bounds.lo.z, 0.0f, bounds.hi.x, bounds.hi.y, bounds.hi.z, 0.0f};
    s->accel = (rp_accel){
        .width = width,
        .nodes = s->tri_bvh.nodes,
        .tris = s->tris,
        .tri_mask_and = tri_mask_and,
        .geom_masks = s->geom_masks,
        .nodes2 = s->tri_bvh2q.nodes,
        .q_org = {s->tri_bvh2q.org[0], s->tri_bvh2q.org[1], s->tri_bvh2q.org[2]},
        .q_scale = {s->tri_bvh2q.scale[0], s->tri_bvh2q.scale[1], s->tri_bvh2q.scale[2]},
        .pnodes = s->prim_bvh.nodes,
        .prims = s->prims,
        .prim_intersect = sphere_intersect_cb,
        .prim_occluded = sphere_occluded_cb,
        .scene = s,
        .coherent_extent = coherent_extent(bounds, mean_side),
        .alt = ops ? &s->alt : NULL,
        .base = s->device->kernels,
    };
    s->kernels = !ops ? s->device->kernels
                 : ops->kernels_for_isa ? ops->kernels_for_isa(s->device->kernels->isa) : ops->kernels;
    return RP_ERROR_NONE;
}

/* ---- spheres and user primitives ---------------------------------------------------------- */

/* A ray in an instance's space: origin and direction through the inverse map, t unchanged. */
static void instance_ray(const rp_geometry *g, const rp_ray *ray, rp_ray *out) {
    const float *m = g->inv;
    *out = *ray;
    out->org_x = m[0] * ray->org_x + m[1] * ray->org_y + m[2] * ray->org_z + m[3];
    out->org_y = m[4] * ray->org_x + m[5] * ray->org_y + m[6] * ray->org_z + m[7];
    out->org_z = m[8] * ray->org_x + m[9] * ray->org_y + m[10] * ray->org_z + m[11];
    out->dir_x = m[0] * ray->dir_x + m[1] * ray->dir_y + m[2] * ray->dir_z;
    out->dir_y = m[4] * ray->dir_x + m[5] * ray->dir_y + m[6] * ray->dir_z;
    out->dir_z = m[8] * ray->dir_x + m[9] * ray->dir_y + m[10] * ray->dir_z;
}

/* The instanced scene's own queries (whatever its structure), the same leaf for every level. */
static bool instance_intersect(const rp_geometry *g, uint32_t inst, rp_ray *ray, rp_hit *hit) {
    const rp_scene *c = g->inst;
    rp_rayhit rh;
    memset(&rh, 0, sizeof rh);
    instance_ray(g, ray, &rh.ray);
    rh.hit.geom_id = RP_INVALID_ID;
    c->kernels->intersect1(&c->accel, &rh);
    if (rh.hit.geom_id == RP_INVALID_ID) return false;
    const float *m = g->inv; /* normals go by the inverse transpose */
    ray->tfar = rh.ray.tfar;
    hit->Ng_x = m[0] * rh.hit.Ng_x + m[4] * rh.hit.Ng_y + m[8] * rh.hit.Ng_z;
    hit->Ng_y = m[1] * rh.hit.Ng_x + m[5] * rh.hit.Ng_y + m[9] * rh.hit.Ng_z;
    hit->Ng_z = m[2] * rh.hit.Ng_x + m[6] * rh.hit.Ng_y + m[10] * rh.hit.Ng_z;
    hit->u = rh.hit.u, hit->v = rh.hit.v;
    hit->geom_id = rh.hit.geom_id, hit->prim_id = rh.hit.prim_id;
    hit->inst_id = inst; /* the outermost level writes last */
    return true;
}

static bool instance_occluded(const rp_geometry *g, const rp_ray *ray) {
    rp_ray r;
    instance_ray(g, ray, &r);
    g->inst->kernels->occluded1(&g->inst->accel, &r);
    return r.tfar == -INFINITY;
}

static bool sphere_intersect_cb(const rp_accel *acc, prim_ref ref, rp_ray *ray, rp_hit *hit) {
    const rp_scene *s = acc->scene;
    const rp_geometry *g = s->geoms[ref.geom];
    if ((ray->mask & g->mask) == 0) return false;
    if (g->type == RP_GEOMETRY_INSTANCE) return instance_intersect(g, ref.geom, ray, hit);
    if (g->type == RP_GEOMETRY_USER) {
        if (!g->user_intersect(g->user, ref.prim, ray, hit)) return false;
        hit->geom_id = ref.geom, hit->prim_id = ref.prim, hit->inst_id = RP_INVALID_ID;
        return true;
    }
    const float *c = geom_item(&g->buffers[RP_BUFFER_VERTEX], ref.prim);
    float org[3] = {ray->org_x, ray->org_y, ray->org_z}, dir[3] = {ray->dir_x, ray->dir_y, ray->dir_z}, t;
    if (!sphere_intersect(org, dir, ray->tnear, ray->tfar, c, c[3], &t)) return false;
    float n[3] = {org[0] + t * dir[0] - c[0], org[1] + t * dir[1] - c[1], org[2] + t * dir[2] - c[2]};
    ray->tfar = t;
    hit->Ng_x = n[0], hit->Ng_y = n[1], hit->Ng_z = n[2];
    /* spherical coordinates, for texturing */
    float r = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    float phi = atan2f(n[1], n[0]);
    hit->u = (phi < 0.0f ? phi + 6.2831853f : phi) * 0.15915494f;
    hit->v = r > 0.0f ? acosf(fminf(fmaxf(n[2] / r, -1.0f), 1.0f)) * 0.31830989f : 0.0f;
    hit->geom_id = ref.geom, hit->prim_id = ref.prim, hit->inst_id = RP_INVALID_ID;
    return true;
}

static bool sphere_occluded_cb(const rp_accel *acc, prim_ref ref, const rp_ray *ray) {
    const rp_scene *s = acc->scene;
    const rp_geometry *g = s->geoms[ref.geom];
    if ((ray->mask & g->mask) == 0) return false;
    if (g->type == RP_GEOMETRY_INSTANCE) return instance_occluded(g, ray);
    if (g->type == RP_GEOMETRY_USER) return g->user_occluded(g->user, ref.prim, ray);
    const float *c = geom_item(&g->buffers[RP_BUFFER_VERTEX], ref.prim);
    float org[3] = {ray->org_x, ray->org_y, ray->org_z}, dir[3] = {ray->dir_x, ray->dir_y, ray->dir_z}, t;
    return sphere_intersect(org, dir, ray->tnear, ray->tfar, c, c[3], &t);
}

/* ---- refit -------------------------------------------------------------------------------- */

typedef struct refit_job {
    const rp_scene *s;
    tri4 *blocks;
    uint32_t count, chunks;
    _Atomic bool bad; /* a vertex became NaN / Inf: rebuild */
} refit_job;

/* Reloads the vertices of a chunk of the blocks from their lanes' (geom, prim); padding lanes
 * repeat lane 0's triangle, so they reload it too. */
static void refit_fill_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    refit_job *j = user;
    uint32_t b = (uint32_t)((uint64_t)j->count * index / j->chunks), e = (uint32_t)((uint64_t)j->count * (index + 1) / j->chunks);
    for (uint32_t i = b; i < e; i++) {
        tri4 *t = &j->blocks[i];
        for (int lane = 0; lane < 4; lane++) {
            vec3 v[3];
            if (!load_triangle(j->s->geoms[t->geom[lane]], t->prim[lane], v)) {
                atomic_store(&j->bad, true);
                return;
            }
            for (int q = 0; q < 3; q++) t->v[3 * q][lane] = v[q].x, t->v[3 * q + 1][lane] = v[q].y, t->v[3 * q + 2][lane] = v[q].z;
        }
    }
}

/* A commit after only vertices moved: the triangle BVH keeps its topology, its blocks get the
 * new vertices, its boxes are refitted and the wide layout collapsed again from them. Declines
 * (false, nothing changed that a rebuild does not redo) when the scene is not a plain triangle
 * BVH scene whose geometries kept their topology since the last build, when a vertex became
 * invalid, or when the refitted tree's SAH cost grew past refit_max_growth times the built one's. */
static bool scene_refit(rp_scene *s) {
    if (s->desc.accel != RP_ACCEL_BVH || s->desc.refit_max_growth < 0.0f || !s->tri_bvh2q.nodes || !s->tris ||
        s->attach_changed || s->geom_count != s->built_count || s->prim_count || s->stats.rejected_prims ||
        s->stats.degenerate_prims)
        return false;
    for (uint32_t i = 0; i < s->geom_count; i++) {
        const rp_geometry *g = s->geoms[i];
        if (!g) {
            if (s->built_topo[i] != RP_INVALID_ID) return false;
            continue;
        }
        if (g->type != RP_GEOMETRY_TRIANGLE || g->topo != s->built_topo[i]) return false;
    }
    const sys_allocator *a = &s->device->alloc;
    bool locked = pthread_mutex_trylock(&s->device->pool_lock) == 0;
    sys_pool *pool = locked ? s->device->pool : NULL;
    refit_job j = {.s = s, .blocks = s->tris, .count = (uint32_t)(s->tri_block_count - 1)};
    j.chunks = pool && j.count >= 1024 ? (uint32_t)sys_pool_threads(pool) * 8 : 1;
    atomic_store(&j.bad, false);
    if (j.chunks > 1) sys_pool_parallel_for(pool, j.chunks, refit_fill_task, &j);
    else refit_fill_task(&j, 0, 0);
    bool ok = !atomic_load(&j.bad);
    /* the float tree, refitted, then quantized again (its topology is the quantized one's) */
    bvh2 tree = {0};
    bvh2q q = {0};
    if (ok) ok = bvh2q_to_bvh2(a, &s->tri_bvh2q, true, &tree);
    double cost = ok ? bvh2_refit_blocks(&tree, s->tris, REFIT_TRAV_COST) : 0.0;
    if (ok && cost > (double)s->desc.refit_max_growth * s->built_cost) ok = false;
    if (ok) bvh2_pad_boxes(&tree); /* as the build does */
    bvhw wide = {0};
    if (ok) ok = bvhw_from_bvh2(a, j.count >= 1024 ? pool : NULL, &tree, s->tri_bvh.width, leaf_range, NULL, &wide);
    if (locked) pthread_mutex_unlock(&s->device->pool_lock);
    if (ok && !bvhw_compact(a, &wide)) bvhw_free(a, &wide), ok = false;
    if (ok && !bvh2q_from_bvh2(a, &tree, &q)) bvhw_free(a, &wide), ok = false;
    if (!ok) {
        bvh2_free(a, &tree);
        return false;
    }
    bvhw_free(a, &s->tri_bvh);
    s->tri_bvh = wide;
    bvh2q_free(a, &s->tri_bvh2q);
    s->tri_bvh2q = q;
    const bvh_node *r = &tree.nodes[0];
    s->bounds = (rp_bounds){r->lo[0], r->lo[1], r->lo[2], 0.0f, r->hi[0], r->hi[1], r->hi[2], 0.0f};
    bvh2_free(a, &tree);
    s->accel.nodes = s->tri_bvh.nodes;
    s->accel.nodes2 = s->tri_bvh2q.nodes;
    for (int k = 0; k < 3; k++) s->accel.q_org[k] = s->tri_bvh2q.org[k], s->accel.q_scale[k] = s->tri_bvh2q.scale[k];
    s->stats.wide_nodes = s->tri_bvh.node_count;
    s->stats.sah_cost = cost;
    s->stats.bytes = s->tri_bvh.bytes + (s->tri_block_count - 1) * sizeof(tri4) +
                     (size_t)s->tri_bvh2q.node_count * sizeof(bvh2q_node) + s->geom_mask_count * sizeof(uint32_t);
    s->stats.refit = 1;
    return true;
}
