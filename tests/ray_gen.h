/* Shared by test_kernels.c and test_accel.c: the brute-force closest hit over a mesh (the reference
 * triangle test with the (geom, prim) tie-break) and the random rays both trace. */
#ifndef RP_RAY_GEN_H
#define RP_RAY_GEN_H
#include <math.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "traverse/traverse.h"

#include "sys/sys.h"
#include "traverse/traverse.h"

typedef struct ref_hit {
    float t;
    uint32_t prim;
} ref_hit;

/* Brute force over every triangle with the reference test and the (geom, prim) tie-break. */
static ref_hit brute_force(const test_mesh *m, const rp_ray *r) {
    ref_hit h = {r->tfar, RP_INVALID_ID};
    float o[3] = {r->org_x, r->org_y, r->org_z}, d[3] = {r->dir_x, r->dir_y, r->dir_z};
    for (uint32_t i = 0; i < m->nt; i++) {
        const float *v0 = &m->v[3 * m->idx[3 * i]], *v1 = &m->v[3 * m->idx[3 * i + 1]], *v2 = &m->v[3 * m->idx[3 * i + 2]];
        if (!isfinite(v0[0] + v0[1] + v0[2] + v1[0] + v1[1] + v1[2] + v2[0] + v2[1] + v2[2])) continue;
        float t, u, v;
        if (tri_intersect_ref(o, d, r->tnear, h.t, v0, v1, v2, &t, &u, &v) &&
            (t < h.t || (t == h.t && i < h.prim))) {
            h.t = t, h.prim = i;
        }
    }
    return h;
}

/* Random rays: half from inside the bounds in random directions, half from outside aimed at
 * random points of random triangles (so most of them hit). */
static void make_rays(const test_mesh *m, rp_ray *rays, uint32_t n, uint64_t seed) {
    test_rng g = {seed};
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < m->nv; i++)
        for (int a = 0; a < 3; a++) {
            float x = m->v[3 * i + a];
            if (x < lo[a]) lo[a] = x;
            if (x > hi[a]) hi[a] = x;
        }
    for (uint32_t i = 0; i < n; i++) {
        rp_ray *r = &rays[i];
        float o[3], d[3];
        if (i % 2) {
            for (int a = 0; a < 3; a++) o[a] = lo[a] + (hi[a] - lo[a]) * test_rng_float(&g);
            for (int a = 0; a < 3; a++) d[a] = test_rng_float(&g) * 2.0f - 1.0f;
        } else {
            uint32_t t = test_rng_u32(&g) % m->nt;
            float b1 = test_rng_float(&g), b2 = test_rng_float(&g);
            if (b1 + b2 > 1.0f) b1 = 1.0f - b1, b2 = 1.0f - b2;
            float p[3];
            for (int a = 0; a < 3; a++) {
                float v0 = m->v[3 * m->idx[3 * t] + a], v1 = m->v[3 * m->idx[3 * t + 1] + a], v2 = m->v[3 * m->idx[3 * t + 2] + a];
                p[a] = v0 + b1 * (v1 - v0) + b2 * (v2 - v0);
                o[a] = lo[a] - (hi[a] - lo[a]) * 0.5f + (hi[a] - lo[a]) * 2.0f * test_rng_float(&g);
                d[a] = p[a] - o[a];
            }
        }
        uint32_t block = i / 16;
        if (block % 4 == 3) {
            /* shadow rays: from points on the mesh, spread over it, to one light far outside
             * (one direction from spread origins: per-ray-mask traversal), the segments ending
             * at the light or halfway */
            test_rng pg = {seed * 1361u + block};
            float light[3];
            for (int a = 0; a < 3; a++) light[a] = hi[a] + (hi[a] - lo[a]) * (2.0f + test_rng_float(&pg));
            uint32_t t = test_rng_u32(&g) % m->nt;
            float b1 = test_rng_float(&g), b2 = test_rng_float(&g);
            if (b1 + b2 > 1.0f) b1 = 1.0f - b1, b2 = 1.0f - b2;
            for (int a = 0; a < 3; a++) {
                float v0 = m->v[3 * m->idx[3 * t] + a], v1 = m->v[3 * m->idx[3 * t + 1] + a], v2 = m->v[3 * m->idx[3 * t + 2] + a];
                o[a] = v0 + b1 * (v1 - v0) + b2 * (v2 - v0);
                d[a] = light[a] - o[a];
            }
            *r = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .tnear = 1e-3f, .dir_x = d[0], .dir_y = d[1],
                          .dir_z = d[2], .tfar = i % 2 ? 1.0f : 0.5f, .mask = 0xFFFFFFFFu};
            continue;
        }
        if (block % 4 != 2) {
            /* packets of 16 that a camera would make: a shared origin outside the bounds and
             * directions around one aimed at a triangle (block % 4 == 0), or spread across
             * octant borders (block % 4 == 1, exercising the per-octant split) */
            test_rng pg = {seed * 977u + block};
            float po[3], pd[3];
            uint32_t t = test_rng_u32(&pg) % m->nt;
            for (int a = 0; a < 3; a++) {
                po[a] = lo[a] - (hi[a] - lo[a]) * 0.5f + (hi[a] - lo[a]) * 2.0f * test_rng_float(&pg);
                pd[a] = m->v[3 * m->idx[3 * t] + a] - po[a];
            }
            float spread = block % 4 == 0 ? 0.02f : 1.0f;
            float len = sqrtf(pd[0] * pd[0] + pd[1] * pd[1] + pd[2] * pd[2]);
            for (int a = 0; a < 3; a++) {
                o[a] = po[a];
                d[a] = pd[a] / len + (test_rng_float(&g) - 0.5f) * spread;
            }
            if (block % 4 == 1) d[i % 3] = (test_rng_float(&g) - 0.5f) * 0.2f; /* straddle an axis */
        }
        *r = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .tnear = 0.0f, .dir_x = d[0], .dir_y = d[1],
                      .dir_z = d[2], .tfar = INFINITY, .mask = 0xFFFFFFFFu};
        if (i % 7 == 3) r->tfar = 0.5f; /* some finite segments, as for shadow rays */
    }
}

#endif
