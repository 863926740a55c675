/* BVH traversal on the GPU (see cuda_bvh.h). The kernels are Aila and Laine's while-while loop
 * (2009): a thread walks inner nodes until it reaches a leaf, then tests the leaf's triangles,
 * with a per-thread stack of far children. Box tests are the CPU's (traverse/trav1.inc): the far
 * distance widened by 1 + 2 gamma(3) and limited by the closest hit times CULL_SLACK, so no box a
 * ray touches is culled; the triangle test and the tie-break are the CPU's (cuda_tri.cuh). */
#include <cuda_runtime.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cuda_bvh.h"
#include "cuda_tri.cuh"

#define ROBUST_FAR 1.00000036f
#define CULL_SLACK 1.000244140625f
#define NO_ID 0xFFFFFFFFu
#define BLOCK 128

struct rp_cuda_bvh {
    float4 *nodes, *tris;
    uint32_t node_count, tri_count;
    size_t bytes;
};

struct rp_cuda_batch {
    rp_cuda_bvh_ray *rays;
    rp_cuda_bvh_hit *hits;
    size_t n, cap;          /* rays now, room for */
    unsigned *counter;
};

static int fail(char *err, size_t size, const char *what, cudaError_t e) {
    if (err && size) snprintf(err, size, "cuda: %s: %s", what, cudaGetErrorString(e));
    return 0;
}

/* ---- traversal ------------------------------------------------------------------------------ */

/* The traversal is host code too (rp_cuda_bvh_trace_emulated): read-only loads through the
 * texture path on the device, plain loads on the host. */
#ifdef __CUDA_ARCH__
#define LDG(p) __ldg(p)
__device__ __forceinline__ uint32_t as_u32(float f) { return __float_as_uint(f); }
#else
#define LDG(p) (*(p))
static inline uint32_t as_u32(float f) {
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}
#endif

struct hit_state {
    float t, u, v;
    uint32_t geom, prim, tri;
};

/* ray_usable of core/core.h: every other ray is a miss. */
__host__ __device__ __forceinline__ bool usable(float3 o, float3 d, float tn, float tf) {
    float f = (o.x - o.x) + (o.y - o.y) + (o.z - o.z) + (d.x - d.x) + (d.y - d.y) + (d.z - d.z);
    return f == 0.0f && (d.x != 0.0f || d.y != 0.0f || d.z != 0.0f) && tn <= tf && tn < INFINITY;
}

/* 1 / d with tiny components replaced (wt_rcp of traverse/wt.h). */
__host__ __device__ __forceinline__ float safe_rcp(float d) { return 1.0f / (fabsf(d) < 1e-18f ? copysignf(1e-18f, d) : d); }

/* Entry distance of the box (near and far planes chosen by the ray's signs); hit when tn <= tf. */
__host__ __device__ __forceinline__ bool slab(float nx, float fx, float ny, float fy, float nz, float fz, float3 o, float3 r,
                                     float tnear, float limit, float *entry) {
    float tnx = (nx - o.x) * r.x, tfx = (fx - o.x) * r.x;
    float tny = (ny - o.y) * r.y, tfy = (fy - o.y) * r.y;
    float tnz = (nz - o.z) * r.z, tfz = (fz - o.z) * r.z;
    float tn = fmaxf(fmaxf(tnx, tny), fmaxf(tnz, tnear));
    float tf = fminf(fminf(tfx, tfy), tfz) * ROBUST_FAR;
    tf = fminf(tf, limit);
    *entry = tn;
    return tn <= tf;
}

/* Triangles [first, first + count): closest hit, or with ANY true at the first hit. */
template <bool ANY>
__host__ __device__ __forceinline__ bool leaf_test(const float4 *__restrict__ tris, const wt_ray &wr, float tnear,
                                                   uint32_t ref, hit_state &h) {
    uint32_t first = (ref & ~RP_CUDA_LEAF) >> RP_CUDA_COUNT_BITS, count = ref & RP_CUDA_MAX_LEAF;
    for (uint32_t i = first; i < first + count; i++) {
        const float4 *t4 = tris + 3 * (size_t)i;
        float4 v0 = LDG(t4), v1 = LDG(t4 + 1), v2 = LDG(t4 + 2);
        float t, u, v;
        if (!wt_test(wr, tnear, h.t, make_float3(v0.x, v0.y, v0.z), make_float3(v1.x, v1.y, v1.z),
                     make_float3(v2.x, v2.y, v2.z), &t, &u, &v))
            continue;
        /* rays carry every mask bit and the converter left out mask-0 triangles, so the CPU's mask
         * test always passes here */
        uint32_t geom = as_u32(v0.w), prim = as_u32(v1.w);
        if (ANY) {
            h.t = t, h.geom = geom, h.prim = prim, h.tri = i;
            return true;
        }
        if (t < h.t || h.tri == NO_ID || wt_key_less(geom, prim, h.geom, h.prim))
            h.t = t, h.u = u, h.v = v, h.geom = geom, h.prim = prim, h.tri = i;
    }
    return false;
}

