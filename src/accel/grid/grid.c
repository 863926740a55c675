/* Uniform grid: build (resolution rule, CSR voxel lists) and 3D-DDA traversal. See grid.h. */
#include "accel/grid/grid.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "core/core.h"

grid_desc grid_desc_defaults(const grid_desc *desc) {
    grid_desc d = desc ? *desc : (grid_desc){0};
    if (!(d.density > 0.0f)) d.density = 4.0f;
    if (d.min_dim < 0) d.min_dim = 0;
    if (d.max_voxels <= 0) d.max_voxels = 1 << 24;
    return d;
}

static bool tri_finite(const float *v) {
    float s = 0.0f;
    for (int i = 0; i < 9; i++) s += v[i] * 0.0f;
    return s == 0.0f;
}

/* Resolution: the paper's (cubic voxels, min_dim along the shortest side) or Cleary-Wyvill's
 * (density * n voxels of cubic shape), capped at max_voxels by scaling all sides alike. */
static void pick_resolution(const grid_desc *d, const double ext[3], uint32_t n, int res[3]) {
    double emin = fmin(ext[0], fmin(ext[1], ext[2])), vol = ext[0] * ext[1] * ext[2];
    double per_len; /* voxels per unit length */
    if (d->min_dim > 0)
        per_len = (double)d->min_dim / emin;
    else
        per_len = cbrt((double)d->density * (double)(n ? n : 1) / vol);
    for (;;) {
        double total = 1.0;
        for (int a = 0; a < 3; a++) {
            double r = ceil(ext[a] * per_len - 1e-9);
            res[a] = r < 1.0 ? 1 : (r > 4096.0 ? 4096 : (int)r);
            total *= res[a];
        }
        if (total <= (double)d->max_voxels) return;
        per_len *= 0.95 * cbrt((double)d->max_voxels / total);
    }
}

/* Conservative triangle / voxel overlap: the triangle's plane passes within the voxel's box
 * (enlarged by margin). The boxes already overlap. Done in double with the margin so float
 * rounding of the hit point never loses a voxel. */
static bool plane_overlaps(const double n[3], double d, const double c[3], const double h[3]) {
    double s = n[0] * c[0] + n[1] * c[1] + n[2] * c[2] - d;
    double r = h[0] * fabs(n[0]) + h[1] * fabs(n[1]) + h[2] * fabs(n[2]);
    return fabs(s) <= r;
}

/* The nine edge x axis separating axes of the triangle-box test (Akenine-Moller 2001): false
 * when one separates triangle v (three points) from the box of centre c and half sides h. */
static bool edges_overlap(const float *v, const double c[3], const double h[3]) {
    double p[3][3];
    for (int i = 0; i < 3; i++)
        for (int a = 0; a < 3; a++) p[i][a] = (double)v[3 * i + a] - c[a];
    for (int e = 0; e < 3; e++) {
        const double *a0 = p[e], *a1 = p[(e + 1) % 3];
        double ed[3] = {a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2]};
        for (int k = 0; k < 3; k++) {
            /* axis = unit vector k x edge */
            double ax[3] = {0.0, 0.0, 0.0};
            int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
            ax[k1] = -ed[k2], ax[k2] = ed[k1];
            double mn = INFINITY, mx = -INFINITY;
            for (int i = 0; i < 3; i++) {
                double d = ax[0] * p[i][0] + ax[1] * p[i][1] + ax[2] * p[i][2];
                mn = fmin(mn, d), mx = fmax(mx, d);
            }
            double rad = h[0] * fabs(ax[0]) + h[1] * fabs(ax[1]) + h[2] * fabs(ax[2]);
            if (mn > rad || mx < -rad) return false;
        }
    }
    return true;
}

