// rp-test: labels=core timeout=600
/* The kd-tree, the BIH and the uniform grid (rp_scene_desc.accel) against a brute-force reference and against the
 * BVH, every query kind: intersect / occluded of single rays, 4/8/16-ray packets, n x n packets
 * (8x8, 16x16, every traversal) and arrays (both hints), on random rays over generated meshes
 * (soups with duplicates and zero-area triangles, axis-aligned boxes, a sphere mesh, a mesh plus
 * spheres) and the real cornell box, teapot and bunny: the same (geom, prim) as brute force and
 * bit for bit the BVH's distance, barycentrics and normal. */
#include <math.h>

#include "mesh_gen.h"
#include "query_got.h"
#include "raypack.h"
#include "raypack_io.h"
#include "rp_test.h"
#include "ray_gen.h"

/* n x n packets of consecutive rays (their order in the packet: rp_packet_n_index's). */
static void trace_n(rp_device *dev, rp_scene *s, uint32_t side, rp_traversal trav, const rp_ray *rays, uint32_t n,
                    got *out) {
    rp_rayhit_n p;
    if (!rp_rayhit_n_alloc(dev, side, &p)) return;
    uint32_t per = side * side;
    float *keep = malloc(sizeof(float) * per);
    for (uint32_t base = 0; base + per <= n; base += per) {
        for (uint32_t i = 0; i < per; i++) {
            const rp_ray *r = &rays[base + i];
            p.org_x[i] = r->org_x, p.org_y[i] = r->org_y, p.org_z[i] = r->org_z;
            p.dir_x[i] = r->dir_x, p.dir_y[i] = r->dir_y, p.dir_z[i] = r->dir_z;
            p.tnear[i] = r->tnear, p.tfar[i] = r->tfar, p.geom_id[i] = RP_INVALID_ID;
        }
        rp_query_n_desc d = {.traversal = trav};
        rp_intersect_n(s, &d, &p);
        for (uint32_t i = 0; i < per; i++)
            out[base + i] = (got){p.tfar[i], p.u[i], p.v[i], {p.Ng_x[i], p.Ng_y[i], p.Ng_z[i]}, p.geom_id[i], p.prim_id[i], 0};
        for (uint32_t i = 0; i < per; i++) p.tfar[i] = rays[base + i].tfar;
        rp_occluded_n(s, &d, &p);
        for (uint32_t i = 0; i < per; i++) out[base + i].occluded = p.tfar[i] == -INFINITY;
    }
    free(keep);
    rp_rayhit_n_free(dev, &p);
}

/* A scene of the mesh (geometry 0) and, when given, spheres (geometry 1); density: the grid's. */
static rp_scene *make_scene_d(rp_device *dev, rp_accel_type accel, const test_mesh *m, const float *spheres,
                              uint32_t nspheres, float density) {
    rp_scene *s = rp_scene_new(dev, &(rp_scene_desc){.accel = accel, .grid_density = density});
    rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m->v, 0, 0, m->nv);
    rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, m->idx, 0, 0, m->nt);
    rp_geometry_commit(g);
    rp_scene_attach(s, g);
    rp_geometry_release(g);
    if (nspheres) {
        rp_geometry *sp = rp_geometry_new(dev, RP_GEOMETRY_SPHERE);
        rp_geometry_set_buffer(sp, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, spheres, 0, 0, nspheres);
        rp_geometry_commit(sp);
        rp_scene_attach(s, sp);
        rp_geometry_release(sp);
    }
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    return s;
}

static rp_scene *make_scene(rp_device *dev, rp_accel_type accel, const test_mesh *m, const float *spheres,
                            uint32_t nspheres) {
    return make_scene_d(dev, accel, m, spheres, nspheres, 0.0f);
}

/* Every query kind of every structure against the BVH's single rays (bit for bit) and, when
 * brute is set, the BVH's against brute force. */
