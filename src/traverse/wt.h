/* The watertight ray-triangle test (Woop, Benthin, Wald 2013) on N SIMD lanes, shared by the
 * single-ray and small-packet kernels (kernels.inc) and the large packets (packet_n.inc). It is
 * the arithmetic of tri_intersect_ref, so every kernel returns the same hits bit for bit.
 * Included once per ISA translation unit, after simd/simd.h; WT_DEFINE(N) makes wt_N. */
#ifndef RP_WT_H
#define RP_WT_H

#include "simd/simd.h"
#include "sys/sys.h"

/* Double-precision fallback of the edge functions when one is exactly 0 (sec. 4.1 of the paper):
 * decides edge and vertex hits consistently for neighbouring triangles. */
static inline void wt_refine(float Ax, float Ay, float Bx, float By, float Cx, float Cy, float *U, float *V,
                             float *W) {
    *U = (float)((double)Cx * (double)By - (double)Cy * (double)Bx);
    *V = (float)((double)Ax * (double)Cy - (double)Ay * (double)Cx);
    *W = (float)((double)Bx * (double)Ay - (double)By * (double)Ax);
}

/* The test's lane masks: -1/0 vectors, except 16 wide with AVX-512, where they stay in mask
 * registers (__mmask16) from the compares to the returned lanes. GCC's vector compares had taken
 * each one through a -1/0 vector and back (vpmovm2d, vpmovd2m) to combine and test it. Same
 * predicates either way: == false on NaN, < and > false on NaN, != true on NaN. */
#define WT_MASKS_VEC(N)                                                                           \
    typedef vi##N wt_mask##N;                                                                     \
    RP_INLINE wt_mask##N wt_zero_##N(vf##N U, vf##N V, vf##N W) {                                 \
        vf##N z = vf##N##_splat(0.0f);                                                            \
        return (U == z) | (V == z) | (W == z);                                                    \
    }                                                                                             \
    RP_INLINE wt_mask##N wt_inside_##N(vf##N mn, vf##N mx, vf##N det) {                           \
        vf##N z = vf##N##_splat(0.0f);                                                            \
        return ~((mn < z) & (mx > z)) & (det != z);                                               \
    }                                                                                             \
    RP_INLINE wt_mask##N wt_and_nonzero_##N(wt_mask##N m, vf##N x) { return m & (x != vf##N##_splat(0.0f)); } \
    RP_INLINE uint32_t wt_bits_##N(wt_mask##N m) { return vi##N##_movemask(m); }                  \
    RP_INLINE vi##N wt_lanes_##N(wt_mask##N m) { return m; }
WT_MASKS_VEC(4)
WT_MASKS_VEC(8)
#if defined(__AVX512F__) && defined(__AVX512DQ__)
typedef __mmask16 wt_mask16;
RP_INLINE wt_mask16 wt_zero_16(vf16 U, vf16 V, vf16 W) {
    __m512 z = _mm512_setzero_ps();
    return (wt_mask16)(_mm512_cmp_ps_mask((__m512)U, z, _CMP_EQ_OQ) | _mm512_cmp_ps_mask((__m512)V, z, _CMP_EQ_OQ) |
                       _mm512_cmp_ps_mask((__m512)W, z, _CMP_EQ_OQ));
}
RP_INLINE wt_mask16 wt_inside_16(vf16 mn, vf16 mx, vf16 det) {
    __m512 z = _mm512_setzero_ps();
    wt_mask16 out = (wt_mask16)(_mm512_cmp_ps_mask((__m512)mn, z, _CMP_LT_OS) & _mm512_cmp_ps_mask((__m512)mx, z, _CMP_GT_OS));
    return (wt_mask16)(~out & _mm512_cmp_ps_mask((__m512)det, z, _CMP_NEQ_UQ));
}
RP_INLINE wt_mask16 wt_and_nonzero_16(wt_mask16 m, vf16 x) {
    return (wt_mask16)(m & _mm512_cmp_ps_mask((__m512)x, _mm512_setzero_ps(), _CMP_NEQ_UQ));
}
RP_INLINE uint32_t wt_bits_16(wt_mask16 m) { return (uint32_t)m; }
RP_INLINE vi16 wt_lanes_16(wt_mask16 m) { return (vi16)_mm512_movm_epi32(m); }
#else
WT_MASKS_VEC(16)
#endif

/* wt_N: a*, b*, c* are the vertices minus the ray origin, already permuted so that z is the ray's
 * dominant axis; s* the shear constants. Returns the lanes hit, with t, u, v; when no lane passes
 * the edge tests it returns at once (t, u, v are 0), so the distance and its divisions are paid
 * only by leaves with a candidate. The exact-zero refinement is a separate, cold function that
 * takes and returns the edge functions by value, so the hot path keeps them in registers. */
