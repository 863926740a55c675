/* `raypack bench SCENE --vs embree`: raypack and Embree 3 in one process, on the same triangles and
 * the same rays, taking turns; each engine at its best per ray set (DESIGN.md, "Benchmarks against
 * Embree"). Compiled to nothing when CMake did not find Embree. */
#include "bench.h"
#include "cli.h"
#include <raypack_io.h>

#if defined(RP_HAVE_EMBREE)

#include <embree3/rtcore.h>
#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

/* Builds of each kind whose median is reported. */
#define EMB_BUILD_REPEATS 5
#define EMB_MAX_MODES 12
#define EMB_SCREEN 2    /* screening passes per mode */
#define EMB_FINALISTS 2 /* modes per engine timed `repeats` times */
/* More mismatching rays than 1 in this many fails the run. */
#define EMB_MISMATCH_DENOMINATOR 10000

/* Bytes Embree holds, from its memory monitor callback. */
static _Atomic long long emb_bytes;

/* Embree's memory monitor: counts every allocation and free, refuses none. */
static bool emb_memory_monitor(void *user, ssize_t bytes, bool post) {
    (void)user;
    (void)post;
    atomic_fetch_add(&emb_bytes, (long long)bytes);
    return true;
}

/* Embree's error callback: errors are printed, the run fails where the call's result is checked. */
static void emb_error(void *user, enum RTCError code, const char *message) {
    (void)user;
    fprintf(stderr, "embree error %d: %s\n", (int)code, message ? message : "");
}

/* An Embree scene and the context flags its packet calls get for the set being traced. */
typedef struct emb_engine {
    RTCScene scene;
    enum RTCIntersectContextFlags flags;
} emb_engine;

/* Builds Embree's scene over the same vertex and index arrays raypack got (shared, not copied, so
 * the monitor counts the acceleration structure only, as raypack's stats do). */
static RTCScene emb_build(RTCDevice device, const bench_mesh *mesh, enum RTCBuildQuality quality,
                          double *ms, long long *bytes) {
    RTCScene scene = rtcNewScene(device);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, mesh->positions,
                               0, 3 * sizeof(float), mesh->vertex_count);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, mesh->indices, 0,
                               3 * sizeof(uint32_t), mesh->triangle_count);
    rtcSetGeometryBuildQuality(geom, quality);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    rtcSetSceneBuildQuality(scene, quality);
    long long before = atomic_load(&emb_bytes);
    double t0 = bench_now_ms();
    rtcCommitScene(scene);
    *ms = bench_now_ms() - t0;
    *bytes = atomic_load(&emb_bytes) - before;
    if (rtcGetDeviceError(device) != RTC_ERROR_NONE) {
        rtcReleaseScene(scene);
        return NULL;
    }
    return scene;
}

/* The same numbers raypack gets (fill_rp_ray in bench.c). */
static inline void emb_fill_ray(struct RTCRay *r, const bench_ray *b, size_t slot) {
    r->org_x = b->org[0];
    r->org_y = b->org[1];
    r->org_z = b->org[2];
    r->tnear = b->tnear;
    r->dir_x = b->dir[0];
    r->dir_y = b->dir[1];
    r->dir_z = b->dir[2];
    r->time = 0.0f;
    r->tfar = b->tfar;
    r->mask = 0xFFFFFFFFu;
    r->id = (uint32_t)slot;
    r->flags = 0;
}

/* rtcIntersect1, one ray at a time. */
static void emb_trace_intersect1(void *engine, const bench_rays *set, size_t first, size_t n,
                                 bench_hits *out, void *scratch) {
    (void)scratch;
    const emb_engine *e = engine;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = e->flags;
    for (size_t i = first; i < first + n; i++) {
        if (!set->valid[i]) continue;
        struct RTCRayHit rh;
        emb_fill_ray(&rh.ray, &set->rays[i], i);
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
        BENCH_TRACE(rtcIntersect1(e->scene, &ctx, &rh));
        bool hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        out->t[i] = hit ? rh.ray.tfar : INFINITY;
        out->prim[i] = hit ? rh.hit.primID : RP_INVALID_ID;
    }
}

/* rtcOccluded1, one ray at a time. */
static void emb_trace_occluded1(void *engine, const bench_rays *set, size_t first, size_t n,
                                bench_hits *out, void *scratch) {
    (void)scratch;
    const emb_engine *e = engine;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = e->flags;
    for (size_t i = first; i < first + n; i++) {
        if (!set->valid[i]) continue;
        struct RTCRay r;
        emb_fill_ray(&r, &set->rays[i], i);
        BENCH_TRACE(rtcOccluded1(e->scene, &ctx, &r));
        out->t[i] = r.tfar;
        out->prim[i] = RP_INVALID_ID;
    }
}

