/* Materials: mapping the scene files' parameters to the renderer's tagged union, textures, Fresnel. */
#include "render.h"

#include <string.h>
#include <math.h>

static bool any_positive(const float c[3]) { return c[0] > 0.0f || c[1] > 0.0f || c[2] > 0.0f; }

/* Picks the transport from what the file asks for: transmission wins over mirror reflection, which
 * wins over a plain highlight (an NFF surface with T > 0 is glass whatever its Ks). */
rp_material rp_material_from_data(const rp_material_data *d) {
    rp_material m;
    memset(&m, 0, sizeof m);
    memcpy(m.kd, d->kd, sizeof m.kd);
    memcpy(m.ks, d->ks, sizeof m.ks);
    memcpy(m.ke, d->ke, sizeof m.ke);
    m.ns = d->ns > 0.0f ? d->ns : 1.0f;
    m.texture = d->map_kd;
    m.roughness_texture = d->map_roughness - 1;
    m.normal_texture = d->map_normal - 1;
    m.emission_texture = d->map_ke - 1;
    m.metal_rough_texture = -1;
    /* alpha cutouts: a mode the renderer does not know is opaque */
    m.alpha_mode = d->alpha_mode == RP_ALPHA_MASK || d->alpha_mode == RP_ALPHA_BLEND ? d->alpha_mode : RP_ALPHA_OPAQUE;
    m.alpha = isfinite(d->alpha) ? render_fminf(render_fmaxf(d->alpha, 0.0f), 1.0f) : 1.0f;
    m.alpha_cutoff = d->alpha_cutoff;
    m.alpha_texture = d->map_alpha - 1;
    m.uv_transform = d->uv_transform;
    m.specular_texture = d->map_ks - 1;
    memcpy(m.uv_matrix, d->uv_matrix, sizeof m.uv_matrix);
    if (d->metal_rough) {
        /* glTF's metallic-roughness: the physically based integrators read it per hit
         * (metal_rough_bsdf), Whitted too (material_phong); ks and ns here are the factors' Phong
         * look: a highlight of lerp(0.04, base, metallic), Blinn-Phong exponent 2 / alpha^2 - 2
         * (alpha = r^2) */
        float metallic = render_fminf(render_fmaxf(d->metallic, 0.0f), 1.0f), r = render_fminf(render_fmaxf(d->roughness, 0.0f), 1.0f);
        m.type = RP_MATERIAL_PHONG;
        m.metal_rough = true;
        m.metallic = metallic;
        m.roughness = r;
        m.metal_rough_texture = d->map_metal_rough - 1;
        for (int k = 0; k < 3; k++) m.ks[k] = 0.04f * (1.0f - metallic) + render_fminf(render_fmaxf(d->kd[k], 0.0f), 1.0f) * metallic;
        float alpha = render_fmaxf(r * r, 0.01f);
        m.ns = render_fmaxf(2.0f / (alpha * alpha) - 2.0f, 1.0f);
        return m;
    }
    if (any_positive(d->kt)) {
        m.type = RP_MATERIAL_DIELECTRIC;
        memcpy(m.dielectric.kt, d->kt, sizeof m.dielectric.kt);
        m.dielectric.ior = d->ior > 0.0f ? d->ior : 1.5f;
    } else if (any_positive(d->kr)) {
        m.type = RP_MATERIAL_MIRROR;
        memcpy(m.mirror.kr, d->kr, sizeof m.mirror.kr);
    } else if (any_positive(d->ks)) {
        m.type = RP_MATERIAL_PHONG;
    } else {
        m.type = RP_MATERIAL_DIFFUSE;
    }
    return m;
}

