/* Path tracing (next-event estimation, MIS with the power heuristic, Russian roulette, max depth),
 * direct lighting (the same with one bounce: light and BSDF sampling with MIS) and ambient
 * occlusion. Wavefront per packet: a block's primary rays are one n x n packet (rp_intersect_n);
 * then, depth by depth, its shadow rays and its bounce rays are one array each through the
 * incoherent path (rp_occluded_array / rp_intersect_array). */
#include "pbr.h"

#include <string.h>

#define PI_F 3.14159265358979323846f

static float max3(v3 c) { return render_fmaxf(c.x, render_fmaxf(c.y, c.z)); }

void path_add_px(render_thread *th, uint32_t pixel, v3 c) {
    if (!(isfinite(c.x) && isfinite(c.y) && isfinite(c.z))) return; /* never let one NaN poison a pixel */
    th->accum[3 * pixel + 0] += c.x;
    th->accum[3 * pixel + 1] += c.y;
    th->accum[3 * pixel + 2] += c.z;
}

/* Shades one path vertex: adds emission and a light sample's contribution (queued as a shadow ray),
 * and samples the bounce into *next. Returns false when the path ends. */
bool path_vertex(const render_frame *f, render_thread *th, pbr_path *st, const rp_rayhit *rh, rp_rayhit *next,
                 uint32_t *nshadow) {
    const rp_render_scene *s = f->s;
    pbr_thread *pt = th->pbr;
    bool ao = f->desc.integrator == RP_INTEGRATOR_AO;
    v3 dir = v3_make(rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z);
    uint32_t base = 2u + (uint32_t)st->depth * 8u;
    if (s->medium) {
        if (!ao) {
            int r = volume_path_vertex(f, th, st, rh, next, nshadow);
            if (r >= 0) return r > 0;
        } else if (st->depth == 0) { /* the medium's opacity, then what shows through it */
            float a = volume_primary_opacity(f, &rh->ray);
            path_add_px(th, st->pixel, v3_scale(st->beta, a));
            st->beta = v3_scale(st->beta, 1.0f - a);
        }
    }
    if (rh->hit.geom_id == RP_INVALID_ID) {
        if (ao || s->env_light < 0) return false;
        v3 le = light_env_radiance(s, dir);
        float w = 1.0f;
        if (!st->specular) w = pbr_mis(st->pdf, s->light_pick.pmf[s->env_light] * light_env_pdf(s, dir));
        path_add_px(th, st->pixel, v3_scale(v3_mul(st->beta, le), w));
        return false;
    }
    render_surface sf;
    scene_surface(s, &rh->ray, &rh->hit, &sf);
    float eps = sf.eps;
    if (ao) {
        v3 t, b;
        bsdf_frame(sf.ns, &t, &b);
        v3 wi = bsdf_to_world(bsdf_cosine_hemisphere(sampler_at(&st->rng, base), sampler_at(&st->rng, base + 1)), t, b, sf.ns);
        if (v3_dot(wi, sf.ng) <= 0.0f) return false;
        uint32_t k = (*nshadow)++;
        render_ray_init(&pt->shadow[k], v3_madd(sf.p, sf.ng, eps), wi, f->desc.ao_distance);
        pt->shadow_L[k] = st->beta; /* 1, less a medium's opacity in front */
        pt->shadow_pixel[k] = st->pixel;
        return false;
    }
    const rp_material *m = &s->materials[sf.material];
    material_normal_map(s, m, &sf);
    v3 le = material_emission(s, sf.material, &sf);
    if (!v3_is_zero(le)) {
        float w = 1.0f;
        int32_t li = -1;
        rp_hit fh = rh->hit;
        scene_hit_flat(s, &fh);
        if (fh.geom_id == s->geom_ids[RENDER_GEOM_TRIANGLES] && s->tri_light) li = s->tri_light[fh.prim_id];
        if (!st->specular && li >= 0) {
            float pl = s->light_pick.pmf[li] * light_triangle_pdf(&s->pb_lights[li], st->prev, sf.p, sf.ng);
            w = pbr_mis(st->pdf, pl);
        }
        path_add_px(th, st->pixel, v3_scale(v3_mul(st->beta, le), w));
    }
    if (st->depth >= f->desc.max_depth) return false;
    render_bsdf bsdf = material_bsdf(s, m, &sf);
    v3 t, b;
    bsdf_frame(sf.ns, &t, &b);
    v3 wo = bsdf_to_local(v3_neg(dir), t, b, sf.ns);
    v3 above = v3_madd(sf.p, sf.ng, eps);
    /* Next-event estimation: one light, chosen by power. */
    if (!bsdf_is_delta(&bsdf) && s->pb_light_count) {
        float pmf;
        uint32_t li = light_pick(&s->light_pick, sampler_at(&st->rng, base), &pmf);
        light_sample ls;
        /* Transmitting BSDFs see lights behind the surface too: their shadow rays start below it. */
        bool transmits = bsdf.type == BSDF_DIELECTRIC;
        if (light_sample_li(s, &s->pb_lights[li], above, sampler_at(&st->rng, base + 1), sampler_at(&st->rng, base + 2),
                            &ls) &&
            (v3_dot(ls.wi, sf.ng) > 0.0f || transmits)) {
            v3 from = v3_dot(ls.wi, sf.ng) > 0.0f ? above : v3_madd(sf.p, sf.ng, -eps);
            v3 wl = bsdf_to_local(ls.wi, t, b, sf.ns);
            v3 fv = v3_scale(bsdf_eval(&bsdf, wo, wl), fabsf(wl.z));
            if (!v3_is_zero(fv) && ls.pdf > 0.0f) {
                float pl = pmf * ls.pdf;
                float w = ls.delta ? 1.0f : pbr_mis(pl, bsdf_pdf(&bsdf, wo, wl));
                v3 c = v3_scale(v3_mul(v3_mul(st->beta, fv), ls.L), w / pl);
                float tfar = isfinite(ls.dist) ? ls.dist * (1.0f - 1e-4f) - eps : INFINITY;
                if (s->medium && max3(c) > 0.0f) c = v3_scale(c, volume_shadow_transmittance(f, st, from, ls.wi, tfar));
                if (max3(c) > 0.0f) {
                    uint32_t k = (*nshadow)++;
                    render_ray_init(&pt->shadow[k], from, ls.wi, tfar);
                    pt->shadow_L[k] = c;
                    pt->shadow_pixel[k] = st->pixel;
                }
            }
        }
    }
    /* The bounce. */
    float u[3] = {sampler_at(&st->rng, base + 3), sampler_at(&st->rng, base + 4), sampler_at(&st->rng, base + 5)};
    bsdf_sample bs;
    if (!bsdf_sample_dir(&bsdf, wo, u, &bs) || !(bs.pdf > 0.0f)) return false;
    v3 wi = bsdf_to_world(bs.wi, t, b, sf.ns);
    bool transmit = bs.wi.z < 0.0f;
    if ((v3_dot(wi, sf.ng) > 0.0f) == transmit) return false; /* the shading normal bent it through */
    st->beta = v3_mul(st->beta, v3_scale(bs.f, fabsf(bs.wi.z) / bs.pdf));
    st->specular = bs.delta;
    st->pdf = bs.pdf;
    st->prev = sf.p;
    st->depth++;
    if (st->depth >= 3) {
        float q = render_fminf(0.95f, max3(st->beta));
        if (!(sampler_at(&st->rng, base + 6) < q)) return false;
        st->beta = v3_scale(st->beta, 1.0f / q);
    }
    pbr_rayhit_reset(next, transmit ? v3_madd(sf.p, sf.ng, -eps) : above, wi);
    return true;
}

