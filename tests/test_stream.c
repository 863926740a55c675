// rp-test: labels=core timeout=300
/* The stream tracer (src/stream) on the shared bunny, Cornell box and conference, from the default
 * camera and random ones: every eye ray's hit equals rp_intersect1's bit for bit; the eyelight image
 * equals the packet renderer's --integrator eyelight image value for value; the statistics are
 * deterministic, their sums hold (passes = traversal + intersection + other), no ray does more
 * steps or tests than there were passes of that kind, the per-ray work equals the single-ray grid
 * loop's and does not depend on the oracle (20% rule, naive); shadow shading traces shadow rays.
 * Whitted on cornell_box, spd_teapot, bart_museum5 (its cones through the grid) and bart_kitchen
 * (refraction), and path
 * tracing, direct lighting and AO on cornell_original: the stream's image equals rp_render's bit
 * for bit, with both schedulers, with as many rays of each kind as rp_render traced, and the
 * statistics per ray kind add up to the totals. */
#include <math.h>
#include <stdint.h>

#include "accel/grid/grid.h"
#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"
#include "stream/stream.h"

static uint64_t rng_state = 99;
static float rng_f(void) {
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (float)(rng_state >> 40) * (1.0f / 16777216.0f);
}

static bool same_f(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

static void check_view(rp_render_scene *rs, const grid *g, const char *name, const rp_camera *cam, int w, int h) {
    size_t n = (size_t)w * (size_t)h;
    float *px = malloc(n * 3 * sizeof(float)), *ref = malloc(n * 3 * sizeof(float));
    rp_rayhit *hits = malloc(n * sizeof(rp_rayhit));
    char err[256] = "";
    stream_desc sd = {.width = w, .height = h, .camera = cam};
    stream_stats st, st2;
    CHECKF(stream_render(rs, g, &sd, px, hits, &st, err, sizeof err), "%s: %s", name, err);
    /* hits ray for ray */
    rp_scene *scene = rp_render_scene_core(rs);
    size_t bad = 0;
    grid_work work = {0};
    for (size_t i = 0; i < n; i++) {
        rp_rayhit a = hits[i];
        a.ray.tfar = INFINITY;
        a.hit = (rp_hit){.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID};
        rp_rayhit b = a;
        rp_intersect1(scene, &a);
        grid_intersect1(g, &b, &work);
        const rp_rayhit *s = &hits[i];
        bool same = a.hit.geom_id == s->hit.geom_id && a.hit.prim_id == s->hit.prim_id && same_f(a.ray.tfar, s->ray.tfar);
        if (same && a.hit.geom_id != RP_INVALID_ID)
            same = same_f(a.hit.u, s->hit.u) && same_f(a.hit.v, s->hit.v) && same_f(a.hit.Ng_x, s->hit.Ng_x) &&
                   same_f(a.hit.Ng_y, s->hit.Ng_y) && same_f(a.hit.Ng_z, s->hit.Ng_z);
        bad += !same;
    }
    CHECKF(bad == 0, "%s: %zu of %zu stream hits differ from rp_intersect1", name, bad, n);
    /* the same per-ray work as the single-ray grid loop (same voxels, same mailbox) */
    CHECKF(work.voxels == st.voxels && work.tests == st.tests, "%s: voxels %llu/%llu tests %llu/%llu", name,
           (unsigned long long)work.voxels, (unsigned long long)st.voxels, (unsigned long long)work.tests,
           (unsigned long long)st.tests);
    /* the packet renderer's eyelight image */
    rp_render_desc rd = {.width = w, .height = h, .integrator = RP_INTEGRATOR_EYELIGHT, .camera = cam};
    CHECK(rp_render(rs, &rd, ref, NULL));
    size_t diff = 0;
    for (size_t i = 0; i < n * 3; i++) diff += !same_f(px[i], ref[i]);
    CHECKF(diff == 0, "%s: %zu of %zu values differ from the eyelight integrator's", name, diff, n * 3);
    /* sums, bounds, determinism */
    CHECK(st.passes == st.traversal_passes + st.intersection_passes + st.other_passes);
    CHECK(st.other_passes == 3 && st.rays == n && st.eye_rays == n && st.shades == st.eye_hits);
    CHECKF(st.max_voxels <= st.traversal_passes + 1 && st.max_tests <= st.intersection_passes,
           "%s: max %u/%u, passes %llu/%llu", name, st.max_voxels, st.max_tests,
           (unsigned long long)st.traversal_passes, (unsigned long long)st.intersection_passes);
    CHECK(st.simd_efficiency > 0.0 && st.simd_efficiency <= 1.0 && st.work <= st.slots);
    CHECK(stream_render(rs, g, &sd, px, NULL, &st2, err, sizeof err));
    st2.ms = st.ms;
    CHECKF(memcmp(&st, &st2, sizeof st) == 0, "%s: statistics differ between two runs", name);
    /* the naive oracle: other passes, the same work per ray and the same image */
    stream_desc naive = sd;
    naive.oracle = 1e-9f;
    CHECK(stream_render(rs, g, &naive, px, NULL, &st2, err, sizeof err));
    diff = 0;
    for (size_t i = 0; i < n * 3; i++) diff += !same_f(px[i], ref[i]);
    CHECK(diff == 0 && st2.voxels == st.voxels && st2.tests == st.tests && st2.max_voxels == st.max_voxels);
    CHECK(st2.passes == st2.traversal_passes + st2.intersection_passes + st2.other_passes);
    printf("%s %dx%d: %.2f voxels, %.2f tests, %.2f shades per ray; passes %llu = %llu + %llu + %llu (naive "
           "oracle %llu); max %u / %u; SIMD efficiency %.3f\n",
           name, w, h, (double)st.voxels / (double)n, (double)st.tests / (double)n, (double)st.shades / (double)n,
           (unsigned long long)st.passes, (unsigned long long)st.traversal_passes,
           (unsigned long long)st.intersection_passes, (unsigned long long)st.other_passes,
           (unsigned long long)st2.passes, st.max_voxels, st.max_tests, st.simd_efficiency);
    /* the wavefront scheduler: the same image and work per ray, every ray of a pass busy */
    stream_desc wave = sd;
    wave.wavefront = true;
    CHECK(stream_render(rs, g, &wave, px, NULL, &st2, err, sizeof err));
    diff = 0;
    for (size_t i = 0; i < n * 3; i++) diff += !same_f(px[i], ref[i]);
    CHECKF(diff == 0 && st2.voxels == st.voxels && st2.tests == st.tests && st2.max_tests == st.max_tests &&
               st2.passes == st2.traversal_passes + st2.intersection_passes + st2.other_passes &&
               (st2.slots == 0 || st2.simd_efficiency == 1.0),
           "%s: wavefront: %zu values differ, efficiency %.3f", name, diff, st2.simd_efficiency);
    /* eye light of 3 samples from sample 1 (the renderer's desc: spp, sample_start), a stream each:
     * rp_render's image value for value (the stream engine had traced the pixel centres alone) */
    rp_render_desc rd3 = {.width = w, .height = h, .integrator = RP_INTEGRATOR_EYELIGHT, .camera = cam, .spp = 3,
                          .sample_start = 1};
    stream_desc sd3 = sd;
    sd3.render = &rd3;
    CHECK(rp_render(rs, &rd3, ref, NULL));
    CHECK(stream_render(rs, g, &sd3, px, NULL, &st2, err, sizeof err));
    diff = 0;
    for (size_t i = 0; i < n * 3; i++) diff += !same_f(px[i], ref[i]);
    CHECKF(diff == 0 && st2.eye_rays == 3 * n, "%s: eye light, 3 samples: %zu of %zu values differ from rp_render's",
           name, diff, n * 3);
    /* shadow shading: a second stream of any-hit rays; every pixel written, a miss black (the
     * buffer was left as it came, garbage from malloc) */
    sd.shading = STREAM_SHADE_SHADOW;
    for (size_t i = 0; i < n * 3; i++) px[i] = NAN;
    CHECK(stream_render(rs, g, &sd, px, NULL, &st2, err, sizeof err));
    CHECK(st2.shadow_rays > 0 && st2.rays == n + st2.shadow_rays && st2.other_passes == 5);
    size_t unwritten = 0, lit_misses = 0;
    for (size_t i = 0; i < n; i++) {
        unwritten += isnan(px[3 * i]) || isnan(px[3 * i + 1]) || isnan(px[3 * i + 2]);
        lit_misses += hits[i].hit.geom_id == RP_INVALID_ID && !(px[3 * i] == 0.0f && px[3 * i + 1] == 0.0f && px[3 * i + 2] == 0.0f);
    }
    CHECKF(unwritten == 0 && lit_misses == 0, "%s: shadow shading left %zu pixels unwritten, %zu misses not black", name,
           unwritten, lit_misses);
    CHECK(st2.passes == st2.traversal_passes + st2.intersection_passes + st2.other_passes);
    free(px), free(ref), free(hits);
}

static void check_file(rp_device *dev, const char *file, int w, int h) {
    char buf[512], err[512] = "";
    const char *path = rp_test_scene(file, buf, sizeof buf);
    CHECKF(path != NULL, "%s", file);
    if (!path) return;
    rp_scene_data d;
    bool ok = rp_scene_data_load(path, &d, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    rp_render_scene *rs = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s: %s", file, err);
    grid *g = rs ? grid_build_scene(rp_render_scene_core(rs), NULL, err, sizeof err) : NULL;
    CHECKF(g != NULL, "%s: %s", file, err);
    if (g) {
        rp_camera cam = rp_render_scene_default_camera(rs);
        check_view(rs, g, file, &cam, w, h);
        /* random cameras: inside and outside the box, random fields of view */
        for (int k = 0; k < 2; k++) {
            rp_camera c = cam;
            for (int a = 0; a < 3; a++) {
                float lo = g->lo[a], hi = g->hi[a], e = hi - lo;
                c.pinhole.eye[a] = k == 0 ? lo + e * rng_f() : lo - e + 3.0f * e * rng_f();
                c.pinhole.look[a] = lo + e * rng_f();
            }
            c.pinhole.fov_deg = 20.0f + 100.0f * rng_f();
            char label[600];
            snprintf(label, sizeof label, "%s (random camera %d)", file, k);
            check_view(rs, g, label, &c, w / 2 + 3, h / 2 + 1);
        }
    }
    grid_free(g);
    rp_render_scene_release(rs);
    rp_scene_data_free(&d);
}

/* The renderer's integrator on the stream against rp_render (the packet renderer) with the same
 * desc: every value bit for bit, for both schedulers; the statistics per ray kind add up to the
 * totals and are the same twice. */
/* box: a homogeneous medium in it (lo xyz, hi xyz), or NULL */
static void check_integrator_in(rp_device *dev, const char *file, const float *box, rp_integrator_type integrator, int w,
                                int h, int spp, int want_kind) {
    char buf[512], err[512] = "";
    const char *path = rp_test_scene(file, buf, sizeof buf);
    CHECKF(path != NULL, "%s", file);
    if (!path) return;
    rp_scene_data d;
    bool ok = rp_scene_data_load(path, &d, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    CHECK(!box || rp_scene_data_add_medium_box(&d, box, box + 3));
    /* flat, as the stream engine builds animated scenes */
    rp_render_scene *rs = rp_render_scene_new(dev, &d, &(rp_render_scene_desc){.flatten_animation = true}, err, sizeof err);
    CHECKF(rs != NULL, "%s: %s", file, err);
    grid *g = rs ? grid_build_scene(rp_render_scene_core(rs), NULL, err, sizeof err) : NULL;
    CHECKF(g != NULL, "%s: %s", file, err);
    size_t n = (size_t)w * (size_t)h;
    float *px = malloc(n * 3 * sizeof(float)), *ref = malloc(n * 3 * sizeof(float));
    if (g && px && ref) {
        rp_camera cam = rp_render_scene_default_camera(rs);
        rp_render_desc rd = {.width = w, .height = h, .integrator = integrator, .spp = spp, .camera = &cam};
        rp_render_stats rst;
        CHECK(rp_render(rs, &rd, ref, &rst));
        for (int wave = 0; wave < 2; wave++) {
            stream_desc sd = {.width = w, .height = h, .camera = &cam, .render = &rd, .wavefront = wave == 1};
            stream_stats st, st2;
            CHECKF(stream_render(rs, g, &sd, px, NULL, &st, err, sizeof err), "%s: %s", file, err);
            size_t diff = 0, lit = 0;
            for (size_t i = 0; i < n * 3; i++) diff += !same_f(px[i], ref[i]), lit += ref[i] > 0.0f;
            CHECKF(diff == 0 && lit > n / 4, "%s (integrator %d, %s): %zu of %zu values differ from rp_render's, %zu lit",
                   file, (int)integrator, wave ? "wavefront" : "multipass", diff, n * 3, lit);
            /* sums: passes, and the kinds against the totals */
            CHECK(st.passes == st.traversal_passes + st.intersection_passes + st.other_passes);
            uint64_t rays = 0, voxels = 0, tests = 0, trav = 0, isect = 0;
            uint32_t maxv = 0, maxt = 0;
            for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
                const stream_kind_stats *ks = &st.kind[k];
                rays += ks->rays, voxels += ks->voxels, tests += ks->tests;
                trav += ks->traversal_passes, isect += ks->intersection_passes;
                maxv = ks->max_voxels > maxv ? ks->max_voxels : maxv, maxt = ks->max_tests > maxt ? ks->max_tests : maxt;
                CHECK(ks->hits <= ks->rays && (ks->rays == 0) == (ks->batches == 0));
            }
            CHECKF(rays == st.rays && voxels == st.voxels && tests == st.tests && trav == st.traversal_passes &&
                       isect == st.intersection_passes && maxv == st.max_voxels && maxt == st.max_tests,
                   "%s: the kinds' statistics do not add up to the totals", file);
            CHECK(st.kind[RP_RAY_PRIMARY].rays == n * (size_t)spp && st.eye_rays == n * (size_t)spp);
            /* the same rays of each kind as the packet renderer traced */
            for (int k = 0; k < RP_RAY_KIND_COUNT; k++)
                CHECKF(st.kind[k].rays == rst.rays[k], "%s: %llu rays of kind %d, rp_render %llu", file,
                       (unsigned long long)st.kind[k].rays, k, (unsigned long long)rst.rays[k]);
            CHECK(st.kind[RP_RAY_SHADOW].rays == st.shadow_rays && st.kind[RP_RAY_SHADOW].hits == st.shadow_blocked &&
                  st.shadow_rays > 0);
            CHECKF(want_kind < 0 || st.kind[want_kind].rays > 0, "%s: no rays of kind %d", file, want_kind);
            CHECK(st.simd_efficiency > 0.0 && st.simd_efficiency <= 1.0 && st.work <= st.slots);
            CHECK(stream_render(rs, g, &sd, px, NULL, &st2, err, sizeof err));
            st2.ms = st.ms;
            CHECKF(memcmp(&st, &st2, sizeof st) == 0, "%s: statistics differ between two runs", file);
            if (!wave)
                printf("%s integrator %d %dx%d %d spp: %llu rays (primary %llu, shadow %llu, reflection %llu, "
                       "refraction %llu, bounce %llu); passes %llu = %llu + %llu + %llu; same as rp_render\n",
                       file, (int)integrator, w, h, spp, (unsigned long long)st.rays,
                       (unsigned long long)st.kind[0].rays, (unsigned long long)st.kind[1].rays,
                       (unsigned long long)st.kind[2].rays, (unsigned long long)st.kind[3].rays,
                       (unsigned long long)st.kind[4].rays, (unsigned long long)st.passes,
                       (unsigned long long)st.traversal_passes, (unsigned long long)st.intersection_passes,
                       (unsigned long long)st.other_passes);
        }
    }
    free(px), free(ref);
    grid_free(g);
    rp_render_scene_release(rs);
    rp_scene_data_free(&d);
}

static void check_integrator(rp_device *dev, const char *file, rp_integrator_type integrator, int w, int h, int spp,
                             int want_kind) {
    check_integrator_in(dev, file, NULL, integrator, w, h, spp, want_kind);
}

int main(void) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    CHECK(dev != NULL);
    if (!dev) return RP_TEST_END();
    bool small = rp_test_sanitized();
    check_file(dev, "stanford_bunny_bun_zipper.ply.gz", small ? 40 : 96, small ? 30 : 72);
    check_file(dev, "cornell_box/cornell_box.obj", small ? 32 : 64, small ? 32 : 64);
    check_file(dev, "conference_geom.obj.gz", small ? 40 : 80, small ? 30 : 60);
    /* Whitted (shadow, reflection and refraction streams) and path tracing (shadow and bounce
     * streams), direct lighting and AO, against the packet renderer */
    check_integrator(dev, "cornell_box/cornell_box.obj", RP_INTEGRATOR_WHITTED, small ? 24 : 48, small ? 24 : 48, 1,
                     RP_RAY_SHADOW);
    check_integrator(dev, "spd_teapot.nff.gz", RP_INTEGRATOR_WHITTED, small ? 32 : 64, small ? 24 : 48, 2,
                     RP_RAY_REFLECTION);
    check_integrator(dev, "bart_museum5.tar.gz", RP_INTEGRATOR_WHITTED, small ? 32 : 64, small ? 24 : 48, 1,
                     RP_RAY_REFLECTION);
    /* glass: refraction streams */
    check_integrator(dev, "bart_kitchen.tar.gz", RP_INTEGRATOR_WHITTED, small ? 24 : 48, small ? 18 : 36, 1,
                     RP_RAY_REFRACTION);
    check_integrator(dev, "cornell_original/CornellBox-Original.obj", RP_INTEGRATOR_PATH, small ? 16 : 32,
                     small ? 16 : 32, small ? 2 : 4, RP_RAY_BOUNCE);
    check_integrator(dev, "cornell_original/CornellBox-Original.obj", RP_INTEGRATOR_DIRECT, 16, 16, 2, RP_RAY_BOUNCE);
    check_integrator(dev, "cornell_original/CornellBox-Original.obj", RP_INTEGRATOR_AO, 16, 16, 2, RP_RAY_SHADOW);
    /* more than one chunk of 4096 rays: the shading kernels on both threads, merged in order */
    check_integrator(dev, "cornell_original/CornellBox-Original.obj", RP_INTEGRATOR_PATH, small ? 80 : 128,
                     small ? 64 : 96, 1, RP_RAY_BOUNCE);
    check_integrator(dev, "bart_kitchen.tar.gz", RP_INTEGRATOR_WHITTED, small ? 80 : 128, small ? 64 : 72, 1,
                     RP_RAY_REFRACTION);
    /* in a participating medium: Whitted composites it over the eye ray (the stream keeps each
     * pixel's opacity from the eye stream), path tracing tracks it; more than one chunk */
    const float box[6] = {150, 100, 150, 400, 350, 400};
    check_integrator_in(dev, "cornell_box/cornell_box.obj", box, RP_INTEGRATOR_WHITTED, small ? 72 : 80, 64, 1,
                        RP_RAY_SHADOW);
    check_integrator_in(dev, "cornell_box/cornell_box.obj", box, RP_INTEGRATOR_PATH, 24, 24, 1, RP_RAY_BOUNCE);
    rp_device_release(dev);
    return RP_TEST_END();
}
