/* BSDFs with eval, sample and pdf (pbrt-v4's interface, in C): Lambert, conductor (complex-IOR
 * Fresnel; GGX microfacets with visible-normal sampling, or a mirror), dielectric (Fresnel
 * reflection and refraction; GGX rough transmission after pbrt-v4's DielectricBxDF) and plastic. All work in the local shading frame (z = normal), wo and
 * wi unit and pointing away from the surface. Delta lobes are never returned by eval or pdf; their
 * sample gives f with f cos / pdf equal to the lobe's weight, as pbrt does. */
#include "render.h"


#define PI_F 3.14159265358979323846f

static float lum(v3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }
static float max3(v3 c) { return render_fmaxf(c.x, render_fmaxf(c.y, c.z)); }

void bsdf_frame(v3 n, v3 *t, v3 *b) {
    /* Duff et al. 2017, "Building an orthonormal basis, revisited". */
    float sign = copysignf(1.0f, n.z);
    float a = -1.0f / (sign + n.z), bb = n.x * n.y * a;
    *t = v3_make(1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x);
    *b = v3_make(bb, sign + n.y * n.y * a, -n.y);
}

v3 bsdf_cosine_hemisphere(float u0, float u1) {
    /* Concentric disk mapping (Shirley and Chiu), lifted to the hemisphere (Malley's method). */
    float ox = 2.0f * u0 - 1.0f, oy = 2.0f * u1 - 1.0f, r, phi;
    if (ox == 0.0f && oy == 0.0f) return v3_make(0, 0, 1);
    if (fabsf(ox) > fabsf(oy)) {
        r = ox;
        phi = (PI_F / 4.0f) * (oy / ox);
    } else {
        r = oy;
        phi = PI_F / 2.0f - (PI_F / 4.0f) * (ox / oy);
    }
    float x = r * cosf(phi), y = r * sinf(phi);
    return v3_make(x, y, sqrtf(render_fmaxf(0.0f, 1.0f - x * x - y * y)));
}

/* ---- GGX (Trowbridge-Reitz), isotropic, pbrt-v4's formulation ---- */

static float ggx_d(float alpha, v3 wm) {
    float c2 = wm.z * wm.z;
    if (!(c2 > 0.0f)) return 0.0f;
    float s2 = render_fmaxf(0.0f, 1.0f - c2), t2 = s2 / c2;
    float e = 1.0f + t2 / (alpha * alpha);
    return 1.0f / (PI_F * alpha * alpha * c2 * c2 * e * e);
}

static float ggx_lambda(float alpha, v3 w) {
    float c2 = w.z * w.z;
    if (!(c2 > 0.0f)) return 0.0f;
    float t2 = render_fmaxf(0.0f, 1.0f - c2) / c2;
    return (sqrtf(1.0f + alpha * alpha * t2) - 1.0f) * 0.5f;
}

static float ggx_g1(float alpha, v3 w) { return 1.0f / (1.0f + ggx_lambda(alpha, w)); }
static float ggx_g(float alpha, v3 wo, v3 wi) { return 1.0f / (1.0f + ggx_lambda(alpha, wo) + ggx_lambda(alpha, wi)); }

/* Density of the visible normal wm seen from wo (Heitz 2018). */
static float ggx_pdf_wm(float alpha, v3 wo, v3 wm) {
    return ggx_g1(alpha, wo) / fabsf(wo.z) * ggx_d(alpha, wm) * fabsf(v3_dot(wo, wm));
}

/* Visible normal sampling (Heitz 2018, "Sampling the GGX distribution of visible normals"). */
static v3 ggx_sample_wm(float alpha, v3 wo, float u0, float u1) {
    v3 wh = v3_normalize(v3_make(alpha * wo.x, alpha * wo.y, wo.z));
    if (wh.z < 0.0f) wh = v3_neg(wh);
    v3 t1 = wh.z < 0.99999f ? v3_normalize(v3_cross(v3_make(0, 0, 1), wh)) : v3_make(1, 0, 0);
    v3 t2 = v3_cross(wh, t1);
    float r = sqrtf(u0), phi = 2.0f * PI_F * u1;
    float px = r * cosf(phi), py = r * sinf(phi);
    float h = sqrtf(render_fmaxf(0.0f, 1.0f - px * px));
    float s = (1.0f + wh.z) * 0.5f;
    py = (1.0f - s) * h + s * py;
    float pz = sqrtf(render_fmaxf(0.0f, 1.0f - px * px - py * py));
    v3 nh = v3_add(v3_add(v3_scale(t1, px), v3_scale(t2, py)), v3_scale(wh, pz));
    return v3_normalize(v3_make(alpha * nh.x, alpha * nh.y, render_fmaxf(1e-6f, nh.z)));
}

