/* Whitted ray tracing: point lights, hard shadows, mirror reflection and refraction. The reference
 * tracer (one ray at a time, depth first) and the packet tracer (n x n packets, breadth first per ray
 * kind, Overbeck et al. 2008, sec. 5) share the shading arithmetic, so their images are identical. */
#include "../render.h"

#include <stdlib.h>
#include <string.h>



/* The mirror direction of dir about the shading normal, or about the geometric one where that one
 * would send it under the surface; made only for hits that spawn a reflection ray (most hits are
 * diffuse, and the two normalisations were a tenth of whitted_surface). */
static inline v3 reflect_dir(v3 dir, const render_surface *sf, float cos_i) {
    v3 refl = v3_normalize(v3_madd(dir, sf->ns, 2.0f * cos_i));
    if (v3_dot(refl, sf->ng) <= 0.0f) refl = v3_normalize(v3_madd(dir, sf->ng, -2.0f * v3_dot(dir, sf->ng)));
    return refl;
}

/* Shading of a Whitted hit without the rays it spawns: the local terms, the shading point the
 * shadow rays start from, and the reflection and refraction rays with their weights. */
void whitted_surface(const render_frame *f, const rp_ray *ray, const rp_hit *hit, int depth, float weight,
                     whitted_slot *o) {
    o->lit = o->has_r = o->has_t = false;
    if (hit->geom_id == RP_INVALID_ID) {
        o->color = f->background;
        return;
    }
    const rp_render_scene *s = f->s;
    render_surface sf;
    scene_surface(s, ray, hit, &sf);
    const rp_material *m = &s->materials[sf.material];
    material_normal_map(s, m, &sf); /* MTL norm and bump, glTF normal textures */
    v3 dir = v3_make(ray->dir_x, ray->dir_y, ray->dir_z);
    v3 kd;
    material_phong(s, m, &sf, &kd, &o->ks, &o->shininess);
    o->color = v3_add(material_ke_textured(s, m, v3_load(m->ke), &sf), v3_scale(kd, f->desc.ambient));
    /* reflect_depth / refract_depth: resolved by rp_render (positive, or -1 for none) */
    bool more_r = depth < f->desc.reflect_depth, more_t = depth < f->desc.refract_depth;
    float eps = sf.eps;
    float cos_i = -v3_dot(dir, sf.ns);
    if (cos_i < 0.0f) cos_i = 0.0f;
    v3 above = v3_madd(sf.p, sf.ng, eps);
    o->lit = true;
    o->direct = v3_make(0, 0, 0);
    o->eps = eps;
    o->org = above;
    o->ns = sf.ns;
    o->ng = sf.ng;
    o->kd = kd;
    o->dir = dir;
    o->m = m;
    o->highlight = m->type != RP_MATERIAL_DIFFUSE;
    switch (m->type) {
    case RP_MATERIAL_DIFFUSE:
    case RP_MATERIAL_PHONG:
        break;
    case RP_MATERIAL_MIRROR: {
        v3 kr = v3_load(m->mirror.kr);
        float w = weight * v3_max_abs(kr);
        if (more_r && w > 1e-3f) {
            o->has_r = true;
            o->w_r = w;
            o->mul_r = kr;
            o->org_r = above;
            o->dir_r = reflect_dir(dir, &sf, cos_i);
        }
        break;
    }
    case RP_MATERIAL_DIELECTRIC: {
        if (!more_r && !more_t) break;
        float ior = m->dielectric.ior;
        float eta = sf.entering ? 1.0f / ior : ior;
        float fr = material_fresnel(cos_i, eta);
        if (more_r && weight * fr > 1e-3f) {
            o->has_r = true;
            o->w_r = weight * fr;
            o->mul_r = v3_make(fr, fr, fr); /* fr * c is c * fr: the product is exact either way */
            o->org_r = above;
            o->dir_r = reflect_dir(dir, &sf, cos_i);
        }
        v3 kt = v3_scale(v3_load(m->dielectric.kt), 1.0f - fr);
        float wt = weight * v3_max_abs(kt);
        if (more_t && fr < 1.0f && wt > 1e-3f) {
            float cos_t = sqrtf(1.0f - eta * eta * (1.0f - cos_i * cos_i));
            v3 t = v3_normalize(v3_madd(v3_scale(dir, eta), sf.ns, eta * cos_i - cos_t));
            if (v3_dot(t, sf.ng) < 0.0f) {
                o->has_t = true;
                o->w_t = wt;
                o->mul_t = kt;
                o->org_t = v3_madd(sf.p, sf.ng, -eps);
                o->dir_t = t;
            }
        }
        break;
    }
    }
}

