/* The tile renderer and the integrators (eye light, Whitted, AOVs). Tiles go to the device's
 * threads. Whitted traces n x n packets breadth first per ray kind (Overbeck et al. 2008, sec. 5);
 * the reference tracer (packet < 0), eye light and the AOVs trace a tile's primary rays as one
 * coherent array and secondary rays one by one. A pixel's value depends only on the pixel, and both
 * Whitted tracers share the shading arithmetic, so images depend neither on the thread count nor on
 * the packet settings. */
#include "render.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

rp_render_desc rp_render_desc_defaults(const rp_render_desc *desc) {
    rp_render_desc d;
    memset(&d, 0, sizeof d);
    if (desc) d = *desc;
    if (d.width <= 0) d.width = 512;
    if (d.height <= 0) d.height = 512;
    if (d.spp <= 0) d.spp = 1;
    if (d.sample_start < 0) d.sample_start = 0;
    if (d.max_depth == 0) d.max_depth = 5;
    if (d.max_depth < 0) d.max_depth = 0;
    if (d.tile_size <= 0) d.tile_size = 16;
    if (d.ambient == 0.0f) d.ambient = 0.08f;
    if (d.ambient < 0.0f) d.ambient = 0.0f;
    if (d.packet == 0) d.packet = 16;
    return d;
}

int rp_render_channels(const rp_render_desc *desc) {
    if (desc && desc->integrator == RP_INTEGRATOR_AOV && desc->aov == RP_AOV_DEPTH) return 1;
    return 3;
}

/* What one Whitted ray found: the radiance so far and what is still to be traced for it (shadow
 * rays to the lights, a reflection and a refraction ray with their multipliers). Shared by the
 * depth-first and the packet tracer, so that both do the same float operations in the same order. */
typedef struct whitted_slot {
    v3 color;               /* background on a miss; ke + ambient, then + direct, then + children */
    v3 direct;              /* sum of the unoccluded lights, in light order */
    v3 org, ns, ng, kd, dir; /* shading point (lifted off the surface) for the shadow rays */
    const rp_material *m;
    bool lit, highlight;    /* lit: the ray hit a surface, whose lights must be gathered */
    bool has_r, has_t;      /* a reflection / refraction ray follows */
    float w_r, w_t;         /* path weights of the children */
    v3 mul_r, mul_t;        /* what the children's radiance is multiplied by */
    v3 org_r, dir_r, org_t, dir_t;
} whitted_slot;

/* One depth of the packet tracer: the packet of rays at that depth and their slots. */
typedef struct whitted_level {
    rp_rayhit_n rh;
    int32_t *valid;
    float *weight;
    whitted_slot *slots;
    /* what auto learns about this level's packets (rp_auto_tally), per ray kind: which way pays
     * differs by kind and by depth (primary rays, then the bounces); a frame's packets start afresh */
    rp_auto_tally tally[RP_RAY_KIND_COUNT];
} whitted_level;

/* Per-thread state, padded so counters of different threads do not share a cache line. */
typedef struct render_thread {
    _Alignas(64) uint64_t rays[RP_RAY_KIND_COUNT];
    rp_rayhit *rayhits; /* tile_size^2 primary rays */
    float *accum;       /* tile_size^2 * 3 */
    whitted_level **levels;  /* max_depth + 1, each made on first use */
    rp_rayhit_n shadow;      /* the shadow packet and its per-ray light contributions */
    int32_t *shadow_valid;
    v3 *shadow_contrib;
    rp_counters_n *work;     /* RP_RAY_KIND_COUNT, or NULL when work is not counted */
} render_thread;

