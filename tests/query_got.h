/* Shared by test_accel.c, test_masks.c and test_refit.c: one ray's hit as every query kind reports
 * it, compared bit for bit, and the single-ray, packet and array queries that fill it. */
#ifndef RP_QUERY_GOT_H
#define RP_QUERY_GOT_H
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "raypack.h"

typedef struct got {
    float t, u, v, ng[3];
    uint32_t geom, prim;
    int occluded;
} got;

/* The same closest hit (occluded not compared): triangle, distance's bits, barycentrics, normal. */
static inline bool same_got(const got *a, const got *b) {
    if (a->geom != b->geom) return false;
    if (a->geom == RP_INVALID_ID) return true; /* a miss leaves prim_id as it was */
    if (a->prim != b->prim) return false;
    return memcmp(&a->t, &b->t, 4) == 0 && a->u == b->u && a->v == b->v && a->ng[0] == b->ng[0] &&
           a->ng[1] == b->ng[1] && a->ng[2] == b->ng[2];
}

static inline void trace1(rp_scene *s, const rp_ray *r, got *g) {
    rp_rayhit rh = {.ray = *r};
    rh.hit.geom_id = RP_INVALID_ID;
    rp_intersect1(s, &rh);
    *g = (got){rh.ray.tfar, rh.hit.u, rh.hit.v, {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z}, rh.hit.geom_id, rh.hit.prim_id, 0};
    rp_ray o = *r;
    rp_occluded1(s, &o);
    g->occluded = o.tfar == -INFINITY;
}

static inline void trace_array(rp_scene *s, const rp_ray *rays, uint32_t n, uint32_t flags, got *out) {
    rp_rayhit *a = malloc(sizeof(rp_rayhit) * n);
    rp_ray *o = malloc(sizeof(rp_ray) * n);
    for (uint32_t i = 0; i < n; i++) {
        a[i] = (rp_rayhit){.ray = rays[i]};
        a[i].hit.geom_id = RP_INVALID_ID;
        o[i] = rays[i];
    }
    rp_intersect_array(s, a, n, flags);
    rp_occluded_array(s, o, n, flags);
    for (uint32_t i = 0; i < n; i++)
        out[i] = (got){a[i].ray.tfar, a[i].hit.u, a[i].hit.v, {a[i].hit.Ng_x, a[i].hit.Ng_y, a[i].hit.Ng_z},
                       a[i].hit.geom_id, a[i].hit.prim_id, o[i].tfar == -INFINITY};
    free(a);
    free(o);
}

/* W-ray packets of consecutive rays, every fifth lane dead: its got is geom 0xDEAD when the
 * queries left it untouched, 0xBAD when they wrote it. */
#define TRACE_PACKET(W)                                                                           \
    static inline void trace_##W(rp_scene *s, const rp_ray *rays, uint32_t n, got *out) {         \
        for (uint32_t base = 0; base + W <= n; base += W) {                                       \
            rp_rayhit##W p;                                                                       \
            rp_ray##W sh;                                                                         \
            int32_t valid[W];                                                                     \
            memset(&p, 0, sizeof p);                                                              \
            for (int i = 0; i < W; i++) {                                                         \
                const rp_ray *r = &rays[base + (uint32_t)i];                                      \
                valid[i] = (i % 5 == 4) ? 0 : -1;                                                 \
                p.ray.org_x[i] = r->org_x, p.ray.org_y[i] = r->org_y, p.ray.org_z[i] = r->org_z;  \
                p.ray.dir_x[i] = r->dir_x, p.ray.dir_y[i] = r->dir_y, p.ray.dir_z[i] = r->dir_z;  \
                p.ray.tnear[i] = r->tnear, p.ray.tfar[i] = r->tfar, p.ray.mask[i] = r->mask;      \
                p.hit.geom_id[i] = RP_INVALID_ID, p.hit.prim_id[i] = 12345u;                      \
                sh.org_x[i] = r->org_x, sh.org_y[i] = r->org_y, sh.org_z[i] = r->org_z;           \
                sh.dir_x[i] = r->dir_x, sh.dir_y[i] = r->dir_y, sh.dir_z[i] = r->dir_z;           \
                sh.tnear[i] = r->tnear, sh.tfar[i] = r->tfar, sh.mask[i] = r->mask;               \
                sh.time[i] = 0, sh.id[i] = 0, sh.flags[i] = 0;                                    \
            }                                                                                     \
            rp_intersect##W(s, valid, &p);                                                        \
            rp_occluded##W(s, valid, &sh);                                                        \
            for (int i = 0; i < W; i++) {                                                         \
                got *g = &out[base + (uint32_t)i];                                                \
                if (!valid[i]) {                                                                  \
                    /* dead lanes stay untouched: marked so the comparison fails if not */      \
                    bool clean = p.hit.prim_id[i] == 12345u && p.hit.geom_id[i] == RP_INVALID_ID && \
                                 sh.tfar[i] == rays[base + (uint32_t)i].tfar;                     \
                    *g = (got){0};                                                                \
                    g->geom = clean ? 0xDEADu : 0xBADu;                                           \
                    continue;                                                                     \
                }                                                                                 \
                *g = (got){p.ray.tfar[i], p.hit.u[i], p.hit.v[i], {p.hit.Ng_x[i], p.hit.Ng_y[i], p.hit.Ng_z[i]}, \
                           p.hit.geom_id[i], p.hit.prim_id[i], sh.tfar[i] == -INFINITY};          \
            }                                                                                     \
        }                                                                                         \
    }
TRACE_PACKET(4)
TRACE_PACKET(8)
TRACE_PACKET(16)

#endif