/* The shadow ray of a lit slot towards a light and what the light brings when unoccluded (Phong
 * lobe of the material, whitted_light_contrib); false when the light cannot reach the point, so no
 * ray is needed. */
bool whitted_light(const render_frame *f, const whitted_slot *o, const rp_light_source *light, rp_ray *sr,
                   whitted_light_term *lt) {
    (void)f; /* the offset is the slot's now (its surface's), not the scene's */
    v3 pos = v3_make(0, 0, 0), intensity = pos;
    bool inverse_square = false;
    switch (light->type) {
    case RP_LIGHT_SOURCE_POINT:
        pos = v3_load(light->point.position);
        intensity = v3_load(light->point.intensity);
        inverse_square = light->point.inverse_square;
        break;
    case RP_LIGHT_SOURCE_SPOT:
    case RP_LIGHT_SOURCE_DIRECTIONAL:
    case RP_LIGHT_SOURCE_TRIANGLE:
    case RP_LIGHT_SOURCE_ENVIRONMENT:
        return false; /* Whitted sees the files' point lights only */
    }
    float eps = o->eps;
    v3 to = v3_sub(pos, o->org);
    float dist = v3_length(to);
    if (!(dist > eps)) return false;
    v3 l = v3_scale(to, 1.0f / dist);
    float cos_s = v3_dot(o->ns, l);
    if (cos_s <= 0.0f || v3_dot(o->ng, l) <= 0.0f) return false;
    render_ray_init(sr, o->org, l, dist * (1.0f - 1e-5f) - eps);
    if (inverse_square) intensity = v3_scale(intensity, 1.0f / (dist * dist));
    lt->intensity = intensity;
    lt->term = v3_scale(o->kd, cos_s);
    lt->rv = 0.0f;
    if (o->highlight) {
        /* Phong: reflect the light direction about the shading normal, compare with the eye. */
        v3 r = v3_sub(v3_scale(o->ns, 2.0f * cos_s), l);
        lt->rv = -v3_dot(r, o->dir);
    }
    return true;
}

/* The light of whitted_light's term, once its shadow ray found the light unoccluded (the highlight's
 * powf only then: most of a kitchen's shadow rays are occluded). */
v3 whitted_light_contrib(const whitted_slot *o, const whitted_light_term *lt) {
    v3 term = lt->term;
    if (lt->rv > 0.0f) term = v3_add(term, v3_scale(o->ks, powf(lt->rv, o->shininess)));
    return v3_mul(lt->intensity, term);
}

/* ---- the reference tracer: one ray at a time, depth first ---- */

static v3 whitted_trace(const render_frame *f, render_thread *th, v3 org, v3 dir, rp_ray_kind kind,
                        int depth, float weight);

v3 whitted_shade(const render_frame *f, render_thread *th, const rp_ray *ray, const rp_hit *hit,
                        int depth, float weight) {
    whitted_slot o;
    whitted_surface(f, ray, hit, depth, weight, &o);
    if (!o.lit) return o.color;
    for (size_t i = 0; i < f->light_count; i++) {
        rp_ray sr;
        whitted_light_term lt;
        if (!whitted_light(f, &o, &f->lights[i], &sr, &lt)) continue;
        th->rays[RP_RAY_SHADOW]++;
        alpha_occluded1(f->s, &sr);
        if (sr.tfar < 0.0f) continue;
        o.direct = v3_add(o.direct, whitted_light_contrib(&o, &lt));
    }
    v3 c = v3_add(o.color, o.direct);
    if (o.has_r)
        c = v3_add(c, v3_mul(o.mul_r, whitted_trace(f, th, o.org_r, o.dir_r, RP_RAY_REFLECTION, depth + 1, o.w_r)));
    if (o.has_t)
        c = v3_add(c, v3_mul(o.mul_t, whitted_trace(f, th, o.org_t, o.dir_t, RP_RAY_REFRACTION, depth + 1, o.w_t)));
    return c;
}

