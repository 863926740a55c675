/* `raypack bench [SCENE]`: Mrays/s of raypack's query modes on primary, shadow, reflection and
 * diffuse rays, checked against single-ray hits before timing. `--vs embree` runs raypack against
 * Embree (bench_embree.c). */
#include "bench.h"
#include "cli.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#if defined(__x86_64__) || defined(__i386__) || defined(__SSE__)
#include <pmmintrin.h>
#include <xmmintrin.h>
#define BENCH_HAVE_MXCSR 1
#endif

#include <raypack_io.h>

/* rp_intersect_array / rtcIntersect1M copy a chunk into an array of this many bytes per ray. */
#define BENCH_SCRATCH_RAY_BYTES 128

/* ---- small helpers -------------------------------------------------------------------------- */

const char *bench_kind_name(bench_kind kind) {
    switch (kind) {
    case BENCH_PRIMARY: return "primary";
    case BENCH_SHADOW: return "shadow";
    case BENCH_REFLECTION: return "reflection";
    case BENCH_DIFFUSE: return "diffuse";
    case BENCH_BOUNCE1: return "bounce1";
    case BENCH_BOUNCE2: return "bounce2";
    case BENCH_KIND_COUNT: break;
    }
    return "?";
}

double bench_now_ms(void) { return cli_now_ms(); }

void bench_set_ftz(void) {
#if defined(BENCH_HAVE_MXCSR)
    _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
    _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
#endif
}

void bench_json_string(FILE *f, const char *s) {
    fputc('"', f);
    for (; *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\')
            fprintf(f, "\\%c", c);
        else if (c < 0x20)
            fprintf(f, "\\u%04x", c);
        else
            fputc(c, f);
    }
    fputc('"', f);
}

/* 64-byte aligned zeroed allocation (packets and hit arrays), NULL when out of memory. */
static void *alloc_aligned(size_t bytes) {
    size_t rounded = (bytes + 63) / 64 * 64;
    void *p = aligned_alloc(64, rounded ? rounded : 64);
    if (p) memset(p, 0, rounded ? rounded : 64);
    return p;
}

bool bench_hits_alloc(bench_hits *hits, size_t slots) {
    hits->t = alloc_aligned(slots * sizeof(float));
    hits->prim = alloc_aligned(slots * sizeof(uint32_t));
    if (!hits->t || !hits->prim) {
        bench_hits_free(hits);
        return false;
    }
    return true;
}

void bench_hits_free(bench_hits *hits) {
    free(hits->t);
    free(hits->prim);
    hits->t = NULL;
    hits->prim = NULL;
}

/* qsort order of doubles. */
static int compare_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

bench_stat bench_stats(double *samples, int n) {
    bench_stat s = {0, 0, 0};
    if (n <= 0) return s;
    qsort(samples, (size_t)n, sizeof *samples, compare_double);
    s.min = samples[0];
    s.max = samples[n - 1];
    s.median = n % 2 ? samples[n / 2] : 0.5 * (samples[n / 2 - 1] + samples[n / 2]);
    return s;
}

/* Relative tolerance on hit distances between modes and engines. */
#define BENCH_T_TOLERANCE 1e-4f
/* Floor of the tolerance in float ulps of the hit point's magnitude, divided by the cosine of the
 * incidence angle: a hit point is only known to that precision, and a plane met at a grazing angle
 * spreads it along the ray (a reflection ray leaving a corner of the Cornell box hits the next wall
 * at t = 0.03, 552 units from the origin; diffuse rays in the conference room graze lamp panels). */
#define BENCH_T_ULPS 16.0
#define BENCH_MIN_COSINE 1e-2

/* Cosine between the ray and triangle prim's normal (1 when the triangle is degenerate). */
static double hit_cosine(const bench_mesh *mesh, const bench_ray *r, uint32_t prim) {
    if (prim >= mesh->triangle_count) return 1.0;
    const uint32_t *tri = mesh->indices + 3 * (size_t)prim;
    const float *v0 = mesh->positions + 3 * (size_t)tri[0];
    const float *v1 = mesh->positions + 3 * (size_t)tri[1];
    const float *v2 = mesh->positions + 3 * (size_t)tri[2];
    double e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)v1[k] - v0[k];
        e2[k] = (double)v2[k] - v0[k];
    }
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]};
    double nn = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    double dd = sqrt((double)r->dir[0] * r->dir[0] + (double)r->dir[1] * r->dir[1] +
                     (double)r->dir[2] * r->dir[2]);
    if (!(nn > 0.0) || !(dd > 0.0)) return 1.0;
    return fabs(n[0] * r->dir[0] + n[1] * r->dir[1] + n[2] * r->dir[2]) / (nn * dd);
}

/* True when two hit distances of the same ray agree: within 1e-4 relative, or within the precision
 * of the hit point (cosine: of the incidence angle on the hit triangle). */
static bool same_distance(const bench_ray *r, double ta, double tb, double cosine) {
    double t = fmax(fabs(ta), fabs(tb));
    double org = fmax(fabs((double)r->org[0]), fmax(fabs((double)r->org[1]), fabs((double)r->org[2])));
    double floor_tol = BENCH_T_ULPS * (double)FLT_EPSILON * (org + t) / fmax(cosine, BENCH_MIN_COSINE);
    return fabs(ta - tb) <= fmax((double)BENCH_T_TOLERANCE * t, floor_tol);
}

/* Distance along the ray to triangle prim's plane in double precision (NAN when parallel or prim is
 * out of range), with the barycentrics of that point. */
static double triangle_t_double(const bench_mesh *mesh, const bench_ray *r, uint32_t prim, double *u,
                                double *v) {
    if (prim >= mesh->triangle_count) return NAN;
    const uint32_t *tri = mesh->indices + 3 * (size_t)prim;
    const float *v0 = mesh->positions + 3 * (size_t)tri[0];
    const float *v1 = mesh->positions + 3 * (size_t)tri[1];
    const float *v2 = mesh->positions + 3 * (size_t)tri[2];
    double e1[3], e2[3], o[3], d[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)v1[k] - v0[k];
        e2[k] = (double)v2[k] - v0[k];
        o[k] = (double)r->org[k] - v0[k];
        d[k] = r->dir[k];
    }
    double p[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]};
    double det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
    if (det == 0.0) return NAN;
    double q[3] = {o[1] * e1[2] - o[2] * e1[1], o[2] * e1[0] - o[0] * e1[2], o[0] * e1[1] - o[1] * e1[0]};
    *u = (o[0] * p[0] + o[1] * p[1] + o[2] * p[2]) / det;
    *v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) / det;
    return (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) / det;
}

/* True when the ray meets triangle prim at distance t (double precision, edges included): the
 * triangle the other side reported lies at the same distance, so both answers are closest hits. */
static bool hits_triangle_at(const bench_mesh *mesh, const bench_ray *r, uint32_t prim, float t) {
    double u, v, tt = triangle_t_double(mesh, r, prim, &u, &v);
    const double edge = 1e-6;
    if (!(tt == tt) || u < -edge || v < -edge || u + v > 1.0 + edge) return false;
    return same_distance(r, tt, (double)t, hit_cosine(mesh, r, prim));
}

bench_diff bench_compare(const bench_mesh *mesh, const bench_rays *set, const bench_hits *ref,
                         const bench_hits *hits) {
    bench_diff d = {0, 0, 0, 0, 0};
    for (size_t i = 0; i < set->slots; i++) {
        if (!set->valid[i]) continue;
        if (set->occlusion) {
            bool a = ref->t[i] == -INFINITY, b = hits->t[i] == -INFINITY;
            if (a != b) d.hit_miss++;
            continue;
        }
        bool a = ref->prim[i] != RP_INVALID_ID, b = hits->prim[i] != RP_INVALID_ID;
        if (a != b) {
            d.hit_miss++;
        } else if (a) {
            float ta = ref->t[i], tb = hits->t[i];
            const bench_ray *r = &set->rays[i];
            if (!same_distance(r, (double)ta, (double)tb, hit_cosine(mesh, r, ref->prim[i])))
                d.distance++;
            else if (ref->prim[i] != hits->prim[i]) {
                if (hits_triangle_at(mesh, r, hits->prim[i], ta) &&
                    hits_triangle_at(mesh, r, ref->prim[i], tb))
                    d.ties++;
                else
                    d.primitive++;
            }
        }
    }
    d.total = d.hit_miss + d.distance + d.primitive;
    return d;
}

void bench_print_mismatches(const bench_mesh *mesh, const bench_rays *set, const bench_hits *ref,
                            const bench_hits *hits, const char *ref_name, const char *name, int max) {
    int shown = 0;
    for (size_t i = 0; i < set->slots && shown < max; i++) {
        if (!set->valid[i]) continue;
        bench_hits one_ref = {ref->t + i, ref->prim + i}, one = {hits->t + i, hits->prim + i};
        bench_rays one_set = *set;
        one_set.slots = 1;
        one_set.rays = set->rays + i;
        one_set.valid = set->valid + i;
        if (bench_compare(mesh, &one_set, &one_ref, &one).total == 0) continue;
        const bench_ray *r = &set->rays[i];
        double u, v, exact = triangle_t_double(mesh, r, ref->prim[i], &u, &v);
        fprintf(stderr,
                "  %s ray %zu: org %.9g,%.9g,%.9g dir %.9g,%.9g,%.9g [%g, %g]: %s t=%.9g prim %d, "
                "%s t=%.9g prim %d (double precision: t=%.9g, cosine %.3g)\n",
                bench_kind_name(set->kind), i, (double)r->org[0], (double)r->org[1],
                (double)r->org[2], (double)r->dir[0], (double)r->dir[1], (double)r->dir[2],
                (double)r->tnear, (double)r->tfar, ref_name, (double)ref->t[i], (int)ref->prim[i],
                name, (double)hits->t[i], (int)hits->prim[i], exact,
                hit_cosine(mesh, r, ref->prim[i]));
        shown++;
    }
}

/* ---- the timing loop ------------------------------------------------------------------------ */

typedef struct trace_job {
    const bench_mode *mode;
    const bench_rays *set;
    bench_hits *out;
    bench_scratch *scratch;
} trace_job;

/* One chunk (a 32x32 pixel block) on a device thread; FTZ/DAZ are set on every thread that traces,
 * for both engines alike. */
static void trace_task(void *user, uint32_t index, uint32_t thread) {
    trace_job *job = user;
    bench_set_ftz();
    size_t first = (size_t)index * BENCH_CHUNK;
    job->mode->trace(job->mode->engine, job->set, first, BENCH_CHUNK, job->out,
                     job->scratch->per_thread[thread]);
}

static uint64_t bench_traces; /* bench_trace_set calls so far */