/* Counts (fill == false) or writes (fill == true) the voxels of each triangle. */
static void scan(grid *g, double margin, bool fill, uint32_t *cursor, bool sat) {
    for (uint32_t i = 0; i < g->tri_count; i++) {
        const float *v = g->tris[i].v;
        int lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            double mn = fmin(v[a], fmin(v[3 + a], v[6 + a])) - margin, mx = fmax(v[a], fmax(v[3 + a], v[6 + a])) + margin;
            double l = floor((mn - g->lo[a]) / g->cell[a]), h = floor((mx - g->lo[a]) / g->cell[a]);
            lo[a] = l < 0.0 ? 0 : (l > g->res[a] - 1 ? g->res[a] - 1 : (int)l);
            hi[a] = h < 0.0 ? 0 : (h > g->res[a] - 1 ? g->res[a] - 1 : (int)h);
        }
        double e1[3], e2[3], n[3];
        for (int a = 0; a < 3; a++) e1[a] = (double)v[3 + a] - v[a], e2[a] = (double)v[6 + a] - v[a];
        n[0] = e1[1] * e2[2] - e1[2] * e2[1];
        n[1] = e1[2] * e2[0] - e1[0] * e2[2];
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double nd = n[0] * v[0] + n[1] * v[1] + n[2] * v[2];
        bool flat_test = isfinite(nd) && (n[0] != 0.0 || n[1] != 0.0 || n[2] != 0.0);
        bool single = lo[0] == hi[0] && lo[1] == hi[1] && lo[2] == hi[2];
        double h[3] = {0.5 * g->cell[0] + margin, 0.5 * g->cell[1] + margin, 0.5 * g->cell[2] + margin};
        for (int z = lo[2]; z <= hi[2]; z++)
            for (int y = lo[1]; y <= hi[1]; y++)
                for (int x = lo[0]; x <= hi[0]; x++) {
                    if (!single && flat_test) {
                        double c[3] = {g->lo[0] + (x + 0.5) * g->cell[0], g->lo[1] + (y + 0.5) * g->cell[1],
                                       g->lo[2] + (z + 0.5) * g->cell[2]};
                        if (!plane_overlaps(n, nd, c, h)) continue;
                        if (sat && !edges_overlap(v, c, h)) continue;
                    }
                    uint32_t c = ((uint32_t)z * (uint32_t)g->res[1] + (uint32_t)y) * (uint32_t)g->res[0] + (uint32_t)x;
                    if (fill)
                        g->items[cursor[c]++] = i;
                    else
                        g->offsets[c + 1]++;
                }
    }
    /* primitives: every voxel their box (with the margin) overlaps */
    for (uint32_t k = 0; k < g->prim_count; k++) {
        const float *b = &g->prim_box[6 * k];
        int lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            double l = floor((b[a] - margin - g->lo[a]) / g->cell[a]), h = floor((b[3 + a] + margin - g->lo[a]) / g->cell[a]);
            lo[a] = l < 0.0 ? 0 : (l > g->res[a] - 1 ? g->res[a] - 1 : (int)l);
            hi[a] = h < 0.0 ? 0 : (h > g->res[a] - 1 ? g->res[a] - 1 : (int)h);
        }
        for (int z = lo[2]; z <= hi[2]; z++)
            for (int y = lo[1]; y <= hi[1]; y++)
                for (int x = lo[0]; x <= hi[0]; x++) {
                    uint32_t c = ((uint32_t)z * (uint32_t)g->res[1] + (uint32_t)y) * (uint32_t)g->res[0] + (uint32_t)x;
                    if (fill)
                        g->items[cursor[c]++] = g->tri_count + k;
                    else
                        g->offsets[c + 1]++;
                }
    }
}

static grid *build_lists(grid *g, const grid_desc *desc_in);

/* The grid of the tri4 blocks' triangles (their geometries' masks: geom_masks, per geom_id) and of
 * the primitives of g->prims / g->prim_box (set by the caller; g allocated, its allocator set). */
static grid *build(grid *g, const tri4 *blocks, size_t block_count, const uint32_t *geom_masks,
                   const grid_desc *desc_in) {
    const sys_allocator *alloc = &g->alloc;
    size_t n = 0;
    for (size_t b = 0; b < block_count; b++) n += (size_t)simd_popcount(tri4_lanes(&blocks[b]));
    g->tri_capacity = n ? n : 1;
    g->tris = sys_alloc(alloc, g->tri_capacity * sizeof(grid_tri));
    if (!g->tris) goto fail;
    for (size_t b = 0; b < block_count; b++)
        for (uint32_t lanes = tri4_lanes(&blocks[b]); lanes; lanes &= lanes - 1) {
            uint32_t l = simd_ctz(lanes);
            grid_tri t = {.geom = blocks[b].geom[l], .prim = blocks[b].prim[l], .mask = geom_masks[blocks[b].geom[l]]};
            if (!t.mask) continue; /* never hit */
            for (int k = 0; k < 9; k++) t.v[k] = blocks[b].v[k][l];
            if (!tri_finite(t.v)) continue; /* the BVH never hits these either */
            g->tris[g->tri_count++] = t;
        }
    return build_lists(g, desc_in);
fail:
    grid_free(g);
    return NULL;
}

