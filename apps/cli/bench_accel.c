/* `raypack bench --accel-grid`: every acceleration structure (rp_accel_type) on the same rays -
 * build time, memory, and Mrays/s of single rays, SIMD rays (rp_intersect16 / rp_occluded16) and
 * 16x16 packets (rp_intersect_n, auto traversal with the set's frustum) for primary, shadow,
 * reflection and diffuse rays. The rays and the reference hits are the BVH's single rays; every
 * structure's every mode must find them before anything is timed. Structures take turns inside
 * each repeat, so drift hits them alike. */
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench.h"
#include "cli.h"

#define ACCEL_MODES 3
/* bench_raypack_modes' order: single, packet4, packet8, packet16, ..., n16_auto_frustum */
static const int mode_index[ACCEL_MODES] = {0, 3, 6};
static const char *const mode_names[ACCEL_MODES] = {"single", "simd16", "16x16"};

typedef struct accel_run {
    rp_scene *scene;
    rp_scene_stats st;
    double build_ms;  /* median of the builds */
    bench_mode modes[BENCH_KIND_COUNT][ACCEL_MODES];
    bench_n_engine engines[BENCH_KIND_COUNT][BENCH_N_MODES];
    bench_stat stat[BENCH_KIND_COUNT][ACCEL_MODES];
} accel_run;

/* CPU seconds of the calling thread: on one thread (--threads 1) the modes are timed by it, so other
 * programs on a shared machine do not skew the ratios */
static double thread_cpu_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

