/* The multipass stream tracer (Purcell et al. 2002). See stream.h. */
#include "stream/stream.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "render/integrator/pbr.h"
#include "render/render.h"
#include "sys/sys.h"

const stream_paper_row stream_paper_table2[] = {
    {"Soda Hall Outside", 2443, 692, 1747, 4, 384, 1123, 0.009},
    {"Soda Hall Inside", 1198, 70, 1124, 4, 60, 1039, 0.061},
    {"Forest Top Down", 1999, 311, 1684, 4, 137, 1435, 0.062},
    {"Forest Inside", 2835, 1363, 1468, 4, 898, 990, 0.068},
    {"Bunny Ray Cast", 1085, 610, 471, 4, 221, 328, 0.105},
};
const size_t stream_paper_table2_count = sizeof stream_paper_table2 / sizeof stream_paper_table2[0];

stream_desc stream_desc_defaults(const stream_desc *desc) {
    stream_desc d = desc ? *desc : (stream_desc){0};
    if (d.width <= 0) d.width = 512;
    if (d.height <= 0) d.height = 512;
    if (!(d.oracle > 0.0f)) d.oracle = 0.2f;
    return d;
}

/* The per-ray state of the paper's state machine. */
typedef enum ray_state { RAY_TRAVERSING = 0, RAY_INTERSECTING = 1, RAY_SHADING = 2, RAY_DONE = 3 } ray_state;

/* A stream of rays, structure of arrays: one entry per ray in each. */
typedef struct ray_stream {
    size_t count;
    bool any;              /* shadow rays: stop at the first hit */
    rp_ray *ray;
    grid_walk *walk;       /* traversal state: voxel and stepping */
    grid_hit *hit;         /* closest hit so far */
    uint32_t *cursor, *end;/* the voxel's triangle list still to test */
    uint32_t *mailbox;     /* GRID_MAILBOX per ray */
    uint8_t *state;
    uint32_t *voxels, *tests;
    uint32_t *cuts;        /* hits on cut-out points passed over */
    const rp_render_scene *cutouts; /* the scene, where it has alpha-tested materials: its cut-out
                                     * points are no hits (set by trace_rays); else NULL */
    uint32_t *active;      /* rays traversing or intersecting, compacted after each pass */
    uint32_t *queue;       /* wavefront: the intersect queue, then the traverse queue (2 per ray) */
    size_t active_count;
    rp_rayhit *xray;       /* stream_desc.trace: each ray and its hit as the tracer left them */
} ray_stream;

static void stream_free(ray_stream *s) {
    free(s->ray), free(s->walk), free(s->hit), free(s->cursor), free(s->end), free(s->mailbox);
    free(s->state), free(s->voxels), free(s->tests), free(s->cuts), free(s->active), free(s->queue), free(s->xray);
    memset(s, 0, sizeof *s);
}

/* A stream of n rays; walk: with the grid's traversal state (not for an external tracer). */
static bool stream_alloc(ray_stream *s, size_t n, bool any, bool walk) {
    memset(s, 0, sizeof *s);
    s->count = n, s->any = any;
    size_t m = n ? n : 1;
    s->ray = malloc(m * sizeof(rp_ray));
    s->hit = malloc(m * sizeof(grid_hit));
    s->state = malloc(m);
    s->voxels = calloc(m, sizeof(uint32_t));
    s->tests = calloc(m, sizeof(uint32_t));
    s->cuts = calloc(m, sizeof(uint32_t));
    bool ok = s->ray && s->hit && s->state && s->voxels && s->tests && s->cuts;
    if (ok && walk) {
        s->walk = malloc(m * sizeof(grid_walk));
        s->cursor = malloc(m * sizeof(uint32_t));
        s->end = malloc(m * sizeof(uint32_t));
        s->mailbox = malloc(m * GRID_MAILBOX * sizeof(uint32_t));
        s->active = malloc(m * sizeof(uint32_t));
        s->queue = malloc(2 * m * sizeof(uint32_t));
        ok = s->walk && s->cursor && s->end && s->mailbox && s->active && s->queue;
    }
    if (!ok) stream_free(s);
    return ok;
}

/* Enters voxel state: intersecting when the current voxel lists triangles, else traversing. */
static void enter_voxel(const grid *g, ray_stream *s, uint32_t i) {
    uint32_t c = grid_walk_voxel(g, &s->walk[i]);
    s->voxels[i]++;
    s->cursor[i] = g->offsets[c], s->end[i] = g->offsets[c + 1];
    s->state[i] = s->cursor[i] < s->end[i] ? RAY_INTERSECTING : RAY_TRAVERSING;
}

/* Kernel: traversal setup of ray i (DDA setup and the first voxel); false when it misses the grid
 * (shaded as a miss). */
static bool setup_ray(const grid *g, ray_stream *s, size_t i) {
    s->voxels[i] = s->tests[i] = s->cuts[i] = 0;
    s->hit[i] = (grid_hit){.t = s->ray[i].tfar, .tri = UINT32_MAX};
    for (int k = 0; k < GRID_MAILBOX; k++) s->mailbox[i * GRID_MAILBOX + k] = UINT32_MAX;
    if (!(s->ray[i].tnear <= s->ray[i].tfar) || !grid_walk_setup(g, &s->ray[i], &s->walk[i])) {
        s->state[i] = RAY_SHADING;
        return false;
    }
    enter_voxel(g, s, (uint32_t)i);
    return true;
}

/* Kernel: one traversal step of ray i (a traversal pass runs it on every traversing ray). */
static void kernel_traverse(const grid *g, ray_stream *s, uint32_t i) {
    if (!grid_walk_step(g, &s->walk[i], s->hit[i].t))
        s->state[i] = RAY_SHADING;
    else
        enter_voxel(g, s, i);
}

/* grid_test on ray i with alpha cutouts: a hit it takes on a cut-out point (alpha.c's test: the
 * material's alpha at the hit's uv under the cutoff, BLEND's hash) is undone, the ray's closest hit
 * so far restored, as an any-hit filter rejects it (Embree's filter functions): the ray goes on
 * looking in this voxel and beyond. True when the triangle was hit and not cut out. */
