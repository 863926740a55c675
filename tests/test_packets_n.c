// rp-test: labels=core timeout=900
/* Large ray packets (Overbeck et al. 2008): every traversal mode (masked, ranged, partition, auto,
 * single, simd), packet size 4x4..32x32, ray type (primary, shadow to a point light, reflection,
 * refraction), with frusta on and off, on every ISA, against rp_intersect1 / rp_occluded1 ray by
 * ray on shared scenes: identical geom_id, prim_id, t, u, v and Ng. Then conservativeness: packets
 * that break each frustum's assumptions (jittered primary rays, random cones, random secondary
 * rays) traced with frusta, every ray checked on its own, and the frusta shown to cull. */
#include <math.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "raypack_io.h"
#include "rp_test.h"
#include "sys/sys.h"

#include "packets_n_gen.h"

typedef struct result {
    uint32_t bad, bad_dead, bad_occl, rays;
} result;

/* Traces the image in n x n packets with one mode and compares ray by ray. */
static void run_packets(rp_device *dev, rp_scene *scene, const test_ray *rays, int res, uint32_t n,
                        const rp_query_n_desc *desc, rp_counters_n *cnt, result *res_out) {
    rp_rayhit_n p;
    CHECK(rp_rayhit_n_alloc(dev, n, &p));
    int32_t *valid = malloc(sizeof(int32_t) * n * n);
    rp_query_n_desc d = *desc;
    d.counters = cnt;
    for (int py = 0; py + (int)n <= res; py += (int)n)
        for (int px = 0; px + (int)n <= res; px += (int)n) {
            for (int pass = 0; pass < 2; pass++) {
                for (uint32_t y = 0; y < n; y++)
                    for (uint32_t x = 0; x < n; x++) {
                        uint32_t q = rp_packet_n_index(n, x, y);
                        const test_ray *t = &rays[(py + (int)y) * res + px + (int)x];
                        valid[q] = t->live ? -1 : 0;
                        p.org_x[q] = t->ray.org_x, p.org_y[q] = t->ray.org_y, p.org_z[q] = t->ray.org_z;
                        p.dir_x[q] = t->ray.dir_x, p.dir_y[q] = t->ray.dir_y, p.dir_z[q] = t->ray.dir_z;
                        p.tnear[q] = t->ray.tnear, p.tfar[q] = t->live ? t->ray.tfar : 42.0f;
                        p.geom_id[q] = RP_INVALID_ID, p.prim_id[q] = 777u;
                    }
                p.valid = valid;
                if (pass == 0) rp_intersect_n(scene, &d, &p);
                else rp_occluded_n(scene, &d, &p);
                for (uint32_t y = 0; y < n; y++)
                    for (uint32_t x = 0; x < n; x++) {
                        uint32_t q = rp_packet_n_index(n, x, y);
                        const test_ray *t = &rays[(py + (int)y) * res + px + (int)x];
                        if (!t->live) {
                            res_out->bad_dead += p.tfar[q] != 42.0f || p.geom_id[q] != RP_INVALID_ID || p.prim_id[q] != 777u;
                            continue;
                        }
                        if (pass == 1) {
                            res_out->bad_occl += (p.tfar[q] == -INFINITY) != t->occluded;
                            continue;
                        }
                        res_out->rays++;
                        const rp_rayhit *r = &t->ref;
                        bool same = p.geom_id[q] == r->hit.geom_id;
                        if (same && r->hit.geom_id != RP_INVALID_ID)
                            same = p.prim_id[q] == r->hit.prim_id && p.tfar[q] == r->ray.tfar && p.u[q] == r->hit.u &&
                                   p.v[q] == r->hit.v && p.Ng_x[q] == r->hit.Ng_x && p.Ng_y[q] == r->hit.Ng_y &&
                                   p.Ng_z[q] == r->hit.Ng_z;
                        if (!same && getenv("RP_TEST_VERBOSE"))
                            fprintf(stderr, "pixel %d,%d: ref geom %u prim %u t %.9g, got geom %u prim %u t %.9g\n",
                                    px + (int)x, py + (int)y, r->hit.geom_id, r->hit.prim_id, (double)r->ray.tfar,
                                    p.geom_id[q], p.prim_id[q], (double)p.tfar[q]);
                        res_out->bad += !same;
                    }
            }
        }
    free(valid);
    rp_rayhit_n_free(dev, &p);
}

