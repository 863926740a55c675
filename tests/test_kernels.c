// rp-test: labels=core timeout=900
/* Every traversal kernel (each ISA, each BVH width, single rays, 4/8/16-ray packets, the array
 * call) against a brute-force scalar reference, on random rays over generated meshes and over the
 * real bunny and conference meshes: identical geom_id and prim_id, t within 1e-5 relative. */
#include <math.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "raypack_io.h"
#include "rp_test.h"
#include "ray_gen.h"

static bool same_hit(ref_hit ref, uint32_t geom, uint32_t prim, float t) {
    if (ref.prim == RP_INVALID_ID) return geom == RP_INVALID_ID;
    return geom == 0 && prim == ref.prim && fabsf(t - ref.t) <= 1e-5f * fabsf(ref.t);
}

#define CHECK_PACKET(W)                                                                                   \
    for (uint32_t base = 0; base + W <= n; base += W) {                                                  \
        rp_rayhit##W p;                                                                                   \
        rp_ray##W sh;                                                                                     \
        int32_t valid[W];                                                                                 \
        for (int i = 0; i < W; i++) {                                                                     \
            const rp_ray *r = &rays[base + (uint32_t)i];                                                  \
            valid[i] = (i % 5 == 4) ? 0 : -1; /* some dead lanes: must stay untouched */                 \
            p.ray.org_x[i] = r->org_x, p.ray.org_y[i] = r->org_y, p.ray.org_z[i] = r->org_z;              \
            p.ray.dir_x[i] = r->dir_x, p.ray.dir_y[i] = r->dir_y, p.ray.dir_z[i] = r->dir_z;              \
            p.ray.tnear[i] = r->tnear, p.ray.tfar[i] = r->tfar, p.ray.mask[i] = r->mask;                  \
            p.ray.time[i] = 0, p.ray.id[i] = 0, p.ray.flags[i] = 0;                                        \
            p.hit.geom_id[i] = RP_INVALID_ID, p.hit.prim_id[i] = 12345u;                                  \
            sh.org_x[i] = r->org_x, sh.org_y[i] = r->org_y, sh.org_z[i] = r->org_z;                       \
            sh.dir_x[i] = r->dir_x, sh.dir_y[i] = r->dir_y, sh.dir_z[i] = r->dir_z;                       \
            sh.tnear[i] = r->tnear, sh.tfar[i] = r->tfar, sh.mask[i] = r->mask;                           \
        }                                                                                                 \
        rp_intersect##W(scene, valid, &p);                                                                \
        rp_occluded##W(scene, valid, &sh);                                                                \
        for (int i = 0; i < W; i++) {                                                                     \
            ref_hit rh = refs[base + (uint32_t)i];                                                        \
            if (!valid[i]) {                                                                              \
                bad_packet += p.hit.geom_id[i] != RP_INVALID_ID || p.hit.prim_id[i] != 12345u ||          \
                              p.ray.tfar[i] != rays[base + (uint32_t)i].tfar ||                           \
                              sh.tfar[i] != rays[base + (uint32_t)i].tfar;                                \
                continue;                                                                                 \
            }                                                                                             \
            bad_packet += !same_hit(rh, p.hit.geom_id[i], p.hit.prim_id[i], p.ray.tfar[i]);               \
            bad_occl += (rh.prim != RP_INVALID_ID) != (sh.tfar[i] == -INFINITY);                          \
        }                                                                                                 \
    }