static bool test_cut(const grid *g, ray_stream *s, uint32_t i, uint32_t tri) {
    grid_hit before = s->hit[i];
    if (!grid_test(g, tri, &s->ray[i], &s->hit[i])) return false;
    if (!s->cutouts || s->hit[i].tri != tri || before.tri == tri) return true; /* not taken (a tie lost) */
    rp_rayhit rh = {.ray = s->ray[i]};
    grid_hit_write(g, &s->hit[i], &rh);
    if (!alpha_rayhit_cut(s->cutouts, &rh)) return true;
    s->hit[i] = before;
    s->cuts[i]++;
    return false;
}

/* Kernel: one triangle of ray i's voxel list (triangles already in its mailbox are passed over).
 * At the end of the list the ray is done when its closest hit lies within the voxel. */
static void kernel_intersect(const grid *g, ray_stream *s, uint32_t i) {
    uint32_t *mb = &s->mailbox[(size_t)i * GRID_MAILBOX];
    while (s->cursor[i] < s->end[i]) {
        uint32_t tri = g->items[s->cursor[i]++];
        if (grid_mailbox_seen(mb, tri)) continue;
        s->tests[i]++;
        if (test_cut(g, s, i, tri) && s->any) {
            s->state[i] = RAY_SHADING;
            return;
        }
        break;
    }
    if (s->cursor[i] < s->end[i]) return;
    const grid_walk *w = &s->walk[i];
    float end = s->hit[i].t < w->t_end ? s->hit[i].t : w->t_end;
    s->state[i] = grid_walk_exit(g, w) < end ? RAY_TRAVERSING : RAY_SHADING;
}

/* A pass runs over the active rays in chunks on the device's threads: each chunk runs the kernels
 * on its rays, keeps its rays still traversing or intersecting at the front of its own range and
 * counts; the ranges are then closed up in order, so the active list, every ray's state and every
 * count are the ones a single thread gives. Small lists run on the calling thread. */
#define PASS_CHUNK 8192u

/* Chunks of `size` items over n: how many, and chunk k's items [*a, *b). */
static uint32_t chunk_count(size_t n, size_t size) { return (uint32_t)((n + size - 1) / size); }

static void chunk_bounds(uint32_t k, size_t n, size_t size, size_t *a, size_t *b) {
    *a = (size_t)k * size;
    *b = *a + size < n ? *a + size : n;
}

enum { PASS_SETUP = 0xFE, PASS_BOTH = 0xFF }; /* pass_job.want besides RAY_TRAVERSING / RAY_INTERSECTING */

typedef struct pass_job {
    const grid *g;
    ray_stream *s;
    uint8_t want;     /* the state whose kernel runs; PASS_BOTH: each ray's own (wavefront);
                       * PASS_SETUP: traversal setup of rays [first, first + n) */
    size_t first, n;  /* the active list's length (setup: the rays) */
    uint32_t *active; /* setup: where the active list goes */
    /* per chunk: kept, worked, ran intersect, ran traverse, then traversing, then intersecting */
    uint32_t (*out)[6];
} pass_job;

static void pass_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const pass_job *j = user;
    ray_stream *s = j->s;
    size_t a, b;
    chunk_bounds(k, j->n, PASS_CHUNK, &a, &b);
    size_t kept = a;
    uint32_t worked = 0, ni = 0, nt = 0, trav = 0, isect = 0;
    for (size_t p = a; p < b; p++) {
        uint32_t i;
        if (j->want == PASS_SETUP) {
            i = (uint32_t)(j->first + p);
            if (!setup_ray(j->g, s, i)) continue;
        } else {
            i = s->active[p];
            uint8_t q = s->state[i];
            if (j->want == PASS_BOTH || q == j->want) {
                worked++;
                if (q == RAY_INTERSECTING) {
                    ni++;
                    kernel_intersect(j->g, s, i);
                } else {
                    nt++;
                    kernel_traverse(j->g, s, i);
                }
            }
        }
        uint8_t q = s->state[i];
        if (q == RAY_TRAVERSING || q == RAY_INTERSECTING) {
            j->active[kept++] = i;
            trav += q == RAY_TRAVERSING, isect += q == RAY_INTERSECTING;
        }
    }
    uint32_t *o = j->out[k];
    o[0] = (uint32_t)(kept - a), o[1] = worked, o[2] = ni, o[3] = nt, o[4] = trav, o[5] = isect;
}

/* Runs one pass (see pass_job) and closes up the active list; sums[6] gets the chunks' counts. False
 * when out of memory. */
static bool run_pass(rp_device *dev, const grid *g, ray_stream *s, uint8_t want, size_t first, size_t n,
                     uint64_t sums[6]) {
    uint32_t chunks = chunk_count(n, PASS_CHUNK), one[1][6];
    pass_job j = {.g = g, .s = s, .want = want, .first = first, .n = n, .active = s->active, .out = one};
    if (chunks > 1 && !(j.out = malloc(chunks * sizeof *j.out))) return false;
    if (chunks > 1)
        rp_device_parallel_for(dev, chunks, pass_chunk, &j);
    else if (chunks == 1)
        pass_chunk(&j, 0, 0);
    size_t kept = 0;
    for (int m = 0; m < 6; m++) sums[m] = 0;
    for (uint32_t k = 0; k < chunks; k++) {
        if (kept != (size_t)k * PASS_CHUNK)
            memmove(&s->active[kept], &s->active[(size_t)k * PASS_CHUNK], j.out[k][0] * sizeof(uint32_t));
        kept += j.out[k][0];
        for (int m = 0; m < 6; m++) sums[m] += j.out[k][m];
    }
    s->active_count = kept;
    if (chunks > 1) free(j.out);
    return true;
}

/* The wavefront loop (Laine, Karras, Aila 2013): every iteration runs each active ray's own kernel,
 * as if compacted into one queue per kernel, so every ray of a pass does work (SIMD efficiency 1 by
 * construction; the cost moves into the compaction). */
static bool run_wavefront(rp_device *dev, const grid *g, ray_stream *s, stream_stats *st) {
    while (s->active_count) {
        uint64_t c[6];
        if (!run_pass(dev, g, s, PASS_BOTH, 0, s->active_count, c)) return false;
        if (c[2]) st->intersection_passes++, st->work += c[2], st->slots += c[2];
        if (c[3]) st->traversal_passes++, st->work += c[3], st->slots += c[3];
    }
    return true;
}

/* The multipass loop: the oracle picks the pass, the pass runs its kernel on the rays in its state
 * (the others wait, as fragments killed by the stencil do). */
