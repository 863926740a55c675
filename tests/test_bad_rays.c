// rp-test: labels=core timeout=600
/* Rays no traversal should trust (issue 23): NaN or Inf in an origin or direction, a zero
 * direction, NaN tnear/tfar, tnear > tfar, tnear = +inf. Through every query entry point
 * (rp_intersect1/4/8/16, _array both ways, _n with every traversal and frustum and packet size,
 * and the occluded twins), on every ISA the CPU has, such a ray is a miss: hit.geom_id stays
 * RP_INVALID_ID and tfar keeps its bits (occluded: tfar is not set to -inf), never a crash or a hang
 * (alarm). Good rays sharing the packet get exactly the answers they get alone. */
#include <math.h>
#include <signal.h>
#include <unistd.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "rp_test.h"

enum { BAD_KINDS = 16 };
static const char *const BAD_NAMES[BAD_KINDS] = {
    "org.x NaN", "org.y +Inf", "org.z -Inf", "dir.x NaN", "dir.y NaN", "dir.z +Inf", "dir -Inf,0,0", "dir 0,0,0",
    "tnear NaN", "tfar NaN", "tnear > tfar", "tnear +Inf", "dir NaN,NaN,NaN", "org Inf,Inf,Inf", "dir Inf,Inf,Inf",
    "tfar -Inf"};

typedef struct ray_s {
    float o[3], d[3], tn, tf;
} ray_s;

/* A good ray into the scene (the unit cube of the soup), from random origins around it. */
static ray_s good_ray(test_rng *r) {
    ray_s g;
    for (int a = 0; a < 3; a++) {
        g.o[a] = 0.5f + (test_rng_float(r) - 0.5f) * 3.0f;
        g.d[a] = 0.5f + (test_rng_float(r) - 0.5f) * 0.6f - g.o[a];
    }
    g.tn = 0.0f, g.tf = INFINITY;
    return g;
}

static ray_s bad_ray(test_rng *r, int kind) {
    ray_s b = good_ray(r);
    switch (kind) {
    case 0: b.o[0] = NAN; break;
    case 1: b.o[1] = INFINITY; break;
    case 2: b.o[2] = -INFINITY; break;
    case 3: b.d[0] = NAN; break;
    case 4: b.d[1] = NAN; break;
    case 5: b.d[2] = INFINITY; break;
    case 6: b.d[0] = -INFINITY, b.d[1] = b.d[2] = 0.0f; break;
    case 7: b.d[0] = b.d[1] = b.d[2] = 0.0f; break;
    case 8: b.tn = NAN; break;
    case 9: b.tf = NAN; break;
    case 10: b.tn = 2.0f, b.tf = 1.0f; break;
    case 11: b.tn = INFINITY; break;
    case 12: b.d[0] = b.d[1] = b.d[2] = NAN; break;
    case 13: b.o[0] = b.o[1] = b.o[2] = INFINITY; break;
    case 14: b.d[0] = b.d[1] = b.d[2] = INFINITY; break;
    default: b.tf = -INFINITY; break;
    }
    return b;
}

typedef struct answer {
    uint32_t geom, prim;
    uint32_t tfar_bits;
} answer;

static uint32_t bits(float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    return u;
}

static rp_rayhit to_rayhit(const ray_s *s) {
    rp_rayhit rh = {.ray = {.org_x = s->o[0], .org_y = s->o[1], .org_z = s->o[2], .tnear = s->tn, .dir_x = s->d[0],
                            .dir_y = s->d[1], .dir_z = s->d[2], .tfar = s->tf, .mask = ~0u}};
    rh.hit.geom_id = RP_INVALID_ID;
    return rh;
}

/* The lanes of one batch: kind < 0 for a good ray, else the bad kind. */
enum { BATCH = 32 * 32 };
static ray_s rays[BATCH];
static int kinds[BATCH];
static answer expect_hit[BATCH];
static bool expect_occ[BATCH];