/* The voxel lists of g->tris (finite triangles) and of the primitives of g->prims / g->prim_box. */
static grid *build_lists(grid *g, const grid_desc *desc_in) {
    double t0 = sys_seconds();
    grid_desc desc = grid_desc_defaults(desc_in);
    const sys_allocator *alloc = &g->alloc;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < g->tri_count; i++) {
        const float *v = g->tris[i].v;
        for (int k = 0; k < 9; k++) lo[k % 3] = fmin(lo[k % 3], v[k]), hi[k % 3] = fmax(hi[k % 3], v[k]);
    }
    for (uint32_t k = 0; k < g->prim_count; k++)
        for (int a = 0; a < 3; a++)
            lo[a] = fmin(lo[a], g->prim_box[6 * k + a]), hi[a] = fmax(hi[a], g->prim_box[6 * k + 3 + a]);
    if (g->tri_count + g->prim_count == 0)
        for (int a = 0; a < 3; a++) lo[a] = 0.0, hi[a] = 1.0;
    /* margin: well above the rounding of a hit point's coordinates, so the voxel the DDA is in
     * when a hit's distance is reached always lists the triangle: 2^-16 of the scene's extent plus
     * 2^-20 (16 float spacings) of its largest coordinate. It was 2^-16 of the largest coordinate:
     * the bunny moved 1e4 from the origin grew every triangle's box by 0.15, the bunny's size, and
     * listed each in tens of thousands of voxels (a build that did not end in 10 minutes). */
    double big = 0.0, ext[3];
    for (int a = 0; a < 3; a++) big = fmax(big, fmax(fabs(lo[a]), fabs(hi[a])));
    double emax = 0.0;
    for (int a = 0; a < 3; a++) emax = fmax(emax, hi[a] - lo[a]);
    double margin = emax * 0x1p-16 + big * 0x1p-20 + 1e-30;
    for (int a = 0; a < 3; a++) {
        lo[a] -= margin, hi[a] += margin;
        ext[a] = hi[a] - lo[a];
        if (ext[a] < emax * 1e-3) { /* a flat scene: a thin slab of voxels, not zero-width ones */
            double grow = 0.5 * (emax * 1e-3 - ext[a]);
            lo[a] -= grow, hi[a] += grow, ext[a] = hi[a] - lo[a];
        }
    }
    pick_resolution(&desc, ext, g->tri_count + g->prim_count, g->res);
    for (int a = 0; a < 3; a++) {
        g->lo[a] = (float)lo[a], g->hi[a] = (float)hi[a];
        g->cell[a] = (float)(ext[a] / g->res[a]);
        g->hi[a] = g->lo[a] + g->cell[a] * (float)g->res[a];
        if (g->hi[a] < (float)hi[a]) g->hi[a] = (float)hi[a];
        g->inv_cell[a] = 1.0f / g->cell[a];
    }
    g->voxel_count = (uint32_t)g->res[0] * (uint32_t)g->res[1] * (uint32_t)g->res[2];
    g->offsets = sys_calloc(alloc, ((size_t)g->voxel_count + 1) * sizeof(uint32_t));
    if (!g->offsets) goto fail;
    scan(g, margin, false, NULL, desc.sat);
    for (uint32_t c = 0; c < g->voxel_count; c++) {
        g->nonempty += g->offsets[c + 1] != 0;
        g->offsets[c + 1] += g->offsets[c];
    }
    g->item_count = g->offsets[g->voxel_count];
    g->items = sys_alloc(alloc, (g->item_count ? g->item_count : 1) * sizeof(uint32_t));
    uint32_t *cursor = sys_alloc(alloc, ((size_t)g->voxel_count + 1) * sizeof(uint32_t));
    if (!g->items || !cursor) {
        sys_free(alloc, cursor, ((size_t)g->voxel_count + 1) * sizeof(uint32_t));
        goto fail;
    }
    memcpy(cursor, g->offsets, ((size_t)g->voxel_count + 1) * sizeof(uint32_t));
    scan(g, margin, true, cursor, desc.sat);
    sys_free(alloc, cursor, ((size_t)g->voxel_count + 1) * sizeof(uint32_t));
    g->build_ms = (sys_seconds() - t0) * 1e3;
    return g;