/* One axis of a lookup: the texel coordinate c in [0, 1] (u, or 1 - v: rows run down) after the
 * wrap mode, then the two texels a bilinear lookup blends (i[0] weighted 1 - *a, i[1] weighted *a)
 * or, NEAREST, the one texel c falls in (both i, *a = 0). flip: c is 1 - the wrapped coordinate.
 * Repeat wraps f to [0, 1) first, as ever; clamp and mirror fold it into [0, 1] (mirror: a
 * triangle wave of period 2, so MIRRORED_REPEAT's texel mirroring at each edge, as OpenGL's). */
/* Inlined (with texture_taps) into each lookup: out of line, the two calls were a third of the
 * texture time of a kitchen frame. */
static inline __attribute__((always_inline)) void texture_axis(float f, int32_t n, rp_texture_wrap wrap,
                                                               rp_texture_filter filter, bool flip, int32_t i[2],
                                                               float *a) {
    switch (wrap) {
    case RP_TEXTURE_CLAMP:
        f = render_fminf(render_fmaxf(f, 0.0f), 1.0f); /* NaN to 0 */
        break;
    case RP_TEXTURE_MIRROR:
        f -= 2.0f * floorf(0.5f * f);
        if (!(f >= 0.0f && f < 2.0f)) f = 0.0f; /* NaN, infinities */
        if (f > 1.0f) f = 2.0f - f;
        break;
    case RP_TEXTURE_REPEAT:
    default:
        f -= floorf(f);
        if (!(f >= 0.0f && f < 1.0f)) f = 0.0f; /* NaN or a rounding of floor */
        break;
    }
    float c = flip ? 1.0f - f : f;
    bool repeat = wrap != RP_TEXTURE_CLAMP && wrap != RP_TEXTURE_MIRROR;
    if (filter == RP_TEXTURE_NEAREST) {
        int32_t k = (int32_t)floorf(c * (float)n); /* in [0, n]: n at the far edge */
        i[0] = i[1] = k < n ? k : repeat ? 0 : n - 1;
        *a = 0.0f;
        return;
    }
    float x = c * (float)n - 0.5f, x0f = floorf(x);
    int32_t x0 = (int32_t)x0f;
    *a = x - x0f;
    /* x0 is in [-1, n - 1] (n where c n rounds up): repeat wraps one step either way (no
     * division), the others read the edge texel (a folded coordinate's neighbour across the edge
     * is the edge texel itself) */
    for (int k = 0; k < 2; k++) {
        int32_t xk = x0 + k;
        i[k] = xk < 0 ? (repeat ? xk + n : 0) : xk >= n ? (repeat ? xk - n : n - 1) : xk;
    }
}

/* The four texels a lookup at uv reads (offsets of texel (x, y): y * width + x) and their weights,
 * under the texture's wrap modes and filter (NEAREST: one texel of weight 1, three of 0); false
 * for a texture without texels. v = 0 is the bottom row (OBJ), the data's first row is the top one. */
static inline __attribute__((always_inline)) bool texture_taps(const rp_texture_data *t, const float uv[2],
                                                               size_t at[4], float w[4]) {
    if (!t->rgb || t->width <= 0 || t->height <= 0) return false;
    int32_t xs[2], ys[2];
    float ax, ay;
    texture_axis(uv[0], t->width, t->wrap_u, t->filter, false, xs, &ax);
    texture_axis(uv[1], t->height, t->wrap_v, t->filter, true, ys, &ay);
    w[0] = (1 - ax) * (1 - ay), w[1] = ax * (1 - ay), w[2] = (1 - ax) * ay, w[3] = ax * ay;
    for (int j = 0; j < 4; j++) at[j] = (size_t)ys[j >> 1] * (size_t)t->width + (size_t)xs[j & 1];
    return true;
}

