// rp-test: labels=core timeout=300
/* Dynamic scenes: after rp_geometry_update of moved vertices, rp_scene_commit refits the BVH
 * (stats.refit) and every query then returns, bit for bit, the hits of a scene built from scratch
 * on the same vertices; a motion that spoils the tree past refit_max_growth, a new index buffer, a
 * NaN vertex, an attached geometry or refit_max_growth < 0 make it rebuild instead. */
#include <math.h>

#include "mesh_gen.h"
#include "query_got.h"
#include "raypack.h"
#include "rp_test.h"

static bool same(const got *a, const got *b) { return same_got(a, b) && a->occluded == b->occluded; }

static void rays_make(rp_ray *r, uint32_t n, uint64_t seed) {
    test_rng g = {seed};
    for (uint32_t i = 0; i < n; i++) {
        float o[3], d[3];
        for (int a = 0; a < 3; a++) o[a] = -1.5f + 3.0f * test_rng_float(&g), d[a] = test_rng_float(&g) * 2.0f - 1.0f;
        if (i % 2) o[2] = 4.0f, d[2] = -1.0f; /* from above, at the meshes */
        r[i] = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .dir_x = d[0], .dir_y = d[1], .dir_z = d[2],
                        .tfar = i % 5 ? INFINITY : 2.0f, .mask = ~0u};
    }
}

/* Single rays and 16x16 packets (auto traversal: the binary BVH the refit also updates). */
static void trace(rp_device *dev, rp_scene *s, const rp_ray *rays, uint32_t n, got *out) {
    for (uint32_t i = 0; i < n; i++) {
        rp_rayhit rh = {.ray = rays[i]};
        rh.hit.geom_id = RP_INVALID_ID;
        rp_intersect1(s, &rh);
        rp_ray o = rays[i];
        rp_occluded1(s, &o);
        out[i] = (got){rh.ray.tfar, rh.hit.u, rh.hit.v, {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z}, rh.hit.geom_id,
                       rh.hit.prim_id, o.tfar == -INFINITY};
    }
    rp_rayhit_n p;
    if (!rp_rayhit_n_alloc(dev, 16, &p)) return;
    for (uint32_t base = 0; base + 256 <= n; base += 256) {
        for (uint32_t i = 0; i < 256; i++) {
            const rp_ray *r = &rays[base + i];
            p.org_x[i] = r->org_x, p.org_y[i] = r->org_y, p.org_z[i] = r->org_z;
            p.dir_x[i] = r->dir_x, p.dir_y[i] = r->dir_y, p.dir_z[i] = r->dir_z;
            p.tnear[i] = r->tnear, p.tfar[i] = r->tfar, p.geom_id[i] = RP_INVALID_ID;
        }
        rp_intersect_n(s, NULL, &p);
        for (uint32_t i = 0; i < 256; i++) {
            got g = {p.tfar[i], p.u[i], p.v[i], {p.Ng_x[i], p.Ng_y[i], p.Ng_z[i]}, p.geom_id[i], p.prim_id[i],
                     out[base + i].occluded};
            if (!same(&g, &out[base + i])) out[base + i].geom = 0xBAD; /* packets disagree with single rays */
        }
    }
    rp_rayhit_n_free(dev, &p);
}

static rp_scene *scene_of(rp_device *dev, const rp_scene_desc *d, test_mesh *m, int nm) {
    rp_scene *s = rp_scene_new(dev, d);
    for (int i = 0; i < nm; i++) {
        rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
        rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m[i].v, 0, 0, m[i].nv);
        rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, m[i].idx, 0, 0, m[i].nt);
        rp_geometry_commit(g);
        rp_scene_attach(s, g);
        rp_geometry_release(g);
    }
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    return s;
}

/* Refit (or rebuild) of `s` against a fresh build over the same meshes, on every ray. */
static void compare(rp_device *dev, rp_scene *s, test_mesh *m, int nm, const rp_ray *rays, uint32_t n,
                    const char *what) {
    got *a = malloc(sizeof(got) * n), *b = malloc(sizeof(got) * n);
    rp_scene *fresh = scene_of(dev, NULL, m, nm);
    trace(dev, s, rays, n, a);
    trace(dev, fresh, rays, n, b);
    uint32_t bad = 0, hits = 0;
    for (uint32_t i = 0; i < n; i++) bad += !same(&a[i], &b[i]), hits += b[i].geom != RP_INVALID_ID;
    CHECKF(bad == 0, "%s: %u of %u rays differ from a fresh build", what, bad, n);
    CHECKF(hits > n / 8, "%s: only %u of %u rays hit", what, hits, n);
    rp_scene_release(fresh);
    free(a), free(b);
}

