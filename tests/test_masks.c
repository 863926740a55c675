// rp-test: labels=core timeout=600
/* Geometry masks and the padding lanes of tri4 blocks, which keep neither masks nor markers of
 * their own (traverse.h): a mesh dealt round-robin to four geometries (masks 1, 2, 4 and 0, or
 * with a bit every geometry shares), so most blocks hold triangles of several geometries and
 * leaves of 1-3 triangles leave lanes unused, and scenes of one, two and three triangles (one
 * block, partly padding). Rays carry masks that pass some geometries, all or none. Every ISA and
 * every structure: single rays against brute force with the masks (distance, geom, prim; any hit),
 * 4/8/16-ray packets, n x n packets of every traversal (with ray masks), arrays and an instance of
 * the scene against the single rays bit for bit, and the single rays of each ISA against the
 * scalar kernels'. */
#include <math.h>

#include "mesh_gen.h"
#include "query_got.h"
#include "raypack.h"
#include "ray_gen.h"
#include "rp_test.h"

#define GEOMS 4
#define NRAYS 1024 /* 16 packets of 8 x 8 */
#define SIDE 8

/* Triangle i of the mesh is triangle i / GEOMS of geometry i % GEOMS. */
static rp_scene *make_scene(rp_device *dev, rp_accel_type accel, const test_mesh *m, const uint32_t masks[GEOMS],
                            uint32_t *idx) {
    rp_scene *s = rp_scene_new(dev, &(rp_scene_desc){.accel = accel});
    for (uint32_t g = 0; g < GEOMS && g < m->nt; g++) {
        uint32_t *gi = idx + 3 * (size_t)g * m->nt, n = 0;
        for (uint32_t i = g; i < m->nt; i += GEOMS, n++) memcpy(gi + 3 * n, m->idx + 3 * i, 3 * sizeof(uint32_t));
        rp_geometry *geo = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
        rp_geometry_set_buffer(geo, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m->v, 0, 0, m->nv);
        rp_geometry_set_buffer(geo, RP_BUFFER_INDEX, RP_FORMAT_UINT3, gi, 0, 0, n);
        rp_geometry_set_mask(geo, masks[g]);
        rp_geometry_commit(geo);
        CHECK(rp_scene_attach(s, geo) == g);
        rp_geometry_release(geo);
    }
    CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
    return s;
}

/* Brute force with the masks and the (geom, prim) tie-break. */
static got brute(const test_mesh *m, const uint32_t masks[GEOMS], const rp_ray *r) {
    got b = {.t = r->tfar, .geom = RP_INVALID_ID, .prim = RP_INVALID_ID};
    float o[3] = {r->org_x, r->org_y, r->org_z}, d[3] = {r->dir_x, r->dir_y, r->dir_z};
    for (uint32_t i = 0; i < m->nt; i++) {
        uint32_t g = i % GEOMS, p = i / GEOMS;
        if (!(masks[g] & r->mask)) continue;
        const float *v0 = &m->v[3 * m->idx[3 * i]], *v1 = &m->v[3 * m->idx[3 * i + 1]], *v2 = &m->v[3 * m->idx[3 * i + 2]];
        float t, u, v;
        if (tri_intersect_ref(o, d, r->tnear, b.t, v0, v1, v2, &t, &u, &v) &&
            (t < b.t || (t == b.t && (g < b.geom || (g == b.geom && p < b.prim)))))
            b.t = t, b.geom = g, b.prim = p;
    }
    b.occluded = b.geom != RP_INVALID_ID;
    return b;
}