static void check_world(const world *w, int res, bool all_isas) {
    int isas[4] = {1, 4, 8, 16};
    float diag = sqrtf((w->hi[0] - w->lo[0]) * (w->hi[0] - w->lo[0]) + (w->hi[1] - w->lo[1]) * (w->hi[1] - w->lo[1]) +
                       (w->hi[2] - w->lo[2]) * (w->hi[2] - w->lo[2]));
    for (int ii = 0; ii < 4; ii++) {
        if (isas[ii] > sys_cpu_simd_width()) continue;
        if (!all_isas && isas[ii] != sys_cpu_simd_width()) continue;
        rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1, .isa = isas[ii]});
        rp_scene *scene = make_scene(dev, &w->sd);
        test_ray *rays[RAY_TYPES];
        for (int t = 0; t < RAY_TYPES; t++) {
            rays[t] = malloc(sizeof(test_ray) * (size_t)(res * res));
            make_rays(w, scene, t, res, 1e-4f * diag, rays[0], rays[t]);
        }
        uint32_t hits[RAY_TYPES] = {0};
        for (int t = 0; t < RAY_TYPES; t++)
            for (int i = 0; i < res * res; i++) hits[t] += rays[t][i].live && rays[t][i].ref.hit.geom_id != RP_INVALID_ID;
        CHECKF(hits[0] > (uint32_t)(res * res / 4), "%s: only %u primary hits", w->name, hits[0]);
        for (int t = 0; t < RAY_TYPES; t++) {
            uint64_t culls = 0, auto_span = 0, auto_simd = 0;
            for (uint32_t n = 4; n <= 32; n *= 2) {
                for (size_t m = 0; m < sizeof modes / sizeof modes[0]; m++) {
                    for (int fr = 0; fr < 2; fr++) {
                        rp_query_n_desc d = {.traversal = modes[m], .frustum = fr ? ray_frustum[t] : RP_FRUSTUM_NONE};
                        memcpy(d.point, w->light, sizeof d.point);
                        rp_counters_n c;
                        memset(&c, 0, sizeof c);
                        result r = {0};
                        run_packets(dev, scene, rays[t], res, n, &d, &c, &r);
                        culls += c.frustum_box_culls + c.frustum_tri_culls;
                        uint64_t sum = 0;
                        for (int k = 0; k < RP_COUNTERS_N_DEPTH; k++) sum += c.box_tests_depth[k];
                        CHECKF(r.bad == 0 && r.bad_dead == 0 && r.bad_occl == 0,
                               "%s isa %d %s %ux%u %s frustum %s: %u of %u hits differ, %u occlusions, %u dead rays written",
                               w->name, isas[ii], ray_names[t], n, n, mode_names[m], fr ? "on" : "off", r.bad, r.rays,
                               r.bad_occl, r.bad_dead);
                        CHECK(sum == c.box_tests);
                        if (modes[m] != RP_TRAVERSAL_AUTO && modes[m] != RP_TRAVERSAL_SINGLE &&
                            modes[m] != RP_TRAVERSAL_SIMD)
                            CHECK(c.packets > 0 && c.box_tests > 0);
                        if (modes[m] == RP_TRAVERSAL_AUTO) {
                            /* every packet of auto went to Span, Partition or SIMD rays */
                            CHECK(c.traversal[0] == c.packets &&
                                  c.traversal[3] + c.traversal[4] + c.traversal[5] == c.packets);
                            auto_span += c.traversal[4], auto_simd += c.traversal[5];
                        }
                    }
                }
            }
            /* auto takes Span for coherent packets */
            if (t == RAY_PRIMARY) CHECKF(auto_span > 0, "%s: auto never chose span for primary packets", w->name);
            /* ... and SIMD rays for the packets that leave the rings' spheres facing apart */
            if (t == RAY_REFLECT && strcmp(w->name, "rings") == 0)
                CHECKF(auto_simd > 0, "%s: auto never traced a reflection packet as SIMD rays", w->name);
            /* frusta must do something on primary and shadow packets */
            if (t <= RAY_SHADOW) CHECKF(culls > 0, "%s %s: frusta culled nothing", w->name, ray_names[t]);
            printf("%s isa %d %s: %u hits, %llu frustum culls\n", w->name, isas[ii], ray_names[t], hits[t],
                   (unsigned long long)culls);
        }
        CHECK(rp_device_get_error(dev) == RP_ERROR_NONE);
        for (int t = 0; t < RAY_TYPES; t++) free(rays[t]);
        rp_scene_release(scene);
        rp_device_release(dev);
    }
}

/* Traces the n x n rays (rays[q] is ray q) as packet p and returns how many answers differ from the
 * single-ray ones: the closest hit (geometry, primitive, distance), or occlusion when occ. */
