/* BSDFs of the physically based renderer (src/render/bsdf.c): each non-delta BSDF's sampling
 * against its pdf by a chi-square test (pbrt-v4's and Mitsuba 3's method: bins over the sphere of
 * directions, expected counts from integrating pdf over each bin, bins with fewer than 5 expected
 * samples pooled, alpha 0.01), sample() agreeing with eval() and pdf(), the directional albedo at
 * most 1 + 1e-3 (energy conservation, integrated by quadrature), delta lobes' weights, and the
 * complex-IOR Fresnel against known values; and render.h's inline fmaxf / fminf against the C library's. */
#include "../src/render/render.h"
#include "rp_test.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI_F 3.14159265358979323846f
enum { THETA = 16, PHI = 32 };

/* Regularized upper incomplete gamma Q(a, x) (Numerical Recipes, gammq). */
static double gammq(double a, double x) {
    double gln = lgamma(a);
    if (x < a + 1.0) {
        double ap = a, sum = 1.0 / a, del = sum;
        for (int n = 0; n < 1000; n++) {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if (fabs(del) < fabs(sum) * 1e-12) break;
        }
        return 1.0 - sum * exp(-x + a * log(x) - gln);
    }
    double b = x + 1.0 - a, c = 1.0 / 1e-300, d = 1.0 / b, h = d;
    for (int i = 1; i < 1000; i++) {
        double an = -i * (i - a);
        b += 2.0;
        d = an * d + b;
        if (fabs(d) < 1e-300) d = 1e-300;
        c = b + an / c;
        if (fabs(c) < 1e-300) c = 1e-300;
        d = 1.0 / d;
        double del = d * c;
        h *= del;
        if (fabs(del - 1.0) < 1e-12) break;
    }
    return exp(-x + a * log(x) - gln) * h;
}

static v3 dir_of(double theta, double phi) {
    return v3_make((float)(sin(theta) * cos(phi)), (float)(sin(theta) * sin(phi)), (float)cos(theta));
}

/* Chi-square test of b's sampling from wo; returns the p-value. */
static double chi2_test(const render_bsdf *b, v3 wo, int samples, int *mismatch) {
    static double obs[THETA * PHI], expct[THETA * PHI];
    memset(obs, 0, sizeof obs);
    for (int i = 0; i < samples; i++) {
        render_sampler s = sampler_start((uint32_t)i, 7u, 3u);
        float u[3] = {sampler_1d(&s), sampler_1d(&s), sampler_1d(&s)};
        bsdf_sample bs;
        if (!bsdf_sample_dir(b, wo, u, &bs) || bs.delta) continue;
        /* sample() must return eval() and pdf() of what it picked */
        float pdf = bsdf_pdf(b, wo, bs.wi);
        v3 f = bsdf_eval(b, wo, bs.wi);
        if (fabsf(pdf - bs.pdf) > 1e-3f * fmaxf(1.0f, pdf) || fabsf(f.x - bs.f.x) > 1e-3f * fmaxf(1.0f, f.x)) (*mismatch)++;
        double th = acos(fmin(1.0, fmax(-1.0, (double)bs.wi.z))), ph = atan2((double)bs.wi.y, (double)bs.wi.x);
        if (ph < 0) ph += 2 * M_PI;
        int ti = (int)(th / M_PI * THETA), pi = (int)(ph / (2 * M_PI) * PHI);
        if (ti >= THETA) ti = THETA - 1;
        if (pi >= PHI) pi = PHI - 1;
        obs[ti * PHI + pi] += 1.0;
    }
    /* expected counts: the pdf integrated over each bin by a 12 x 12 midpoint rule in (cos theta, phi) */
    for (int ti = 0; ti < THETA; ti++)
        for (int pi = 0; pi < PHI; pi++) {
            double sum = 0.0, c0 = cos(ti * M_PI / THETA), c1 = cos((ti + 1) * M_PI / THETA);
            double p0 = pi * 2 * M_PI / PHI, p1 = (pi + 1) * 2 * M_PI / PHI;
            enum { K = 12 };
            for (int a = 0; a < K; a++)
                for (int c = 0; c < K; c++) {
                    double ct = c0 + (c1 - c0) * (a + 0.5) / K, ph = p0 + (p1 - p0) * (c + 0.5) / K;
                    sum += bsdf_pdf(b, wo, dir_of(acos(ct), ph));
                }
            expct[ti * PHI + pi] = sum * fabs(c1 - c0) * (p1 - p0) / (K * K) * samples;
        }
    /* pool the small bins */
    double chi2 = 0.0, pool_o = 0.0, pool_e = 0.0;
    int dof = -1;
    for (int i = 0; i < THETA * PHI; i++) {
        if (expct[i] < 5.0) {
            pool_o += obs[i];
            pool_e += expct[i];
            continue;
        }
        chi2 += (obs[i] - expct[i]) * (obs[i] - expct[i]) / expct[i];
        dof++;
    }
    if (pool_e >= 5.0) {
        chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
        dof++;
    } else if (pool_o > 5.0 + 10.0 * pool_e) {
        return 0.0; /* samples where the pdf says there are none */
    }
    if (dof < 1) return 0.0;
    return gammq(dof / 2.0, chi2 / 2.0);
}

