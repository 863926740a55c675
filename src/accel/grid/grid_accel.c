/* The uniform grid as a core acceleration structure (RP_ACCEL_GRID): the voxel lists of grid.c
 * (resolution rule, margin, triangle / voxel overlap) repacked as tri4 blocks per voxel, so a
 * voxel's triangles are tested four at a time by the BVH's watertight leaf test (tri_leaf.h) and
 * every query returns the BVH's hits bit for bit. A triangle in several voxels is in a block of
 * each; a mailbox of the triangles tested (Amanatides, Woo 1987) skips a block whose triangles
 * were all tested already. Triangles are listed by the full triangle-box overlap test (grid_desc.sat).
 * Traversal is the 3D-DDA of Amanatides and Woo, front to back, ending when the closest hit lies
 * before the current voxel's exit; empty space is crossed by proximity clouds (Cohen, Sheffer
 * 1994): each empty voxel stores how far the empty cube around it reaches, and the walk jumps to
 * that cube's exit in one step. Coherent packets walk slice by slice (grid_packet). */
#include <math.h>
#include <string.h>

#include "accel/grid/grid.h"
#include "accel/tri_leaf.h"

/* At the head of accel_built.nodes, followed by
 *   uint32_t first[voxel_count + 1]: voxel v's blocks are [first[v], first[v + 1]),
 *   uint32_t ids[4 * block_count]: the triangle of each lane (the mailbox's key),
 *   uint8_t clear[8][voxel_count]: per octant of ray directions, 0 when voxel v holds triangles,
 *   else the side (in voxels, at most 255) of the largest cube with v at its corner, growing
 *   into that octant, that holds none. (Stored in bricks of 4 x 4 x 4 voxels, a cache line each,
 *   the single rays had been slower against the BVH on all five scenes measured: docs/accel.md.) */
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

/* ---- coherent packets: slice-wise traversal (Wald, Ize, Kensler, Knoll, Parker 2006) -------- */

/* cell ranges are widened by this (in voxels) against the rounding of the rays' coordinates; a
 * cell too many only costs tests */
#define PK_EPS 0.01f
#define PK_MAX 16
/* most spread of the rays' origins, in voxels, for a packet to walk together */
#define PK_SPREAD 1.0f

/* A packet of 8 or more rays whose directions share their sign along the slicing axis K walks the grid one
 * slice of voxels (perpendicular to K) at a time. Each ray is a line in voxel coordinates,
 * u(s) = ua + du * s and v(s) = va + dv * s of its position s along K (grown in the rays'
 * direction), over [s_lo, s_hi] (its entry and its end: the box's exit or the closest hit). In a
 * slice, each ray covers a rectangle of voxels; the packet visits the union, and a ray tests only
 * the blocks of the voxels in its own rectangle (its own mailbox), so it tests what its single
 * walk would, the voxels its rectangle adds at most. Empty space: when a clear cube at the union's
 * corner covers the union, the packet jumps to the first slice where some ray may leave the cube.
 * A ray is done when its end lies before the next slice; the packet when all are. */
typedef struct grid_pk {
    float ua[PK_MAX], du[PK_MAX], va[PK_MAX], dv[PK_MAX];
    float ka[PK_MAX], dk[PK_MAX], t1[PK_MAX];
    float s_lo[PK_MAX], s_hi[PK_MAX];
    int32_t u0[PK_MAX], u1[PK_MAX], v0[PK_MAX], v1[PK_MAX];
} grid_pk;

/* min / max without libm's calls (fminf is not inlined without -ffinite-math-only); a NaN in
 * b gives a */
static inline float minf(float a, float b) { return b < a ? b : a; }
static inline float maxf(float a, float b) { return b > a ? b : a; }

/* The slicing axis: one along which every live ray goes the same way, the one whose slowest ray
 * crosses most slices per voxel travelled (in voxel units); -1 when none suits. */