/* True when some active lane of the warp still has no postponed leaf (on the host: this ray). */
__host__ __device__ __forceinline__ bool warp_any(bool c) {
#ifdef __CUDA_ARCH__
    return __any_sync(__activemask(), c);
#else
    return c;
#endif
}

#define DONE 0x7FFFFFFFu /* the stack's bottom: never a node index (the converter's counts are below) */

/* Closest hit (ANY false) or any hit (true: returns at the first) of one ray. With SPEC, the first
 * leaf a thread reaches is postponed and the thread walks on until every thread of its warp holds
 * one, so the warp tests leaves together (Aila and Laine 2009, sec. 4, speculative traversal). */
template <bool ANY, bool SPEC>
__host__ __device__ __forceinline__ bool trace_ray(const float4 *__restrict__ nodes, const float4 *__restrict__ tris,
                                                   float3 o, float3 d, float tnear, float tfar, hit_state &h) {
    h.t = tfar, h.geom = h.prim = h.tri = NO_ID, h.u = h.v = 0.0f;
    if (!usable(o, d, tnear, tfar)) return false;
    const float3 r = make_float3(safe_rcp(d.x), safe_rcp(d.y), safe_rcp(d.z));
    const bool px = r.x >= 0.0f, py = r.y >= 0.0f, pz = r.z >= 0.0f;
    const wt_ray wr = wt_setup(o, d);
    uint32_t stack[RP_CUDA_STACK + 1];
    stack[0] = DONE;
    int sp = 1;
    uint32_t node = 0, leaf = 0; /* leaf 0: none postponed (a leaf reference has the top bit set) */
    while (node != DONE) {
        while (node != DONE && !(node & RP_CUDA_LEAF)) {
            const float4 *n = nodes + 4 * (size_t)node;
            float4 a = LDG(n), b = LDG(n + 1), c = LDG(n + 2), e = LDG(n + 3);
            float limit = h.t * CULL_SLACK, tl, tr;
            bool hl = slab(px ? a.x : a.y, px ? a.y : a.x, py ? a.z : a.w, py ? a.w : a.z, pz ? c.x : c.y,
                           pz ? c.y : c.x, o, r, tnear, limit, &tl);
            bool hr = slab(px ? b.x : b.y, px ? b.y : b.x, py ? b.z : b.w, py ? b.w : b.z, pz ? c.z : c.w,
                           pz ? c.w : c.z, o, r, tnear, limit, &tr);
            uint32_t cl = as_u32(e.x), cr = as_u32(e.y);
            if (hl && hr) {
                bool swap = tr < tl;
                node = swap ? cr : cl;
                stack[sp++] = swap ? cl : cr;
            } else if (hl || hr) {
                node = hl ? cl : cr;
            } else {
                node = stack[--sp];
            }
            if (SPEC) {
                if ((node & RP_CUDA_LEAF) && node != DONE && leaf == 0) leaf = node, node = stack[--sp];
                if (!warp_any(leaf == 0)) break;
            }
        }
        if (SPEC) {
            /* the postponed leaf, then any leaves reached since */
            while (leaf) {
                if (leaf_test<ANY>(tris, wr, tnear, leaf, h)) return true;
                leaf = 0;
                if (node != DONE && (node & RP_CUDA_LEAF)) leaf = node, node = stack[--sp];
            }
        } else if (node != DONE) {
            if (leaf_test<ANY>(tris, wr, tnear, node, h)) return true;
            node = stack[--sp];
        }
    }
    return h.tri != NO_ID;
}

__host__ __device__ __forceinline__ void write_hit(const float4 *__restrict__ tris, const hit_state &h, bool any, float tfar,
                                          rp_cuda_bvh_hit *out) {
    rp_cuda_bvh_hit o;
    o.u = o.v = 0.0f, o.ng[0] = o.ng[1] = o.ng[2] = 0.0f;
    o.geom = o.prim = NO_ID;
    o.t = tfar;
    if (h.tri != NO_ID) {
        if (any) {
            o.t = -INFINITY;
        } else {
            const float4 *t4 = tris + 3 * (size_t)h.tri;
            float4 v0 = LDG(t4), v1 = LDG(t4 + 1), v2 = LDG(t4 + 2);
            float3 ng = wt_normal(make_float3(v0.x, v0.y, v0.z), make_float3(v1.x, v1.y, v1.z),
                                  make_float3(v2.x, v2.y, v2.z));
            o.t = h.t, o.u = h.u, o.v = h.v, o.geom = h.geom, o.prim = h.prim;
            o.ng[0] = ng.x, o.ng[1] = ng.y, o.ng[2] = ng.z;
        }
    }
    *out = o;
}