static void check_mesh(const char *name, const test_mesh *m, uint32_t n, bool brute, const float *spheres,
                       uint32_t nspheres) {
    n = n / 256 * 256; /* whole 16x16 packets */
    rp_ray *rays = malloc(sizeof(rp_ray) * n);
    got *ref = malloc(sizeof(got) * n), *g = malloc(sizeof(got) * n);
    make_rays(m, rays, n, 4242);
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    rp_scene *bvh = make_scene(dev, RP_ACCEL_BVH, m, spheres, nspheres);
    uint32_t hits = 0, bad_brute = 0;
    for (uint32_t i = 0; i < n; i++) {
        trace1(bvh, &rays[i], &ref[i]);
        hits += ref[i].geom != RP_INVALID_ID;
        if (brute) {
            ref_hit b = brute_force(m, &rays[i]);
            bool ok = b.prim == RP_INVALID_ID ? ref[i].geom == RP_INVALID_ID
                                              : ref[i].geom == 0 && ref[i].prim == b.prim && ref[i].t == b.t;
            bad_brute += !ok;
        }
    }
    CHECKF(hits > n / 8, "%s: only %u of %u rays hit", name, hits, n);
    CHECKF(bad_brute == 0, "%s: the BVH differs from brute force on %u rays", name, bad_brute);
    for (int kind = RP_ACCEL_KDTREE; kind < RP_ACCEL_COUNT; kind++) {
        const char *an = rp_accel_name((rp_accel_type)kind);
        rp_scene *s = make_scene(dev, (rp_accel_type)kind, m, spheres, nspheres);
        rp_scene_stats st;
        rp_scene_get_stats(s, &st);
        CHECKF(st.accel == (rp_accel_type)kind && st.triangles > 0 && st.leaves > 0 && st.tri_refs >= st.triangles &&
                   st.bytes > 0, "%s %s: stats (accel %d, %llu refs)", name, an, (int)st.accel,
               (unsigned long long)st.tri_refs);
        uint32_t bad[12] = {0};
        for (uint32_t i = 0; i < n; i++) {
            trace1(s, &rays[i], &g[i]);
            bad[0] += !same_got(&g[i], &ref[i]);
            bad[1] += g[i].occluded != (ref[i].geom != RP_INVALID_ID);
            if (getenv("RP_TEST_VERBOSE") && !same_got(&g[i], &ref[i]))
                fprintf(stderr, "%s %s ray %u: bvh %u/%u t %.9g, got %u/%u t %.9g\n", name, an, i, ref[i].geom,
                        ref[i].prim, (double)ref[i].t, g[i].geom, g[i].prim, (double)g[i].t);
        }
        void (*packets[3])(rp_scene *, const rp_ray *, uint32_t, got *) = {trace_4, trace_8, trace_16};
        for (int w = 0; w < 3; w++) {
            packets[w](s, rays, n, g);
            for (uint32_t i = 0; i < n; i++) {
                if (g[i].geom == 0xDEADu) continue;
                bool b = g[i].geom == 0xBADu || !same_got(&g[i], &ref[i]) ||
                         g[i].occluded != (ref[i].geom != RP_INVALID_ID);
                if (b && getenv("RP_TEST_VERBOSE"))
                    fprintf(stderr, "%s %s packet ray %u: bvh %u/%u t %.9g occl %d, got %u/%u t %.9g occl %d\n", name, an, i,
                            ref[i].geom, ref[i].prim, (double)ref[i].t, ref[i].geom != RP_INVALID_ID, g[i].geom, g[i].prim,
                            (double)g[i].t, g[i].occluded);
                bad[2 + w] += b;
            }
        }
        rp_traversal trav[2] = {RP_TRAVERSAL_AUTO, RP_TRAVERSAL_SINGLE};
        uint32_t sides[2] = {8, 16};
        for (int k = 0; k < 2; k++) {
            trace_n(dev, s, sides[k], trav[k], rays, n, g);
            for (uint32_t i = 0; i < n; i++)
                bad[5 + k] += !same_got(&g[i], &ref[i]) || g[i].occluded != (ref[i].geom != RP_INVALID_ID);
        }
        for (int k = 0; k < 2; k++) {
            trace_array(s, rays, n, k ? RP_QUERY_COHERENT : RP_QUERY_INCOHERENT, g);
            for (uint32_t i = 0; i < n; i++)
                bad[7 + k] += !same_got(&g[i], &ref[i]) || g[i].occluded != (ref[i].geom != RP_INVALID_ID);
        }
        static const char *what[9] = {"intersect1", "occluded1", "packet4", "packet8", "packet16", "8x8 auto",
                                      "16x16 single", "array", "array coherent"};
        for (int k = 0; k < 9; k++) CHECKF(bad[k] == 0, "%s %s: %s differs from the BVH on %u of %u rays", name, an, what[k], bad[k], n);
        CHECK(rp_device_get_error(dev) == RP_ERROR_NONE);
        printf("%s %s: %llu nodes, %llu leaves, depth %u, %llu refs for %llu triangles, %.2f ms\n", name, an,
               (unsigned long long)st.binary_nodes, (unsigned long long)st.leaves, st.depth,
               (unsigned long long)st.tri_refs, (unsigned long long)st.triangles, st.build_ms);
        rp_scene_release(s);
    }
    printf("%s: %u triangles, %u spheres, %u rays, %u hit\n", name, m->nt, nspheres, n, hits);
    rp_scene_release(bvh);
    rp_device_release(dev);
    free(rays), free(ref), free(g);
}

/* Axis-aligned boxes on a grid, some touching, some coplanar: the kd-tree's planar events and
 * splits on the triangles' own planes. */