/* A lookup under the texture's sampler (texture_taps); srgb: the bytes are sRGB-encoded colours, else linear data. */
static v3 texture_lookup(const rp_render_scene *s, int32_t texture, const float uv[2], bool srgb) {
    if (texture < 0 || (size_t)texture >= s->data->texture_count) return v3_make(1, 1, 1);
    const rp_texture_data *t = &s->data->textures[texture];
    size_t at[4];
    float w[4];
    if (!texture_taps(t, uv, at, w)) return v3_make(1, 1, 1);
    float c[3] = {0, 0, 0};
    for (int j = 0; j < 4; j++) {
        const uint8_t *px = t->rgb + at[j] * 3;
        for (int k = 0; k < 3; k++) c[k] += w[j] * (srgb ? s->srgb_to_linear[px[k]] : (float)px[k] * (1.0f / 255.0f));
    }
    return v3_make(c[0], c[1], c[2]);
}

float material_texture_alpha(const rp_render_scene *s, int32_t texture, const float uv[2]) {
    if (texture < 0 || (size_t)texture >= s->data->texture_count) return 1.0f;
    const rp_texture_data *t = &s->data->textures[texture];
    size_t at[4];
    float w[4];
    if (!texture_taps(t, uv, at, w)) return 1.0f;
    float a = 0.0f;
    for (int j = 0; j < 4; j++) a += w[j] * (float)(t->alpha ? t->alpha[at[j]] : t->rgb[3 * at[j]]) * (1.0f / 255.0f);
    return a;
}

v3 material_texture(const rp_render_scene *s, int32_t texture, const float uv[2]) {
    return texture_lookup(s, texture, uv, true);
}

v3 material_albedo(const rp_render_scene *s, const rp_material *m, const render_surface *surf) {
    v3 kd = v3_mul(v3_load(m->kd), surf->color);
    if (m->texture >= 0 && surf->has_uv) kd = v3_mul(kd, material_texture(s, m->texture, surf->uv));
    return kd;
}

/* The highlight's colour: ks times its texture (MTL map_Ks), as map_Kd multiplies kd. */
static v3 material_specular(const rp_render_scene *s, const rp_material *m, const render_surface *surf) {
    v3 ks = v3_load(m->ks);
    if (m->specular_texture >= 0 && surf->has_uv) ks = v3_mul(ks, material_texture(s, m->specular_texture, surf->uv));
    return ks;
}

float material_fresnel(float cos_i, float eta) {
    float sin2_t = eta * eta * (1.0f - cos_i * cos_i);
    if (sin2_t >= 1.0f) return 1.0f; /* total internal reflection */
    float cos_t = sqrtf(1.0f - sin2_t);
    float rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    float rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return 0.5f * (rs * rs + rp * rp);
}

/* ---- physically based materials ----
 *
 * How the scene files' materials map onto the BSDFs (bsdf.c), for the physically based integrators
 * (Whitted keeps its Phong shading):
 *   - Kd alone (MTL illum 0-2 with Ks 0, NFF/AFF with Ks 0, the built-in room's walls): Lambert,
 *     albedo Kd times map_Kd (sRGB decoded), each channel clamped to [0, 1].
 *   - Kd with Ks > 0 and no mirror (MTL illum 2, NFF Phong highlights): plastic, a diffuse base
 *     Kd (1 - max Ks) under a GGX coat weighted by Ks, roughness alpha = sqrt(2 / (Ns + 2)) (the
 *     Blinn-Phong exponent's equivalent, Walter et al. 2007).
 *   - a mirror (MTL illum 3/5/7 Ks, NFF Ks with T 0): with Kd 0 a smooth conductor whose normal
 *     reflectance is Kr (eta 1, k = 2 sqrt(Kr / (1 - Kr))); with Kd > 0 a plastic with a smooth
 *     coat of weight Kr over that diffuse base.
 *   - transmission (MTL d < 1 / Tr > 0 / Tf with illum 4/6/7/9, NFF T > 0): a smooth dielectric of
 *     index Ni (NFF index_of_refraction; 1.5 when absent), transmission tinted by Kt.
 *   - glTF's metallic-roughness (assimp's glTF reader): metal_rough_bsdf.
 *   - emission: MTL Ke is the emitted radiance on the front side (that of the geometric normal,
 *     counter-clockwise winding); a material with Ke 0 and Ka above 1 in some channel emits Ka
 *     instead (the classic cornell_box's `Ka 20` light, tinyobjloader's and Mitsuba's importers'
 *     convention; MTL only); Ka at most 1 is an ambient colour and ignored, as there is no ambient
 *     term. An emission texture (MTL map_Ke, glTF's emissive texture, AFF's textured ambient-only
 *     surfaces) multiplies Ke; such a surface is not sampled as a light (light.c), it adds its
 *     radiance where a ray hits it, which path tracing weighs in full (no MIS partner). */