fail:
    grid_free(g);
    return NULL;
}

grid *grid_build_scene(rp_scene *scene, const grid_desc *desc, char *err, size_t err_size) {
    if (!scene || !scene->committed) {
        snprintf(err, err_size, "grid: the scene is not committed");
        return NULL;
    }
    const sys_allocator *alloc = &scene->device->alloc;
    grid *g = sys_calloc(alloc, sizeof(grid));
    if (!g) goto oom;
    g->alloc = *alloc;
    g->acc = &scene->accel;
    size_t np = scene->prim_count;
    if (np) {
        g->prims = sys_alloc(alloc, np * sizeof(prim_ref));
        g->prim_box = sys_alloc(alloc, np * 6 * sizeof(float));
        if (!g->prims || !g->prim_box) goto oom;
        g->prim_count = (uint32_t)np;
    }
    /* the primitives' boxes as the commit gathered them (spheres: centre +- radius; user: its
     * bounds callback), in the order of the core's list */
    for (size_t k = 0; k < np; k++) {
        prim_ref r = scene->prims[k];
        const rp_geometry *geo = scene->geoms[r.geom];
        float *b = &g->prim_box[6 * k];
        g->prims[k] = r;
        if (geo->type == RP_GEOMETRY_SPHERE) {
            const float *c = geom_item(&geo->buffers[RP_BUFFER_VERTEX], r.prim);
            for (int a = 0; a < 3; a++) b[a] = c[a] - c[3], b[3 + a] = c[a] + c[3];
        } else if (geo->type == RP_GEOMETRY_USER) {
            rp_bounds ub = {0};
            geo->user_bounds(geo->user, r.prim, &ub);
            b[0] = ub.lower_x, b[1] = ub.lower_y, b[2] = ub.lower_z, b[3] = ub.upper_x, b[4] = ub.upper_y, b[5] = ub.upper_z;
        } else {
            snprintf(err, err_size, "grid: the scene holds instances (an animated scene not built flat?); the grid "
                                    "holds triangles, spheres and user primitives of one level");
            grid_free(g);
            return NULL;
        }
    }
    /* the blocks without the padding block past their end */
    size_t blocks = scene->tri_block_count ? scene->tri_block_count - 1 : 0;
    if (build(g, scene->tris, blocks, scene->accel.geom_masks, desc)) return g;
    g = NULL; /* build freed it */
oom:
    grid_free(g);
    snprintf(err, err_size, "grid: out of memory");
    return NULL;
}

grid *grid_build_tris(const sys_allocator *alloc, const grid_tri *tris, uint32_t count, const grid_desc *desc) {
    grid *g = sys_calloc(alloc, sizeof(grid));
    if (!g) return NULL;
    g->alloc = *alloc;
    g->tri_capacity = count ? count : 1;
    g->tris = sys_alloc(alloc, g->tri_capacity * sizeof(grid_tri));
    if (!g->tris) {
        grid_free(g);
        return NULL;
    }
    for (uint32_t i = 0; i < count; i++)
        if (tri_finite(tris[i].v)) g->tris[g->tri_count++] = tris[i];
    return build_lists(g, desc);
}

grid *grid_build_tri4(const sys_allocator *alloc, const tri4 *blocks, size_t block_count, const uint32_t *geom_masks,
                      const grid_desc *desc) {
    grid *g = sys_calloc(alloc, sizeof(grid));
    if (!g) return NULL;
    g->alloc = *alloc;
    return build(g, blocks, block_count, geom_masks, desc);
}

size_t grid_bytes(const grid *g) {
    if (!g) return 0;
    return sizeof(grid) + ((size_t)g->voxel_count + 1) * sizeof(uint32_t) + g->item_count * sizeof(uint32_t) +
           (size_t)g->tri_count * sizeof(grid_tri) + (size_t)g->prim_count * (sizeof(prim_ref) + 6 * sizeof(float));
}