static uint32_t trace_compare(rp_scene *scene, const rp_query_n_desc *d, rp_rayhit_n *p, const test_ray *rays,
                              bool occ) {
    const uint32_t count = p->n * p->n;
    for (uint32_t q = 0; q < count; q++) {
        const rp_ray *r = &rays[q].ray;
        p->org_x[q] = r->org_x, p->org_y[q] = r->org_y, p->org_z[q] = r->org_z;
        p->dir_x[q] = r->dir_x, p->dir_y[q] = r->dir_y, p->dir_z[q] = r->dir_z;
        p->tnear[q] = r->tnear, p->tfar[q] = r->tfar, p->geom_id[q] = RP_INVALID_ID;
    }
    if (occ) rp_occluded_n(scene, d, p);
    else rp_intersect_n(scene, d, p);
    uint32_t bad = 0;
    for (uint32_t q = 0; q < count; q++) {
        const test_ray *t = &rays[q];
        if (occ) bad += (p->tfar[q] == -INFINITY) != t->occluded;
        else bad += p->geom_id[q] != t->ref.hit.geom_id ||
                    (t->ref.hit.geom_id != RP_INVALID_ID &&
                     (p->prim_id[q] != t->ref.hit.prim_id || p->tfar[q] != t->ref.ray.tfar));
    }
    return bad;
}

/* Conservativeness: packets that do not look like the textbook case, traced with every frustum
 * kind that applies; every ray must still get its single-ray hit, and the frusta must cull. */
static void check_conservative(const world *w, int packets) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_scene *scene = make_scene(dev, &w->sd);
    test_rng g = {99};
    const uint32_t n = 8;
    test_ray *rays = malloc(sizeof(test_ray) * n * n);
    uint32_t bad = 0, total = 0;
    uint64_t culls[RAY_TYPES] = {0};
    float c[3], e[3];
    for (int a = 0; a < 3; a++) c[a] = 0.5f * (w->lo[a] + w->hi[a]), e[a] = w->hi[a] - w->lo[a];
    for (int k = 0; k < packets; k++) {
        int kind = k % 3; /* 0: jittered primary, 1: random shadow cone, 2: random secondary */
        float spread = test_rng_float(&g) < 0.5f ? 0.002f : 0.1f;
        float org[3], aim[3];
        for (int a = 0; a < 3; a++) {
            org[a] = c[a] + (test_rng_float(&g) - 0.5f) * e[a] * 0.9f;
            aim[a] = c[a] + (test_rng_float(&g) - 0.5f) * e[a] * 0.5f;
        }
        int res = 256, px = (int)(test_rng_u32(&g) % (uint32_t)(res - (int)n)), py = (int)(test_rng_u32(&g) % (uint32_t)(res - (int)n));
        for (uint32_t i = 0; i < n * n; i++) {
            test_ray *t = &rays[i];
            memset(t, 0, sizeof *t);
            t->live = true;
            uint32_t x = i % n, y = i / n;
            float d[3];
            if (kind == 0) {
                primary_ray(w, px + (int)x, py + (int)y, res, test_rng_float(&g), test_rng_float(&g), &t->ray);
            } else {
                float o[3];
                for (int a = 0; a < 3; a++) {
                    d[a] = aim[a] - org[a] + (test_rng_float(&g) - 0.5f) * spread * e[a] * 4.0f;
                    o[a] = kind == 2 ? org[a] + (test_rng_float(&g) - 0.5f) * spread * e[a] : org[a];
                }
                if (kind == 1) {
                    /* shadow rays from scattered points towards the light `aim` */
                    float p[3];
                    for (int a = 0; a < 3; a++) p[a] = aim[a] - d[a];
                    for (int a = 0; a < 3; a++) d[a] = aim[a] - p[a];
                    t->ray = (rp_ray){.org_x = p[0], .org_y = p[1], .org_z = p[2], .tnear = 0.0f, .dir_x = d[0],
                                      .dir_y = d[1], .dir_z = d[2], .tfar = 1.0f, .mask = 0xFFFFFFFFu};
                } else {
                    t->ray = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .tnear = 0.0f, .dir_x = d[0],
                                      .dir_y = d[1], .dir_z = d[2], .tfar = INFINITY, .mask = 0xFFFFFFFFu};
                }
            }
            (void)x, (void)y;
            reference(scene, t);
        }
        /* rays are stored in packet order directly: rays[q] is ray q */
        rp_rayhit_n p;
        rp_rayhit_n_alloc(dev, n, &p);
        for (int pass = 0; pass < 2; pass++) {
            int type = kind == 0 ? RAY_PRIMARY : kind == 1 ? RAY_SHADOW : RAY_REFLECT;
            rp_frustum_kind fk = pass == 0 ? ray_frustum[type] : RP_FRUSTUM_SECONDARY;
            for (size_t m = 0; m < 5; m++) { /* the packet algorithms and auto */
                rp_counters_n cnt;
                memset(&cnt, 0, sizeof cnt);
                rp_query_n_desc d = {.traversal = modes[m], .frustum = fk, .counters = &cnt};
                memcpy(d.point, aim, sizeof d.point);
                for (int occ = 0; occ < 2; occ++) {
                    uint32_t bad_before = bad;
                    bad += trace_compare(scene, &d, &p, rays, occ != 0);
                    total += n * n;
                    if (bad != bad_before && getenv("RP_TEST_VERBOSE"))
                        fprintf(stderr, "%s packet %d kind %d frustum %d %s %s: %u lost\n", w->name, k, kind, (int)fk,
                                mode_names[m], occ ? "occluded" : "intersect", bad - bad_before);
                }
                culls[type] += cnt.frustum_box_culls + cnt.frustum_tri_culls;
            }
        }
        rp_rayhit_n_free(dev, &p);
    }
    CHECKF(bad == 0, "%s: frustum culling lost %u of %u hits", w->name, bad, total);
    for (int t = 0; t < 3; t++) CHECKF(culls[t] > 0, "%s: %s frusta never culled", w->name, ray_names[t]);
    printf("%s: conservativeness, %d packets, %u rays checked, culls %llu %llu %llu\n", w->name, packets, total,
           (unsigned long long)culls[0], (unsigned long long)culls[1], (unsigned long long)culls[2]);
    free(rays);
    rp_scene_release(scene);
    rp_device_release(dev);
}