static float clamp01(float x) { return render_fminf(render_fmaxf(x, 0.0f), 1.0f); }
static v3 clamp3(v3 c) { return v3_make(clamp01(c.x), clamp01(c.y), clamp01(c.z)); }

/* glTF's metallic-roughness model on the plastic BSDF with the specification's Fresnel (glTF 2.0,
 * appendix B: mix(dielectric, metal, metallic)): a GGX coat (alpha = r^2; smooth under r^2 = 1e-3)
 * whose reflectance is Schlick's Fresnel of F0 = lerp(0.04, base, metallic), rising to 1 at grazing
 * angles, over a diffuse base of base (1 - metallic) that loses the dielectric's F(0.04). The
 * texture's green channel scales roughness and its blue channel metallic (linear). */
static void metal_rough_at(const rp_render_scene *s, const rp_material *m, const render_surface *surf,
                           float *metallic, float *r) {
    *metallic = m->metallic, *r = m->roughness;
    if (m->metal_rough_texture >= 0 && surf->has_uv) {
        v3 t = material_texture_linear(s, m->metal_rough_texture, surf->uv);
        *r *= t.y;
        *metallic *= t.z;
    }
}

static void metal_rough_bsdf(const rp_render_scene *s, const rp_material *m, const render_surface *surf,
                             render_bsdf *b) {
    float metallic, r;
    metal_rough_at(s, m, surf, &metallic, &r);
    v3 base = b->kd; /* the base colour (times its texture), clamped */
    b->type = BSDF_PLASTIC;
    b->schlick = true;
    b->ks = v3_add(v3_scale(v3_make(0.04f, 0.04f, 0.04f), 1.0f - metallic), v3_scale(base, metallic));
    b->kd = v3_scale(base, 1.0f - metallic);
    b->alpha = r * r >= 1e-3f ? r * r : 0.0f;
}

void material_phong(const rp_render_scene *s, const rp_material *m, const render_surface *surf, v3 *kd, v3 *ks,
                    float *ns) {
    *kd = material_albedo(s, m, surf);
    if (!m->metal_rough) {
        *ks = material_specular(s, m, surf);
        *ns = m->ns;
        return;
    }
    /* metallic-roughness: rp_material_from_data's Phong look, per hit (its textures) */
    float metallic, r;
    metal_rough_at(s, m, surf, &metallic, &r);
    v3 base = clamp3(*kd);
    *ks = v3_add(v3_scale(v3_make(0.04f, 0.04f, 0.04f), 1.0f - metallic), v3_scale(base, metallic));
    /* kd stays the base colour: a metal has no diffuse term, and under Whitted's point lights (no
     * environment, no glossy reflection) it would be black but for its highlights */
    float alpha = render_fmaxf(r * r, 0.01f);
    *ns = render_fmaxf(2.0f / (alpha * alpha) - 2.0f, 1.0f);
}