static bool run_passes(rp_device *dev, const grid *g, ray_stream *s, size_t first, size_t count, rp_ray_kind kind,
                       float oracle, bool wavefront, stream_stats *st) {
    if (count == 0) return true;
    stream_kind_stats *ks = &st->kind[kind];
    uint64_t trav0 = st->traversal_passes, isect0 = st->intersection_passes, c[6];
    if (!run_pass(dev, g, s, PASS_SETUP, first, count, c)) return false;
    st->other_passes++;
    if (wavefront && !run_wavefront(dev, g, s, st)) return false;
    while (!wavefront) {
        uint64_t n_trav = c[4], n_isect = c[5];
        if (n_trav + n_isect == 0) break;
        bool isect = n_isect > 0 && (float)n_isect >= oracle * (float)(n_trav + n_isect);
        if (!run_pass(dev, g, s, isect ? RAY_INTERSECTING : RAY_TRAVERSING, 0, s->active_count, c)) return false;
        if (isect)
            st->intersection_passes++;
        else
            st->traversal_passes++;
        st->work += c[1];
        st->slots += count;
    }
    for (size_t i = first; i < first + count; i++) {
        st->voxels += s->voxels[i], st->tests += s->tests[i], st->cutouts += s->cuts[i];
        ks->voxels += s->voxels[i], ks->tests += s->tests[i];
        if (s->voxels[i] > st->max_voxels) st->max_voxels = s->voxels[i];
        if (s->tests[i] > st->max_tests) st->max_tests = s->tests[i];
        if (s->voxels[i] > ks->max_voxels) ks->max_voxels = s->voxels[i];
        if (s->tests[i] > ks->max_tests) ks->max_tests = s->tests[i];
        ks->hits += s->hit[i].tri != UINT32_MAX;
    }
    st->rays += count;
    ks->rays += count, ks->batches++;
    ks->traversal_passes += st->traversal_passes - trav0;
    ks->intersection_passes += st->intersection_passes - isect0;
    return true;
}

/* The external tracer (stream_desc.trace) on rays [first, first + count): each ray and its hit into
 * s->xray, and s->hit as the grid's passes leave it (tri 0: a hit, or blocked). The copies run in
 * chunks on the device's threads. */
#define EXTERNAL_CHUNK 16384u

typedef struct external_job {
    ray_stream *s;
    size_t first, count;
    uint32_t *hits; /* per chunk */
    const rp_render_scene *cutouts; /* the scene, where it has alpha-tested surfaces */
} external_job;

static void external_in(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const external_job *j = user;
    size_t a, b;
    chunk_bounds(k, j->count, EXTERNAL_CHUNK, &a, &b);
    for (size_t i = j->first + a; i < j->first + b; i++) {
        j->s->xray[i].ray = j->s->ray[i];
        j->s->xray[i].hit = (rp_hit){.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID};
    }
}

static void external_out(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const external_job *j = user;
    ray_stream *s = j->s;
    size_t a, b;
    chunk_bounds(k, j->count, EXTERNAL_CHUNK, &a, &b);
    uint32_t hits = 0;
    for (size_t i = j->first + a; i < j->first + b; i++) {
        /* the tracer's hits are the core's: alpha.c's fix-up, on the CPU, passes cut-out points */
        if (j->cutouts) alpha_fix_traced(j->cutouts, &s->xray[i], s->ray[i].tfar, s->any);
        const rp_rayhit *x = &s->xray[i];
        bool hit = s->any ? x->ray.tfar == -INFINITY && s->ray[i].tfar != -INFINITY : x->hit.geom_id != RP_INVALID_ID;
        s->hit[i] = (grid_hit){.t = x->ray.tfar, .tri = hit ? 0 : UINT32_MAX};
        s->voxels[i] = s->tests[i] = 0;
        s->state[i] = RAY_SHADING;
        hits += hit;
    }
    j->hits[k] = hits;
}

static bool trace_external(const rp_render_scene *rs, const stream_desc *d, ray_stream *s, size_t first, size_t count,
                           rp_ray_kind kind, stream_stats *st, char *err, size_t err_size) {
    if (count == 0) return true;
    rp_device *dev = rs->device;
    uint32_t chunks = chunk_count(count, EXTERNAL_CHUNK);
    external_job job = {.s = s, .first = first, .count = count, .hits = malloc(chunks * sizeof(uint32_t)),
                        .cutouts = rs->cutouts ? rs : NULL};
    if (!job.hits || (!s->xray && !(s->xray = malloc(s->count * sizeof *s->xray)))) {
        free(job.hits);
        snprintf(err, err_size, "stream: out of memory for %zu rays", s->count);
        return false;
    }
    rp_device_parallel_for(dev, chunks, external_in, &job);
    double t0 = sys_seconds();
    bool ok = d->trace(d->trace_user, s->xray + first, count, s->any, err, err_size);
    st->trace_ms += (sys_seconds() - t0) * 1e3;
    if (ok) {
        rp_device_parallel_for(dev, chunks, external_out, &job);
        stream_kind_stats *ks = &st->kind[kind];
        for (uint32_t k = 0; k < chunks; k++) ks->hits += job.hits[k];
        st->rays += count;
        ks->rays += count, ks->batches++;
    }
    free(job.hits);
    return ok;
}

/* Traces rays [first, first + count) of s: by the external tracer when the desc has one, else by
 * the grid's passes. false (with err) when the tracer failed. */
static bool trace_rays(const rp_render_scene *rs, const grid *g, const stream_desc *d, ray_stream *s, size_t first,
                       size_t count, rp_ray_kind kind, stream_stats *st, char *err, size_t err_size) {
    rp_device *dev = rs->device;
    if (d->trace) return trace_external(rs, d, s, first, count, kind, st, err, err_size);
    s->cutouts = rs->cutouts ? rs : NULL;
    if (run_passes(dev, g, s, first, count, kind, d->oracle, d->wavefront, st)) return true;
    snprintf(err, err_size, "stream: out of memory for the passes over %zu rays", count);
    return false;
}

static void hit_of(const grid *g, const ray_stream *s, size_t i, rp_rayhit *rh) {
    if (s->xray) { /* the external tracer's */
        *rh = s->xray[i];
        return;
    }
    rh->ray = s->ray[i];
    rh->hit = (rp_hit){.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID};
    grid_hit_write(g, &s->hit[i], rh);
}