double bench_trace_set(bench_ctx *ctx, int threads, const bench_mode *mode, const bench_rays *set,
                       bench_hits *out) {
    trace_job job = {mode, set, out, &ctx->scratch};
    uint32_t chunks = (uint32_t)(set->slots / BENCH_CHUNK);
    bench_traces++; /* before the workers start: they read it */
    double t0 = bench_now_ms();
    if (threads <= 1) {
        bench_set_ftz();
        for (uint32_t c = 0; c < chunks; c++)
            mode->trace(mode->engine, set, (size_t)c * BENCH_CHUNK, BENCH_CHUNK, out,
                        ctx->scratch.per_thread[0]);
    } else {
        rp_device_parallel_for(ctx->device, chunks, trace_task, &job);
    }
    return (bench_now_ms() - t0) * 1e-3;
}

/* ---- raypack's query modes ------------------------------------------------------------------ */

static inline void fill_rp_ray(rp_ray *r, const bench_ray *b, size_t slot) {
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

/* rp_intersect1, one ray at a time. */
static void rp_trace_intersect1(void *engine, const bench_rays *set, size_t first, size_t n,
                                bench_hits *out, void *scratch) {
    (void)scratch;
    rp_scene *scene = engine;
    for (size_t i = first; i < first + n; i++) {
        if (!set->valid[i]) continue;
        rp_rayhit rh;
        fill_rp_ray(&rh.ray, &set->rays[i], i);
        rh.hit.geom_id = RP_INVALID_ID;
        rh.hit.prim_id = RP_INVALID_ID;
        BENCH_TRACE(rp_intersect1(scene, &rh));
        bool hit = rh.hit.geom_id != RP_INVALID_ID;
        out->t[i] = hit ? rh.ray.tfar : INFINITY;
        out->prim[i] = hit ? rh.hit.prim_id : RP_INVALID_ID;
    }
}

/* rp_occluded1, one ray at a time. */
static void rp_trace_occluded1(void *engine, const bench_rays *set, size_t first, size_t n,
                               bench_hits *out, void *scratch) {
    (void)scratch;
    rp_scene *scene = engine;
    for (size_t i = first; i < first + n; i++) {
        if (!set->valid[i]) continue;
        rp_ray r;
        fill_rp_ray(&r, &set->rays[i], i);
        BENCH_TRACE(rp_occluded1(scene, &r));
        out->t[i] = r.tfar;
        out->prim[i] = RP_INVALID_ID;
    }
}

/* Packet modes: W consecutive slots (a 2x2 quad, a 4x2 half or all of a 4x4 tile) per call. */
#define BENCH_RP_PACKET_MODES(W)                                                                 \
    static void rp_trace_intersect##W(void *engine, const bench_rays *set, size_t first,         \
                                      size_t n, bench_hits *out, void *scratch) {                \
        (void)scratch;                                                                           \
        rp_scene *scene = engine;                                                                \
        for (size_t base = first; base < first + n; base += W) {                                 \
            const int32_t *valid = set->valid + base;                                            \
            if (!bench_any_valid(valid, W)) continue;                                            \
            rp_rayhit##W p;                                                                      \
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
                p.hit.geom_id[k] = RP_INVALID_ID;                                                \
                p.hit.prim_id[k] = RP_INVALID_ID;                                                \
            }                                                                                    \
            BENCH_TRACE(rp_intersect##W(scene, valid, &p));                                      \
            for (int k = 0; k < W; k++) {                                                        \
                if (!valid[k]) continue;                                                         \
                bool hit = p.hit.geom_id[k] != RP_INVALID_ID;                                    \
                out->t[base + (size_t)k] = hit ? p.ray.tfar[k] : INFINITY;                       \
                out->prim[base + (size_t)k] = hit ? p.hit.prim_id[k] : RP_INVALID_ID;            \
            }                                                                                    \
        }                                                                                        \
    }                                                                                            \
    static void rp_trace_occluded##W(void *engine, const bench_rays *set, size_t first,          \
                                     size_t n, bench_hits *out, void *scratch) {                 \
        (void)scratch;                                                                           \
        rp_scene *scene = engine;                                                                \
        for (size_t base = first; base < first + n; base += W) {                                 \
            const int32_t *valid = set->valid + base;                                            \
            if (!bench_any_valid(valid, W)) continue;                                            \
            rp_ray##W p;                                                                         \
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
            BENCH_TRACE(rp_occluded##W(scene, valid, &p));                                       \
            for (int k = 0; k < W; k++) {                                                        \
                if (!valid[k]) continue;                                                         \
                out->t[base + (size_t)k] = p.tfar[k];                                            \
                out->prim[base + (size_t)k] = RP_INVALID_ID;                                     \
            }                                                                                    \
        }                                                                                        \
    }
BENCH_RP_PACKET_MODES(4)
BENCH_RP_PACKET_MODES(8)
BENCH_RP_PACKET_MODES(16)
#undef BENCH_RP_PACKET_MODES

/* rp_intersect_array / rp_occluded_array on the live rays of a chunk, with the given hint. */
static void rp_trace_array(rp_scene *scene, const bench_rays *set, size_t first, size_t n,
                           bench_hits *out, void *scratch, uint32_t flags) {
    size_t m = 0;
    if (set->occlusion) {
        rp_ray *rays = scratch;
        for (size_t i = first; i < first + n; i++)
            if (set->valid[i]) fill_rp_ray(&rays[m++], &set->rays[i], i);
        if (m == 0) return;
        BENCH_TRACE(rp_occluded_array(scene, rays, m, flags));
        for (size_t j = 0; j < m; j++) {
            out->t[rays[j].id] = rays[j].tfar;
            out->prim[rays[j].id] = RP_INVALID_ID;
        }
    } else {
        rp_rayhit *rh = scratch;
        for (size_t i = first; i < first + n; i++) {
            if (!set->valid[i]) continue;
            fill_rp_ray(&rh[m].ray, &set->rays[i], i);
            rh[m].hit.geom_id = RP_INVALID_ID;
            rh[m].hit.prim_id = RP_INVALID_ID;
            m++;
        }
        if (m == 0) return;
        BENCH_TRACE(rp_intersect_array(scene, rh, m, flags));
        for (size_t j = 0; j < m; j++) {
            bool hit = rh[j].hit.geom_id != RP_INVALID_ID;
            out->t[rh[j].ray.id] = hit ? rh[j].ray.tfar : INFINITY;
            out->prim[rh[j].ray.id] = hit ? rh[j].hit.prim_id : RP_INVALID_ID;
        }
    }
}

/* rp_intersect_array with RP_QUERY_COHERENT. */
static void rp_trace_array_coherent(void *engine, const bench_rays *set, size_t first, size_t n,
                                    bench_hits *out, void *scratch) {
    rp_trace_array(engine, set, first, n, out, scratch, RP_QUERY_COHERENT);
}

/* rp_intersect_array with RP_QUERY_INCOHERENT. */
static void rp_trace_array_incoherent(void *engine, const bench_rays *set, size_t first, size_t n,
                                      bench_hits *out, void *scratch) {
    rp_trace_array(engine, set, first, n, out, scratch, RP_QUERY_INCOHERENT);
}

/* ---- large packets (Overbeck et al. 2008) -------------------------------------------------- */

/* Packet arrays in a thread's scratch buffer: 17 ray and hit arrays of a 32x32 packet plus its
 * valid mask, then the counters, then auto's tally, all inside the BENCH_CHUNK *
 * BENCH_SCRATCH_RAY_BYTES bytes. */
#define BENCH_N_ARRAYS 18
#define BENCH_COUNTERS_OFFSET ((size_t)BENCH_N_ARRAYS * RP_PACKET_N_MAX * RP_PACKET_N_MAX * 4)
#define BENCH_TALLY_OFFSET ((BENCH_COUNTERS_OFFSET + sizeof(rp_counters_n) + 63) / 64 * 64)

/* Auto's tally (rp_auto_tally) of a thread, for the engine and the trace of a set it was made
 * in: each bench_trace_set starts afresh, as each frame of the renderer does. */
typedef struct bench_tally {
    const void *engine;
    uint64_t trace;
    rp_auto_tally tally;
} bench_tally;

_Static_assert(BENCH_COUNTERS_OFFSET % 64 == 0 &&
                   BENCH_TALLY_OFFSET + sizeof(bench_tally) <= (size_t)BENCH_CHUNK * BENCH_SCRATCH_RAY_BYTES,
               "a 32x32 packet, the counters and the tally fit in a thread's scratch");

bool bench_harness_only;

/* The tally for engine e in a thread's scratch, zeroed when it was another engine's or another
 * trace's. */
static rp_auto_tally *bench_scratch_tally(void *scratch, const void *e) {
    bench_tally *t = (bench_tally *)(void *)((char *)scratch + BENCH_TALLY_OFFSET);
    if (t->engine != e || t->trace != bench_traces) {
        memset(t, 0, sizeof *t);
        t->engine = e;
        t->trace = bench_traces;
    }
    return &t->tally;
}

rp_counters_n *bench_scratch_counters(void *scratch) {
    return (rp_counters_n *)(void *)((char *)scratch + BENCH_COUNTERS_OFFSET);
}

void bench_n_engine_init(bench_n_engine *e, rp_scene *scene, uint32_t n, rp_traversal traversal,
                         rp_frustum_kind frustum, const float *point) {
    memset(e, 0, sizeof *e);
    e->scene = scene;
    e->n = n;
    e->desc.traversal = traversal;
    e->desc.frustum = frustum;
    if (point) memcpy(e->desc.point, point, sizeof e->desc.point);
    /* Packet p is the square of n x n pixels at the block's slots [p*n*n, (p+1)*n*n). */
    uint32_t per_side = BENCH_BLOCK / n, per = n * n;
    for (uint32_t p = 0; p < per_side * per_side; p++)
        for (uint32_t y = 0; y < n; y++)
            for (uint32_t x = 0; x < n; x++) {
                uint32_t x0, y0;
                bench_block_pixel(p * per, &x0, &y0);
                uint32_t slot = bench_block_slot(x0 + x, y0 + y), q = rp_packet_n_index(n, x, y);
                /* the library's layout puts each 4x4 tile in a run of 16 in Morton order, as
                 * bench_block_slot does; anything else is a bug here or there */
                if (q % 16 != slot % 16 || slot / per != p) {
                    fprintf(stderr, "raypack bench: entry %u of a %ux%u packet is not in tile order\n", q, n, n);
                    abort();
                }
                e->tile_at[slot / 16] = (uint16_t)(q / 16);
            }
}

/* Points the arrays of an n x n packet into a thread's scratch; returns its valid mask. */
static int32_t *packet_in_scratch(void *scratch, uint32_t n, rp_rayhit_n *p) {
    char *mem = scratch;
    size_t each = (size_t)n * n * 4;
    float **f[13] = {&p->org_x, &p->org_y, &p->org_z, &p->tnear, &p->dir_x, &p->dir_y, &p->dir_z,
                     &p->tfar, &p->Ng_x, &p->Ng_y, &p->Ng_z, &p->u, &p->v};
    memset(p, 0, sizeof *p);
    p->n = n;
    for (int i = 0; i < 13; i++) *f[i] = (float *)(void *)(mem + (size_t)i * each);
    p->prim_id = (uint32_t *)(void *)(mem + 13 * each);
    p->geom_id = (uint32_t *)(void *)(mem + 14 * each);
    p->inst_id = (uint32_t *)(void *)(mem + 15 * each);
    int32_t *valid = (int32_t *)(void *)(mem + 16 * each);
    p->valid = valid;
    return valid;
}

/* One chunk in n x n packets built from the set's rays (the same numbers as every other mode),
 * copied a 4x4 tile at a time, in the order of the slots: the hardware prefetchers follow ascending
 * addresses only (the packet's tiles are in row order, the slots in Morton order; copying in the
 * packet's order took twice as long). Packets without a live ray are skipped, as by the other
 * packet modes. */
static void trace_n(const bench_n_engine *e, const bench_rays *set, size_t first, size_t count,
                    bench_hits *out, void *scratch, bool occlusion) {
    rp_rayhit_n p;
    int32_t *valid = packet_in_scratch(scratch, e->n, &p);
    rp_query_n_desc desc = e->desc;
    desc.counters = e->count ? bench_scratch_counters(scratch) : NULL;
    desc.tally = bench_scratch_tally(scratch, e);
    size_t per = (size_t)e->n * e->n, tiles = per / 16;
    for (size_t base = 0; base + per <= count; base += per) {
        const uint16_t *tile_at = e->tile_at + base / 16;
        size_t s0 = first + base;
        int32_t any = 0;
        for (size_t k = 0; k < tiles; k++) {
            const int32_t *sv = set->valid + s0 + k * 16;
            int32_t *v = valid + tile_at[k] * 16u;
            for (int j = 0; j < 16; j++) any |= v[j] = sv[j];
        }
        /* a packet without a live ray is not gathered (Embree's stream mode gets only the live
         * rays); occlusion reads no hit fields */
        if (!any) continue;
        bool next = base + 2 * per <= count;
        for (size_t k = 0; k < tiles; k++) {
            if (next) {
                bench_prefetch_rays(set, s0 + per + k * 16, 16);
                __builtin_prefetch(set->valid + s0 + per + k * 16);
            }
            size_t q = tile_at[k] * 16u;
            bench_rays_to_soa(set->rays + s0 + k * 16, 16, p.org_x + q, p.org_y + q, p.org_z + q,
                              p.tnear + q, p.dir_x + q, p.dir_y + q, p.dir_z + q, p.tfar + q);
        }
        if (occlusion) {
            BENCH_TRACE(rp_occluded_n(e->scene, &desc, &p));
        } else {
            for (size_t q = 0; q < per; q++) p.geom_id[q] = p.prim_id[q] = RP_INVALID_ID;
            BENCH_TRACE(rp_intersect_n(e->scene, &desc, &p));
        }
        /* (the arrays in locals: GCC had reloaded each pointer for every ray) */
        const float *tfar = p.tfar;
        const uint32_t *geom = p.geom_id, *prim = p.prim_id;
        float *ot = out->t;
        uint32_t *op = out->prim;
        for (size_t k = 0; k < tiles; k++) {
            size_t q = tile_at[k] * 16u, s = s0 + k * 16;
            for (int j = 0; j < 16; j++) {
                if (!valid[q + j]) continue;
                bool hit = !occlusion && geom[q + j] != RP_INVALID_ID;
                ot[s + j] = occlusion || hit ? tfar[q + j] : INFINITY;
                op[s + j] = hit ? prim[q + j] : RP_INVALID_ID;
            }
        }
    }
}

void bench_trace_n_intersect(void *engine, const bench_rays *set, size_t first, size_t n,
                             bench_hits *out, void *scratch) {
    trace_n(engine, set, first, n, out, scratch, false);
}

void bench_trace_n_occluded(void *engine, const bench_rays *set, size_t first, size_t n,
                            bench_hits *out, void *scratch) {
    trace_n(engine, set, first, n, out, scratch, true);
}

/* The frustum that bounds a set's packets: primary rays share the eye, shadow rays the light. */
static rp_frustum_kind set_frustum(bench_kind kind) {
    switch (kind) {
    case BENCH_PRIMARY: return RP_FRUSTUM_PRIMARY;
    case BENCH_SHADOW: return RP_FRUSTUM_SHADOW;
    case BENCH_REFLECTION:
    case BENCH_DIFFUSE:
    case BENCH_BOUNCE1:
    case BENCH_BOUNCE2:
    case BENCH_KIND_COUNT: break;
    }
    return RP_FRUSTUM_SECONDARY;
}

int bench_raypack_modes(bench_ctx *ctx, const bench_rays *set, bench_mode *modes, int max) {
    rp_scene *scene = ctx->scene;
    bool occlusion = set->occlusion;
    bench_n_engine *ne = ctx->n_engines[set->kind];
    bench_trace_fn n_fn = occlusion ? bench_trace_n_occluded : bench_trace_n_intersect;
    const bench_mode all[] = {
        {"single", occlusion ? rp_trace_occluded1 : rp_trace_intersect1, scene},
        {"packet4", occlusion ? rp_trace_occluded4 : rp_trace_intersect4, scene},
        {"packet8", occlusion ? rp_trace_occluded8 : rp_trace_intersect8, scene},
        {"packet16", occlusion ? rp_trace_occluded16 : rp_trace_intersect16, scene},
        {"array_coherent", rp_trace_array_coherent, scene},
        {"array_incoherent", rp_trace_array_incoherent, scene},
        {"n16_auto_frustum", n_fn, &ne[0]},
        {"n8_auto_frustum", n_fn, &ne[1]},
        {"n32_mlrt", n_fn, &ne[2]},
        {"n16_mlrt", n_fn, &ne[3]},
    };
    int n = (int)(sizeof all / sizeof all[0]);
    if (n > max) n = max;
    /* The large-packet engines live in ctx so that the modes can point at them. */
    if (n > 6) {
        rp_frustum_kind fr = set_frustum(set->kind);
        bench_n_engine_init(&ne[0], scene, 16, RP_TRAVERSAL_AUTO, fr, ctx->light);
        bench_n_engine_init(&ne[1], scene, 8, RP_TRAVERSAL_AUTO, fr, ctx->light);
        bench_n_engine_init(&ne[2], scene, 32, RP_TRAVERSAL_MLRT, fr, ctx->light);
        bench_n_engine_init(&ne[3], scene, 16, RP_TRAVERSAL_MLRT, fr, ctx->light);
    }
    for (int i = 0; i < n; i++) modes[i] = all[i];
    return n;
}

/* ---- the mesh ------------------------------------------------------------------------------- */

static bool finite3(const float *v) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

/* Copies the loader's triangles, leaving out those raypack rejects, so both engines get one list
 * in the same order and agree on primitive ids. */
static bool mesh_from_data(bench_mesh *mesh, const float *positions, size_t vertex_count,
                           const uint32_t *indices, size_t triangle_count) {
    memset(mesh, 0, sizeof *mesh);
    mesh->vertex_count = vertex_count;
    mesh->positions = alloc_aligned((3 * vertex_count + 1) * sizeof(float));
    mesh->indices = alloc_aligned((3 * triangle_count + 1) * sizeof(uint32_t));
    if (!mesh->positions || !mesh->indices) return false;
    if (vertex_count) memcpy(mesh->positions, positions, 3 * vertex_count * sizeof(float));
    for (int k = 0; k < 3; k++) {
        mesh->lower[k] = INFINITY;
        mesh->upper[k] = -INFINITY;
    }
    size_t kept = 0;
    for (size_t t = 0; t < triangle_count; t++) {
        const uint32_t *tri = indices + 3 * t;
        if (tri[0] >= vertex_count || tri[1] >= vertex_count || tri[2] >= vertex_count ||
            !finite3(positions + 3 * (size_t)tri[0]) || !finite3(positions + 3 * (size_t)tri[1]) ||
            !finite3(positions + 3 * (size_t)tri[2])) {
            mesh->dropped++;
            continue;
        }
        const float *v[3] = {positions + 3 * (size_t)tri[0], positions + 3 * (size_t)tri[1],
                             positions + 3 * (size_t)tri[2]};
        float e1[3], e2[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = v[1][k] - v[0][k];
            e2[k] = v[2][k] - v[0][k];
        }
        float cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2],
              cz = e1[0] * e2[1] - e1[1] * e2[0];
        if (cx == 0.0f && cy == 0.0f && cz == 0.0f) mesh->degenerate++;
        for (int c = 0; c < 3; c++)
            for (int k = 0; k < 3; k++) {
                mesh->lower[k] = fminf(mesh->lower[k], v[c][k]);
                mesh->upper[k] = fmaxf(mesh->upper[k], v[c][k]);
            }
        memcpy(mesh->indices + 3 * kept, tri, 3 * sizeof(uint32_t));
        kept++;
    }
    mesh->triangle_count = kept;
    return true;
}

