/* Rays traced on the GPU for the CPU's renderer. See cuda_tracer.h. */
#include "cuda_tracer.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/core.h"
#include "sys/sys.h"

struct rp_cuda_tracer {
    rp_cuda_bvh_src src;
    rp_cuda_bvh *gpu;        /* NULL when emulated */
    rp_cuda_batch *batch;
    rp_cuda_kernel kernel;
    rp_cuda_bvh_ray *rays;   /* host staging, cap of each: page-locked on a GPU */
    rp_cuda_bvh_hit *hits;
    size_t cap;
    rp_device *pool;         /* the scene's device: its threads convert the rays and hits */
    rp_scene *rest;          /* the scene's spheres, cones and user primitives under their own geom
                              * ids, traced on the CPU after the GPU's triangles; NULL if none */
    char device[256];
    rp_cuda_tracer_stats stats;
};

static void staging_free(rp_cuda_tracer *t) {
    if (t->gpu) {
        rp_cuda_host_free(t->rays), rp_cuda_host_free(t->hits);
    } else {
        free(t->rays), free(t->hits);
    }
    t->rays = NULL, t->hits = NULL, t->cap = 0;
}

static bool staging_grow(rp_cuda_tracer *t, size_t n) {
    if (n <= t->cap) return true;
    staging_free(t);
    n += n / 4; /* the next depth's stream is rarely larger */
    if (t->gpu) {
        t->rays = rp_cuda_host_alloc(n * sizeof *t->rays), t->hits = rp_cuda_host_alloc(n * sizeof *t->hits);
    } else {
        t->rays = malloc(n * sizeof *t->rays), t->hits = malloc(n * sizeof *t->hits);
    }
    if (!t->rays || !t->hits) {
        staging_free(t);
        return false;
    }
    t->cap = n;
    return true;
}

void rp_cuda_tracer_free(rp_cuda_tracer *t) {
    if (!t) return;
    if (t->rest) rp_scene_release(t->rest);
    rp_cuda_batch_free(t->batch);
    rp_cuda_bvh_free(t->gpu);
    rp_cuda_bvh_src_free(&t->src);
    staging_free(t);
    free(t);
}

/* The primitives the GPU does not trace (spheres; cones and other user geometry) go into a scene of
 * their own on the CPU, each geometry under the geom_id it has in the scene (the slots of the
 * others are filled in order, then freed), so a hit names the same geometry either way. Instances
 * are refused: the GPU layout is one level (`raypack render --engine cuda` flattens animations). */
static bool rest_scene(rp_cuda_tracer *t, const rp_scene *scene, char *err, size_t err_size) {
    for (uint32_t id = 0; id < scene->geom_count; id++)
        if (scene->geoms[id] && scene->geoms[id]->type == RP_GEOMETRY_INSTANCE) {
            snprintf(err, err_size, "cuda: the scene has instances (geometry %u); the GPU traces one level of triangles, spheres and cones", id);
            return false;
        }
    rp_scene_desc desc = scene->desc;
    desc.accel = RP_ACCEL_BVH;
    if (!(t->rest = rp_scene_new(scene->device, &desc))) goto oom;
    rp_geometry *filler = rp_geometry_new(scene->device, RP_GEOMETRY_USER);
    if (!filler) goto oom;
    bool ok = true;
    for (uint32_t id = 0; ok && id < scene->geom_count; id++) {
        rp_geometry *g = scene->geoms[id];
        bool rest = g && g->type != RP_GEOMETRY_TRIANGLE;
        ok = rp_scene_attach(t->rest, rest ? g : filler) == id;
    }
    for (uint32_t id = 0; ok && id < scene->geom_count; id++)
        if (!scene->geoms[id] || scene->geoms[id]->type == RP_GEOMETRY_TRIANGLE) rp_scene_detach(t->rest, id);
    rp_geometry_release(filler);
    if (!ok) goto oom;
    if (rp_scene_commit(t->rest) != RP_ERROR_NONE) {
        snprintf(err, err_size, "cuda: the scene's spheres, cones and user primitives could not be built on the CPU");
        return false;
    }
    return true;
oom:
    snprintf(err, err_size, "cuda: out of memory");
    return false;
}

rp_cuda_tracer *rp_cuda_tracer_new(const rp_scene *scene, rp_cuda_kernel kernel, bool emulate, char *err,
                                   size_t err_size) {
    rp_cuda_tracer *t = calloc(1, sizeof *t);
    if (!t) {
        snprintf(err, err_size, "cuda: out of memory");
        return NULL;
    }
    t->kernel = kernel;
    t->pool = scene->device;
    if (!rp_cuda_bvh_src_from_scene(scene, &t->src, err, err_size)) goto fail;
    if (t->src.skipped && !rest_scene(t, scene, err, err_size)) goto fail;
    if (emulate) {
        snprintf(t->device, sizeof t->device, "CPU (the CUDA kernels' code, emulated)");
        return t;
    }
    if (!rp_cuda_device_info(t->device, sizeof t->device)) {
        snprintf(err, err_size, "cuda: no CUDA device found");
        goto fail;
    }
    if (!(t->gpu = rp_cuda_bvh_upload(&t->src, err, err_size)) || !(t->batch = rp_cuda_batch_new(NULL, 0, err, err_size)))
        goto fail;
    return t;
fail:
    rp_cuda_tracer_free(t);
    return NULL;
}