/* Traces the packet of rays `count` times with auto and tally t (both occlusion and closest hits,
 * in turns), counting into c; every answer must be the single ray's. */
static void trace_tally(const world *w, rp_scene *scene, rp_rayhit_n *p, const test_ray *rays, rp_auto_tally *t,
                        int count, rp_counters_n *c) {
    memset(c, 0, sizeof *c);
    rp_query_n_desc d = {.traversal = RP_TRAVERSAL_AUTO, .frustum = RP_FRUSTUM_SECONDARY, .counters = c, .tally = t};
    uint32_t bad = 0;
    for (int i = 0; i < count; i++) bad += trace_compare(scene, &d, p, rays, i % 2 != 0);
    CHECKF(bad == 0, "%s: auto with a tally, %u answers differ", w->name, bad);
    CHECKF(c->packets == (uint64_t)count && c->traversal[0] == (uint64_t)count &&
               c->traversal[3] + c->traversal[4] + c->traversal[5] == (uint64_t)count,
           "%s: auto with a tally counted %llu packets", w->name, (unsigned long long)c->packets);
}

/* Auto with a tally (rp_auto_tally) on packets of class cls, counted in traversal[alt] when they go
 * way 1: the ways take turns until each has 4 packets, then the faster goes on and the slower
 * takes every 16th; the answers stay the single ray's. A tally primed with one way far cheaper
 * keeps to it but for those every 16th. */
static void check_auto_tally(const world *w, rp_scene *scene, rp_rayhit_n *p, const test_ray *rays, int cls, int alt,
                             const char *what) {
    uint64_t live = (uint64_t)p->n * p->n;
    rp_auto_tally t;
    rp_counters_n c;
    memset(&t, 0, sizeof t);
    trace_tally(w, scene, p, rays, &t, 8, &c);
    CHECKF(c.traversal[alt] == 4 && t.seen[cls] == 8 && t.seen[1 - cls] == 0 && t.packets[cls][0] == 4 &&
               t.packets[cls][1] == 4 && t.rays[cls][0] == 4 * live && t.rays[cls][1] == 4 * live &&
               t.ticks[cls][0] > 0 && t.ticks[cls][1] > 0,
           "%s: %s, a fresh tally: %llu of 8 packets the second way, seen %llu, packets %llu/%llu", w->name, what,
           (unsigned long long)c.traversal[alt], (unsigned long long)t.seen[cls],
           (unsigned long long)t.packets[cls][0], (unsigned long long)t.packets[cls][1]);
    for (int way = 0; way < 2; way++) {
        /* seen 200: packets 207 and 223 of the next 32 go the other way */
        memset(&t, 0, sizeof t);
        t.seen[cls] = 200;
        for (int k = 0; k < 2; k++) t.packets[cls][k] = 100, t.rays[cls][k] = 100 * live;
        t.ticks[cls][way] = 1000000, t.ticks[cls][1 - way] = 1000000000000000ull;
        trace_tally(w, scene, p, rays, &t, 32, &c);
        CHECKF(c.traversal[alt] == (way ? 30u : 2u), "%s: %s, a tally that finds way %d cheaper sent %llu of 32 "
               "packets the second way", w->name, what, way, (unsigned long long)c.traversal[alt]);
        CHECKF(t.seen[cls] == 232 && t.packets[cls][0] + t.packets[cls][1] < 232,
               "%s: %s, the tally's figures did not move on", w->name, what);
    }
}

/* Rays in every direction from the middle of the scene face apart: auto traces them one SIMD ray at a
 * time (counted as such), with the single-ray answers; a packet of two coherent halves facing apart
 * goes to Span. */