/* Frees the mesh arrays. */
static void mesh_free(bench_mesh *mesh) {
    free(mesh->positions);
    free(mesh->indices);
    memset(mesh, 0, sizeof *mesh);
}

/* The scene without a file: a 6x6 field of tessellated spheres on a ground quad (80k triangles),
 * seen from above the front edge. */
static bool mesh_sphere_field(bench_mesh *mesh, bench_camera *cam) {
    enum { GRID = 6, LON = 48, LAT = 24 };
    const float radius = 1.0f, spacing = 3.0f;
    size_t per_vertices = (size_t)(LAT + 1) * (LON + 1);
    size_t per_tris = (size_t)LON * 2 * (LAT - 1);
    size_t vcount = GRID * GRID * per_vertices + 4, tcount = GRID * GRID * per_tris + 2;
    float *pos = malloc(3 * vcount * sizeof(float));
    uint32_t *idx = malloc(3 * tcount * sizeof(uint32_t));
    if (!pos || !idx) {
        free(pos);
        free(idx);
        return false;
    }
    size_t v = 0, t = 0;
    const float pi = 3.14159265358979f;
    for (int gz = 0; gz < GRID; gz++)
        for (int gx = 0; gx < GRID; gx++) {
            float cx = ((float)gx - 0.5f * (GRID - 1)) * spacing;
            float cz = ((float)gz - 0.5f * (GRID - 1)) * spacing;
            uint32_t base = (uint32_t)v;
            for (int i = 0; i <= LAT; i++) {
                float theta = pi * (float)i / LAT;
                for (int j = 0; j <= LON; j++) {
                    float phi = 2.0f * pi * (float)j / LON;
                    pos[3 * v + 0] = cx + radius * sinf(theta) * cosf(phi);
                    pos[3 * v + 1] = radius + radius * cosf(theta);
                    pos[3 * v + 2] = cz + radius * sinf(theta) * sinf(phi);
                    v++;
                }
            }
            for (int i = 0; i < LAT; i++)
                for (int j = 0; j < LON; j++) {
                    uint32_t a = base + (uint32_t)(i * (LON + 1) + j), b = a + 1;
                    uint32_t c = a + (LON + 1), d = c + 1;
                    /* The pole rows are fans: their other triangle would have zero area. */
                    if (i != 0) {
                        idx[3 * t] = a, idx[3 * t + 1] = b, idx[3 * t + 2] = d;
                        t++;
                    }
                    if (i != LAT - 1) {
                        idx[3 * t] = a, idx[3 * t + 1] = d, idx[3 * t + 2] = c;
                        t++;
                    }
                }
        }
    const float g = 0.5f * GRID * spacing + 2.0f;
    const float ground[4][3] = {{-g, 0, -g}, {g, 0, -g}, {g, 0, g}, {-g, 0, g}};
    uint32_t gb = (uint32_t)v;
    for (int i = 0; i < 4; i++, v++) memcpy(pos + 3 * v, ground[i], sizeof ground[i]);
    const uint32_t quad[6] = {gb, gb + 2, gb + 1, gb, gb + 3, gb + 2};
    memcpy(idx + 3 * t, quad, sizeof quad);
    t += 2;
    bool ok = mesh_from_data(mesh, pos, v, idx, t);
    free(pos);
    free(idx);
    *cam = (bench_camera){{0.0f, 9.0f, 19.0f}, {0.0f, 0.5f, 0.0f}, {0.0f, 1.0f, 0.0f}, 40.0f};
    return ok;
}

