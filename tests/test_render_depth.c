/* The depth AOV of the Stanford bunny equals a brute-force reference: every pixel's primary ray
 * (DESIGN.md camera formula, evaluated here independently in double precision) against every
 * triangle with Moller-Trumbore in double precision.
 *
 * Tolerances: t within 1e-4 relative (the renderer traces float rays with a watertight float test;
 * its t carries a few ulp of error plus the float rounding of the ray direction). Hit/miss may
 * differ only where a ray passes within float rounding of a silhouette edge or of one of the bunny's
 * holes, where float and double tests can legitimately disagree; at 64x64 that is expected to be
 * none or one or two pixels, so at most 0.1% of pixels (4) are allowed. The depth AOV is also
 * written to a PFM and read back unchanged, with +inf on the misses. */
#include <math.h>
#include <stdint.h>
#include <sys/stat.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"

static bool mt_intersect(const double o[3], const double d[3], const float *p0, const float *p1, const float *p2,
                         double *t_out) {
    double e1[3], e2[3], pv[3], tv[3], qv[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)p1[k] - (double)p0[k];
        e2[k] = (double)p2[k] - (double)p0[k];
    }
    pv[0] = d[1] * e2[2] - d[2] * e2[1];
    pv[1] = d[2] * e2[0] - d[0] * e2[2];
    pv[2] = d[0] * e2[1] - d[1] * e2[0];
    double det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2];
    if (det == 0.0) return false;
    double inv = 1.0 / det;
    for (int k = 0; k < 3; k++) tv[k] = o[k] - (double)p0[k];
    double u = (tv[0] * pv[0] + tv[1] * pv[1] + tv[2] * pv[2]) * inv;
    if (u < 0.0 || u > 1.0) return false;
    qv[0] = tv[1] * e1[2] - tv[2] * e1[1];
    qv[1] = tv[2] * e1[0] - tv[0] * e1[2];
    qv[2] = tv[0] * e1[1] - tv[1] * e1[0];
    double v = (d[0] * qv[0] + d[1] * qv[1] + d[2] * qv[2]) * inv;
    if (v < 0.0 || u + v > 1.0) return false;
    double t = (e2[0] * qv[0] + e2[1] * qv[1] + e2[2] * qv[2]) * inv;
    if (t <= 0.0) return false;
    *t_out = t;
    return true;
}

static void normalize3(double v[3]) {
    double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++) v[k] /= l;
}