static test_mesh boxes_mesh(int per_side) {
    uint32_t nbox = (uint32_t)(per_side * per_side * per_side);
    test_mesh m = {malloc(sizeof(float) * 24 * nbox), malloc(sizeof(uint32_t) * 36 * nbox), 8 * nbox, 12 * nbox};
    static const uint32_t f[36] = {0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 4, 5, 0, 5, 1,
                                   2, 3, 7, 2, 7, 6, 0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3};
    uint32_t b = 0;
    for (int x = 0; x < per_side; x++)
        for (int y = 0; y < per_side; y++)
            for (int z = 0; z < per_side; z++, b++) {
                float lo[3] = {(float)x, (float)y, (float)z}, size = (x + y + z) % 3 == 0 ? 1.0f : 0.5f;
                for (uint32_t c = 0; c < 8; c++)
                    for (int a = 0; a < 3; a++) m.v[24 * b + 3 * c + (uint32_t)a] = lo[a] + (float)((c >> (2 - a)) & 1u) * size;
                for (int k = 0; k < 36; k++) m.idx[36 * b + (uint32_t)k] = 8 * b + f[k];
            }
    return m;
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

/* Rays the uniform grid's 3D-DDA finds hardest (the kind cycles with each 16-ray packet):
 * 0: axis-parallel ones (two direction components exactly 0) from origins on the vertices'
 * coordinates, so on triangles' edges and planes and, for the boxes, on voxel planes; 1 / 2:
 * segments starting deep inside (tnear > 0) or ending there; 3: rays from 40 times the scene's
 * size away; 4: make_rays' kinds. (Rays in a triangle's plane are left out: the watertight test
 * gives them distances that are not where the ray meets the triangle, so which of them a
 * traversal finds depends on its order.) */
#define GRID_RAY_KINDS 5
static uint32_t grid_ray_kind(uint32_t i) { return (i / 16) % GRID_RAY_KINDS; }

static void make_grid_rays(const test_mesh *m, rp_ray *rays, uint32_t n, uint64_t seed) {
    make_rays(m, rays, n, seed);
    test_rng g = {seed * 31u + 7u};
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < m->nv; i++)
        for (int a = 0; a < 3; a++) lo[a] = fminf(lo[a], m->v[3 * i + a]), hi[a] = fmaxf(hi[a], m->v[3 * i + a]);
    for (uint32_t i = 0; i < n; i++) {
        rp_ray *r = &rays[i];
        uint32_t kind = grid_ray_kind(i);
        if (kind == 4) continue; /* make_rays' */
        const float *v = &m->v[3 * m->idx[3 * (test_rng_u32(&g) % m->nt) + test_rng_u32(&g) % 3]];
        float o[3], d[3] = {0.0f, 0.0f, 0.0f};
        float tnear = 0.0f, tfar = INFINITY;
        if (kind == 0) { /* axis-parallel through a vertex's coordinates, from outside or inside */
            int a = (int)(test_rng_u32(&g) % 3);
            float sgn = test_rng_u32(&g) & 1u ? 1.0f : -1.0f;
            for (int k = 0; k < 3; k++) o[k] = v[k];
            o[a] = test_rng_u32(&g) & 1u ? (sgn > 0 ? lo[a] - 1.0f : hi[a] + 1.0f) : v[a];
            d[a] = sgn;
        } else if (kind == 1 || kind == 2) { /* a segment inside: starts (1) or ends (2) within the grid */
            for (int k = 0; k < 3; k++) o[k] = lo[k] - (hi[k] - lo[k]) * 0.25f, d[k] = v[k] - o[k];
            float len = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            for (int k = 0; k < 3; k++) d[k] = d[k] / len + (test_rng_float(&g) - 0.5f) * 0.1f;
            float mid = len * (0.3f + 0.9f * test_rng_float(&g));
            if (kind == 1) tnear = mid;
            else tfar = mid;
        } else { /* from far away, aimed at a vertex */
            for (int k = 0; k < 3; k++) {
                o[k] = 0.5f * (lo[k] + hi[k]) + 40.0f * (hi[k] - lo[k] + 1e-3f) * (test_rng_float(&g) - 0.5f);
                d[k] = v[k] - o[k];
            }
        }
        *r = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .tnear = tnear, .dir_x = d[0], .dir_y = d[1],
                      .dir_z = d[2], .tfar = tfar, .mask = 0xFFFFFFFFu};
    }
}

/* The same triangle at the same distance, or both a miss. */
static bool same_hit(const got *a, const got *b) {
    if (a->geom != b->geom) return false;
    return a->geom == RP_INVALID_ID || (a->prim == b->prim && a->t == b->t);
}