/* Packet calls over W consecutive slots (4x4 screen tiles for W = 16), exactly as raypack's. */
#define EMB_PACKET_MODES(W)                                                                      \
    static void emb_trace_intersect##W(void *engine, const bench_rays *set, size_t first,        \
                                       size_t n, bench_hits *out, void *scratch) {               \
        (void)scratch;                                                                           \
        const emb_engine *e = engine;                                                            \
        struct RTCIntersectContext ctx;                                                          \
        rtcInitIntersectContext(&ctx);                                                           \
        ctx.flags = e->flags;                                                                    \
        for (size_t base = first; base < first + n; base += W) {                                 \
            const int32_t *valid = set->valid + base;                                            \
            if (!bench_any_valid(valid, W)) continue;                                            \
            struct RTCRayHit##W p;                                                               \
            for (int k = 0; k < W; k++) {                                                        \
                const bench_ray *b = &set->rays[base + (size_t)k];                               \
                p.ray.org_x[k] = b->org[0];                                                      \
                p.ray.org_y[k] = b->org[1];                                                      \
                p.ray.org_z[k] = b->org[2];                                                      \
                p.ray.tnear[k] = b->tnear;                                                       \
                p.ray.dir_x[k] = b->dir[0];                                                      \
                p.ray.dir_y[k] = b->dir[1];                                                      \
                p.ray.dir_z[k] = b->dir[2];                                                      \
                p.ray.time[k] = 0.0f;                                                            \
                p.ray.tfar[k] = b->tfar;                                                         \
                p.ray.mask[k] = 0xFFFFFFFFu;                                                     \
                p.ray.id[k] = (uint32_t)(base + (size_t)k);                                      \
                p.ray.flags[k] = 0;                                                              \
                p.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;                                       \
                p.hit.primID[k] = RTC_INVALID_GEOMETRY_ID;                                       \
            }                                                                                    \
            BENCH_TRACE(rtcIntersect##W(valid, e->scene, &ctx, &p));                             \
            for (int k = 0; k < W; k++) {                                                        \
                if (!valid[k]) continue;                                                         \
                bool hit = p.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;                           \
                out->t[base + (size_t)k] = hit ? p.ray.tfar[k] : INFINITY;                       \
                out->prim[base + (size_t)k] = hit ? p.hit.primID[k] : RP_INVALID_ID;             \
            }                                                                                    \
        }                                                                                        \
    }                                                                                            \
    static void emb_trace_occluded##W(void *engine, const bench_rays *set, size_t first,         \
                                      size_t n, bench_hits *out, void *scratch) {                \
        (void)scratch;                                                                           \
        const emb_engine *e = engine;                                                            \
        struct RTCIntersectContext ctx;                                                          \
        rtcInitIntersectContext(&ctx);                                                           \
        ctx.flags = e->flags;                                                                    \
        for (size_t base = first; base < first + n; base += W) {                                 \
            const int32_t *valid = set->valid + base;                                            \
            if (!bench_any_valid(valid, W)) continue;                                            \
            struct RTCRay##W p;                                                                  \
            for (int k = 0; k < W; k++) {                                                        \
                const bench_ray *b = &set->rays[base + (size_t)k];                               \
                p.org_x[k] = b->org[0];                                                          \
                p.org_y[k] = b->org[1];                                                          \
                p.org_z[k] = b->org[2];                                                          \
                p.tnear[k] = b->tnear;                                                           \
                p.dir_x[k] = b->dir[0];                                                          \
                p.dir_y[k] = b->dir[1];                                                          \
                p.dir_z[k] = b->dir[2];                                                          \
                p.time[k] = 0.0f;                                                                \
                p.tfar[k] = b->tfar;                                                             \
                p.mask[k] = 0xFFFFFFFFu;                                                         \
                p.id[k] = (uint32_t)(base + (size_t)k);                                          \
                p.flags[k] = 0;                                                                  \
            }                                                                                    \
            BENCH_TRACE(rtcOccluded##W(valid, e->scene, &ctx, &p));                              \
            for (int k = 0; k < W; k++) {                                                        \
                if (!valid[k]) continue;                                                         \
                out->t[base + (size_t)k] = p.tfar[k];                                            \
                out->prim[base + (size_t)k] = RP_INVALID_ID;                                     \
            }                                                                                    \
        }                                                                                        \
    }
EMB_PACKET_MODES(4)
EMB_PACKET_MODES(8)
EMB_PACKET_MODES(16)
#undef EMB_PACKET_MODES

/* rtcIntersect1M / rtcOccluded1M: Embree's stream API on the live rays of a chunk, the counterpart
 * of rp_intersect_array (with the coherent flag it forms packets itself). */
static void emb_trace_stream(void *engine, const bench_rays *set, size_t first, size_t n,
                             bench_hits *out, void *scratch) {
    const emb_engine *e = engine;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = e->flags;
    unsigned int m = 0;
    if (set->occlusion) {
        struct RTCRay *rays = scratch;
        for (size_t i = first; i < first + n; i++)
            if (set->valid[i]) emb_fill_ray(&rays[m++], &set->rays[i], i);
        if (m == 0) return;
        BENCH_TRACE(rtcOccluded1M(e->scene, &ctx, rays, m, sizeof(struct RTCRay)));
        for (unsigned int j = 0; j < m; j++) {
            out->t[rays[j].id] = rays[j].tfar;
            out->prim[rays[j].id] = RP_INVALID_ID;
        }
    } else {
        struct RTCRayHit *rh = scratch;
        for (size_t i = first; i < first + n; i++) {
            if (!set->valid[i]) continue;
            emb_fill_ray(&rh[m].ray, &set->rays[i], i);
            rh[m].hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rh[m].hit.primID = RTC_INVALID_GEOMETRY_ID;
            m++;
        }
        if (m == 0) return;
        BENCH_TRACE(rtcIntersect1M(e->scene, &ctx, rh, m, sizeof(struct RTCRayHit)));
        for (unsigned int j = 0; j < m; j++) {
            bool hit = rh[j].hit.geomID != RTC_INVALID_GEOMETRY_ID;
            out->t[rh[j].ray.id] = hit ? rh[j].ray.tfar : INFINITY;
            out->prim[rh[j].ray.id] = hit ? rh[j].hit.primID : RP_INVALID_ID;
        }
    }
}

/* Embree's APIs for a set, each with both context flags (DESIGN.md: Embree at its best on every
 * set; COHERENT makes its packets several times faster on reflections off flat mirrors too):
 * rtcIntersect1 first (the reference), then the packet sizes and the stream call; occlusion sets
 * get the rtcOccluded versions. engines[0] has the COHERENT flag, engines[1] INCOHERENT; a mode's
 * name is the API, '/', and the flag. */
static int emb_modes(emb_engine engines[2], bool occlusion, bench_mode *modes) {
    static const char *names[2][2][5] = {
        {{"rtcIntersect1/coherent", "rtcIntersect4/coherent", "rtcIntersect8/coherent", "rtcIntersect16/coherent",
          "rtcIntersect1M/coherent"},
         {"rtcIntersect1/incoherent", "rtcIntersect4/incoherent", "rtcIntersect8/incoherent",
          "rtcIntersect16/incoherent", "rtcIntersect1M/incoherent"}},
        {{"rtcOccluded1/coherent", "rtcOccluded4/coherent", "rtcOccluded8/coherent", "rtcOccluded16/coherent",
          "rtcOccluded1M/coherent"},
         {"rtcOccluded1/incoherent", "rtcOccluded4/incoherent", "rtcOccluded8/incoherent",
          "rtcOccluded16/incoherent", "rtcOccluded1M/incoherent"}}};
    const bench_trace_fn fns[5] = {occlusion ? emb_trace_occluded1 : emb_trace_intersect1,
                                   occlusion ? emb_trace_occluded4 : emb_trace_intersect4,
                                   occlusion ? emb_trace_occluded8 : emb_trace_intersect8,
                                   occlusion ? emb_trace_occluded16 : emb_trace_intersect16, emb_trace_stream};
    int n = 0;
    for (int api = 0; api < 5; api++)
        for (int fl = 0; fl < 2; fl++) modes[n++] = (bench_mode){names[occlusion][fl][api], fns[api], &engines[fl]};
    return n;
}

/* The API part of an Embree mode's name into buf, and its flag ("coherent" or "incoherent"). */
static const char *emb_api(const char *mode, char *buf, size_t size) {
    const char *slash = strchr(mode, '/');
    size_t len = slash ? (size_t)(slash - mode) : strlen(mode);
    if (len >= size) len = size - 1;
    memcpy(buf, mode, len);
    buf[len] = 0;
    return slash ? slash + 1 : "";
}

/* Results of one ray set. */
typedef struct emb_set_result {
    bench_mode rp_modes[EMB_MAX_MODES], emb_modes[EMB_MAX_MODES];
    int rp_count, emb_count;
    bench_stat rp_stat[EMB_MAX_MODES], emb_stat[EMB_MAX_MODES];
    bench_diff emb_diff[EMB_MAX_MODES]; /* each Embree API against raypack's single rays */
    size_t mismatches;                  /* the worst of emb_diff */
    int rp_best, emb_best;
    bool rp_final[EMB_MAX_MODES], emb_final[EMB_MAX_MODES]; /* timed `repeats` times */
    bench_stat rp_harness, emb_harness; /* the best modes with bench_harness_only */
    emb_engine engines[2]; /* COHERENT, INCOHERENT */
} emb_set_result;

/* Embree's tracing time per ray over raypack's, each mode's harness time taken out of its
 * median (0 when a harness is not faster than its mode, as timing noise can make it). */
static double tracing_ratio(const emb_set_result *r) {
    double p = r->rp_stat[r->rp_best].median, e = r->emb_stat[r->emb_best].median;
    double ph = r->rp_harness.median, eh = r->emb_harness.median;
    if (!(p > 0.0 && e > 0.0 && ph > p && eh > e)) return 0.0;
    return (1.0 / e - 1.0 / eh) / (1.0 / p - 1.0 / ph);
}

typedef struct emb_build_result {
    double rp_ms, rp_commit_ms, emb_ms, emb_hq_ms;
    long long emb_bytes, emb_hq_bytes;
    size_t rp_bytes;
} emb_build_result;

/* Median of n samples (sorted in place). */
static double median_of(double *v, int n) { return bench_stats(v, n).median; }

/* Builds each structure EMB_BUILD_REPEATS times, taking turns, and keeps the last raypack scene and
 * the last Embree scene of default quality for tracing. */
static bool emb_build_all(bench_ctx *ctx, RTCDevice device, RTCScene *emb_scene,
                          emb_build_result *out) {
    double rp_ms[EMB_BUILD_REPEATS], rp_commit[EMB_BUILD_REPEATS], emb_ms[EMB_BUILD_REPEATS],
        hq_ms[EMB_BUILD_REPEATS];
    memset(out, 0, sizeof *out);
    for (int r = 0; r < EMB_BUILD_REPEATS; r++) {
        rp_scene_stats st;
        memset(&st, 0, sizeof st);
        if (ctx->scene) rp_scene_release(ctx->scene);
        ctx->scene = bench_build_raypack(ctx, &rp_ms[r], &st);
        if (!ctx->scene) return false;
        rp_commit[r] = st.build_ms;
        out->rp_bytes = st.bytes;

        if (*emb_scene) rtcReleaseScene(*emb_scene);
        *emb_scene = emb_build(device, &ctx->mesh, RTC_BUILD_QUALITY_MEDIUM, &emb_ms[r], &out->emb_bytes);
        if (!*emb_scene) return false;

        RTCScene hq = emb_build(device, &ctx->mesh, RTC_BUILD_QUALITY_HIGH, &hq_ms[r], &out->emb_hq_bytes);
        if (!hq) return false;
        rtcReleaseScene(hq);
    }
    out->rp_ms = median_of(rp_ms, EMB_BUILD_REPEATS);
    out->rp_commit_ms = median_of(rp_commit, EMB_BUILD_REPEATS);
    out->emb_ms = median_of(emb_ms, EMB_BUILD_REPEATS);
    out->emb_hq_ms = median_of(hq_ms, EMB_BUILD_REPEATS);
    return true;
}

/* Mrays/s of a pass over a set that took s seconds. */
static double bench_mrays(const bench_rays *set, double s) { return s > 0.0 ? (double)set->count / s * 1e-6 : 0.0; }

/* Index of the mode with the highest median, among those not excluded (exclude may be NULL). */
static int best_of(const bench_stat *s, int n, const bool *exclude) {
    int best = -1;
    for (int i = 0; i < n; i++)
        if (!(exclude && exclude[i]) && (best < 0 || s[i].median > s[best].median)) best = i;
    return best;
}

/* The finalists of one engine: the EMB_FINALISTS modes of highest screening median. */
static int finalists(const bench_stat *s, int n, int out[EMB_FINALISTS], bool *final) {
    int k = 0;
    for (; k < EMB_FINALISTS && k < n; k++) {
        out[k] = best_of(s, n, final);
        final[out[k]] = true;
    }
    return k;
}

/* The three Mrays/s fields of a JSON result. */
static void write_stat(FILE *f, bench_stat s) {
    fprintf(f, "\"mrays_median\": %.4f, \"mrays_min\": %.4f, \"mrays_max\": %.4f", s.median, s.min,
            s.max);
}

/* --json: the shape of the issue (scene, threads, build, rays.{primary,...}) plus detail. */
static bool emb_write_json(const bench_ctx *ctx, const emb_build_result *b,
                           const emb_set_result *res) {
    rp_atomic_file *af;
    FILE *f = bench_json_begin(ctx, &af);
    if (!f) return false;
    fprintf(f, ", \"triangles\": %zu, \"threads\": %d, \"width\": %d, \"height\": %d, "
               "\"repeats\": %d, \"isa\": \"%s\", \"embree_version\": \"%s\",\n",
            ctx->mesh.triangle_count, ctx->opts.threads, ctx->opts.width, ctx->opts.height,
            ctx->opts.repeats, cli_isa_name(rp_device_isa(ctx->device)), RTC_VERSION_STRING);
    fprintf(f, " \"build\": {\"raypack_ms\": %.3f, \"raypack_commit_ms\": %.3f, \"embree_ms\": %.3f, "
               "\"embree_hq_ms\": %.3f, \"raypack_bytes\": %zu, \"embree_bytes\": %lld, "
               "\"embree_hq_bytes\": %lld},\n \"rays\": {",
            b->rp_ms, b->rp_commit_ms, b->emb_ms, b->emb_hq_ms, b->rp_bytes, b->emb_bytes,
            b->emb_hq_bytes);
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        const emb_set_result *r = &res[k];
        fprintf(f, "%s\n  \"%s\": {\"count\": %zu, \"mismatches\": %zu, \"ties\": %zu,\n",
                k ? "," : "", bench_kind_name((bench_kind)k), ctx->sets[k].count, r->mismatches,
                r->emb_diff[0].ties);
        fprintf(f, "   \"raypack\": {\"mode\": \"%s\", ", r->rp_modes[r->rp_best].name);
        write_stat(f, r->rp_stat[r->rp_best]);
        char api[32];
        const char *flags = emb_api(r->emb_modes[r->emb_best].name, api, sizeof api);
        fprintf(f, "},\n   \"embree\": {\"api\": \"%s\", \"flags\": \"%s\", \"mode\": \"%s\", ", api, flags,
                r->emb_modes[r->emb_best].name);
        write_stat(f, r->emb_stat[r->emb_best]);
        fprintf(f, "},\n   \"raypack_all\": {");
        for (int m = 0; m < r->rp_count; m++)
            fprintf(f, "%s\"%s\": %.4f", m ? ", " : "", r->rp_modes[m].name, r->rp_stat[m].median);
        fprintf(f, "},\n   \"embree_all\": {");
        for (int m = 0; m < r->emb_count; m++)
            fprintf(f, "%s\"%s\": %.4f", m ? ", " : "", r->emb_modes[m].name, r->emb_stat[m].median);
        /* the finalists, timed `repeats` times; the best of each engine is among them */
        fprintf(f, "},\n   \"raypack_finalists\": {");
        for (int m = 0, n = 0; m < r->rp_count; m++)
            if (r->rp_final[m]) fprintf(f, "%s\"%s\": %.4f", n++ ? ", " : "", r->rp_modes[m].name, r->rp_stat[m].median);
        fprintf(f, "},\n   \"embree_finalists\": {");
        for (int m = 0, n = 0; m < r->emb_count; m++)
            if (r->emb_final[m]) fprintf(f, "%s\"%s\": %.4f", n++ ? ", " : "", r->emb_modes[m].name, r->emb_stat[m].median);
        fprintf(f, "},\n   \"embree_mismatches\": {");
        for (int m = 0; m < r->emb_count; m++)
            fprintf(f, "%s\"%s\": %zu", m ? ", " : "", r->emb_modes[m].name, r->emb_diff[m].total);
        double ratio = r->emb_stat[r->emb_best].median > 0.0
                           ? r->rp_stat[r->rp_best].median / r->emb_stat[r->emb_best].median
                           : 0.0;
        fprintf(f, "},\n   \"harness\": {\"raypack_mrays\": %.4f, \"embree_mrays\": %.4f, "
                   "\"tracing_ratio\": %.4f},\n   \"ratio\": %.4f}",
                r->rp_harness.median, r->emb_harness.median, tracing_ratio(r), ratio);
    }
    fprintf(f, "\n }\n}\n");
    return bench_json_end(af);
}