static v3 whitted_trace(const render_frame *f, render_thread *th, v3 org, v3 dir, rp_ray_kind kind,
                        int depth, float weight) {
    rp_rayhit rh;
    render_ray_init(&rh.ray, org, dir, INFINITY);
    rh.hit.geom_id = RP_INVALID_ID;
    rh.hit.prim_id = RP_INVALID_ID;
    rh.hit.inst_id = RP_INVALID_ID;
    th->rays[kind]++;
    alpha_intersect1(f->s, &rh);
    return whitted_shade(f, th, &rh.ray, &rh.hit, depth, weight);
}

/* ---- the packet tracer: n x n packets, breadth first per ray kind ---- */

/* Level `level` of the thread's packet stack, made on first use; NULL when out of memory. */
whitted_level *whitted_packet_level(const render_frame *f, render_thread *th, int level) {
    if (th->levels[level]) return th->levels[level];
    uint32_t n = (uint32_t)f->desc.packet, nn = n * n;
    whitted_level *lv = calloc(1, sizeof *lv);
    if (!lv) return NULL;
    lv->valid = calloc(nn, sizeof *lv->valid);
    lv->weight = calloc(nn, sizeof *lv->weight);
    lv->slots = calloc(nn, sizeof *lv->slots);
    bool ok = lv->valid && lv->weight && lv->slots && rp_rayhit_n_alloc(f->s->device, n, &lv->rh);
    if (!ok) {
        free(lv->valid);
        free(lv->weight);
        free(lv->slots);
        free(lv);
        return NULL;
    }
    th->levels[level] = lv;
    return lv;
}

/* Sets ray q of a packet (tnear 0, no hit yet). */
void packet_set_ray(rp_rayhit_n *p, uint32_t q, v3 org, v3 dir, float tfar) {
    p->org_x[q] = org.x;
    p->org_y[q] = org.y;
    p->org_z[q] = org.z;
    p->tnear[q] = 0.0f;
    p->dir_x[q] = dir.x;
    p->dir_y[q] = dir.y;
    p->dir_z[q] = dir.z;
    p->tfar[q] = tfar;
    p->geom_id[q] = RP_INVALID_ID;
    p->prim_id[q] = RP_INVALID_ID;
    p->inst_id[q] = RP_INVALID_ID;
}

rp_query_n_desc whitted_packet_query(const render_frame *f, render_thread *th, whitted_level *lv, rp_ray_kind kind) {
    rp_query_n_desc q = {.traversal = f->traversal[kind],
                         .counters = th->work ? &th->work[kind] : NULL,
                         .tally = &lv->tally[kind]};
    rp_frustum_kind fk = RP_FRUSTUM_NONE;
    switch (kind) {
    case RP_RAY_PRIMARY: fk = RP_FRUSTUM_PRIMARY; break;
    case RP_RAY_SHADOW: fk = RP_FRUSTUM_SHADOW; break;
    case RP_RAY_REFLECTION:
    case RP_RAY_REFRACTION: fk = RP_FRUSTUM_SECONDARY; break;
    case RP_RAY_BOUNCE:
    case RP_RAY_KIND_COUNT: break;
    }
    q.frustum = f->desc.no_frustum ? RP_FRUSTUM_NONE : fk;
    return q;
}

/* whitted_light's arithmetic towards the light at pos for every lane of a (see packet_shadows):
 * the shadow packet's directions and ends, live where the light can reach the lit point; returns
 * the live count. */