/* The eyelight integrator's shade (render.c, shade_primary), the same arithmetic. */
static float eyelight(const rp_rayhit *rh) {
    if (rh->hit.geom_id == RP_INVALID_ID) return 0.0f;
    v3 ng = v3_normalize(v3_make(rh->hit.Ng_x, rh->hit.Ng_y, rh->hit.Ng_z));
    float c = fabsf(v3_dot(ng, v3_make(rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z)));
    if (!(c <= 1.0f)) c = c > 1.0f ? 1.0f : 0.0f;
    return c;
}

/* ---- the renderer's integrators on the stream ------------------------------------------------ */

/* A stream whose rays are traced as closest hits (any-hit rays are shadow streams). */
static bool stream_grow(ray_stream *s, size_t n, bool any, bool walk) {
    if (s->ray && n <= s->count) return true;
    stream_free(s);
    return stream_alloc(s, n, any, walk);
}

/* rp_occluded1's answer for ray i of a traced any-hit stream: its tfar -inf when blocked, and a ray
 * that was empty from the start (tnear > tfar) left as it was, as the core leaves it. */
static bool shadow_passes(const ray_stream *s, size_t i) {
    return s->hit[i].tri == UINT32_MAX && !(s->ray[i].tfar < 0.0f);
}

/* One level of the Whitted tree: its rays (reflection children first, then refraction children),
 * the slot each one's shading left, and the parent slot it adds its radiance to. */
typedef struct whitted_stream_level {
    whitted_slot *slot;
    uint32_t *parent;
    float *weight;
    size_t count, reflected; /* rays [0, reflected) are reflection rays, the rest refraction rays */
} whitted_stream_level;

typedef struct stream_ctx {
    const grid *g;
    const stream_desc *d;
    render_frame *f;
    render_thread th;
    stream_stats *st;
    ray_stream rays, shadow;
    uint32_t *owner;          /* shadow ray -> the slot it lights */
    whitted_light_term *term; /* shadow ray -> what its light brings */
    float *veil;              /* Whitted in a medium: per pixel, the medium's opacity along the eye ray */
    char *err;                /* the tracer's message when it failed */
    size_t err_size;
    bool failed;
} stream_ctx;

static bool trace(stream_ctx *c, ray_stream *s, size_t first, size_t count, rp_ray_kind kind) {
    if (trace_rays(c->f->s, c->g, c->d, s, first, count, kind, c->st, c->err, c->err_size)) return true;
    c->failed = true;
    return false;
}

/* The shading kernels run over chunks of a stream on the device's threads; each chunk keeps its own
 * counts and outputs, merged in chunk order afterwards, so every image and statistic is the one
 * ray order gives. */
#define STREAM_CHUNK 4096u

static uint32_t chunks_of(size_t n) { return chunk_count(n, STREAM_CHUNK); }

static void chunk_range(uint32_t k, size_t n, size_t *a, size_t *b) { chunk_bounds(k, n, STREAM_CHUNK, a, b); }

/* Kernel: eye-ray generation, the packet tracer's rays: Whitted's (render_sample_offset) or the
 * path tracer's (the pixel's sampler), with their per-ray state. */
typedef struct eye_job {
    stream_ctx *c;
    size_t n;
    int sample;
    whitted_stream_level *level; /* Whitted, else paths */
    pbr_path *paths;
} eye_job;

static void eye_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const eye_job *j = user;
    const render_frame *f = j->c->f;
    size_t w = (size_t)f->desc.width, a, b;
    chunk_range(k, j->n, &a, &b);
    rp_ray *rays = j->c->rays.ray;
    for (size_t i = a; i < b; i++) {
        int x = (int)(i % w), y = (int)(i / w);
        if (j->level) {
            float ox, oy;
            render_sample_offset(x, y, j->sample, &ox, &oy);
            camera_ray(&f->cam, (float)x + ox, (float)y + oy, &rays[i]);
            j->level->weight[i] = 1.0f;
            j->level->parent[i] = (uint32_t)i;
            continue;
        }
        pbr_path *p = &j->paths[i];
        p->rng = sampler_start_pixel(f->desc.sampler, (uint32_t)x, (uint32_t)y, (uint32_t)j->sample);
        camera_ray(&f->cam, (float)x + sampler_at(&p->rng, 0), (float)y + sampler_at(&p->rng, 1), &rays[i]);
        p->beta = v3_make(1, 1, 1), p->pdf = 0.0f, p->pixel = (uint32_t)i, p->depth = 0, p->specular = true;
    }
}

static void make_eye_rays(stream_ctx *c, size_t n, int sample, whitted_stream_level *level, pbr_path *paths) {
    eye_job j = {.c = c, .n = n, .sample = sample, .level = level, .paths = paths};
    rp_device_parallel_for(c->f->s->device, chunks_of(n), eye_chunk, &j);
}

typedef struct whitted_job {
    stream_ctx *c;
    whitted_stream_level *lv;
    int depth;
    /* per chunk: hits and lit slots (surface pass); the first entry of its shadow rays before and
     * after closing up, their count and how many were blocked (light passes) */
    uint32_t *hits, *lit, *made, *blocked;
    size_t *base, *start;
} whitted_job;

/* Kernel: whitted_surface on a chunk of the level's rays. */
static void whitted_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const whitted_job *j = user;
    size_t a, b;
    chunk_range(k, j->lv->count, &a, &b);
    uint32_t hits = 0, lit = 0;
    for (size_t i = a; i < b; i++) {
        rp_rayhit rh;
        hit_of(j->c->g, &j->c->rays, i, &rh);
        hits += rh.hit.geom_id != RP_INVALID_ID;
        whitted_surface(j->c->f, &rh.ray, &rh.hit, j->depth, j->lv->weight[i], &j->lv->slot[i]);
        if (j->depth == 0 && j->c->veil) j->c->veil[i] = volume_primary_opacity(j->c->f, &rh.ray);
        lit += j->lv->slot[i].lit;
    }
    j->hits[k] = hits, j->lit[k] = lit;
}

/* Kernel: the shadow rays of a chunk's lit slots (one a light, slot after slot, lights in order),
 * from its own range of the shadow stream. */
static void whitted_lights_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const whitted_job *j = user;
    stream_ctx *c = j->c;
    const render_frame *f = c->f;
    size_t a, b, n = j->base[k];
    chunk_range(k, j->lv->count, &a, &b);
    for (size_t s = a; s < b; s++) {
        if (!j->lv->slot[s].lit) continue;
        for (size_t i = 0; i < f->light_count; i++) {
            if (!whitted_light(f, &j->lv->slot[s], &f->lights[i], &c->shadow.ray[n], &c->term[n])) continue;
            c->owner[n++] = (uint32_t)s;
        }
    }
    j->made[k] = (uint32_t)(n - j->base[k]);
}