__device__ __forceinline__ void trace_one(const float4 *nodes, const float4 *tris, const rp_cuda_bvh_ray *rays,
                                          rp_cuda_bvh_hit *hits, size_t id, bool any, bool spec) {
    const float4 *rr = reinterpret_cast<const float4 *>(rays + id);
    float4 a = LDG(rr), b = LDG(rr + 1);
    hit_state h;
    float3 o = make_float3(a.x, a.y, a.z), d = make_float3(b.x, b.y, b.z);
    if (any)
        spec ? trace_ray<true, true>(nodes, tris, o, d, a.w, b.w, h) : trace_ray<true, false>(nodes, tris, o, d, a.w, b.w, h);
    else
        spec ? trace_ray<false, true>(nodes, tris, o, d, a.w, b.w, h) : trace_ray<false, false>(nodes, tris, o, d, a.w, b.w, h);
    write_hit(tris, h, any, b.w, hits + id);
}

__global__ void __launch_bounds__(BLOCK) simple_kernel(const float4 *nodes, const float4 *tris,
                                                       const rp_cuda_bvh_ray *rays, rp_cuda_bvh_hit *hits,
                                                       size_t n, bool any, bool spec) {
    size_t id = (size_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (id < n) trace_one(nodes, tris, rays, hits, id, any, spec);
}

/* Persistent warps (Aila and Laine 2009, sec. 3): as many threads as the GPU keeps resident, each
 * warp taking the next 32 rays from a global counter when all of its rays are done, so long rays
 * do not leave launch-time blocks idle. */
__global__ void __launch_bounds__(BLOCK) persistent_kernel(const float4 *nodes, const float4 *tris,
                                                           const rp_cuda_bvh_ray *rays, rp_cuda_bvh_hit *hits,
                                                           size_t n, bool any, unsigned *counter) {
    const unsigned lane = threadIdx.x & 31u;
    for (;;) {
        unsigned base = 0;
        if (lane == 0) base = atomicAdd(counter, 32u);
        base = __shfl_sync(0xFFFFFFFFu, base, 0);
        if ((size_t)base >= n) return;
        size_t id = (size_t)base + lane;
        if (id < n) trace_one(nodes, tris, rays, hits, id, any, false);
        __syncwarp();
    }
}

/* ---- the frame pipeline: eye rays, their hits, a diffuse bounce and its hit --------------------- */

struct dev_view {
    float3 eye, f, r, u;
    float tan_half, aspect;
    int w, h;
    uint32_t seed;
};

/* Primary ray of pixel (x, y): DESIGN.md's camera contract. */
__device__ __forceinline__ rp_cuda_bvh_ray eye_ray(const dev_view &v, int x, int y) {
    float sx = (2.0f * ((float)x + 0.5f) / (float)v.w - 1.0f) * v.tan_half * v.aspect;
    float sy = (1.0f - 2.0f * ((float)y + 0.5f) / (float)v.h) * v.tan_half;
    float3 d = make_float3(v.f.x + sx * v.r.x + sy * v.u.x, v.f.y + sx * v.r.y + sy * v.u.y,
                           v.f.z + sx * v.r.z + sy * v.u.z);
    float il = 1.0f / sqrtf(d.x * d.x + d.y * d.y + d.z * d.z);
    rp_cuda_bvh_ray ray;
    ray.org[0] = v.eye.x, ray.org[1] = v.eye.y, ray.org[2] = v.eye.z, ray.tnear = 0.0f;
    ray.dir[0] = d.x * il, ray.dir[1] = d.y * il, ray.dir[2] = d.z * il, ray.tfar = INFINITY;
    return ray;
}

/* A uniform float in [0, 1) from (pixel, dimension, seed): PCG's output hash of a mixed key. */
__device__ __forceinline__ float rand01(uint32_t pixel, uint32_t dim, uint32_t seed) {
    uint32_t s = pixel * 0x9E3779B9u ^ (dim + 1u) * 0x85EBCA6Bu ^ seed * 0xC2B2AE35u;
    s = s * 747796405u + 2891336453u;
    uint32_t w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    w = (w >> 22u) ^ w;
    return (float)(w >> 8) * (1.0f / 16777216.0f);
}

/* The bounce of a primary hit: from the hit point, nudged off the surface on the ray's side, in a
 * cosine-distributed direction around the face normal turned towards the ray (Malley's method in
 * Duff et al. 2017's frame). A miss gives a ray with tfar = -1 (none). */
__device__ __forceinline__ rp_cuda_bvh_ray bounce_ray(const rp_cuda_bvh_ray &p, const rp_cuda_bvh_hit &h,
                                                      uint32_t pixel, uint32_t seed) {
    rp_cuda_bvh_ray b;
    b.org[0] = b.org[1] = b.org[2] = 0.0f, b.dir[0] = 0.0f, b.dir[1] = 0.0f, b.dir[2] = 1.0f;
    b.tnear = 0.0f, b.tfar = -1.0f;
    if (h.geom == NO_ID) return b;
    float3 n = make_float3(h.ng[0], h.ng[1], h.ng[2]);
    float len = sqrtf(n.x * n.x + n.y * n.y + n.z * n.z);
    if (!(len > 0.0f)) return b;
    float s = (n.x * p.dir[0] + n.y * p.dir[1] + n.z * p.dir[2]) > 0.0f ? -1.0f / len : 1.0f / len;
    n = make_float3(n.x * s, n.y * s, n.z * s);
    float3 hp = make_float3(p.org[0] + h.t * p.dir[0], p.org[1] + h.t * p.dir[1], p.org[2] + h.t * p.dir[2]);
    float scale = fmaxf(fmaxf(fabsf(hp.x), fabsf(hp.y)), fmaxf(fabsf(hp.z), 1.0f)) * 1e-4f;
    float u1 = rand01(pixel, 0, seed), u2 = rand01(pixel, 1, seed);
    float rad = sqrtf(u1), phi = 6.28318530717959f * u2;
    float lx = rad * cosf(phi), ly = rad * sinf(phi), lz = sqrtf(fmaxf(0.0f, 1.0f - u1));
    float sign = copysignf(1.0f, n.z);
    float a = -1.0f / (sign + n.z), bb = n.x * n.y * a;
    float3 t1 = make_float3(1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x);
    float3 t2 = make_float3(bb, sign + n.y * n.y * a, -n.y);
    float3 d = make_float3(lx * t1.x + ly * t2.x + lz * n.x, lx * t1.y + ly * t2.y + lz * n.y,
                           lx * t1.z + ly * t2.z + lz * n.z);
    float il = 1.0f / sqrtf(d.x * d.x + d.y * d.y + d.z * d.z);
    b.org[0] = hp.x + n.x * scale, b.org[1] = hp.y + n.y * scale, b.org[2] = hp.z + n.z * scale;
    b.dir[0] = d.x * il, b.dir[1] = d.y * il, b.dir[2] = d.z * il;
    b.tfar = INFINITY;
    return b;
}

__device__ __forceinline__ rp_cuda_bvh_hit closest(const float4 *nodes, const float4 *tris, const rp_cuda_bvh_ray &ray) {
    hit_state h;
    trace_ray<false, false>(nodes, tris, make_float3(ray.org[0], ray.org[1], ray.org[2]),
                            make_float3(ray.dir[0], ray.dir[1], ray.dir[2]), ray.tnear, ray.tfar, h);
    rp_cuda_bvh_hit out;
    write_hit(tris, h, false, ray.tfar, &out);
    return out;
}

/* Pixels are taken in 8x4 tiles, one per warp, so a warp's eye rays are neighbours. */
__device__ __forceinline__ bool tile_pixel(const dev_view &v, size_t id, int *x, int *y, uint32_t *pixel) {
    int tiles_x = (v.w + 7) / 8;
    size_t tile = id / 32;
    int in = (int)(id % 32);
    *x = (int)(tile % (size_t)tiles_x) * 8 + in % 8;
    *y = (int)(tile / (size_t)tiles_x) * 4 + in / 8;
    *pixel = (uint32_t)*y * (uint32_t)v.w + (uint32_t)*x;
    return *x < v.w && *y < v.h;
}

/* One atomic per warp for the lanes of a full warp that pass (the callers never return early, so
 * every lane takes part). */
__device__ __forceinline__ unsigned warp_append(bool live, unsigned *count) {
    unsigned m = __ballot_sync(0xFFFFFFFFu, live);
    unsigned lane = threadIdx.x & 31u, base = 0;
    if (lane == 0 && m) base = atomicAdd(count, (unsigned)__popc(m));
    base = __shfl_sync(0xFFFFFFFFu, base, 0);
    return base + (unsigned)__popc(m & ((1u << lane) - 1u));
}

__device__ __forceinline__ rp_cuda_bvh_hit no_hit(void) {
    rp_cuda_bvh_hit h;
    h.t = -1.0f, h.u = h.v = 0.0f, h.geom = h.prim = NO_ID, h.ng[0] = h.ng[1] = h.ng[2] = 0.0f;
    return h;
}

/* The megakernel: one thread follows a pixel through both rays. */
__global__ void __launch_bounds__(BLOCK) mega_kernel(const float4 *nodes, const float4 *tris, dev_view v,
                                                     rp_cuda_bvh_ray *prays, rp_cuda_bvh_hit *phits,
                                                     rp_cuda_bvh_ray *brays, rp_cuda_bvh_hit *bhits, size_t slots,
                                                     unsigned *bounces) {
    size_t id = (size_t)blockIdx.x * blockDim.x + threadIdx.x;
    int x = 0, y = 0;
    uint32_t pixel = 0;
    bool in = id < slots && tile_pixel(v, id, &x, &y, &pixel), live = false;
    if (in) {
        rp_cuda_bvh_ray p = eye_ray(v, x, y);
        rp_cuda_bvh_hit ph = closest(nodes, tris, p);
        rp_cuda_bvh_ray b = bounce_ray(p, ph, pixel, v.seed);
        live = b.tfar >= 0.0f;
        rp_cuda_bvh_hit bh = live ? closest(nodes, tris, b) : no_hit();
        prays[pixel] = p, phits[pixel] = ph, brays[pixel] = b, bhits[pixel] = bh;
    }
    warp_append(live, bounces);
}

/* Wavefront stage 1: eye rays into a stream (pixel order of the tiles). */
__global__ void __launch_bounds__(BLOCK) gen_kernel(dev_view v, rp_cuda_bvh_ray *prays, size_t slots) {
    size_t id = (size_t)blockIdx.x * blockDim.x + threadIdx.x;
    int x, y;
    uint32_t pixel;
    if (id >= slots || !tile_pixel(v, id, &x, &y, &pixel)) return;
    prays[pixel] = eye_ray(v, x, y);
}

/* Stage 2 traces a stream in stream order; `order` maps a stream slot to its pixel (NULL: the
 * identity), so the primary pass reads its rays in the tiles' order. */
__global__ void __launch_bounds__(BLOCK) trace_stream_kernel(const float4 *nodes, const float4 *tris, dev_view v,
                                                             const rp_cuda_bvh_ray *rays, rp_cuda_bvh_hit *hits,
                                                             const uint32_t *queue, const unsigned *count,
                                                             size_t slots) {
    size_t id = (size_t)blockIdx.x * blockDim.x + threadIdx.x;
    uint32_t pixel;
    if (queue) {
        if (id >= *count) return;
        pixel = queue[id];
    } else {
        int x, y;
        if (id >= slots || !tile_pixel(v, id, &x, &y, &pixel)) return;
    }
    hits[pixel] = closest(nodes, tris, rays[pixel]);
}

/* Stage 3: a bounce ray per primary hit, appended to a compacted queue of live pixels (warp-
 * aggregated: one atomic per warp). */
__global__ void __launch_bounds__(BLOCK) bounce_kernel(dev_view v, const rp_cuda_bvh_ray *prays,
                                                       const rp_cuda_bvh_hit *phits, rp_cuda_bvh_ray *brays,
                                                       rp_cuda_bvh_hit *bhits, uint32_t *queue, unsigned *count,
                                                       size_t slots) {
    size_t id = (size_t)blockIdx.x * blockDim.x + threadIdx.x;
    int x = 0, y = 0;
    uint32_t pixel = 0;
    bool in = id < slots && tile_pixel(v, id, &x, &y, &pixel);
    bool live = false;
    if (in) {
        rp_cuda_bvh_ray b = bounce_ray(prays[pixel], phits[pixel], pixel, v.seed);
        brays[pixel] = b;
        live = b.tfar >= 0.0f;
        if (!live) bhits[pixel] = no_hit();
    }
    unsigned slot = warp_append(live, count);
    if (live) queue[slot] = pixel;
}

/* ---- host side ------------------------------------------------------------------------------ */

extern "C" void rp_cuda_bvh_trace_emulated(const rp_cuda_bvh_src *src, const rp_cuda_bvh_ray *rays, size_t n,
                                           bool occlusion, rp_cuda_bvh_hit *hits) {
    const float4 *nodes = reinterpret_cast<const float4 *>(src->nodes), *tris = reinterpret_cast<const float4 *>(src->tris);
    for (size_t i = 0; i < n; i++) {
        const rp_cuda_bvh_ray &r = rays[i];
        float3 o = make_float3(r.org[0], r.org[1], r.org[2]), d = make_float3(r.dir[0], r.dir[1], r.dir[2]);
        hit_state h;
        /* speculative: one lane of a warp here, so the same walk with the leaf postponing logic */
        if (occlusion)
            trace_ray<true, true>(nodes, tris, o, d, r.tnear, r.tfar, h);
        else
            trace_ray<false, true>(nodes, tris, o, d, r.tnear, r.tfar, h);
        write_hit(tris, h, occlusion, r.tfar, &hits[i]);
    }
}

extern "C" const char *rp_cuda_kernel_name(rp_cuda_kernel k) {
    switch (k) {
    case RP_CUDA_KERNEL_SIMPLE: return "simple";
    case RP_CUDA_KERNEL_PERSISTENT: return "persistent";
    case RP_CUDA_KERNEL_SPECULATIVE: return "speculative";
    case RP_CUDA_KERNEL_COUNT: break;
    }
    return "?";
}

extern "C" int rp_cuda_device_info(char *out, size_t out_size) {
    cudaDeviceProp p;
    int n = 0;
    if (cudaGetDeviceCount(&n) != cudaSuccess || n == 0 || cudaGetDeviceProperties(&p, 0) != cudaSuccess) return 0;
    snprintf(out, out_size, "%s, %d multiprocessors, %.1f GiB, compute capability %d.%d", p.name,
             p.multiProcessorCount, (double)p.totalGlobalMem / (1024.0 * 1024.0 * 1024.0), p.major, p.minor);
    return 1;
}

extern "C" void rp_cuda_bvh_free(rp_cuda_bvh *b) {
    if (!b) return;
    cudaFree(b->nodes);
    cudaFree(b->tris);
    free(b);
}

extern "C" size_t rp_cuda_bvh_bytes(const rp_cuda_bvh *b) { return b ? b->bytes : 0; }

extern "C" rp_cuda_bvh *rp_cuda_bvh_upload(const rp_cuda_bvh_src *src, char *err, size_t err_size) {
    rp_cuda_bvh *b = (rp_cuda_bvh *)calloc(1, sizeof(rp_cuda_bvh));
    if (!b) {
        fail(err, err_size, "BVH upload", cudaErrorMemoryAllocation);
        return NULL;
    }
    b->node_count = src->node_count, b->tri_count = src->tri_count;
    size_t nb = (size_t)src->node_count * 64, tb = (size_t)(src->tri_count ? src->tri_count : 1) * 48;
    b->bytes = nb + tb;
    cudaError_t e;
    if ((e = cudaMalloc(&b->nodes, nb)) != cudaSuccess || (e = cudaMalloc(&b->tris, tb)) != cudaSuccess ||
        (e = cudaMemcpy(b->nodes, src->nodes, nb, cudaMemcpyHostToDevice)) != cudaSuccess ||
        (src->tri_count && (e = cudaMemcpy(b->tris, src->tris, tb, cudaMemcpyHostToDevice)) != cudaSuccess)) {
        fail(err, err_size, "BVH upload", e);
        rp_cuda_bvh_free(b);
        return NULL;
    }
    return b;
}

extern "C" void rp_cuda_batch_free(rp_cuda_batch *q) {
    if (!q) return;
    cudaFree(q->rays);
    cudaFree(q->hits);
    cudaFree(q->counter);
    free(q);
}

extern "C" rp_cuda_batch *rp_cuda_batch_new(const rp_cuda_bvh_ray *rays, size_t n, char *err, size_t err_size) {
    rp_cuda_batch *q = (rp_cuda_batch *)calloc(1, sizeof(rp_cuda_batch));
    if (!q) {
        fail(err, err_size, "ray upload", cudaErrorMemoryAllocation);
        return NULL;
    }
    q->n = n;
    size_t m = n ? n : 1;
    q->cap = m;
    cudaError_t e;
    if ((e = cudaMalloc(&q->rays, m * sizeof *rays)) != cudaSuccess ||
        (e = cudaMalloc(&q->hits, m * sizeof(rp_cuda_bvh_hit))) != cudaSuccess ||
        (e = cudaMalloc(&q->counter, sizeof(unsigned))) != cudaSuccess ||
        (n && (e = cudaMemcpy(q->rays, rays, n * sizeof *rays, cudaMemcpyHostToDevice)) != cudaSuccess)) {
        fail(err, err_size, "ray upload", e);
        rp_cuda_batch_free(q);
        return NULL;
    }
    return q;
}

extern "C" void *rp_cuda_host_alloc(size_t bytes) {
    void *p = NULL;
    return cudaMallocHost(&p, bytes ? bytes : 1) == cudaSuccess ? p : NULL;
}

extern "C" void rp_cuda_host_free(void *p) {
    if (p) cudaFreeHost(p);
}

extern "C" int rp_cuda_batch_set(rp_cuda_batch *q, const rp_cuda_bvh_ray *rays, size_t n, char *err,
                                  size_t err_size) {
    cudaError_t e = cudaSuccess;
    if (n > q->cap) {
        cudaFree(q->rays);
        cudaFree(q->hits);
        q->rays = NULL, q->hits = NULL, q->n = q->cap = 0;
        if ((e = cudaMalloc(&q->rays, n * sizeof *rays)) != cudaSuccess ||
            (e = cudaMalloc(&q->hits, n * sizeof(rp_cuda_bvh_hit))) != cudaSuccess)
            return fail(err, err_size, "ray upload", e);
        q->cap = n;
    }
    q->n = n;
    if (n && (e = cudaMemcpy(q->rays, rays, n * sizeof *rays, cudaMemcpyHostToDevice)) != cudaSuccess)
        return fail(err, err_size, "ray upload", e);
    return 1;
}

extern "C" int rp_cuda_batch_hits(const rp_cuda_batch *q, rp_cuda_bvh_hit *out, char *err, size_t err_size) {
    cudaError_t e = q->n ? cudaMemcpy(out, q->hits, q->n * sizeof *out, cudaMemcpyDeviceToHost) : cudaSuccess;
    return e == cudaSuccess ? 1 : fail(err, err_size, "hit download", e);
}

static unsigned blocks_for(size_t n) { return (unsigned)((n + BLOCK - 1) / BLOCK); }

extern "C" int rp_cuda_bvh_trace(const rp_cuda_bvh *b, rp_cuda_batch *q, rp_cuda_kernel kernel, bool occlusion,
                                 float *ms, char *err, size_t err_size) {
    if (q->n == 0) return 1;
    cudaEvent_t e0, e1;
    cudaEventCreate(&e0);
    cudaEventCreate(&e1);
    cudaError_t e = cudaSuccess;
    unsigned resident = 0;
    if (kernel == RP_CUDA_KERNEL_PERSISTENT) {
        int per_sm = 0, sms = 0;
        cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_sm, persistent_kernel, BLOCK, 0);
        cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, 0);
        resident = (unsigned)(per_sm > 0 ? per_sm : 1) * (unsigned)(sms > 0 ? sms : 1);
        e = cudaMemset(q->counter, 0, sizeof(unsigned));
    }
    cudaEventRecord(e0);
    if (kernel == RP_CUDA_KERNEL_PERSISTENT)
        persistent_kernel<<<resident, BLOCK>>>(b->nodes, b->tris, q->rays, q->hits, q->n, occlusion, q->counter);
    else
        simple_kernel<<<blocks_for(q->n), BLOCK>>>(b->nodes, b->tris, q->rays, q->hits, q->n, occlusion,
                                                   kernel == RP_CUDA_KERNEL_SPECULATIVE);
    cudaEventRecord(e1);
    if (e == cudaSuccess) e = cudaEventSynchronize(e1);
    if (e == cudaSuccess) e = cudaGetLastError();
    float t = 0.0f;
    cudaEventElapsedTime(&t, e0, e1);
    if (ms) *ms = t;
    cudaEventDestroy(e0);
    cudaEventDestroy(e1);
    return e == cudaSuccess ? 1 : fail(err, err_size, "trace", e);
}