/* A hit as brute force finds it (distance and triangle; the rest left 0). */
static got brute_got(const test_mesh *m, const rp_ray *r) {
    ref_hit b = brute_force(m, r);
    got g = {0};
    g.t = b.prim == RP_INVALID_ID ? r->tfar : b.t;
    g.geom = b.prim == RP_INVALID_ID ? RP_INVALID_ID : 0, g.prim = b.prim;
    g.occluded = b.prim != RP_INVALID_ID;
    return g;
}

/* The uniform grid at several resolutions (one voxel for many triangles up to many voxels per
 * triangle) on make_grid_rays' rays: single rays against the BVH bit for bit, except the
 * axis-parallel ones, which are checked against brute force (distance and triangle; the BVH must
 * give it too), the first brute_rays of them only on large meshes;
 * 16-ray packets, 16x16 packets and coherent arrays against the grid's single rays bit for bit. */
static void check_grid(const char *name, const test_mesh *m, uint32_t n, uint32_t brute_rays) {
    n = n / 256 * 256;
    rp_ray *rays = malloc(sizeof(rp_ray) * n);
    got *ref = malloc(sizeof(got) * n), *g = malloc(sizeof(got) * n), *one = malloc(sizeof(got) * n);
    bool *brute = calloc(n, sizeof(bool));
    make_grid_rays(m, rays, n, 777);
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    rp_scene *bvh = make_scene(dev, RP_ACCEL_BVH, m, NULL, 0);
    uint32_t hits = 0, brutes = 0, bvh_off = 0;
    for (uint32_t i = 0; i < n; i++) {
        trace1(bvh, &rays[i], &ref[i]);
        if (grid_ray_kind(i) == 0 && brutes < brute_rays) {
            got b = brute_got(m, &rays[i]);
            bvh_off += !same_hit(&ref[i], &b);
            if (!same_hit(&ref[i], &b) && getenv("RP_TEST_VERBOSE"))
                fprintf(stderr, "%s bvh ray %u o %.9g %.9g %.9g d %g %g %g: bvh %u/%u t %.9g, brute %u/%u t %.9g\n", name, i,
                        (double)rays[i].org_x, (double)rays[i].org_y, (double)rays[i].org_z, (double)rays[i].dir_x,
                        (double)rays[i].dir_y, (double)rays[i].dir_z, ref[i].geom, ref[i].prim, (double)ref[i].t, b.geom,
                        b.prim, (double)b.t);
            ref[i] = b, brute[i] = true, brutes++;
        }
        hits += ref[i].geom != RP_INVALID_ID;
    }
    CHECKF(hits > n / 8, "%s: only %u of %u rays hit", name, hits, n);
    /* the BVH itself, single rays and packets, on the same rays: axis-parallel rays through vertices
     * lie in box faces, which the kernels' slab test (a zero direction component taken as 1e-18)
     * left at t = 0 until bvh2_pad_boxes widened the boxes: 272 of these 832 rays on boxes, 21 of
     * 256 on the bunny missed their hits */
    CHECKF(bvh_off == 0, "%s: the BVH misses brute force's hit on %u of %u axis-parallel rays", name, bvh_off, brutes);
    {
        uint32_t bad[3] = {0};
        trace_16(bvh, rays, n, g);
        for (uint32_t i = 0; i < n; i++)
            bad[0] += g[i].geom != 0xDEADu &&
                      (g[i].geom == 0xBADu || (brute[i] ? !same_hit(&g[i], &ref[i]) : !same_got(&g[i], &ref[i])));
        trace_n(dev, bvh, 16, RP_TRAVERSAL_AUTO, rays, n, g);
        for (uint32_t i = 0; i < n; i++) bad[1] += brute[i] ? !same_hit(&g[i], &ref[i]) : !same_got(&g[i], &ref[i]);
        trace_array(bvh, rays, n, RP_QUERY_COHERENT, g);
        for (uint32_t i = 0; i < n; i++) bad[2] += brute[i] ? !same_hit(&g[i], &ref[i]) : !same_got(&g[i], &ref[i]);
        CHECKF(bad[0] + bad[1] + bad[2] == 0, "%s: BVH packet16 %u, 16x16 auto %u, coherent array %u rays differ", name,
               bad[0], bad[1], bad[2]);
    }
    /* the grid at four densities, then the kd-tree and the BIH on the same rays: their planes and
     * boxes lie on the vertices' coordinates too, so the axis-parallel rays run in their faces */
    static const struct { rp_accel_type accel; float density; } cases[6] = {
        {RP_ACCEL_GRID, 0.01f}, {RP_ACCEL_GRID, 0.5f}, {RP_ACCEL_GRID, 0.0f}, {RP_ACCEL_GRID, 24.0f},
        {RP_ACCEL_KDTREE, 0.0f}, {RP_ACCEL_BIH, 0.0f}};
    uint64_t voxels_prev = 0;
    for (int d = 0; d < 6; d++) {
        const char *an = rp_accel_name(cases[d].accel);
        double density = (double)cases[d].density;
        rp_scene *s = make_scene_d(dev, cases[d].accel, m, NULL, 0, cases[d].density);
        rp_scene_stats st;
        rp_scene_get_stats(s, &st);
        bool grid = cases[d].accel == RP_ACCEL_GRID;
        CHECKF(st.accel == cases[d].accel && (!grid || st.binary_nodes > voxels_prev) && st.tri_refs >= st.triangles,
               "%s %s density %g: %llu voxels after %llu, %llu refs", name, an, density,
               (unsigned long long)st.binary_nodes, (unsigned long long)voxels_prev, (unsigned long long)st.tri_refs);
        if (grid) voxels_prev = st.binary_nodes;
        uint32_t bad[4] = {0};
        for (uint32_t i = 0; i < n; i++) {
            trace1(s, &rays[i], &one[i]);
            bool b;
            if (brute[i])
                b = !same_hit(&one[i], &ref[i]) || one[i].occluded != ref[i].occluded;
            else if (grid_ray_kind(i) == 0)
                b = false; /* no reference: the packets below are checked against it */
            else
                b = !same_got(&one[i], &ref[i]) || one[i].occluded != (ref[i].geom != RP_INVALID_ID);
            bad[0] += b;
            if (b && getenv("RP_TEST_VERBOSE"))
                fprintf(stderr, "%s %s %g ray %u (kind %u): ref %u/%u t %.9g, got %u/%u t %.9g occl %d\n", name, an,
                        density, i, grid_ray_kind(i), ref[i].geom, ref[i].prim, (double)ref[i].t,
                        one[i].geom, one[i].prim, (double)one[i].t, one[i].occluded);
        }
        trace_16(s, rays, n, g);
        for (uint32_t i = 0; i < n; i++)
            bad[1] += g[i].geom != 0xDEADu && (g[i].geom == 0xBADu || !same_got(&g[i], &one[i]) ||
                                               g[i].occluded != one[i].occluded);
        trace_n(dev, s, 16, RP_TRAVERSAL_AUTO, rays, n, g);
        for (uint32_t i = 0; i < n; i++) bad[2] += !same_got(&g[i], &one[i]) || g[i].occluded != one[i].occluded;
        trace_array(s, rays, n, RP_QUERY_COHERENT, g);
        for (uint32_t i = 0; i < n; i++) bad[3] += !same_got(&g[i], &one[i]) || g[i].occluded != one[i].occluded;
        static const char *what[4] = {"single rays differ from the BVH (or brute force)",
                                      "packet16 differs from its single rays", "16x16 auto differs from its single rays",
                                      "array coherent differs from its single rays"};
        for (int k = 0; k < 4; k++)
            CHECKF(bad[k] == 0, "%s %s density %g: %s on %u of %u rays", name, an, density, what[k], bad[k], n);
        printf("%s %s density %g: %llu voxels or nodes, %llu not empty or leaves, %llu refs for %llu triangles, %.2f ms\n",
               name, an, density, (unsigned long long)st.binary_nodes, (unsigned long long)st.leaves,
               (unsigned long long)st.tri_refs, (unsigned long long)st.triangles, st.build_ms);
        rp_scene_release(s);
    }
    printf("%s: %u rays for the grid, %u hit; %u axis-parallel rays checked by brute force, the BVH differs on %u\n",
           name, n, hits, brutes, bvh_off);
    rp_scene_release(bvh);
    rp_device_release(dev);
    free(rays), free(ref), free(g), free(one), free(brute);
}