/* Kernel: the lights that got through, into a chunk's slots (each slot sums its lights in order). */
static void whitted_direct_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const whitted_job *j = user;
    stream_ctx *c = j->c;
    uint32_t blocked = 0;
    for (size_t r = j->start[k]; r < j->start[k] + j->made[k]; r++) {
        if (!shadow_passes(&c->shadow, r)) {
            blocked++;
            continue;
        }
        whitted_slot *o = &j->lv->slot[c->owner[r]];
        o->direct = v3_add(o->direct, whitted_light_contrib(o, &c->term[r]));
    }
    size_t a, b;
    chunk_range(k, j->lv->count, &a, &b);
    for (size_t s = a; s < b; s++)
        if (j->lv->slot[s].lit) j->lv->slot[s].color = v3_add(j->lv->slot[s].color, j->lv->slot[s].direct);
    j->blocked[k] = blocked;
}

/* Whitted's shading kernel on a level: whitted_surface per ray, then its shadow stream (one ray per
 * lit slot and light, slot after slot, lights in order, so each slot sums its lights in the order
 * the packet tracer does), then the lights that got through. */
static bool whitted_level_shade(stream_ctx *c, whitted_stream_level *lv, int depth) {
    const render_frame *f = c->f;
    rp_device *dev = f->s->device;
    uint32_t chunks = chunks_of(lv->count), m = chunks ? chunks : 1;
    whitted_job job = {.c = c, .lv = lv, .depth = depth, .hits = calloc(4 * (size_t)m, sizeof(uint32_t)),
                       .base = calloc(2 * (size_t)m, sizeof(size_t))};
    bool ok = false;
    if (!job.hits || !job.base) goto done;
    job.lit = job.hits + m, job.made = job.lit + m, job.blocked = job.made + m, job.start = job.base + m;
    rp_device_parallel_for(dev, chunks, whitted_chunk, &job);
    size_t lit = 0;
    for (uint32_t k = 0; k < chunks; k++) {
        c->st->shades += job.hits[k];
        if (depth == 0) c->st->eye_hits += job.hits[k];
        job.base[k] = lit * f->light_count;
        lit += job.lit[k];
    }
    c->st->other_passes++;
    size_t cap = lit * f->light_count;
    if (cap) {
        if (!stream_grow(&c->shadow, cap, true, !c->d->trace)) goto done;
        free(c->owner), free(c->term);
        c->owner = malloc(cap * sizeof *c->owner), c->term = malloc(cap * sizeof *c->term);
        if (!c->owner || !c->term) goto done;
        rp_device_parallel_for(dev, chunks, whitted_lights_chunk, &job);
    }
    size_t ns = 0; /* close up the chunks' ranges, in order */
    for (uint32_t k = 0; cap && k < chunks; k++) {
        job.start[k] = ns;
        memmove(&c->shadow.ray[ns], &c->shadow.ray[job.base[k]], job.made[k] * sizeof(rp_ray));
        memmove(&c->term[ns], &c->term[job.base[k]], job.made[k] * sizeof *c->term);
        memmove(&c->owner[ns], &c->owner[job.base[k]], job.made[k] * sizeof *c->owner);
        ns += job.made[k];
    }
    if (!trace(c, &c->shadow, 0, ns, RP_RAY_SHADOW)) goto done;
    rp_device_parallel_for(dev, chunks, whitted_direct_chunk, &job);
    for (uint32_t k = 0; k < chunks; k++) c->st->shadow_blocked += job.blocked[k];
    c->st->shades += ns;
    c->st->shadow_rays += ns;
    if (ns) c->st->other_passes++;
    ok = true;
done:
    free(job.hits), free(job.base);
    return ok;
}

static void whitted_level_free(whitted_stream_level *lv) {
    free(lv->slot), free(lv->parent), free(lv->weight);
    memset(lv, 0, sizeof *lv);
}

static bool whitted_level_alloc(whitted_stream_level *lv, size_t n) {
    size_t m = n ? n : 1;
    lv->slot = malloc(m * sizeof *lv->slot), lv->parent = malloc(m * sizeof *lv->parent);
    lv->weight = malloc(m * sizeof *lv->weight);
    lv->count = n;
    return lv->slot && lv->parent && lv->weight;
}

/* One sample of Whitted over the image, level by level (breadth first, as the packet tracer goes
 * through a packet): each level's rays a stream, the children's radiance folded into their
 * parents from the deepest level up (reflection before refraction, as whitted_shade adds them). */
static bool whitted_sample(stream_ctx *c, int sample, whitted_stream_level *levels) {
    const render_frame *f = c->f;
    int w = f->desc.width, h = f->desc.height;
    size_t n = (size_t)w * (size_t)h;
    int depth_max = f->desc.max_depth;
    if (!whitted_level_alloc(&levels[0], n) || !stream_grow(&c->rays, n, false, !c->d->trace)) return false;
    make_eye_rays(c, n, sample, &levels[0], NULL);
    levels[0].reflected = n;
    c->st->other_passes++;
    c->st->eye_rays += n;
    if (!trace(c, &c->rays, 0, n, RP_RAY_PRIMARY)) return false;
    int used = 1;
    for (int depth = 0; depth <= depth_max; depth++) {
        whitted_stream_level *lv = &levels[depth];
        if (!whitted_level_shade(c, lv, depth)) return false;
        size_t nr = 0, nt = 0;
        for (size_t k = 0; k < lv->count; k++) nr += lv->slot[k].has_r, nt += lv->slot[k].has_t;
        if (nr + nt == 0 || depth == depth_max) break;
        whitted_stream_level *dn = &levels[depth + 1];
        if (!whitted_level_alloc(dn, nr + nt) || !stream_grow(&c->rays, nr + nt, false, !c->d->trace)) return false;
        used = depth + 2;
        size_t r = 0, t = nr;
        for (size_t k = 0; k < lv->count; k++) {
            const whitted_slot *o = &lv->slot[k];
            if (o->has_r) {
                render_ray_init(&c->rays.ray[r], o->org_r, o->dir_r, INFINITY);
                dn->weight[r] = o->w_r, dn->parent[r++] = (uint32_t)k;
            }
            if (o->has_t) {
                render_ray_init(&c->rays.ray[t], o->org_t, o->dir_t, INFINITY);
                dn->weight[t] = o->w_t, dn->parent[t++] = (uint32_t)k;
            }
        }
        dn->reflected = nr;
        if (!trace(c, &c->rays, 0, nr, RP_RAY_REFLECTION) || !trace(c, &c->rays, nr, nt, RP_RAY_REFRACTION))
            return false;
    }
    /* Kernel: the children's radiance into their parents, deepest level first */
    for (int l = used - 1; l > 0; l--) {
        whitted_stream_level *lv = &levels[l], *up = &levels[l - 1];
        for (size_t k = 0; k < lv->count; k++) {
            whitted_slot *o = &up->slot[lv->parent[k]];
            o->color = v3_add(o->color, v3_mul(k < lv->reflected ? o->mul_r : o->mul_t, lv->slot[k].color));
        }
        c->st->other_passes++;
    }
    for (size_t i = 0; i < n; i++) {
        v3 col = levels[0].slot[i].color;
        if (c->veil) col = volume_composite_opacity(c->f, c->veil[i], col); /* as the tile renderer's */
        c->th.accum[3 * i + 0] += col.x, c->th.accum[3 * i + 1] += col.y, c->th.accum[3 * i + 2] += col.z;
    }
    for (int l = 0; l < used; l++) whitted_level_free(&levels[l]);
    return true;
}

