/* The uniform grid as a core acceleration structure (RP_ACCEL_GRID): the voxel lists of grid.c
 * (resolution rule, margin, triangle / voxel overlap) repacked as tri4 blocks per voxel, so a
 * voxel's triangles are tested four at a time by the BVH's watertight leaf test (tri_leaf.h) and
 * every query returns the BVH's hits bit for bit. A triangle in several voxels is in a block of
 * each; a mailbox of the triangles tested (Amanatides, Woo 1987) skips a block whose triangles
 * were all tested already. Triangles are listed by the full triangle-box overlap test (grid_desc.sat).
 * Traversal is the 3D-DDA of Amanatides and Woo, front to back, ending when the closest hit lies
 * before the current voxel's exit; empty space is crossed by macro cells of 4^3 and 16^3 voxels
 * (occupancy bytes, and one bit per voxel). Packets go ray by ray. */
#include <math.h>
#include <string.h>

#include "accel/grid/grid.h"
#include "accel/tri_leaf.h"

#define GRID_LEVELS 2

/* At the head of accel_built.nodes, followed by
 *   uint64_t bits[(voxel_count + 63) / 64]: voxel v holds triangles,
 *   uint32_t first[voxel_count + 1]: voxel v's blocks are [first[v], first[v + 1]),
 *   uint32_t ids[4 * block_count]: the triangle of each lane (the mailbox's key),
 *   uint8_t macro[level][macro_count[level]]: the macro cell holds triangles. */
typedef struct grid_layout {
    float lo[3], cell[3], inv_cell[3];
    int32_t res[3];
    uint32_t voxel_count;
    uint64_t block_count;
    /* macro cells of GRID_LEVELS sizes: level l is (1 << macro_log2[l])^3 voxels (fewer at the
     * far sides); an empty one is crossed in one step */
    int32_t mres[GRID_LEVELS][3];
    uint32_t macro_count[GRID_LEVELS];
} grid_layout;

static const int32_t macro_log2[GRID_LEVELS] = {2, 4};

#define LAYOUT_HEAD ((sizeof(grid_layout) + 63) / 64 * 64)

/* One bit per voxel (set: it holds triangles; first, for its alignment), then first[] and ids[],
 * then per level one byte per macro cell (1: one of its voxels holds triangles). The bits and
 * bytes are small enough to stay in cache, so empty space costs no load of first[]. */
static inline const uint64_t *layout_bits(const grid_layout *g) {
    return (const uint64_t *)((const char *)g + LAYOUT_HEAD);
}
static inline const uint32_t *layout_first(const grid_layout *g) {
    return (const uint32_t *)(layout_bits(g) + (g->voxel_count + 63) / 64);
}
static inline const uint32_t *layout_ids(const grid_layout *g) { return layout_first(g) + g->voxel_count + 1; }
static inline const uint8_t *layout_macro(const grid_layout *g, int level) {
    const uint8_t *m = (const uint8_t *)(layout_ids(g) + 4 * g->block_count);
    for (int l = 0; l < level; l++) m += g->macro_count[l];
    return m;
}
static inline uint32_t macro_index(const grid_layout *g, int level, const int32_t cell[3]) {
    int lg = macro_log2[level];
    return ((uint32_t)(cell[2] >> lg) * (uint32_t)g->mres[level][1] + (uint32_t)(cell[1] >> lg)) *
               (uint32_t)g->mres[level][0] +
           (uint32_t)(cell[0] >> lg);
}

/* voxels per triangle when rp_scene_desc.grid_density is 0 */
#define GRID_ACCEL_DENSITY 4.0f