static void wobble(test_mesh *m, const test_mesh *rest, float t, float amp) {
    for (uint32_t i = 0; i < m->nv; i++) {
        const float *p = &rest->v[3 * i];
        m->v[3 * i + 0] = p[0] + amp * sinf(3.0f * p[1] + t);
        m->v[3 * i + 1] = p[1] + amp * cosf(2.0f * p[2] + 1.7f * t);
        m->v[3 * i + 2] = p[2] + amp * sinf(2.5f * p[0] - t);
    }
}

int main(void) {
    uint32_t n = rp_test_sanitized() ? 1024 : 8192;
    rp_ray *rays = malloc(sizeof(rp_ray) * n);
    rays_make(rays, n, 99);
    float c[3] = {0.0f, 0.0f, 0.0f};
    test_mesh m[2] = {test_mesh_sphere(40, 80, c, 1.0f), test_mesh_soup(3000, 0.15f, 5)};
    for (uint32_t i = 0; i < 3 * m[1].nt * 3; i++) m[1].v[i] = m[1].v[i] * 3.0f - 1.5f;
    test_mesh rest[2];
    for (int k = 0; k < 2; k++) {
        rest[k] = m[k];
        rest[k].v = malloc(sizeof(float) * 3 * m[k].nv);
        memcpy(rest[k].v, m[k].v, sizeof(float) * 3 * m[k].nv);
    }
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    rp_scene *s = scene_of(dev, NULL, m, 2);
    rp_scene_stats st;
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 0);
    /* small motions: refits, hit for hit a rebuild's */
    for (int f = 1; f <= 4; f++) {
        for (int k = 0; k < 2; k++) wobble(&m[k], &rest[k], 0.3f * (float)f, 0.02f);
        rp_geometry_update(rp_scene_get_geometry(s, 0), RP_BUFFER_VERTEX);
        rp_geometry_update(rp_scene_get_geometry(s, 1), RP_BUFFER_VERTEX);
        CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
        rp_scene_get_stats(s, &st);
        CHECKF(st.refit == 1, "frame %d: a small motion refits (SAH %.3f)", f, st.sah_cost);
        char what[64];
        snprintf(what, sizeof what, "refit frame %d", f);
        compare(dev, s, m, 2, rays, n, what);
    }
    /* the soup scattered everywhere: the refitted tree costs too much, a rebuild */
    test_rng g = {3};
    for (uint32_t i = 0; i < 3 * m[1].nv; i++) m[1].v[i] = test_rng_float(&g) * 3.0f - 1.5f;
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    rp_scene_get_stats(s, &st);
    CHECKF(st.refit == 0, "a scattering motion rebuilds (SAH %.3f)", st.sah_cost);
    compare(dev, s, m, 2, rays, n, "rebuild after scattering");
    /* and a small motion after that rebuild refits again */
    for (uint32_t i = 0; i < 3 * m[0].nv; i++) m[0].v[i] *= 1.01f;
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 1);
    compare(dev, s, m, 2, rays, n, "refit after rebuild");
    /* a changed index buffer rebuilds */
    uint32_t t0[3] = {m[0].idx[0], m[0].idx[1], m[0].idx[2]};
    m[0].idx[0] = t0[1], m[0].idx[1] = t0[0];
    rp_geometry_update(rp_scene_get_geometry(s, 0), RP_BUFFER_INDEX);
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 0);
    compare(dev, s, m, 2, rays, n, "rebuild after new indices");
    /* a NaN vertex rebuilds (and the triangles using it are rejected) */
    float keep = m[1].v[0];
    m[1].v[0] = NAN;
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 0 && st.rejected_prims == 1);
    m[1].v[0] = keep;
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE); /* rejected triangles last time: rebuild */
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 0 && st.rejected_prims == 0);
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 1);
    /* attaching a geometry rebuilds */
    rp_geometry *extra = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(extra, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m[0].v, 0, 0, m[0].nv);
    rp_geometry_set_buffer(extra, RP_BUFFER_INDEX, RP_FORMAT_UINT3, m[0].idx, 0, 0, 8);
    rp_geometry_commit(extra);
    rp_scene_attach(s, extra);
    rp_geometry_release(extra);
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 0);
    rp_scene_release(s);
    /* refit_max_growth < 0: always rebuilds */
    s = scene_of(dev, &(rp_scene_desc){.refit_max_growth = -1.0f}, m, 2);
    for (uint32_t i = 0; i < 3 * m[0].nv; i++) m[0].v[i] *= 1.01f;
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    rp_scene_get_stats(s, &st);
    CHECK(st.refit == 0);
    compare(dev, s, m, 2, rays, n, "rebuild when refits are off");
    rp_scene_release(s);
    CHECK(rp_device_get_error(dev) == RP_ERROR_NONE);
    rp_device_release(dev);
    for (int k = 0; k < 2; k++) test_mesh_free(&m[k]), free(rest[k].v);
    free(rays);
    return RP_TEST_END();
}