/* Directional albedo: integral of f cos over the hemisphere, midpoint rule in (cos theta, phi). */
static double albedo(const render_bsdf *b, v3 wo) {
    enum { NT = 400, NP = 400 };
    double sum = 0.0;
    for (int i = 0; i < NT; i++)
        for (int j = 0; j < NP; j++) {
            double ct = (i + 0.5) / NT, ph = (j + 0.5) * 2 * M_PI / NP;
            v3 f = bsdf_eval(b, wo, dir_of(acos(ct), ph));
            sum += fmax(f.x, fmax(f.y, f.z)) * ct;
        }
    return sum * 2 * M_PI / (NT * NP);
}

/* render_fmaxf / render_fminf (render.h) against the C library's fmaxf / fminf on NaNs, infinities,
 * signed zeros, denormals and random bit patterns: the same results (NaN payloads and signalling
 * NaNs aside), since
 * every clamp of the render library now goes through them. */
static unsigned fbits(float x) {
    unsigned u;
    memcpy(&u, &x, 4);
    return u;
}
static void check_minmax(void) {
    volatile float lib_a, lib_b; /* keeps GCC from folding or reordering the library calls */
    const float sp[] = {0.0f, -0.0f, 1.0f, -1.0f, NAN, INFINITY, -INFINITY, 1e-45f, -1e-45f, 3.4e38f, 0.5f};
    const int n = (int)(sizeof sp / sizeof sp[0]);
    uint32_t h = 12345;
    for (int i = 0; i < n * n + 200000; i++) {
        float a, b;
        if (i < n * n) {
            a = sp[i / n], b = sp[i % n];
        } else {
            uint32_t ua, ub;
            h = h * 1664525u + 1013904223u, ua = h;
            h = h * 1664525u + 1013904223u, ub = i & 1 ? ua ^ (h & 3u) : h;
            memcpy(&a, &ua, 4), memcpy(&b, &ub, 4);
            /* which NaN comes back is not specified; a signalling NaN (quiet bit clear, which no
             * arithmetic makes) makes the library return NaN */
            if ((isnan(a) && isnan(b)) || (isnan(a) && !(ua & 0x400000u)) || (isnan(b) && !(ub & 0x400000u))) continue;
        }
        lib_a = a, lib_b = b;
        float mx = fmaxf(lib_a, lib_b), mn = fminf(lib_a, lib_b);
        float rx = render_fmaxf(a, b), rn = render_fminf(a, b);
        bool same_x = isnan(mx) ? isnan(rx) : fbits(mx) == fbits(rx) || (mx == 0.0f && rx == 0.0f);
        bool same_n = isnan(mn) ? isnan(rn) : fbits(mn) == fbits(rn) || (mn == 0.0f && rn == 0.0f);
        CHECKF(same_x && same_n, "render_fmaxf/fminf(%a, %a) = %a, %a; library %a, %a", (double)a, (double)b,
               (double)rx, (double)rn, (double)mx, (double)mn);
    }
    /* the NaN-dropping clamp the texture wrap and the BSDFs rely on, and the order of signed zeros */
    CHECK(render_fminf(render_fmaxf(NAN, 0.0f), 1.0f) == 0.0f);
    CHECK(render_fmaxf(0.25f, NAN) == 0.25f && render_fminf(NAN, -2.0f) == -2.0f);
    CHECK(fbits(render_fmaxf(-0.0f, 0.0f)) == fbits(-0.0f) && fbits(render_fminf(0.0f, -0.0f)) == fbits(0.0f));
}

