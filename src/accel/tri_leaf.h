/* Single rays through the tri4 leaves of the kd-tree and the BIH: the setup and the leaf test of
 * the BVH's kernels (src/traverse/kernels.inc) - dominant axis, shear, the watertight test
 * (traverse/wt.h) and the (geom, prim) tie-break - so each structure returns the BVH's hits bit
 * for bit. Also the query entry points every such structure shares (ALT_KERNELS). Included by
 * one translation unit per structure. */
#ifndef RP_TRI_LEAF_H
#define RP_TRI_LEAF_H

#include <math.h>
#include <string.h>

#include "accel/accel.h"
#include "simd/simd.h"
#include "traverse/wt.h"

WT_DEFINE(4)

/* 1 + 2 gamma(3) (Ize 2013), as kernels.inc: slab and plane distances widened by it never cull a
 * cell the ray touches. Its inverse narrows a distance by as much. */
#define ALT_UP 1.00000036f
#define ALT_DN 0.99999964f
/* cells entered beyond the closest hit times this are skipped (kernels.inc's CULL_SLACK) */
#define ALT_CULL_SLACK 1.000244140625f

typedef struct alt_ray {
    float org[3], dir[3], rdir[3];
    float tnear;
    uint32_t mask;
    const uint32_t *geom_masks; /* rp_accel.geom_masks when the ray needs the mask test, else NULL */
    int kx, ky, kz;
    float sx, sy, sz;
} alt_ray;

typedef struct alt_hit {
    float t, u, v;
    uint32_t geom, prim;
    uint32_t block, lane;
} alt_hit;

/* A distance moved away from zero / towards it by the rounding bound (conservative ends). */
static inline float alt_up(float t) { return t > 0.0f ? t * ALT_UP : t * ALT_DN; }
static inline float alt_dn(float t) { return t > 0.0f ? t * ALT_DN : t * ALT_UP; }

static inline void alt_ray_setup(alt_ray *r, const rp_ray *ray, const rp_accel *acc) {
    static const int8_t next[3] = {1, 2, 0};
    const float d[3] = {ray->dir_x, ray->dir_y, ray->dir_z};
    r->org[0] = ray->org_x, r->org[1] = ray->org_y, r->org[2] = ray->org_z;
    r->tnear = ray->tnear, r->mask = ray->mask;
    r->geom_masks = (ray->mask & acc->tri_mask_and) ? NULL : acc->geom_masks; /* as kernels.inc's leaf1_tri */
    float a0 = fabsf(d[0]), a1 = fabsf(d[1]), a2 = fabsf(d[2]);
    int z = a1 > a0;
    z = a2 > (z ? a1 : a0) ? 2 : z;
    int x = next[z], y = next[x];
    int neg = d[z] < 0.0f;
    r->kx = neg ? y : x, r->ky = neg ? x : y, r->kz = z;
    vf4 rd = wt_rcp_4((vf4){d[0], d[1], d[2], 1.0f});
    vf4 sh = (vf4){d[r->kx], d[r->ky], 1.0f, 1.0f} / vf4_splat(d[r->kz]);
    for (int i = 0; i < 3; i++) r->rdir[i] = rd[i], r->dir[i] = d[i];
    r->sx = sh[0], r->sy = sh[1], r->sz = sh[2];
}

/* Entry and exit of the ray in box b (lo xyz, hi xyz), clipped to [tnear, tfar]; false if it
 * misses. The exit is widened (Ize 2013). */
static inline bool alt_ray_box(const alt_ray *r, const float b[6], float tfar, float *t0, float *t1) {
    float lo = r->tnear, hi = tfar;
    for (int k = 0; k < 3; k++) {
        float ta = (b[k] - r->org[k]) * r->rdir[k], tb = (b[3 + k] - r->org[k]) * r->rdir[k];
        float tn = ta < tb ? ta : tb, tf = ta < tb ? tb : ta;
        tf = alt_up(tf);
        lo = tn > lo ? tn : lo;
        hi = tf < hi ? tf : hi;
    }
    *t0 = lo, *t1 = hi;
    return lo <= hi;
}

