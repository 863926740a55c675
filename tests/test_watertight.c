// rp-test: labels=core timeout=600
/* Watertightness (Woop, Benthin, Wald 2013): rays aimed exactly at the shared edges and vertices of
 * a closed tessellated sphere, from inside and from outside, near the origin and offset by 1e5,
 * through single rays and 16-ray packets: every one must hit (0 leaks in 10^5 rays). */
#include <math.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "rp_test.h"

static void aim(const test_mesh *m, test_rng *g, const float c[3], bool inside, rp_ray *r) {
    uint32_t t = test_rng_u32(g) % m->nt, e = test_rng_u32(g) % 3;
    const float *a = &m->v[3 * m->idx[3 * t + e]], *b = &m->v[3 * m->idx[3 * t + (e + 1) % 3]];
    /* a vertex, the midpoint of an edge, or a random point of an edge */
    uint32_t kind = test_rng_u32(g) % 3;
    float s = kind == 0 ? 0.0f : kind == 1 ? 0.5f : test_rng_float(g);
    float p[3], o[3];
    for (int k = 0; k < 3; k++) p[k] = a[k] + s * (b[k] - a[k]);
    if (inside) {
        for (int k = 0; k < 3; k++) o[k] = c[k] + (test_rng_float(g) - 0.5f) * 0.6f;
    } else {
        float d[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
        for (int k = 0; k < 3; k++) o[k] = p[k] + d[k] * 2.0f + (test_rng_float(g) - 0.5f) * 1.0f;
    }
    *r = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .dir_x = p[0] - o[0], .dir_y = p[1] - o[1],
                  .dir_z = p[2] - o[2], .tnear = 0.0f, .tfar = INFINITY, .mask = ~0u};
}

static void run(rp_device *dev, const float c[3], uint32_t n) {
    test_mesh m = test_mesh_sphere(64, 128, c, 1.0f);
    rp_scene *scene = rp_scene_new(dev, NULL);
    rp_geometry *geo = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(geo, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m.v, 0, 0, m.nv);
    rp_geometry_set_buffer(geo, RP_BUFFER_INDEX, RP_FORMAT_UINT3, m.idx, 0, 0, m.nt);
    rp_scene_attach(scene, geo);
    rp_geometry_release(geo);
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    test_rng g = {99};
    uint32_t leaks1 = 0, leaks16 = 0, leaks_occ = 0;
    for (uint32_t base = 0; base < n; base += 16) {
        rp_rayhit16 p;
        rp_ray16 sh;
        int32_t valid[16];
        for (int i = 0; i < 16; i++) {
            rp_ray r;
            aim(&m, &g, c, (base / 16) % 2 == 0, &r);
            rp_rayhit rh = {.ray = r};
            rh.hit.geom_id = RP_INVALID_ID;
            rp_intersect1(scene, &rh);
            leaks1 += rh.hit.geom_id == RP_INVALID_ID;
            valid[i] = -1;
            p.ray.org_x[i] = sh.org_x[i] = r.org_x, p.ray.org_y[i] = sh.org_y[i] = r.org_y;
            p.ray.org_z[i] = sh.org_z[i] = r.org_z, p.ray.dir_x[i] = sh.dir_x[i] = r.dir_x;
            p.ray.dir_y[i] = sh.dir_y[i] = r.dir_y, p.ray.dir_z[i] = sh.dir_z[i] = r.dir_z;
            p.ray.tnear[i] = sh.tnear[i] = 0.0f, p.ray.tfar[i] = sh.tfar[i] = INFINITY;
            p.ray.mask[i] = sh.mask[i] = ~0u;
            p.hit.geom_id[i] = RP_INVALID_ID;
        }
        rp_intersect16(scene, valid, &p);
        rp_occluded16(scene, valid, &sh);
        for (int i = 0; i < 16; i++) {
            leaks16 += p.hit.geom_id[i] == RP_INVALID_ID;
            leaks_occ += sh.tfar[i] != -INFINITY;
        }
    }
    printf("sphere at %g: %u rays, leaks: single %u, packet %u, occlusion %u\n", (double)c[0], n, leaks1, leaks16, leaks_occ);
    CHECKF(leaks1 == 0, "centre %g: %u single-ray leaks", (double)c[0], leaks1);
    CHECKF(leaks16 == 0, "centre %g: %u packet leaks", (double)c[0], leaks16);
    CHECKF(leaks_occ == 0, "centre %g: %u occlusion leaks", (double)c[0], leaks_occ);
    rp_scene_release(scene);
    test_mesh_free(&m);
}

int main(void) {
    uint32_t n = rp_test_sanitized() ? 10000 : 100000;
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    float c0[3] = {0.0f, 0.0f, 0.0f}, c1[3] = {1e5f, 1e5f, 1e5f}, c2[3] = {-1e5f, 3.0f, 1e5f};
    run(dev, c0, n);
    run(dev, c1, n);
    run(dev, c2, n);
    rp_device_release(dev);
    return RP_TEST_END();
}