static void check_auto_apart(const world *w) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_scene *scene = make_scene(dev, &w->sd);
    enum { N = 8 };
    test_ray rays[N * N];
    for (uint32_t q = 0; q < N * N; q++) {
        /* a Fibonacci sphere */
        float z = 1.0f - 2.0f * ((float)q + 0.5f) / (float)(N * N), r = sqrtf(1.0f - z * z), phi = 2.39996323f * (float)q;
        float c[3];
        for (int a = 0; a < 3; a++) c[a] = 0.5f * (w->lo[a] + w->hi[a]);
        rays[q] = (test_ray){.ray = {.org_x = c[0], .org_y = c[1], .org_z = c[2], .tnear = 0.0f, .dir_x = r * cosf(phi),
                                     .dir_y = r * sinf(phi), .dir_z = z, .tfar = INFINITY, .mask = 0xFFFFFFFFu},
                             .live = true};
        reference(scene, &rays[q]);
    }
    rp_rayhit_n p;
    CHECK(rp_rayhit_n_alloc(dev, N, &p));
    for (int fr = 0; fr < 2; fr++)
        for (int occ = 0; occ < 2; occ++) {
            rp_counters_n c;
            memset(&c, 0, sizeof c);
            rp_query_n_desc d = {.traversal = RP_TRAVERSAL_AUTO, .frustum = fr ? RP_FRUSTUM_SECONDARY : RP_FRUSTUM_NONE,
                                 .counters = &c};
            uint32_t bad = trace_compare(scene, &d, &p, rays, occ != 0);
            CHECKF(bad == 0, "%s: rays facing apart, %u of %d answers differ", w->name, bad, N * N);
            CHECKF(c.packets == 1 && c.traversal[0] == 1 && c.traversal[5] == 1,
                   "%s: auto traced rays facing apart as a packet", w->name);
        }
    check_auto_tally(w, scene, &p, rays, 1, 5, "incoherent packets (a packet or SIMD rays)");
    /* Two coherent halves facing apart (a packet across the corner of two mirrors): Span */
    for (uint32_t y = 0; y < N; y++)
        for (uint32_t x = 0; x < N; x++) {
            uint32_t q = rp_packet_n_index(N, x, y);
            float s = x < N / 2 ? -1.0f : 1.0f, jx = 0.02f * (float)(x % (N / 2)), jy = 0.02f * (float)y;
            rp_ray *r = &rays[q].ray;
            r->dir_x = s, r->dir_y = jx - 0.03f, r->dir_z = jy - 0.07f; /* no axis where all agree */
            reference(scene, &rays[q]);
        }
    for (int occ = 0; occ < 2; occ++) {
        rp_counters_n c;
        memset(&c, 0, sizeof c);
        rp_query_n_desc d = {.traversal = RP_TRAVERSAL_AUTO, .frustum = RP_FRUSTUM_SECONDARY, .counters = &c};
        uint32_t bad = trace_compare(scene, &d, &p, rays, occ != 0);
        CHECKF(bad == 0, "%s: two halves facing apart, %u of %d answers differ", w->name, bad, N * N);
        CHECKF(c.packets == 1 && c.traversal[4] == 1, "%s: auto traced two coherent halves facing apart without Span",
               w->name);
    }
    /* Rays that part, a slope of -2.5..2.5 across z (a spread between auto's bounds for Span and for
     * SIMD rays in bunny's 69451 triangles): Partition, or with a tally Partition and Span in turns */
    for (uint32_t y = 0; y < N; y++)
        for (uint32_t x = 0; x < N; x++) {
            uint32_t q = rp_packet_n_index(N, x, y);
            rp_ray *r = &rays[q].ray;
            r->dir_x = -2.5f + 5.0f * (float)x / (N - 1), r->dir_y = -2.5f + 5.0f * (float)y / (N - 1), r->dir_z = 1.0f;
            reference(scene, &rays[q]);
        }
    rp_counters_n c;
    trace_tally(w, scene, &p, rays, NULL, 2, &c);
    CHECKF(c.traversal[3] == 2, "%s: auto traced rays that part without Partition", w->name);
    check_auto_tally(w, scene, &p, rays, 0, 4, "packets whose rays part (Partition or Span)");
    rp_rayhit_n_free(dev, &p);
    rp_scene_release(scene);
    rp_device_release(dev);
}

