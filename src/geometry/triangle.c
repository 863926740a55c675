/* Scalar reference of the watertight ray-triangle test (Woop, Benthin, Wald 2013, JCGT 2(1)).
 * The kernels in traverse/kernels.inc run this exact arithmetic on SIMD lanes. The inside test
 * is the paper's; the distance comes from the plane equation, which keeps short rays accurate. */
#include <math.h>

#include "traverse/traverse.h"

bool tri_intersect_ref(const float org[3], const float dir[3], float tnear, float tfar, const float v0[3],
                       const float v1[3], const float v2[3], float *t, float *u, float *v) {
    int kz = 0;
    float a = fabsf(dir[0]);
    if (fabsf(dir[1]) > a) kz = 1, a = fabsf(dir[1]);
    if (fabsf(dir[2]) > a) kz = 2;
    int kx = kz == 2 ? 0 : kz + 1, ky = kx == 2 ? 0 : kx + 1;
    if (dir[kz] < 0.0f) {
        int s = kx;
        kx = ky, ky = s;
    }
    float sx = dir[kx] / dir[kz], sy = dir[ky] / dir[kz], sz = 1.0f / dir[kz];
    float ax = v0[kx] - org[kx], ay = v0[ky] - org[ky], az = v0[kz] - org[kz];
    float bx = v1[kx] - org[kx], by = v1[ky] - org[ky], bz = v1[kz] - org[kz];
    float cx = v2[kx] - org[kx], cy = v2[ky] - org[ky], cz = v2[kz] - org[kz];
    float Ax = ax - sx * az, Ay = ay - sy * az;
    float Bx = bx - sx * bz, By = by - sy * bz;
    float Cx = cx - sx * cz, Cy = cy - sy * cz;
    float U = Cx * By - Cy * Bx, V = Ax * Cy - Ay * Cx, W = Bx * Ay - By * Ax;
    if (U == 0.0f || V == 0.0f || W == 0.0f) {
        U = (float)((double)Cx * (double)By - (double)Cy * (double)Bx);
        V = (float)((double)Ax * (double)Cy - (double)Ay * (double)Cx);
        W = (float)((double)Bx * (double)Ay - (double)By * (double)Ax);
    }
    /* some edge function negative and some positive: outside. Written as the kernels' minps /
     * maxps (a < b ? a : b), so a NaN (overflow) is decided the same way there and here. */
    float m1 = V < W ? V : W, mn = U < m1 ? U : m1;
    float M1 = V > W ? V : W, mx = U > M1 ? U : M1;
    if (mn < 0.0f && mx > 0.0f) return false;
    float det = U + V + W;
    if (det == 0.0f) return false;
    /* distance from the plane (see WT_DEFINE in traverse/wt.h for why) */
    float e1x = bx - ax, e1y = by - ay, e1z = bz - az;
    float e2x = cx - ax, e2y = cy - ay, e2z = cz - az;
    float nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
    float na = nx * ax + ny * ay + nz * az;
    float nd = nx * sx + ny * sy + nz;
    if (nd == 0.0f) return false;
    float tt = (na * sz) / nd;
    float rcp = 1.0f / det;
    if (!(tt >= tnear && tt <= tfar)) return false;
    *t = tt;
    *u = V * rcp;
    *v = W * rcp;
    return true;
}