/* n x n packets of consecutive rays, with their masks. */
static void trace_n(rp_device *dev, rp_scene *s, rp_traversal trav, const rp_ray *rays, uint32_t n, got *out) {
    rp_rayhit_n p;
    if (!rp_rayhit_n_alloc(dev, SIDE, &p)) return;
    uint32_t per = SIDE * SIDE, *mask = malloc(sizeof(uint32_t) * per);
    p.mask = mask;
    for (uint32_t base = 0; base + per <= n; base += per) {
        for (int occ = 0; occ < 2; occ++) {
            for (uint32_t i = 0; i < per; i++) {
                const rp_ray *r = &rays[base + i];
                p.org_x[i] = r->org_x, p.org_y[i] = r->org_y, p.org_z[i] = r->org_z;
                p.dir_x[i] = r->dir_x, p.dir_y[i] = r->dir_y, p.dir_z[i] = r->dir_z;
                p.tnear[i] = r->tnear, p.tfar[i] = r->tfar, p.geom_id[i] = RP_INVALID_ID, mask[i] = r->mask;
            }
            rp_query_n_desc d = {.traversal = trav};
            if (occ) {
                rp_occluded_n(s, &d, &p);
                for (uint32_t i = 0; i < per; i++) out[base + i].occluded = p.tfar[i] == -INFINITY;
            } else {
                rp_intersect_n(s, &d, &p);
                for (uint32_t i = 0; i < per; i++)
                    out[base + i] = (got){p.tfar[i], p.u[i], p.v[i], {p.Ng_x[i], p.Ng_y[i], p.Ng_z[i]}, p.geom_id[i],
                                          p.prim_id[i], 0};
            }
        }
    }
    p.mask = NULL;
    free(mask);
    rp_rayhit_n_free(dev, &p);
}

/* An instance of s under the identity: the same hits (the normal through the identity too). */
static rp_scene *make_instance(rp_device *dev, rp_scene *s) {
    static const float id[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    rp_scene *top = rp_scene_new(dev, NULL);
    rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_INSTANCE);
    rp_geometry_set_instance(g, s, id);
    rp_geometry_commit(g);
    rp_scene_attach(top, g);
    rp_geometry_release(g);
    CHECK(rp_scene_commit(top) == RP_ERROR_NONE);
    return top;
}

static uint32_t count_bad(const got *a, const got *b, uint32_t n) {
    uint32_t bad = 0;
    for (uint32_t i = 0; i < n; i++) /* a packet's dead lanes: 0xDEAD untouched, 0xBAD written */
        bad += a[i].geom != 0xDEADu && (!same_got(&a[i], &b[i]) || a[i].occluded != b[i].occluded);
    return bad;
}