static void check_api(void) {
    rp_device *dev = rp_device_new(NULL);
    rp_rayhit_n p;
    CHECK(!rp_rayhit_n_alloc(dev, 6, &p));
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_ARGUMENT);
    CHECK(rp_rayhit_n_alloc(dev, 4, &p));
    rp_scene *scene = rp_scene_new(dev, NULL);
    rp_intersect_n(scene, NULL, &p); /* not committed */
    CHECK(rp_device_get_error(dev) == RP_ERROR_NOT_COMMITTED);
    rp_intersect_n(scene, NULL, NULL);
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_ARGUMENT);
    /* the index covers every ray once */
    for (uint32_t n = 4; n <= 32; n += 4) {
        uint32_t seen = 0, bad = 0;
        uint8_t *hit = calloc(n * n, 1);
        for (uint32_t y = 0; y < n; y++)
            for (uint32_t x = 0; x < n; x++) {
                uint32_t q = rp_packet_n_index(n, x, y);
                if (q >= n * n || hit[q]) bad++;
                else hit[q] = 1, seen++;
            }
        CHECKF(bad == 0 && seen == n * n, "rp_packet_n_index(%u) is not a permutation", n);
        free(hit);
    }
    rp_query_n_desc d = rp_query_n_desc_defaults(NULL);
    CHECK(d.traversal == RP_TRAVERSAL_AUTO && d.frustum == RP_FRUSTUM_NONE && d.counters == NULL);
    rp_rayhit_n_free(dev, &p);
    rp_scene_release(scene);
    rp_device_release(dev);
}

/* Rays through the shared vertices and edges of a jittered, tilted grid mesh, from one apex: primary
 * packets from it and shadow packets towards it (origins beyond the mesh). The single-ray kernel is
 * watertight, so every such ray hits; the packets' frusta and the leaves' edge-plane (cone) test
 * must not lose one to rounding, whatever the algorithm. */
/* The triangles of a g x g grid of vertices (row major), two per cell; returns their count. */
static size_t grid_triangles(int g, uint32_t *idx) {
    size_t tc = 0;
    for (int j = 0; j + 1 < g; j++)
        for (int i = 0; i + 1 < g; i++) {
            uint32_t v00 = (uint32_t)(j * g + i), v10 = v00 + 1, v01 = v00 + (uint32_t)g, v11 = v01 + 1;
            uint32_t t[6] = {v00, v10, v11, v00, v11, v01};
            memcpy(idx + 3 * tc, t, sizeof t);
            tc += 2;
        }
    return tc;
}

static void check_cone_edges(void) {
    enum { G = 33, N = 16 };
    float *pos = malloc(sizeof(float) * 3 * G * G);
    uint32_t *idx = malloc(sizeof(uint32_t) * 6 * (G - 1) * (G - 1));
    uint32_t seed = 12345;
    const float ex[3] = {0.9f, 0.2f, 0.3f}, ey[3] = {-0.25f, 0.95f, 0.1f}, base[3] = {-14.3f, -15.1f, 40.7f};
    for (int j = 0; j < G; j++)
        for (int i = 0; i < G; i++) {
            float jit[3];
            for (int a = 0; a < 3; a++) {
                seed = seed * 1664525u + 1013904223u;
                jit[a] = ((float)(seed >> 8) / 16777216.0f - 0.5f) * 0.3f;
            }
            for (int a = 0; a < 3; a++)
                pos[3 * (j * G + i) + a] = base[a] + ((float)i + jit[0]) * ex[a] + ((float)j + jit[1]) * ey[a] + jit[2];
        }
    size_t tc = grid_triangles(G, idx);
    /* the targets: interior vertices, then midpoints of interior edges */
    size_t max_targets = 4 * G * G, nt = 0;
    float *target = malloc(sizeof(float) * 3 * max_targets);
    for (int j = 1; j + 1 < G; j++)
        for (int i = 1; i + 1 < G; i++) {
            const float *v = pos + 3 * (j * G + i);
            memcpy(target + 3 * nt++, v, 3 * sizeof(float));
            const int nb[3][2] = {{1, 0}, {0, 1}, {1, 1}};
            for (int k = 0; k < 3; k++) {
                if (i + nb[k][0] >= G - 1 || j + nb[k][1] >= G - 1) continue;
                const float *w = pos + 3 * ((j + nb[k][1]) * G + i + nb[k][0]);
                for (int a = 0; a < 3; a++) target[3 * nt + a] = 0.5f * (v[a] + w[a]);
                nt++;
            }
        }
    const float apex[3] = {1.7f, 2.3f, -3.1f};
    int isas[4] = {1, 4, 8, 16};
    for (int ii = 0; ii < 4; ii++) {
        if (isas[ii] > sys_cpu_simd_width()) continue;
        rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1, .isa = isas[ii]});
        rp_scene *scene = make_scene(dev, &(rp_scene_data){.positions = pos, .vertex_count = G * G, .indices = idx,
                                                          .triangle_count = tc});
        rp_rayhit_n p;
        CHECK(rp_rayhit_n_alloc(dev, N, &p));
        uint32_t bad = 0, missed = 0, total = 0, culls = 0;
        for (int shadow = 0; shadow < 2; shadow++)
            for (size_t first = 0; first < nt; first += N * N) {
                test_ray rays[N * N];
                for (uint32_t q = 0; q < N * N; q++) {
                    const float *tg = target + 3 * ((first + q) % nt);
                    rp_ray r = {.tnear = 0.0f, .tfar = INFINITY, .mask = 0xFFFFFFFFu};
                    if (!shadow) {
                        r.org_x = apex[0], r.org_y = apex[1], r.org_z = apex[2];
                        r.dir_x = tg[0] - apex[0], r.dir_y = tg[1] - apex[1], r.dir_z = tg[2] - apex[2];
                    } else {
                        float o[3];
                        for (int a = 0; a < 3; a++) o[a] = apex[a] + 1.25f * (tg[a] - apex[a]);
                        r.org_x = o[0], r.org_y = o[1], r.org_z = o[2];
                        r.dir_x = apex[0] - o[0], r.dir_y = apex[1] - o[1], r.dir_z = apex[2] - o[2];
                        r.tfar = 0.999f;
                    }
                    rays[q] = (test_ray){.ray = r, .live = true};
                    reference(scene, &rays[q]);
                    missed += shadow ? !rays[q].occluded : rays[q].ref.hit.geom_id == RP_INVALID_ID;
                }
                for (size_t m = 0; m < 5; m++) { /* the packet algorithms and auto */
                    rp_counters_n cnt;
                    memset(&cnt, 0, sizeof cnt);
                    rp_query_n_desc d = {.traversal = modes[m],
                                         .frustum = shadow ? RP_FRUSTUM_SHADOW : RP_FRUSTUM_PRIMARY,
                                         .counters = &cnt};
                    memcpy(d.point, apex, sizeof d.point);
                    bad += trace_compare(scene, &d, &p, rays, shadow != 0);
                    total += N * N;
                    culls += (uint32_t)(cnt.frustum_box_culls + cnt.frustum_tri_culls);
                }
            }
        CHECKF(missed == 0, "isa %d: %u rays through the mesh's vertices and edges escape single-ray tests",
               isas[ii], missed);
        CHECKF(bad == 0, "isa %d: %u of %u packet rays through vertices and edges differ from single rays",
               isas[ii], bad, total);
        printf("cone edges, isa %d: %u rays through vertices and edges, %u differ, frustum culls %u\n", isas[ii],
               total, bad, culls);
        rp_rayhit_n_free(dev, &p);
        rp_scene_release(scene);
        rp_device_release(dev);
    }
    free(target);
    free(idx);
    free(pos);
}