RENDER_INLINE uint64_t shadow_lanes(uint32_t nn, whitted_shadow_soa *restrict a, v3 pos, float *restrict dx,
                                    float *restrict dy, float *restrict dz, float *restrict tfar,
                                    int32_t *restrict valid) {
    const float px = pos.x, py = pos.y, pz = pos.z;
    uint64_t live = 0;
    for (uint32_t q = 0; q < nn; q++) {
        float tx = px - a->ox[q], ty = py - a->oy[q], tz = pz - a->oz[q];
        float d = sqrtf(tx * tx + ty * ty + tz * tz), inv = 1.0f / d;
        float x = tx * inv, y = ty * inv, z = tz * inv;
        float c = a->nx[q] * x + a->ny[q] * y + a->nz[q] * z, cg = a->gx[q] * x + a->gy[q] * y + a->gz[q] * z;
        /* the mirrored light direction against the eye (Phong) */
        float s2 = 2.0f * c;
        a->rv[q] = -((a->nx[q] * s2 - x) * a->ex[q] + (a->ny[q] * s2 - y) * a->ey[q] + (a->nz[q] * s2 - z) * a->ez[q]);
        a->dist[q] = d, a->cs[q] = c;
        dx[q] = x, dy[q] = y, dz[q] = z, tfar[q] = d * (1.0f - 1e-5f) - a->eps[q];
        int32_t ok = a->lit[q] & (d > a->eps[q] && !(c <= 0.0f) && !(cg <= 0.0f));
        valid[q] = -ok;
        live += (uint64_t)ok;
    }
    return live;
}

/* Gathers the lights of every lit slot of a level: one shadow packet per light, aimed at the light
 * (slots that need no shadow ray are simply not live in it). whitted_light's arithmetic, lane by
 * lane over the level's shading points in SoA (vectorised: CMakeLists.txt compiles this file
 * without errno and FP traps), straight into the packet; the light each unoccluded ray brings
 * (whitted_light_contrib) after the test. The same rays and sums as whitted_light's. */
RENDER_INLINE void packet_shadows_body(const render_frame *f, render_thread *th, whitted_level *lv) {
    uint32_t nn = (uint32_t)f->desc.packet * (uint32_t)f->desc.packet;
    rp_rayhit_n *sp = &th->shadow;
    whitted_shadow_soa *a = th->shadow_soa;
    bool any = false;
    for (uint32_t q = 0; q < nn; q++) {
        const whitted_slot *o = &lv->slots[q];
        bool lit = lv->valid[q] && o->lit;
        any |= lit;
        a->ox[q] = lit ? o->org.x : 0.0f, a->oy[q] = lit ? o->org.y : 0.0f, a->oz[q] = lit ? o->org.z : 0.0f;
        a->nx[q] = lit ? o->ns.x : 0.0f, a->ny[q] = lit ? o->ns.y : 0.0f, a->nz[q] = lit ? o->ns.z : 0.0f;
        a->gx[q] = lit ? o->ng.x : 0.0f, a->gy[q] = lit ? o->ng.y : 0.0f, a->gz[q] = lit ? o->ng.z : 0.0f;
        a->ex[q] = lit ? o->dir.x : 0.0f, a->ey[q] = lit ? o->dir.y : 0.0f, a->ez[q] = lit ? o->dir.z : 0.0f;
        a->eps[q] = lit ? o->eps : 0.0f;
        a->lit[q] = lit;
    }
    if (!any) return;
    /* Origins once per level: every light's rays of a slot leave its shading point. */
    for (uint32_t q = 0; q < nn; q++) {
        sp->org_x[q] = a->ox[q], sp->org_y[q] = a->oy[q], sp->org_z[q] = a->oz[q], sp->tnear[q] = 0.0f;
        sp->geom_id[q] = sp->prim_id[q] = sp->inst_id[q] = RP_INVALID_ID;
    }
    for (size_t i = 0; i < f->light_count; i++) {
        const rp_light_source *light = &f->lights[i];
        if (light->type != RP_LIGHT_SOURCE_POINT) continue; /* Whitted sees the files' point lights only */
        v3 pos = v3_load(light->point.position), intensity = v3_load(light->point.intensity);
        uint64_t live = shadow_lanes(nn, a, pos, sp->dir_x, sp->dir_y, sp->dir_z, sp->tfar, th->shadow_valid);
        if (!live) continue;
        th->rays[RP_RAY_SHADOW] += live;
        rp_query_n_desc qd = whitted_packet_query(f, th, lv, RP_RAY_SHADOW);
        for (int k = 0; k < 3; k++) qd.point[k] = light->point.position[k];
        sp->valid = th->shadow_valid;
        alpha_occluded_n(f->s, &qd, sp);
        for (uint32_t q = 0; q < nn; q++) {
            if (!th->shadow_valid[q] || sp->tfar[q] < 0.0f) continue;
            whitted_slot *o = &lv->slots[q];
            float d = a->dist[q];
            whitted_light_term lt = {
                .intensity = light->point.inverse_square ? v3_scale(intensity, 1.0f / (d * d)) : intensity,
                .term = v3_scale(o->kd, a->cs[q]),
                .rv = o->highlight ? a->rv[q] : 0.0f};
            o->direct = v3_add(o->direct, whitted_light_contrib(o, &lt));
        }
    }
}