static bool grid_accel_build(const sys_allocator *a, sys_pool *pool, accel_tri_input *in, accel_built *out) {
    (void)pool;
    memset(out, 0, sizeof *out);
    grid_tri *tris = sys_alloc(a, (size_t)(in->count ? in->count : 1) * sizeof(grid_tri));
    if (!tris) return false;
    for (uint32_t i = 0; i < in->count; i++) {
        grid_tri *t = &tris[i];
        prim_ref r = in->refs[i];
        in->fetch(in->user, r, t->v, &t->mask);
        t->geom = r.geom, t->prim = r.prim, t->pad = 0;
    }
    grid_desc gd = {.density = in->grid_density > 0.0f ? in->grid_density : GRID_ACCEL_DENSITY, .sat = true};
    grid *g = grid_build_tris(a, tris, in->count, &gd);
    sys_free(a, tris, (size_t)(in->count ? in->count : 1) * sizeof(grid_tri));
    if (!g) return false;
    uint64_t blocks = 0;
    for (uint32_t v = 0; v < g->voxel_count; v++) blocks += (g->offsets[v + 1] - g->offsets[v] + 3) / 4;
    if (blocks >= UINT32_MAX / 4) {
        grid_free(g);
        return false;
    }
    int32_t mres[GRID_LEVELS][3];
    uint32_t macro_count[GRID_LEVELS];
    size_t macro_bytes = 0;
    for (int l = 0; l < GRID_LEVELS; l++) {
        for (int k = 0; k < 3; k++) mres[l][k] = (g->res[k] + (1 << macro_log2[l]) - 1) >> macro_log2[l];
        macro_count[l] = (uint32_t)mres[l][0] * (uint32_t)mres[l][1] * (uint32_t)mres[l][2];
        macro_bytes += macro_count[l];
    }
    size_t bit_words = ((size_t)g->voxel_count + 63) / 64;
    size_t bytes = LAYOUT_HEAD + ((size_t)g->voxel_count + 1) * sizeof(uint32_t) + (size_t)blocks * 4 * sizeof(uint32_t) +
                   bit_words * sizeof(uint64_t) + macro_bytes;
    grid_layout *lay = sys_alloc(a, bytes);
    tri4 *tb = lay ? accel_blocks_alloc(a, (uint32_t)blocks) : NULL;
    if (!tb) {
        sys_free(a, lay, bytes);
        grid_free(g);
        return false;
    }
    memset(lay, 0, LAYOUT_HEAD);
    for (int k = 0; k < 3; k++) lay->lo[k] = g->lo[k], lay->cell[k] = g->cell[k], lay->res[k] = g->res[k];
    for (int k = 0; k < 3; k++) lay->inv_cell[k] = 1.0f / g->cell[k];
    lay->voxel_count = g->voxel_count;
    lay->block_count = blocks;
    memcpy(lay->mres, mres, sizeof mres);
    memcpy(lay->macro_count, macro_count, sizeof macro_count);
    uint64_t *bits = (uint64_t *)((char *)lay + LAYOUT_HEAD);
    uint32_t *first = (uint32_t *)(bits + bit_words), *ids = first + g->voxel_count + 1;
    memset(bits, 0, bit_words * sizeof(uint64_t));
    memset((uint8_t *)layout_macro(lay, 0), 0, macro_bytes);
    for (int32_t z = 0; z < g->res[2]; z++)
        for (int32_t y = 0; y < g->res[1]; y++)
            for (int32_t x = 0; x < g->res[0]; x++) {
                uint32_t v = ((uint32_t)z * (uint32_t)g->res[1] + (uint32_t)y) * (uint32_t)g->res[0] + (uint32_t)x;
                if (g->offsets[v] == g->offsets[v + 1]) continue;
                bits[v >> 6] |= 1ull << (v & 63);
                const int32_t c[3] = {x, y, z};
                for (int l = 0; l < GRID_LEVELS; l++) ((uint8_t *)layout_macro(lay, l))[macro_index(lay, l, c)] = 1;
            }
    uint32_t b = 0;
    for (uint32_t v = 0; v < g->voxel_count; v++) {
        first[v] = b;
        for (uint32_t k = g->offsets[v]; k < g->offsets[v + 1]; k += 4, b++) {
            uint32_t n = g->offsets[v + 1] - k < 4 ? g->offsets[v + 1] - k : 4;
            tri4 *dst = &tb[b];
            for (uint32_t lane = 0; lane < 4; lane++) {
                /* unused lanes: lane 0 again, as the BVH's blocks */
                uint32_t i = g->items[k + (lane < n ? lane : 0)];
                ids[4 * b + lane] = i;
                if (lane >= n) continue;
                const grid_tri *t = &g->tris[i];
                for (int q = 0; q < 9; q++) dst->v[q][lane] = t->v[q];
                dst->geom[lane] = t->geom, dst->prim[lane] = t->prim;
            }
            tri4_pad(dst, n);
        }
    }
    first[g->voxel_count] = b;
    out->nodes = lay;
    out->node_bytes = bytes;
    out->blocks = tb;
    out->block_count = (uint32_t)blocks;
    out->root_depth = 1;
    out->nodes_total = g->voxel_count;
    out->inner_nodes = 0;
    out->leaves = g->nonempty;
    out->tri_refs = g->item_count;
    out->sah_cost = 0.0;
    for (int k = 0; k < 3; k++) out->bounds[k] = g->lo[k], out->bounds[3 + k] = g->hi[k];
    grid_free(g);
    return true;
}

/* True when every lane's triangle of the block is in the mailbox; else puts them there. */
static inline bool mailbox_all_seen(uint32_t *mb, const uint32_t *id) {
    bool seen = mb[id[0] % GRID_MAILBOX] == id[0] && mb[id[1] % GRID_MAILBOX] == id[1] &&
                mb[id[2] % GRID_MAILBOX] == id[2] && mb[id[3] % GRID_MAILBOX] == id[3];
    if (!seen)
        for (int l = 0; l < 4; l++) mb[id[l] % GRID_MAILBOX] = id[l];
    return seen;
}

/* Crossing of the plane `index` (in voxels) of axis k by the ray; +inf when parallel to it. */
static inline float plane_t(const grid_layout *g, const alt_ray *r, int k, int32_t index) {
    return r->dir[k] == 0.0f ? INFINITY : (g->lo[k] + (float)index * g->cell[k] - r->org[k]) * r->rdir[k];
}

/* The voxel of axis k that holds the ray's point at t, clamped to [lo, hi]. */
static inline int32_t cell_at(const grid_layout *g, const alt_ray *r, int k, float t, int32_t lo, int32_t hi) {
    float c = floorf((r->org[k] + r->dir[k] * t - g->lo[k]) * g->inv_cell[k]);
    return !(c >= (float)lo) ? lo : (c > (float)hi ? hi : (int32_t)c);
}

