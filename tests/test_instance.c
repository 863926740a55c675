// rp-test: labels=core timeout=300
/* Instancing (RP_GEOMETRY_INSTANCE): scenes placed by affine transforms, two and three levels
 * deep, against the same triangles flattened into one scene (transformed vertices): the same hit
 * or miss, the same (geom, prim) and inst_id, and t within 1e-4 relative (the ray's mapping into
 * an instance rounds differently from the vertices' mapping out of it), on all but a handful of
 * rays grazing an edge; single rays, 16-ray packets and 16x16 packets; occlusion; instances of a
 * kd-tree and of a BIH scene; nesting past RP_MAX_INSTANCE_DEPTH and cycles fail to commit. */
#include <math.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "rp_test.h"

static void xfm_make(float m[12], float angle, float scale, float tx, float ty, float tz) {
    float c = cosf(angle), s = sinf(angle);
    float r[12] = {c * scale, -s * scale, 0.0f, tx, s * scale * 0.8f, c * scale * 0.8f, 0.3f * scale, ty,
                   0.0f, -0.2f * scale, scale * 1.2f, tz};
    memcpy(m, r, sizeof r);
}

static void xfm_mul(const float a[12], const float b[12], float out[12]) { /* a after b */
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) out[4 * i + j] = a[4 * i] * b[j] + a[4 * i + 1] * b[4 + j] + a[4 * i + 2] * b[8 + j];
        out[4 * i + 3] = a[4 * i] * b[3] + a[4 * i + 1] * b[7] + a[4 * i + 2] * b[11] + a[4 * i + 3];
    }
}

static rp_geometry *mesh_geom(rp_device *dev, const test_mesh *m) {
    rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m->v, 0, 0, m->nv);
    rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, m->idx, 0, 0, m->nt);
    rp_geometry_commit(g);
    return g;
}

static uint32_t attach_instance(rp_device *dev, rp_scene *parent, rp_scene *child, const float m[12]) {
    rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_INSTANCE);
    rp_geometry_set_instance(g, child, m);
    rp_geometry_commit(g);
    uint32_t id = rp_scene_attach(parent, g);
    rp_geometry_release(g);
    return id;
}

/* A copy of mesh m with its vertices mapped by x. */
static test_mesh mapped(const test_mesh *m, const float x[12]) {
    test_mesh o = {malloc(sizeof(float) * 3 * m->nv), malloc(sizeof(uint32_t) * 3 * m->nt), m->nv, m->nt};
    memcpy(o.idx, m->idx, sizeof(uint32_t) * 3 * m->nt);
    for (uint32_t i = 0; i < m->nv; i++) {
        const float *p = &m->v[3 * i];
        for (int r = 0; r < 3; r++) o.v[3 * i + r] = x[4 * r] * p[0] + x[4 * r + 1] * p[1] + x[4 * r + 2] * p[2] + x[4 * r + 3];
    }
    return o;
}

typedef struct got {
    float t;
    uint32_t geom, prim, inst;
    int occ;
} got;