static void packet_shadows_base(const render_frame *f, render_thread *th, whitted_level *lv) {
    packet_shadows_body(f, th, lv);
}

#if RENDER_X86_AVX2
__attribute__((target("avx2"))) static void packet_shadows_avx2(const render_frame *f, render_thread *th,
                                                                whitted_level *lv) {
    packet_shadows_body(f, th, lv);
}
#endif

/* The shadow pass of a level, in the AVX2 copy where the frame says so (the same values: render.h,
 * RENDER_X86_AVX2). */
static void packet_shadows(const render_frame *f, render_thread *th, whitted_level *lv) {
#if RENDER_X86_AVX2
    if (f->avx2) {
        packet_shadows_avx2(f, th, lv);
        return;
    }
#endif
    packet_shadows_base(f, th, lv);
}

static bool packet_trace(const render_frame *f, render_thread *th, int level, rp_ray_kind kind);

/* Traces the children of one kind (reflection or refraction) of a level as the packet one level
 * down, and adds their radiance to their parents'. */
static bool packet_children(const render_frame *f, render_thread *th, int level, rp_ray_kind kind) {
    uint32_t nn = (uint32_t)f->desc.packet * (uint32_t)f->desc.packet;
    whitted_level *lv = th->levels[level];
    bool refl = kind == RP_RAY_REFLECTION, any = false;
    for (uint32_t q = 0; q < nn && !any; q++)
        any = lv->valid[q] && (refl ? lv->slots[q].has_r : lv->slots[q].has_t);
    if (!any) return true;
    whitted_level *down = whitted_packet_level(f, th, level + 1);
    if (!down) return false;
    for (uint32_t q = 0; q < nn; q++) {
        const whitted_slot *o = &lv->slots[q];
        bool live = lv->valid[q] && (refl ? o->has_r : o->has_t);
        down->valid[q] = live ? -1 : 0;
        if (!live) continue;
        down->weight[q] = refl ? o->w_r : o->w_t;
        packet_set_ray(&down->rh, q, refl ? o->org_r : o->org_t, refl ? o->dir_r : o->dir_t, INFINITY);
    }
    if (!packet_trace(f, th, level + 1, kind)) return false;
    for (uint32_t q = 0; q < nn; q++) {
        if (!down->valid[q]) continue;
        whitted_slot *o = &lv->slots[q];
        o->color = v3_add(o->color, v3_mul(refl ? o->mul_r : o->mul_t, down->slots[q].color));
    }
    return true;
}

/* Traces the packet of a level (its rays and valid mask set by the caller), gathers its lights,
 * then its reflection and refraction packets: slots[q].color ends as rp_intersect1-by-ray Whitted
 * would leave it. False when out of memory. */
static bool packet_trace(const render_frame *f, render_thread *th, int level, rp_ray_kind kind) {
    uint32_t nn = (uint32_t)f->desc.packet * (uint32_t)f->desc.packet;
    whitted_level *lv = th->levels[level];
    rp_rayhit_n *p = &lv->rh;
    uint64_t live = 0;
    for (uint32_t q = 0; q < nn; q++) live += lv->valid[q] != 0;
    th->rays[kind] += live;
    p->valid = lv->valid;
    rp_query_n_desc qd = whitted_packet_query(f, th, lv, kind);
    alpha_intersect_n(f->s, &qd, p);
    for (uint32_t q = 0; q < nn; q++) {
        if (!lv->valid[q]) continue;
        rp_ray ray;
        render_ray_init(&ray, v3_make(p->org_x[q], p->org_y[q], p->org_z[q]), v3_make(p->dir_x[q], p->dir_y[q], p->dir_z[q]),
                 p->tfar[q]);
        ray.tnear = p->tnear[q];
        rp_hit hit = {.Ng_x = p->Ng_x[q], .Ng_y = p->Ng_y[q], .Ng_z = p->Ng_z[q], .u = p->u[q], .v = p->v[q],
                      .prim_id = p->prim_id[q], .geom_id = p->geom_id[q], .inst_id = p->inst_id[q]};
        whitted_surface(f, &ray, &hit, level, lv->weight[q], &lv->slots[q]);
    }
    packet_shadows(f, th, lv);
    for (uint32_t q = 0; q < nn; q++) {
        whitted_slot *o = &lv->slots[q];
        if (lv->valid[q] && o->lit) o->color = v3_add(o->color, o->direct);
    }
    return packet_children(f, th, level, RP_RAY_REFLECTION) && packet_children(f, th, level, RP_RAY_REFRACTION);
}