static v3 reflect(v3 wo, v3 n) { return v3_sub(v3_scale(n, 2.0f * v3_dot(wo, n)), wo); }

/* ---- Fresnel ---- */

/* Complex numbers as pairs: C99's complex division and cabsf go through the slow, Annex G-exact
 * library paths (__divsc3, hypotf), which the Fresnel term does not need. */
typedef struct cpx {
    float re, im;
} cpx;
static cpx c_make(float re, float im) { return (cpx){re, im}; }
static cpx c_add(cpx a, cpx b) { return c_make(a.re + b.re, a.im + b.im); }
static cpx c_sub(cpx a, cpx b) { return c_make(a.re - b.re, a.im - b.im); }
static cpx c_mul(cpx a, cpx b) { return c_make(a.re * b.re - a.im * b.im, a.re * b.im + a.im * b.re); }
static cpx c_div(cpx a, cpx b) {
    float d = b.re * b.re + b.im * b.im;
    return c_make((a.re * b.re + a.im * b.im) / d, (a.im * b.re - a.re * b.im) / d);
}
static float c_norm(cpx a) { return a.re * a.re + a.im * a.im; }
static cpx c_sqrt(cpx a) {
    /* principal root */
    float n = sqrtf(sqrtf(c_norm(a)));
    if (n == 0.0f) return c_make(0, 0);
    float t = 0.5f * atan2f(a.im, a.re);
    return c_make(n * cosf(t), n * sinf(t));
}

static float fresnel_complex1(float cos_i, float eta, float k) {
    cos_i = render_fminf(render_fmaxf(cos_i, 0.0f), 1.0f);
    cpx e = c_make(eta, k), ci = c_make(cos_i, 0.0f);
    float sin2_i = 1.0f - cos_i * cos_i;
    cpx sin2_t = c_div(c_make(sin2_i, 0.0f), c_mul(e, e));
    cpx cos_t = c_sqrt(c_sub(c_make(1.0f, 0.0f), sin2_t));
    cpx ec = c_mul(e, ci), ect = c_mul(e, cos_t);
    float r_parl = c_norm(c_div(c_sub(ec, cos_t), c_add(ec, cos_t)));
    float r_perp = c_norm(c_div(c_sub(ci, ect), c_add(ci, ect)));
    return 0.5f * (r_parl + r_perp);
}

v3 bsdf_fresnel_conductor(float cos_i, v3 eta, v3 k) {
    return v3_make(fresnel_complex1(cos_i, eta.x, k.x), fresnel_complex1(cos_i, eta.y, k.y),
                   fresnel_complex1(cos_i, eta.z, k.z));
}

v3 bsdf_conductor_k_from_reflectance(v3 r) {
    /* With eta = 1, F(0) = k^2 / (4 + k^2), so k = 2 sqrt(r / (1 - r)). */
    float c[3] = {r.x, r.y, r.z};
    for (int i = 0; i < 3; i++) {
        float x = render_fminf(render_fmaxf(c[i], 0.0f), 0.9999f);
        c[i] = 2.0f * sqrtf(x / (1.0f - x));
    }
    return v3_make(c[0], c[1], c[2]);
}

/* Dielectric Fresnel reflectance; cos_i > 0, eta = n_transmitted / n_incident. */
static float fresnel_dielectric(float cos_i, float eta) {
    float sin2_t = (1.0f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0f) return 1.0f;
    float cos_t = sqrtf(1.0f - sin2_t);
    float r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    float r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return 0.5f * (r_parl * r_parl + r_perp * r_perp);
}

/* ---- plastic ---- */

/* Schlick's Fresnel, F0 + (1 - F0) (1 - c)^5, for glTF's metallic-roughness BRDF (the glTF 2.0
 * specification, appendix B): the coat's reflectance F(ks, c) (ks = lerp(0.04, base, metallic)) and
 * its dielectric part's F(0.04, c), which the diffuse base loses. */