/* ---- cameras and rays ----------------------------------------------------------------------- */

static void normalize3(float *v) {
    double l = sqrt((double)v[0] * v[0] + (double)v[1] * v[1] + (double)v[2] * v[2]);
    if (l > 0.0)
        for (int k = 0; k < 3; k++) v[k] = (float)(v[k] / l);
}

/* out = a x b. */
static void cross3(float *out, const float *a, const float *b) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* a . b */
static float dot3(const float *a, const float *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* Pixel of a slot (inverse of the block layout of bench.h). */
static void slot_pixel(int width, size_t slot, int *x, int *y) {
    int blocks_x = (width + BENCH_BLOCK - 1) / BENCH_BLOCK;
    size_t block = slot / BENCH_CHUNK, within = slot % BENCH_CHUNK;
    uint32_t lx, ly;
    bench_block_pixel((uint32_t)within, &lx, &ly);
    *x = (int)(block % (size_t)blocks_x) * BENCH_BLOCK + (int)lx;
    *y = (int)(block / (size_t)blocks_x) * BENCH_BLOCK + (int)ly;
}

bool bench_rays_alloc(bench_rays *set, bench_kind kind, int width, int height) {
    size_t blocks = (size_t)((width + BENCH_BLOCK - 1) / BENCH_BLOCK) *
                    (size_t)((height + BENCH_BLOCK - 1) / BENCH_BLOCK);
    memset(set, 0, sizeof *set);
    set->kind = kind;
    set->occlusion = kind == BENCH_SHADOW;
    set->slots = blocks * BENCH_CHUNK;
    set->rays = alloc_aligned(set->slots * sizeof(bench_ray));
    set->valid = alloc_aligned(set->slots * sizeof(int32_t));
    return set->rays && set->valid;
}

void bench_rays_free(bench_rays *set) {
    free(set->rays);
    free(set->valid);
    memset(set, 0, sizeof *set);
}

/* Primary rays of DESIGN.md's pinhole camera through pixel centres. */
static void make_primary(bench_rays *set, const bench_camera *cam, int width, int height) {
    float f[3], r[3], u[3];
    for (int k = 0; k < 3; k++) f[k] = cam->look[k] - cam->eye[k];
    normalize3(f);
    cross3(r, f, cam->up);
    normalize3(r);
    cross3(u, r, f);
    float tan_half = tanf(0.5f * cam->fov_deg * 3.14159265358979f / 180.0f);
    float aspect = (float)width / (float)height;
    for (size_t i = 0; i < set->slots; i++) {
        int x, y;
        slot_pixel(width, i, &x, &y);
        if (x >= width || y >= height) continue;
        float sx = (2.0f * ((float)x + 0.5f) / (float)width - 1.0f) * tan_half * aspect;
        float sy = (1.0f - 2.0f * ((float)y + 0.5f) / (float)height) * tan_half;
        bench_ray *ray = &set->rays[i];
        for (int k = 0; k < 3; k++) {
            ray->org[k] = cam->eye[k];
            ray->dir[k] = f[k] + sx * r[k] + sy * u[k];
        }
        normalize3(ray->dir);
        ray->tnear = 0.0f;
        ray->tfar = INFINITY;
        set->valid[i] = -1;
        set->count++;
    }
}

/* Front faces minus back faces hit by a 12x12 grid of primary rays: a room open on one side (the
 * Cornell box) is seen through its opening. */
static int view_score(const bench_ctx *ctx, const bench_camera *cam) {
    enum { N = 12 };
    float f[3], r[3], u[3];
    for (int k = 0; k < 3; k++) f[k] = cam->look[k] - cam->eye[k];
    normalize3(f);
    cross3(r, f, cam->up);
    normalize3(r);
    cross3(u, r, f);
    float tan_half = tanf(0.5f * cam->fov_deg * 3.14159265358979f / 180.0f);
    int score = 0;
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            float sx = (2.0f * ((float)x + 0.5f) / N - 1.0f) * tan_half;
            float sy = (1.0f - 2.0f * ((float)y + 0.5f) / N) * tan_half;
            bench_ray b = {{cam->eye[0], cam->eye[1], cam->eye[2]}, 0.0f, {0, 0, 0}, INFINITY};
            for (int k = 0; k < 3; k++) b.dir[k] = f[k] + sx * r[k] + sy * u[k];
            normalize3(b.dir);
            rp_rayhit rh;
            fill_rp_ray(&rh.ray, &b, 0);
            rh.hit.geom_id = RP_INVALID_ID;
            rh.hit.prim_id = RP_INVALID_ID;
            rp_intersect1(ctx->scene, &rh);
            if (rh.hit.geom_id == RP_INVALID_ID || rh.hit.prim_id >= ctx->mesh.triangle_count) continue;
            const uint32_t *tri = ctx->mesh.indices + 3 * (size_t)rh.hit.prim_id;
            const float *v0 = ctx->mesh.positions + 3 * (size_t)tri[0];
            const float *v1 = ctx->mesh.positions + 3 * (size_t)tri[1];
            const float *v2 = ctx->mesh.positions + 3 * (size_t)tri[2];
            float e1[3], e2[3], n[3];
            for (int k = 0; k < 3; k++) {
                e1[k] = v1[k] - v0[k];
                e2[k] = v2[k] - v0[k];
            }
            cross3(n, e1, e2);
            float d = dot3(n, b.dir);
            score += d < 0.0f ? 1 : (d > 0.0f ? -1 : 0);
        }
    return score;
}

/* The camera of `raypack render` for files without one: the bounds framed at 45 degrees from the
 * first of +z, -z, +x, -x (y up) that sees the most front faces. */
static bench_camera camera_frame_bounds(const bench_ctx *ctx) {
    const bench_mesh *mesh = &ctx->mesh;
    bench_camera cam = {{0, 0, 0}, {0, 0, 0}, {0, 1, 0}, 45.0f};
    float radius = 0.0f;
    for (int k = 0; k < 3; k++) {
        cam.look[k] = 0.5f * (mesh->lower[k] + mesh->upper[k]);
        radius += (mesh->upper[k] - mesh->lower[k]) * (mesh->upper[k] - mesh->lower[k]);
    }
    radius = 0.5f * sqrtf(radius);
    if (!(radius > 0.0f)) radius = 1.0f;
    float dist = radius / sinf(0.5f * cam.fov_deg * 3.14159265358979f / 180.0f);
    static const float dirs[4][3] = {{0, 0, 1}, {0, 0, -1}, {1, 0, 0}, {-1, 0, 0}};
    bench_camera best = cam;
    int best_score = 0;
    for (int i = 0; i < 4; i++) {
        bench_camera cand = cam;
        for (int k = 0; k < 3; k++) cand.eye[k] = cam.look[k] + dirs[i][k] * dist;
        int s = view_score(ctx, &cand);
        if (i == 0 || s > best_score) {
            best = cand;
            best_score = s;
        }
    }
    return best;
}

/* Camera (the file's, framed bounds, then the command line's overrides) and light (the file's
 * first, else above the centre along the camera's up axis, inside the bounds so closed rooms are
 * lit); needs the committed scene to frame the bounds. */
static void finish_camera_and_light(bench_ctx *ctx) {
    const bench_opts *o = &ctx->opts;
    if (!ctx->have_camera) ctx->camera = camera_frame_bounds(ctx);
    if (o->has_eye) memcpy(ctx->camera.eye, o->eye, sizeof o->eye);
    if (o->has_look) memcpy(ctx->camera.look, o->look, sizeof o->look);
    if (o->has_up) memcpy(ctx->camera.up, o->up, sizeof o->up);
    if (o->has_fov) ctx->camera.fov_deg = o->fov_deg;
    if (!ctx->have_light) {
        int axis = 0;
        for (int k = 1; k < 3; k++)
            if (fabsf(ctx->camera.up[k]) > fabsf(ctx->camera.up[axis])) axis = k;
        for (int k = 0; k < 3; k++) ctx->light[k] = 0.5f * (ctx->mesh.lower[k] + ctx->mesh.upper[k]);
        float extent = ctx->mesh.upper[axis] - ctx->mesh.lower[axis];
        ctx->light[axis] += copysignf(0.45f * extent, ctx->camera.up[axis]);
    }
}