/* One ray against blocks [first, first + count): closest hit (tie-break by (geom, prim)) or, with
 * any, true at the first hit. Unused lanes repeat lane 0, so they find only its hit again. */
static inline bool alt_leaf(const tri4 *blocks, const alt_ray *r, uint32_t first, uint32_t count, alt_hit *h,
                            bool any) {
    const int kx = r->kx, ky = r->ky, kz = r->kz;
    vf4 ox = vf4_splat(r->org[kx]), oy = vf4_splat(r->org[ky]), oz = vf4_splat(r->org[kz]);
    vf4 sx = vf4_splat(r->sx), sy = vf4_splat(r->sy), sz = vf4_splat(r->sz);
    for (uint32_t b = first; b < first + count; b++) {
        const tri4 *tr = &blocks[b];
        vf4 t, u, v;
        vi4 ok = wt_4(vf4_load(tr->v[kx]) - ox, vf4_load(tr->v[ky]) - oy, vf4_load(tr->v[kz]) - oz,
                      vf4_load(tr->v[3 + kx]) - ox, vf4_load(tr->v[3 + ky]) - oy, vf4_load(tr->v[3 + kz]) - oz,
                      vf4_load(tr->v[6 + kx]) - ox, vf4_load(tr->v[6 + ky]) - oy, vf4_load(tr->v[6 + kz]) - oz,
                      sx, sy, sz, &t, &u, &v);
        ok &= (t >= vf4_splat(r->tnear)) & (t <= vf4_splat(h->t));
        uint32_t m = vi4_movemask(ok);
        if (m && r->geom_masks) m &= tri4_mask_lanes(r->geom_masks, tr, r->mask);
        if (!m) continue;
        if (any) return true;
        do {
            uint32_t j = simd_ctz(m);
            m &= m - 1;
            if (t[j] < h->t || (t[j] == h->t && hit_key_less(tr->geom[j], tr->prim[j], h->geom, h->prim))) {
                h->t = t[j], h->u = u[j], h->v = v[j];
                h->geom = tr->geom[j], h->prim = tr->prim[j];
                h->block = b, h->lane = j;
            }
        } while (m);
    }
    return false;
}

/* The query entry points of a structure whose single-ray traversal is
 * bool TRAV(const rp_accel *acc, const accel_built *s, const alt_ray *r, alt_hit *h, bool any)
 * and whose packet traversal is
 * bool PTRAV(const accel_built *s, const alt_ray *r, alt_hit *h, uint32_t live, int k, bool any,
 *            uint32_t *occluded)
 * (false: it does not take this packet, which then goes ray by ray through TRAV), and TRACE_N its
 * n x n packets' traversal (rp_kernels.trace_n) or NULL. Spheres and
 * user primitives go to the device's BVH kernels (acc->nodes is NULL), after the triangles, as
 * the BVH's kernels order them. */
#define ALT_KERNELS(NAME, TRAV, PTRAV, TRACE_N) ALT_KERNELS_ISA(NAME, TRAV, PTRAV, TRACE_N, 1)
/* The same, for kernels compiled per instruction set (the grid's, src/accel/grid/grid_trav.inc):
 * ISA is the SIMD width rp_kernels.isa reports, which sizes the SIMD packets that the n x n
 * packets are cut into when TRACE_N is NULL (api_n.c). */
