// rp-test: timeout=300
/* The pixel samplers (sampler.c): hashed PCG and Owen-scrambled Sobol. Sobol's first 2^m samples
 * of a pixel in dimensions (0, 1) and (4, 5) (Sobol's first two of each group of four) are a
 * (0, m, 2)-net: one point in each of the 16 x 16 cells of the unit square; each dimension alone
 * is stratified into 2^m bins; images with --sampler sobol are the same on 1, 2 and 3 threads; on
 * cornell_original, path tracing with Sobol has the PCG image's mean and a lower error at 16 spp. */
#include "../src/render/render.h"
#include "rp_test.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static float *render(rp_render_scene *s, const rp_render_desc *d) {
    float *px = malloc((size_t)d->width * (size_t)d->height * 3 * sizeof(float));
    if (px && !rp_render(s, d, px, NULL)) {
        free(px);
        return NULL;
    }
    return px;
}

static double rmse(const float *a, const float *b, size_t n) {
    double e = 0.0;
    for (size_t i = 0; i < n; i++) e += ((double)a[i] - b[i]) * ((double)a[i] - b[i]);
    return sqrt(e / (double)n);
}

int main(void) {
    /* Nets and strata. */
    int bad_net = 0, bad_strata = 0, differ = 0;
    for (uint32_t px = 0; px < 8; px++) {
        for (uint32_t g = 0; g < 2; g++) {
            int cells[256] = {0}, bins0[256] = {0}, bins1[256] = {0};
            for (uint32_t i = 0; i < 256; i++) {
                render_sampler s = sampler_start_pixel(RP_SAMPLER_SOBOL, px * 7u, px * 3u + 1u, i);
                float a = sampler_at(&s, 4 * g), b = sampler_at(&s, 4 * g + 1);
                cells[(int)(a * 16.0f) * 16 + (int)(b * 16.0f)]++;
                bins0[(int)(a * 256.0f)]++;
                bins1[(int)(b * 256.0f)]++;
            }
            for (int c = 0; c < 256; c++) {
                bad_net += cells[c] != 1;
                bad_strata += bins0[c] != 1 || bins1[c] != 1;
            }
        }
        /* other pixels get other scrambles */
        render_sampler s0 = sampler_start_pixel(RP_SAMPLER_SOBOL, px, 0, 5);
        render_sampler s1 = sampler_start_pixel(RP_SAMPLER_SOBOL, px + 1, 0, 5);
        differ += sampler_at(&s0, 0) != sampler_at(&s1, 0);
    }
    CHECKF(bad_net == 0, "Sobol: %d of the 16x16 cells do not hold exactly one of 256 samples", bad_net);
    CHECKF(bad_strata == 0, "Sobol: %d 1D strata of 256 do not hold exactly one sample", bad_strata);
    CHECKF(differ >= 7, "Sobol: neighbouring pixels share their numbers (%d of 8 differ)", differ);
    {
        render_sampler a = sampler_start_pixel(RP_SAMPLER_PCG, 3, 4, 5), b = sampler_start(3, 4, 5);
        CHECK(sampler_at(&a, 7) == sampler_at(&b, 7));
    }
    /* PCG's 256 samples are not a net (the test can tell the two apart). */
    {
        int cells[256] = {0}, bad = 0;
        for (uint32_t i = 0; i < 256; i++) {
            render_sampler s = sampler_start_pixel(RP_SAMPLER_PCG, 1, 2, i);
            cells[(int)(sampler_at(&s, 0) * 16.0f) * 16 + (int)(sampler_at(&s, 1) * 16.0f)]++;
        }
        for (int c = 0; c < 256; c++) bad += cells[c] != 1;
        CHECKF(bad > 0, "PCG looks like a net");
    }
    /* Images. */
    char path[512], err[512];
    if (rp_test_scene("cornell_original/CornellBox-Original.obj", path, sizeof path)) {
        rp_scene_data d;
        CHECK(rp_scene_data_load(path, &d, err, sizeof err));
        int W = 32, H = 32;
        size_t n = (size_t)W * H * 3;
        float *ref[2] = {NULL, NULL};
        for (int t = 1; t <= 3; t++) {
            rp_device *dev = rp_device_new(&(rp_device_desc){.threads = t});
            rp_render_scene *s = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
            CHECK(s != NULL);
            for (int k = 0; s && k < 2; k++) {
                rp_render_desc rd = {.width = W, .height = H, .spp = 4, .sampler = RP_SAMPLER_SOBOL,
                                     .integrator = k ? RP_INTEGRATOR_IR : RP_INTEGRATOR_PATH};
                float *img = render(s, &rd);
                CHECK(img != NULL);
                if (t == 1) {
                    ref[k] = img;
                    continue;
                }
                CHECKF(img && ref[k] && memcmp(img, ref[k], n * sizeof(float)) == 0, "Sobol %s: %d threads differ from 1",
                       k ? "IR" : "path", t);
                free(img);
            }
            if (s) rp_render_scene_release(s);
            rp_device_release(dev);
        }
        free(ref[0]);
        free(ref[1]);
        if (!rp_test_sanitized()) {
            rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
            rp_render_scene *s = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
            W = H = 48;
            n = (size_t)W * H * 3;
            rp_render_desc rd = {.width = W, .height = H, .spp = 512, .integrator = RP_INTEGRATOR_PATH};
            float *truth = render(s, &rd);
            rd.spp = 16;
            float *pcg = render(s, &rd);
            rd.sampler = RP_SAMPLER_SOBOL;
            rd.sample_start = 0;
            float *sob = render(s, &rd);
            CHECK(truth && pcg && sob);
            if (truth && pcg && sob) {
                double mt = 0, ms = 0, ep = rmse(pcg, truth, n), es = rmse(sob, truth, n);
                for (size_t i = 0; i < n; i++) mt += truth[i], ms += sob[i];
                printf("cornell_original 48x48, path: mean PCG 512 spp %.5f, Sobol 16 spp %.5f; RMSE at 16 spp: PCG %.5f, "
                       "Sobol %.5f\n", mt / (double)n, ms / (double)n, ep, es);
                CHECKF(fabs(ms / mt - 1.0) < 0.03, "Sobol mean %.5f vs PCG %.5f", ms / (double)n, mt / (double)n);
                CHECKF(es < ep, "Sobol's error %.5f is not below PCG's %.5f", es, ep);
            }
            free(truth);
            free(pcg);
            free(sob);
            rp_render_scene_release(s);
            rp_device_release(dev);
        }
        rp_scene_data_free(&d);
    }
    return RP_TEST_END();
}
