/* What the integrators do with a participating medium (medium.h):
 * - path and direct: volumetric path tracing. Delta tracking samples where a ray's first real
 *   collision lies before its surface hit; there the path scatters (its throughput times the
 *   albedo), takes one light sample by next-event estimation, weighted by the Henyey-Greenstein
 *   phase function and the ratio-tracking transmittance of the shadow ray, MIS (power heuristic)
 *   against phase sampling, and continues in a phase-sampled direction, with the surfaces'
 *   Russian roulette and --max-depth counting scattering events as bounces. A ray that gets
 *   through shades its hit (or the environment) as without a medium. Direct lighting is single
 *   scattering (max depth 1).
 * - eyelight and whitted: the medium's opacity along the primary ray, 1 - T (T by ray marching),
 *   over what the ray sees behind it: white for eye light, the albedo for Whitted.
 * - ao: 1 - T of the primary ray, plus T times the occlusion of the surface behind.
 * - ir: has no VPLs in a medium; it renders direct lighting instead (render_desc_resolve). */
#include "../medium.h"
#include "pbr.h"

static float max3(v3 c) { return render_fmaxf(c.x, render_fmaxf(c.y, c.z)); }

/* The tracking numbers of one path vertex: a stream of its own, seeded by the pixel's sampler,
 * the sample and the depth (and which of the vertex's estimates it is). */
static medium_rng vertex_rng(const pbr_path *st, uint32_t which) {
    return medium_rng_seed(st->rng.key, st->rng.index, (uint32_t)st->depth * 4u + which);
}

int volume_path_vertex(const render_frame *f, render_thread *th, pbr_path *st, const rp_rayhit *rh, rp_rayhit *next,
                       uint32_t *nshadow) {
    const rp_render_scene *s = f->s;
    const render_medium *m = s->medium;
    v3 org = v3_make(rh->ray.org_x, rh->ray.org_y, rh->ray.org_z), dir = v3_make(rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z);
    medium_rng rng = vertex_rng(st, 0);
    float t;
    if (!medium_sample_collision(m, org, dir, rh->ray.tfar, &rng, &t)) return -1;
    v3 p = v3_madd(org, dir, t);
    st->beta = v3_mul(st->beta, m->albedo);
    if (st->depth >= f->desc.max_depth || !(max3(st->beta) > 0.0f)) return 0;
    uint32_t base = 2u + (uint32_t)st->depth * 8u;
    pbr_thread *pt = th->pbr;
    /* Next-event estimation: one light, chosen by power. */
    if (s->pb_light_count) {
        float pmf;
        uint32_t li = light_pick(&s->light_pick, sampler_at(&st->rng, base), &pmf);
        light_sample ls;
        if (light_sample_li(s, &s->pb_lights[li], p, sampler_at(&st->rng, base + 1), sampler_at(&st->rng, base + 2), &ls) &&
            ls.pdf > 0.0f) {
            float ph = medium_phase(m->g, dir, ls.wi), pl = pmf * ls.pdf;
            float w = ls.delta ? 1.0f : pbr_mis(pl, ph);
            v3 c = v3_scale(v3_mul(st->beta, ls.L), ph * w / pl);
            if (max3(c) > 0.0f) {
                float tfar = isfinite(ls.dist) ? ls.dist * (1.0f - 1e-4f) - ray_offset(s) : INFINITY;
                medium_rng trng = vertex_rng(st, 1);
                float tr = medium_transmittance(m, p, ls.wi, tfar, &trng);
                if (tr > 0.0f && tfar > 0.0f) {
                    uint32_t k = (*nshadow)++;
                    render_ray_init(&pt->shadow[k], p, ls.wi, tfar);
                    pt->shadow_L[k] = v3_scale(c, tr);
                    pt->shadow_pixel[k] = st->pixel;
                }
            }
        }
    }
    /* The bounce: the phase function sampled exactly (its weight is 1). */
    v3 wi = medium_phase_sample(m->g, dir, sampler_at(&st->rng, base + 3), sampler_at(&st->rng, base + 4));
    st->pdf = medium_phase(m->g, dir, wi);
    st->specular = false;
    st->prev = p;
    st->depth++;
    if (st->depth >= 3) {
        float q = render_fminf(0.95f, max3(st->beta));
        if (!(sampler_at(&st->rng, base + 6) < q)) return 0;
        st->beta = v3_scale(st->beta, 1.0f / q);
    }
    pbr_rayhit_reset(next, p, wi);
    return 1;
}

float volume_shadow_transmittance(const render_frame *f, const pbr_path *st, v3 org, v3 dir, float tfar) {
    medium_rng rng = vertex_rng(st, 2);
    return medium_transmittance(f->s->medium, org, dir, tfar, &rng);
}

float volume_primary_opacity(const render_frame *f, const rp_ray *ray) {
    v3 org = v3_make(ray->org_x, ray->org_y, ray->org_z), dir = v3_make(ray->dir_x, ray->dir_y, ray->dir_z);
    return 1.0f - medium_transmittance_march(f->s->medium, org, dir, ray->tfar);
}

v3 volume_composite(const render_frame *f, const rp_ray *ray, v3 behind) {
    return volume_composite_opacity(f, volume_primary_opacity(f, ray), behind);
}

v3 volume_composite_opacity(const render_frame *f, float a, v3 behind) {
    v3 mc = f->desc.integrator == RP_INTEGRATOR_WHITTED ? f->s->medium->albedo : v3_make(1, 1, 1);
    return v3_add(v3_scale(behind, 1.0f - a), v3_scale(mc, a));
}