static int pk_axis(const grid_layout *g, const alt_ray *r, uint32_t live) {
    int best = -1;
    float best_q = 0.25f; /* below: the rectangles grow long, rays go ray by ray */
    for (int a = 0; a < 3; a++) {
        uint32_t npos = 0, n = 0;
        float q = INFINITY;
        for (uint32_t m = live; m; m &= m - 1) {
            const alt_ray *ri = &r[simd_ctz(m)];
            float d[3];
            for (int b = 0; b < 3; b++) d[b] = fabsf(ri->dir[b]) * g->inv_cell[b];
            float mx = maxf(d[0], maxf(d[1], d[2]));
            float qi = mx > 0.0f ? d[a] / mx : 0.0f;
            q = minf(q, qi);
            npos += ri->dir[a] > 0.0f, n++;
        }
        if ((npos == 0 || npos == n) && q > best_q) best = a, best_q = q;
    }
    return best;
}

static inline int32_t clampi(int32_t x, int32_t lo, int32_t hi) { return x < lo ? lo : (x > hi ? hi : x); }
/* floor of a float within [-2^30, 2^30] (rectangle ends; NaN gives lo's side: caller clamps) */
static inline int32_t floor_i(float x) {
    x = x < -1e9f ? -1e9f : (x > 1e9f ? 1e9f : x);
    int32_t i = (int32_t)x;
    return (float)i > x ? i - 1 : i;
}


/* The side planes of a packet of rays from one point O (camera rays, rays from a point light):
 * every ray's slopes d_U / d_K and d_V / d_K lie in [su0, su1] x [sv0, sv1] (widened against
 * rounding), so each ray's points P (t >= 0; tnear >= 0 for all) have sg * ((P_U - O_U) - su1 (P_K - O_K)) <= 0, and
 * so on for the other three. A triangle with its three vertices beyond one plane meets no ray
 * (Wald et al. 2006, sec. 4.3: the packet's frustum culls triangles before the rays' tests). */
typedef struct pk_frustum {
    bool on;
    int K, U, V;
    float o[3], sg;
    float su0, su1, sv0, sv1;
} pk_frustum;

/* Plane value of one vertex against slope s (positive: beyond the plane), with its rounding
 * margin taken off, so a vertex within rounding of the plane never counts as beyond it. */
static inline vf4 pk_beyond(vf4 du, vf4 dk, float s, float sg) {
    vf4 v = (du - vf4_splat(s) * dk) * vf4_splat(sg);
    return v - vf4_splat(1e-5f) * (vf4_abs(du) + vf4_abs(vf4_splat(s) * dk));
}

/* True when no ray of the packet can hit any triangle of block b. */
static inline bool pk_culled(const pk_frustum *f, const tri4 *tr) {
    vi4 b1 = vi4_splat(-1), b2 = b1, b3 = b1, b4 = b1;
    for (int i = 0; i < 3; i++) {
        vf4 dk = vf4_load(tr->v[3 * i + f->K]) - vf4_splat(f->o[f->K]);
        vf4 du = vf4_load(tr->v[3 * i + f->U]) - vf4_splat(f->o[f->U]);
        vf4 dv = vf4_load(tr->v[3 * i + f->V]) - vf4_splat(f->o[f->V]);
        vf4 z = vf4_splat(0.0f);
        b1 &= pk_beyond(du, dk, f->su1, f->sg) > z;
        b2 &= pk_beyond(du, dk, f->su0, -f->sg) > z; /* sg (su0 dk - du) > 0 */
        b3 &= pk_beyond(dv, dk, f->sv1, f->sg) > z;
        b4 &= pk_beyond(dv, dk, f->sv0, -f->sg) > z;
    }
    return vi4_movemask(b1 | b2 | b3 | b4) == 0xF;
}

/* The blocks of a voxel against the rays of mask rays (each its own mailbox); with any, returns
 * the rays that hit (they stop testing), else 0. */