static float schlick_w(float c) {
    float m = 1.0f - render_fminf(render_fmaxf(c, 0.0f), 1.0f), m2 = m * m;
    return m2 * m2 * m;
}
static v3 schlick(v3 f0, float c) {
    float w = schlick_w(c);
    return v3_add(f0, v3_scale(v3_sub(v3_make(1, 1, 1), f0), w));
}
static float schlick_base(float c) { return 1.0f - (0.04f + 0.96f * schlick_w(c)); }

/* The probability of sampling the coat seen from wo. */
static float plastic_spec_prob(const render_bsdf *b, v3 wo) {
    float ls, ld;
    if (b->schlick) {
        ls = lum(schlick(b->ks, wo.z));
        ld = lum(b->kd) * schlick_base(wo.z);
    } else {
        ls = lum(b->ks);
        ld = lum(b->kd) * (1.0f - render_fminf(1.0f, max3(b->ks)));
    }
    if (!(ls + ld > 0.0f)) return 0.5f;
    return ls / (ls + ld);
}

/* The diffuse base; glTF's loses the dielectric Fresnel at the viewing angle. (The specification
 * takes it at the half vector, which reflects up to 8% more than arrives at grazing angles for a
 * white base; at wo the coat takes at most F(wo.z), as its half vectors lean towards wo.) */
static v3 plastic_diffuse(const render_bsdf *b, v3 wo) {
    if (!b->schlick) return v3_scale(b->kd, (1.0f - render_fminf(1.0f, max3(b->ks))) / PI_F);
    return v3_scale(b->kd, schlick_base(wo.z) / PI_F);
}

static v3 ggx_reflection_eval(float alpha, v3 wo, v3 wi) {
    v3 wm = v3_add(wo, wi);
    if (v3_dot(wm, wm) == 0.0f) return v3_make(0, 0, 0);
    wm = v3_normalize(wm);
    float v = ggx_d(alpha, wm) * ggx_g(alpha, wo, wi) / (4.0f * wo.z * wi.z);
    return v3_make(v, v, v);
}

static float ggx_reflection_pdf(float alpha, v3 wo, v3 wi) {
    v3 wm = v3_add(wo, wi);
    if (v3_dot(wm, wm) == 0.0f) return 0.0f;
    wm = v3_normalize(wm);
    return ggx_pdf_wm(alpha, wo, wm) / (4.0f * fabsf(v3_dot(wo, wm)));
}

/* ---- rough dielectric (pbrt-v4's DielectricBxDF with GGX), wo.z > 0, eta = n_other / n_this ---- */

/* The generalized half vector of (wo, wi) facing +z, its relative eta, or false when the pair has no
 * microfacet that can connect them. */
static bool rough_dielectric_wm(v3 wo, v3 wi, float eta, v3 *wm, float *etap) {
    float co = wo.z, ci = wi.z;
    if (co == 0.0f || ci == 0.0f) return false;
    bool refl = ci * co > 0.0f;
    *etap = refl ? 1.0f : eta;
    v3 m = v3_add(v3_scale(wi, *etap), wo);
    if (v3_dot(m, m) == 0.0f) return false;
    m = v3_normalize(m);
    if (m.z < 0.0f) m = v3_neg(m);
    if (v3_dot(m, wi) * ci < 0.0f || v3_dot(m, wo) * co < 0.0f) return false;
    *wm = m;
    return true;
}

static v3 rough_dielectric_eval(const render_bsdf *b, v3 wo, v3 wi) {
    float eta = b->entering ? b->ior : 1.0f / b->ior, etap;
    v3 wm;
    if (wo.z <= 0.0f || !rough_dielectric_wm(wo, wi, eta, &wm, &etap)) return v3_make(0, 0, 0);
    float fr = fresnel_dielectric(v3_dot(wo, wm), eta);
    float d = ggx_d(b->alpha, wm), g = ggx_g(b->alpha, wo, wi);
    if (wi.z > 0.0f) {
        float v = d * g * fr / fabsf(4.0f * wi.z * wo.z);
        return v3_make(v, v, v);
    }
    float denom = v3_dot(wi, wm) + v3_dot(wo, wm) / etap;
    denom = denom * denom * wi.z * wo.z;
    float v = d * (1.0f - fr) * g * fabsf(v3_dot(wi, wm) * v3_dot(wo, wm) / denom);
    return v3_scale(b->kt, v / (etap * etap)); /* radiance: 1 / eta^2 */
}

