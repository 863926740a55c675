/* The tile renderer and the integrators (eye light, Whitted, AOVs). Tiles go to the device's
 * threads; the primary rays of a tile are traced as one coherent array, secondary rays one by one.
 * A pixel's value depends only on the pixel, so images do not depend on the thread count. */
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
    if (d.max_depth == 0) d.max_depth = 5;
    if (d.max_depth < 0) d.max_depth = 0;
    if (d.tile_size <= 0) d.tile_size = 16;
    if (d.ambient == 0.0f) d.ambient = 0.08f;
    if (d.ambient < 0.0f) d.ambient = 0.0f;
    return d;
}

int rp_render_channels(const rp_render_desc *desc) {
    if (desc && desc->integrator == RP_INTEGRATOR_AOV && desc->aov == RP_AOV_DEPTH) return 1;
    return 3;
}

/* Per-thread state, padded so counters of different threads do not share a cache line. */
typedef struct render_thread {
    _Alignas(64) uint64_t rays[RP_RAY_KIND_COUNT];
    rp_rayhit *rayhits; /* tile_size^2 primary rays */
    float *accum;       /* tile_size^2 * 3 */
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
    render_thread *threads;
    atomic_uint tiles_done;
    atomic_uint_least64_t rays_done;
    atomic_flag reporting;
} render_frame;

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* Distance secondary rays start off the surface, along the geometric normal. */
static float ray_offset(const rp_render_scene *s) { return 2e-5f * s->scale; }

static void ray_init(rp_ray *r, v3 org, v3 dir, float tfar) {
    r->org_x = org.x;
    r->org_y = org.y;
    r->org_z = org.z;
    r->tnear = 0.0f;
    r->dir_x = dir.x;
    r->dir_y = dir.y;
    r->dir_z = dir.z;
    r->time = 0.0f;
    r->tfar = tfar;
    r->mask = 0xFFFFFFFFu;
    r->id = 0;
    r->flags = 0;
}

static v3 whitted_trace(const render_frame *f, render_thread *th, v3 org, v3 dir, rp_ray_kind kind,
                        int depth, float weight);

/* Light arriving from point lights through shadow rays, Phong lobe of the material. */
static v3 whitted_direct(const render_frame *f, render_thread *th, const render_surface *sf,
                         const rp_material *m, v3 kd, v3 dir, bool highlight) {
    v3 c = v3_make(0, 0, 0);
    float eps = ray_offset(f->s);
    v3 org = v3_madd(sf->p, sf->ng, eps);
    for (size_t i = 0; i < f->light_count; i++) {
        const rp_light_source *light = &f->lights[i];
        v3 pos, intensity;
        bool inverse_square;
        switch (light->type) {
        case RP_LIGHT_SOURCE_POINT:
            pos = v3_load(light->point.position);
            intensity = v3_load(light->point.intensity);
            inverse_square = light->point.inverse_square;
            break;
        default:
            continue;
        }
        v3 to = v3_sub(pos, org);
        float dist = v3_length(to);
        if (!(dist > eps)) continue;
        v3 l = v3_scale(to, 1.0f / dist);
        float cos_s = v3_dot(sf->ns, l);
        if (cos_s <= 0.0f || v3_dot(sf->ng, l) <= 0.0f) continue;
        rp_ray sr;
        ray_init(&sr, org, l, dist * (1.0f - 1e-5f) - eps);
        th->rays[RP_RAY_SHADOW]++;
        rp_occluded1(f->s->scene, &sr);
        if (sr.tfar < 0.0f) continue;
        if (inverse_square) intensity = v3_scale(intensity, 1.0f / (dist * dist));
        v3 term = v3_scale(kd, cos_s);
        if (highlight) {
            /* Phong: reflect the light direction about the shading normal, compare with the eye. */
            v3 r = v3_sub(v3_scale(sf->ns, 2.0f * cos_s), l);
            float rv = -v3_dot(r, dir);
            if (rv > 0.0f) term = v3_add(term, v3_scale(v3_load(m->ks), powf(rv, m->ns)));
        }
        c = v3_add(c, v3_mul(intensity, term));
    }
    return c;
}

