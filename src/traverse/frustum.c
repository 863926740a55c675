/* Frustum planes for large packets, Overbeck et al. 2008, sec. 4 (eq. 1-3 in the simplified form
 * of the dominant-axis construction). */
#include "traverse/frustum.h"

#include <math.h>
#include <string.h>

/* Widening of the rectangles: relative to their extent, and absolute (in slope units for the
 * apex frusta, in units of the scene's scale for positions). Rays are rounded to about 1e-7. */
#define WIDEN_REL 1e-3f
#define WIDEN_ABS 1e-5f
/* Plane tests: n . p + d is rounded to about 3 ulp of the scene's scale; cull only beyond this. */
#define TOL_REL 4e-6f

static void widen(float lo[2], float hi[2], float abs_margin) {
    for (int a = 0; a < 2; a++) {
        float m = WIDEN_REL * (hi[a] - lo[a]) + abs_margin;
        lo[a] -= m, hi[a] += m;
    }
}

/* Side planes between rectangle (lo0, hi0) at s p_k = k0 and (lo1, hi1) at s p_k = k1: a ray inside
 * both rectangles stays inside the planes between them, where all geometry lies. In double: the
 * rectangles of an apex frustum differ by slopes much smaller than the ulp of the apex's
 * coordinates, which a float rectangle at distance 1 from the apex would round away. */
static void set_planes(frustum *f, int k, float s, double k0, double k1, const double lo0[2], const double hi0[2],
                       const double lo1[2], const double hi1[2], float scale) {
    int ax[2];
    frustum_axes(k, &ax[0], &ax[1]);
    double D = k1 - k0, K0 = (double)s * k0; /* K0: the plane's coordinate */
    int pi = 0;
    for (int a = 0; a < 2; a++) {
        for (int side = 0; side < 2; side++) {
            /* lower: (p_a - c0) D - (c1 - c0) w >= 0; upper: (c0 - p_a) D + (c1 - c0) w >= 0,
             * with w = s (p_k - K0) */
            double c0 = side == 0 ? lo0[a] : hi0[a], c1 = side == 0 ? lo1[a] : hi1[a];
            double sg = side == 0 ? 1.0 : -1.0;
            double n[3] = {0, 0, 0};
            n[ax[a]] = sg * D;
            n[k] = -sg * (c1 - c0) * s;
            double d = -sg * D * c0 + sg * (c1 - c0) * s * K0;
            double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (int q = 0; q < 3; q++) f->n[pi][q] = (float)(n[q] / len);
            f->d[pi] = (float)(d / len);
            pi++;
        }
    }
    f->tol = TOL_REL * scale;
    f->valid = true;
}

void frustum_apex(frustum *f, const float apex[3], int k, float s, const float lo[2], const float hi[2], float scale) {
    int iu, iv;
    frustum_axes(k, &iu, &iv);
    float slo[2] = {lo[0], lo[1]}, shi[2] = {hi[0], hi[1]};
    float amax = fmaxf(fmaxf(fabsf(lo[0]), fabsf(hi[0])), fmaxf(fabsf(lo[1]), fabsf(hi[1])));
    widen(slo, shi, WIDEN_ABS * (1.0f + amax));
    /* the apex, widened in world units for the rounding of ray origins; the far rectangle is the
     * widened apex plus the slopes, so the widening moves each plane outward at every distance */
    float wlo[2] = {apex[iu], apex[iv]}, whi[2] = {apex[iu], apex[iv]};
    widen(wlo, whi, WIDEN_ABS * scale);
    double lo0[2] = {wlo[0], wlo[1]}, hi0[2] = {whi[0], whi[1]};
    double lo1[2] = {lo0[0] + slo[0], lo0[1] + slo[1]}, hi1[2] = {hi0[0] + shi[0], hi0[1] + shi[1]};
    double k0 = (double)s * apex[k];
    set_planes(f, k, s, k0, k0 + 1.0, lo0, hi0, lo1, hi1, scale);
    /* every ray's points lie on the apex's side of the near plane: primary rays start at the
     * apex, shadow rays end before it, both facing s along k */
    f->near_k = k, f->near_s = s, f->near_d = (float)(k0 - (double)WIDEN_ABS * scale);
    f->cone = true;
    memcpy(f->apex, apex, sizeof f->apex);
}

void frustum_near_far(frustum *f, int k, float s, float k0, float k1, const float lo0[2], const float hi0[2],
                      const float lo1[2], const float hi1[2], float scale) {
    float a0[2] = {lo0[0], lo0[1]}, b0[2] = {hi0[0], hi0[1]}, a1[2] = {lo1[0], lo1[1]}, b1[2] = {hi1[0], hi1[1]};
    widen(a0, b0, WIDEN_ABS * scale);
    widen(a1, b1, WIDEN_ABS * scale);
    const double A0[2] = {a0[0], a0[1]}, B0[2] = {b0[0], b0[1]}, A1[2] = {a1[0], a1[1]}, B1[2] = {b1[0], b1[1]};
    set_planes(f, k, s, k0, k1, A0, B0, A1, B1, scale);
    f->near_k = k, f->near_s = s, f->near_d = k0 - WIDEN_ABS * scale; /* k0: the rearmost origin */
    f->cone = false;
}

void frustum_req_init(frustum_req *q, rp_frustum_kind kind, const float point[3], const rp_bounds *b) {
    memset(q, 0, sizeof *q);
    q->kind = kind;
    if (point) memcpy(q->point, point, sizeof q->point);
    const float lo[3] = {b->lower_x, b->lower_y, b->lower_z}, hi[3] = {b->upper_x, b->upper_y, b->upper_z};
    float m = 1e-30f;
    for (int a = 0; a < 3; a++) {
        q->lo[a] = lo[a], q->hi[a] = hi[a];
        if (isfinite(lo[a])) m = fmaxf(m, fabsf(lo[a]));
        if (isfinite(hi[a])) m = fmaxf(m, fabsf(hi[a]));
        if (kind == RP_FRUSTUM_SHADOW && isfinite(q->point[a])) m = fmaxf(m, fabsf(q->point[a]));
    }
    q->scale = m;
}
