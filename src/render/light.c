/* Lights of the physically based integrators: area lights from emissive triangles (sampled
 * uniformly by area, converted to solid angle), point, spot and directional lights, and an
 * environment (a lat-long map importance sampled by its piecewise-constant density, or a constant);
 * one of them is chosen per light sample by power from an alias table (Walker 1977, Vose 1991). */
#include "render.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI_F 3.14159265358979323846f

static float lum(v3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

/* ---- alias table ---- */

static bool alias_build(light_sampler *ls, const float *w, size_t n) {
    ls->count = n;
    if (n == 0) return true;
    ls->prob = malloc(n * sizeof *ls->prob);
    ls->alias = malloc(n * sizeof *ls->alias);
    ls->pmf = malloc(n * sizeof *ls->pmf);
    uint32_t *small = malloc(n * sizeof *small), *large = malloc(n * sizeof *large);
    double *scaled = malloc(n * sizeof *scaled);
    bool ok = ls->prob && ls->alias && ls->pmf && small && large && scaled;
    if (ok) {
        double sum = 0.0;
        for (size_t i = 0; i < n; i++) sum += w[i];
        size_t ns = 0, nl = 0;
        for (size_t i = 0; i < n; i++) {
            double p = sum > 0.0 ? w[i] / sum : 1.0 / (double)n;
            ls->pmf[i] = (float)p;
            scaled[i] = p * (double)n;
            ls->alias[i] = (uint32_t)i;
            if (scaled[i] < 1.0) small[ns++] = (uint32_t)i;
            else large[nl++] = (uint32_t)i;
        }
        while (ns && nl) {
            uint32_t s = small[--ns], l = large[--nl];
            ls->prob[s] = (float)scaled[s];
            ls->alias[s] = l;
            scaled[l] = scaled[l] + scaled[s] - 1.0;
            if (scaled[l] < 1.0) small[ns++] = l;
            else large[nl++] = l;
        }
        while (nl) ls->prob[large[--nl]] = 1.0f;
        while (ns) ls->prob[small[--ns]] = 1.0f; /* rounding leftovers */
    }
    free(small);
    free(large);
    free(scaled);
    return ok;
}

uint32_t light_pick(const light_sampler *ls, float u, float *pmf) {
    float x = u * (float)ls->count;
    uint32_t i = (uint32_t)x;
    if (i >= ls->count) i = (uint32_t)ls->count - 1;
    float up = x - (float)i;
    uint32_t k = up < ls->prob[i] ? i : ls->alias[i];
    *pmf = ls->pmf[k];
    return k;
}

/* ---- environment map ---- */

static v3 env_dir(float u, float v) {
    float theta = PI_F * v, phi = 2.0f * PI_F * (u - 0.5f);
    float st = sinf(theta);
    return v3_make(st * sinf(phi), cosf(theta), -st * cosf(phi));
}

static void env_uv(v3 d, float *u, float *v) {
    float y = render_fminf(1.0f, render_fmaxf(-1.0f, d.y));
    *v = acosf(y) / PI_F;
    *u = 0.5f + atan2f(d.x, -d.z) / (2.0f * PI_F);
    if (!(*u >= 0.0f)) *u = 0.0f;
    if (*u >= 1.0f) *u = 0.0f;
}

static bool env_build(render_envmap *e) {
    int w = e->width, h = e->height;
    e->row_cdf = calloc((size_t)h + 1, sizeof(float));
    e->col_cdf = calloc((size_t)h * ((size_t)w + 1), sizeof(float));
    if (!e->row_cdf || !e->col_cdf) return false;
    double total = 0.0;
    for (int y = 0; y < h; y++) {
        float st = sinf(PI_F * ((float)y + 0.5f) / (float)h);
        float *cdf = e->col_cdf + (size_t)y * ((size_t)w + 1);
        double row = 0.0;
        cdf[0] = 0.0f;
        for (int x = 0; x < w; x++) {
            const float *c = e->rgb + ((size_t)y * (size_t)w + (size_t)x) * 3;
            float l = render_fmaxf(0.0f, lum(v3_load(c))) * st;
            row += l;
            cdf[x + 1] = (float)row;
        }
        for (int x = 1; x <= w; x++) cdf[x] = row > 0.0 ? (float)(cdf[x] / row) : (float)x / (float)w;
        total += row;
        e->row_cdf[y + 1] = (float)total;
    }
    for (int y = 1; y <= h; y++) e->row_cdf[y] = total > 0.0 ? (float)(e->row_cdf[y] / total) : (float)y / (float)h;
    e->integral = (float)total;
    return total > 0.0;
}

/* The largest radiance a scaled texel may hold: a texel near FLT_MAX (an RGBE exponent of 255 is
 * 1.7e38) overflowed to Inf in instant radiosity's VPLs and in the light's power (a black or NaN
 * image); 1e30 leaves the sums and the estimators' factors 8 orders of magnitude. */
#define ENV_MAX_RADIANCE 1e30

/* False, with the first texel past ENV_MAX_RADIANCE (times scale) in *x, *y, when there is one. */
static bool env_in_range(const render_envmap *e, const float scale[3], int *x, int *y) {
    for (size_t i = 0; i < (size_t)e->width * (size_t)e->height; i++)
        for (int c = 0; c < 3; c++)
            if (!((double)e->rgb[3 * i + (size_t)c] * (double)scale[c] <= ENV_MAX_RADIANCE)) {
                *x = (int)(i % (size_t)e->width), *y = (int)(i / (size_t)e->width);
                return false;
            }
    return true;
}

/* Index of the interval of cdf[0..n] holding u. */
static int cdf_find(const float *cdf, int n, float u) {
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (cdf[mid] <= u) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

static v3 env_texel(const render_envmap *e, int x, int y) {
    return v3_load(e->rgb + ((size_t)y * (size_t)e->width + (size_t)x) * 3);
}

/* Density of picking texel (x, y), per unit of (u, v). */
static float env_pdf_uv(const render_envmap *e, int x, int y) {
    const float *cdf = e->col_cdf + (size_t)y * ((size_t)e->width + 1);
    float prow = e->row_cdf[y + 1] - e->row_cdf[y], pcol = cdf[x + 1] - cdf[x];
    return prow * pcol * (float)e->width * (float)e->height;
}

v3 light_env_radiance(const rp_render_scene *s, v3 d) {
    if (s->env_light < 0) return v3_make(0, 0, 0);
    const rp_environment_light *l = &s->pb_lights[s->env_light].environment;
    v3 scale = v3_load(l->scale);
    if (!l->has_map) return scale;
    float u, v;
    env_uv(d, &u, &v);
    int x = (int)(u * (float)s->env.width), y = (int)(v * (float)s->env.height);
    if (x >= s->env.width) x = s->env.width - 1;
    if (y >= s->env.height) y = s->env.height - 1;
    return v3_mul(scale, env_texel(&s->env, x, y));
}

float light_env_pdf(const rp_render_scene *s, v3 d) {
    if (s->env_light < 0) return 0.0f;
    if (!s->pb_lights[s->env_light].environment.has_map) return 1.0f / (4.0f * PI_F);
    float u, v;
    env_uv(d, &u, &v);
    int x = (int)(u * (float)s->env.width), y = (int)(v * (float)s->env.height);
    if (x >= s->env.width) x = s->env.width - 1;
    if (y >= s->env.height) y = s->env.height - 1;
    float st = sinf(PI_F * v);
    if (!(st > 0.0f)) return 0.0f;
    return env_pdf_uv(&s->env, x, y) / (2.0f * PI_F * PI_F * st);
}

/* ---- sampling ---- */

static float spot_falloff(const rp_spot_light *l, v3 w) {
    float c = v3_dot(v3_load(l->direction), w);
    if (c >= l->cos_inner) return 1.0f;
    if (c <= l->cos_outer) return 0.0f;
    float t = (c - l->cos_outer) / (l->cos_inner - l->cos_outer);
    return t * t * (3.0f - 2.0f * t);
}

static void tri_geom(const rp_triangle_light *t, v3 *n, float *area) {
    v3 e1 = v3_sub(v3_load(t->p[1]), v3_load(t->p[0])), e2 = v3_sub(v3_load(t->p[2]), v3_load(t->p[0]));
    v3 c = v3_cross(e1, e2);
    float l = v3_length(c);
    *area = 0.5f * l;
    *n = l > 0.0f ? v3_scale(c, 1.0f / l) : v3_make(0, 0, 1);
}

static v3 tri_point(const rp_triangle_light *t, float u0, float u1) {
    float su = sqrtf(u0), b0 = 1.0f - su, b1 = u1 * su;
    v3 p0 = v3_load(t->p[0]), p1 = v3_load(t->p[1]), p2 = v3_load(t->p[2]);
    return v3_add(v3_add(v3_scale(p0, b0), v3_scale(p1, b1)), v3_scale(p2, 1.0f - b0 - b1));
}

float light_triangle_pdf(const rp_light_source *l, v3 p, v3 q, v3 ng) {
    v3 n;
    float area;
    tri_geom(&l->triangle, &n, &area);
    v3 d = v3_sub(q, p);
    float d2 = v3_dot(d, d);
    float c = fabsf(v3_dot(ng, v3_normalize(d)));
    if (!(c > 0.0f) || !(area > 0.0f)) return 0.0f;
    return d2 / (c * area);
}

static v3 uniform_sphere(float u0, float u1) {
    float z = 1.0f - 2.0f * u0, r = sqrtf(render_fmaxf(0.0f, 1.0f - z * z)), phi = 2.0f * PI_F * u1;
    return v3_make(r * cosf(phi), r * sinf(phi), z);
}

void light_from_data(const rp_light_data *d, rp_light_source *out) {
    memset(out, 0, sizeof *out);
    switch (d->type) {
    case RP_LIGHT_DATA_POINT:
        out->type = RP_LIGHT_SOURCE_POINT;
        memcpy(out->point.position, d->position, sizeof d->position);
        memcpy(out->point.intensity, d->color, sizeof d->color);
        out->point.inverse_square = true;
        break;
    case RP_LIGHT_DATA_SPOT:
        out->type = RP_LIGHT_SOURCE_SPOT;
        memcpy(out->spot.position, d->position, sizeof d->position);
        memcpy(out->spot.direction, d->direction, sizeof d->direction);
        memcpy(out->spot.intensity, d->color, sizeof d->color);
        out->spot.cos_inner = d->cos_inner;
        out->spot.cos_outer = d->cos_outer;
        break;
    case RP_LIGHT_DATA_DIRECTIONAL:
        out->type = RP_LIGHT_SOURCE_DIRECTIONAL;
        memcpy(out->directional.direction, d->direction, sizeof d->direction);
        memcpy(out->directional.irradiance, d->color, sizeof d->color);
        break;
    }
}

bool light_sample_li(const rp_render_scene *s, const rp_light_source *l, v3 p, float u0, float u1,
                     light_sample *out) {
    out->delta = false;
    switch (l->type) {
    case RP_LIGHT_SOURCE_POINT:
    case RP_LIGHT_SOURCE_SPOT: {
        bool spot = l->type == RP_LIGHT_SOURCE_SPOT;
        v3 pos = v3_load(spot ? l->spot.position : l->point.position);
        v3 d = v3_sub(pos, p);
        float d2 = v3_dot(d, d);
        if (!(d2 > 0.0f)) return false;
        out->dist = sqrtf(d2);
        out->wi = v3_scale(d, 1.0f / out->dist);
        v3 inten = v3_load(spot ? l->spot.intensity : l->point.intensity);
        if (spot) inten = v3_scale(inten, spot_falloff(&l->spot, v3_neg(out->wi)));
        out->L = v3_scale(inten, 1.0f / d2);
        out->pdf = 1.0f;
        out->delta = true;
        return !v3_is_zero(out->L);
    }
    case RP_LIGHT_SOURCE_DIRECTIONAL:
        out->wi = v3_neg(v3_load(l->directional.direction));
        out->dist = INFINITY;
        out->L = v3_load(l->directional.irradiance);
        out->pdf = 1.0f;
        out->delta = true;
        return true;
    case RP_LIGHT_SOURCE_TRIANGLE: {
        v3 n;
        float area;
        tri_geom(&l->triangle, &n, &area);
        v3 q = tri_point(&l->triangle, u0, u1);
        v3 d = v3_sub(q, p);
        float d2 = v3_dot(d, d);
        if (!(d2 > 0.0f) || !(area > 0.0f)) return false;
        out->dist = sqrtf(d2);
        out->wi = v3_scale(d, 1.0f / out->dist);
        float c = -v3_dot(n, out->wi);
        if (!(c > 0.0f)) return false; /* the back of a one-sided emitter */
        out->pdf = d2 / (c * area);
        out->L = v3_load(l->triangle.radiance);
        return true;
    }
    case RP_LIGHT_SOURCE_ENVIRONMENT: {
        out->dist = INFINITY;
        if (!l->environment.has_map) {
            out->wi = uniform_sphere(u0, u1);
            out->pdf = 1.0f / (4.0f * PI_F);
            out->L = v3_load(l->environment.scale);
            return true;
        }
        const render_envmap *e = &s->env;
        int y = cdf_find(e->row_cdf, e->height, u0);
        const float *cdf = e->col_cdf + (size_t)y * ((size_t)e->width + 1);
        int x = cdf_find(cdf, e->width, u1);
        /* A uniform point inside the texel, from what is left of u0 and u1. */
        float prow = e->row_cdf[y + 1] - e->row_cdf[y], pcol = cdf[x + 1] - cdf[x];
        float fy = prow > 0.0f ? (u0 - e->row_cdf[y]) / prow : 0.5f, fx = pcol > 0.0f ? (u1 - cdf[x]) / pcol : 0.5f;
        fx = render_fminf(render_fmaxf(fx, 0.0f), 0.999f);
        fy = render_fminf(render_fmaxf(fy, 0.0f), 0.999f);
        float u = ((float)x + fx) / (float)e->width, v = ((float)y + fy) / (float)e->height;
        out->wi = env_dir(u, v);
        float st = sinf(PI_F * v);
        float pdf_uv = env_pdf_uv(e, x, y);
        if (!(st > 0.0f) || !(pdf_uv > 0.0f)) return false;
        out->pdf = pdf_uv / (2.0f * PI_F * PI_F * st);
        out->L = v3_mul(v3_load(l->environment.scale), env_texel(e, x, y));
        return true;
    }
    }
    return false;
}

bool light_sample_le(const rp_render_scene *s, const rp_light_source *l, const float u[4], v3 *p, v3 *n, v3 *dir,
                     v3 *power) {
    (void)s;
    switch (l->type) {
    case RP_LIGHT_SOURCE_POINT:
    case RP_LIGHT_SOURCE_SPOT: {
        bool spot = l->type == RP_LIGHT_SOURCE_SPOT;
        *p = v3_load(spot ? l->spot.position : l->point.position);
        *n = v3_make(0, 0, 0);
        *dir = uniform_sphere(u[2], u[3]);
        v3 inten = v3_load(spot ? l->spot.intensity : l->point.intensity);
        if (spot) inten = v3_scale(inten, spot_falloff(&l->spot, *dir));
        *power = v3_scale(inten, 4.0f * PI_F);
        return true;
    }
    case RP_LIGHT_SOURCE_TRIANGLE: {
        float area;
        tri_geom(&l->triangle, n, &area);
        *p = tri_point(&l->triangle, u[0], u[1]);
        v3 t, b;
        bsdf_frame(*n, &t, &b);
        *dir = bsdf_to_world(bsdf_cosine_hemisphere(u[2], u[3]), t, b, *n);
        /* Flux of a Lambertian emitter, L A pi, over the densities 1/A and cos/pi. */
        *power = v3_scale(v3_load(l->triangle.radiance), area * PI_F);
        return area > 0.0f;
    }
    case RP_LIGHT_SOURCE_DIRECTIONAL:
    case RP_LIGHT_SOURCE_ENVIRONMENT:
        return false;
    }
    return false;
}

/* ---- the scene's lights ---- */

static float light_power(const rp_render_scene *s, const rp_light_source *l) {
    float r = s->radius;
    switch (l->type) {
    case RP_LIGHT_SOURCE_POINT: return 4.0f * PI_F * lum(v3_load(l->point.intensity));
    case RP_LIGHT_SOURCE_SPOT:
        return 2.0f * PI_F * (1.0f - 0.5f * (l->spot.cos_inner + l->spot.cos_outer)) * lum(v3_load(l->spot.intensity));
    case RP_LIGHT_SOURCE_DIRECTIONAL: return PI_F * r * r * lum(v3_load(l->directional.irradiance));
    case RP_LIGHT_SOURCE_TRIANGLE: {
        v3 n;
        float area;
        tri_geom(&l->triangle, &n, &area);
        return PI_F * area * lum(v3_load(l->triangle.radiance));
    }
    case RP_LIGHT_SOURCE_ENVIRONMENT: {
        float avg = lum(v3_load(l->environment.scale));
        if (l->environment.has_map) avg *= s->env.integral / ((float)s->env.width * (float)s->env.height) * (PI_F / 2.0f);
        return 4.0f * PI_F * PI_F * r * r * avg;
    }
    }
    return 0.0f;
}

/* Emissive triangles become area lights, except textured emitters (their radiance varies over the
 * triangle): rays that hit them add their radiance, next-event estimation does not aim at them. */
static bool sampled_emitter(const rp_render_scene *s, uint32_t m) {
    return !v3_is_zero(material_ke(s, m)) && rp_render_scene_material(s, m)->emission_texture < 0;
}

bool light_scene_init(rp_render_scene *s, const rp_render_scene_desc *desc, char *err, size_t err_size) {
    const rp_scene_data *d = s->data;
    const rp_bounds *b = &s->bounds;
    s->center = v3_make(0.5f * (b->lower_x + b->upper_x), 0.5f * (b->lower_y + b->upper_y),
                        0.5f * (b->lower_z + b->upper_z));
    s->radius = 0.5f * v3_length(v3_make(b->upper_x - b->lower_x, b->upper_y - b->lower_y, b->upper_z - b->lower_z));
    if (!(s->radius > 0.0f) || !isfinite(s->radius)) s->radius = 1.0f;
    if (!isfinite(s->center.x) || !isfinite(s->center.y) || !isfinite(s->center.z)) s->center = v3_make(0, 0, 0);
    s->env_light = -1;
    if (d->triangle_count) {
        s->tri_light = malloc(d->triangle_count * sizeof *s->tri_light);
        if (!s->tri_light) goto oom;
    }
    size_t n = d->light_count, emissive = 0;
    for (size_t i = 0; i < d->triangle_count; i++) {
        s->tri_light[i] = -1;
        uint32_t m = d->tri_materials ? d->tri_materials[i] : 0;
        if (sampled_emitter(s, m)) emissive++;
    }
    bool env = desc && (desc->environment || !v3_is_zero(v3_load(desc->environment_scale)));
    s->pb_lights = calloc(n + emissive + 1, sizeof *s->pb_lights);
    if (!s->pb_lights) goto oom;
    size_t k = 0;
    for (size_t i = 0; i < d->triangle_count; i++) {
        uint32_t m = d->tri_materials ? d->tri_materials[i] : 0;
        if (!sampled_emitter(s, m)) continue;
        v3 ke = material_ke(s, m);
        rp_light_source *l = &s->pb_lights[k];
        l->type = RP_LIGHT_SOURCE_TRIANGLE;
        for (int c = 0; c < 3; c++) memcpy(l->triangle.p[c], d->positions + 3 * (size_t)d->indices[3 * i + (size_t)c], 3 * sizeof(float));
        memcpy(l->triangle.radiance, &ke, sizeof l->triangle.radiance);
        l->triangle.prim = (uint32_t)i;
        v3 nn;
        float area;
        tri_geom(&l->triangle, &nn, &area);
        if (!(area > 0.0f)) continue;
        s->tri_light[i] = (int32_t)k++;
    }
    for (size_t i = 0; i < n; i++) {
        light_from_data(&d->lights[i], &s->pb_lights[k++]);
    }
    if (env) {
        rp_light_source *l = &s->pb_lights[k];
        l->type = RP_LIGHT_SOURCE_ENVIRONMENT;
        v3 sc = v3_load(desc->environment_scale);
        if (v3_is_zero(sc)) sc = v3_make(1, 1, 1);
        memcpy(l->environment.scale, &sc, sizeof l->environment.scale);
        if (desc->environment) {
            s->env.rgb = rp_image_read_hdr(desc->environment, &s->env.width, &s->env.height, err, err_size);
            if (!s->env.rgb) return false;
            int x, y;
            if (!env_in_range(&s->env, l->environment.scale, &x, &y)) {
                if (err && err_size)
                    snprintf(err, err_size, "%s: error: pixel (%d, %d)'s radiance, times the scale, is over %g", desc->environment,
                             x, y, ENV_MAX_RADIANCE);
                return false;
            }
            if (!env_build(&s->env)) {
                if (err && err_size) snprintf(err, err_size, "%s: error: the environment map is black", desc->environment);
                return false;
            }
            l->environment.has_map = true;
        }
        s->env_light = (int32_t)k++;
    }
    s->pb_light_count = k;
    float *w = malloc((k ? k : 1) * sizeof *w);
    if (!w) goto oom;
    for (size_t i = 0; i < k; i++) w[i] = light_power(s, &s->pb_lights[i]);
    bool ok = alias_build(&s->light_pick, w, k);
    free(w);
    if (!ok) goto oom;
    return true;
oom:
    if (err && err_size) snprintf(err, err_size, "out of memory");
    return false;
}

void light_scene_free(rp_render_scene *s) {
    free(s->pb_lights);
    free(s->tri_light);
    free(s->light_pick.prob);
    free(s->light_pick.alias);
    free(s->light_pick.pmf);
    free(s->env.rgb);
    free(s->env.row_cdf);
    free(s->env.col_cdf);
}

const rp_light_source *rp_render_scene_lights(const rp_render_scene *scene, size_t *count) {
    if (count) *count = scene ? scene->pb_light_count : 0;
    return scene ? scene->pb_lights : NULL;
}