/* One n x n block of a tile for one sample. */
static void path_block(const render_frame *f, render_thread *th, int bx, int by, int x0, int y0, int x1, int y1,
                       uint32_t sample) {
    pbr_thread *pt = th->pbr;
    uint32_t n = (uint32_t)f->desc.packet;
    int tw = x1 - x0;
    for (uint32_t j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            uint32_t q = rp_packet_n_index(n, i, j);
            int x = bx + (int)i, y = by + (int)j;
            render_sampler rng = sampler_start_pixel(f->desc.sampler, (uint32_t)x, (uint32_t)y, sample);
            rp_ray r;
            camera_ray(&f->cam, (float)x + sampler_at(&rng, 0), (float)y + sampler_at(&rng, 1), &r);
            packet_set_ray(&pt->prim, q, v3_make(r.org_x, r.org_y, r.org_z), v3_make(r.dir_x, r.dir_y, r.dir_z), r.tfar);
            pt->prim_valid[q] = x < x1 && y < y1 ? -1 : 0;
        }
    pt->prim.valid = pt->prim_valid;
    rp_query_n_desc qd = pbr_query(f, th, RP_RAY_PRIMARY);
    alpha_intersect_n(f->s, &qd, &pt->prim);
    uint32_t count = 0;
    rp_rayhit_n *p = &pt->prim;
    for (uint32_t j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            uint32_t q = rp_packet_n_index(n, i, j);
            if (!pt->prim_valid[q]) continue;
            int x = bx + (int)i, y = by + (int)j;
            pbr_path *st = &pt->paths[count];
            st->beta = v3_make(1, 1, 1);
            st->pdf = 0.0f;
            st->pixel = (uint32_t)((y - y0) * tw + (x - x0));
            st->depth = 0;
            st->specular = true;
            st->rng = sampler_start_pixel(f->desc.sampler, (uint32_t)x, (uint32_t)y, sample);
            rp_rayhit *rh = &pt->bounce[count++];
            render_ray_init(&rh->ray, v3_make(p->org_x[q], p->org_y[q], p->org_z[q]),
                            v3_make(p->dir_x[q], p->dir_y[q], p->dir_z[q]), p->tfar[q]);
            rh->hit = (rp_hit){.Ng_x = p->Ng_x[q], .Ng_y = p->Ng_y[q], .Ng_z = p->Ng_z[q], .u = p->u[q], .v = p->v[q],
                               .prim_id = p->prim_id[q], .geom_id = p->geom_id[q], .inst_id = p->inst_id[q]};
        }
    th->rays[RP_RAY_PRIMARY] += count;
    rp_ray *record = sample == (uint32_t)f->desc.sample_start ? f->desc.bounce_rays : NULL;
    size_t wh = (size_t)f->desc.width * (size_t)f->desc.height;
    while (count) {
        uint32_t nshadow = 0, next = 0;
        for (uint32_t i = 0; i < count; i++) {
            pbr_path st = pt->paths[i];
            rp_rayhit rh = pt->bounce[i];
            if (!path_vertex(f, th, &st, &rh, &pt->bounce[next], &nshadow)) continue;
            if (record && st.depth <= 2) /* the bounce ray just made, for raypack bench */
                record[(size_t)(st.depth - 1) * wh + (size_t)(y0 + (int)st.pixel / tw) * (size_t)f->desc.width +
                       (size_t)(x0 + (int)st.pixel % tw)] = pt->bounce[next].ray;
            pt->paths[next++] = st;
        }
        if (nshadow) {
            alpha_occluded_array(f->s, pt->shadow, nshadow, RP_QUERY_INCOHERENT);
            th->rays[RP_RAY_SHADOW] += nshadow;
            for (uint32_t k = 0; k < nshadow; k++)
                if (!(pt->shadow[k].tfar < 0.0f)) path_add_px(th, pt->shadow_pixel[k], pt->shadow_L[k]);
        }
        if (next) {
            alpha_intersect_array(f->s, pt->bounce, next, RP_QUERY_INCOHERENT);
            th->rays[RP_RAY_BOUNCE] += next;
        }
        count = next;
    }
}

bool path_tile(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1) {
    const rp_render_desc *d = &f->desc;
    for (int s = 0; s < d->spp; s++)
        for (int by = y0; by < y1; by += d->packet)
            for (int bx = x0; bx < x1; bx += d->packet)
                path_block(f, th, bx, by, x0, y0, x1, y1, (uint32_t)(d->sample_start + s));
    return true;
}