/* Hash of 32 bits (lowbias32, Chris Wellons), for random numbers that depend only on their key. */
static uint32_t hash_u32(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

/* Uniform number in [0,1) from (pixel, dimension): the same whatever the thread count. */
static float rand_pixel(uint32_t pixel, uint32_t dim) {
    uint32_t h = hash_u32(pixel ^ hash_u32(dim * 0x9E3779B9u + 0x632BE5ABu));
    return (float)(h >> 8) * 0x1p-24f;
}

/* Refracted direction of unit d through a surface of facing normal n (dot(d, n) < 0), entering
 * when the triangle's own normal faces d (ior 1.5 inside); false on total internal reflection. */
static bool refract_dir(const float *d, const float *n, bool entering, float *out) {
    float eta = entering ? 1.0f / 1.5f : 1.5f;
    float cosi = -dot3(d, n);
    float k = 1.0f - eta * eta * (1.0f - cosi * cosi);
    if (k < 0.0f) return false;
    for (int j = 0; j < 3; j++) out[j] = eta * d[j] + (eta * cosi - sqrtf(k)) * n[j];
    normalize3(out);
    return true;
}

/* Shadow, reflection, refraction and diffuse rays from reference hits: each leaves its hit point
 * offset along the normal (to the side it goes to) so that it does not re-hit its surface. */
void bench_make_next(const bench_ctx *ctx, const bench_rays *prim, const bench_hits *hits,
                     bench_rays *set, bench_next how) {
    const bench_mesh *mesh = &ctx->mesh;
    float diag = 0.0f;
    for (int k = 0; k < 3; k++) diag += (mesh->upper[k] - mesh->lower[k]) * (mesh->upper[k] - mesh->lower[k]);
    const float eps = 5e-5f * sqrtf(diag);
    for (size_t i = 0; i < set->slots; i++) {
        if (!prim->valid[i] || hits->prim[i] == RP_INVALID_ID) continue;
        const bench_ray *in = &prim->rays[i];
        const uint32_t *tri = mesh->indices + 3 * (size_t)hits->prim[i];
        const float *v0 = mesh->positions + 3 * (size_t)tri[0];
        const float *v1 = mesh->positions + 3 * (size_t)tri[1];
        const float *v2 = mesh->positions + 3 * (size_t)tri[2];
        float e1[3], e2[3], n[3], p[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = v1[k] - v0[k];
            e2[k] = v2[k] - v0[k];
        }
        cross3(n, e1, e2);
        normalize3(n);
        if (dot3(n, n) == 0.0f) continue;
        bool entering = dot3(n, in->dir) < 0.0f;
        if (!entering)
            for (int k = 0; k < 3; k++) n[k] = -n[k];
        /* A refracted ray starts below the surface. */
        float side = how == BENCH_NEXT_REFRACT ? -eps : eps;
        for (int k = 0; k < 3; k++) p[k] = in->org[k] + hits->t[i] * in->dir[k] + side * n[k];
        bench_ray *out = &set->rays[i];
        memcpy(out->org, p, sizeof p);
        out->tnear = 0.0f;
        out->tfar = INFINITY;
        switch (how) {
        case BENCH_NEXT_SHADOW: {
            float d[3] = {ctx->light[0] - p[0], ctx->light[1] - p[1], ctx->light[2] - p[2]};
            float dist = sqrtf(dot3(d, d));
            /* A light behind the surface needs no ray. */
            if (!(dist > 0.0f) || dot3(d, n) <= 0.0f) continue;
            for (int k = 0; k < 3; k++) out->dir[k] = d[k] / dist;
            out->tfar = dist * (1.0f - 1e-4f);
            break;
        }
        case BENCH_NEXT_REFRACT: {
            float d[3] = {in->dir[0], in->dir[1], in->dir[2]};
            normalize3(d);
            if (!refract_dir(d, n, entering, out->dir)) continue;
            break;
        }
        case BENCH_NEXT_REFLECT: {
            float dn = dot3(in->dir, n);
            for (int k = 0; k < 3; k++) out->dir[k] = in->dir[k] - 2.0f * dn * n[k];
            normalize3(out->dir);
            break;
        }
        case BENCH_NEXT_DIFFUSE: {
            int x, y;
            slot_pixel(ctx->opts.width, i, &x, &y);
            uint32_t pixel = (uint32_t)y * (uint32_t)ctx->opts.width + (uint32_t)x;
            float u1 = rand_pixel(pixel, 0), u2 = rand_pixel(pixel, 1);
            /* Cosine-distributed around n (Malley), in the frame of Duff et al. 2017. */
            float rad = sqrtf(u1), phi = 2.0f * 3.14159265358979f * u2;
            float lx = rad * cosf(phi), ly = rad * sinf(phi), lz = sqrtf(fmaxf(0.0f, 1.0f - u1));
            float sign = copysignf(1.0f, n[2]);
            float a = -1.0f / (sign + n[2]), b = n[0] * n[1] * a;
            float t1[3] = {1.0f + sign * n[0] * n[0] * a, sign * b, -sign * n[0]};
            float t2[3] = {b, sign + n[1] * n[1] * a, -n[1]};
            for (int k = 0; k < 3; k++) out->dir[k] = lx * t1[k] + ly * t2[k] + lz * n[k];
            normalize3(out->dir);
            break;
        }
        }
        set->valid[i] = -1;
        set->count++;
    }
}

/* Shadow, reflection and diffuse rays from the reference primary hits. */
static void make_secondary(bench_ctx *ctx, bench_rays *set) {
    bench_next how = set->kind == BENCH_SHADOW       ? BENCH_NEXT_SHADOW
                     : set->kind == BENCH_REFLECTION ? BENCH_NEXT_REFLECT
                                                     : BENCH_NEXT_DIFFUSE;
    bench_make_next(ctx, &ctx->sets[BENCH_PRIMARY], &ctx->ref[BENCH_PRIMARY], set, how);
}

/* ---- setting up a run ----------------------------------------------------------------------- */

static void usage(FILE *f) {
    fprintf(f,
            "usage: raypack bench [SCENE] [options]\n"
            "  Times raypack's query modes (single rays, 4/8/16-wide packets, ray arrays) on\n"
            "  primary, shadow, reflection and diffuse rays and the path tracer's bounce rays of\n"
            "  depth 1 and 2 (bounce1, bounce2); no SCENE: a generated sphere field.\n"
            "  --vs embree        raypack against Embree on the same rays, in one process, and\n"
            "                     each best mode with the engines' calls skipped (the harness alone)\n"
            "  --grid             the experiment grid of Overbeck et al. 2008 (sec. 5): masked,\n"
            "                     ranged, partition, span and auto traversal x 4x4..32x32 packets x\n"
            "                     primary / +shadows / 2-deep refraction / 2-bounce reflection,\n"
            "                     frusta off and on, against single and SIMD rays (repeats 3)\n"
            "  --accel-grid       every acceleration structure (bvh, kdtree, bih, grid): build time,\n"
            "                     memory and Mrays/s of single rays, SIMD rays and 16x16 packets\n"
            "                     per ray kind, on the same rays (repeats 3); with --threads 1\n"
            "                     timed by the thread's CPU time\n"
            "  --builds           build times alone: the BVH, the BIH and the grid built --repeats\n"
            "                     times (default 7) in turns in one process, the kd-tree once; median,\n"
            "                     min and the BVH's median over each, wall and process CPU time\n"
            "  --engine cuda      the CUDA BVH kernels (gpu/cuda) on the same sets, checked against\n"
            "                     raypack's single rays, kernel time by CUDA events (docs/gpu.md)\n"
            "  --accel KIND       the structure of plain bench and --grid: bvh, kdtree, bih or grid\n"
            "  --density F        the uniform grid's voxels per triangle (Cleary-Wyvill; --accel grid,\n"
            "                     --accel-grid) [4]\n"
            "  --threads N        tracing threads (default 2); plain bench also times 1 thread\n"
            "  --isa NAME         raypack's kernels: auto (the widest the CPU has; AVX2 on Intel\n"
            "                     CPUs that clock down under AVX-512), scalar, sse, avx2 or\n"
            "                     avx512 (default auto)\n"
            "  --repeats N        timed repeats per mode (default 5, --grid 3; median, min, max)\n"
            "  --warmup N         untimed passes per mode first (default 1)\n"
            "  --width W --height H   primary rays (default 1024x1024)\n"
            "  --eye x,y,z --look x,y,z --up x,y,z --fov DEG   override the scene's camera\n"
            "  --bad-rays F       also time each mode on the sets with a fraction F (0 < F <= 1)\n"
            "                     of their rays made NaN/Inf in origin or direction, zero-\n"
            "                     direction, tnear > tfar, NaN/Inf tnear or tfar (16 kinds in\n"
            "                     turn), checking they miss and the rest keep their hits;\n"
            "                     prints Mrays/s of both and the slowdown\n"
            "  --json FILE        write the results as JSON\n");
}

/* Parses argv (argv[0] is "bench"); returns CLI_EXIT_OK to go on, CLI_EXIT_USAGE on a bad
 * argument, -1 after --help. */
static int parse_args(int argc, char **argv, bench_opts *o) {
    const char *cmd = "bench";
    *o = (bench_opts){.threads = 2, .repeats = 5, .warmup = 1, .width = 1024, .height = 1024};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            usage(stdout);
            return -1;
        }
        if (a[0] != '-') {
            if (o->scene_path) {
                fprintf(stderr, "raypack bench: more than one scene (%s, %s)\n", o->scene_path, a);
                return CLI_EXIT_USAGE;
            }
            o->scene_path = a;
            continue;
        }
        if (strcmp(a, "--grid") == 0) {
            o->grid = true;
            continue;
        }
        if (strcmp(a, "--accel-grid") == 0) {
            o->accel_grid = true;
            continue;
        }
        if (strcmp(a, "--builds") == 0) {
            o->builds = true;
            continue;
        }
        const char *val = cli_flag_value(cmd, argc, argv, &i);
        if (!val) return CLI_EXIT_USAGE;
        bool ok = true;
        if (strcmp(a, "--vs") == 0) {
            ok = strcmp(val, "embree") == 0;
            if (!ok) fprintf(stderr, "raypack bench: --vs takes 'embree', got '%s'\n", val);
            o->vs_embree = ok;
        } else if (strcmp(a, "--engine") == 0) {
            ok = strcmp(val, "cuda") == 0;
            if (!ok) fprintf(stderr, "raypack bench: --engine takes 'cuda' (or 'stream', alone), got '%s'\n", val);
            o->cuda = ok;
        } else if (strcmp(a, "--threads") == 0) {
            ok = cli_parse_int(cmd, a, val, 1, CLI_MAX_THREADS, &o->threads);
        } else if (strcmp(a, "--isa") == 0) {
            ok = cli_parse_isa(cmd, a, val, &o->isa);
        } else if (strcmp(a, "--accel") == 0) {
            ok = cli_parse_accel(cmd, a, val, &o->accel);
        } else if (strcmp(a, "--density") == 0) {
            ok = cli_parse_float(cmd, a, val, 0.0, 1000.0, true, &o->grid_density);
        } else if (strcmp(a, "--repeats") == 0) {
            ok = cli_parse_int(cmd, a, val, 1, 1000, &o->repeats);
            o->repeats_set = true;
        } else if (strcmp(a, "--warmup") == 0) {
            ok = cli_parse_int(cmd, a, val, 0, 1000, &o->warmup);
        } else if (strcmp(a, "--width") == 0) {
            ok = cli_parse_int(cmd, a, val, 1, 1 << 15, &o->width);
        } else if (strcmp(a, "--height") == 0) {
            ok = cli_parse_int(cmd, a, val, 1, 1 << 15, &o->height);
        } else if (strcmp(a, "--eye") == 0) {
            ok = o->has_eye = cli_parse_vec3(cmd, a, val, o->eye);
        } else if (strcmp(a, "--look") == 0) {
            ok = o->has_look = cli_parse_vec3(cmd, a, val, o->look);
        } else if (strcmp(a, "--up") == 0) {
            ok = o->has_up = cli_parse_vec3(cmd, a, val, o->up);
        } else if (strcmp(a, "--fov") == 0) {
            ok = o->has_fov = cli_parse_float(cmd, a, val, 0.0, 180.0, true, &o->fov_deg);
        } else if (strcmp(a, "--json") == 0) {
            o->json_path = val;
        } else if (strcmp(a, "--bad-rays") == 0) {
            float f = 0.0f;
            ok = cli_parse_float(cmd, a, val, 0.0, 1.0, false, &f);
            if (ok && f == 0.0f) {
                fprintf(stderr, "raypack bench: --bad-rays takes a fraction in (0, 1], got '%s'\n", val);
                ok = false;
            }
            o->bad_rays = (double)f;
        } else {
            fprintf(stderr, "raypack bench: unknown option %s (see --help)\n", a);
            return CLI_EXIT_USAGE;
        }
        if (!ok) return CLI_EXIT_USAGE;
    }
    const cli_path paths[] = {{"SCENE", o->scene_path, true}, {"--json", o->json_path, false}};
    if (!cli_check_paths(cmd, paths, 2)) return CLI_EXIT_USAGE;
    /* before the runs, as render does: a --json into a missing folder failed only at the end */
    if (o->json_path && !cli_output_writable(cmd, o->json_path)) return CLI_EXIT_FAILURE;
    return CLI_EXIT_OK;
}