int bench_accel_grid(bench_ctx *ctx) {
    ctx->opts.accel = RP_ACCEL_BVH; /* the reference */
    double ref_ms;
    rp_scene_stats ref_st;
    ctx->scene = bench_build_raypack(ctx, &ref_ms, &ref_st);
    if (!ctx->scene || !bench_make_ray_sets(ctx)) return 1; /* either printed why */
    bench_print_header(ctx);
    accel_run *runs = calloc(RP_ACCEL_COUNT, sizeof *runs);
    bench_hits hits;
    if (!runs || !bench_hits_alloc(&hits, ctx->sets[0].slots)) {
        free(runs);
        return 1;
    }
    int failed = 0;
    rp_scene *keep = ctx->scene;
    for (int a = 0; a < RP_ACCEL_COUNT && !failed; a++) {
        accel_run *r = &runs[a];
        ctx->opts.accel = (rp_accel_type)a;
        /* the kd-tree's serial build is slow on large scenes: one build; the others three */
        int builds = a == RP_ACCEL_KDTREE ? 1 : 3;
        double ms[3];
        for (int b = 0; b < builds; b++) {
            if (r->scene) rp_scene_release(r->scene);
            r->scene = bench_build_raypack(ctx, &ms[b], &r->st);
            if (!r->scene) {
                failed = 1;
                break;
            }
        }
        if (failed) break;
        qsort(ms, (size_t)builds, sizeof ms[0], cmp_double);
        r->build_ms = ms[builds / 2];
        ctx->scene = r->scene;
        for (int k = 0; k < BENCH_KIND_COUNT; k++) {
            bench_mode all[8];
            int n = bench_raypack_modes(ctx, &ctx->sets[k], all, 8);
            memcpy(r->engines[k], ctx->n_engines[k], sizeof r->engines[k]);
            for (int m = 0; m < ACCEL_MODES && mode_index[m] < n; m++) {
                r->modes[k][m] = all[mode_index[m]];
                if (mode_index[m] >= 6) r->modes[k][m].engine = &r->engines[k][mode_index[m] - 6];
                r->modes[k][m].name = mode_names[m];
                bench_trace_set(ctx, ctx->opts.threads, &r->modes[k][m], &ctx->sets[k], &hits);
                bench_diff d = bench_compare(&ctx->mesh, &ctx->sets[k], &ctx->ref[k], &hits);
                if (d.total) {
                    fprintf(stderr, "raypack bench: %s %s rays, %s disagrees with the BVH's single rays on %zu of %zu\n",
                            rp_accel_name((rp_accel_type)a), bench_kind_name((bench_kind)k), mode_names[m], d.total,
                            ctx->sets[k].count);
                    bench_print_mismatches(&ctx->mesh, &ctx->sets[k], &ctx->ref[k], &hits, "bvh single",
                                           mode_names[m], 3);
                    failed = 1;
                }
            }
        }
        printf("build     %-7s %9.2f ms, %8.2f MiB, %llu nodes, %llu leaves, depth %u, %llu triangle refs\n",
               rp_accel_name((rp_accel_type)a), r->build_ms, (double)r->st.bytes / 1048576.0,
               (unsigned long long)r->st.binary_nodes, (unsigned long long)r->st.leaves, r->st.depth,
               (unsigned long long)r->st.tri_refs);
    }
    ctx->scene = keep;
    ctx->opts.accel = RP_ACCEL_BVH;
    if (failed) {
        for (int a = 0; a < RP_ACCEL_COUNT; a++)
            if (runs[a].scene) rp_scene_release(runs[a].scene);
        free(runs);
        bench_hits_free(&hits);
        return 1;
    }
    printf("check     every structure and mode finds the BVH's single-ray hits on every ray\n\n");
    int reps = ctx->opts.repeats;
    double *samples = calloc((size_t)reps * RP_ACCEL_COUNT * ACCEL_MODES, sizeof(double));
    for (int k = 0; k < BENCH_KIND_COUNT && samples; k++) {
        const bench_rays *set = &ctx->sets[k];
        for (int w = 0; w < ctx->opts.warmup; w++)
            for (int a = 0; a < RP_ACCEL_COUNT; a++)
                for (int m = 0; m < ACCEL_MODES; m++) bench_trace_set(ctx, ctx->opts.threads, &runs[a].modes[k][m], set, &hits);
        for (int r = 0; r < reps; r++)
            for (int a = 0; a < RP_ACCEL_COUNT; a++)
                for (int m = 0; m < ACCEL_MODES; m++) {
                    double c0 = thread_cpu_seconds();
                    double s = bench_trace_set(ctx, ctx->opts.threads, &runs[a].modes[k][m], set, &hits);
                    if (ctx->opts.threads <= 1) s = thread_cpu_seconds() - c0;
                    samples[((size_t)a * ACCEL_MODES + (size_t)m) * (size_t)reps + (size_t)r] =
                        s > 0.0 ? (double)set->count / s * 1e-6 : 0.0;
                }
        for (int a = 0; a < RP_ACCEL_COUNT; a++)
            for (int m = 0; m < ACCEL_MODES; m++)
                runs[a].stat[k][m] = bench_stats(samples + ((size_t)a * ACCEL_MODES + (size_t)m) * (size_t)reps, reps);
    }
    free(samples);
    bench_hits_free(&hits);
    printf("Mrays/s, median of %d on %d threads (min-max)%s\n", reps, ctx->opts.threads,
           ctx->opts.threads <= 1 ? ", per CPU second of the tracing thread" : "");
    printf("%-11s %-8s", "rays", "mode");
    for (int a = 0; a < RP_ACCEL_COUNT; a++) printf("  %-24s", rp_accel_name((rp_accel_type)a));
    printf("\n");
    for (int k = 0; k < BENCH_KIND_COUNT; k++)
        for (int m = 0; m < ACCEL_MODES; m++) {
            printf("%-11s %-8s", m == 0 ? bench_kind_name((bench_kind)k) : "", mode_names[m]);
            for (int a = 0; a < RP_ACCEL_COUNT; a++) {
                bench_stat s = runs[a].stat[k][m];
                printf("  %7.2f (%6.2f - %6.2f) ", s.median, s.min, s.max);
            }
            printf("\n");
        }
    int rc = 0;
    if (ctx->opts.json_path) {
        FILE *f = fopen(ctx->opts.json_path, "w");
        if (!f) {
            fprintf(stderr, "raypack bench: cannot write %s: %s\n", ctx->opts.json_path, strerror(errno));
            rc = 1;
        } else {
            fprintf(f, "{\"scene\": ");
            bench_json_string(f, ctx->scene_name);
            fprintf(f, ", \"triangles\": %zu, \"threads\": %d, \"width\": %d, \"height\": %d, \"repeats\": %d,\n \"accel\": {",
                    ctx->mesh.triangle_count, ctx->opts.threads, ctx->opts.width, ctx->opts.height, reps);
            for (int a = 0; a < RP_ACCEL_COUNT; a++) {
                const accel_run *r = &runs[a];
                fprintf(f, "%s\n  \"%s\": {\"build_ms\": %.3f, \"bytes\": %zu, \"nodes\": %llu, \"leaves\": %llu, "
                           "\"depth\": %u, \"tri_refs\": %llu, \"rays\": {",
                        a ? "," : "", rp_accel_name((rp_accel_type)a), r->build_ms, r->st.bytes,
                        (unsigned long long)r->st.binary_nodes, (unsigned long long)r->st.leaves, r->st.depth,
                        (unsigned long long)r->st.tri_refs);
                for (int k = 0; k < BENCH_KIND_COUNT; k++) {
                    fprintf(f, "%s\"%s\": {\"count\": %zu", k ? ", " : "", bench_kind_name((bench_kind)k), ctx->sets[k].count);
                    for (int m = 0; m < ACCEL_MODES; m++)
                        fprintf(f, ", \"%s\": {\"mrays_median\": %.4f, \"mrays_min\": %.4f, \"mrays_max\": %.4f}", mode_names[m],
                                r->stat[k][m].median, r->stat[k][m].min, r->stat[k][m].max);
                    fprintf(f, "}");
                }
                fprintf(f, "}}");
            }
            fprintf(f, "\n }\n}\n");
            if (fclose(f) != 0) rc = 1;
        }
    }
    for (int a = 0; a < RP_ACCEL_COUNT; a++)
        if (runs[a].scene) rp_scene_release(runs[a].scene);
    free(runs);
    return rc;
}

