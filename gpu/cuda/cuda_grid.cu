/* The grid traversal of accel/grid/grid.c as a CUDA megakernel. See cuda_grid.h. Every operation
 * is the CPU's in the same order (no FMA contraction: --fmad=false), so hits agree bit for bit. */
#include <cuda_runtime.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "cuda_grid.h"
#include "cuda_tri.cuh"

struct rp_cuda_grid {
    rp_cuda_grid_src g;      /* device pointers in offsets, items, tris */
    uint32_t *d_offsets, *d_items;
    float *d_tris;
};

#define MAILBOX 8

struct dev_grid {
    float lo[3], cell[3], inv_cell[3], hi[3];
    int res[3];
    const uint32_t *offsets, *items;
    const float *tris;
};

__device__ static float axis_exit(const dev_grid &g, const int *cell, const int *step, const float *o,
                                  const float *r, int a) {
    float plane = g.lo[a] + (float)(cell[a] + (step[a] > 0)) * g.cell[a];
    return (plane - o[a]) * r[a];
}

/* grid_walk_setup + walk + grid_walk_step of grid.c, closest hit. */
__global__ static void intersect_kernel(dev_grid g, rp_cuda_ray *rays, size_t n) {
    size_t id = (size_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (id >= n) return;
    rp_cuda_ray ray = rays[id];
    if (!(ray.tnear <= ray.tfar)) return;
    float o[3] = {ray.org[0], ray.org[1], ray.org[2]}, d[3] = {ray.dir[0], ray.dir[1], ray.dir[2]}, r[3];
    int step[3], cell[3];
    float t0 = ray.tnear, t1 = ray.tfar;
    for (int a = 0; a < 3; a++) {
        float dd = fabsf(d[a]) < 1e-18f ? copysignf(1e-18f, d[a]) : d[a];
        r[a] = 1.0f / dd;
        float tn = (g.lo[a] - o[a]) * r[a], tf = (g.hi[a] - o[a]) * r[a];
        if (tn > tf) {
            float s = tn;
            tn = tf, tf = s;
        }
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
        step[a] = r[a] >= 0.0f ? 1 : -1;
    }
    if (!(t0 <= t1)) return;
    float t_end = t1;
    for (int a = 0; a < 3; a++) {
        float p = o[a] + d[a] * t0;
        float c = floorf((p - g.lo[a]) * g.inv_cell[a]);
        cell[a] = !(c >= 0.0f) ? 0 : (c > (float)(g.res[a] - 1) ? g.res[a] - 1 : (int)c);
    }
    const wt_ray wr = wt_setup(make_float3(o[0], o[1], o[2]), make_float3(d[0], d[1], d[2]));
    uint32_t mb[MAILBOX];
    for (int i = 0; i < MAILBOX; i++) mb[i] = 0xFFFFFFFFu;
    float ht = ray.tfar, hu = 0.0f, hv = 0.0f;
    uint32_t htri = 0xFFFFFFFFu, hgeom = 0xFFFFFFFFu, hprim = 0xFFFFFFFFu;
    for (;;) {
        uint32_t c = ((uint32_t)cell[2] * (uint32_t)g.res[1] + (uint32_t)cell[1]) * (uint32_t)g.res[0] + (uint32_t)cell[0];
        for (uint32_t k = g.offsets[c]; k < g.offsets[c + 1]; k++) {
            uint32_t i = g.items[k];
            if (mb[i % MAILBOX] == i) continue;
            mb[i % MAILBOX] = i;
            const float *tr = g.tris + 16 * (size_t)i;
            uint32_t geom = __float_as_uint(tr[9]), prim = __float_as_uint(tr[10]), mask = __float_as_uint(tr[11]);
            if (!(mask & ray.mask)) continue;
            float t, u, v;
            if (!wt_test(wr, ray.tnear, ht, make_float3(tr[0], tr[1], tr[2]), make_float3(tr[3], tr[4], tr[5]),
                         make_float3(tr[6], tr[7], tr[8]), &t, &u, &v))
                continue;
            if (t < ht || htri == 0xFFFFFFFFu || geom < hgeom || (geom == hgeom && prim < hprim))
                ht = t, hu = u, hv = v, htri = i, hgeom = geom, hprim = prim;
        }
        float tx = axis_exit(g, cell, step, o, r, 0), ty = axis_exit(g, cell, step, o, r, 1),
              tz = axis_exit(g, cell, step, o, r, 2);
        int a = tx <= ty ? (tx <= tz ? 0 : 2) : (ty <= tz ? 1 : 2);
        float t = a == 0 ? tx : (a == 1 ? ty : tz);
        float end = ht < t_end ? ht : t_end;
        if (!(t < end)) break;
        cell[a] += step[a];
        if (cell[a] < 0 || cell[a] >= g.res[a]) break;
    }
    if (htri == 0xFFFFFFFFu) return;
    const float *tr = g.tris + 16 * (size_t)htri;
    float3 ng = wt_normal(make_float3(tr[0], tr[1], tr[2]), make_float3(tr[3], tr[4], tr[5]),
                          make_float3(tr[6], tr[7], tr[8]));
    ray.tfar = ht, ray.u = hu, ray.v = hv, ray.geom = hgeom, ray.prim = hprim;
    ray.ng[0] = ng.x, ray.ng[1] = ng.y, ray.ng[2] = ng.z;
    rays[id] = ray;
}

static int fail(char *err, size_t size, const char *what, cudaError_t e) {
    if (err && size) snprintf(err, size, "cuda: %s: %s", what, cudaGetErrorString(e));
    return 0;
}

extern "C" int rp_cuda_device_count(void) {
    int n = 0;
    if (cudaGetDeviceCount(&n) != cudaSuccess) return 0;
    return n;
}

extern "C" void rp_cuda_grid_free(rp_cuda_grid *g) {
    if (!g) return;
    cudaFree(g->d_offsets);
    cudaFree(g->d_items);
    cudaFree(g->d_tris);
    free(g);
}

extern "C" rp_cuda_grid *rp_cuda_grid_upload(const rp_cuda_grid_src *src, char *err, size_t err_size) {
    rp_cuda_grid *g = (rp_cuda_grid *)calloc(1, sizeof(rp_cuda_grid));
    if (!g) {
        fail(err, err_size, "upload", cudaErrorMemoryAllocation);
        return NULL;
    }
    g->g = *src;
    size_t ob = ((size_t)src->voxel_count + 1) * 4, ib = (src->item_count ? src->item_count : 1) * 4,
           tb = (size_t)(src->tri_count ? src->tri_count : 1) * 64;
    cudaError_t e;
    if ((e = cudaMalloc(&g->d_offsets, ob)) != cudaSuccess || (e = cudaMalloc(&g->d_items, ib)) != cudaSuccess ||
        (e = cudaMalloc(&g->d_tris, tb)) != cudaSuccess ||
        (e = cudaMemcpy(g->d_offsets, src->offsets, ob, cudaMemcpyHostToDevice)) != cudaSuccess ||
        (src->item_count && (e = cudaMemcpy(g->d_items, src->items, ib, cudaMemcpyHostToDevice)) != cudaSuccess) ||
        (src->tri_count && (e = cudaMemcpy(g->d_tris, src->tris, tb, cudaMemcpyHostToDevice)) != cudaSuccess)) {
        fail(err, err_size, "upload", e);
        rp_cuda_grid_free(g);
        return NULL;
    }
    return g;
}

extern "C" int rp_cuda_grid_intersect(rp_cuda_grid *g, rp_cuda_ray *rays, size_t n, float *kernel_ms, char *err,
                                      size_t err_size) {
    if (n == 0) return 1;
    rp_cuda_ray *d = NULL;
    cudaError_t e;
    if ((e = cudaMalloc(&d, n * sizeof(rp_cuda_ray))) != cudaSuccess) return fail(err, err_size, "rays", e);
    if ((e = cudaMemcpy(d, rays, n * sizeof(rp_cuda_ray), cudaMemcpyHostToDevice)) != cudaSuccess) {
        cudaFree(d);
        return fail(err, err_size, "copy rays", e);
    }
    dev_grid dg;
    for (int a = 0; a < 3; a++) {
        dg.lo[a] = g->g.lo[a], dg.hi[a] = g->g.hi[a], dg.cell[a] = g->g.cell[a], dg.inv_cell[a] = g->g.inv_cell[a];
        dg.res[a] = g->g.res[a];
    }
    dg.offsets = g->d_offsets, dg.items = g->d_items, dg.tris = g->d_tris;
    cudaEvent_t a, b;
    cudaEventCreate(&a);
    cudaEventCreate(&b);
    cudaEventRecord(a);
    unsigned blocks = (unsigned)((n + 127) / 128);
    intersect_kernel<<<blocks, 128>>>(dg, d, n);
    cudaEventRecord(b);
    e = cudaEventSynchronize(b);
    if (e == cudaSuccess) e = cudaGetLastError();
    float ms = 0.0f;
    cudaEventElapsedTime(&ms, a, b);
    if (kernel_ms) *kernel_ms = ms;
    cudaEventDestroy(a);
    cudaEventDestroy(b);
    if (e == cudaSuccess) e = cudaMemcpy(rays, d, n * sizeof(rp_cuda_ray), cudaMemcpyDeviceToHost);
    cudaFree(d);
    if (e != cudaSuccess) return fail(err, err_size, "intersect", e);
    return 1;
}