/* The grid's coherent packets (slice-wise walk, grid_packet) on camera rays: random cameras inside
 * and outside the scene, 64x64 pixels in rp_packet_n_index's order (each 16 rays a 4x4 tile), the
 * lanes of every other camera's packets shuffled and some of its rays cut short (tfar), and
 * shadow rays from a point light to the BVH's hits (one origin, ends spread over the image):
 * single rays, 16-ray packets and 16x16 packets of the grid against the BVH's single rays, bit
 * for bit, closest and any hit. */
static void check_grid_cameras(const char *name, const test_mesh *m, int cameras, uint64_t seed, int isa) {
    const uint32_t side = 64, n = side * side;
    rp_ray *rays = malloc(sizeof(rp_ray) * 2 * n);
    got *ref = malloc(sizeof(got) * 2 * n), *g = malloc(sizeof(got) * 2 * n);
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < m->nv; i++)
        for (int a = 0; a < 3; a++) lo[a] = fminf(lo[a], m->v[3 * i + a]), hi[a] = fmaxf(hi[a], m->v[3 * i + a]);
    float diag = sqrtf((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) + (hi[2] - lo[2]) * (hi[2] - lo[2]));
    /* isa 0: the widest the CPU has; else that ISA's kernels (the grid's traversal is compiled per
     * ISA, src/accel/grid/grid_trav.inc), when the CPU has it */
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2, .isa = isa});
    if (!dev) {
        free(rays), free(ref), free(g);
        return;
    }
    rp_scene *bvh = make_scene(dev, RP_ACCEL_BVH, m, NULL, 0);
    rp_scene *grid = make_scene(dev, RP_ACCEL_GRID, m, NULL, 0);
    test_rng rng = {seed};
    uint32_t bad[3] = {0}, hits = 0, total = 0;
    for (int c = 0; c < cameras; c++) {
        float eye[3], look[3], fwd[3], up[3] = {0.0f, 1.0f, 0.0f}, right[3], u[3];
        bool inside = c % 2 == 0;
        for (int a = 0; a < 3; a++) {
            float mid = 0.5f * (lo[a] + hi[a]), ext = hi[a] - lo[a];
            look[a] = lo[a] + ext * (0.1f + 0.8f * test_rng_float(&rng));
            eye[a] = inside ? lo[a] + ext * (0.1f + 0.8f * test_rng_float(&rng))
                            : mid + diag * (test_rng_float(&rng) - 0.5f) * 2.0f;
        }
        if (!inside) /* outside the box: pushed out along the view */
            for (int a = 0; a < 3; a++) eye[a] += (eye[a] - look[a]) * 0.5f;
        float len = 0.0f;
        for (int a = 0; a < 3; a++) fwd[a] = look[a] - eye[a], len += fwd[a] * fwd[a];
        len = sqrtf(len);
        for (int a = 0; a < 3; a++) fwd[a] /= len;
        right[0] = fwd[1] * up[2] - fwd[2] * up[1], right[1] = fwd[2] * up[0] - fwd[0] * up[2],
        right[2] = fwd[0] * up[1] - fwd[1] * up[0];
        u[0] = right[1] * fwd[2] - right[2] * fwd[1], u[1] = right[2] * fwd[0] - right[0] * fwd[2],
        u[2] = right[0] * fwd[1] - right[1] * fwd[0];
        float scale = tanf((0.3f + 0.6f * test_rng_float(&rng)) * 0.5f * 3.14159265f * 0.5f);
        bool shuffle = c % 4 >= 2;
        for (uint32_t y = 0; y < side; y++)
            for (uint32_t x = 0; x < side; x++) {
                uint32_t q = ((y / 16) * (side / 16) + x / 16) * 256 + rp_packet_n_index(16, x % 16, y % 16);
                float px = ((float)x + 0.5f) / (float)side * 2.0f - 1.0f, py = ((float)y + 0.5f) / (float)side * 2.0f - 1.0f;
                float d[3];
                for (int a = 0; a < 3; a++) d[a] = fwd[a] + scale * (px * right[a] + py * u[a]);
                float tfar = shuffle && test_rng_u32(&rng) % 4 == 0 ? diag * test_rng_float(&rng) : INFINITY;
                rays[q] = (rp_ray){.org_x = eye[0], .org_y = eye[1], .org_z = eye[2], .dir_x = d[0], .dir_y = d[1],
                                   .dir_z = d[2], .tfar = tfar, .mask = 0xFFFFFFFFu};
            }
        if (shuffle) /* the lanes of each 16-ray packet in a random order */
            for (uint32_t b = 0; b < n; b += 16)
                for (uint32_t i = 15; i > 0; i--) {
                    uint32_t j = test_rng_u32(&rng) % (i + 1);
                    rp_ray t = rays[b + i];
                    rays[b + i] = rays[b + j], rays[b + j] = t;
                }
        for (uint32_t i = 0; i < n; i++) trace1(bvh, &rays[i], &ref[i]);
        /* shadow rays: from a light near the eye to each primary hit (misses: along the ray) */
        float light[3];
        for (int a = 0; a < 3; a++) light[a] = eye[a] + 0.02f * diag * (u[a] - right[a]);
        for (uint32_t i = 0; i < n; i++) {
            const rp_ray *r = &rays[i];
            float t = ref[i].geom != RP_INVALID_ID ? ref[i].t : diag;
            float p[3] = {r->org_x + r->dir_x * t, r->org_y + r->dir_y * t, r->org_z + r->dir_z * t};
            rays[n + i] = (rp_ray){.org_x = light[0], .org_y = light[1], .org_z = light[2], .dir_x = p[0] - light[0],
                                   .dir_y = p[1] - light[1], .dir_z = p[2] - light[2], .tfar = 0.999f, .mask = 0xFFFFFFFFu};
            trace1(bvh, &rays[n + i], &ref[n + i]);
        }
        for (uint32_t i = 0; i < 2 * n; i++) {
            trace1(grid, &rays[i], &g[i]);
            bad[0] += !same_got(&g[i], &ref[i]) || g[i].occluded != ref[i].occluded;
            hits += ref[i].geom != RP_INVALID_ID;
        }
        trace_16(grid, rays, 2 * n, g);
        for (uint32_t i = 0; i < 2 * n; i++) {
            bool b = g[i].geom != 0xDEADu && (g[i].geom == 0xBADu || !same_got(&g[i], &ref[i]) || g[i].occluded != ref[i].occluded);
            if (b && getenv("RP_TEST_VERBOSE"))
                fprintf(stderr, "%s camera %d packet16 ray %u: bvh %u/%u t %.9g occl %d, grid %u/%u t %.9g occl %d\n", name, c,
                        i, ref[i].geom, ref[i].prim, (double)ref[i].t, ref[i].occluded, g[i].geom, g[i].prim, (double)g[i].t,
                        g[i].occluded);
            bad[1] += b;
        }
        trace_n(dev, grid, 16, RP_TRAVERSAL_AUTO, rays, 2 * n, g);
        for (uint32_t i = 0; i < 2 * n; i++) bad[2] += !same_got(&g[i], &ref[i]) || g[i].occluded != ref[i].occluded;
        total += 2 * n;
    }
    CHECKF(hits > total / 8, "%s cameras: only %u of %u rays hit", name, hits, total);
    CHECKF(bad[0] + bad[1] + bad[2] == 0,
           "%s cameras, isa %d: the grid differs from the BVH: single %u, packet16 %u, 16x16 %u of %u", name,
           rp_device_isa(dev), bad[0], bad[1], bad[2], total);
    printf("%s: %d cameras, isa %d, %u camera and shadow rays, %u hit; the grid's single rays and packets give the BVH's "
           "hits\n", name, cameras, rp_device_isa(dev), total, hits);
    rp_scene_release(bvh);
    rp_scene_release(grid);
    rp_device_release(dev);
    free(rays), free(ref), free(g);
}