/* One sample of path tracing (direct lighting, AO) over the image: the eye stream, then per depth
 * path_vertex on every live path (emission into the accumulator, the light sample's shadow ray into
 * the shadow stream, the bounce into the next stream), the shadow stream, the bounce stream. Each
 * pixel gets its terms in the packet renderer's order. */
typedef struct path_job {
    stream_ctx *c;
    pbr_path *paths;
    size_t count;
    uint32_t *counts; /* per chunk: next rays, shadow rays, hits */
} path_job;

static void path_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    const path_job *j = user;
    stream_ctx *c = j->c;
    size_t a, b;
    chunk_range(k, j->count, &a, &b);
    /* the chunk's own view of the thread state: the shared sums (each pixel has one path) and its
     * own range of the shadow queue */
    pbr_thread pt = *c->th.pbr;
    pt.shadow += a, pt.shadow_L += a, pt.shadow_pixel += a;
    render_thread th = c->th;
    th.pbr = &pt;
    uint32_t nshadow = 0, hits = 0;
    size_t next = a;
    for (size_t i = a; i < b; i++) {
        rp_rayhit rh, nx;
        hit_of(c->g, &c->rays, i, &rh);
        hits += rh.hit.geom_id != RP_INVALID_ID;
        pbr_path p = j->paths[i];
        if (!path_vertex(c->f, &th, &p, &rh, &nx, &nshadow)) continue;
        /* next <= i: the slot is read already */
        c->rays.ray[next] = nx.ray;
        j->paths[next++] = p;
    }
    j->counts[3 * k] = (uint32_t)(next - a), j->counts[3 * k + 1] = nshadow, j->counts[3 * k + 2] = hits;
}

static bool path_sample(stream_ctx *c, uint32_t sample, pbr_path *paths) {
    const render_frame *f = c->f;
    int w = f->desc.width, h = f->desc.height;
    size_t n = (size_t)w * (size_t)h;
    if (!stream_grow(&c->rays, n, false, !c->d->trace) || !stream_grow(&c->shadow, n, true, !c->d->trace)) return false;
    pbr_thread *pt = c->th.pbr;
    pt->shadow = c->shadow.ray; /* path_vertex queues its shadow rays straight into the stream */
    make_eye_rays(c, n, (int)sample, NULL, paths);
    uint32_t *counts = malloc(3 * (size_t)(chunks_of(n) ? chunks_of(n) : 1) * sizeof *counts);
    if (!counts) return false;
    c->st->other_passes++;
    c->st->eye_rays += n;
    if (!trace(c, &c->rays, 0, n, RP_RAY_PRIMARY)) {
        free(counts);
        return false;
    }
    size_t count = n;
    rp_ray_kind kind = RP_RAY_PRIMARY;
    while (count) {
        /* Kernel: path_vertex on every live path, chunk by chunk: a chunk's shadow rays (at most
         * one a path) and its next rays go to its own range, then the ranges are closed up in order */
        uint32_t chunks = chunks_of(count), nshadow = 0;
        path_job job = {.c = c, .paths = paths, .count = count, .counts = counts};
        rp_device_parallel_for(f->s->device, chunks, path_chunk, &job);
        size_t next = 0;
        for (uint32_t k = 0; k < chunks; k++) {
            size_t a, b;
            chunk_range(k, count, &a, &b);
            uint32_t nn = counts[3 * k], ns = counts[3 * k + 1], hits = counts[3 * k + 2];
            c->st->shades += hits;
            if (kind == RP_RAY_PRIMARY) c->st->eye_hits += hits;
            memmove(&c->rays.ray[next], &c->rays.ray[a], nn * sizeof(rp_ray));
            memmove(&paths[next], &paths[a], nn * sizeof(pbr_path));
            memmove(&pt->shadow[nshadow], &pt->shadow[a], ns * sizeof(rp_ray));
            memmove(&pt->shadow_L[nshadow], &pt->shadow_L[a], ns * sizeof(v3));
            memmove(&pt->shadow_pixel[nshadow], &pt->shadow_pixel[a], ns * sizeof(uint32_t));
            next += nn, nshadow += ns;
        }
        c->st->other_passes++;
        if (!trace(c, &c->shadow, 0, nshadow, RP_RAY_SHADOW)) {
            free(counts);
            return false;
        }
        for (uint32_t k = 0; k < nshadow; k++) {
            c->st->shades++;
            if (shadow_passes(&c->shadow, k))
                path_add_px(&c->th, pt->shadow_pixel[k], pt->shadow_L[k]);
            else
                c->st->shadow_blocked++;
        }
        c->st->shadow_rays += nshadow;
        if (nshadow) c->st->other_passes++;
        kind = RP_RAY_BOUNCE;
        if (!trace(c, &c->rays, 0, next, kind)) {
            free(counts);
            return false;
        }
        count = next;
    }
    free(counts);
    return true;
}