typedef struct render_frame {
    rp_render_scene *s;
    rp_render_desc desc;
    render_camera cam;
    const rp_light_source *lights;
    size_t light_count;
    rp_light_source headlight;
    v3 background;
    int channels;
    float *pixels;
    uint32_t tiles_x, tiles_y;
    uint32_t tile;             /* tile side in pixels (a multiple of the packet side) */
    int rx0, ry0, rx1, ry1;    /* the region rendered (desc.region, or the whole image); tiles start at its corner */
    bool packets;              /* Whitted in n x n packets */
    rp_traversal traversal[RP_RAY_KIND_COUNT];
    render_thread *threads;
    atomic_uint tiles_done;
    atomic_uint_least64_t rays_done;
    atomic_flag reporting;
    atomic_bool failed;        /* a thread ran out of memory */
} render_frame;

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* Distance secondary rays start off the surface, along the geometric normal. */
static float ray_offset(const rp_render_scene *s) { return 2e-5f * s->scale; }


/* Shading of a Whitted hit without the rays it spawns: the local terms, the shading point the
 * shadow rays start from, and the reflection and refraction rays with their weights. */
static void whitted_surface(const render_frame *f, const rp_ray *ray, const rp_hit *hit, int depth, float weight,
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
    v3 dir = v3_make(ray->dir_x, ray->dir_y, ray->dir_z);
    v3 kd = material_albedo(s, m, &sf);
    o->color = v3_add(v3_load(m->ke), v3_scale(kd, f->desc.ambient));
    bool more = depth < f->desc.max_depth;
    float eps = ray_offset(s);
    float cos_i = -v3_dot(dir, sf.ns);
    if (cos_i < 0.0f) cos_i = 0.0f;
    v3 refl = v3_normalize(v3_madd(dir, sf.ns, 2.0f * cos_i));
    if (v3_dot(refl, sf.ng) <= 0.0f) refl = v3_normalize(v3_madd(dir, sf.ng, -2.0f * v3_dot(dir, sf.ng)));
    v3 above = v3_madd(sf.p, sf.ng, eps);
    o->lit = true;
    o->direct = v3_make(0, 0, 0);
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
        if (more && w > 1e-3f) {
            o->has_r = true;
            o->w_r = w;
            o->mul_r = kr;
            o->org_r = above;
            o->dir_r = refl;
        }
        break;
    }
    case RP_MATERIAL_DIELECTRIC: {
        if (!more) break;
        float ior = m->dielectric.ior;
        float eta = sf.entering ? 1.0f / ior : ior;
        float fr = material_fresnel(cos_i, eta);
        if (weight * fr > 1e-3f) {
            o->has_r = true;
            o->w_r = weight * fr;
            o->mul_r = v3_make(fr, fr, fr); /* fr * c is c * fr: the product is exact either way */
            o->org_r = above;
            o->dir_r = refl;
        }
        v3 kt = v3_scale(v3_load(m->dielectric.kt), 1.0f - fr);
        float wt = weight * v3_max_abs(kt);
        if (fr < 1.0f && wt > 1e-3f) {
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

/* The shadow ray of a lit slot towards a light and the light it brings when unoccluded (Phong lobe
 * of the material); false when the light cannot reach the point, so no ray is needed. */
static bool whitted_light(const render_frame *f, const whitted_slot *o, const rp_light_source *light, rp_ray *sr,
                          v3 *contrib) {
    v3 pos, intensity;
    bool inverse_square;
    switch (light->type) {
    case RP_LIGHT_SOURCE_POINT:
        pos = v3_load(light->point.position);
        intensity = v3_load(light->point.intensity);
        inverse_square = light->point.inverse_square;
        break;
    default:
        return false;
    }
    float eps = ray_offset(f->s);
    v3 to = v3_sub(pos, o->org);
    float dist = v3_length(to);
    if (!(dist > eps)) return false;
    v3 l = v3_scale(to, 1.0f / dist);
    float cos_s = v3_dot(o->ns, l);
    if (cos_s <= 0.0f || v3_dot(o->ng, l) <= 0.0f) return false;
    render_ray_init(sr, o->org, l, dist * (1.0f - 1e-5f) - eps);
    if (inverse_square) intensity = v3_scale(intensity, 1.0f / (dist * dist));
    v3 term = v3_scale(o->kd, cos_s);
    if (o->highlight) {
        /* Phong: reflect the light direction about the shading normal, compare with the eye. */
        v3 r = v3_sub(v3_scale(o->ns, 2.0f * cos_s), l);
        float rv = -v3_dot(r, o->dir);
        if (rv > 0.0f) term = v3_add(term, v3_scale(v3_load(o->m->ks), powf(rv, o->m->ns)));
    }
    *contrib = v3_mul(intensity, term);
    return true;
}

/* ---- the reference tracer: one ray at a time, depth first ---- */

static v3 whitted_trace(const render_frame *f, render_thread *th, v3 org, v3 dir, rp_ray_kind kind,
                        int depth, float weight);

static v3 whitted_shade(const render_frame *f, render_thread *th, const rp_ray *ray, const rp_hit *hit,
                        int depth, float weight) {
    whitted_slot o;
    whitted_surface(f, ray, hit, depth, weight, &o);
    if (!o.lit) return o.color;
    for (size_t i = 0; i < f->light_count; i++) {
        rp_ray sr;
        v3 contrib;
        if (!whitted_light(f, &o, &f->lights[i], &sr, &contrib)) continue;
        th->rays[RP_RAY_SHADOW]++;
        rp_occluded1(f->s->scene, &sr);
        if (sr.tfar < 0.0f) continue;
        o.direct = v3_add(o.direct, contrib);
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
    rp_intersect1(f->s->scene, &rh);
    return whitted_shade(f, th, &rh.ray, &rh.hit, depth, weight);
}

/* ---- the packet tracer: n x n packets, breadth first per ray kind ---- */

/* Level `level` of the thread's packet stack, made on first use; NULL when out of memory. */
static whitted_level *packet_level(const render_frame *f, render_thread *th, int level) {
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
static void packet_set_ray(rp_rayhit_n *p, uint32_t q, v3 org, v3 dir, float tfar) {
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

static rp_query_n_desc packet_query(const render_frame *f, render_thread *th, whitted_level *lv, rp_ray_kind kind) {
    rp_query_n_desc q = {.traversal = f->traversal[kind],
                         .counters = th->work ? &th->work[kind] : NULL,
                         .tally = &lv->tally[kind]};
    rp_frustum_kind fk = RP_FRUSTUM_NONE;
    switch (kind) {
    case RP_RAY_PRIMARY: fk = RP_FRUSTUM_PRIMARY; break;
    case RP_RAY_SHADOW: fk = RP_FRUSTUM_SHADOW; break;
    case RP_RAY_REFLECTION:
    case RP_RAY_REFRACTION: fk = RP_FRUSTUM_SECONDARY; break;
    case RP_RAY_KIND_COUNT: break;
    }
    q.frustum = f->desc.no_frustum ? RP_FRUSTUM_NONE : fk;
    return q;
}

/* Gathers the lights of every lit slot of a level: one shadow packet per light, aimed at the light
 * (slots that need no shadow ray are simply not live in it). */
static void packet_shadows(const render_frame *f, render_thread *th, whitted_level *lv) {
    uint32_t nn = (uint32_t)f->desc.packet * (uint32_t)f->desc.packet;
    rp_rayhit_n *sp = &th->shadow;
    for (size_t i = 0; i < f->light_count; i++) {
        const rp_light_source *light = &f->lights[i];
        uint64_t live = 0;
        for (uint32_t q = 0; q < nn; q++) {
            th->shadow_valid[q] = 0;
            if (!lv->valid[q] || !lv->slots[q].lit) continue;
            rp_ray sr;
            if (!whitted_light(f, &lv->slots[q], light, &sr, &th->shadow_contrib[q])) continue;
            packet_set_ray(sp, q, v3_make(sr.org_x, sr.org_y, sr.org_z), v3_make(sr.dir_x, sr.dir_y, sr.dir_z),
                           sr.tfar);
            th->shadow_valid[q] = -1;
            live++;
        }
        if (!live) continue;
        th->rays[RP_RAY_SHADOW] += live;
        rp_query_n_desc qd = packet_query(f, th, lv, RP_RAY_SHADOW);
        switch (light->type) {
        case RP_LIGHT_SOURCE_POINT:
            for (int k = 0; k < 3; k++) qd.point[k] = light->point.position[k];
            break;
        default:
            qd.frustum = RP_FRUSTUM_NONE;
            break;
        }
        sp->valid = th->shadow_valid;
        rp_occluded_n(f->s->scene, &qd, sp);
        for (uint32_t q = 0; q < nn; q++)
            if (th->shadow_valid[q] && !(sp->tfar[q] < 0.0f))
                lv->slots[q].direct = v3_add(lv->slots[q].direct, th->shadow_contrib[q]);
    }
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
    whitted_level *down = packet_level(f, th, level + 1);
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
    rp_query_n_desc qd = packet_query(f, th, lv, kind);
    rp_intersect_n(f->s->scene, &qd, p);
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

static v3 aov_shade(const render_frame *f, const rp_ray *ray, const rp_hit *hit) {
    bool miss = hit->geom_id == RP_INVALID_ID;
    switch (f->desc.aov) {
    case RP_AOV_DEPTH:
        return v3_make(miss ? INFINITY : ray->tfar, 0, 0);
    case RP_AOV_PRIMID: {
        if (miss) return v3_make(0, 0, 0);
        uint32_t h = render_hash(render_hash(hit->geom_id + 1u) ^ hit->prim_id);
        return v3_make((float)(h & 255u) / 255.0f, (float)((h >> 8) & 255u) / 255.0f,
                       (float)((h >> 16) & 255u) / 255.0f);
    }
    case RP_AOV_NORMAL:
    case RP_AOV_ALBEDO: {
        if (miss) return v3_make(0, 0, 0);
        render_surface sf;
        scene_surface(f->s, ray, hit, &sf);
        if (f->desc.aov == RP_AOV_NORMAL) return v3_madd(v3_make(0.5f, 0.5f, 0.5f), sf.ns_raw, 0.5f);
        return material_albedo(f->s, &f->s->materials[sf.material], &sf);
    }
    }
    return v3_make(0, 0, 0);
}

static v3 shade_primary(const render_frame *f, render_thread *th, const rp_rayhit *rh) {
    switch (f->desc.integrator) {
    case RP_INTEGRATOR_EYELIGHT: {
        if (rh->hit.geom_id == RP_INVALID_ID) return v3_make(0, 0, 0);
        v3 ng = v3_normalize(v3_make(rh->hit.Ng_x, rh->hit.Ng_y, rh->hit.Ng_z));
        float c = fabsf(v3_dot(ng, v3_make(rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z)));
        if (!(c <= 1.0f)) c = c > 1.0f ? 1.0f : 0.0f; /* NaN from a zero-area triangle */
        return v3_make(c, c, c);
    }
    case RP_INTEGRATOR_WHITTED:
        return whitted_shade(f, th, &rh->ray, &rh->hit, 0, 1.0f);
    case RP_INTEGRATOR_AOV:
        return aov_shade(f, &rh->ray, &rh->hit);
    }
    return v3_make(0, 0, 0);
}

static void report_progress(render_frame *f, uint32_t done) {
    if (!f->desc.progress) return;
    /* Skip the report rather than wait when another thread is in the callback. */
    if (atomic_flag_test_and_set_explicit(&f->reporting, memory_order_acquire)) return;
    f->desc.progress(f->desc.progress_user, done, f->tiles_x * f->tiles_y,
                     atomic_load_explicit(&f->rays_done, memory_order_relaxed));
    atomic_flag_clear_explicit(&f->reporting, memory_order_release);
}

/* Where in pixel (x, y) sample `sample` (an index counted from the first sample of the pixel, not of
 * the frame) goes: sample 0 at the centre, the others jittered. So a frame of samples [k, k+1)
 * accumulated for k = 0..n-1 sums what one n-spp frame sums, in the same order (the viewer's
 * progressive refinement), and a 1-spp frame is the pixel centre as before. */
static void sample_offset(int x, int y, int sample, float *ox, float *oy) {
    *ox = *oy = 0.5f;
    if (sample == 0) return;
    *ox = render_random((uint32_t)x, (uint32_t)y, (uint32_t)sample, 0);
    *oy = render_random((uint32_t)x, (uint32_t)y, (uint32_t)sample, 1);
}

/* Whitted radiance of one n x n block of a tile for sample s, added to the tile's accumulator. */
static bool render_block(const render_frame *f, render_thread *th, int bx, int by, int x0, int y0, int tw, int tile_h,
                         int s) {
    const rp_render_desc *d = &f->desc;
    uint32_t n = (uint32_t)d->packet;
    whitted_level *lv = packet_level(f, th, 0);
    if (!lv) return false;
    for (uint32_t j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            uint32_t q = rp_packet_n_index(n, i, j);
            int x = bx + (int)i, y = by + (int)j;
            float ox, oy;
            sample_offset(x, y, d->sample_start + s, &ox, &oy);
            /* Rays past the image's edge are made too (the frustum code ignores them) but not live. */
            rp_ray r;
            camera_ray(&f->cam, (float)x + ox, (float)y + oy, &r);
            packet_set_ray(&lv->rh, q, v3_make(r.org_x, r.org_y, r.org_z), v3_make(r.dir_x, r.dir_y, r.dir_z), r.tfar);
            lv->valid[q] = x < x0 + tw && y < y0 + tile_h ? -1 : 0;
            lv->weight[q] = 1.0f;
        }
    if (!packet_trace(f, th, 0, RP_RAY_PRIMARY)) return false;
    for (uint32_t j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            uint32_t q = rp_packet_n_index(n, i, j);
            if (!lv->valid[q]) continue;
            int k = (by + (int)j - y0) * tw + (bx + (int)i - x0);
            v3 c = lv->slots[q].color;
            th->accum[3 * k + 0] += c.x;
            th->accum[3 * k + 1] += c.y;
            th->accum[3 * k + 2] += c.z;
        }
    return true;
}

static void render_tile(void *user, uint32_t index, uint32_t thread) {
    render_frame *f = user;
    render_thread *th = &f->threads[thread];
    const rp_render_desc *d = &f->desc;
    if (atomic_load_explicit(&f->failed, memory_order_relaxed)) return;
    int ts = (int)f->tile;
    int x0 = f->rx0 + (int)(index % f->tiles_x) * ts, y0 = f->ry0 + (int)(index / f->tiles_x) * ts;
    int x1 = x0 + ts < f->rx1 ? x0 + ts : f->rx1, y1 = y0 + ts < f->ry1 ? y0 + ts : f->ry1;
    int tw = x1 - x0, n = tw * (y1 - y0);
    int spp = d->integrator == RP_INTEGRATOR_AOV ? 1 : d->spp;
    int first = d->integrator == RP_INTEGRATOR_AOV ? 0 : d->sample_start; /* AOVs: the pixel centre */
    uint64_t rays_before = 0;
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) rays_before += th->rays[k];
    memset(th->accum, 0, (size_t)n * 3 * sizeof(float));
    for (int s = 0; s < spp; s++) {
        if (f->packets) {
            for (int by = y0; by < y1; by += d->packet)
                for (int bx = x0; bx < x1; bx += d->packet)
                    if (!render_block(f, th, bx, by, x0, y0, tw, y1 - y0, s)) {
                        atomic_store(&f->failed, true);
                        return;
                    }
            continue;
        }
        for (int i = 0; i < n; i++) {
            int x = x0 + i % tw, y = y0 + i / tw;
            float ox, oy;
            sample_offset(x, y, first + s, &ox, &oy);
            rp_rayhit *rh = &th->rayhits[i];
            camera_ray(&f->cam, (float)x + ox, (float)y + oy, &rh->ray);
            rh->ray.id = (uint32_t)i;
            rh->hit.geom_id = RP_INVALID_ID;
            rh->hit.prim_id = RP_INVALID_ID;
            rh->hit.inst_id = RP_INVALID_ID;
        }
        rp_intersect_array(f->s->scene, th->rayhits, (size_t)n, RP_QUERY_COHERENT);
        th->rays[RP_RAY_PRIMARY] += (uint64_t)n;
        for (int i = 0; i < n; i++) {
            v3 c = shade_primary(f, th, &th->rayhits[i]);
            th->accum[3 * i + 0] += c.x;
            th->accum[3 * i + 1] += c.y;
            th->accum[3 * i + 2] += c.z;
        }
    }
    float inv = 1.0f / (float)spp;
    for (int i = 0; i < n; i++) {
        int x = x0 + i % tw, y = y0 + i / tw;
        float *out = f->pixels + ((size_t)y * (size_t)d->width + (size_t)x) * (size_t)f->channels;
        if (f->channels == 1) {
            out[0] = th->accum[3 * i];
        } else {
            for (int k = 0; k < 3; k++) out[k] = spp == 1 ? th->accum[3 * i + k] : th->accum[3 * i + k] * inv;
        }
    }
    uint64_t rays_after = 0;
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) rays_after += th->rays[k];
    atomic_fetch_add_explicit(&f->rays_done, rays_after - rays_before, memory_order_relaxed);
    uint32_t done = atomic_fetch_add_explicit(&f->tiles_done, 1u, memory_order_relaxed) + 1u;
    report_progress(f, done);
}

/* Allocates what a thread needs beyond its tile buffers for packet tracing. */
static bool thread_packets_init(const render_frame *f, render_thread *th) {
    uint32_t n = (uint32_t)f->desc.packet, nn = n * n;
    th->levels = calloc((size_t)f->desc.max_depth + 1, sizeof *th->levels);
    th->shadow_valid = calloc(nn, sizeof *th->shadow_valid);
    th->shadow_contrib = calloc(nn, sizeof *th->shadow_contrib);
    if (f->desc.count_work) th->work = calloc(RP_RAY_KIND_COUNT, sizeof *th->work);
    return th->levels && th->shadow_valid && th->shadow_contrib && (!f->desc.count_work || th->work) &&
           rp_rayhit_n_alloc(f->s->device, n, &th->shadow);
}

static void thread_free(const render_frame *f, render_thread *th) {
    free(th->rayhits);
    free(th->accum);
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
    free(th->shadow_contrib);
    free(th->work);
}

/* Traversal per ray kind. AUTO lets the core choose per packet from its coherence. */
static void choose_traversal(const rp_render_desc *d, rp_traversal out[RP_RAY_KIND_COUNT]) {
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) out[k] = d->traversal;
}

bool rp_render(rp_render_scene *scene, const rp_render_desc *desc, float *pixels, rp_render_stats *stats) {
    if (!scene || !pixels) return false;
    double t0 = now_ms();
    rp_render_desc dd = rp_render_desc_defaults(desc);
    bool packets = dd.integrator == RP_INTEGRATOR_WHITTED && dd.packet > 0;
    if (packets && dd.packet != 4 && dd.packet != 8 && dd.packet != 16 && dd.packet != 32) return false;
    switch (dd.traversal) {
    case RP_TRAVERSAL_AUTO:
    case RP_TRAVERSAL_MASKED:
    case RP_TRAVERSAL_RANGED:
    case RP_TRAVERSAL_PARTITION:
    case RP_TRAVERSAL_SPAN:
    case RP_TRAVERSAL_MLRT:
    case RP_TRAVERSAL_SINGLE:
    case RP_TRAVERSAL_SIMD:
        break;
    default:
        return false;
    }
    /* A region (an MPI client's tile): the same pixels, so tiles of it start at its corner; a
     * pixel's value does not depend on which tile or packet holds it. */
    const int *rg = dd.region;
    bool whole = rg[0] == 0 && rg[1] == 0 && rg[2] == 0 && rg[3] == 0;
    if (!whole && !(rg[0] >= 0 && rg[1] >= 0 && rg[0] < rg[2] && rg[1] < rg[3] && rg[2] <= dd.width &&
                    rg[3] <= dd.height))
        return false;
    render_frame *f = calloc(1, sizeof *f);
    if (!f) return false;
    f->rx0 = whole ? 0 : rg[0];
    f->ry0 = whole ? 0 : rg[1];
    f->rx1 = whole ? dd.width : rg[2];
    f->ry1 = whole ? dd.height : rg[3];
    f->s = scene;
    f->desc = dd;
    f->packets = packets;
    choose_traversal(&dd, f->traversal);
    f->channels = rp_render_channels(&f->desc);
    f->pixels = pixels;
    rp_camera cam = f->desc.camera ? *f->desc.camera : rp_render_scene_default_camera(scene);
    camera_setup(&cam, f->desc.width, f->desc.height, &f->cam);
    f->lights = scene->lights;
    f->light_count = scene->light_count;
    if (f->light_count == 0) {
        /* A scene without lights is lit from just above the eye, so that Whitted still shows it
         * with some shadows. */
        float dist = v3_length(v3_sub(v3_load(cam.pinhole.look), f->cam.eye));
        v3 pos = v3_madd(f->cam.eye, f->cam.u, 0.25f * dist);
        /* Inside a building the raised light could end up in a wall or on the floor above: then
         * it sits at the eye itself. */
        rp_ray probe;
        render_ray_init(&probe, f->cam.eye, f->cam.u, 0.25f * dist);
        rp_occluded1(scene->scene, &probe);
        if (probe.tfar < 0.0f) pos = f->cam.eye;
        f->headlight.type = RP_LIGHT_SOURCE_POINT;
        f->headlight.point = (rp_point_light){.intensity = {1, 1, 1}};
        f->headlight.point.position[0] = pos.x;
        f->headlight.point.position[1] = pos.y;
        f->headlight.point.position[2] = pos.z;
        f->lights = &f->headlight;
        f->light_count = 1;
    }
    const rp_scene_data *d = scene->data;
    f->background = d->has_background ? v3_load(d->background) : v3_make(0, 0, 0);
    /* Packet blocks never straddle tiles: a tile is a whole number of packets. */
    uint32_t ts = (uint32_t)f->desc.tile_size;
    if (packets) {
        uint32_t n = (uint32_t)f->desc.packet;
        ts = (ts < n ? n : ts + n - 1) / n * n;
    }
    f->tile = ts;
    f->tiles_x = ((uint32_t)(f->rx1 - f->rx0) + ts - 1) / ts;
    f->tiles_y = ((uint32_t)(f->ry1 - f->ry0) + ts - 1) / ts;
    atomic_init(&f->tiles_done, 0u);
    atomic_init(&f->rays_done, 0u);
    atomic_flag_clear(&f->reporting);
    atomic_init(&f->failed, false);

    int nthreads = rp_device_thread_count(scene->device);
    if (nthreads < 1) nthreads = 1;
    f->threads = aligned_alloc(64, (size_t)nthreads * sizeof *f->threads);
    bool ok = f->threads != NULL;
    if (ok) memset(f->threads, 0, (size_t)nthreads * sizeof *f->threads);
    for (int i = 0; ok && i < nthreads; i++) {
        size_t bytes = ((size_t)ts * ts * sizeof(rp_rayhit) + 63u) & ~(size_t)63u;
        f->threads[i].rayhits = aligned_alloc(64, bytes);
        f->threads[i].accum = malloc((size_t)ts * ts * 3 * sizeof(float));
        ok = f->threads[i].rayhits && f->threads[i].accum;
        if (ok && packets) ok = thread_packets_init(f, &f->threads[i]);
    }
    if (ok) {
        rp_device_parallel_for(scene->device, f->tiles_x * f->tiles_y, render_tile, f);
        ok = !atomic_load(&f->failed);
        if (ok && f->desc.progress)
            f->desc.progress(f->desc.progress_user, f->tiles_x * f->tiles_y, f->tiles_x * f->tiles_y,
                             atomic_load(&f->rays_done));
    }
    if (stats) {
        memset(stats, 0, sizeof *stats);
        for (int i = 0; ok && i < nthreads; i++)
            for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
                stats->rays[k] += f->threads[i].rays[k];
                if (f->threads[i].work) rp_counters_n_add(&stats->work[k], &f->threads[i].work[k]);
            }
        stats->render_ms = now_ms() - t0;
    }
    for (int i = 0; f->threads && i < nthreads; i++) thread_free(f, &f->threads[i]);
    free(f->threads);
    free(f);
    return ok;
}