/* 3D-DDA (Amanatides, Woo 1987) over the voxels, with empty macro cells crossed in one step
 * (the largest empty one holding the current voxel): from a macro cell's exit the walk goes on in the voxel of the next macro
 * cell that holds the exit point. Each axis's next crossing is computed afresh from its plane
 * (not accumulated), so rounding does not grow along the ray; where a voxel found from a point is
 * one off, the ray is within rounding of its side and the voxel lists' margin covers it (a voxel
 * behind the ray is left at once: its crossing is already past). The walk ends when the next
 * voxel starts beyond the closest hit (with the kernels' cull slack, relative to the distance, for
 * the rounding of both). */
static bool grid_trav(const rp_accel *acc, const accel_built *s, const alt_ray *r, alt_hit *h, bool any) {
    (void)acc;
    float t0, t1;
    if (!alt_ray_box(r, s->bounds, h->t, &t0, &t1)) return false;
    const grid_layout *g = s->nodes;
    const uint32_t *first = layout_first(g), *ids = layout_ids(g);
    const uint64_t *bits = layout_bits(g);
    const uint8_t *macro[GRID_LEVELS];
    for (int l = 0; l < GRID_LEVELS; l++) macro[l] = layout_macro(g, l);
    const int32_t stride[3] = {1, g->res[0], g->res[0] * g->res[1]};
    int32_t cell[3], step[3], stop[3];
    bool pos[3];
    float next[3];
    uint32_t voxel = 0;
    for (int k = 0; k < 3; k++) {
        cell[k] = cell_at(g, r, k, t0, 0, g->res[k] - 1);
        pos[k] = r->rdir[k] >= 0.0f;
        step[k] = pos[k] ? 1 : -1;
        stop[k] = pos[k] ? g->res[k] : -1;
        next[k] = plane_t(g, r, k, cell[k] + pos[k]);
        voxel += (uint32_t)(cell[k] * stride[k]);
    }
    uint32_t mb[GRID_MAILBOX];
    for (int i = 0; i < GRID_MAILBOX; i++) mb[i] = UINT32_MAX;
    for (;;) {
        int lv = GRID_LEVELS - 1;
        while (lv >= 0 && macro[lv][macro_index(g, lv, cell)]) lv--;
        if (lv >= 0) {
            /* an empty macro cell: on to the voxel of the next one that holds its exit point */
            const int lg = macro_log2[lv];
            int32_t mc[3] = {cell[0] >> lg, cell[1] >> lg, cell[2] >> lg};
            float mt[3];
            for (int k = 0; k < 3; k++) {
                int32_t side = (mc[k] + pos[k]) << lg;
                mt[k] = plane_t(g, r, k, side < g->res[k] ? side : g->res[k]);
            }
            int k = mt[0] < mt[1] ? (mt[0] < mt[2] ? 0 : 2) : (mt[1] < mt[2] ? 1 : 2);
            float te = mt[k];
            float ht = h->t, lim = ht > 0.0f ? ht * ALT_CULL_SLACK : ht * (1.0f / ALT_CULL_SLACK);
            if (te > t1 || te > lim) return false;
            int32_t c = pos[k] ? (mc[k] + 1) << lg : (mc[k] << lg) - 1;
            if (c < 0 || c >= g->res[k]) return false; /* it leaves the grid */
            voxel = 0;
            for (int j = 0; j < 3; j++) {
                if (j == k) {
                    cell[j] = c;
                } else {
                    int32_t lo = mc[j] << lg, hi = lo + (1 << lg) - 1;
                    cell[j] = cell_at(g, r, j, te, lo, hi < g->res[j] - 1 ? hi : g->res[j] - 1);
                }
                next[j] = plane_t(g, r, j, cell[j] + pos[j]);
                voxel += (uint32_t)(cell[j] * stride[j]);
            }
            continue;
        }
        if (bits[voxel >> 6] >> (voxel & 63) & 1u) {
            for (uint32_t b = first[voxel], e = first[voxel + 1]; b < e; b++) {
                if (mailbox_all_seen(mb, &ids[4 * b])) continue;
                if (alt_leaf(s->blocks, r, b, 1, h, any)) return true;
            }
        }
        int k = next[0] < next[1] ? (next[0] < next[2] ? 0 : 2) : (next[1] < next[2] ? 1 : 2);
        float te = next[k];
        float ht = h->t, lim = ht > 0.0f ? ht * ALT_CULL_SLACK : ht * (1.0f / ALT_CULL_SLACK);
        if (te > t1 || te > lim) return false;
        cell[k] += step[k];
        if (cell[k] == stop[k]) return false;
        voxel += (uint32_t)(step[k] * stride[k]);
        next[k] = plane_t(g, r, k, cell[k] + pos[k]);
    }
}

ALT_KERNELS(grid_accel, grid_trav, alt_no_packets, NULL)

RP_HIDDEN const accel_ops accel_grid = {"grid", grid_accel_build, &grid_accel_kernels};