static float rough_dielectric_pdf(const render_bsdf *b, v3 wo, v3 wi) {
    float eta = b->entering ? b->ior : 1.0f / b->ior, etap;
    v3 wm;
    if (wo.z <= 0.0f || !rough_dielectric_wm(wo, wi, eta, &wm, &etap)) return 0.0f;
    float fr = fresnel_dielectric(v3_dot(wo, wm), eta);
    float pv = ggx_pdf_wm(b->alpha, wo, wm);
    if (wi.z > 0.0f) return pv / (4.0f * fabsf(v3_dot(wo, wm))) * fr;
    float denom = v3_dot(wi, wm) + v3_dot(wo, wm) / etap;
    return pv * fabsf(v3_dot(wi, wm)) / (denom * denom) * (1.0f - fr);
}

static bool rough_dielectric_sample(const render_bsdf *b, v3 wo, const float u[3], bsdf_sample *out) {
    float eta = b->entering ? b->ior : 1.0f / b->ior;
    v3 wm = ggx_sample_wm(b->alpha, wo, u[1], u[2]);
    float c = v3_dot(wo, wm);
    float fr = fresnel_dielectric(c, eta);
    if (u[0] < fr) {
        out->wi = reflect(wo, wm);
        if (out->wi.z <= 0.0f) return false;
    } else {
        float sin2_t = render_fmaxf(0.0f, 1.0f - c * c) / (eta * eta);
        if (sin2_t >= 1.0f) return false;
        float cos_t = sqrtf(1.0f - sin2_t);
        out->wi = v3_add(v3_scale(wo, -1.0f / eta), v3_scale(wm, c / eta - cos_t));
        if (out->wi.z >= 0.0f) return false;
    }
    out->f = rough_dielectric_eval(b, wo, out->wi);
    out->pdf = rough_dielectric_pdf(b, wo, out->wi);
    return out->pdf > 0.0f;
}

bool bsdf_is_delta(const render_bsdf *b) {
    switch (b->type) {
    case BSDF_LAMBERT:
    case BSDF_PLASTIC:
        return false;
    case BSDF_CONDUCTOR:
    case BSDF_DIELECTRIC:
        return b->alpha == 0.0f;
    }
    return false;
}

v3 bsdf_eval(const render_bsdf *b, v3 wo, v3 wi) {
    v3 zero = v3_make(0, 0, 0);
    bool reflect_side = wo.z > 0.0f && wi.z > 0.0f;
    switch (b->type) {
    case BSDF_LAMBERT:
        return reflect_side ? v3_scale(b->kd, 1.0f / PI_F) : zero;
    case BSDF_CONDUCTOR: {
        if (!reflect_side || b->alpha == 0.0f) return zero;
        v3 wm = v3_normalize(v3_add(wo, wi));
        v3 fr = v3_mul(bsdf_fresnel_conductor(fabsf(v3_dot(wo, wm)), b->eta, b->k), b->ks);
        return v3_mul(fr, ggx_reflection_eval(b->alpha, wo, wi));
    }
    case BSDF_DIELECTRIC:
        return b->alpha == 0.0f ? zero : rough_dielectric_eval(b, wo, wi);
    case BSDF_PLASTIC: {
        if (!reflect_side) return zero;
        v3 f = plastic_diffuse(b, wo);
        if (b->alpha > 0.0f) {
            v3 coat = b->ks;
            if (b->schlick) coat = schlick(b->ks, v3_dot(wo, v3_normalize(v3_add(wo, wi))));
            f = v3_add(f, v3_mul(coat, ggx_reflection_eval(b->alpha, wo, wi)));
        }
        return f;
    }
    }
    return zero;
}

bool bsdf_eval_constant(const render_bsdf *b, v3 wo, v3 *f) {
    if (b->type != BSDF_PLASTIC || b->alpha != 0.0f) return false;
    /* bsdf_eval's: no coat term at alpha 0, the diffuse base on the reflecting side */
    *f = wo.z > 0.0f ? plastic_diffuse(b, wo) : v3_make(0, 0, 0);
    return true;
}