static int failures_reported;

static void check_lane(const char *entry, int isa, int i, uint32_t geom, uint32_t prim, float tfar) {
    bool ok;
    if (kinds[i] >= 0)
        ok = geom == RP_INVALID_ID && bits(tfar) == bits(rays[i].tf);
    else
        ok = geom == expect_hit[i].geom && (geom == RP_INVALID_ID || prim == expect_hit[i].prim) &&
             bits(tfar) == expect_hit[i].tfar_bits;
    CHECKF(ok || failures_reported > 20, "%s isa %d lane %d (%s): geom %u prim %u tfar %g", entry, isa, i,
           kinds[i] >= 0 ? BAD_NAMES[kinds[i]] : "good ray", geom, prim, (double)tfar);
    if (!ok) failures_reported++;
}

static void check_occ(const char *entry, int isa, int i, float tfar) {
    bool occluded = tfar == -INFINITY;
    bool ok = kinds[i] >= 0 ? bits(tfar) == bits(rays[i].tf) : occluded == expect_occ[i];
    if (kinds[i] < 0 && !occluded) ok = ok && bits(tfar) == bits(rays[i].tf);
    CHECKF(ok || failures_reported > 20, "%s isa %d lane %d (%s): tfar %g", entry, isa, i,
           kinds[i] >= 0 ? BAD_NAMES[kinds[i]] : "good ray", (double)tfar);
    if (!ok) failures_reported++;
}

#define FILL_PACKET(P, W, base)                                                                    \
    do {                                                                                           \
        for (int l = 0; l < (W); l++) {                                                            \
            const ray_s *rs_ = &rays[(base) + l];                                                  \
            (P).org_x[l] = rs_->o[0], (P).org_y[l] = rs_->o[1], (P).org_z[l] = rs_->o[2];          \
            (P).dir_x[l] = rs_->d[0], (P).dir_y[l] = rs_->d[1], (P).dir_z[l] = rs_->d[2];          \
            (P).tnear[l] = rs_->tn, (P).tfar[l] = rs_->tf, (P).mask[l] = ~0u, (P).time[l] = 0.0f;  \
        }                                                                                          \
    } while (0)

static void run_packets(rp_scene *s, int isa) {
    int32_t valid[16];
    for (int l = 0; l < 16; l++) valid[l] = -1;
    for (int base = 0; base < BATCH; base += 16) {
        rp_rayhit4 h4;
        rp_ray4 r4;
        for (int q = 0; q < 16; q += 4) {
            FILL_PACKET(h4.ray, 4, base + q);
            for (int l = 0; l < 4; l++) h4.hit.geom_id[l] = RP_INVALID_ID;
            rp_intersect4(s, valid, &h4);
            for (int l = 0; l < 4; l++)
                check_lane("rp_intersect4", isa, base + q + l, h4.hit.geom_id[l], h4.hit.prim_id[l], h4.ray.tfar[l]);
            FILL_PACKET(r4, 4, base + q);
            rp_occluded4(s, valid, &r4);
            for (int l = 0; l < 4; l++) check_occ("rp_occluded4", isa, base + q + l, r4.tfar[l]);
        }
        rp_rayhit8 h8;
        rp_ray8 r8;
        for (int q = 0; q < 16; q += 8) {
            FILL_PACKET(h8.ray, 8, base + q);
            for (int l = 0; l < 8; l++) h8.hit.geom_id[l] = RP_INVALID_ID;
            rp_intersect8(s, valid, &h8);
            for (int l = 0; l < 8; l++)
                check_lane("rp_intersect8", isa, base + q + l, h8.hit.geom_id[l], h8.hit.prim_id[l], h8.ray.tfar[l]);
            FILL_PACKET(r8, 8, base + q);
            rp_occluded8(s, valid, &r8);
            for (int l = 0; l < 8; l++) check_occ("rp_occluded8", isa, base + q + l, r8.tfar[l]);
        }
        rp_rayhit16 h16;
        rp_ray16 r16;
        FILL_PACKET(h16.ray, 16, base);
        for (int l = 0; l < 16; l++) h16.hit.geom_id[l] = RP_INVALID_ID;
        rp_intersect16(s, valid, &h16);
        for (int l = 0; l < 16; l++)
            check_lane("rp_intersect16", isa, base + l, h16.hit.geom_id[l], h16.hit.prim_id[l], h16.ray.tfar[l]);
        FILL_PACKET(r16, 16, base);
        rp_occluded16(s, valid, &r16);
        for (int l = 0; l < 16; l++) check_occ("rp_occluded16", isa, base + l, r16.tfar[l]);
    }
}