/* The tables on the terminal: builds, every mode of both engines, then the best of each. */
static void emb_print(const bench_ctx *ctx, const emb_build_result *b, const emb_set_result *res) {
    const double mib = 1024.0 * 1024.0;
    printf("\n%-24s %10s %10s\n", "build", "ms", "MiB");
    printf("%-24s %10.2f %10.2f   (commit stats %.2f ms)\n", "raypack (default)", b->rp_ms,
           (double)b->rp_bytes / mib, b->rp_commit_ms);
    printf("%-24s %10.2f %10.2f\n", "embree (medium)", b->emb_ms, (double)b->emb_bytes / mib);
    printf("%-24s %10.2f %10.2f\n", "embree (high)", b->emb_hq_ms, (double)b->emb_hq_bytes / mib);
    printf("(median of %d builds each; traced: raypack default, embree medium)\n\n", EMB_BUILD_REPEATS);

    printf("%-11s %-8s %-25s %28s\n", "rays", "engine", "mode", "Mrays/s median (min - max)");
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        const emb_set_result *r = &res[k];
        for (int m = 0; m < r->rp_count; m++)
            printf("%-11s %-8s %-25s %10.2f (%7.2f - %7.2f)%s\n",
                   m == 0 ? bench_kind_name((bench_kind)k) : "", "raypack", r->rp_modes[m].name,
                   r->rp_stat[m].median, r->rp_stat[m].min, r->rp_stat[m].max,
                   m == r->rp_best ? "  *" : r->rp_final[m] ? "  +" : "");
        for (int m = 0; m < r->emb_count; m++)
            printf("%-11s %-8s %-25s %10.2f (%7.2f - %7.2f)%s   mismatches %zu\n", "", "embree",
                   r->emb_modes[m].name, r->emb_stat[m].median, r->emb_stat[m].min,
                   r->emb_stat[m].max, m == r->emb_best ? "  *" : r->emb_final[m] ? "  +" : "   ",
                   r->emb_diff[m].total);
    }
    printf("(* the engine's best and + its other finalist: %d timed passes, alternating with the other "
           "engine's; the rest: %d screening passes)\n",
           ctx->opts.repeats, EMB_SCREEN);

    printf("\n%-11s %9s %10s  %-16s %8s  %-25s %8s  %6s\n", "rays", "count", "mismatch",
           "raypack best", "Mrays/s", "embree best", "Mrays/s", "ratio");
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        const emb_set_result *r = &res[k];
        double e = r->emb_stat[r->emb_best].median, p = r->rp_stat[r->rp_best].median;
        printf("%-11s %9zu %10zu  %-16s %8.2f  %-25s %8.2f  %6.3f\n", bench_kind_name((bench_kind)k),
               ctx->sets[k].count, r->mismatches, r->rp_modes[r->rp_best].name, p,
               r->emb_modes[r->emb_best].name, e, e > 0.0 ? p / e : 0.0);
    }

    /* What the benchmark costs besides tracing: with the engines' calls skipped, each best mode
     * still copies its rays into the engine's layout and writes the hits back. A lower bound (the
     * rays stay in the caches that tracing would share) of what its Mrays/s pays for the copies,
     * and so a ceiling on the ratio: raypack's harness alone over Embree's median. */
    printf("\nharness alone (the same modes, the engines' calls skipped; median of %d passes):\n",
           ctx->opts.repeats);
    printf("%-11s %16s %15s %14s %15s\n", "rays", "raypack Mrays/s", "embree Mrays/s", "ratio ceiling",
           "tracing ratio");
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        const emb_set_result *r = &res[k];
        double e = r->emb_stat[r->emb_best].median;
        printf("%-11s %16.2f %15.2f %14.2f %15.3f\n", bench_kind_name((bench_kind)k), r->rp_harness.median,
               r->emb_harness.median, e > 0.0 ? r->rp_harness.median / e : 0.0, tracing_ratio(r));
    }
    printf("(tracing ratio: Embree's time per ray over raypack's, each harness's time taken out)\n");
}