/* The renderer's integrator d->render on the stream (see stream_desc.render). */
static bool render_integrator(rp_render_scene *rs, const grid *g, const stream_desc *d, float *pixels,
                              stream_stats *st, char *err, size_t err_size) {
    rp_render_desc rd = *d->render;
    rd.width = d->width, rd.height = d->height, rd.camera = d->camera;
    rd.region[0] = rd.region[1] = rd.region[2] = rd.region[3] = 0;
    rd.accumulate = false, rd.bounce_rays = NULL;
    render_frame *f = calloc(1, sizeof *f);
    stream_ctx c = {.g = g, .d = d, .f = f, .st = st, .err = err, .err_size = err_size};
    size_t n = (size_t)d->width * (size_t)d->height;
    bool whitted = false, ok = false;
    whitted_stream_level *levels = NULL;
    pbr_path *paths = NULL;
    if (!f) goto oom;
    f->s = rs;
    f->desc = render_desc_resolve(rs, &rd);
    switch (f->desc.integrator) {
    case RP_INTEGRATOR_WHITTED: whitted = true; break;
    case RP_INTEGRATOR_PATH:
    case RP_INTEGRATOR_DIRECT:
    case RP_INTEGRATOR_AO: break;
    case RP_INTEGRATOR_EYELIGHT:
    case RP_INTEGRATOR_AOV:
    case RP_INTEGRATOR_IR:
    default:
        snprintf(err, err_size, "stream: the stream engine renders whitted, path, direct, ao or eyelight");
        free(f);
        return false;
    }
    render_frame_view(f);
    c.th.accum = calloc(n * 3, sizeof(float));
    if (!c.th.accum) goto oom;
    if (whitted) {
        levels = calloc((size_t)f->desc.max_depth + 1, sizeof *levels);
        if (!levels) goto oom;
        if (rs->medium && !(c.veil = malloc(n * sizeof *c.veil))) goto oom;
        for (int s = 0; s < f->desc.spp; s++)
            if (!whitted_sample(&c, f->desc.sample_start + s, levels)) goto oom;
    } else {
        c.th.pbr = calloc(1, sizeof *c.th.pbr);
        paths = malloc(n * sizeof *paths);
        if (!c.th.pbr || !paths) goto oom;
        c.th.pbr->shadow_L = malloc(n * sizeof(v3));
        c.th.pbr->shadow_pixel = malloc(n * sizeof(uint32_t));
        if (!c.th.pbr->shadow_L || !c.th.pbr->shadow_pixel) goto oom;
        for (int s = 0; s < f->desc.spp; s++)
            if (!path_sample(&c, (uint32_t)(f->desc.sample_start + s), paths)) goto oom;
    }
    /* the tile renderer's mean: the sum itself for one sample, else times 1 / spp */
    float inv = 1.0f / (float)f->desc.spp;
    for (size_t i = 0; i < 3 * n; i++) pixels[i] = f->desc.spp == 1 ? c.th.accum[i] : c.th.accum[i] * inv;
    ok = true;
oom:
    if (!ok && !c.failed) snprintf(err, err_size, "stream: out of memory for %zu rays", n);
    if (levels)
        for (int l = 0; l <= f->desc.max_depth; l++) whitted_level_free(&levels[l]);
    free(levels), free(paths);
    if (c.th.pbr) free(c.th.pbr->shadow_L), free(c.th.pbr->shadow_pixel);
    free(c.th.pbr), free(c.th.accum), free(c.owner), free(c.term), free(c.veil);
    stream_free(&c.rays), stream_free(&c.shadow);
    free(f);
    return ok;
}

/* Kernel: eye-ray generation, the renderer's camera at sample `sample`'s offsets (render_sample_offset:
 * sample 0 the pixel centres). */
static void eye_rays(const render_camera *rc, int width, size_t n, int sample, ray_stream *eye) {
    for (size_t i = 0; i < n; i++) {
        int x = (int)(i % (size_t)width), y = (int)(i / (size_t)width);
        float ox, oy;
        render_sample_offset(x, y, sample, &ox, &oy);
        camera_ray(rc, (float)x + ox, (float)y + oy, &eye->ray[i]);
    }
}

/* Eye light's colour of a traced eye ray, composited with the medium as the tile renderer does. */
static v3 eyelight_color(rp_render_scene *rs, const rp_rayhit *rh) {
    float c = eyelight(rh);
    v3 col = v3_make(c, c, c);
    if (rs->medium) {
        render_frame ef = {.s = rs};
        ef.desc.integrator = RP_INTEGRATOR_EYELIGHT;
        col = volume_composite_opacity(&ef, volume_primary_opacity(&ef, &rh->ray), col);
    }
    return col;
}

/* Eye light of more than one sample a pixel, or from a sample past 0 (the renderer's desc: spp,
 * sample_start): samples [first, first + spp) traced as a stream each, summed from 0 in order and
 * scaled by 1 / spp, the tile renderer's arithmetic, so the image equals rp_render's bit for bit.
 * hits (when not NULL) get the first sample's. */
static bool eyelight_samples(rp_render_scene *rs, const grid *g, const stream_desc *d, const render_camera *rc, int first,
                             int spp, float *pixels, rp_rayhit *hits, stream_stats *st, char *err, size_t err_size) {
    size_t n = (size_t)d->width * (size_t)d->height;
    memset(pixels, 0, n * 3 * sizeof(float));
    for (int s = 0; s < spp; s++) {
        ray_stream eye;
        if (!stream_alloc(&eye, n, false, !d->trace)) {
            snprintf(err, err_size, "stream: out of memory for %zu rays", n);
            return false;
        }
        eye_rays(rc, d->width, n, first + s, &eye);
        st->other_passes++;
        if (!trace_rays(rs, g, d, &eye, 0, n, RP_RAY_PRIMARY, st, err, err_size)) {
            stream_free(&eye);
            return false;
        }
        st->eye_rays += n;
        for (size_t i = 0; i < n; i++) {
            rp_rayhit rh;
            hit_of(g, &eye, i, &rh);
            if (hits && s == 0) hits[i] = rh;
            bool hit = rh.hit.geom_id != RP_INVALID_ID;
            st->eye_hits += hit, st->shades += hit;
            v3 col = eyelight_color(rs, &rh);
            pixels[3 * i + 0] += col.x, pixels[3 * i + 1] += col.y, pixels[3 * i + 2] += col.z;
        }
        st->other_passes++;
        stream_free(&eye);
    }
    float inv = 1.0f / (float)spp;
    if (spp > 1)
        for (size_t i = 0; i < 3 * n; i++) pixels[i] *= inv;
    return true;
}

