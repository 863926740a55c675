/* Rays traced on the GPU for the CPU's renderer. See cuda_tracer.h. */
#include "cuda_tracer.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sys/sys.h"

struct rp_cuda_tracer {
    rp_cuda_bvh_src src;
    rp_cuda_bvh *gpu;        /* NULL when emulated */
    rp_cuda_batch *batch;
    rp_cuda_kernel kernel;
    rp_cuda_bvh_ray *rays;   /* host staging, cap of each */
    rp_cuda_bvh_hit *hits;
    size_t cap;
    char device[256];
    rp_cuda_tracer_stats stats;
};

void rp_cuda_tracer_free(rp_cuda_tracer *t) {
    if (!t) return;
    rp_cuda_batch_free(t->batch);
    rp_cuda_bvh_free(t->gpu);
    rp_cuda_bvh_src_free(&t->src);
    free(t->rays), free(t->hits);
    free(t);
}

rp_cuda_tracer *rp_cuda_tracer_new(const rp_scene *scene, rp_cuda_kernel kernel, bool emulate, char *err,
                                   size_t err_size) {
    rp_cuda_tracer *t = calloc(1, sizeof *t);
    if (!t) {
        snprintf(err, err_size, "cuda: out of memory");
        return NULL;
    }
    t->kernel = kernel;
    if (!rp_cuda_bvh_src_from_scene(scene, &t->src, err, err_size)) goto fail;
    if (t->src.skipped) {
        snprintf(err, err_size,
                 "cuda: the scene has %zu spheres, cones, instances or user primitives; the GPU traces "
                 "triangles only",
                 t->src.skipped);
        goto fail;
    }
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

bool rp_cuda_trace(void *user, rp_rayhit *rh, size_t n, bool occlusion, char *err, size_t err_size) {
    rp_cuda_tracer *t = user;
    if (n == 0) return true;
    double t0 = sys_seconds();
    if (n > t->cap) {
        free(t->rays), free(t->hits);
        t->rays = malloc(n * sizeof *t->rays), t->hits = malloc(n * sizeof *t->hits);
        t->cap = t->rays && t->hits ? n : 0;
        if (!t->cap) {
            snprintf(err, err_size, "cuda: out of memory for %zu rays", n);
            return false;
        }
    }
    for (size_t i = 0; i < n; i++) {
        const rp_ray *r = &rh[i].ray;
        if (r->mask != 0xFFFFFFFFu) {
            snprintf(err, err_size, "cuda: ray %zu has mask 0x%x; the GPU traces rays with every mask bit", i, r->mask);
            return false;
        }
        t->rays[i] = (rp_cuda_bvh_ray){{r->org_x, r->org_y, r->org_z}, r->tnear, {r->dir_x, r->dir_y, r->dir_z}, r->tfar};
    }
    float ms = 0.0f;
    if (!t->gpu) {
        rp_cuda_bvh_trace_emulated(&t->src, t->rays, n, occlusion, t->hits);
    } else if (!rp_cuda_batch_set(t->batch, t->rays, n, err, err_size) ||
               !rp_cuda_bvh_trace(t->gpu, t->batch, t->kernel, occlusion, &ms, err, err_size) ||
               !rp_cuda_batch_hits(t->batch, t->hits, err, err_size)) {
        return false;
    }
    for (size_t i = 0; i < n; i++) {
        const rp_cuda_bvh_hit *h = &t->hits[i];
        if (occlusion) {
            if (h->t == -INFINITY) rh[i].ray.tfar = -INFINITY;
            continue;
        }
        if (h->geom == RP_INVALID_ID) continue;
        rh[i].ray.tfar = h->t;
        rh[i].hit = (rp_hit){.Ng_x = h->ng[0], .Ng_y = h->ng[1], .Ng_z = h->ng[2], .u = h->u, .v = h->v,
                             .prim_id = h->prim, .geom_id = h->geom, .inst_id = RP_INVALID_ID};
    }
    t->stats.rays += n, t->stats.batches++;
    t->stats.kernel_ms += ms;
    t->stats.total_ms += (sys_seconds() - t0) * 1e3;
    return true;
}