/* Runs every query form on every device configuration against the reference hits. */
static void check_mesh(const char *name, const test_mesh *m, uint32_t n) {
    rp_ray *rays = malloc(sizeof(rp_ray) * n);
    ref_hit *refs = malloc(sizeof(ref_hit) * n);
    rp_rayhit *arr = malloc(sizeof(rp_rayhit) * n);
    make_rays(m, rays, n, 12345);
    uint32_t hits = 0;
    for (uint32_t i = 0; i < n; i++) {
        refs[i] = brute_force(m, &rays[i]);
        hits += refs[i].prim != RP_INVALID_ID;
    }
    CHECKF(hits > n / 8, "%s: only %u of %u reference rays hit", name, hits, n);
    int isas[4] = {1, 4, 8, 16};
    int widths[3] = {4, 8, 16};
    for (int ii = 0; ii < 4; ii++) {
        if (isas[ii] > sys_cpu_simd_width()) continue;
        rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2, .isa = isas[ii]});
        CHECK(dev != NULL);
        if (!dev) continue;
        for (int wi = 0; wi < 3; wi++) {
            rp_scene *scene = rp_scene_new(dev, &(rp_scene_desc){.bvh_width = widths[wi]});
            rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
            rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m->v, 0, 0, m->nv);
            rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, m->idx, 0, 0, m->nt);
            rp_geometry_commit(g);
            rp_scene_attach(scene, g);
            rp_geometry_release(g);
            CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
            uint32_t bad1 = 0, bad_occl1 = 0, bad_packet = 0, bad_occl = 0, bad_arr = 0;
            for (uint32_t i = 0; i < n; i++) {
                rp_rayhit rh = {.ray = rays[i]};
                rh.hit.geom_id = RP_INVALID_ID;
                rp_intersect1(scene, &rh);
                if (!same_hit(refs[i], rh.hit.geom_id, rh.hit.prim_id, rh.ray.tfar)) {
                    bad1++;
                    if (getenv("RP_TEST_VERBOSE"))
                        fprintf(stderr, "ray %u: ref prim %u t %.9g, got geom %u prim %u t %.9g\n", i, refs[i].prim,
                                (double)refs[i].t, rh.hit.geom_id, rh.hit.prim_id, (double)rh.ray.tfar);
                }
                rp_ray sr = rays[i];
                rp_occluded1(scene, &sr);
                bad_occl1 += (refs[i].prim != RP_INVALID_ID) != (sr.tfar == -INFINITY);
                arr[i] = (rp_rayhit){.ray = rays[i]};
                arr[i].hit.geom_id = RP_INVALID_ID;
            }
            CHECK_PACKET(4)
            CHECK_PACKET(8)
            CHECK_PACKET(16)
            rp_intersect_array(scene, arr, n, RP_QUERY_COHERENT);
            for (uint32_t i = 0; i < n; i++) bad_arr += !same_hit(refs[i], arr[i].hit.geom_id, arr[i].hit.prim_id, arr[i].ray.tfar);
            CHECKF(bad1 == 0, "%s isa %d width %d: intersect1 %u of %u differ", name, isas[ii], widths[wi], bad1, n);
            CHECKF(bad_occl1 == 0, "%s isa %d width %d: occluded1 %u differ", name, isas[ii], widths[wi], bad_occl1);
            CHECKF(bad_packet == 0, "%s isa %d width %d: packets %u differ", name, isas[ii], widths[wi], bad_packet);
            CHECKF(bad_occl == 0, "%s isa %d width %d: packet occlusion %u differ", name, isas[ii], widths[wi], bad_occl);
            CHECKF(bad_arr == 0, "%s isa %d width %d: array %u differ", name, isas[ii], widths[wi], bad_arr);
            CHECK(rp_device_get_error(dev) == RP_ERROR_NONE);
            rp_scene_release(scene);
        }
        rp_device_release(dev);
    }
    printf("%s: %u triangles, %u rays, %u hit\n", name, m->nt, n, hits);
    free(rays);
    free(refs);
    free(arr);
}

/* A shared scene through the loader, as one indexed mesh. */
static bool load_mesh(const char *file, test_mesh *m) {
    char path[1024], err[512];
    if (!rp_test_scene(file, path, sizeof path)) return false;
    rp_scene_data sd;
    if (!rp_scene_data_load(path, &sd, err, sizeof err)) {
        fprintf(stderr, "%s\n", err);
        return false;
    }
    m->nv = (uint32_t)sd.vertex_count;
    m->nt = (uint32_t)sd.triangle_count;
    m->v = malloc(sizeof(float) * 3 * m->nv);
    m->idx = malloc(sizeof(uint32_t) * 3 * m->nt);
    memcpy(m->v, sd.positions, sizeof(float) * 3 * m->nv);
    memcpy(m->idx, sd.indices, sizeof(uint32_t) * 3 * m->nt);
    rp_scene_data_free(&sd);
    return true;
}

int main(void) {
    bool small = rp_test_sanitized();
    test_mesh soup = test_mesh_soup(small ? 2000 : 20000, 0.05f, 7);
    check_mesh("soup", &soup, small ? 400 : 4000);
    /* duplicates and zero-area triangles: the tie-break must pick the lowest prim id */
    for (uint32_t t = 0; t < soup.nt / 10; t++) {
        memcpy(&soup.v[9 * (t + soup.nt / 2)], &soup.v[9 * t], 9 * sizeof(float));
        if (t % 3 == 0) memcpy(&soup.v[9 * t + 3], &soup.v[9 * t], 3 * sizeof(float)); /* v1 = v0 */
    }
    check_mesh("soup with duplicates", &soup, small ? 400 : 4000);
    test_mesh_free(&soup);
    float c[3] = {0.1f, -0.2f, 0.3f};
    test_mesh sph = test_mesh_sphere(40, 80, c, 1.0f);
    check_mesh("sphere", &sph, small ? 400 : 4000);
    test_mesh_free(&sph);
    test_mesh bunny = {0}, conf = {0};
    bool ok = load_mesh("stanford_bunny_bun_zipper.ply.gz", &bunny);
    CHECKF(ok && bunny.nt == 69451, "bunny loads with 69451 triangles");
    if (ok) check_mesh("bunny", &bunny, small ? 100 : 2000);
    test_mesh_free(&bunny);
    if (!small) {
        ok = load_mesh("conference_geom.obj.gz", &conf);
        CHECKF(ok && conf.nt == 331179, "conference loads with 331179 triangles");
        if (ok) check_mesh("conference", &conf, 600);
        test_mesh_free(&conf);
    }
    return RP_TEST_END();
}