/* A packet whose rays all hit every box on their way (parallel rays into one large quad, in a grid
 * of quads) stays whole: Span then tests a leaf's triangles on all its rays, as Ranged does,
 * without box tests for the rays between the span's ends, so the two count the same box tests. */
static void check_span_whole(void) {
    enum { G = 9, N = 16 };
    float pos[3 * G * G];
    uint32_t idx[6 * (G - 1) * (G - 1)];
    for (int j = 0; j < G; j++)
        for (int i = 0; i < G; i++) {
            float *v = pos + 3 * (j * G + i);
            v[0] = (float)i, v[1] = (float)j, v[2] = 0.1f * (float)((i * 7 + j * 3) % 5);
        }
    size_t tc = grid_triangles(G, idx);
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_scene *scene = make_scene(dev, &(rp_scene_data){.positions = pos, .vertex_count = G * G, .indices = idx,
                                                      .triangle_count = tc});
    test_ray rays[N * N];
    for (uint32_t q = 0; q < N * N; q++) {
        /* inside the quad (4.1 .. 4.9)^2, so every ray hits the same leaves */
        float x = 4.1f + 0.8f * (float)(q % N) / N, y = 4.1f + 0.8f * (float)(q / N) / N;
        rays[q] = (test_ray){.ray = {.org_x = x, .org_y = y, .org_z = 5.0f, .tnear = 0.0f, .dir_x = 0.0f, .dir_y = 0.0f,
                                     .dir_z = -1.0f, .tfar = INFINITY, .mask = 0xFFFFFFFFu},
                             .live = true};
        reference(scene, &rays[q]);
    }
    rp_rayhit_n p;
    CHECK(rp_rayhit_n_alloc(dev, N, &p));
    uint64_t box[2];
    const rp_traversal algs[2] = {RP_TRAVERSAL_RANGED, RP_TRAVERSAL_SPAN};
    for (int a = 0; a < 2; a++) {
        rp_counters_n c;
        memset(&c, 0, sizeof c);
        rp_query_n_desc d = {.traversal = algs[a], .frustum = RP_FRUSTUM_NONE, .counters = &c};
        CHECKF(trace_compare(scene, &d, &p, rays, false) == 0, "span whole: %s differs from single rays",
               a ? "span" : "ranged");
        box[a] = c.box_tests;
    }
    CHECKF(box[0] > 0 && box[1] == box[0], "a whole packet: span %llu box tests, ranged %llu",
           (unsigned long long)box[1], (unsigned long long)box[0]);
    rp_rayhit_n_free(dev, &p);
    rp_scene_release(scene);
    rp_device_release(dev);
}