static void cross3(const double a[3], const double b[3], double out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

int main(void) {
    char buf[512], err[512] = "";
    const char *path = rp_test_scene("stanford_bunny_bun_zipper.ply.gz", buf, sizeof buf);
    CHECK(path != NULL);
    if (!path) return RP_TEST_END();
    rp_scene_data d;
    bool ok = rp_scene_data_load(path, &d, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return RP_TEST_END();
    CHECK(d.triangle_count == 69451);

    const int W = rp_test_sanitized() ? 40 : 64, H = rp_test_sanitized() ? 30 : 48;
    rp_device *dev = rp_device_new(NULL);
    rp_render_scene *rs = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s", err);
    if (!rs) return RP_TEST_END();

    /* A camera looking at the bunny from the front and a little above. */
    rp_bounds b;
    rp_scene_get_bounds(rp_render_scene_core(rs), &b);
    float c[3] = {0.5f * (b.lower_x + b.upper_x), 0.5f * (b.lower_y + b.upper_y), 0.5f * (b.lower_z + b.upper_z)};
    float ext = b.upper_y - b.lower_y;
    rp_camera cam = {.type = RP_CAMERA_PINHOLE};
    rp_pinhole_camera *pc = &cam.pinhole;
    const float eye[3] = {c[0] + 0.4f * ext, c[1] + 0.5f * ext, c[2] + 2.2f * ext}, up[3] = {0, 1, 0};
    memcpy(pc->eye, eye, sizeof eye);
    memcpy(pc->look, c, sizeof c);
    memcpy(pc->up, up, sizeof up);
    pc->fov_deg = 35.0f;

    rp_render_desc desc = {.width = W, .height = H, .integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_DEPTH,
                           .camera = &cam};
    CHECK(rp_render_channels(&desc) == 1);
    float *depth = malloc(sizeof(float) * (size_t)(W * H));
    CHECK(rp_render(rs, &desc, depth, NULL));

    /* Brute force. */
    double e[3] = {eye[0], eye[1], eye[2]}, f[3], r[3], u[3], upd[3] = {0, 1, 0};
    for (int k = 0; k < 3; k++) f[k] = (double)c[k] - e[k];
    normalize3(f);
    cross3(f, upd, r);
    normalize3(r);
    cross3(r, f, u);
    double th = tan(35.0 * 0.5 * M_PI / 180.0), aspect = (double)W / H;
    int hits = 0, misses = 0, hitmiss = 0, tbad = 0;
    double worst = 0.0;
    for (int y = 0; y < H; y++) {
        for (int x = 0; x < W; x++) {
            double a = (2.0 * (x + 0.5) / W - 1.0) * th * aspect, bb = (1.0 - 2.0 * (y + 0.5) / H) * th, dir[3];
            for (int k = 0; k < 3; k++) dir[k] = f[k] + a * r[k] + bb * u[k];
            normalize3(dir);
            double best = INFINITY;
            for (size_t t = 0; t < d.triangle_count; t++) {
                const uint32_t *idx = d.indices + 3 * t;
                double tt;
                if (mt_intersect(e, dir, d.positions + 3 * idx[0], d.positions + 3 * idx[1], d.positions + 3 * idx[2], &tt) &&
                    tt < best)
                    best = tt;
            }
            float got = depth[y * W + x];
            bool hr = isfinite(best), hg = isfinite(got);
            if (hr != hg) {
                hitmiss++;
                fprintf(stderr, "pixel (%d,%d): reference %s, render %s\n", x, y, hr ? "hit" : "miss", hg ? "hit" : "miss");
                continue;
            }
            if (!hr) {
                misses++;
                CHECKF(got == INFINITY, "pixel (%d,%d) miss is %g, not +inf", x, y, (double)got);
                continue;
            }
            hits++;
            double rel = fabs((double)got - best) / best;
            if (rel > worst) worst = rel;
            if (rel > 1e-4) {
                tbad++;
                fprintf(stderr, "pixel (%d,%d): t %.9g, reference %.9g\n", x, y, (double)got, best);
            }
        }
    }
    printf("%d hits, %d misses, %d hit/miss differences, worst relative t error %.3g\n", hits, misses, hitmiss, worst);
    CHECK(hits > W * H / 8 && misses > W * H / 8); /* the bunny is in view, and so is the background */
    CHECKF(hitmiss <= (W * H) / 1000 + 1, "%d hit/miss differences", hitmiss);
    CHECKF(tbad == 0, "%d pixels with t off by more than 1e-4 relative", tbad);

    /* Through a PFM file and back. */
    const char *dir = getenv("RP_TEST_TMP");
    if (!dir) dir = ".";
    mkdir(dir, 0777);
    char pfm[512];
    snprintf(pfm, sizeof pfm, "%s/bunny_depth.pfm", dir);
    CHECKF(rp_image_write(pfm, W, H, 1, depth, err, sizeof err), "%s", err);
    int w, h, ch;
    float *back = rp_image_read_pfm(pfm, &w, &h, &ch, err, sizeof err);
    CHECKF(back != NULL, "%s", err);
    if (back) {
        CHECK(w == W && h == H && ch == 1);
        CHECK(memcmp(back, depth, sizeof(float) * (size_t)(W * H)) == 0);
        free(back);
    }

    free(depth);
    rp_render_scene_release(rs);
    rp_device_release(dev);
    rp_scene_data_free(&d);
    return RP_TEST_END();
}