static v3 whitted_shade(const render_frame *f, render_thread *th, const rp_ray *ray, const rp_hit *hit,
                        int depth, float weight) {
    if (hit->geom_id == RP_INVALID_ID) return f->background;
    const rp_render_scene *s = f->s;
    render_surface sf;
    scene_surface(s, ray, hit, &sf);
    const rp_material *m = &s->materials[sf.material];
    v3 dir = v3_make(ray->dir_x, ray->dir_y, ray->dir_z);
    v3 kd = material_albedo(s, m, &sf);
    v3 c = v3_add(v3_load(m->ke), v3_scale(kd, f->desc.ambient));
    bool more = depth < f->desc.max_depth;
    float eps = ray_offset(s);
    float cos_i = -v3_dot(dir, sf.ns);
    if (cos_i < 0.0f) cos_i = 0.0f;
    v3 refl = v3_normalize(v3_madd(dir, sf.ns, 2.0f * cos_i));
    if (v3_dot(refl, sf.ng) <= 0.0f) refl = v3_normalize(v3_madd(dir, sf.ng, -2.0f * v3_dot(dir, sf.ng)));
    v3 above = v3_madd(sf.p, sf.ng, eps);
    switch (m->type) {
    case RP_MATERIAL_DIFFUSE:
        c = v3_add(c, whitted_direct(f, th, &sf, m, kd, dir, false));
        break;
    case RP_MATERIAL_PHONG:
        c = v3_add(c, whitted_direct(f, th, &sf, m, kd, dir, true));
        break;
    case RP_MATERIAL_MIRROR: {
        c = v3_add(c, whitted_direct(f, th, &sf, m, kd, dir, true));
        v3 kr = v3_load(m->mirror.kr);
        float w = weight * v3_max_abs(kr);
        if (more && w > 1e-3f)
            c = v3_add(c, v3_mul(kr, whitted_trace(f, th, above, refl, RP_RAY_REFLECTION, depth + 1, w)));
        break;
    }
    case RP_MATERIAL_DIELECTRIC: {
        c = v3_add(c, whitted_direct(f, th, &sf, m, kd, dir, true));
        if (!more) break;
        float ior = m->dielectric.ior;
        float eta = sf.entering ? 1.0f / ior : ior;
        float fr = material_fresnel(cos_i, eta);
        if (weight * fr > 1e-3f)
            c = v3_add(c, v3_scale(whitted_trace(f, th, above, refl, RP_RAY_REFLECTION, depth + 1, weight * fr), fr));
        v3 kt = v3_scale(v3_load(m->dielectric.kt), 1.0f - fr);
        float wt = weight * v3_max_abs(kt);
        if (fr < 1.0f && wt > 1e-3f) {
            float cos_t = sqrtf(1.0f - eta * eta * (1.0f - cos_i * cos_i));
            v3 t = v3_normalize(v3_madd(v3_scale(dir, eta), sf.ns, eta * cos_i - cos_t));
            if (v3_dot(t, sf.ng) < 0.0f) {
                v3 below = v3_madd(sf.p, sf.ng, -eps);
                c = v3_add(c, v3_mul(kt, whitted_trace(f, th, below, t, RP_RAY_REFRACTION, depth + 1, wt)));
            }
        }
        break;
    }
    }
    return c;
}

static v3 whitted_trace(const render_frame *f, render_thread *th, v3 org, v3 dir, rp_ray_kind kind,
                        int depth, float weight) {
    rp_rayhit rh;
    ray_init(&rh.ray, org, dir, INFINITY);
    rh.hit.geom_id = RP_INVALID_ID;
    rh.hit.prim_id = RP_INVALID_ID;
    rh.hit.inst_id = RP_INVALID_ID;
    th->rays[kind]++;
    rp_intersect1(f->s->scene, &rh);
    return whitted_shade(f, th, &rh.ray, &rh.hit, depth, weight);
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

static void render_tile(void *user, uint32_t index, uint32_t thread) {
    render_frame *f = user;
    render_thread *th = &f->threads[thread];
    const rp_render_desc *d = &f->desc;
    int ts = d->tile_size;
    int x0 = (int)(index % f->tiles_x) * ts, y0 = (int)(index / f->tiles_x) * ts;
    int x1 = x0 + ts < d->width ? x0 + ts : d->width, y1 = y0 + ts < d->height ? y0 + ts : d->height;
    int tw = x1 - x0, n = tw * (y1 - y0);
    int spp = d->integrator == RP_INTEGRATOR_AOV ? 1 : d->spp;
    uint64_t rays_before = 0;
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) rays_before += th->rays[k];
    memset(th->accum, 0, (size_t)n * 3 * sizeof(float));
    for (int s = 0; s < spp; s++) {
        for (int i = 0; i < n; i++) {
            int x = x0 + i % tw, y = y0 + i / tw;
            float ox = 0.5f, oy = 0.5f;
            if (spp > 1) {
                ox = render_random((uint32_t)x, (uint32_t)y, (uint32_t)s, 0);
                oy = render_random((uint32_t)x, (uint32_t)y, (uint32_t)s, 1);
            }
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

bool rp_render(rp_render_scene *scene, const rp_render_desc *desc, float *pixels, rp_render_stats *stats) {
    if (!scene || !pixels) return false;
    double t0 = now_ms();
    render_frame *f = calloc(1, sizeof *f);
    if (!f) return false;
    f->s = scene;
    f->desc = rp_render_desc_defaults(desc);
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
        ray_init(&probe, f->cam.eye, f->cam.u, 0.25f * dist);
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
    uint32_t ts = (uint32_t)f->desc.tile_size;
    f->tiles_x = ((uint32_t)f->desc.width + ts - 1) / ts;
    f->tiles_y = ((uint32_t)f->desc.height + ts - 1) / ts;
    atomic_init(&f->tiles_done, 0u);
    atomic_init(&f->rays_done, 0u);
    atomic_flag_clear(&f->reporting);

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
    }
    if (ok) {
        rp_device_parallel_for(scene->device, f->tiles_x * f->tiles_y, render_tile, f);
        if (f->desc.progress)
            f->desc.progress(f->desc.progress_user, f->tiles_x * f->tiles_y, f->tiles_x * f->tiles_y,
                             atomic_load(&f->rays_done));
    }
    if (stats) {
        memset(stats, 0, sizeof *stats);
        for (int i = 0; ok && i < nthreads; i++)
            for (int k = 0; k < RP_RAY_KIND_COUNT; k++) stats->rays[k] += f->threads[i].rays[k];
        stats->render_ms = now_ms() - t0;
    }
    for (int i = 0; f->threads && i < nthreads; i++) {
        free(f->threads[i].rayhits);
        free(f->threads[i].accum);
    }
    free(f->threads);
    free(f);
    return ok;
}