/* Ray masks in large packets: two stacked grid meshes with geometry masks 1 and 2, rays from one
 * apex with masks 1, 2, 3 and 4 (the last sees neither) and directions that differ in their
 * dominant axis within a SIMD ray; every algorithm, with and without frusta, must return the
 * single-ray hits, closest and any. */
static void check_ray_masks(void) {
    enum { G = 9, N = 16 };
    float pos[2][3 * G * G];
    uint32_t idx[6 * (G - 1) * (G - 1)];
    for (int m = 0; m < 2; m++)
        for (int j = 0; j < G; j++)
            for (int i = 0; i < G; i++) {
                float *v = pos[m] + 3 * (j * G + i);
                v[0] = (float)i - 4.0f, v[1] = (float)j - 4.0f, v[2] = -(float)m - 0.05f * (float)((i + 2 * j) % 3);
            }
    size_t tc = grid_triangles(G, idx);
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_scene *scene = rp_scene_new(dev, NULL);
    for (int m = 0; m < 2; m++) {
        rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
        rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, pos[m], 0, 0, G * G);
        rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, idx, 0, 0, tc);
        rp_geometry_set_mask(g, 1u << m);
        rp_geometry_commit(g);
        rp_scene_attach(scene, g);
        rp_geometry_release(g);
    }
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    rp_rayhit_n p;
    CHECK(rp_rayhit_n_alloc(dev, N, &p));
    uint32_t *mask = malloc(sizeof(uint32_t) * N * N);
    test_ray rays[N * N];
    uint32_t hits[2] = {0, 0};
    for (uint32_t y = 0; y < N; y++)
        for (uint32_t x = 0; x < N; x++) {
            uint32_t q = rp_packet_n_index(N, x, y);
            /* from (0, 0, 3) over the grids: the outer columns' rays are x-dominant */
            float dx = 3.2f * ((float)x + 0.5f) / N - 1.6f, dy = 1.4f * ((float)y + 0.5f) / N - 0.7f;
            mask[q] = 1u << ((x + 3 * y) % 4);
            rays[q] = (test_ray){.ray = {.org_x = 0.0f, .org_y = 0.0f, .org_z = 3.0f, .tnear = 0.0f, .dir_x = dx,
                                         .dir_y = dy, .dir_z = -1.0f, .tfar = INFINITY, .mask = mask[q]},
                                 .live = true};
            reference(scene, &rays[q]);
            if (rays[q].ref.hit.geom_id < 2) hits[rays[q].ref.hit.geom_id]++;
        }
    CHECKF(hits[0] > 0 && hits[1] > 0, "ray masks: each grid is hit (%u, %u)", hits[0], hits[1]);
    p.mask = mask;
    const rp_traversal algs[] = {RP_TRAVERSAL_MASKED, RP_TRAVERSAL_RANGED, RP_TRAVERSAL_PARTITION,
                                 RP_TRAVERSAL_SPAN, RP_TRAVERSAL_AUTO};
    for (size_t a = 0; a < sizeof algs / sizeof algs[0]; a++)
        for (int fr = 0; fr < 2; fr++)
            for (int occ = 0; occ < 2; occ++) {
                rp_query_n_desc d = {.traversal = algs[a], .frustum = fr ? RP_FRUSTUM_PRIMARY : RP_FRUSTUM_NONE};
                uint32_t bad = trace_compare(scene, &d, &p, rays, occ);
                CHECKF(bad == 0, "ray masks: traversal %d, frustum %d, %s: %u rays differ", (int)algs[a], fr,
                       occ ? "occluded" : "intersect", bad);
            }
    p.mask = NULL;
    free(mask);
    rp_rayhit_n_free(dev, &p);
    rp_scene_release(scene);
    rp_device_release(dev);
}

int main(void) {
    bool small = rp_test_sanitized();
    check_api();
    check_cone_edges();
    check_span_whole();
    check_ray_masks();
    world w;
    if (load_world("stanford_bunny_bun_zipper.ply.gz", "bunny", &w)) {
        check_world(&w, small ? 32 : 64, !small);
        check_conservative(&w, small ? 30 : 300);
        check_auto_apart(&w);
        rp_scene_data_free(&w.sd);
    } else {
        CHECK(!"bunny loads");
    }
    if (load_world("spd_rings_s5.nff.gz", "rings", &w)) {
        check_world(&w, small ? 32 : 64, false);
        if (!small) check_conservative(&w, 150);
        rp_scene_data_free(&w.sd);
    } else {
        CHECK(!"rings loads");
    }
    if (!small) {
        if (load_world("conference_geom.obj.gz", "conference", &w)) {
            check_world(&w, 64, false);
            check_conservative(&w, 150);
            rp_scene_data_free(&w.sd);
        } else {
            CHECK(!"conference loads");
        }
    }
    return RP_TEST_END();
}