#define ALT_KERNELS_ISA(NAME, TRAV, PTRAV, TRACE_N, ISA)                                          \
    static void NAME##_intersect1(const rp_accel *acc, rp_rayhit *rh) {                           \
        if (!(rh->ray.tnear <= rh->ray.tfar)) return;                                             \
        const accel_built *s = acc->alt;                                                          \
        if (s && s->block_count) {                                                                \
            alt_ray r;                                                                            \
            alt_ray_setup(&r, &rh->ray, acc);                                                          \
            alt_hit h = {.t = rh->ray.tfar, .geom = RP_INVALID_ID, .prim = RP_INVALID_ID};        \
            TRAV(acc, s, &r, &h, false);                                                          \
            if (h.geom != RP_INVALID_ID) alt_write_hit(s, &h, rh);                                \
        }                                                                                         \
        if (acc->pnodes) acc->base->intersect1(acc, rh);                                          \
    }                                                                                             \
    static void NAME##_occluded1(const rp_accel *acc, rp_ray *ray) {                              \
        if (!(ray->tnear <= ray->tfar)) return;                                                   \
        const accel_built *s = acc->alt;                                                          \
        if (s && s->block_count) {                                                                \
            alt_ray r;                                                                            \
            alt_ray_setup(&r, ray, acc);                                                               \
            alt_hit h = {.t = ray->tfar, .geom = RP_INVALID_ID, .prim = RP_INVALID_ID};           \
            if (TRAV(acc, s, &r, &h, true)) {                                                     \
                ray->tfar = -INFINITY;                                                            \
                return;                                                                           \
            }                                                                                     \
        }                                                                                         \
        if (acc->pnodes) acc->base->occluded1(acc, ray);                                          \
    }                                                                                             \
    ALT_PACKET(NAME, TRAV, PTRAV, 4)                                                              \
    ALT_PACKET(NAME, TRAV, PTRAV, 8)                                                              \
    ALT_PACKET(NAME, TRAV, PTRAV, 16)                                                             \
    RP_HIDDEN const rp_kernels NAME##_kernels = {                                                 \
        .name = #NAME, .isa = ISA,                                                                \
        .intersect1 = NAME##_intersect1, .occluded1 = NAME##_occluded1,                           \
        .intersect4 = NAME##_intersect_4, .intersect8 = NAME##_intersect_8,                       \
        .intersect16 = NAME##_intersect_16, .occluded4 = NAME##_occluded_4,                       \
        .occluded8 = NAME##_occluded_8, .occluded16 = NAME##_occluded_16,                         \
        .trace_n = TRACE_N,                                                                       \
    };

static inline void alt_write_hit(const accel_built *s, const alt_hit *h, rp_rayhit *rh) {
    float n[3];
    tri_normal(&s->blocks[h->block], h->lane, n);
    rh->ray.tfar = h->t;
    rh->hit.u = h->u, rh->hit.v = h->v;
    rh->hit.Ng_x = n[0], rh->hit.Ng_y = n[1], rh->hit.Ng_z = n[2];
    rh->hit.geom_id = h->geom, rh->hit.prim_id = h->prim;
    rh->hit.inst_id = RP_INVALID_ID;
}

/* Lane i of a packet as a single ray. */
#define ALT_LANE(p, i)                                                                            \
    (rp_ray) {                                                                                    \
        .org_x = (p)->org_x[i], .org_y = (p)->org_y[i], .org_z = (p)->org_z[i], .tnear = (p)->tnear[i], \
        .dir_x = (p)->dir_x[i], .dir_y = (p)->dir_y[i], .dir_z = (p)->dir_z[i], .time = (p)->time[i],   \
        .tfar = (p)->tfar[i], .mask = (p)->mask[i], .id = (p)->id[i], .flags = (p)->flags[i]             \
    }