/* Loads the scene (or generates one) into the mesh, camera and light of ctx. */
static bool load_scene(bench_ctx *ctx) {
    const bench_opts *o = &ctx->opts;
    bool have_camera = false, have_light = false;
    if (!o->scene_path) {
        ctx->scene_name = "sphere_field";
        if (!mesh_sphere_field(&ctx->mesh, &ctx->camera)) return false;
        /* Above and in front of the field, so its spheres cast shadows toward the back. */
        const float light[3] = {4.0f, 12.0f, 8.0f};
        memcpy(ctx->light, light, sizeof light);
        have_camera = true;
        have_light = true;
    } else {
        const char *slash = strrchr(o->scene_path, '/');
        ctx->scene_name = slash ? slash + 1 : o->scene_path;
        rp_scene_data data;
        char err[512] = "";
        memset(&data, 0, sizeof data);
        double t0 = cli_now_ms();
        if (!rp_scene_data_load_ex(o->scene_path, &(rp_scene_load_desc){.threads = o->threads, .warning = cli_load_warning}, &data, err, sizeof err)) {
            fprintf(stderr, "raypack bench: %s\n", err[0] ? err : "cannot load the scene");
            return false;
        }
        ctx->load_ms = cli_now_ms() - t0;
        ctx->load_bytes = data.file_bytes;
        bool ok = mesh_from_data(&ctx->mesh, data.positions, data.vertex_count, data.indices,
                                 data.triangle_count);
        if (data.camera.valid) {
            memcpy(ctx->camera.eye, data.camera.eye, sizeof ctx->camera.eye);
            memcpy(ctx->camera.look, data.camera.look, sizeof ctx->camera.look);
            memcpy(ctx->camera.up, data.camera.up, sizeof ctx->camera.up);
            ctx->camera.fov_deg = data.camera.fov_deg;
            have_camera = true;
        }
        for (size_t i = 0; i < data.light_count && !have_light; i++)
            if (data.lights[i].type != RP_LIGHT_DATA_DIRECTIONAL) { /* the first with a position */
                memcpy(ctx->light, data.lights[i].position, sizeof ctx->light);
                have_light = true;
            }
        if (data.sphere_count || data.cone_count)
            printf("note: %zu spheres and %zu cones of the scene are not benchmarked (triangles only)\n",
                   data.sphere_count, data.cone_count);
        ctx->data = malloc(sizeof *ctx->data); /* kept for the path-traced sets */
        if (ctx->data) *ctx->data = data;
        else rp_scene_data_free(&data);
        if (!ok || !ctx->data) {
            fprintf(stderr, "raypack bench: out of memory\n");
            return false;
        }
    }
    if (ctx->mesh.triangle_count == 0) {
        fprintf(stderr, "raypack bench: %s has no valid triangles\n", ctx->scene_name);
        return false;
    }
    ctx->have_camera = have_camera;
    ctx->have_light = have_light;
    return true;
}

/* Device, raypack's scene and per-thread scratch. */
static bool setup_raypack(bench_ctx *ctx) {
    ctx->device = cli_device_new("bench", ctx->opts.threads, ctx->opts.isa);
    if (!ctx->device) return false;
    int threads = rp_device_thread_count(ctx->device);
    if (threads < 1) threads = 1;
    ctx->scratch.threads = threads;
    ctx->scratch.per_thread = calloc((size_t)threads, sizeof(void *));
    if (!ctx->scratch.per_thread) return false;
    for (int i = 0; i < threads; i++) {
        ctx->scratch.per_thread[i] = alloc_aligned((size_t)BENCH_CHUNK * BENCH_SCRATCH_RAY_BYTES);
        if (!ctx->scratch.per_thread[i]) return false;
    }
    return true;
}

rp_scene *bench_build_raypack(bench_ctx *ctx, double *wall_ms, rp_scene_stats *stats) {
    rp_scene *scene = rp_scene_new(ctx->device, &(rp_scene_desc){.accel = ctx->opts.accel, .grid_density = ctx->opts.grid_density});
    rp_geometry *geom = rp_geometry_new(ctx->device, RP_GEOMETRY_TRIANGLE);
    if (!scene || !geom) {
        if (geom) rp_geometry_release(geom);
        if (scene) rp_scene_release(scene);
        return NULL;
    }
    rp_geometry_set_buffer(geom, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, ctx->mesh.positions, 0, 0,
                           ctx->mesh.vertex_count);
    rp_geometry_set_buffer(geom, RP_BUFFER_INDEX, RP_FORMAT_UINT3, ctx->mesh.indices, 0, 0,
                           ctx->mesh.triangle_count);
    rp_geometry_commit(geom);
    rp_scene_attach(scene, geom);
    rp_geometry_release(geom);
    struct timespec c0, c1;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
    double t0 = bench_now_ms();
    rp_error e = rp_scene_commit(scene);
    *wall_ms = bench_now_ms() - t0;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
    ctx->build_cpu_ms = (double)(c1.tv_sec - c0.tv_sec) * 1e3 + (double)(c1.tv_nsec - c0.tv_nsec) * 1e-6;
    if (e != RP_ERROR_NONE) {
        fprintf(stderr, "raypack bench: rp_scene_commit: %s\n", rp_error_string(e));
        rp_scene_release(scene);
        return NULL;
    }
    /* as render refuses them: past the float tests' reach the modes would disagree, and the check
     * would blame the kernels */
    rp_bounds sb;
    rp_scene_get_bounds(scene, &sb);
    const float inside[3] = {sb.lower_x, sb.lower_y, sb.lower_z}; /* the framed camera's eye is near */
    const float *eye = ctx->opts.has_eye ? ctx->opts.eye : ctx->have_camera ? ctx->camera.eye : inside;
    if (!cli_core_in_reach("bench", ctx->opts.scene_path, scene, eye)) {
        rp_scene_release(scene);
        return NULL;
    }
    rp_scene_get_stats(scene, stats);
    return scene;
}

/* Generates the ray sets; shadow, reflection and diffuse rays start at raypack's single-ray
 * primary hits, bounce1 and bounce2 come from a path-traced frame. False after printing why. */
static bool make_ray_sets(bench_ctx *ctx) {
    for (int k = 0; k < BENCH_KIND_COUNT; k++)
        if (!bench_rays_alloc(&ctx->sets[k], (bench_kind)k, ctx->opts.width, ctx->opts.height) ||
            !bench_hits_alloc(&ctx->ref[k], ctx->sets[k].slots)) {
            fprintf(stderr, "raypack bench: out of memory for the ray sets\n");
            return false;
        }
    finish_camera_and_light(ctx);
    if (cli_camera_check("bench", ctx->opts.scene_path, ctx->camera.eye, ctx->camera.look, ctx->camera.up,
                         ctx->opts.has_eye, ctx->opts.has_look, ctx->opts.has_up) != CLI_EXIT_OK)
        return false; /* its rays would all be NaN, or all one line */
    make_primary(&ctx->sets[BENCH_PRIMARY], &ctx->camera, ctx->opts.width, ctx->opts.height);
    bench_mode single[1];
    bench_raypack_modes(ctx, &ctx->sets[BENCH_PRIMARY], single, 1);
    bench_trace_set(ctx, ctx->opts.threads, &single[0], &ctx->sets[BENCH_PRIMARY],
                    &ctx->ref[BENCH_PRIMARY]);
    if (!bench_make_path_sets(ctx)) return false;
    for (int k = BENCH_SHADOW; k < BENCH_KIND_COUNT; k++) {
        if (k <= BENCH_DIFFUSE) make_secondary(ctx, &ctx->sets[k]);
        bench_raypack_modes(ctx, &ctx->sets[k], single, 1);
        bench_trace_set(ctx, ctx->opts.threads, &single[0], &ctx->sets[k], &ctx->ref[k]);
    }
    return true;
}

/* Releases everything setup and the ray sets made, in reverse order. */
static void teardown(bench_ctx *ctx) {
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        bench_rays_free(&ctx->sets[k]);
        bench_hits_free(&ctx->ref[k]);
    }
    if (ctx->scratch.per_thread)
        for (int i = 0; i < ctx->scratch.threads; i++) free(ctx->scratch.per_thread[i]);
    free(ctx->scratch.per_thread);
    if (ctx->scene) rp_scene_release(ctx->scene);
    if (ctx->device) rp_device_release(ctx->device);
    mesh_free(&ctx->mesh);
    if (ctx->data) rp_scene_data_free(ctx->data);
    free(ctx->data);
}

void bench_print_header(const bench_ctx *ctx) {
    const bench_camera *c = &ctx->camera;
    printf("scene     %s: %zu triangles (%zu zero-area), %zu left out (NaN/Inf or bad indices)\n",
           ctx->scene_name, ctx->mesh.triangle_count, ctx->mesh.degenerate, ctx->mesh.dropped);
    printf("camera    eye %g,%g,%g look %g,%g,%g up %g,%g,%g fov %g, %dx%d\n", (double)c->eye[0],
           (double)c->eye[1], (double)c->eye[2], (double)c->look[0], (double)c->look[1],
           (double)c->look[2], (double)c->up[0], (double)c->up[1], (double)c->up[2],
           (double)c->fov_deg, ctx->opts.width, ctx->opts.height);
    printf("bounds    %g,%g,%g .. %g,%g,%g\n", (double)ctx->mesh.lower[0], (double)ctx->mesh.lower[1],
           (double)ctx->mesh.lower[2], (double)ctx->mesh.upper[0], (double)ctx->mesh.upper[1],
           (double)ctx->mesh.upper[2]);
    printf("light     %g,%g,%g\n", (double)ctx->light[0], (double)ctx->light[1], (double)ctx->light[2]);
    printf("device    %d threads, %s kernels (SIMD width %d); %d timed repeats after %d warm-up\n",
           rp_device_thread_count(ctx->device), cli_isa_name(rp_device_isa(ctx->device)),
           rp_device_isa(ctx->device), ctx->opts.repeats,
           ctx->opts.warmup);
}