bool stream_render(rp_render_scene *rs, const grid *g, const stream_desc *desc_in, float *pixels, rp_rayhit *hits,
                   stream_stats *stats, char *err, size_t err_size) {
    double t0 = sys_seconds();
    stream_desc d = stream_desc_defaults(desc_in);
    stream_stats st = {0};
    if (!rs || (!g && !d.trace) || !pixels) {
        snprintf(err, err_size, "stream: missing scene, grid or pixels");
        return false;
    }
    rp_camera cam = d.camera ? *d.camera : rp_render_scene_default_camera(rs);
    if (!camera_valid(&cam)) {
        snprintf(err, err_size, "stream: the camera has no frame (not finite, eye == look, up along the view or fov "
                                "outside (0, 180))");
        return false;
    }
    size_t n = (size_t)d.width * (size_t)d.height;
    if (d.render && d.render->integrator != RP_INTEGRATOR_EYELIGHT) {
        if (!render_integrator(rs, g, &d, pixels, &st, err, err_size)) return false;
        goto done;
    }
    render_camera rc;
    camera_setup(&cam, d.width, d.height, &rc);
    bool shadows = d.shading == STREAM_SHADE_SHADOW;
    /* eye light through the renderer's desc: its samples (spp, sample_start) */
    int spp = d.render && d.render->spp > 1 ? d.render->spp : 1;
    int first = d.render && d.render->sample_start > 0 ? d.render->sample_start : 0;
    if (!shadows && (spp > 1 || first > 0)) {
        if (!eyelight_samples(rs, g, &d, &rc, first, spp, pixels, hits, &st, err, err_size)) return false;
        goto done;
    }
    ray_stream eye;
    if (!stream_alloc(&eye, n, false, !d.trace)) {
        snprintf(err, err_size, "stream: out of memory for %zu rays", n);
        return false;
    }
    eye_rays(&rc, d.width, n, 0, &eye); /* the pixel centres */
    st.other_passes++;
    if (!trace_rays(rs, g, &d, &eye, 0, n, RP_RAY_PRIMARY, &st, err, err_size)) {
        stream_free(&eye);
        return false;
    }
    st.eye_rays = n;

    /* Kernel: shading (one pass); with shadows it emits the shadow stream */
    ray_stream shadow = {0};
    v3 light = rc.eye;
    if (shadows && rs->light_count > 0 && rs->lights[0].type == RP_LIGHT_SOURCE_POINT)
        light = v3_load(rs->lights[0].point.position);
    if (shadows && !stream_alloc(&shadow, n, true, !d.trace)) {
        stream_free(&eye);
        snprintf(err, err_size, "stream: out of memory for %zu shadow rays", n);
        return false;
    }
    float *kd_cos = shadows ? malloc(n * 3 * sizeof(float)) : NULL;
    if (shadows && !kd_cos) {
        stream_free(&eye), stream_free(&shadow);
        snprintf(err, err_size, "stream: out of memory");
        return false;
    }
    for (size_t i = 0; i < n; i++) {
        rp_rayhit rh;
        hit_of(g, &eye, i, &rh);
        if (hits) hits[i] = rh;
        bool hit = rh.hit.geom_id != RP_INVALID_ID;
        st.eye_hits += hit, st.shades += hit;
        eye.state[i] = RAY_DONE;
        if (!shadows) { /* composited as the tile renderer's eye light does */
            v3 col = eyelight_color(rs, &rh);
            pixels[3 * i + 0] = col.x, pixels[3 * i + 1] = col.y, pixels[3 * i + 2] = col.z;
            continue;
        }
        rp_ray *sr = &shadow.ray[i];
        render_ray_init(sr, rc.eye, v3_make(0, 0, 1), -1.0f); /* a miss: nothing to trace */
        if (!hit) { /* black, as eye light's misses */
            for (int k = 0; k < 3; k++) kd_cos[3 * i + k] = pixels[3 * i + k] = 0.0f;
            continue;
        }
        render_surface sf;
        scene_surface(rs, &rh.ray, &rh.hit, &sf);
        v3 kd = material_albedo(rs, &rs->materials[sf.material], &sf);
        /* the surface's offset (render_surface.eps), as the renderer's shadow rays: the scene's
         * (2e-5 of its largest coordinate) started a small object's shadow rays beyond its
         * neighbours on a large ground */
        v3 org = v3_madd(sf.p, sf.ng, sf.eps), to = v3_sub(light, org);
        float dist = v3_length(to);
        v3 l = dist > 0.0f ? v3_scale(to, 1.0f / dist) : sf.ng;
        float c = v3_dot(sf.ns, l);
        c = c > 0.0f ? c : 0.0f;
        kd_cos[3 * i + 0] = kd.x * c, kd_cos[3 * i + 1] = kd.y * c, kd_cos[3 * i + 2] = kd.z * c;
        for (int k = 0; k < 3; k++) pixels[3 * i + k] = 0.1f * v3_at(kd, k);
        if (c > 0.0f) render_ray_init(sr, org, l, dist * (1.0f - 1e-4f));
    }
    st.other_passes++;
    if (shadows) {
        if (!trace_rays(rs, g, &d, &shadow, 0, n, RP_RAY_SHADOW, &st, err, err_size)) {
            free(kd_cos);
            stream_free(&shadow), stream_free(&eye);
            return false;
        }
        for (size_t i = 0; i < n; i++) {
            bool traced = shadow.ray[i].tfar >= 0.0f;
            if (!traced) continue;
            st.shadow_rays++;
            bool blocked = shadow.hit[i].tri != UINT32_MAX;
            st.shadow_blocked += blocked;
            st.shades++;
            if (!blocked)
                for (int k = 0; k < 3; k++) pixels[3 * i + k] += 0.9f * kd_cos[3 * i + k];
        }
        st.other_passes++; /* the final shading pass */
        /* shadow rays that were not traced (misses, back-lit) are not rays of the frame */
        st.rays -= n - st.shadow_rays;
        st.kind[RP_RAY_SHADOW].rays -= n - st.shadow_rays;
        free(kd_cos);
        stream_free(&shadow);
    }
    stream_free(&eye);
done:
    st.passes = st.traversal_passes + st.intersection_passes + st.other_passes;
    st.simd_efficiency = st.slots ? (double)st.work / (double)st.slots : 0.0;
    st.ms = (sys_seconds() - t0) * 1e3;
    if (stats) *stats = st;
    return true;
}