int main(void) {
    check_minmax();
    int samples = rp_test_sanitized() ? 20000 : 200000;
    render_bsdf lambert = {.type = BSDF_LAMBERT, .kd = {0.8f, 0.5f, 0.2f}};
    render_bsdf cond[3], plas[3], gltf[3];
    float alphas[3] = {0.15f, 0.35f, 0.7f};
    for (int k = 0; k < 3; k++) {
        cond[k] = (render_bsdf){.type = BSDF_CONDUCTOR, .eta = {0.2f, 0.9f, 1.1f}, .k = {3.9f, 2.4f, 2.2f},
                                .ks = {1, 1, 1}, .alpha = alphas[k]};
        plas[k] = (render_bsdf){.type = BSDF_PLASTIC, .kd = {0.6f, 0.6f, 0.6f}, .ks = {0.3f, 0.3f, 0.3f},
                                .alpha = alphas[k]};
        gltf[k] = (render_bsdf){.type = BSDF_PLASTIC, .kd = {0.5f, 0.3f, 0.1f}, .ks = {0.3f, 0.2f, 0.1f},
                                .alpha = alphas[k], .schlick = true};
    }
    render_bsdf glass[3] = {
        {.type = BSDF_DIELECTRIC, .kt = {1, 1, 1}, .ior = 1.5f, .alpha = 0.3f, .entering = true},
        {.type = BSDF_DIELECTRIC, .kt = {1, 1, 1}, .ior = 1.5f, .alpha = 0.6f, .entering = true},
        {.type = BSDF_DIELECTRIC, .kt = {1, 1, 1}, .ior = 1.33f, .alpha = 0.4f, .entering = false},
    };
    const render_bsdf *all[13] = {&lambert, &cond[0], &cond[1], &cond[2], &plas[0], &plas[1], &plas[2],
                                  &glass[0], &glass[1], &glass[2], &gltf[0], &gltf[1], &gltf[2]};
    const char *names[13] = {"lambert", "conductor a=0.15", "conductor a=0.35", "conductor a=0.7",
                             "plastic a=0.15", "plastic a=0.35", "plastic a=0.7",
                             "rough glass a=0.3", "rough glass a=0.6", "rough glass, inside, a=0.4",
                             "glTF plastic a=0.15", "glTF plastic a=0.35", "glTF plastic a=0.7"};
    float thetas[3] = {0.2f, 0.9f, 1.4f};
    for (int i = 0; i < 13; i++)
        for (int t = 0; t < 3; t++) {
            v3 wo = dir_of(thetas[t], 0.7);
            int mismatch = 0;
            double p = chi2_test(all[i], wo, samples, &mismatch);
            CHECKF(p > 0.01, "%s, theta_o %.1f: chi-square p-value %.4g <= 0.01", names[i], thetas[t], p);
            CHECKF(mismatch == 0, "%s: %d samples whose f/pdf disagree with eval/pdf", names[i], mismatch);
        }
    /* A sampler whose pdf is wrong must fail: a Lambert BSDF whose pdf claims uniform hemisphere. */
    {
        /* (checked by comparing cosine samples against the uniform density by hand) */
        static double obs[THETA];
        memset(obs, 0, sizeof obs);
        for (int i = 0; i < samples; i++) {
            render_sampler s = sampler_start((uint32_t)i, 1u, 1u);
            v3 w = bsdf_cosine_hemisphere(sampler_1d(&s), sampler_1d(&s));
            int ti = (int)(acos(w.z) / (M_PI / 2) * THETA);
            obs[ti < THETA ? ti : THETA - 1] += 1;
        }
        double chi2 = 0.0;
        for (int ti = 0; ti < THETA; ti++) {
            double e = (cos(ti * M_PI / 2 / THETA) - cos((ti + 1) * M_PI / 2 / THETA)) * samples;
            chi2 += (obs[ti] - e) * (obs[ti] - e) / e;
        }
        CHECKF(gammq((THETA - 1) / 2.0, chi2 / 2.0) < 0.01, "the chi-square test cannot tell cosine from uniform");
    }
    /* Energy: white BSDFs reflect at most what arrives. */
    render_bsdf white[4] = {
        {.type = BSDF_LAMBERT, .kd = {1, 1, 1}},
        {.type = BSDF_CONDUCTOR, .eta = {1, 1, 1}, .k = {1e3f, 1e3f, 1e3f}, .ks = {1, 1, 1}, .alpha = 0.3f},
        {.type = BSDF_PLASTIC, .kd = {1, 1, 1}, .ks = {0.5f, 0.5f, 0.5f}, .alpha = 0.3f},
        {.type = BSDF_PLASTIC, .kd = {1, 1, 1}, .ks = {1, 1, 1}, .alpha = 0.6f},
    };
    for (int i = 0; i < 4; i++)
        for (int t = 0; t < 3; t++) {
            double a = albedo(&white[i], dir_of(thetas[t], 0.3));
            CHECKF(a <= 1.0 + 1e-3, "white BSDF %d, theta_o %.1f: albedo %.5f > 1", i, thetas[t], a);
            if (i == 0) CHECKF(fabs(a - 1.0) < 1e-3, "Lambert albedo %.5f != 1", a);
        }
    /* glTF's metallic-roughness (material_bsdf): a metal is its base colour's coat and no diffuse, a
     * dielectric its base colour's diffuse under a 4% coat, in between both in proportion; white at
     * every metallic and roughness reflects at most what arrives; the factors map through
     * rp_material_from_data (the loader's fields). */
    {
        const float metals[4] = {0.0f, 0.3f, 0.7f, 1.0f}, roughs[3] = {0.0f, 0.5f, 0.9f};
        for (int mi = 0; mi < 4; mi++)
            for (int ri = 0; ri < 3; ri++) {
                rp_material_data d = {.kd = {0.9f, 0.6f, 0.2f}, .map_kd = -1, .illum = -1, .ior = 1.0f,
                                      .metal_rough = true, .metallic = metals[mi], .roughness = roughs[ri]};
                rp_material m = rp_material_from_data(&d);
                render_surface sf = {.ns = {0, 0, 1}, .ng = {0, 0, 1}, .entering = true, .color = {1, 1, 1}};
                render_bsdf b = material_bsdf(NULL, &m, &sf);
                float mt = metals[mi], r = roughs[ri];
                CHECKF(b.type == BSDF_PLASTIC, "metallic %g: BSDF %d, not the plastic", mt, (int)b.type);
                float want_ks[3] = {0.04f * (1 - mt) + 0.9f * mt, 0.04f * (1 - mt) + 0.6f * mt, 0.04f * (1 - mt) + 0.2f * mt};
                /* the diffuse base, before the dielectric's Fresnel: base (1 - metallic) */
                v3 diffuse = b.kd;
                CHECKF(b.schlick, "metallic %g: not glTF's Fresnel", mt);
                CHECKF(fabsf(b.ks.x - want_ks[0]) < 1e-6f && fabsf(b.ks.y - want_ks[1]) < 1e-6f &&
                           fabsf(b.ks.z - want_ks[2]) < 1e-6f,
                       "metallic %g: coat %g %g %g", mt, b.ks.x, b.ks.y, b.ks.z);
                CHECKF(fabsf(diffuse.x - 0.9f * (1 - mt)) < 1e-5f && fabsf(diffuse.y - 0.6f * (1 - mt)) < 1e-5f &&
                           fabsf(diffuse.z - 0.2f * (1 - mt)) < 1e-5f,
                       "metallic %g: diffuse %g %g %g", mt, diffuse.x, diffuse.y, diffuse.z);
                CHECKF(fabsf(b.alpha - (r * r >= 1e-3f ? r * r : 0.0f)) < 1e-6f, "roughness %g: alpha %g", r, b.alpha);
                if (r > 0.0f) {
                    d.kd[0] = d.kd[1] = d.kd[2] = 1.0f;
                    m = rp_material_from_data(&d);
                    render_bsdf w = material_bsdf(NULL, &m, &sf);
                    for (int t = 0; t < 3; t++) {
                        double a = albedo(&w, dir_of(thetas[t], 0.3));
                        CHECKF(a <= 1.0 + 1e-3, "white metallic %g roughness %g, theta_o %.1f: albedo %.5f > 1", mt, r,
                               thetas[t], a);
                    }
                }
            }
    }
    /* glTF's Fresnel: a smooth dielectric (metallic 0) reflects Schlick's 0.04 + 0.96 (1 - cos)^5,
     * 4% head-on and far more at grazing angles; its diffuse base loses as much. */
    {
        rp_material_data d = {.kd = {0.5f, 0.5f, 0.5f}, .map_kd = -1, .illum = -1, .ior = 1.0f,
                              .metal_rough = true, .metallic = 0.0f, .roughness = 0.0f};
        rp_material m = rp_material_from_data(&d);
        render_surface sf = {.ns = {0, 0, 1}, .ng = {0, 0, 1}, .entering = true, .color = {1, 1, 1}};
        render_bsdf b = material_bsdf(NULL, &m, &sf);
        for (int t = 0; t < 3; t++) {
            v3 wo = dir_of(thetas[t], 0.3);
            float u[3] = {0.0f, 0.5f, 0.5f};
            bsdf_sample bs;
            CHECKF(bsdf_sample_dir(&b, wo, u, &bs) && bs.delta, "smooth glTF coat, theta_o %.1f: no mirror sample",
                   thetas[t]);
            double w = pow(1.0 - wo.z, 5.0), want = 0.04 + 0.96 * w;
            CHECKF(fabs(bs.f.x * wo.z - want) < 1e-4, "smooth glTF coat, theta_o %.1f: reflects %.5f, Schlick %.5f",
                   thetas[t], bs.f.x * wo.z, want);
            v3 fd = bsdf_eval(&b, wo, dir_of(0.5, 2.0));
            CHECKF(fabs(fd.x - 0.5 * (1.0 - want) / M_PI) < 1e-5, "smooth glTF base, theta_o %.1f: %.6f, want %.6f",
                   thetas[t], fd.x, 0.5 * (1.0 - want) / M_PI);
        }
    }
    /* Rough glass reflects and transmits at most what arrives (its radiance scaling 1/eta^2 undone). */
    for (int t = 0; t < 3; t++) {
        const render_bsdf *g = &glass[0];
        v3 wo = dir_of(thetas[t], 0.3);
        enum { NT = 600, NP = 300 };
        double sum = 0.0;
        for (int i = 0; i < NT; i++)
            for (int j = 0; j < NP; j++) {
                double ct = -1.0 + 2.0 * (i + 0.5) / NT, ph = (j + 0.5) * 2 * M_PI / NP;
                v3 f = bsdf_eval(g, wo, dir_of(acos(ct), ph));
                sum += f.x * fabs(ct) * (ct < 0 ? 1.5 * 1.5 : 1.0);
            }
        double a = sum * 4 * M_PI / (NT * NP);
        CHECKF(a <= 1.0 + 1e-3, "rough glass, theta_o %.1f: albedo %.5f > 1", thetas[t], a);
        CHECKF(a > 0.8, "rough glass, theta_o %.1f: albedo %.5f (energy lost?)", thetas[t], a);
    }
    /* Delta lobes: a smooth dielectric reflects F and transmits 1 - F (times the radiance scale). */
    {
        render_bsdf g = {.type = BSDF_DIELECTRIC, .kt = {1, 1, 1}, .ior = 1.5f, .entering = true};
        v3 wo = dir_of(0.5, 0.0);
        double r = 0.0, tr = 0.0;
        int n = 20000;
        for (int i = 0; i < n; i++) {
            render_sampler s = sampler_start((uint32_t)i, 2u, 2u);
            float u[3] = {sampler_1d(&s), sampler_1d(&s), sampler_1d(&s)};
            bsdf_sample bs;
            if (!bsdf_sample_dir(&g, wo, u, &bs)) continue;
            double w = bs.f.x * fabsf(bs.wi.z) / bs.pdf;
            if (bs.wi.z > 0) r += w;
            else tr += w * 1.5 * 1.5; /* undo the 1/eta^2 radiance scaling */
        }
        CHECKF(fabs((r + tr) / n - 1.0) < 1e-3, "dielectric R + T = %.5f", (r + tr) / n);
    }
    /* Conductor Fresnel: eta 1 and k from reflectance r gives F(0) = r; gold-like (eta 0.2, k 3.9) about 0.9. */
    {
        v3 r = v3_make(0.2f, 0.5f, 0.9f);
        v3 f0 = bsdf_fresnel_conductor(1.0f, v3_make(1, 1, 1), bsdf_conductor_k_from_reflectance(r));
        CHECKF(fabsf(f0.x - 0.2f) < 1e-4f && fabsf(f0.y - 0.5f) < 1e-4f && fabsf(f0.z - 0.9f) < 1e-4f,
               "F0 %g %g %g", f0.x, f0.y, f0.z);
        v3 au = bsdf_fresnel_conductor(1.0f, v3_make(0.2f, 0.2f, 0.2f), v3_make(3.9f, 3.9f, 3.9f));
        double want = ((0.2 - 1) * (0.2 - 1) + 3.9 * 3.9) / ((0.2 + 1) * (0.2 + 1) + 3.9 * 3.9);
        CHECKF(fabs(au.x - want) < 1e-4, "F0 of eta 0.2 k 3.9: %g, want %g", au.x, want);
        v3 g = bsdf_fresnel_conductor(0.0f, v3_make(0.2f, 0.2f, 0.2f), v3_make(3.9f, 3.9f, 3.9f));
        CHECKF(fabsf(g.x - 1.0f) < 1e-4f, "grazing Fresnel %g != 1", g.x);
    }
    return RP_TEST_END();
}