static void trace(rp_device *dev, rp_scene *s, const rp_ray *rays, uint32_t n, got *g, int mode) {
    if (mode == 0) {
        for (uint32_t i = 0; i < n; i++) {
            rp_rayhit rh = {.ray = rays[i]};
            rh.hit.geom_id = RP_INVALID_ID, rh.hit.inst_id = RP_INVALID_ID;
            rp_intersect1(s, &rh);
            rp_ray o = rays[i];
            rp_occluded1(s, &o);
            g[i] = (got){rh.ray.tfar, rh.hit.geom_id, rh.hit.prim_id, rh.hit.inst_id, o.tfar == -INFINITY};
        }
    } else if (mode == 1) {
        for (uint32_t b = 0; b + 16 <= n; b += 16) {
            rp_rayhit16 p;
            rp_ray16 o;
            int32_t valid[16];
            memset(&p, 0, sizeof p);
            for (int i = 0; i < 16; i++) {
                const rp_ray *r = &rays[b + (uint32_t)i];
                valid[i] = -1;
                p.ray.org_x[i] = r->org_x, p.ray.org_y[i] = r->org_y, p.ray.org_z[i] = r->org_z;
                p.ray.dir_x[i] = r->dir_x, p.ray.dir_y[i] = r->dir_y, p.ray.dir_z[i] = r->dir_z;
                p.ray.tnear[i] = r->tnear, p.ray.tfar[i] = r->tfar, p.ray.mask[i] = r->mask;
                p.hit.geom_id[i] = RP_INVALID_ID, p.hit.inst_id[i] = RP_INVALID_ID;
            }
            o = p.ray;
            rp_intersect16(s, valid, &p);
            rp_occluded16(s, valid, &o);
            for (int i = 0; i < 16; i++)
                g[b + (uint32_t)i] = (got){p.ray.tfar[i], p.hit.geom_id[i], p.hit.prim_id[i], p.hit.inst_id[i], o.tfar[i] == -INFINITY};
        }
    } else {
        /* mode 2: 16x16 packets (auto); mode 3: the same as SIMD rays, which go into each instance */
        rp_query_n_desc qd = {.traversal = mode == 3 ? RP_TRAVERSAL_SIMD : RP_TRAVERSAL_AUTO};
        rp_rayhit_n p;
        if (!rp_rayhit_n_alloc(dev, 16, &p)) return;
        for (uint32_t b = 0; b + 256 <= n; b += 256) {
            for (uint32_t i = 0; i < 256; i++) {
                const rp_ray *r = &rays[b + i];
                p.org_x[i] = r->org_x, p.org_y[i] = r->org_y, p.org_z[i] = r->org_z;
                p.dir_x[i] = r->dir_x, p.dir_y[i] = r->dir_y, p.dir_z[i] = r->dir_z;
                p.tnear[i] = r->tnear, p.tfar[i] = r->tfar, p.geom_id[i] = RP_INVALID_ID, p.inst_id[i] = RP_INVALID_ID;
            }
            rp_intersect_n(s, &qd, &p);
            for (uint32_t i = 0; i < 256; i++) g[b + i] = (got){p.tfar[i], p.geom_id[i], p.prim_id[i], p.inst_id[i], 0};
            for (uint32_t i = 0; i < 256; i++) p.tfar[i] = rays[b + i].tfar;
            rp_occluded_n(s, &qd, &p);
            for (uint32_t i = 0; i < 256; i++) g[b + i].occ = p.tfar[i] == -INFINITY;
        }
        rp_rayhit_n_free(dev, &p);
    }
}

/* Coherent 16x16 packets (narrow pinhole views) into a top level of 49 small instances, most of
 * which a packet misses: packets into instances cull those by one interval test of the packet's
 * bounds against each instance box before the rays' own slab tests. The packets' hits and
 * occlusion, with lanes switched off and some rays cut short, views from outside and from among
 * the instances, are the single rays' (rp_intersect1 / rp_occluded1 into the same instances). */
