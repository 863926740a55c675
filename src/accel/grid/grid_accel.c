/* The uniform grid as a core acceleration structure (RP_ACCEL_GRID): the voxel lists of grid.c
 * (resolution rule, margin, triangle / voxel overlap) repacked as tri4 blocks per voxel, so a
 * voxel's triangles are tested four at a time by the BVH's watertight leaf test (tri_leaf.h) and
 * every query returns the BVH's hits bit for bit. A triangle in several voxels is in a block of
 * each; a mailbox of the triangles tested (Amanatides, Woo 1987) skips a block whose triangles
 * were all tested already. Triangles are listed by the full triangle-box overlap test (grid_desc.sat).
 * Traversal is the 3D-DDA of Amanatides and Woo, front to back, ending when the closest hit lies
 * before the current voxel's exit; empty space is crossed by proximity clouds (Cohen, Sheffer
 * 1994): each empty voxel stores how far the empty cube around it reaches, and the walk jumps to
 * that cube's exit in one step. Packets go ray by ray. */
#include <math.h>
#include <string.h>

#include "accel/grid/grid.h"
#include "accel/tri_leaf.h"

/* At the head of accel_built.nodes, followed by
 *   uint32_t first[voxel_count + 1]: voxel v's blocks are [first[v], first[v + 1]),
 *   uint32_t ids[4 * block_count]: the triangle of each lane (the mailbox's key),
 *   uint8_t clear[8][voxel_count]: per octant of ray directions, 0 when voxel v holds triangles,
 *   else the side (in voxels, at most 255) of the largest cube with v at its corner, growing
 *   into that octant, that holds none. */
typedef struct grid_layout {
    float lo[3], cell[3], inv_cell[3];
    int32_t res[3];
    uint32_t voxel_count;
    uint64_t block_count;
} grid_layout;

#define LAYOUT_HEAD ((sizeof(grid_layout) + 63) / 64 * 64)

static inline const uint32_t *layout_first(const grid_layout *g) {
    return (const uint32_t *)((const char *)g + LAYOUT_HEAD);
}
static inline const uint32_t *layout_ids(const grid_layout *g) { return layout_first(g) + g->voxel_count + 1; }
/* One byte per voxel for a ray's octant (bit k: the ray goes towards +axis k), small enough to
 * stay in cache: empty space costs no load of first[]. */
static inline const uint8_t *layout_clear(const grid_layout *g, int octant) {
    return (const uint8_t *)(layout_ids(g) + 4 * g->block_count) + (size_t)octant * g->voxel_count;
}

/* The clear cubes of octant o (bit k set: the cube grows towards +axis k) from the occupancy in d
 * (0: occupied, else empty): d[v] becomes the side of the largest empty cube with v at its corner
 * that lies in octant o, at most 255 (voxels outside the grid count as empty). A cube of side n at
 * v is v and the cubes of side n - 1 at its 7 neighbours in the octant, so one pass that visits
 * those neighbours first gives it (the largest empty square's recurrence, in 3D). */