float bsdf_pdf(const render_bsdf *b, v3 wo, v3 wi) {
    if (b->type == BSDF_DIELECTRIC) return b->alpha == 0.0f ? 0.0f : rough_dielectric_pdf(b, wo, wi);
    bool reflect_side = wo.z > 0.0f && wi.z > 0.0f;
    if (!reflect_side) return 0.0f;
    switch (b->type) {
    case BSDF_LAMBERT:
        return wi.z / PI_F;
    case BSDF_CONDUCTOR:
        return b->alpha == 0.0f ? 0.0f : ggx_reflection_pdf(b->alpha, wo, wi);
    case BSDF_DIELECTRIC:
        return 0.0f;
    case BSDF_PLASTIC: {
        float ps = plastic_spec_prob(b, wo);
        float p = (1.0f - ps) * wi.z / PI_F;
        if (b->alpha > 0.0f) p += ps * ggx_reflection_pdf(b->alpha, wo, wi);
        return p;
    }
    }
    return 0.0f;
}

bool bsdf_sample_dir(const render_bsdf *b, v3 wo, const float u[3], bsdf_sample *out) {
    out->delta = false;
    switch (b->type) {
    case BSDF_LAMBERT: {
        if (wo.z <= 0.0f) return false;
        out->wi = bsdf_cosine_hemisphere(u[1], u[2]);
        if (out->wi.z <= 0.0f) return false;
        out->f = v3_scale(b->kd, 1.0f / PI_F);
        out->pdf = out->wi.z / PI_F;
        return true;
    }
    case BSDF_CONDUCTOR: {
        if (wo.z <= 0.0f) return false;
        if (b->alpha == 0.0f) {
            out->wi = v3_make(-wo.x, -wo.y, wo.z);
            out->f = v3_scale(v3_mul(bsdf_fresnel_conductor(wo.z, b->eta, b->k), b->ks), 1.0f / wo.z);
            out->pdf = 1.0f;
            out->delta = true;
            return true;
        }
        v3 wm = ggx_sample_wm(b->alpha, wo, u[1], u[2]);
        out->wi = reflect(wo, wm);
        if (out->wi.z <= 0.0f) return false;
        out->f = bsdf_eval(b, wo, out->wi);
        out->pdf = ggx_reflection_pdf(b->alpha, wo, out->wi);
        return out->pdf > 0.0f;
    }
    case BSDF_DIELECTRIC: {
        /* wo is on the side the ray came from (z > 0); eta is the other side's index over this one's. */
        if (wo.z <= 0.0f) return false;
        if (b->alpha > 0.0f) return rough_dielectric_sample(b, wo, u, out);
        float eta = b->entering ? b->ior : 1.0f / b->ior;
        float fr = fresnel_dielectric(wo.z, eta);
        out->delta = true;
        if (u[0] < fr) {
            out->wi = v3_make(-wo.x, -wo.y, wo.z);
            out->f = v3_make(fr / wo.z, fr / wo.z, fr / wo.z);
            out->pdf = fr;
            return true;
        }
        float sin2_t = (1.0f - wo.z * wo.z) / (eta * eta);
        float cos_t = sqrtf(render_fmaxf(0.0f, 1.0f - sin2_t));
        out->wi = v3_normalize(v3_make(-wo.x / eta, -wo.y / eta, -cos_t));
        /* Radiance is scaled by 1 / eta^2 across the interface (pbrt's TransportMode::Radiance). */
        float t = (1.0f - fr) / (cos_t * eta * eta);
        out->f = v3_scale(b->kt, t);
        out->pdf = 1.0f - fr;
        return cos_t > 0.0f;
    }
    case BSDF_PLASTIC: {
        if (wo.z <= 0.0f) return false;
        float ps = plastic_spec_prob(b, wo);
        if (u[0] < ps) {
            if (b->alpha == 0.0f) {
                out->wi = v3_make(-wo.x, -wo.y, wo.z);
                out->f = v3_scale(b->schlick ? schlick(b->ks, wo.z) : b->ks, 1.0f / wo.z);
                out->pdf = ps;
                out->delta = true;
                return true;
            }
            v3 wm = ggx_sample_wm(b->alpha, wo, u[1], u[2]);
            out->wi = reflect(wo, wm);
        } else {
            out->wi = bsdf_cosine_hemisphere(u[1], u[2]);
        }
        if (out->wi.z <= 0.0f) return false;
        out->f = bsdf_eval(b, wo, out->wi);
        out->pdf = bsdf_pdf(b, wo, out->wi);
        return out->pdf > 0.0f;
    }
    }
    return false;
}