static void coherent_packets(rp_device *dev, rp_scene *obj, int kind, int views) {
    rp_scene *top = rp_scene_new(dev, NULL);
    for (int i = 0; i < 7; i++)
        for (int j = 0; j < 7; j++) {
            float m[12];
            xfm_make(m, 0.4f * (float)(i + j), 0.35f, -3.0f + (float)i, -3.0f + (float)j, 0.3f * (float)((i * j) % 3));
            attach_instance(dev, top, obj, m);
        }
    CHECK(rp_scene_commit(top) == RP_ERROR_NONE);
    rp_rayhit_n p;
    if (!rp_rayhit_n_alloc(dev, 16, &p)) {
        CHECKF(0, "accel %d: rp_rayhit_n_alloc failed", kind);
        rp_scene_release(top);
        return;
    }
    int32_t valid[256];
    test_rng r = {91};
    uint32_t total = 0, hits = 0, occluded = 0, bad = 0, far = 0;
    for (int view = 0; view < views; view++) {
        bool inside = view % 4 == 3; /* the eye among the instances, so some origins are in their boxes */
        float eye[3] = {-4.0f + 8.0f * test_rng_float(&r), -4.0f + 8.0f * test_rng_float(&r),
                        inside ? 0.3f : 3.0f + 2.0f * test_rng_float(&r)};
        float look[3] = {-3.0f + 6.0f * test_rng_float(&r), -3.0f + 6.0f * test_rng_float(&r), inside ? 0.3f : 0.0f};
        float f[3], up[3] = {0.0f, inside ? 0.0f : 1.0f, inside ? 1.0f : 0.0f}, rt[3], u[3];
        for (int k = 0; k < 3; k++) f[k] = look[k] - eye[k];
        rt[0] = f[1] * up[2] - f[2] * up[1], rt[1] = f[2] * up[0] - f[0] * up[2], rt[2] = f[0] * up[1] - f[1] * up[0];
        u[0] = rt[1] * f[2] - rt[2] * f[1], u[1] = rt[2] * f[0] - rt[0] * f[2], u[2] = rt[0] * f[1] - rt[1] * f[0];
        float lf = sqrtf(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]), lr = sqrtf(rt[0] * rt[0] + rt[1] * rt[1] + rt[2] * rt[2]),
              lu = sqrtf(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        float span = 0.02f + 0.2f * test_rng_float(&r); /* a patch of one to a few instances */
        for (uint32_t q = 0; q < 256; q++) {
            float a = ((float)(q % 16) / 15.0f - 0.5f) * span, b = ((float)(q / 16) / 15.0f - 0.5f) * span;
            p.org_x[q] = eye[0], p.org_y[q] = eye[1], p.org_z[q] = eye[2];
            p.dir_x[q] = f[0] / lf + a * rt[0] / lr + b * u[0] / lu;
            p.dir_y[q] = f[1] / lf + a * rt[1] / lr + b * u[1] / lu;
            p.dir_z[q] = f[2] / lf + a * rt[2] / lr + b * u[2] / lu;
            p.tnear[q] = 0.0f;
            valid[q] = view % 2 && q % 3 == 0 ? 0 : -1;
        }
        for (int pass = 0; pass < 2; pass++) { /* closest hits, then occlusion */
            for (uint32_t q = 0; q < 256; q++) {
                p.tfar[q] = q % 5 == 0 ? 0.6f * lf : INFINITY;
                p.geom_id[q] = p.prim_id[q] = p.inst_id[q] = RP_INVALID_ID;
            }
            p.valid = valid;
            rp_query_n_desc qd = {.frustum = RP_FRUSTUM_PRIMARY};
            if (pass == 0) rp_intersect_n(top, &qd, &p);
            else rp_occluded_n(top, &qd, &p);
            for (uint32_t q = 0; q < 256; q++) {
                rp_rayhit one = {.ray = {.org_x = p.org_x[q], .org_y = p.org_y[q], .org_z = p.org_z[q],
                                         .dir_x = p.dir_x[q], .dir_y = p.dir_y[q], .dir_z = p.dir_z[q],
                                         .tfar = q % 5 == 0 ? 0.6f * lf : INFINITY, .mask = ~0u}};
                one.hit.geom_id = one.hit.prim_id = one.hit.inst_id = RP_INVALID_ID;
                if (!valid[q]) { /* lanes switched off are left as they were */
                    bad += p.geom_id[q] != RP_INVALID_ID || p.tfar[q] != one.ray.tfar;
                    continue;
                }
                total++;
                if (pass == 1) {
                    rp_occluded1(top, &one.ray);
                    bool o = one.ray.tfar == -INFINITY;
                    occluded += o;
                    bad += o != (p.tfar[q] == -INFINITY);
                    continue;
                }
                rp_intersect1(top, &one);
                hits += one.hit.geom_id != RP_INVALID_ID;
                bool ok = p.geom_id[q] == one.hit.geom_id && p.prim_id[q] == one.hit.prim_id && p.inst_id[q] == one.hit.inst_id;
                if (ok && one.hit.geom_id != RP_INVALID_ID && !(fabsf(p.tfar[q] - one.ray.tfar) <= 1e-5f * one.ray.tfar)) far++;
                bad += !ok;
            }
        }
    }
    CHECKF(hits > total / 16 && hits < total / 2, "accel %d: %u hits of %u coherent rays (want a mix)", kind, hits, total);
    CHECKF(occluded > 0, "accel %d: no coherent ray occluded", kind);
    CHECKF(bad <= total / 1000 + 1, "accel %d: %u of %u coherent packet rays differ from single rays", kind, bad, total);
    CHECKF(far == 0, "accel %d: %u coherent packet distances beyond 1e-5 of the single rays'", kind, far);
    rp_rayhit_n_free(dev, &p);
    rp_scene_release(top);
}