void grid_free(grid *g) {
    if (!g) return;
    sys_allocator a = g->alloc;
    if (g->offsets) sys_free(&a, g->offsets, ((size_t)g->voxel_count + 1) * sizeof(uint32_t));
    if (g->items) sys_free(&a, g->items, (g->item_count ? g->item_count : 1) * sizeof(uint32_t));
    if (g->tris) sys_free(&a, g->tris, g->tri_capacity * sizeof(grid_tri));
    if (g->prims) sys_free(&a, g->prims, (size_t)g->prim_count * sizeof(prim_ref));
    if (g->prim_box) sys_free(&a, g->prim_box, (size_t)g->prim_count * 6 * sizeof(float));
    sys_free(&a, g, sizeof(grid));
}

/* ---- traversal ----------------------------------------------------------------------------- */

bool grid_walk_setup(const grid *g, const rp_ray *ray, grid_walk *w) {
    const float o[3] = {ray->org_x, ray->org_y, ray->org_z}, d[3] = {ray->dir_x, ray->dir_y, ray->dir_z};
    float t0 = ray->tnear, t1 = ray->tfar;
    if (!(t0 <= t1) || g->tri_count + g->prim_count == 0) return false;
    for (int a = 0; a < 3; a++) {
        /* the kernels' safe reciprocal: no 0 * inf */
        float dd = fabsf(d[a]) < 1e-18f ? copysignf(1e-18f, d[a]) : d[a];
        float r = 1.0f / dd;
        float tn = (g->lo[a] - o[a]) * r, tf = (g->hi[a] - o[a]) * r;
        if (tn > tf) {
            float s = tn;
            tn = tf, tf = s;
        }
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
        w->org[a] = o[a], w->dir[a] = d[a], w->rcp[a] = r;
        w->step[a] = r >= 0.0f ? 1 : -1;
    }
    /* the box has a margin around the triangles, so rounding of the clip loses no hit */
    if (!(t0 <= t1)) return false;
    w->t_end = t1;
    for (int a = 0; a < 3; a++) {
        float p = o[a] + d[a] * t0;
        float c = floorf((p - g->lo[a]) * g->inv_cell[a]);
        w->cell[a] = !(c >= 0.0f) ? 0 : (c > (float)(g->res[a] - 1) ? g->res[a] - 1 : (int)c);
    }
    return true;
}

static inline float axis_exit(const grid *g, const grid_walk *w, int a) {
    float plane = g->lo[a] + (float)(w->cell[a] + (w->step[a] > 0)) * g->cell[a];
    return (plane - w->org[a]) * w->rcp[a];
}

float grid_walk_exit(const grid *g, const grid_walk *w) {
    float tx = axis_exit(g, w, 0), ty = axis_exit(g, w, 1), tz = axis_exit(g, w, 2);
    float t = tx < ty ? tx : ty;
    return t < tz ? t : tz;
}

bool grid_walk_step(const grid *g, grid_walk *w, float tfar) {
    float tx = axis_exit(g, w, 0), ty = axis_exit(g, w, 1), tz = axis_exit(g, w, 2);
    int a = tx <= ty ? (tx <= tz ? 0 : 2) : (ty <= tz ? 1 : 2);
    float t = a == 0 ? tx : (a == 1 ? ty : tz);
    float end = tfar < w->t_end ? tfar : w->t_end;
    /* the hit so far (or the segment's end) lies within the voxel: nothing nearer is further on */
    if (!(t < end)) return false;
    w->cell[a] += w->step[a];
    return w->cell[a] >= 0 && w->cell[a] < g->res[a];
}

/* A primitive through the core's callback, over [tnear, the hit so far]: the BVH's leaves test
 * primitives after the triangles with tfar at the triangles' hit, so a primitive wins a tie. */
static bool prim_test(const grid *g, uint32_t k, const rp_ray *ray, grid_hit *h) {
    rp_ray r = *ray;
    r.tfar = h->t;
    rp_hit hit = {.geom_id = RP_INVALID_ID};
    if (!g->acc->prim_intersect(g->acc, g->prims[k], &r, &hit)) return false;
    h->t = r.tfar, h->u = hit.u, h->v = hit.v, h->tri = g->tri_count + k;
    h->ng[0] = hit.Ng_x, h->ng[1] = hit.Ng_y, h->ng[2] = hit.Ng_z;
    return true;
}