const char *rp_cuda_tracer_device(const rp_cuda_tracer *t) { return t->device; }
size_t rp_cuda_tracer_bytes(const rp_cuda_tracer *t) {
    return t->gpu ? rp_cuda_bvh_bytes(t->gpu) : (size_t)t->src.node_count * 64 + (size_t)t->src.tri_count * 48;
}
rp_cuda_tracer_stats rp_cuda_tracer_get_stats(const rp_cuda_tracer *t) { return t->stats; }

/* The conversions, in chunks on the scene's device's threads. */
#define TRACE_CHUNK 16384u

static void chunk_bounds(uint32_t k, size_t n, size_t *a, size_t *b) {
    *a = (size_t)k * TRACE_CHUNK;
    *b = *a + TRACE_CHUNK < n ? *a + TRACE_CHUNK : n;
}

typedef struct convert_job {
    rp_cuda_tracer *t;
    rp_rayhit *rh;
    size_t n;
    bool occlusion;
    uint32_t *bad_mask; /* per chunk: 1 + the first ray with a mask other than all ones, or 0 */
} convert_job;

static void rays_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    convert_job *j = user;
    size_t a, b;
    chunk_bounds(k, j->n, &a, &b);
    j->bad_mask[k] = 0;
    for (size_t i = a; i < b; i++) {
        const rp_ray *r = &j->rh[i].ray;
        if (r->mask != 0xFFFFFFFFu && !j->bad_mask[k]) j->bad_mask[k] = (uint32_t)(i - a) + 1;
        j->t->rays[i] = (rp_cuda_bvh_ray){{r->org_x, r->org_y, r->org_z}, r->tnear, {r->dir_x, r->dir_y, r->dir_z}, r->tfar};
    }
}

/* The kernels' code on the CPU, a chunk of rays per task. */
static void emulate_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    convert_job *j = user;
    size_t a, b;
    chunk_bounds(k, j->n, &a, &b);
    rp_cuda_bvh_trace_emulated(&j->t->src, j->t->rays + a, b - a, j->occlusion, j->t->hits + a);
}

static void hits_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    convert_job *j = user;
    size_t a, b;
    chunk_bounds(k, j->n, &a, &b);
    for (size_t i = a; i < b; i++) {
        const rp_cuda_bvh_hit *h = &j->t->hits[i];
        rp_rayhit *o = &j->rh[i];
        if (j->occlusion) {
            if (h->t == -INFINITY) o->ray.tfar = -INFINITY;
            continue;
        }
        if (h->geom == RP_INVALID_ID) continue;
        o->ray.tfar = h->t;
        o->hit = (rp_hit){.Ng_x = h->ng[0], .Ng_y = h->ng[1], .Ng_z = h->ng[2], .u = h->u, .v = h->v,
                          .prim_id = h->prim, .geom_id = h->geom, .inst_id = RP_INVALID_ID};
    }
}

/* The spheres, cones and user primitives on the CPU, after the GPU: a closest hit among them nearer
 * than the triangle's (tfar is its t now) replaces it; a ray the triangles do not block is tested
 * against them. A sphere at exactly a triangle's t loses to it, where the CPU's one structure would
 * take the lower (geom_id, prim_id). */
static void rest_chunk(void *user, uint32_t k, uint32_t thread) {
    (void)thread;
    convert_job *j = user;
    size_t a, b;
    chunk_bounds(k, j->n, &a, &b);
    for (size_t i = a; i < b; i++) {
        if (!j->occlusion) rp_intersect1(j->t->rest, &j->rh[i]);
        else if (j->rh[i].ray.tfar != -INFINITY) rp_occluded1(j->t->rest, &j->rh[i].ray);
    }
}

bool rp_cuda_trace(void *user, rp_rayhit *rh, size_t n, bool occlusion, char *err, size_t err_size) {
    rp_cuda_tracer *t = user;
    if (n == 0) return true;
    double t0 = sys_seconds();
    uint32_t chunks = (uint32_t)((n + TRACE_CHUNK - 1) / TRACE_CHUNK);
    convert_job job = {.t = t, .rh = rh, .n = n, .occlusion = occlusion, .bad_mask = malloc(chunks * sizeof(uint32_t))};
    if (!job.bad_mask || !staging_grow(t, n)) {
        free(job.bad_mask);
        snprintf(err, err_size, "cuda: out of memory for %zu rays", n);
        return false;
    }
    rp_device_parallel_for(t->pool, chunks, rays_chunk, &job);
    for (uint32_t k = 0; k < chunks; k++) {
        if (!job.bad_mask[k]) continue;
        size_t i = (size_t)k * TRACE_CHUNK + job.bad_mask[k] - 1;
        snprintf(err, err_size, "cuda: ray %zu has mask 0x%x; the GPU traces rays with every mask bit", i,
                 rh[i].ray.mask);
        free(job.bad_mask);
        return false;
    }
    free(job.bad_mask);
    float ms = 0.0f;
    if (!t->gpu) {
        rp_device_parallel_for(t->pool, chunks, emulate_chunk, &job);
    } else if (!rp_cuda_batch_set(t->batch, t->rays, n, err, err_size) ||
               !rp_cuda_bvh_trace(t->gpu, t->batch, t->kernel, occlusion, &ms, err, err_size) ||
               !rp_cuda_batch_hits(t->batch, t->hits, err, err_size)) {
        return false;
    }
    rp_device_parallel_for(t->pool, chunks, hits_chunk, &job);
    if (t->rest) rp_device_parallel_for(t->pool, chunks, rest_chunk, &job);
    t->stats.rays += n, t->stats.batches++;
    t->stats.kernel_ms += ms;
    t->stats.total_ms += (sys_seconds() - t0) * 1e3;
    return true;
}