static inline uint32_t test_voxel(const accel_built *s, const alt_ray *r, alt_hit *h, const uint32_t *ids,
                                  const uint32_t *first, uint32_t voxel, uint32_t rays, uint32_t (*mb)[GRID_MAILBOX],
                                  bool any, const pk_frustum *f) {
    uint32_t hit = 0;
    for (uint32_t b = first[voxel], e = first[voxel + 1]; b < e && rays; b++) {
        if (f->on && pk_culled(f, &s->blocks[b])) continue;
        for (uint32_t m = rays; m; m &= m - 1) {
            uint32_t i = simd_ctz(m);
            if (mailbox_all_seen(mb[i], &ids[4 * b])) continue;
            if (alt_leaf(s->blocks, &r[i], b, 1, &h[i], any)) hit |= 1u << i, rays &= ~(1u << i);
        }
    }
    return hit;
}

static bool grid_packet(const accel_built *s, const alt_ray *r, alt_hit *h, uint32_t live, int width, bool any,
                        uint32_t *occluded) {
    (void)width;
    /* fewer rays than 8 (the 2x2 quads the n x n packets of these kernels are cut into): the
     * setup costs more than the shared walk saves (bunny 16x16: 7.9 against 10.3 Mrays/s of
     * single rays), so they go ray by ray */
    if (simd_popcount(live) < 8 || !s->block_count) return false;
    const grid_layout *g = s->nodes;
    /* rays from one point (camera rays) or nearly: else the rectangles of a slice lie apart and
     * their union holds many voxels no ray enters; such packets go ray by ray */
    float olo[3] = {INFINITY, INFINITY, INFINITY}, ohi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t m = live; m; m &= m - 1)
        for (int a = 0; a < 3; a++) {
            float o = r[simd_ctz(m)].org[a];
            olo[a] = minf(olo[a], o), ohi[a] = maxf(ohi[a], o);
        }
    for (int a = 0; a < 3; a++)
        if (!((ohi[a] - olo[a]) * g->inv_cell[a] <= PK_SPREAD)) return false;
    int K = pk_axis(g, r, live);
    if (K < 0) return false;
    const int U = (K + 1) % 3, V = (K + 2) % 3;
    const bool kpos = r[simd_ctz(live)].dir[K] > 0.0f;
    const int32_t resK = g->res[K], resU = g->res[U], resV = g->res[V];
    const uint32_t *first = layout_first(g), *ids = layout_ids(g);
    const int32_t stride[3] = {1, g->res[0], g->res[0] * g->res[1]};
    RP_ALIGN(64) grid_pk p;
    uint32_t mb[PK_MAX][GRID_MAILBOX];
    uint32_t act = 0; /* rays still walking */
    float smin = INFINITY;
    int32_t upos = 0, vpos = 0, n = 0;
    for (uint32_t m = live; m; m &= m - 1) {
        uint32_t i = simd_ctz(m);
        const alt_ray *ri = &r[i];
        float t0, t1;
        if (!alt_ray_box(ri, s->bounds, h[i].t, &t0, &t1)) continue;
        float ck = (ri->org[K] - g->lo[K]) * g->inv_cell[K], dk = ri->dir[K] * g->inv_cell[K];
        if (!kpos) ck = (float)resK - ck, dk = -dk;
        float cu = (ri->org[U] - g->lo[U]) * g->inv_cell[U], dut = ri->dir[U] * g->inv_cell[U];
        float cv = (ri->org[V] - g->lo[V]) * g->inv_cell[V], dvt = ri->dir[V] * g->inv_cell[V];
        p.ka[i] = ck, p.dk[i] = dk, p.t1[i] = t1;
        p.du[i] = dut / dk, p.dv[i] = dvt / dk;
        p.ua[i] = cu - p.du[i] * ck, p.va[i] = cv - p.dv[i] * ck;
        p.s_lo[i] = ck + dk * t0 - PK_EPS;
        p.s_hi[i] = ck + dk * walk_end(t1, h[i].t) + PK_EPS;
        if (!(p.s_lo[i] <= p.s_hi[i])) continue; /* NaN too: a bad ray misses */
        for (int q = 0; q < GRID_MAILBOX; q++) mb[i][q] = UINT32_MAX;
        smin = minf(smin, p.s_lo[i]);
        upos += p.du[i] >= 0.0f, vpos += p.dv[i] >= 0.0f, n++;
        act |= 1u << i;
    }
    pk_frustum fr = {.on = act != 0, .K = K, .U = U, .V = V, .sg = kpos ? 1.0f : -1.0f,
                     .su0 = INFINITY, .su1 = -INFINITY, .sv0 = INFINITY, .sv1 = -INFINITY};
    if (act) {
        const alt_ray *r0 = &r[simd_ctz(act)];
        for (int a = 0; a < 3; a++) fr.o[a] = r0->org[a];
    }
    for (uint32_t m = act; m; m &= m - 1) {
        const alt_ray *ri = &r[simd_ctz(m)];
        /* (t >= 0 only: a ray's points behind O lie outside the planes) */
        fr.on &= ri->org[0] == fr.o[0] && ri->org[1] == fr.o[1] && ri->org[2] == fr.o[2] && ri->tnear >= 0.0f;
        float su = ri->dir[U] / ri->dir[K], sv = ri->dir[V] / ri->dir[K];
        fr.su0 = minf(fr.su0, su), fr.su1 = maxf(fr.su1, su), fr.sv0 = minf(fr.sv0, sv), fr.sv1 = maxf(fr.sv1, sv);
    }
    /* widened by more than the slopes' rounding */
    fr.su0 -= 1e-4f * (1.0f + fabsf(fr.su0)), fr.su1 += 1e-4f * (1.0f + fabsf(fr.su1));
    fr.sv0 -= 1e-4f * (1.0f + fabsf(fr.sv0)), fr.sv1 += 1e-4f * (1.0f + fabsf(fr.sv1));
    fr.on &= isfinite(fr.su0 + fr.su1 + fr.sv0 + fr.sv1);
    /* the octant of the clear cubes: towards +K in the walk's order, +u / +v as most rays go */
    const bool cu_pos = 2 * upos >= n, cv_pos = 2 * vpos >= n;
    const int octant = (kpos << K) | (cu_pos << U) | (cv_pos << V);
    const uint8_t *clear = layout_clear(g, octant);
    int32_t j = clampi(floor_i(smin), 0, resK);
    uint32_t occ = 0;
    while (act && j < resK) {
        /* each ray's rectangle in slice j, and their union */
        int32_t bu0 = INT32_MAX, bu1 = INT32_MIN, bv0 = INT32_MAX, bv1 = INT32_MIN;
        uint32_t in = 0; /* rays in this slice */
        int32_t area = 0; /* of their rectangles */
        for (uint32_t m = act; m; m &= m - 1) {
            uint32_t i = simd_ctz(m);
            float a = maxf((float)j, p.s_lo[i]), b = minf((float)(j + 1), p.s_hi[i]);
            if (!(a <= b)) continue;
            float ua = p.ua[i] + p.du[i] * a, ub = p.ua[i] + p.du[i] * b;
            float va = p.va[i] + p.dv[i] * a, vb = p.va[i] + p.dv[i] * b;
            p.u0[i] = clampi(floor_i(minf(ua, ub) - PK_EPS), 0, resU - 1);
            p.u1[i] = clampi(floor_i(maxf(ua, ub) + PK_EPS), 0, resU - 1);
            p.v0[i] = clampi(floor_i(minf(va, vb) - PK_EPS), 0, resV - 1);
            p.v1[i] = clampi(floor_i(maxf(va, vb) + PK_EPS), 0, resV - 1);
            area += (p.u1[i] - p.u0[i] + 1) * (p.v1[i] - p.v0[i] + 1);
            bu0 = p.u0[i] < bu0 ? p.u0[i] : bu0, bu1 = p.u1[i] > bu1 ? p.u1[i] : bu1;
            bv0 = p.v0[i] < bv0 ? p.v0[i] : bv0, bv1 = p.v1[i] > bv1 ? p.v1[i] : bv1;
            in |= 1u << i;
        }
        const int32_t kc = kpos ? j : resK - 1 - j; /* the slice's voxel index along K */
        int32_t next = j + 1;
        if (in) {
            /* a clear cube at the union's corner that holds the whole union: every ray stays in
             * it, so in empty space, up to the slice where the first may leave it */
            int32_t cu = cu_pos ? bu0 : bu1, cv = cv_pos ? bv0 : bv1;
            int32_t side = clear[kc * stride[K] + cu * stride[U] + cv * stride[V]];
            if (side > bu1 - bu0 && side > bv1 - bv0) {
                float lim = (float)(j + side);
                float ulo = (float)(cu_pos ? cu : cu + 1 - side), uhi = (float)(cu_pos ? cu + side : cu + 1);
                float vlo = (float)(cv_pos ? cv : cv + 1 - side), vhi = (float)(cv_pos ? cv + side : cv + 1);
                for (uint32_t m = act; m; m &= m - 1) {
                    uint32_t i = simd_ctz(m);
                    if (!(in >> i & 1u)) { /* not in the cube yet: its own entry bounds the jump */
                        lim = minf(lim, p.s_lo[i]);
                        continue;
                    }
                    float su = p.du[i] > 0.0f ? (uhi - p.ua[i]) / p.du[i] : p.du[i] < 0.0f ? (ulo - p.ua[i]) / p.du[i] : INFINITY;
                    float sv = p.dv[i] > 0.0f ? (vhi - p.va[i]) / p.dv[i] : p.dv[i] < 0.0f ? (vlo - p.va[i]) / p.dv[i] : INFINITY;
                    lim = minf(lim, minf(su, sv) - PK_EPS);
                }
                int32_t jl = floor_i(lim);
                next = jl > next ? jl : next;
            } else if ((bu1 - bu0 + 1) * (bv1 - bv0 + 1) > 2 * area) {
                /* rays apart (silhouettes, their ends spread): each its own voxels */
                for (uint32_t m = in; m; m &= m - 1) {
                    uint32_t i = simd_ctz(m);
                    for (int32_t cvv = p.v0[i]; cvv <= p.v1[i]; cvv++)
                        for (int32_t cuu = p.u0[i]; cuu <= p.u1[i]; cuu++) {
                            uint32_t voxel = (uint32_t)(kc * stride[K] + cuu * stride[U] + cvv * stride[V]);
                            if (clear[voxel]) continue;
                            if (test_voxel(s, r, h, ids, first, voxel, 1u << i, mb, any, &fr)) {
                                occ |= 1u << i, act &= ~(1u << i);
                                goto next_ray;
                            }
                        }
                next_ray:;
                }
            } else {
                for (int32_t cvv = bv0; cvv <= bv1; cvv++)
                    for (int32_t cuu = bu0; cuu <= bu1; cuu++) {
                        uint32_t voxel = (uint32_t)(kc * stride[K] + cuu * stride[U] + cvv * stride[V]);
                        if (clear[voxel]) continue;
                        uint32_t rays = 0;
                        for (uint32_t m = in; m; m &= m - 1) {
                            uint32_t i = simd_ctz(m);
                            rays |= (uint32_t)(cuu >= p.u0[i] && cuu <= p.u1[i] && cvv >= p.v0[i] && cvv <= p.v1[i]) << i;
                        }
                        uint32_t hit = test_voxel(s, r, h, ids, first, voxel, rays, mb, any, &fr);
                        occ |= hit, in &= ~hit, act &= ~hit;
                    }
            }
        }
        /* rays whose end lies before the next slice are done */
        for (uint32_t m = act; m; m &= m - 1) {
            uint32_t i = simd_ctz(m);
            p.s_hi[i] = p.ka[i] + p.dk[i] * walk_end(p.t1[i], h[i].t) + PK_EPS;
            if (!(p.s_hi[i] >= (float)next)) act &= ~(1u << i);
        }
        j = next;
    }
    *occluded = occ;
    return true;
}

ALT_KERNELS(grid_accel, grid_trav, grid_packet, NULL)

RP_HIDDEN const accel_ops accel_grid = {"grid", grid_accel_build, &grid_accel_kernels};