static void check(const char *name, const test_mesh *m, const uint32_t masks[GEOMS]) {
    static const uint32_t ray_masks[8] = {1u, 2u, 4u, 3u, 5u, 6u, 8u, 0xFFFFFFFFu};
    rp_ray *rays = malloc(sizeof(rp_ray) * NRAYS);
    got *ref = malloc(sizeof(got) * NRAYS), *scalar = malloc(sizeof(got) * NRAYS), *g1 = malloc(sizeof(got) * NRAYS),
        *g = malloc(sizeof(got) * NRAYS);
    uint32_t *idx = malloc(sizeof(uint32_t) * 3 * GEOMS * (m->nt + 1));
    make_rays(m, rays, NRAYS, 99);
    uint32_t hits[GEOMS + 1] = {0};
    for (uint32_t i = 0; i < NRAYS; i++) {
        rays[i].mask = ray_masks[(i * 7 + i / 16) % 8];
        ref[i] = brute(m, masks, &rays[i]);
        hits[ref[i].geom == RP_INVALID_ID ? GEOMS : ref[i].geom]++;
    }
    bool each = hits[GEOMS] > 0;
    for (uint32_t k = 0; k < GEOMS; k++) each &= hits[k] > 0 || k >= m->nt || masks[k] == 0;
    CHECKF(each, "%s: every geometry with a mask and triangles hit, and some misses (%u %u %u, %u)", name, hits[0],
           hits[1], hits[2], hits[GEOMS]);
    CHECKF(masks[3] != 0 || hits[3] == 0, "%s: brute force hit the mask-0 geometry", name);
    static const int isas[4] = {1, 4, 8, 16};
    for (int ii = 0; ii < 4; ii++) {
        rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2, .isa = isas[ii]});
        if (rp_device_isa(dev) != isas[ii]) { /* not on this CPU */
            rp_device_release(dev);
            continue;
        }
        for (int kind = 0; kind < RP_ACCEL_COUNT; kind++) {
            const char *an = rp_accel_name((rp_accel_type)kind);
            rp_scene *s = make_scene(dev, (rp_accel_type)kind, m, masks, idx);
            uint32_t bad_brute = 0;
            for (uint32_t i = 0; i < NRAYS; i++) {
                trace1(s, &rays[i], &g1[i]);
                bad_brute += g1[i].geom != ref[i].geom || g1[i].occluded != ref[i].occluded ||
                             (ref[i].geom != RP_INVALID_ID && (g1[i].prim != ref[i].prim || g1[i].t != ref[i].t));
            }
            CHECKF(bad_brute == 0, "%s isa %d %s: single rays differ from brute force on %u of %u", name, isas[ii], an,
                   bad_brute, NRAYS);
            if (kind == RP_ACCEL_BVH && ii == 0) memcpy(scalar, g1, sizeof(got) * NRAYS);
            uint32_t bad_isa = count_bad(g1, scalar, NRAYS);
            CHECKF(bad_isa == 0, "%s isa %d %s: %u single rays differ from the scalar BVH's", name, isas[ii], an, bad_isa);
            void (*packets[3])(rp_scene *, const rp_ray *, uint32_t, got *) = {trace_4, trace_8, trace_16};
            for (int w = 0; w < 3; w++) {
                packets[w](s, rays, NRAYS, g);
                uint32_t bad = count_bad(g, g1, NRAYS);
                CHECKF(bad == 0, "%s isa %d %s: %d-ray packets differ on %u", name, isas[ii], an, 4 << w, bad);
            }
            for (int t = RP_TRAVERSAL_AUTO; t <= RP_TRAVERSAL_MLRT; t++) {
                trace_n(dev, s, (rp_traversal)t, rays, NRAYS, g);
                uint32_t bad = count_bad(g, g1, NRAYS);
                CHECKF(bad == 0, "%s isa %d %s: %dx%d packets, traversal %d, differ on %u", name, isas[ii], an, SIDE,
                       SIDE, t, bad);
            }
            for (int k = 0; k < 2; k++) {
                trace_array(s, rays, NRAYS, k ? RP_QUERY_COHERENT : RP_QUERY_INCOHERENT, g);
                uint32_t bad = count_bad(g, g1, NRAYS);
                CHECKF(bad == 0, "%s isa %d %s: arrays (%d) differ on %u", name, isas[ii], an, k, bad);
            }
            rp_scene *top = make_instance(dev, s);
            for (uint32_t i = 0; i < NRAYS; i++) trace1(top, &rays[i], &g[i]);
            uint32_t bad = count_bad(g, g1, NRAYS);
            trace_16(top, rays, NRAYS, g);
            bad += count_bad(g, g1, NRAYS);
            CHECKF(bad == 0, "%s isa %d %s: the instance differs on %u", name, isas[ii], an, bad);
            rp_scene_release(top);
            CHECK(rp_device_get_error(dev) == RP_ERROR_NONE);
            rp_scene_release(s);
        }
        rp_device_release(dev);
    }
    printf("%s: %u triangles, hits by geometry %u %u %u %u, %u misses\n", name, m->nt, hits[0], hits[1], hits[2],
           hits[3], hits[GEOMS]);
    free(rays), free(ref), free(scalar), free(g1), free(g), free(idx);
}

/* The first n triangles of a mesh (which keeps its vertices). */
static test_mesh first_triangles(const test_mesh *m, uint32_t n) {
    test_mesh t = *m;
    t.nt = n;
    return t;
}

int main(void) {
    (void)brute_force; /* ray_gen.h's, which knows no masks: brute() here */
    static const uint32_t apart[GEOMS] = {1u, 2u, 4u, 0u};  /* no bit shared: every ray takes the mask test */
    static const uint32_t shared[GEOMS] = {9u, 10u, 12u, 8u}; /* bit 8 in all: those rays skip it */
    test_mesh soup = test_mesh_soup(1200, 4.0f, 5);
    const float c[3] = {0.0f, 0.0f, 0.0f};
    test_mesh sphere = test_mesh_sphere(12, 24, c, 2.0f);
    check("soup apart", &soup, apart);
    check("soup shared", &soup, shared);
    check("sphere apart", &sphere, apart);
    check("sphere shared", &sphere, shared);
    for (uint32_t n = 1; n <= 3; n++) { /* one block, n real lanes (of n geometries) */
        test_mesh few = first_triangles(&soup, n);
        char name[32];
        snprintf(name, sizeof name, "%u triangles", n);
        check(name, &few, apart);
        check(name, &few, shared);
    }
    test_mesh_free(&soup);
    test_mesh_free(&sphere);
    return RP_TEST_END();
}