/* ---- plain `raypack bench` ------------------------------------------------------------------ */

#define BENCH_MAX_MODES 8

/* ---- --bad-rays: rays no traversal should trust, mixed into the sets ------------------------ */

enum { BAD_KINDS = 16 };

/* The kinds of tests/test_bad_rays.c, applied to a good ray. */
static void spoil_ray(bench_ray *r, int kind) {
    switch (kind) {
    case 0: r->org[0] = NAN; break;
    case 1: r->org[1] = INFINITY; break;
    case 2: r->org[2] = -INFINITY; break;
    case 3: r->dir[0] = NAN; break;
    case 4: r->dir[1] = NAN; break;
    case 5: r->dir[2] = INFINITY; break;
    case 6: r->dir[0] = -INFINITY, r->dir[1] = r->dir[2] = 0.0f; break;
    case 7: r->dir[0] = r->dir[1] = r->dir[2] = 0.0f; break;
    case 8: r->tnear = NAN; break;
    case 9: r->tfar = NAN; break;
    case 10: r->tnear = r->tfar == INFINITY ? 2.0f : r->tfar * 2.0f + 1.0f, r->tfar = r->tnear * 0.5f; break;
    case 11: r->tnear = INFINITY; break;
    case 12: r->dir[0] = r->dir[1] = r->dir[2] = NAN; break;
    case 13: r->org[0] = r->org[1] = r->org[2] = INFINITY; break;
    case 14: r->dir[0] = r->dir[1] = r->dir[2] = INFINITY; break;
    default: r->tfar = -INFINITY; break;
    }
}

/* Whether slot i gets a bad ray: a hash of the slot below the fraction, so the bad rays are spread
 * over every packet, the same ones every run. */
static bool bad_slot(size_t i, double fraction) {
    uint32_t h = (uint32_t)i * 0x9E3779B1u;
    h ^= h >> 15, h *= 0x85EBCA77u, h ^= h >> 13;
    return (double)h < fraction * 4294967296.0;
}

typedef struct bad_result {
    size_t bad;                           /* rays of the set made bad */
    bench_stat finite[BENCH_MAX_MODES];   /* Mrays/s on the set as it is */
    bench_stat mixed[BENCH_MAX_MODES];    /* ... with the bad rays mixed in */
} bad_result;

/* A copy of set with the bad rays, and a view of it whose valid mask leaves them out (to compare
 * the good rays with the reference). */
static bool make_bad_set(const bench_ctx *ctx, const bench_rays *set, bench_rays *mixed, bench_rays *good,
                         size_t *bad) {
    if (!bench_rays_alloc(mixed, set->kind, ctx->opts.width, ctx->opts.height) ||
        !bench_rays_alloc(good, set->kind, ctx->opts.width, ctx->opts.height))
        return false;
    memcpy(mixed->rays, set->rays, set->slots * sizeof(bench_ray));
    memcpy(mixed->valid, set->valid, set->slots * sizeof(int32_t));
    memcpy(good->rays, set->rays, set->slots * sizeof(bench_ray));
    memcpy(good->valid, set->valid, set->slots * sizeof(int32_t));
    mixed->count = good->count = set->count;
    *bad = 0;
    for (size_t i = 0; i < set->slots; i++) {
        if (!set->valid[i] || !bad_slot(i, ctx->opts.bad_rays)) continue;
        spoil_ray(&mixed->rays[i], (int)(*bad % BAD_KINDS));
        good->valid[i] = 0;
        good->count--;
        (*bad)++;
    }
    return true;
}

/* The bad rays' answers: a miss (intersect: no primitive, t +inf as the harness writes a miss;
 * occluded: tfar keeps its bits, not set to -inf). Returns how many are wrong. */
static size_t check_bad(const bench_rays *mixed, const bench_rays *good, const bench_hits *hits) {
    size_t wrong = 0;
    for (size_t i = 0; i < mixed->slots; i++) {
        if (!mixed->valid[i] || good->valid[i]) continue;
        if (mixed->occlusion) {
            uint32_t a, b;
            memcpy(&a, &hits->t[i], 4);
            memcpy(&b, &mixed->rays[i].tfar, 4);
            wrong += a != b;
        } else {
            wrong += hits->prim[i] != RP_INVALID_ID || hits->t[i] != INFINITY;
        }
    }
    return wrong;
}

/* CPU seconds of the calling thread: the bad-ray comparison runs on one thread and counts its own
 * time only, so other programs on a shared machine do not skew the ratio. */
static double thread_cpu_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Checks every mode on each set with bad rays mixed in, then times the set as it is and with the
 * bad rays, alternating, on the calling thread by its CPU time; returns false when a mode got an
 * answer wrong. */
static bool bench_bad_rays(bench_ctx *ctx, bench_mode modes[][BENCH_MAX_MODES], const int *nmodes,
                           bench_hits *hits, bad_result *res) {
    bool ok = true;
    int threads = 1, repeats = ctx->opts.repeats;
    double *samples = calloc((size_t)repeats * 2, sizeof(double));
    if (!samples) return false;
    for (int k = 0; k < BENCH_KIND_COUNT && ok; k++) {
        bench_rays mixed, good;
        if (!make_bad_set(ctx, &ctx->sets[k], &mixed, &good, &res[k].bad)) {
            fprintf(stderr, "raypack bench: out of memory\n");
            bench_rays_free(&mixed);
            bench_rays_free(&good);
            ok = false;
            break;
        }
        for (int m = 0; m < nmodes[k]; m++) {
            bench_trace_set(ctx, threads, &modes[k][m], &mixed, hits);
            bench_diff d = bench_compare(&ctx->mesh, &good, &ctx->ref[k], hits);
            size_t wrong = check_bad(&mixed, &good, hits);
            if (d.total || wrong) {
                fprintf(stderr,
                        "raypack bench: %s rays with bad rays mixed in, %s: %zu good rays lost their hits, "
                        "%zu bad rays did not miss\n",
                        bench_kind_name((bench_kind)k), modes[k][m].name, d.total, wrong);
                ok = false;
            }
        }
        for (int m = 0; ok && m < nmodes[k]; m++) {
            const bench_rays *both[2] = {&ctx->sets[k], &mixed};
            for (int w = 0; w < ctx->opts.warmup; w++)
                for (int b = 0; b < 2; b++) bench_trace_set(ctx, threads, &modes[k][m], both[b], hits);
            for (int r = 0; r < repeats; r++)
                for (int b = 0; b < 2; b++) {
                    double t0 = thread_cpu_seconds();
                    bench_trace_set(ctx, threads, &modes[k][m], both[b], hits);
                    double s = thread_cpu_seconds() - t0;
                    samples[b * repeats + r] = s > 0.0 ? (double)both[b]->count / s * 1e-6 : 0.0;
                }
            res[k].finite[m] = bench_stats(samples, repeats);
            res[k].mixed[m] = bench_stats(samples + repeats, repeats);
        }
        bench_rays_free(&mixed);
        bench_rays_free(&good);
    }
    free(samples);
    if (!ok) return false;
    printf("\nbad rays  %.3g of each set's rays made NaN/Inf/zero-direction/tnear > tfar (%d kinds in turn), "
           "%d thread, Mrays per CPU second; every mode checked first: the bad rays miss, the others keep their hits\n",
           ctx->opts.bad_rays, BAD_KINDS, threads);
    printf("%-11s %9s  %-17s  %18s  %18s  %8s\n", "rays", "bad", "mode", "finite Mrays/CPU-s", "mixed Mrays/CPU-s",
           "slowdown");
    double worst = 0.0;
    for (int k = 0; k < BENCH_KIND_COUNT; k++)
        for (int m = 0; m < nmodes[k]; m++) {
            double slow = res[k].mixed[m].median > 0.0 ? res[k].finite[m].median / res[k].mixed[m].median : 0.0;
            if (slow > worst) worst = slow;
            printf("%-11s %9zu  %-17s  %18.2f  %18.2f  %7.2fx\n", m == 0 ? bench_kind_name((bench_kind)k) : "",
                   res[k].bad, modes[k][m].name, res[k].finite[m].median, res[k].mixed[m].median, slow);
        }
    printf("bad rays  worst slowdown %.2fx (goal: at most 2.5x, as Embree promises)\n", worst);
    return true;
}

typedef struct core_result {
    bench_stat stat[2][BENCH_MAX_MODES]; /* [thread config][mode] in Mrays/s */
} core_result;

/* Times every raypack mode on every set at 1 and N threads, after checking them against single
 * rays; returns the exit code. */