int bench_vs_embree(bench_ctx *ctx) {
    char config[64];
    snprintf(config, sizeof config, "threads=%d", ctx->opts.threads);
    RTCDevice device = rtcNewDevice(config);
    if (!device) {
        fprintf(stderr, "raypack bench: rtcNewDevice failed (error %d)\n", (int)rtcGetDeviceError(NULL));
        return 1;
    }
    rtcSetDeviceErrorFunction(device, emb_error, NULL);
    rtcSetDeviceMemoryMonitorFunction(device, emb_memory_monitor, NULL);

    int rc = 1;
    RTCScene emb_scene = NULL;
    emb_build_result build;
    bench_hits hits = {NULL, NULL};
    emb_set_result *res = calloc(BENCH_KIND_COUNT, sizeof *res);
    double *samples = calloc((size_t)ctx->opts.repeats * 2 * EMB_FINALISTS, sizeof(double));
    if (!res || !samples) goto done;
    if (!emb_build_all(ctx, device, &emb_scene, &build)) goto done;
    if (!bench_make_ray_sets(ctx) || !bench_hits_alloc(&hits, ctx->sets[0].slots)) goto done;
    bench_print_header(ctx);
    printf("embree    %s, device \"%s\"\n", RTC_VERSION_STRING, config);

    /* Both engines' hits on every ray, before anything is timed. */
    bool failed = false;
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        const bench_rays *set = &ctx->sets[k];
        emb_set_result *r = &res[k];
        r->engines[0] = (emb_engine){emb_scene, RTC_INTERSECT_CONTEXT_FLAG_COHERENT};
        r->engines[1] = (emb_engine){emb_scene, RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT};
        r->rp_count = bench_raypack_modes(ctx, set, r->rp_modes, EMB_MAX_MODES);
        r->emb_count = emb_modes(r->engines, set->occlusion, r->emb_modes);
        for (int m = 1; m < r->rp_count; m++) {
            bench_trace_set(ctx, ctx->opts.threads, &r->rp_modes[m], set, &hits);
            bench_diff d = bench_compare(&ctx->mesh, set, &ctx->ref[k], &hits);
            if (d.total) {
                fprintf(stderr, "raypack bench: %s rays: raypack %s disagrees with raypack single "
                                "on %zu rays (hit/miss %zu, distance %zu, primitive %zu)\n",
                        bench_kind_name((bench_kind)k), r->rp_modes[m].name, d.total, d.hit_miss,
                        d.distance, d.primitive);
                bench_print_mismatches(&ctx->mesh, set, &ctx->ref[k], &hits, "single",
                                       r->rp_modes[m].name, 3);
                failed = true;
            }
        }
        for (int m = 0; m < r->emb_count; m++) {
            bench_trace_set(ctx, ctx->opts.threads, &r->emb_modes[m], set, &hits);
            r->emb_diff[m] = bench_compare(&ctx->mesh, set, &ctx->ref[k], &hits);
            if (m == 0 && r->emb_diff[m].total)
                bench_print_mismatches(&ctx->mesh, set, &ctx->ref[k], &hits, "raypack",
                                       r->emb_modes[m].name, 3);
            if (r->emb_diff[m].total > r->mismatches) r->mismatches = r->emb_diff[m].total;
        }
        const bench_diff *d = &r->emb_diff[0];
        printf("check     %-10s %9zu rays: raypack vs embree %zu mismatches (hit/miss %zu, "
               "distance %zu, primitive %zu; worst embree API %zu), %zu ties\n",
               bench_kind_name((bench_kind)k), set->count, d->total, d->hit_miss, d->distance,
               d->primitive, r->mismatches, d->ties);
        if (r->mismatches * EMB_MISMATCH_DENOMINATOR > set->count) {
            fprintf(stderr, "raypack bench: %s rays: %zu of %zu mismatch, more than 1 in %d\n",
                    bench_kind_name((bench_kind)k), r->mismatches, set->count,
                    EMB_MISMATCH_DENOMINATOR);
            failed = true;
        }
    }
    if (failed) goto done;

    /* Timing. Every raypack mode and every Embree API gets the warm-up and EMB_SCREEN screening
     * passes, the engines taking turns (the per-mode figures of the others); then the
     * EMB_FINALISTS fastest of each engine are timed `repeats` times, all four alternating, and
     * the finalist of higher median is the engine's best. One screening pass picked whichever
     * mode had the luckiest pass (teapot shadows: rtcOccluded1M, timed at 65.7 Mrays/s, over
     * rtcOccluded16, screened at 84.4). Timing every mode `repeats` times made a 1024x1024 run
     * take a quarter of an hour. */
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        const bench_rays *set = &ctx->sets[k];
        emb_set_result *r = &res[k];
        int turns = r->rp_count > r->emb_count ? r->rp_count : r->emb_count;
        for (int w = 0; w < ctx->opts.warmup; w++)
            for (int m = 0; m < turns; m++) {
                if (m < r->rp_count) bench_trace_set(ctx, ctx->opts.threads, &r->rp_modes[m], set, &hits);
                if (m < r->emb_count) bench_trace_set(ctx, ctx->opts.threads, &r->emb_modes[m], set, &hits);
            }
        double screen[2][EMB_MAX_MODES][EMB_SCREEN];
        for (int p = 0; p < EMB_SCREEN; p++)
            for (int m = 0; m < turns; m++) {
                if (m < r->rp_count)
                    screen[0][m][p] = bench_mrays(set, bench_trace_set(ctx, ctx->opts.threads, &r->rp_modes[m], set, &hits));
                if (m < r->emb_count)
                    screen[1][m][p] = bench_mrays(set, bench_trace_set(ctx, ctx->opts.threads, &r->emb_modes[m], set, &hits));
            }
        for (int m = 0; m < r->rp_count; m++) r->rp_stat[m] = bench_stats(screen[0][m], EMB_SCREEN);
        for (int m = 0; m < r->emb_count; m++) r->emb_stat[m] = bench_stats(screen[1][m], EMB_SCREEN);
        int rf[EMB_FINALISTS], ef[EMB_FINALISTS];
        int nrf = finalists(r->rp_stat, r->rp_count, rf, r->rp_final);
        int nef = finalists(r->emb_stat, r->emb_count, ef, r->emb_final);
        size_t reps = (size_t)ctx->opts.repeats;
        for (size_t rep = 0; rep < reps; rep++)
            for (int f = 0; f < EMB_FINALISTS; f++) {
                if (f < nrf)
                    samples[(size_t)f * reps + rep] =
                        bench_mrays(set, bench_trace_set(ctx, ctx->opts.threads, &r->rp_modes[rf[f]], set, &hits));
                if (f < nef)
                    samples[(size_t)(EMB_FINALISTS + f) * reps + rep] =
                        bench_mrays(set, bench_trace_set(ctx, ctx->opts.threads, &r->emb_modes[ef[f]], set, &hits));
            }
        for (int f = 0; f < nrf; f++) r->rp_stat[rf[f]] = bench_stats(samples + (size_t)f * reps, ctx->opts.repeats);
        for (int f = 0; f < nef; f++)
            r->emb_stat[ef[f]] = bench_stats(samples + (size_t)(EMB_FINALISTS + f) * reps, ctx->opts.repeats);
        bool rp_out[EMB_MAX_MODES], emb_out[EMB_MAX_MODES];
        for (int m = 0; m < EMB_MAX_MODES; m++) rp_out[m] = !r->rp_final[m], emb_out[m] = !r->emb_final[m];
        r->rp_best = best_of(r->rp_stat, r->rp_count, rp_out);
        r->emb_best = best_of(r->emb_stat, r->emb_count, emb_out);
        /* the best modes' harness alone, taking turns (samples: the finalists' buffer, reused) */
        bench_harness_only = true;
        for (size_t rep = 0; rep < reps; rep++) {
            samples[rep] = bench_mrays(set, bench_trace_set(ctx, ctx->opts.threads, &r->rp_modes[r->rp_best], set, &hits));
            samples[reps + rep] =
                bench_mrays(set, bench_trace_set(ctx, ctx->opts.threads, &r->emb_modes[r->emb_best], set, &hits));
        }
        bench_harness_only = false;
        r->rp_harness = bench_stats(samples, ctx->opts.repeats);
        r->emb_harness = bench_stats(samples + reps, ctx->opts.repeats);
    }
    emb_print(ctx, &build, res);
    rc = 0;
    if (ctx->opts.json_path && !emb_write_json(ctx, &build, res)) rc = 1;

done:
    bench_hits_free(&hits);
    free(samples);
    free(res);
    if (emb_scene) rtcReleaseScene(emb_scene);
    rtcReleaseDevice(device);
    return rc;
}

#else
/* ISO C wants a translation unit to declare something. */
typedef int bench_embree_unused;
#endif /* RP_HAVE_EMBREE */
