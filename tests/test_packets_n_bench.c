// rp-test: labels=bench timeout=600 sanitized=no
/* Large-packet benchmark (Overbeck et al. 2008, sec. 5): Mrays/s of every traversal mode, packet
 * size and frustum setting on the rays of a Whitted frame (primary, shadow, reflection,
 * refraction), one thread, best of RP_BENCH_REPS runs. Checks its results against rp_intersect1 /
 * rp_occluded1 before timing them. Under CTest it runs on a tiny bunny frame so it cannot rot;
 * for measurements:
 *   RP_BENCH_SCENES=bunny,conference,rings RP_BENCH_RES=512 RP_BENCH_REPS=3 ./test_packets_n_bench
 * RP_BENCH_N=16 and RP_BENCH_FRUSTUM=0|1 keep one packet size / frustum setting; RP_BENCH_COUNTERS=1
 * adds the work counters (box and triangle tests per ray, frustum culls); RP_BENCH_COMPARE=1 times
 * simd, masked, ranged, partition, span and auto in round-robin on one setting (default 16x16, frusta on). */
#include <math.h>
#include <time.h>

#include "packets_n_gen.h"

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Traces the frame's rays of one type in n x n packets; returns seconds, counts mismatches. */
static double trace(rp_device *dev, rp_scene *scene, const test_ray *rays, int res, uint32_t n,
                    const rp_query_n_desc *desc, bool occluded, uint32_t *bad) {
    rp_rayhit_n p;
    rp_rayhit_n_alloc(dev, n, &p);
    int32_t *valid = malloc(sizeof(int32_t) * n * n);
    p.valid = valid;
    double t0 = now();
    for (int py = 0; py + (int)n <= res; py += (int)n)
        for (int px = 0; px + (int)n <= res; px += (int)n) {
            for (uint32_t y = 0; y < n; y++)
                for (uint32_t x = 0; x < n; x++) {
                    uint32_t q = rp_packet_n_index(n, x, y);
                    const test_ray *t = &rays[(py + (int)y) * res + px + (int)x];
                    valid[q] = t->live ? -1 : 0;
                    p.org_x[q] = t->ray.org_x, p.org_y[q] = t->ray.org_y, p.org_z[q] = t->ray.org_z;
                    p.dir_x[q] = t->ray.dir_x, p.dir_y[q] = t->ray.dir_y, p.dir_z[q] = t->ray.dir_z;
                    p.tnear[q] = t->ray.tnear, p.tfar[q] = t->ray.tfar, p.geom_id[q] = RP_INVALID_ID;
                }
            if (occluded) rp_occluded_n(scene, desc, &p);
            else rp_intersect_n(scene, desc, &p);
            if (!bad) continue;
            for (uint32_t y = 0; y < n; y++)
                for (uint32_t x = 0; x < n; x++) {
                    uint32_t q = rp_packet_n_index(n, x, y);
                    const test_ray *t = &rays[(py + (int)y) * res + px + (int)x];
                    if (!t->live) continue;
                    if (occluded) *bad += (p.tfar[q] == -INFINITY) != t->occluded;
                    else *bad += p.geom_id[q] != t->ref.hit.geom_id ||
                                 (t->ref.hit.geom_id != RP_INVALID_ID && p.tfar[q] != t->ref.ray.tfar);
                }
        }
    double dt = now() - t0;
    free(valid);
    rp_rayhit_n_free(dev, &p);
    return dt;
}

static int env_int(const char *name, int def) {
    const char *s = getenv(name);
    return s ? atoi(s) : def;
}

/* Masked, ranged, partition, span, auto and simd on one packet size and frustum setting, in
 * round-robin so that the machine's drift hits them alike: best time of `reps` rounds each. */
static void compare_modes(rp_device *dev, rp_scene *scene, const world *w, test_ray *rays[RAY_TYPES], int res,
                          uint32_t n, int fr, int reps) {
    static const size_t cmp[6] = {6, 0, 1, 2, 3, 4};
    printf("  round-robin, %ux%u, frustum %s, best of %d: Mrays/s\n", n, n, fr ? "on" : "off", reps);
    for (int t = 0; t < RAY_TYPES; t++) {
        uint32_t live = 0;
        for (int i = 0; i < res * res; i++) live += rays[t][i].live;
        double best[6] = {1e30, 1e30, 1e30, 1e30, 1e30, 1e30};
        for (int r = 0; r < reps; r++)
            for (int c = 0; c < 6; c++) {
                rp_query_n_desc d = {.traversal = modes[cmp[c]], .frustum = fr ? ray_frustum[t] : RP_FRUSTUM_NONE};
                memcpy(d.point, w->light, sizeof d.point);
                uint32_t bad = 0;
                double dt = trace(dev, scene, rays[t], res, n, &d, t == RAY_SHADOW, r == 0 ? &bad : NULL);
                CHECK(bad == 0);
                best[c] = dt < best[c] ? dt : best[c];
            }
        double fixed = 0.0;
        printf("    %-10s", ray_names[t]);
        for (int c = 0; c < 6; c++) {
            double mr = live / best[c] * 1e-6;
            if (c >= 1 && c <= 4 && mr > fixed) fixed = mr;
            printf(" %s %6.2f", mode_names[cmp[c]], mr);
        }
        printf("  | auto / best fixed %.2f\n", live / best[5] * 1e-6 / fixed);
    }
}