static void run_arrays(rp_scene *s, int isa) {
    static rp_rayhit rh[BATCH];
    static rp_ray rr[BATCH];
    for (uint32_t flags = 0; flags < 2; flags++) {
        for (int i = 0; i < BATCH; i++) rh[i] = to_rayhit(&rays[i]), rr[i] = rh[i].ray;
        rp_intersect_array(s, rh, BATCH, flags);
        rp_occluded_array(s, rr, BATCH, flags);
        for (int i = 0; i < BATCH; i++) {
            check_lane(flags ? "rp_intersect_array coherent" : "rp_intersect_array", isa, i, rh[i].hit.geom_id,
                       rh[i].hit.prim_id, rh[i].ray.tfar);
            check_occ(flags ? "rp_occluded_array coherent" : "rp_occluded_array", isa, i, rr[i].tfar);
        }
    }
    for (int i = 0; i < BATCH; i++) {
        rp_rayhit one = to_rayhit(&rays[i]);
        rp_intersect1(s, &one);
        check_lane("rp_intersect1", isa, i, one.hit.geom_id, one.hit.prim_id, one.ray.tfar);
        rp_ray r = to_rayhit(&rays[i]).ray;
        rp_occluded1(s, &r);
        check_occ("rp_occluded1", isa, i, r.tfar);
    }
}

static void run_large(rp_device *dev, rp_scene *s, int isa) {
    static const rp_traversal travs[] = {RP_TRAVERSAL_AUTO,   RP_TRAVERSAL_MASKED, RP_TRAVERSAL_RANGED,
                                         RP_TRAVERSAL_PARTITION, RP_TRAVERSAL_SINGLE, RP_TRAVERSAL_SIMD,
                                         RP_TRAVERSAL_SPAN};
    static const char *const tnames[] = {"auto", "masked", "ranged", "partition", "single", "simd", "span"};
    for (uint32_t n = 4; n <= 32; n *= 2) {
        rp_rayhit_n p;
        if (!rp_rayhit_n_alloc(dev, n, &p)) {
            CHECK(!"rp_rayhit_n_alloc");
            return;
        }
        uint32_t count = n * n;
        for (size_t t = 0; t < sizeof travs / sizeof travs[0]; t++)
            for (int fr = 0; fr < 2; fr++) {
                rp_auto_tally tally = {0};
                rp_query_n_desc q = {.traversal = travs[t], .frustum = fr ? RP_FRUSTUM_SECONDARY : RP_FRUSTUM_NONE,
                                     .tally = &tally};
                for (uint32_t base = 0; base + count <= BATCH; base += count)
                    for (int occ = 0; occ < 2; occ++) {
                        for (uint32_t i = 0; i < count; i++) {
                            const ray_s *r = &rays[base + i];
                            p.org_x[i] = r->o[0], p.org_y[i] = r->o[1], p.org_z[i] = r->o[2];
                            p.dir_x[i] = r->d[0], p.dir_y[i] = r->d[1], p.dir_z[i] = r->d[2];
                            p.tnear[i] = r->tn, p.tfar[i] = r->tf, p.geom_id[i] = RP_INVALID_ID;
                        }
                        char entry[96];
                        snprintf(entry, sizeof entry, "%s n=%u %s%s", occ ? "rp_occluded_n" : "rp_intersect_n", n,
                                 tnames[t], fr ? " +frustum" : "");
                        if (occ) {
                            rp_occluded_n(s, &q, &p);
                            for (uint32_t i = 0; i < count; i++) check_occ(entry, isa, (int)(base + i), p.tfar[i]);
                        } else {
                            rp_intersect_n(s, &q, &p);
                            for (uint32_t i = 0; i < count; i++)
                                check_lane(entry, isa, (int)(base + i), p.geom_id[i], p.prim_id[i], p.tfar[i]);
                        }
                    }
            }
        rp_rayhit_n_free(dev, &p);
    }
}