bool grid_test(const grid *g, uint32_t i, const rp_ray *ray, grid_hit *h) {
    if (i >= g->tri_count) return prim_test(g, i - g->tri_count, ray, h);
    const grid_tri *tr = &g->tris[i];
    if (!(tr->mask & ray->mask)) return false;
    const float o[3] = {ray->org_x, ray->org_y, ray->org_z}, d[3] = {ray->dir_x, ray->dir_y, ray->dir_z};
    float t, u, v;
    if (!tri_intersect_ref(o, d, ray->tnear, h->t, tr->v, tr->v + 3, tr->v + 6, &t, &u, &v)) return false;
    /* t <= h->t here: nearer, or a tie won by the lower (geom, prim) as in the BVH kernels */
    if (t < h->t || h->tri == UINT32_MAX ||
        (h->tri < g->tri_count && hit_key_less(tr->geom, tr->prim, g->tris[h->tri].geom, g->tris[h->tri].prim))) {
        h->t = t, h->u = u, h->v = v, h->tri = i;
    }
    return true;
}

void grid_hit_write(const grid *g, const grid_hit *h, rp_rayhit *rh) {
    if (h->tri == UINT32_MAX) return;
    if (h->tri >= g->tri_count) {
        prim_ref r = g->prims[h->tri - g->tri_count];
        rh->ray.tfar = h->t;
        rh->hit.u = h->u, rh->hit.v = h->v;
        rh->hit.Ng_x = h->ng[0], rh->hit.Ng_y = h->ng[1], rh->hit.Ng_z = h->ng[2];
        rh->hit.geom_id = r.geom, rh->hit.prim_id = r.prim, rh->hit.inst_id = RP_INVALID_ID;
        return;
    }
    const grid_tri *tr = &g->tris[h->tri];
    float e1[3], e2[3];
    for (int a = 0; a < 3; a++) e1[a] = tr->v[3 + a] - tr->v[a], e2[a] = tr->v[6 + a] - tr->v[a];
    rh->ray.tfar = h->t;
    rh->hit.u = h->u, rh->hit.v = h->v;
    rh->hit.Ng_x = e1[1] * e2[2] - e1[2] * e2[1];
    rh->hit.Ng_y = e1[2] * e2[0] - e1[0] * e2[2];
    rh->hit.Ng_z = e1[0] * e2[1] - e1[1] * e2[0];
    rh->hit.geom_id = tr->geom, rh->hit.prim_id = tr->prim;
    rh->hit.inst_id = RP_INVALID_ID;
}

/* One loop for closest and any hit; `any` is a constant at both call sites. */
static inline bool walk(const grid *g, const rp_ray *ray, grid_hit *h, bool any, grid_work *work) {
    grid_walk w;
    if (!grid_walk_setup(g, ray, &w)) return false;
    uint32_t mb[GRID_MAILBOX];
    for (int i = 0; i < GRID_MAILBOX; i++) mb[i] = UINT32_MAX;
    uint64_t voxels = 0, tests = 0;
    bool found = false;
    do {
        voxels++;
        uint32_t c = grid_walk_voxel(g, &w);
        for (uint32_t k = g->offsets[c]; k < g->offsets[c + 1]; k++) {
            uint32_t i = g->items[k];
            if (grid_mailbox_seen(mb, i)) continue;
            tests++;
            if (grid_test(g, i, ray, h)) {
                found = true;
                if (any) goto done;
            }
        }
    } while (grid_walk_step(g, &w, h->t));
done:
    if (work) work->voxels += voxels, work->tests += tests;
    return found;
}

void grid_intersect1(const grid *g, rp_rayhit *rh, grid_work *work) {
    if (!(rh->ray.tnear <= rh->ray.tfar)) return;
    grid_hit h = {.t = rh->ray.tfar, .tri = UINT32_MAX};
    if (walk(g, &rh->ray, &h, false, work)) grid_hit_write(g, &h, rh);
}

void grid_occluded1(const grid *g, rp_ray *ray, grid_work *work) {
    if (!(ray->tnear <= ray->tfar)) return;
    grid_hit h = {.t = ray->tfar, .tri = UINT32_MAX};
    if (walk(g, ray, &h, true, work)) ray->tfar = -INFINITY;
}