#define ALT_PACKET(NAME, TRAV, PTRAV, K)                                                          \
    static void NAME##_intersect_##K(const rp_accel *acc, const int32_t *valid, rp_rayhit##K *p) { \
        const accel_built *s = acc->alt;                                                          \
        alt_ray r[K];                                                                             \
        alt_hit h[K];                                                                             \
        uint32_t live = 0, occ = 0;                                                               \
        for (int i = 0; i < K; i++) {                                                             \
            if (!valid[i] || !(p->ray.tnear[i] <= p->ray.tfar[i])) continue;                      \
            live |= 1u << i;                                                                      \
            rp_ray one = ALT_LANE(&p->ray, i);                                                    \
            alt_ray_setup(&r[i], &one, acc);                                                           \
            h[i] = (alt_hit){.t = one.tfar, .geom = RP_INVALID_ID, .prim = RP_INVALID_ID};        \
        }                                                                                         \
        if (!live) return;                                                                        \
        if (s && s->block_count && !PTRAV(s, r, h, live, K, false, &occ))                         \
            for (uint32_t m = live; m; m &= m - 1) TRAV(acc, s, &r[simd_ctz(m)], &h[simd_ctz(m)], false); \
        for (uint32_t m = live; m; m &= m - 1) {                                                  \
            uint32_t i = simd_ctz(m);                                                             \
            rp_rayhit one;                                                                        \
            one.ray = ALT_LANE(&p->ray, i);                                                       \
            one.hit.geom_id = RP_INVALID_ID;                                                      \
            if (s && s->block_count && h[i].geom != RP_INVALID_ID) alt_write_hit(s, &h[i], &one); \
            if (acc->pnodes) acc->base->intersect1(acc, &one);                                    \
            if (one.hit.geom_id == RP_INVALID_ID) continue;                                       \
            p->ray.tfar[i] = one.ray.tfar;                                                        \
            p->hit.Ng_x[i] = one.hit.Ng_x, p->hit.Ng_y[i] = one.hit.Ng_y, p->hit.Ng_z[i] = one.hit.Ng_z; \
            p->hit.u[i] = one.hit.u, p->hit.v[i] = one.hit.v;                                     \
            p->hit.prim_id[i] = one.hit.prim_id, p->hit.geom_id[i] = one.hit.geom_id;             \
            p->hit.inst_id[i] = one.hit.inst_id;                                                  \
        }                                                                                         \
    }                                                                                             \
    static void NAME##_occluded_##K(const rp_accel *acc, const int32_t *valid, rp_ray##K *p) {    \
        const accel_built *s = acc->alt;                                                          \
        alt_ray r[K];                                                                             \
        alt_hit h[K];                                                                             \
        uint32_t live = 0, occ = 0;                                                               \
        for (int i = 0; i < K; i++) {                                                             \
            if (!valid[i] || !(p->tnear[i] <= p->tfar[i])) continue;                              \
            live |= 1u << i;                                                                      \
            rp_ray one = ALT_LANE(p, i);                                                          \
            alt_ray_setup(&r[i], &one, acc);                                                           \
            h[i] = (alt_hit){.t = one.tfar, .geom = RP_INVALID_ID, .prim = RP_INVALID_ID};        \
        }                                                                                         \
        if (!live) return;                                                                        \
        if (s && s->block_count && !PTRAV(s, r, h, live, K, true, &occ))                          \
            for (uint32_t m = live; m; m &= m - 1)                                                \
                if (TRAV(acc, s, &r[simd_ctz(m)], &h[simd_ctz(m)], true)) occ |= m & -m;          \
        for (uint32_t m = live; m; m &= m - 1) {                                                  \
            uint32_t i = simd_ctz(m);                                                             \
            if (occ & (1u << i)) {                                                                \
                p->tfar[i] = -INFINITY;                                                           \
                continue;                                                                         \
            }                                                                                     \
            if (!acc->pnodes) continue;                                                           \
            rp_ray one = ALT_LANE(p, i);                                                          \
            acc->base->occluded1(acc, &one);                                                      \
            p->tfar[i] = one.tfar;                                                                \
        }                                                                                         \
    }

/* A structure without a packet traversal: every packet goes ray by ray. */
static inline bool alt_no_packets(const accel_built *s, const alt_ray *r, alt_hit *h, uint32_t live, int k, bool any,
                                  uint32_t *occluded) {
    (void)s, (void)r, (void)h, (void)live, (void)k, (void)any, (void)occluded;
    return false;
}

#endif
