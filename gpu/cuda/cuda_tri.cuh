/* The watertight ray-triangle test of geometry/triangle.c (tri_intersect_ref, Woop, Benthin, Wald
 * 2013) as device code, shared by the CUDA grid and BVH kernels. Built with --fmad=false and IEEE
 * division (nvcc's default without --use_fast_math), every operation rounds as the CPU's in the
 * same order, so hits agree bit for bit. The per-ray part (dominant axis, shear) is split from the
 * per-triangle part so that a traversal computes it once per ray: the same divisions, the same
 * results. The functions are host code too, so the CPU can run the kernels' traversal
 * (rp_cuda_bvh_trace_emulated) where no GPU is. */
#ifndef RP_CUDA_TRI_CUH
#define RP_CUDA_TRI_CUH

#include <math.h>
#include <stdint.h>

/* A ray prepared for the test: kx, ky, kz the permuted axes, s the shear (tri_intersect_ref). */
struct wt_ray {
    float ox, oy, oz; /* the origin's components along kx, ky, kz */
    float sx, sy, sz;
    int kx, ky, kz;
};

/* Component k (0, 1, 2) of v, by selects rather than an indexed array (which would live in local
 * memory). */
__host__ __device__ __forceinline__ float wt_comp(float3 v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

__host__ __device__ __forceinline__ wt_ray wt_setup(float3 o, float3 d) {
    int kz = 0;
    float a = fabsf(d.x);
    if (fabsf(d.y) > a) kz = 1, a = fabsf(d.y);
    if (fabsf(d.z) > a) kz = 2;
    int kx = kz == 2 ? 0 : kz + 1, ky = kx == 2 ? 0 : kx + 1;
    float dz = wt_comp(d, kz);
    if (dz < 0.0f) {
        int s = kx;
        kx = ky, ky = s;
    }
    wt_ray r;
    r.kx = kx, r.ky = ky, r.kz = kz;
    r.sx = wt_comp(d, kx) / dz, r.sy = wt_comp(d, ky) / dz, r.sz = 1.0f / dz;
    r.ox = wt_comp(o, kx), r.oy = wt_comp(o, ky), r.oz = wt_comp(o, kz);
    return r;
}

/* tri_intersect_ref from its fourth line on: true on a hit with tnear <= t <= tfar. */
__host__ __device__ __forceinline__ bool wt_test(const wt_ray &r, float tnear, float tfar, float3 v0, float3 v1, float3 v2,
                                        float *t, float *u, float *v) {
    float ax = wt_comp(v0, r.kx) - r.ox, ay = wt_comp(v0, r.ky) - r.oy, az = wt_comp(v0, r.kz) - r.oz;
    float bx = wt_comp(v1, r.kx) - r.ox, by = wt_comp(v1, r.ky) - r.oy, bz = wt_comp(v1, r.kz) - r.oz;
    float cx = wt_comp(v2, r.kx) - r.ox, cy = wt_comp(v2, r.ky) - r.oy, cz = wt_comp(v2, r.kz) - r.oz;
    float Ax = ax - r.sx * az, Ay = ay - r.sy * az;
    float Bx = bx - r.sx * bz, By = by - r.sy * bz;
    float Cx = cx - r.sx * cz, Cy = cy - r.sy * cz;
    float U = Cx * By - Cy * Bx, V = Ax * Cy - Ay * Cx, W = Bx * Ay - By * Ax;
    if (U == 0.0f || V == 0.0f || W == 0.0f) {
        U = (float)((double)Cx * (double)By - (double)Cy * (double)Bx);
        V = (float)((double)Ax * (double)Cy - (double)Ay * (double)Cx);
        W = (float)((double)Bx * (double)Ay - (double)By * (double)Ax);
    }
    float m1 = V < W ? V : W, mn = U < m1 ? U : m1;
    float M1 = V > W ? V : W, mx = U > M1 ? U : M1;
    if (mn < 0.0f && mx > 0.0f) return false;
    float det = U + V + W;
    if (det == 0.0f) return false;
    float e1x = bx - ax, e1y = by - ay, e1z = bz - az;
    float e2x = cx - ax, e2y = cy - ay, e2z = cz - az;
    float nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
    float na = nx * ax + ny * ay + nz * az;
    float nd = nx * r.sx + ny * r.sy + nz;
    if (nd == 0.0f) return false;
    float tt = (na * r.sz) / nd;
    if (!(tt >= tnear && tt <= tfar)) return false;
    float rcp = 1.0f / det;
    *t = tt, *u = V * rcp, *v = W * rcp;
    return true;
}

/* The geometric normal of tri_normal (traverse/traverse.h): (v1 - v0) x (v2 - v0). */
__host__ __device__ __forceinline__ float3 wt_normal(float3 v0, float3 v1, float3 v2) {
    float3 e1 = make_float3(v1.x - v0.x, v1.y - v0.y, v1.z - v0.z);
    float3 e2 = make_float3(v2.x - v0.x, v2.y - v0.y, v2.z - v0.z);
    return make_float3(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
}

/* The lower (geom, prim) wins a tie of distances (hit_key_less). */
__host__ __device__ __forceinline__ bool wt_key_less(uint32_t g0, uint32_t p0, uint32_t g1, uint32_t p1) {
    return g0 < g1 || (g0 == g1 && p0 < p1);
}

#endif