static void clear_cubes(uint8_t *d, const int32_t res[3], int o) {
    const int32_t nx = res[0], ny = res[1], nz = res[2];
    const int32_t sx = o & 1 ? 1 : -1, sy = o & 2 ? 1 : -1, sz = o & 4 ? 1 : -1;
    uint8_t m[4096]; /* per x: the least of the neighbours in the rows already done (res <= 4096) */
    for (int32_t zi = 0; zi < nz; zi++) {
        int32_t z = sz > 0 ? nz - 1 - zi : zi;
        for (int32_t yi = 0; yi < ny; yi++) {
            int32_t y = sy > 0 ? ny - 1 - yi : yi;
            uint8_t *row = d + ((size_t)z * (size_t)ny + (size_t)y) * (size_t)nx;
            bool in_y = y + sy >= 0 && y + sy < ny, in_z = z + sz >= 0 && z + sz < nz;
            const uint8_t *ry = in_y ? d + ((size_t)z * (size_t)ny + (size_t)(y + sy)) * (size_t)nx : NULL;
            const uint8_t *rz = in_z ? d + ((size_t)(z + sz) * (size_t)ny + (size_t)y) * (size_t)nx : NULL;
            const uint8_t *ryz = in_y && in_z ? d + ((size_t)(z + sz) * (size_t)ny + (size_t)(y + sy)) * (size_t)nx : NULL;
            for (int32_t x = 0; x < nx; x++) {
                uint8_t v = 254; /* outside the grid: empty */
                if (ry && ry[x] < v) v = ry[x];
                if (rz && rz[x] < v) v = rz[x];
                if (ryz && ryz[x] < v) v = ryz[x];
                m[x] = v;
            }
            /* along the row, in the octant's order: x + sx is done before x */
            for (int32_t xi = 0; xi < nx; xi++) {
                int32_t x = sx > 0 ? nx - 1 - xi : xi;
                if (!row[x]) continue;
                uint8_t v = m[x];
                if (x + sx >= 0 && x + sx < nx) {
                    if (m[x + sx] < v) v = m[x + sx];
                    if (row[x + sx] < v) v = row[x + sx];
                }
                row[x] = (uint8_t)(v + 1);
            }
        }
    }
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
    size_t bytes = LAYOUT_HEAD + ((size_t)g->voxel_count + 1) * sizeof(uint32_t) + (size_t)blocks * 4 * sizeof(uint32_t) +
                   8 * (size_t)g->voxel_count;
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
    uint32_t *first = (uint32_t *)((char *)lay + LAYOUT_HEAD), *ids = first + g->voxel_count + 1;
    for (int o = 0; o < 8; o++) {
        uint8_t *clear = (uint8_t *)layout_clear(lay, o);
        for (uint32_t v = 0; v < g->voxel_count; v++) clear[v] = g->offsets[v] != g->offsets[v + 1] ? 0 : 1;
        clear_cubes(clear, lay->res, o);
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
    float t = (g->lo[k] + (float)index * g->cell[k] - r->org[k]) * r->rdir[k];
    return r->dir[k] == 0.0f ? INFINITY : t;
}

/* The voxel of axis k that holds the ray's point at t, clamped to [lo, hi]. */
static inline int32_t cell_at(const grid_layout *g, const alt_ray *r, int k, float t, int32_t lo, int32_t hi) {
    /* floor(c) >= lo iff c >= lo, and floor(c) > hi iff c >= hi + 1; between them truncation
     * is floor (c >= 0) */
    float c = (r->org[k] + r->dir[k] * t - g->lo[k]) * g->inv_cell[k];
    return !(c >= (float)lo) ? lo : (c >= (float)(hi + 1) ? hi : (int32_t)c);
}

/* Where the walk ends: the segment's exit t1, or the closest hit ht widened by the kernels' cull
 * slack (a cell starting beyond it holds no nearer hit). NaN never ends it (as before: the
 * comparisons with a NaN are false). */
static inline float walk_end(float t1, float ht) {
    float lim = ht > 0.0f ? ht * ALT_CULL_SLACK : ht * (1.0f / ALT_CULL_SLACK);
    return lim < t1 ? lim : t1;
}

/* 3D-DDA (Amanatides, Woo 1987) over the voxels. From an empty voxel whose clear cube in the
 * ray's octant reaches r > 0 voxels further, the walk jumps to that cube's exit: on to the voxel beyond
 * the face the ray leaves by, at the exit point (clamped to the cube's side on the other axes).
 * Each axis's next crossing is computed afresh from its plane (not accumulated), so rounding does
 * not grow along the ray; where a voxel found from a point is one off, the ray is within rounding
 * of its side and the voxel lists' margin covers it (a voxel behind the ray is left at once: its
 * crossing is already past). The walk ends when the next voxel starts beyond the closest hit
 * (with the kernels' cull slack, relative to the distance, for the rounding of both). */
static bool grid_trav(const rp_accel *acc, const accel_built *s, const alt_ray *r, alt_hit *h, bool any) {
    (void)acc;
    float t0, t1;
    if (!alt_ray_box(r, s->bounds, h->t, &t0, &t1)) return false;
    const grid_layout *g = s->nodes;
    const uint32_t *first = layout_first(g), *ids = layout_ids(g);
    const uint8_t *clear = layout_clear(g, (r->rdir[0] >= 0.0f) | (r->rdir[1] >= 0.0f) << 1 | (r->rdir[2] >= 0.0f) << 2);
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
    float end = walk_end(t1, h->t);
    bool fresh = true; /* next[] holds the current voxel's crossings */
    for (;;) {
        const int32_t reach = (int32_t)clear[voxel] - 1;
        if (reach > 0) {
            /* an empty cube from cell to cell + reach * step (within the grid): on to the voxel
             * past its exit */
            int32_t lo[3], hi[3];
            float mt[3];
            for (int k = 0; k < 3; k++) {
                lo[k] = pos[k] ? cell[k] : (cell[k] - reach > 0 ? cell[k] - reach : 0);
                hi[k] = !pos[k] ? cell[k] : (cell[k] + reach < g->res[k] - 1 ? cell[k] + reach : g->res[k] - 1);
                mt[k] = plane_t(g, r, k, pos[k] ? hi[k] + 1 : lo[k]);
            }
            int k = mt[0] < mt[1] ? (mt[0] < mt[2] ? 0 : 2) : (mt[1] < mt[2] ? 1 : 2);
            float te = mt[k];
            if (te > end) return false;
            int32_t c = pos[k] ? hi[k] + 1 : lo[k] - 1;
            if (c < 0 || c >= g->res[k]) return false; /* it leaves the grid */
            voxel = 0;
            for (int j = 0; j < 3; j++) {
                cell[j] = j == k ? c : cell_at(g, r, j, te, lo[j], hi[j]);
                voxel += (uint32_t)(cell[j] * stride[j]);
            }
            fresh = false;
            continue;
        }
        if (reach < 0) {
            for (uint32_t b = first[voxel], e = first[voxel + 1]; b < e; b++) {
                if (mailbox_all_seen(mb, &ids[4 * b])) continue;
                if (alt_leaf(s->blocks, r, b, 1, h, any)) return true;
            }
            end = walk_end(t1, h->t);
        }
        if (!fresh) { /* after a jump (which needs none): the crossings of this voxel's sides */
            for (int j = 0; j < 3; j++) next[j] = plane_t(g, r, j, cell[j] + pos[j]);
            fresh = true;
        }
        int k = next[0] < next[1] ? (next[0] < next[2] ? 0 : 2) : (next[1] < next[2] ? 1 : 2);
        if (next[k] > end) return false;
        cell[k] += step[k];
        if (cell[k] == stop[k]) return false;
        voxel += (uint32_t)(step[k] * stride[k]);
        next[k] = plane_t(g, r, k, cell[k] + pos[k]);
    }
}

ALT_KERNELS(grid_accel, grid_trav, alt_no_packets, NULL)

RP_HIDDEN const accel_ops accel_grid = {"grid", grid_accel_build, &grid_accel_kernels};