int main(void) {
    uint32_t n = rp_test_sanitized() ? 1024 : 8192;
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    float c[3] = {0.0f, 0.0f, 0.0f};
    test_mesh sph = test_mesh_sphere(24, 48, c, 0.5f), soup = test_mesh_soup(1500, 0.1f, 21);
    /* the object: a sphere (geom 0) and a soup (geom 1) */
    for (int kind = 0; kind < RP_ACCEL_COUNT; kind++) {
        rp_scene *obj = rp_scene_new(dev, &(rp_scene_desc){.accel = (rp_accel_type)kind});
        rp_geometry *g0 = mesh_geom(dev, &sph), *g1 = mesh_geom(dev, &soup);
        rp_scene_attach(obj, g0), rp_scene_attach(obj, g1);
        rp_geometry_release(g0), rp_geometry_release(g1);
        CHECK(rp_scene_commit(obj) == RP_ERROR_NONE);
        coherent_packets(dev, obj, kind, rp_test_sanitized() ? 16 : 64);
        /* two levels: a "group" of two objects, placed three times: instance ids 0..2 of the top */
        rp_scene *group = rp_scene_new(dev, NULL);
        float ga[12], gb[12];
        xfm_make(ga, 0.3f, 1.0f, 0.0f, 0.0f, 0.0f), xfm_make(gb, -0.7f, 0.6f, 1.2f, 0.1f, 0.2f);
        attach_instance(dev, group, obj, ga), attach_instance(dev, group, obj, gb);
        CHECK(rp_scene_commit(group) == RP_ERROR_NONE);
        rp_scene *top = rp_scene_new(dev, NULL);
        float tx[3][12];
        xfm_make(tx[0], 0.0f, 1.0f, -2.0f, 0.0f, 0.0f), xfm_make(tx[1], 1.1f, 0.8f, 0.5f, 1.5f, -0.3f);
        xfm_make(tx[2], 2.0f, 1.3f, 2.0f, -1.0f, 0.4f);
        for (int i = 0; i < 3; i++) CHECK(attach_instance(dev, top, group, tx[i]) == (uint32_t)i);
        CHECK(rp_scene_commit(top) == RP_ERROR_NONE);
        /* flattened: geometry 4 i + 2 j + k is mesh k of group member j of top instance i */
        rp_scene *flat = rp_scene_new(dev, NULL);
        test_mesh copies[12];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 2; j++) {
                float x[12];
                xfm_mul(tx[i], j ? gb : ga, x);
                copies[4 * i + 2 * j] = mapped(&sph, x), copies[4 * i + 2 * j + 1] = mapped(&soup, x);
                for (int k = 0; k < 2; k++) {
                    rp_geometry *g = mesh_geom(dev, &copies[4 * i + 2 * j + k]);
                    rp_scene_attach(flat, g);
                    rp_geometry_release(g);
                }
            }
        CHECK(rp_scene_commit(flat) == RP_ERROR_NONE);
        rp_ray *rays = malloc(sizeof(rp_ray) * n);
        test_rng r = {77};
        for (uint32_t i = 0; i < n; i++) {
            float o[3] = {-4.0f + 8.0f * test_rng_float(&r), -4.0f + 8.0f * test_rng_float(&r), 5.0f};
            float t[3] = {-3.0f + 6.0f * test_rng_float(&r), -2.5f + 5.0f * test_rng_float(&r), -0.5f + test_rng_float(&r)};
            rays[i] = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .dir_x = t[0] - o[0], .dir_y = t[1] - o[1],
                               .dir_z = t[2] - o[2], .tfar = i % 7 == 0 ? 0.8f : INFINITY, .mask = ~0u};
        }
        got *a = malloc(sizeof(got) * n), *b = malloc(sizeof(got) * n);
        trace(dev, flat, rays, n, b, 0);
        uint32_t hits = 0;
        for (uint32_t i = 0; i < n; i++) hits += b[i].geom != RP_INVALID_ID;
        CHECKF(hits > n / 8, "accel %d: %u of %u rays hit the flattened scene", kind, hits, n);
        for (int mode = 0; mode < 4; mode++) {
            trace(dev, top, rays, n, a, mode);
            uint32_t bad = 0, far = 0;
            for (uint32_t i = 0; i < n; i++) {
                bool ok = (a[i].geom == RP_INVALID_ID) == (b[i].geom == RP_INVALID_ID) && a[i].occ == b[i].occ;
                if (ok && b[i].geom != RP_INVALID_ID) {
                    uint32_t fi = b[i].geom / 4, fk = b[i].geom % 2;
                    ok = a[i].inst == fi && a[i].geom == fk && a[i].prim == b[i].prim;
                    if (ok && !(fabsf(a[i].t - b[i].t) <= 1e-4f * fabsf(b[i].t))) far++;
                }
                bad += !ok;
            }
            /* rays grazing an edge may fall on the other side of it after the two roundings */
            CHECKF(bad <= n / 1000 + 1, "accel %d mode %d: %u of %u rays differ from the flattened scene", kind, mode, bad, n);
            CHECKF(far == 0, "accel %d mode %d: %u distances beyond 1e-4", kind, mode, far);
        }
        free(a), free(b), free(rays);
        for (int i = 0; i < 12; i++) test_mesh_free(&copies[i]);
        rp_scene_release(flat);
        rp_scene_release(top);
        rp_scene_release(group);
        rp_scene_release(obj);
    }
    /* nesting: depth RP_MAX_INSTANCE_DEPTH commits, one more fails; a cycle fails */
    rp_scene *level = rp_scene_new(dev, NULL);
    rp_geometry *gm = mesh_geom(dev, &sph);
    rp_scene_attach(level, gm);
    rp_geometry_release(gm);
    CHECK(rp_scene_commit(level) == RP_ERROR_NONE);
    float id[12] = {1, 0, 0, 0.1f, 0, 1, 0, 0, 0, 0, 1, 0};
    for (int d = 1; d <= RP_MAX_INSTANCE_DEPTH + 1; d++) {
        rp_scene *up = rp_scene_new(dev, NULL);
        attach_instance(dev, up, level, id);
        rp_error e = rp_scene_commit(up);
        CHECKF((e == RP_ERROR_NONE) == (d <= RP_MAX_INSTANCE_DEPTH), "depth %d commits: %d", d, (int)e);
        rp_scene_release(level);
        level = up;
    }
    rp_scene_release(level);
    (void)rp_device_get_error(dev);
    rp_scene *a1 = rp_scene_new(dev, NULL), *b1 = rp_scene_new(dev, NULL);
    CHECK(rp_scene_commit(a1) == RP_ERROR_NONE);
    attach_instance(dev, b1, a1, id);
    CHECK(rp_scene_commit(b1) == RP_ERROR_NONE);
    uint32_t cyc = attach_instance(dev, a1, b1, id);
    CHECK(rp_scene_commit(a1) != RP_ERROR_NONE);
    rp_scene_detach(a1, cyc); /* breaks the cycle of references, so both are freed */
    rp_scene_release(b1), rp_scene_release(a1);
    float singular[12] = {0};
    rp_geometry *gi = rp_geometry_new(dev, RP_GEOMETRY_INSTANCE);
    (void)rp_device_get_error(dev);
    rp_scene *e = rp_scene_new(dev, NULL);
    rp_geometry_set_instance(gi, e, singular);
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_ARGUMENT);
    rp_geometry_release(gi), rp_scene_release(e);
    test_mesh_free(&sph), test_mesh_free(&soup);
    rp_device_release(dev);
    return RP_TEST_END();
}