int main(void) {
    alarm(rp_test_sanitized() ? 540 : 240); /* a hang is a failure, not a stuck CTest */
    test_mesh mesh = test_mesh_soup(20000, 0.03f, 11);
    static float spheres[4 * 16];
    for (int i = 0; i < 16; i++)
        spheres[4 * i] = 0.1f + 0.05f * (float)i, spheres[4 * i + 1] = 0.5f, spheres[4 * i + 2] = 0.5f,
                    spheres[4 * i + 3] = 0.03f;
    static const int isas[] = {1, 4, 8, 16};
    int tested = 0;
    for (size_t ii = 0; ii < sizeof isas / sizeof isas[0]; ii++) {
        rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1, .isa = isas[ii]});
        if (!dev) continue; /* the CPU lacks it */
        tested++;
        rp_scene *s = rp_scene_new(dev, NULL);
        rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
        rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, mesh.v, 0, 0, mesh.nv);
        rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, mesh.idx, 0, 0, mesh.nt);
        rp_scene_attach(s, g);
        rp_geometry_release(g);
        rp_geometry *sp = rp_geometry_new(dev, RP_GEOMETRY_SPHERE);
        rp_geometry_set_buffer(sp, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, spheres, 0, 0, 16);
        rp_scene_attach(s, sp);
        rp_geometry_release(sp);
        CHECK(rp_scene_commit(s) == RP_ERROR_NONE);
        /* the batch: every 3rd lane a bad ray of a kind cycling through them, so bad rays land in
         * corner lanes, whole SIMD rays and mixed ones */
        test_rng r = {(uint64_t)42 + ii};
        for (int i = 0; i < BATCH; i++) {
            int kind = (i % 3 == 0 || (i / 64) % 5 == 4) ? (i / 3 + i / 64) % BAD_KINDS : -1;
            kinds[i] = kind;
            rays[i] = kind < 0 ? good_ray(&r) : bad_ray(&r, kind);
        }
        /* what the good rays get alone, from the scalar single-ray path of this device */
        int hits = 0;
        for (int i = 0; i < BATCH; i++) {
            if (kinds[i] >= 0) continue;
            rp_rayhit one = to_rayhit(&rays[i]);
            rp_intersect1(s, &one);
            expect_hit[i] = (answer){one.hit.geom_id, one.hit.prim_id, bits(one.ray.tfar)};
            hits += one.hit.geom_id != RP_INVALID_ID;
            rp_ray o = to_rayhit(&rays[i]).ray;
            rp_occluded1(s, &o);
            expect_occ[i] = o.tfar == -INFINITY;
        }
        CHECKF(hits > 100, "only %d of the good rays hit: the test would prove little", hits);
        run_arrays(s, isas[ii]);
        run_packets(s, isas[ii]);
        run_large(dev, s, isas[ii]);
        rp_scene_release(s);
        rp_device_release(dev);
    }
    CHECK(tested >= 1);
    printf("%d ISAs, %d kinds of bad rays\n", tested, BAD_KINDS);
    test_mesh_free(&mesh);
    return RP_TEST_END();
}