static dev_view make_view(const rp_cuda_view *v) {
    dev_view d;
    float3 eye = make_float3(v->eye[0], v->eye[1], v->eye[2]);
    float3 f = make_float3(v->look[0] - eye.x, v->look[1] - eye.y, v->look[2] - eye.z);
    float fl = sqrtf(f.x * f.x + f.y * f.y + f.z * f.z);
    f = make_float3(f.x / fl, f.y / fl, f.z / fl);
    float3 up = make_float3(v->up[0], v->up[1], v->up[2]);
    float3 r = make_float3(f.y * up.z - f.z * up.y, f.z * up.x - f.x * up.z, f.x * up.y - f.y * up.x);
    float rl = sqrtf(r.x * r.x + r.y * r.y + r.z * r.z);
    r = make_float3(r.x / rl, r.y / rl, r.z / rl);
    d.eye = eye, d.f = f, d.r = r;
    d.u = make_float3(r.y * f.z - r.z * f.y, r.z * f.x - r.x * f.z, r.x * f.y - r.y * f.x);
    d.tan_half = tanf(v->fov_deg * 0.5f * 3.14159265358979f / 180.0f);
    d.aspect = (float)v->width / (float)v->height;
    d.w = v->width, d.h = v->height, d.seed = v->seed;
    return d;
}