/* `raypack bench --builds`: build times alone. The BVH, the BIH and the grid are built --repeats
 * times in turns (BVH, BIH, grid, BVH, ...) in one process, each scene released before the next
 * build, so the structures share the machine's drift and every build after the first reuses memory
 * the process has touched before (a renderer that rebuilds each frame works that way); the
 * kd-tree's serial build, slow on large scenes, runs once at the end. */
int bench_builds(bench_ctx *ctx) {
    static const rp_accel_type turns[] = {RP_ACCEL_BVH, RP_ACCEL_BIH, RP_ACCEL_GRID};
    enum { TURNS = sizeof turns / sizeof turns[0] };
    int reps = ctx->opts.repeats;
    /* wall times, then the process's CPU times (all threads: on a shared machine the wall time
     * carries the other jobs' load, the CPU time less so) */
    double *ms = calloc((size_t)reps * RP_ACCEL_COUNT * 2, sizeof(double));
    double *cpu = ms ? ms + (size_t)reps * RP_ACCEL_COUNT : NULL;
    rp_scene_stats st[RP_ACCEL_COUNT];
    memset(st, 0, sizeof st);
    bool failed = ms == NULL;
    rp_accel_type keep = ctx->opts.accel;
    for (int r = 0; r < reps && !failed; r++)
        for (int t = 0; t < TURNS + (r == reps - 1) && !failed; t++) {
            rp_accel_type a = t < TURNS ? turns[t] : RP_ACCEL_KDTREE;
            ctx->opts.accel = a;
            rp_scene *s = bench_build_raypack(ctx, &ms[(size_t)a * (size_t)reps + (size_t)r], &st[a]);
            if (!s) failed = true;
            else rp_scene_release(s);
            if (s) cpu[(size_t)a * (size_t)reps + (size_t)r] = ctx->build_cpu_ms;
        }
    ctx->opts.accel = keep;
    if (failed) {
        fprintf(stderr, "raypack bench: a build failed\n");
        free(ms);
        return 1;
    }
    printf("scene     %s: %zu triangles, %d threads, %d builds each in turns (the kd-tree: 1)\n", ctx->scene_name,
           ctx->mesh.triangle_count, ctx->opts.threads, reps);
    double bvh = 0.0, bvh_cpu = 0.0;
    for (int a = 0; a < RP_ACCEL_COUNT; a++) {
        int n = a == RP_ACCEL_KDTREE ? 1 : reps;
        size_t first = (size_t)a * (size_t)reps + (a == RP_ACCEL_KDTREE ? (size_t)reps - 1 : 0);
        double *v = ms + first, *c = cpu + first;
        qsort(v, (size_t)n, sizeof *v, cmp_double);
        qsort(c, (size_t)n, sizeof *c, cmp_double);
        double med = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
        double cmed = n % 2 ? c[n / 2] : 0.5 * (c[n / 2 - 1] + c[n / 2]);
        if (a == RP_ACCEL_BVH) bvh = med, bvh_cpu = cmed;
        printf("build     %-7s median %9.2f ms, min %9.2f ms, %8.2f MiB, BVH / this %.2fx; CPU median %9.2f ms, "
               "BVH / this %.2fx\n",
               rp_accel_name((rp_accel_type)a), med, v[0], (double)st[a].bytes / 1048576.0, med > 0.0 ? bvh / med : 0.0,
               cmed, cmed > 0.0 ? bvh_cpu / cmed : 0.0);
    }
    free(ms);
    return 0;
}