static void bench_world(const world *w, int res, int reps) {
    int only_n = env_int("RP_BENCH_N", 0), only_f = env_int("RP_BENCH_FRUSTUM", -1);
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_scene *scene = make_scene(dev, &w->sd);
    float diag = 0.0f;
    for (int a = 0; a < 3; a++) diag += (w->hi[a] - w->lo[a]) * (w->hi[a] - w->lo[a]);
    diag = sqrtf(diag);
    test_ray *rays[RAY_TYPES];
    for (int t = 0; t < RAY_TYPES; t++) {
        rays[t] = malloc(sizeof(test_ray) * (size_t)(res * res));
        make_rays(w, scene, t, res, 1e-4f * diag, rays[0], rays[t]);
    }
    printf("%s: %zu triangles, %dx%d, isa %d, best of %d, Mrays/s (x: speedup over simd)\n", w->name,
           w->sd.triangle_count, res, res, rp_device_isa(dev), reps);
    if (env_int("RP_BENCH_COMPARE", 0)) {
        compare_modes(dev, scene, w, rays, res, only_n ? (uint32_t)only_n : 16, only_f >= 0 ? only_f : 1, reps);
        for (int t = 0; t < RAY_TYPES; t++) free(rays[t]);
        rp_scene_release(scene);
        rp_device_release(dev);
        return;
    }
    for (int t = 0; t < RAY_TYPES; t++) {
        uint32_t live = 0;
        for (int i = 0; i < res * res; i++) live += rays[t][i].live;
        bool occ = t == RAY_SHADOW;
        double base = 0.0;
        printf("  %s (%s, %u rays)\n", ray_names[t], occ ? "occluded" : "intersect", live);
        static const size_t order[7] = {5, 6, 0, 1, 2, 3, 4}; /* single, simd first: simd is the baseline */
        for (size_t o = 0; o < 7; o++) {
            size_t m = order[o];
            bool small = modes[m] == RP_TRAVERSAL_SINGLE || modes[m] == RP_TRAVERSAL_SIMD;
            printf("    %-9s", mode_names[m]);
            for (uint32_t n = 4; n <= 32; n *= 2) {
                if (only_n && !small && n != (uint32_t)only_n) continue;
                for (int fr = 0; fr < (small ? 1 : 2); fr++) {
                    if (only_f >= 0 && !small && fr != only_f) continue;
                    rp_query_n_desc d = {.traversal = modes[m], .frustum = fr ? ray_frustum[t] : RP_FRUSTUM_NONE};
                    memcpy(d.point, w->light, sizeof d.point);
                    uint32_t bad = 0;
                    double best = trace(dev, scene, rays[t], res, n, &d, occ, &bad);
                    CHECKF(bad == 0, "%s %s %s %u: %u results differ", w->name, ray_names[t], mode_names[m], n, bad);
                    for (int r = 1; r < reps; r++) {
                        double dt = trace(dev, scene, rays[t], res, n, &d, occ, NULL);
                        best = dt < best ? dt : best;
                    }
                    if (getenv("RP_BENCH_COUNTERS") && !small) {
                        rp_counters_n c;
                        memset(&c, 0, sizeof c);
                        d.counters = &c;
                        trace(dev, scene, rays[t], res, n, &d, occ, NULL);
                        d.counters = NULL;
                        printf("\n      [%s %u f%c: per ray: box %.2f tri %.2f; frustum box %.3f/%.3f tri %.3f/%.3f "
                               "(tests/culls); packets masked/ranged/partition/span/simd %llu/%llu/%llu/%llu/%llu]",
                               mode_names[m], n, fr ? '+' : '-', (double)c.box_tests / live, (double)c.tri_tests / live,
                               (double)c.frustum_box_tests / live, (double)c.frustum_box_culls / live,
                               (double)c.frustum_tri_tests / live, (double)c.frustum_tri_culls / live,
                               (unsigned long long)c.traversal[1], (unsigned long long)c.traversal[2],
                               (unsigned long long)c.traversal[3], (unsigned long long)c.traversal[4],
                               (unsigned long long)c.traversal[5]);
                    }
                    double mr = live / best * 1e-6;
                    if (modes[m] == RP_TRAVERSAL_SIMD) base = mr;
                    printf("  %2u%s %7.2f", n, small ? "    " : fr ? " f+" : " f-", mr);
                    if (base > 0.0 && !small) printf(" (%.2fx)", mr / base);
                }
                if (small) break; /* packet size does not matter to these */
            }
            printf("\n");
        }
        fflush(stdout);
    }
    for (int t = 0; t < RAY_TYPES; t++) free(rays[t]);
    rp_scene_release(scene);
    rp_device_release(dev);
}

int main(void) {
    const char *list = getenv("RP_BENCH_SCENES");
    if (!list) list = "bunny";
    int res = env_int("RP_BENCH_RES", 64), reps = env_int("RP_BENCH_REPS", 1);
    static const char *names[3] = {"bunny", "conference", "rings"};
    static const char *files[3] = {"stanford_bunny_bun_zipper.ply.gz", "conference_geom.obj.gz", "spd_rings_s5.nff.gz"};
    for (int i = 0; i < 3; i++) {
        if (!strstr(list, names[i])) continue;
        world w;
        if (!load_world(files[i], names[i], &w)) {
            CHECK(!"scene loads");
            continue;
        }
        bench_world(&w, res, reps);
        rp_scene_data_free(&w.sd);
    }
    return RP_TEST_END();
}