#define WT_DEFINE(N)                                                                              \
    typedef struct wt_edges##N {                                                                  \
        vf##N U, V, W;                                                                            \
    } wt_edges##N;                                                                                \
    __attribute__((noinline, cold)) static wt_edges##N wt_fix_##N(                                \
        vf##N Ax, vf##N Ay, vf##N Bx, vf##N By, vf##N Cx, vf##N Cy, wt_edges##N e, uint32_t z) {  \
        do {                                                                                      \
            uint32_t i = simd_ctz(z);                                                             \
            z &= z - 1;                                                                           \
            float u_, v_, w_;                                                                     \
            wt_refine(Ax[i], Ay[i], Bx[i], By[i], Cx[i], Cy[i], &u_, &v_, &w_);                   \
            e.U[i] = u_, e.V[i] = v_, e.W[i] = w_;                                                \
        } while (z);                                                                              \
        return e;                                                                                 \
    }                                                                                             \
    /* Per lane: the dominant axis kz of d, kx and ky (swapped when d_kz < 0) and the shear        \
     * (d_kx, d_ky, 1) / d_kz, the rule of tri_intersect_ref, lane for lane the same results. */ \
    RP_INLINE void wt_axes_##N(vf##N d0, vf##N d1, vf##N d2, vi##N *kx, vi##N *ky, vi##N *kz,     \
                               vf##N *sx, vf##N *sy, vf##N *sz) {                                 \
        vf##N a0 = vf##N##_abs(d0), a1 = vf##N##_abs(d1), a2 = vf##N##_abs(d2);                   \
        vi##N y_gt = a1 > a0;                                                                     \
        vi##N z = y_gt & vi##N##_splat(1);                                                        \
        z = vi##N##_select(a2 > vf##N##_select(y_gt, a1, a0), vi##N##_splat(2), z);               \
        vi##N x = vi##N##_select(z == 2, vi##N##_splat(0), z + 1);                                \
        vi##N y = vi##N##_select(x == 2, vi##N##_splat(0), x + 1);                                \
        vf##N dz = vf##N##_select(z == 0, d0, vf##N##_select(z == 1, d1, d2));                    \
        vi##N neg = dz < vf##N##_splat(0.0f);                                                     \
        *kx = vi##N##_select(neg, y, x), *ky = vi##N##_select(neg, x, y), *kz = z;                \
        vf##N dx = vf##N##_select(*kx == 0, d0, vf##N##_select(*kx == 1, d1, d2));                \
        vf##N dy = vf##N##_select(*ky == 0, d0, vf##N##_select(*ky == 1, d1, d2));                \
        *sx = dx / dz, *sy = dy / dz, *sz = vf##N##_splat(1.0f) / dz;                             \
    }                                                                                             \
    /* 1 / d per lane with tiny components replaced (safe_rcp), so no 0 * inf makes a NaN. */   \
    RP_INLINE vf##N wt_rcp_##N(vf##N d) {                                                         \
        vi##N tiny = vf##N##_abs(d) < vf##N##_splat(1e-18f);                                      \
        return vf##N##_splat(1.0f) / vf##N##_select(tiny, vf##N##_xorsign(vf##N##_splat(1e-18f), d), d); \
    }                                                                                             \
    RP_INLINE vi##N wt_##N(vf##N ax, vf##N ay, vf##N az, vf##N bx, vf##N by, vf##N bz, vf##N cx,  \
                           vf##N cy, vf##N cz, vf##N sx, vf##N sy, vf##N sz, vf##N *t, vf##N *u,  \
                           vf##N *v) {                                                            \
        vf##N Ax = ax - sx * az, Ay = ay - sy * az;                                               \
        vf##N Bx = bx - sx * bz, By = by - sy * bz;                                               \
        vf##N Cx = cx - sx * cz, Cy = cy - sy * cz;                                               \
        vf##N U = Cx * By - Cy * Bx, V = Ax * Cy - Ay * Cx, W = Bx * Ay - By * Ax;                \
        vf##N zero = vf##N##_splat(0.0f);                                                         \
        uint32_t z = wt_bits_##N(wt_zero_##N(U, V, W));                                           \
        if (RP_UNLIKELY(z)) {                                                                     \
            wt_edges##N e = wt_fix_##N(Ax, Ay, Bx, By, Cx, Cy, (wt_edges##N){U, V, W}, z);        \
            U = e.U, V = e.V, W = e.W;                                                            \
        }                                                                                         \
        /* some edge function negative and some positive: outside. As min / max (minps: a NaN  \
         * operand yields the other one), the same decision as tri_intersect_ref's. */           \
        vf##N mn = vf##N##_min(U, vf##N##_min(V, W)), mx = vf##N##_max(U, vf##N##_max(V, W));     \
        vf##N det = U + V + W;                                                                    \
        wt_mask##N ok = wt_inside_##N(mn, mx, det);                                               \
        if (!wt_bits_##N(ok)) {                                                                   \
            *t = zero, *u = zero, *v = zero;                                                      \
            return vi##N##_splat(0);                                                              \
        }                                                                                         \
        /* distance from the plane, N.(v0 - o) / N.d with d = (sx, sy, 1) / sz: exact for      \
         * axis-aligned planes, unlike the sheared sum of the paper, which cancels badly for   \
         * rays starting near a large triangle (short secondary rays) */                     \
        vf##N e1x = bx - ax, e1y = by - ay, e1z = bz - az;                                        \
        vf##N e2x = cx - ax, e2y = cy - ay, e2z = cz - az;                                        \
        vf##N nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x; \
        vf##N na = nx * ax + ny * ay + nz * az;                                                   \
        vf##N nd = nx * sx + ny * sy + nz;                                                        \
        ok = wt_and_nonzero_##N(ok, nd);                                                          \
        *t = (na * sz) / nd;                                                                      \
        vf##N rcp = vf##N##_splat(1.0f) / det;                                                    \
        *u = V * rcp;                                                                             \
        *v = W * rcp;                                                                             \
        return wt_lanes_##N(ok);                                                                  \
    }

#endif
