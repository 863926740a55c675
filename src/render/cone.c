/* Cones and cylinders (NFF `c`) as user geometry: an exact ray / truncated-cone intersection.
 * NFF defines the surface without end caps, so none are added. Solved in double precision: the
 * quadratic loses many bits when a ray grazes the surface or runs nearly along the axis. */
#include "render.h"

#include <math.h>

void cone_prepare(const rp_cone_data *in, render_cone *out) {
    double axis[3], len2 = 0.0;
    for (int k = 0; k < 3; k++) {
        axis[k] = (double)in->apex[k] - (double)in->base[k];
        len2 += axis[k] * axis[k];
    }
    double len = sqrt(len2);
    for (int k = 0; k < 3; k++) {
        out->base[k] = in->base[k];
        out->axis[k] = len > 0.0 ? axis[k] / len : (k == 1 ? 1.0 : 0.0);
    }
    out->height = len;
    out->base_radius = fabs((double)in->base_radius);
    out->slope = len > 0.0 ? (fabs((double)in->apex_radius) - out->base_radius) / len : 0.0;
}

void cone_bounds(void *user, uint32_t prim, rp_bounds *out) {
    const render_cone *c = (const render_cone *)user + prim;
    double rb = c->base_radius, ra = c->base_radius + c->slope * c->height;
    float lo[3], hi[3];
    for (int k = 0; k < 3; k++) {
        /* A disc of radius r around axis a spans r * sqrt(1 - a_k^2) along axis k. */
        double ext = sqrt(fmax(0.0, 1.0 - c->axis[k] * c->axis[k]));
        double b = c->base[k], a = c->base[k] + c->axis[k] * c->height;
        double l = fmin(b - rb * ext, a - ra * ext), h = fmax(b + rb * ext, a + ra * ext);
        lo[k] = nextafterf((float)l, -INFINITY);
        hi[k] = nextafterf((float)h, INFINITY);
    }
    *out = (rp_bounds){lo[0], lo[1], lo[2], 0.0f, hi[0], hi[1], hi[2], 0.0f};
}

/* Closest t in [tnear, tfar) where the ray meets the side of the frustum; returns false if none.
 * Surface: |q - (q.w) w|^2 = (rb + k (q.w))^2 with q = p - base, 0 <= q.w <= height. */
static bool cone_hit(const render_cone *c, const rp_ray *ray, double *t_out, double n_out[3]) {
    const double o[3] = {ray->org_x, ray->org_y, ray->org_z};
    const double d[3] = {ray->dir_x, ray->dir_y, ray->dir_z};
    double delta[3], oz = 0.0, dz = 0.0;
    for (int k = 0; k < 3; k++) {
        delta[k] = o[k] - c->base[k];
        oz += delta[k] * c->axis[k];
        dz += d[k] * c->axis[k];
    }
    double dp[3], op[3];
    for (int k = 0; k < 3; k++) {
        dp[k] = d[k] - dz * c->axis[k];
        op[k] = delta[k] - oz * c->axis[k];
    }
    double kk = c->slope, r0 = c->base_radius + kk * oz;
    double a = dp[0] * dp[0] + dp[1] * dp[1] + dp[2] * dp[2] - kk * kk * dz * dz;
    double b = 2.0 * (op[0] * dp[0] + op[1] * dp[1] + op[2] * dp[2] - kk * dz * r0);
    double cc = op[0] * op[0] + op[1] * op[1] + op[2] * op[2] - r0 * r0;
    double roots[2];
    int n = 0;
    if (fabs(a) < 1e-12 * (fabs(b) + fabs(cc) + 1e-300)) {
        if (b != 0.0) roots[n++] = -cc / b;
    } else {
        double disc = b * b - 4.0 * a * cc;
        if (disc < 0.0) return false;
        double sq = sqrt(disc);
        /* Numerically stable pair of roots. */
        double q = -0.5 * (b + (b >= 0.0 ? sq : -sq));
        double t0 = q / a, t1 = q != 0.0 ? cc / q : t0;
        roots[0] = fmin(t0, t1);
        roots[1] = fmax(t0, t1);
        n = 2;
    }
    for (int i = 0; i < n; i++) {
        double t = roots[i];
        if (!(t >= (double)ray->tnear && t < (double)ray->tfar)) continue;
        double z = oz + t * dz;
        if (z < 0.0 || z > c->height) continue;
        double rz = c->base_radius + kk * z;
        if (rz < 0.0) continue;
        /* Gradient of the implicit surface: radial part minus r(z) k along the axis. */
        for (int k = 0; k < 3; k++) n_out[k] = op[k] + t * dp[k] - rz * kk * c->axis[k];
        *t_out = t;
        return true;
    }
    return false;
}

bool cone_intersect(void *user, uint32_t prim, rp_ray *ray, rp_hit *hit) {
    const render_cone *c = (const render_cone *)user + prim;
    double t, n[3];
    if (!cone_hit(c, ray, &t, n)) return false;
    float tf = (float)t;
    if (!(tf >= ray->tnear && tf < ray->tfar)) return false;
    ray->tfar = tf;
    hit->Ng_x = (float)n[0];
    hit->Ng_y = (float)n[1];
    hit->Ng_z = (float)n[2];
    hit->u = 0.0f;
    hit->v = 0.0f;
    return true;
}

bool cone_occluded(void *user, uint32_t prim, const rp_ray *ray) {
    const render_cone *c = (const render_cone *)user + prim;
    double t, n[3];
    return cone_hit(c, ray, &t, n);
}