/* A flat scene: a 40 x 40 quad mesh in the plane z = 0.25 (the grid's box is a thin slab). */
static test_mesh flat_mesh(void) {
    const uint32_t q = 40;
    test_mesh m = {malloc(sizeof(float) * 3 * (q + 1) * (q + 1)), malloc(sizeof(uint32_t) * 6 * q * q), (q + 1) * (q + 1),
                   2 * q * q};
    for (uint32_t y = 0; y <= q; y++)
        for (uint32_t x = 0; x <= q; x++) {
            float *p = &m.v[3 * (y * (q + 1) + x)];
            p[0] = (float)x * 0.25f, p[1] = (float)y * 0.25f, p[2] = 0.25f;
        }
    for (uint32_t y = 0; y < q; y++)
        for (uint32_t x = 0; x < q; x++) {
            uint32_t a = y * (q + 1) + x, *t = &m.idx[6 * (y * q + x)];
            t[0] = a, t[1] = a + 1, t[2] = a + q + 2, t[3] = a, t[4] = a + q + 2, t[5] = a + q + 1;
        }
    return m;
}

int main(void) {
    bool small = rp_test_sanitized();
    test_mesh soup = test_mesh_soup(small ? 1000 : 5000, 0.08f, 11);
    check_mesh("soup", &soup, small ? 512 : 4096, true, NULL, 0);
    for (uint32_t t = 0; t < soup.nt / 10; t++) {
        memcpy(&soup.v[9 * (t + soup.nt / 2)], &soup.v[9 * t], 9 * sizeof(float));
        if (t % 3 == 0) memcpy(&soup.v[9 * t + 3], &soup.v[9 * t], 3 * sizeof(float)); /* v1 = v0 */
    }
    check_mesh("soup with duplicates", &soup, small ? 512 : 4096, true, NULL, 0);
    float spheres[4 * 8];
    for (int i = 0; i < 8; i++)
        spheres[4 * i] = 0.1f * (float)i, spheres[4 * i + 1] = 0.5f, spheres[4 * i + 2] = 0.5f, spheres[4 * i + 3] = 0.05f;
    check_mesh("soup and spheres", &soup, small ? 512 : 2048, false, spheres, 8);
    test_mesh_free(&soup);
    /* the BIH's radix build: thousands of copies of three triangles (equal centroids, so equal
     * codes: leaves of hundreds), past the size where the build runs on all threads; and a scene
     * flat in z (an axis that is never halved) */
    test_mesh stack = test_mesh_soup(6000, 0.3f, 5);
    for (uint32_t t = 3; t < stack.nt; t++) memcpy(&stack.v[9 * t], &stack.v[9 * (t % 3)], 9 * sizeof(float));
    check_mesh("three triangles stacked", &stack, small ? 512 : 2048, true, NULL, 0);
    test_mesh_free(&stack);
    test_mesh flat = flat_mesh();
    check_mesh("flat", &flat, small ? 512 : 2048, true, NULL, 0);
    test_mesh_free(&flat);
    test_mesh bx = boxes_mesh(small ? 4 : 7);
    check_mesh("boxes", &bx, small ? 512 : 4096, true, NULL, 0);
    test_mesh_free(&bx);
    float c[3] = {0.1f, -0.2f, 0.3f};
    test_mesh sph = test_mesh_sphere(30, 60, c, 1.0f);
    check_mesh("sphere", &sph, small ? 512 : 4096, true, NULL, 0);
    test_mesh_free(&sph);
    static const char *files[3] = {"cornell_box/cornell_box.obj", "spd_teapot.nff.gz", "stanford_bunny_bun_zipper.ply.gz"};
    for (int f = 0; f < 3; f++) {
        test_mesh m = {0};
        bool ok = load_mesh(files[f], &m);
        CHECKF(ok && m.nt > 0, "%s loads", files[f]);
        if (ok) check_mesh(files[f], &m, small ? 1024 : (f == 2 ? 16384 : 8192), f < 2, NULL, 0);
        test_mesh_free(&m);
    }
    /* the grid's own cases: its 3D-DDA on axis-parallel, in-plane, clipped and distant rays, at
     * several resolutions, on boxes on the voxel planes, a flat scene, the bunny, and rooms with
     * large empty volumes and large triangles (sponza, and the conference outside the sanitizers) */
    test_mesh gb = boxes_mesh(small ? 3 : 5);
    check_grid("boxes", &gb, small ? 512 : 4096, 4096);
    test_mesh_free(&gb);
    test_mesh fl = flat_mesh();
    check_grid("flat", &fl, small ? 512 : 4096, 4096);
    test_mesh_free(&fl);
    static const char *grid_files[3] = {"stanford_bunny_bun_zipper.ply.gz", "dabrovic_sponza.obj.gz",
                                        "conference_geom.obj.gz"};
    for (int f = 0; f < (small ? 2 : 3); f++) {
        test_mesh m = {0};
        bool ok = load_mesh(grid_files[f], &m);
        CHECKF(ok && m.nt > 0, "%s loads", grid_files[f]);
        if (ok) check_grid(grid_files[f], &m, small ? 512 : 8192, small ? 16 : 256);
        if (ok) check_grid_cameras(grid_files[f], &m, small ? 2 : 8, 99 + (uint64_t)f, 0);
        /* the grid's other ISAs' kernels (AVX2, SSE4.2, scalar) on the bunny and sponza */
        for (int isa = 8; ok && f < 2 && isa >= 1; isa = isa == 4 ? 1 : isa / 2)
            check_grid_cameras(grid_files[f], &m, 2, 7 + (uint64_t)(f * 16 + isa), isa);
        test_mesh_free(&m);
    }
    /* a scene without triangles, and a bad accel value */
    rp_device *dev = rp_device_new(NULL);
    rp_scene *s = rp_scene_new(dev, &(rp_scene_desc){.accel = RP_ACCEL_KDTREE});
    CHECK(s && rp_scene_commit(s) == RP_ERROR_NONE);
    rp_rayhit rh = {.ray = {.dir_x = 1.0f, .tfar = INFINITY, .mask = ~0u}};
    rh.hit.geom_id = RP_INVALID_ID;
    rp_intersect1(s, &rh);
    CHECK(rh.hit.geom_id == RP_INVALID_ID);
    rp_scene_release(s);
    CHECK(rp_scene_new(dev, &(rp_scene_desc){.accel = (rp_accel_type)RP_ACCEL_COUNT}) == NULL);
    CHECK(rp_scene_new(dev, &(rp_scene_desc){.accel = RP_ACCEL_GRID, .grid_density = -1.0f}) == NULL);
    CHECK(rp_scene_new(dev, &(rp_scene_desc){.accel = RP_ACCEL_GRID, .grid_density = NAN}) == NULL);
    CHECK(rp_accel_name(RP_ACCEL_GRID) && strcmp(rp_accel_name(RP_ACCEL_GRID), "grid") == 0);
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_ARGUMENT);
    CHECK(rp_accel_name(RP_ACCEL_BIH) && strcmp(rp_accel_name(RP_ACCEL_BIH), "bih") == 0);
    rp_device_release(dev);
    return RP_TEST_END();
}