uint64_t whitted_primary_rays(const render_frame *f, whitted_level *lv, int bx, int by, int x0, int y0, int tw,
                              int tile_h, int s) {
    uint32_t n = (uint32_t)f->desc.packet, nn = n * n;
    /* Rays past the image's edge are made too (the frustum code ignores them) but not live. */
    camera_rays_n(&f->cam, bx, by, s, nn, f->lane_i, f->lane_j, f->avx2, &lv->rh);
    int xe = x0 + tw - bx, ye = y0 + tile_h - by;
    if (xe >= (int)n && ye >= (int)n) { /* a block inside the tile: every lane */
        memset(lv->valid, 0xFF, nn * sizeof *lv->valid);
        return nn;
    }
    uint64_t live = 0;
    for (uint32_t q = 0; q < nn; q++) {
        bool in = f->lane_i[q] < xe && f->lane_j[q] < ye;
        lv->valid[q] = in ? -1 : 0;
        live += in;
    }
    return live;
}

bool whitted_block(const render_frame *f, render_thread *th, int bx, int by, int x0, int y0, int tw, int tile_h,
                         int s) {
    const rp_render_desc *d = &f->desc;
    uint32_t n = (uint32_t)d->packet;
    whitted_level *lv = whitted_packet_level(f, th, 0);
    if (!lv) return false;
    whitted_primary_rays(f, lv, bx, by, x0, y0, tw, tile_h, s);
    for (uint32_t q = 0; q < n * n; q++) lv->weight[q] = 1.0f;
    if (!packet_trace(f, th, 0, RP_RAY_PRIMARY)) return false;
    for (uint32_t q = 0; q < n * n; q++) {
        if (!lv->valid[q]) continue;
        int k = (by + f->lane_j[q] - y0) * tw + (bx + f->lane_i[q] - x0);
        v3 c = lv->slots[q].color;
        th->accum[3 * k + 0] += c.x;
        th->accum[3 * k + 1] += c.y;
        th->accum[3 * k + 2] += c.z;
    }
    return true;
}

/* Allocates what a thread needs beyond its tile buffers for packet tracing. */
bool whitted_thread_init(const render_frame *f, render_thread *th) {
    uint32_t n = (uint32_t)f->desc.packet, nn = n * n;
    th->levels = calloc((size_t)f->desc.max_depth + 1, sizeof *th->levels);
    th->shadow_valid = calloc(nn, sizeof *th->shadow_valid);
    th->shadow_soa = aligned_alloc(64, sizeof *th->shadow_soa);
    if (f->desc.count_work) th->work = calloc(RP_RAY_KIND_COUNT, sizeof *th->work);
    return th->levels && th->shadow_valid && th->shadow_soa && (!f->desc.count_work || th->work) &&
           rp_rayhit_n_alloc(f->s->device, n, &th->shadow);
}

void whitted_thread_free(const render_frame *f, render_thread *th) {
    for (int l = 0; th->levels && l <= f->desc.max_depth; l++) {
        whitted_level *lv = th->levels[l];
        if (!lv) continue;
        rp_rayhit_n_free(f->s->device, &lv->rh);
        free(lv->valid);
        free(lv->weight);
        free(lv->slots);
        free(lv);
    }
    free(th->levels);
    if (th->shadow.n) rp_rayhit_n_free(f->s->device, &th->shadow);
    free(th->shadow_valid);
    free(th->shadow_soa);
    free(th->work);
}