static int bench_core(bench_ctx *ctx) {
    double build_ms;
    rp_scene_stats st;
    memset(&st, 0, sizeof st);
    ctx->scene = bench_build_raypack(ctx, &build_ms, &st);
    if (!ctx->scene) return 1;
    if (!make_ray_sets(ctx)) return 1;
    bench_print_header(ctx);
    if (ctx->load_ms > 0.0)
        printf("load      %.2f ms on %d threads, %.1f MB parsed (%.0f MB/s)\n", ctx->load_ms, ctx->opts.threads,
               (double)ctx->load_bytes / 1e6, (double)ctx->load_bytes / 1e3 / ctx->load_ms);
    printf("build     %.2f ms (commit stats %.2f ms), %.2f MiB; %llu triangles, %llu rejected, "
           "%llu nodes of width %u, %llu leaves, depth %u, SAH %.2f\n",
           build_ms, st.build_ms, (double)st.bytes / (1024.0 * 1024.0),
           (unsigned long long)st.triangles, (unsigned long long)st.rejected_prims,
           (unsigned long long)st.wide_nodes, st.bvh_width, (unsigned long long)st.leaves, st.depth,
           st.sah_cost);

    int configs[2] = {1, ctx->opts.threads};
    int nconfigs = ctx->opts.threads > 1 ? 2 : 1;
    bench_mode modes[BENCH_KIND_COUNT][BENCH_MAX_MODES];
    int nmodes[BENCH_KIND_COUNT];
    bench_hits hits;
    if (!bench_hits_alloc(&hits, ctx->sets[0].slots)) return 1;

    /* Every mode must find the single-ray hits before any of them is timed. */
    int failed = 0;
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        bench_rays *set = &ctx->sets[k];
        nmodes[k] = bench_raypack_modes(ctx, set, modes[k], BENCH_MAX_MODES);
        for (int m = 1; m < nmodes[k]; m++) {
            bench_trace_set(ctx, ctx->opts.threads, &modes[k][m], set, &hits);
            bench_diff d = bench_compare(&ctx->mesh, set, &ctx->ref[k], &hits);
            if (d.total) {
                fprintf(stderr,
                        "raypack bench: %s rays, %s disagrees with single rays on %zu of %zu "
                        "(hit/miss %zu, distance %zu, primitive %zu)\n",
                        bench_kind_name((bench_kind)k), modes[k][m].name, d.total, set->count,
                        d.hit_miss, d.distance, d.primitive);
                bench_print_mismatches(&ctx->mesh, set, &ctx->ref[k], &hits, "single",
                                       modes[k][m].name, 3);
                failed = 1;
            } else if (d.ties) {
                printf("note      %s rays: %s ties with single rays on %zu (same distance, other "
                       "triangle)\n",
                       bench_kind_name((bench_kind)k), modes[k][m].name, d.ties);
            }
        }
    }
    if (failed) {
        bench_hits_free(&hits);
        return 1;
    }
    printf("check     every mode finds the single-ray hits on every ray\n\n");

    /* Modes and thread counts take turns inside each repeat, so drift hits them alike. */
    core_result res[BENCH_KIND_COUNT];
    double *samples = calloc((size_t)ctx->opts.repeats * 2 * BENCH_MAX_MODES, sizeof(double));
    if (!samples) {
        bench_hits_free(&hits);
        return 1;
    }
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        bench_rays *set = &ctx->sets[k];
        for (int w = 0; w < ctx->opts.warmup; w++)
            for (int c = 0; c < nconfigs; c++)
                for (int m = 0; m < nmodes[k]; m++)
                    bench_trace_set(ctx, configs[c], &modes[k][m], set, &hits);
        for (int r = 0; r < ctx->opts.repeats; r++)
            for (int c = 0; c < nconfigs; c++)
                for (int m = 0; m < nmodes[k]; m++) {
                    double s = bench_trace_set(ctx, configs[c], &modes[k][m], set, &hits);
                    samples[((size_t)c * BENCH_MAX_MODES + (size_t)m) * (size_t)ctx->opts.repeats +
                            (size_t)r] = s > 0.0 ? (double)set->count / s * 1e-6 : 0.0;
                }
        for (int c = 0; c < nconfigs; c++)
            for (int m = 0; m < nmodes[k]; m++)
                res[k].stat[c][m] = bench_stats(
                    samples + ((size_t)c * BENCH_MAX_MODES + (size_t)m) * (size_t)ctx->opts.repeats,
                    ctx->opts.repeats);
    }
    free(samples);
    bench_hits_free(&hits);

    printf("%-11s %9s  %-17s", "rays", "count", "mode");
    for (int c = 0; c < nconfigs; c++)
        printf("  %2d thr Mrays/s median (min-max)", configs[c]);
    printf("\n");
    for (int k = 0; k < BENCH_KIND_COUNT; k++)
        for (int m = 0; m < nmodes[k]; m++) {
            printf("%-11s %9zu  %-17s", m == 0 ? bench_kind_name((bench_kind)k) : "",
                   ctx->sets[k].count, modes[k][m].name);
            for (int c = 0; c < nconfigs; c++) {
                bench_stat s = res[k].stat[c][m];
                printf("  %8.2f (%7.2f - %7.2f)      ", s.median, s.min, s.max);
            }
            printf("\n");
        }

    bad_result bad[BENCH_KIND_COUNT];
    memset(bad, 0, sizeof bad);
    if (ctx->opts.bad_rays > 0.0) {
        if (!bench_hits_alloc(&hits, ctx->sets[0].slots)) return 1;
        bool bad_ok = bench_bad_rays(ctx, modes, nmodes, &hits, bad);
        bench_hits_free(&hits);
        if (!bad_ok) return 1;
    }

    if (ctx->opts.json_path) {
        char werr[512];
        rp_atomic_file *af = rp_atomic_open(ctx->opts.json_path, werr, sizeof werr);
        if (!af) {
            fprintf(stderr, "raypack bench: %s\n", werr);
            return 1;
        }
        FILE *f = rp_atomic_stream(af);
        fprintf(f, "{\"scene\": ");
        bench_json_string(f, ctx->scene_name);
        fprintf(f, ", \"triangles\": %zu, \"threads\": %d, \"width\": %d, \"height\": %d, "
                   "\"repeats\": %d, \"isa\": \"%s\",\n",
                ctx->mesh.triangle_count, ctx->opts.threads, ctx->opts.width, ctx->opts.height,
                ctx->opts.repeats, cli_isa_name(rp_device_isa(ctx->device)));
        fprintf(f, " \"load\": {\"ms\": %.3f, \"bytes\": %zu, \"threads\": %d},\n", ctx->load_ms, ctx->load_bytes,
                ctx->opts.threads);
        fprintf(f, " \"build\": {\"raypack_ms\": %.3f, \"raypack_commit_ms\": %.3f, "
                   "\"raypack_bytes\": %zu, \"sah_cost\": %.4f},\n \"rays\": {",
                build_ms, st.build_ms, st.bytes, st.sah_cost);
        for (int k = 0; k < BENCH_KIND_COUNT; k++) {
            fprintf(f, "%s\n  \"%s\": {\"count\": %zu, \"mismatches\": 0, \"modes\": {", k ? "," : "",
                    bench_kind_name((bench_kind)k), ctx->sets[k].count);
            for (int m = 0; m < nmodes[k]; m++) {
                fprintf(f, "%s\n   \"%s\": {", m ? "," : "", modes[k][m].name);
                for (int c = 0; c < nconfigs; c++) {
                    bench_stat s = res[k].stat[c][m];
                    fprintf(f, "%s\"threads_%d\": {\"mrays_median\": %.4f, \"mrays_min\": %.4f, "
                               "\"mrays_max\": %.4f}",
                            c ? ", " : "", configs[c], s.median, s.min, s.max);
                }
                fprintf(f, "}");
            }
            fprintf(f, "}}");
        }
        fprintf(f, "\n }");
        if (ctx->opts.bad_rays > 0.0) {
            fprintf(f, ",\n \"bad_rays\": {\"fraction\": %.6g, \"threads\": 1, \"sets\": {", ctx->opts.bad_rays);
            for (int k = 0; k < BENCH_KIND_COUNT; k++) {
                fprintf(f, "%s\n  \"%s\": {\"bad\": %zu, \"modes\": {", k ? "," : "", bench_kind_name((bench_kind)k),
                        bad[k].bad);
                for (int m = 0; m < nmodes[k]; m++)
                    fprintf(f, "%s\"%s\": {\"finite_mrays\": %.4f, \"mixed_mrays\": %.4f}", m ? ", " : "",
                            modes[k][m].name, bad[k].finite[m].median, bad[k].mixed[m].median);
                fprintf(f, "}}");
            }
            fprintf(f, "\n }}");
        }
        fprintf(f, "\n}\n");
        if (!rp_atomic_commit(af, werr, sizeof werr)) {
            fprintf(stderr, "raypack bench: %s\n", werr);
            return 1;
        }
    }
    return 0;
}

int cli_bench(int argc, char **argv) {
    if (argc > 1 && strcmp(argv[1], "--render") == 0) return cli_bench_render(argc - 1, argv + 1);
    if (cli_stream_wanted(argc, argv, "--stream", NULL)) return cli_stream_bench(argc, argv);
    bench_ctx ctx;
    memset(&ctx, 0, sizeof ctx);
    int rc = parse_args(argc, argv, &ctx.opts);
    if (rc) return rc < 0 ? CLI_EXIT_OK : rc;
    if (ctx.opts.grid && ctx.opts.vs_embree) {
        fprintf(stderr, "raypack bench: --grid and --vs embree are separate runs\n");
        return CLI_EXIT_USAGE;
    }
    if (ctx.opts.builds && (ctx.opts.grid || ctx.opts.vs_embree || ctx.opts.accel_grid || ctx.opts.cuda)) {
        fprintf(stderr, "raypack bench: --builds is a run of its own\n");
        return CLI_EXIT_USAGE;
    }
    if (ctx.opts.builds && !ctx.opts.repeats_set) ctx.opts.repeats = 7;
    if (ctx.opts.accel_grid && (ctx.opts.grid || ctx.opts.vs_embree)) {
        fprintf(stderr, "raypack bench: --accel-grid is a run of its own\n");
        return CLI_EXIT_USAGE;
    }
    if (ctx.opts.cuda && (ctx.opts.grid || ctx.opts.accel_grid || ctx.opts.vs_embree)) {
        fprintf(stderr, "raypack bench: --engine cuda is a run of its own\n");
        return CLI_EXIT_USAGE;
    }
#if !defined(RP_HAVE_CUDA)
    if (ctx.opts.cuda) {
        fprintf(stderr, "raypack bench: --engine cuda: raypack was built without CUDA (nvcc not found)\n");
        return CLI_EXIT_USAGE;
    }
#endif
    rc = cli_camera_flags_check("bench", ctx.opts.has_eye ? ctx.opts.eye : NULL, ctx.opts.has_look ? ctx.opts.look : NULL,
                                ctx.opts.has_up ? ctx.opts.up : NULL);
    if (rc != CLI_EXIT_OK) return rc;
    if ((ctx.opts.grid || ctx.opts.accel_grid) && !ctx.opts.repeats_set) ctx.opts.repeats = 3;
#if !defined(RP_HAVE_EMBREE)
    if (ctx.opts.vs_embree) {
        fprintf(stderr, "raypack bench: --vs embree: raypack was built without Embree "
                        "(install libembree-dev and reconfigure)\n");
        return CLI_EXIT_USAGE;
    }
#endif
    bench_set_ftz();
    if (!load_scene(&ctx) || !setup_raypack(&ctx)) {
        teardown(&ctx);
        return 1;
    }
#if defined(RP_HAVE_EMBREE)
    if (ctx.opts.vs_embree) {
        rc = bench_vs_embree(&ctx);
        teardown(&ctx);
        return rc;
    }
#endif
#if defined(RP_HAVE_CUDA)
    if (ctx.opts.cuda) {
        rc = bench_vs_cuda(&ctx);
        teardown(&ctx);
        return rc;
    }
#endif
    rc = ctx.opts.builds       ? bench_builds(&ctx)
         : ctx.opts.accel_grid ? bench_accel_grid(&ctx)
         : ctx.opts.grid       ? bench_grid(&ctx)
                               : bench_core(&ctx);
    teardown(&ctx);
    return rc;
}

FILE *bench_json_begin(const bench_ctx *ctx, rp_atomic_file **af) {
    char werr[512];
    *af = rp_atomic_open(ctx->opts.json_path, werr, sizeof werr);
    if (!*af) {
        fprintf(stderr, "raypack bench: %s\n", werr);
        return NULL;
    }
    FILE *f = rp_atomic_stream(*af);
    fprintf(f, "{\"scene\": ");
    bench_json_string(f, ctx->scene_name);
    return f;
}

bool bench_json_end(rp_atomic_file *af) {
    char werr[512];
    if (rp_atomic_commit(af, werr, sizeof werr)) return true;
    fprintf(stderr, "raypack bench: %s\n", werr);
    return false;
}

/* Used by bench_embree.c. */
bool bench_make_ray_sets(bench_ctx *ctx) { return make_ray_sets(ctx); }