extern "C" int rp_cuda_bvh_frame(const rp_cuda_bvh *b, const rp_cuda_view *view, bool wavefront, rp_cuda_frame *out,
                                 char *err, size_t err_size) {
    if (view->width <= 0 || view->height <= 0) {
        if (err && err_size) snprintf(err, err_size, "cuda: bad view size %dx%d", view->width, view->height);
        return 0;
    }
    dev_view v = make_view(view);
    size_t pixels = (size_t)view->width * (size_t)view->height;
    size_t slots = (size_t)((view->width + 7) / 8) * 8 * (size_t)((view->height + 3) / 4) * 4;
    rp_cuda_bvh_ray *prays = NULL, *brays = NULL;
    rp_cuda_bvh_hit *phits = NULL, *bhits = NULL;
    uint32_t *queue = NULL;
    unsigned *count = NULL;
    cudaEvent_t ev[4];
    for (int i = 0; i < 4; i++) cudaEventCreate(&ev[i]);
    cudaError_t e;
    if ((e = cudaMalloc(&prays, pixels * sizeof *prays)) == cudaSuccess &&
        (e = cudaMalloc(&brays, pixels * sizeof *brays)) == cudaSuccess &&
        (e = cudaMalloc(&phits, pixels * sizeof *phits)) == cudaSuccess &&
        (e = cudaMalloc(&bhits, pixels * sizeof *bhits)) == cudaSuccess &&
        (e = cudaMalloc(&queue, pixels * sizeof *queue)) == cudaSuccess &&
        (e = cudaMalloc(&count, sizeof *count)) == cudaSuccess &&
        (e = cudaMemset(count, 0, sizeof *count)) == cudaSuccess) {
        cudaEventRecord(ev[0]);
        if (wavefront) {
            gen_kernel<<<blocks_for(slots), BLOCK>>>(v, prays, slots);
            cudaEventRecord(ev[1]);
            trace_stream_kernel<<<blocks_for(slots), BLOCK>>>(b->nodes, b->tris, v, prays, phits, NULL, NULL, slots);
            cudaEventRecord(ev[2]);
            bounce_kernel<<<blocks_for(slots), BLOCK>>>(v, prays, phits, brays, bhits, queue, count, slots);
            cudaEventRecord(ev[3]);
            /* the queue's length stays on the device: the trace pass reads it, launched for every pixel */
            trace_stream_kernel<<<blocks_for(pixels), BLOCK>>>(b->nodes, b->tris, v, brays, bhits, queue, count, slots);
        } else {
            mega_kernel<<<blocks_for(slots), BLOCK>>>(b->nodes, b->tris, v, prays, phits, brays, bhits, slots, count);
        }
        cudaEvent_t end;
        cudaEventCreate(&end);
        cudaEventRecord(end);
        e = cudaEventSynchronize(end);
        if (e == cudaSuccess) e = cudaGetLastError();
        float t = 0.0f;
        cudaEventElapsedTime(&t, ev[0], end);
        out->total_ms = t;
        out->primary_ms = out->bounce_ms = 0.0f;
        if (wavefront) {
            cudaEventElapsedTime(&out->primary_ms, ev[1], ev[2]);
            cudaEventElapsedTime(&out->bounce_ms, ev[3], end);
        }
        cudaEventDestroy(end);
        unsigned c = 0;
        if (e == cudaSuccess) e = cudaMemcpy(&c, count, sizeof c, cudaMemcpyDeviceToHost);
        out->bounce_count = c;
        if (e == cudaSuccess && out->primary_rays)
            e = cudaMemcpy(out->primary_rays, prays, pixels * sizeof *prays, cudaMemcpyDeviceToHost);
        if (e == cudaSuccess && out->primary_hits)
            e = cudaMemcpy(out->primary_hits, phits, pixels * sizeof *phits, cudaMemcpyDeviceToHost);
        if (e == cudaSuccess && out->bounce_rays)
            e = cudaMemcpy(out->bounce_rays, brays, pixels * sizeof *brays, cudaMemcpyDeviceToHost);
        if (e == cudaSuccess && out->bounce_hits)
            e = cudaMemcpy(out->bounce_hits, bhits, pixels * sizeof *bhits, cudaMemcpyDeviceToHost);
    }
    for (int i = 0; i < 4; i++) cudaEventDestroy(ev[i]);
    cudaFree(prays), cudaFree(brays), cudaFree(phits), cudaFree(bhits), cudaFree(queue), cudaFree(count);
    return e == cudaSuccess ? 1 : fail(err, err_size, "frame", e);
}