render_bsdf material_bsdf(const rp_render_scene *s, const rp_material *m, const render_surface *surf) {
    render_bsdf b;
    memset(&b, 0, sizeof b);
    b.kd = clamp3(material_albedo(s, m, surf));
    b.entering = surf->entering;
    switch (m->type) {
    case RP_MATERIAL_DIFFUSE:
        b.type = BSDF_LAMBERT;
        break;
    case RP_MATERIAL_PHONG:
        if (m->metal_rough) {
            metal_rough_bsdf(s, m, surf, &b);
            break;
        }
        b.type = BSDF_PLASTIC;
        b.ks = clamp3(material_specular(s, m, surf));
        b.alpha = sqrtf(2.0f / (render_fmaxf(m->ns, 0.0f) + 2.0f));
        if (m->roughness_texture >= 0 && surf->has_uv) {
            /* a roughness map holds perceptual roughness r (linear); alpha = r^2, at least 1e-3 */
            float r = material_texture_linear(s, m->roughness_texture, surf->uv).x;
            b.alpha = render_fmaxf(1e-3f, r * r);
        }
        break;
    case RP_MATERIAL_MIRROR: {
        v3 kr = clamp3(v3_load(m->mirror.kr));
        if (v3_max_abs(b.kd) < 1e-6f) {
            b.type = BSDF_CONDUCTOR;
            b.eta = v3_make(1, 1, 1);
            b.k = bsdf_conductor_k_from_reflectance(kr);
            b.ks = v3_make(1, 1, 1);
        } else {
            b.type = BSDF_PLASTIC;
            b.ks = kr;
        }
        break;
    }
    case RP_MATERIAL_DIELECTRIC:
        b.type = BSDF_DIELECTRIC;
        b.kt = clamp3(v3_load(m->dielectric.kt));
        b.ior = m->dielectric.ior > 0.0f ? m->dielectric.ior : 1.5f;
        break;
    }
    return b;
}

v3 material_ke_compute(const rp_render_scene *s, uint32_t material) {
    const rp_material *m = rp_render_scene_material(s, material);
    v3 ke = v3_load(m->ke);
    if (v3_is_zero(ke) && material < s->data->material_count && s->data->materials[material].illum >= 0) {
        v3 ka = v3_load(s->data->materials[material].ka);
        if (v3_max_abs(ka) > 1.0f) ke = ka;
    }
    return v3_make(render_fmaxf(ke.x, 0.0f), render_fmaxf(ke.y, 0.0f), render_fmaxf(ke.z, 0.0f));
}

v3 material_ke(const rp_render_scene *s, uint32_t material) {
    if (material < s->material_ke_count) return s->material_ke[material];
    return material_ke_compute(s, material);
}

v3 material_ke_textured(const rp_render_scene *s, const rp_material *m, v3 ke, const render_surface *surf) {
    if (m->emission_texture < 0 || !surf->has_uv) return ke;
    return v3_mul(ke, material_texture(s, m->emission_texture, surf->uv));
}

v3 material_emission(const rp_render_scene *s, uint32_t material, const render_surface *surf) {
    if (!surf->entering) return v3_make(0, 0, 0);
    return material_ke_textured(s, rp_render_scene_material(s, material), material_ke(s, material), surf);
}

v3 material_texture_linear(const rp_render_scene *s, int32_t texture, const float uv[2]) {
    return texture_lookup(s, texture, uv, false);
}

void material_normal_map(const rp_render_scene *s, const rp_material *m, render_surface *surf) {
    if (m->normal_texture < 0 || !surf->has_uv || v3_is_zero(surf->dpdu)) return;
    v3 c = material_texture_linear(s, m->normal_texture, surf->uv);
    v3 n = surf->ns;
    v3 t = v3_sub(surf->dpdu, v3_scale(n, v3_dot(n, surf->dpdu)));
    if (!(v3_dot(t, t) > 0.0f)) return;
    t = v3_normalize(t);
    v3 b = v3_cross(n, t);
    v3 p = v3_add(v3_add(v3_scale(t, 2.0f * c.x - 1.0f), v3_scale(b, 2.0f * c.y - 1.0f)), v3_scale(n, 2.0f * c.z - 1.0f));
    p = v3_normalize(p);
    /* keep it on the side the ray came from, as scene_surface's normals are */
    if (v3_dot(p, surf->ng) > 0.0f) surf->ns = p;
}
