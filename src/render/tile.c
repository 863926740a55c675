/* The tile renderer: tiles go to the device's threads, each integrator renders a tile's samples
 * into the thread's accumulator (linear float), and the tile's mean goes into the frame. Whitted
 * traces n x n packets breadth first per ray kind (integrator/whitted.c); the reference tracer
 * (packet < 0), eye light and the AOVs trace a tile's primary rays as one coherent array; the
 * physically based integrators are in integrator/pbr.c. A pixel's value depends only on the pixel
 * and its samples, so images depend neither on the thread count nor on the tile order. */
#include "render.h"

#include <stdatomic.h>
#include <stdio.h>
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
    if (d.packet == 0) d.packet = 16;
    if (d.sample_start < 0) d.sample_start = 0;
    return d;
}

int rp_render_channels(const rp_render_desc *desc) {
    if (desc && desc->integrator == RP_INTEGRATOR_AOV && desc->aov == RP_AOV_DEPTH) return 1;
    return 3;
}

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void report_progress(render_frame *f, uint32_t done) {
    if (!f->desc.progress) return;
    /* Skip the report rather than wait when another thread is in the callback. */
    if (atomic_flag_test_and_set_explicit(&f->reporting, memory_order_acquire)) return;
    f->desc.progress(f->desc.progress_user, done, f->tiles_x * f->tiles_y * (uint32_t)f->passes,
                     atomic_load_explicit(&f->rays_done, memory_order_relaxed));
    atomic_flag_clear_explicit(&f->reporting, memory_order_release);
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
    bool pbr = f->pbr != NULL;
    /* One sample of an integrator that adds each pixel's colour once (all but path tracing and
     * instant radiosity) continues the sum after the tile, sum + (0 + c) being sum + c: the sum's
     * rows, cold in memory, are fetched while the tile renders instead of stalling its start. */
    bool add_after = d->accumulate && !pbr && spp == 1 && f->channels == 3;
    if (add_after) {
        for (int y = y0; y < y1; y++) {
            const char *in = (const char *)(f->pixels + ((size_t)y * (size_t)d->width + (size_t)x0) * 3);
            for (size_t b = 0; b < (size_t)tw * 3 * sizeof(float); b += 64) __builtin_prefetch(in + b, 1, 3);
            __builtin_prefetch(in + (size_t)tw * 3 * sizeof(float) - 1, 1, 3);
        }
        memset(th->accum, 0, (size_t)n * 3 * sizeof(float));
    } else if (d->accumulate) { /* the sum so far, which this frame's samples continue: row by row */
        for (int y = y0; y < y1; y++) {
            const float *in = f->pixels + ((size_t)y * (size_t)d->width + (size_t)x0) * (size_t)f->channels;
            float *acc = th->accum + (size_t)(y - y0) * (size_t)tw * 3;
            if (f->channels == 3) memcpy(acc, in, (size_t)tw * 3 * sizeof(float));
            else
                for (int x = 0; x < tw; x++) acc[3 * x] = acc[3 * x + 1] = acc[3 * x + 2] = in[x];
        }
    } else {
        memset(th->accum, 0, (size_t)n * 3 * sizeof(float));
    }
    if (pbr && !pbr_tile(f, th, x0, y0, x1, y1)) {
        atomic_store(&f->failed, true);
        return;
    }
    for (int s = pbr ? spp : 0; s < spp; s++) {
        if (f->packets) {
            for (int by = y0; by < y1; by += d->packet)
                for (int bx = x0; bx < x1; bx += d->packet)
                    if (!(d->integrator == RP_INTEGRATOR_EYELIGHT
                              ? eyelight_block(f, th, bx, by, x0, y0, tw, y1 - y0, d->sample_start + s)
                              : whitted_block(f, th, bx, by, x0, y0, tw, y1 - y0, d->sample_start + s))) {
                        atomic_store(&f->failed, true);
                        return;
                    }
            continue;
        }
        for (int i = 0; i < n; i++) {
            int x = x0 + i % tw, y = y0 + i / tw;
            float ox, oy;
            render_sample_offset(x, y, first + s, &ox, &oy);
            rp_rayhit *rh = &th->rayhits[i];
            camera_ray(&f->cam, (float)x + ox, (float)y + oy, &rh->ray);
            rh->ray.id = (uint32_t)i;
            rh->hit.geom_id = RP_INVALID_ID;
            rh->hit.prim_id = RP_INVALID_ID;
            rh->hit.inst_id = RP_INVALID_ID;
        }
        alpha_intersect_array(f->s, th->rayhits, (size_t)n, RP_QUERY_COHERENT);
        th->rays[RP_RAY_PRIMARY] += (uint64_t)n;
        for (int i = 0; i < n; i++) {
            v3 c = d->integrator == RP_INTEGRATOR_EYELIGHT ? eyelight_shade(&th->rayhits[i])
                   : d->integrator == RP_INTEGRATOR_AOV    ? aov_shade(f, &th->rayhits[i].ray, &th->rayhits[i].hit)
                                                           : whitted_shade(f, th, &th->rayhits[i].ray, &th->rayhits[i].hit, 0, 1.0f);
            if (f->s->medium && d->integrator != RP_INTEGRATOR_AOV) c = volume_composite(f, &th->rayhits[i].ray, c);
            th->accum[3 * i + 0] += c.x;
            th->accum[3 * i + 1] += c.y;
            th->accum[3 * i + 2] += c.z;
        }
    }
    float inv = 1.0f / (float)spp;
    /* Instant radiosity's pixels come from its discontinuity buffer, after every tile. Row by row:
     * a division and a modulo per pixel cost a cheap scene's frame some percent. */
    for (int y = y0; d->integrator != RP_INTEGRATOR_IR && y < y1; y++) {
        const float *acc = th->accum + (size_t)(y - y0) * (size_t)tw * 3;
        float *out = f->pixels + ((size_t)y * (size_t)d->width + (size_t)x0) * (size_t)f->channels;
        if (f->channels == 1)
            for (int x = 0; x < tw; x++) out[x] = acc[3 * x];
        else if (add_after)
            for (int i = 0; i < 3 * tw; i++) out[i] += acc[i];
        else if (spp == 1 || d->accumulate)
            memcpy(out, acc, (size_t)tw * 3 * sizeof(float));
        else
            for (int i = 0; i < 3 * tw; i++) out[i] = acc[i] * inv;
    }
    if (d->tile_done && d->integrator != RP_INTEGRATOR_IR) d->tile_done(d->tile_user, x0, y0, x1, y1, thread);
    /* The shared counters only for a progress callback: two locked adds a tile on one cache line
     * were 3% of a cheap scene's frame on 2 threads (cornell_box, Whitted). */
    if (!d->progress) return;
    uint64_t rays_after = 0;
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) rays_after += th->rays[k];
    atomic_fetch_add_explicit(&f->rays_done, rays_after - rays_before, memory_order_relaxed);
    uint32_t done = atomic_fetch_add_explicit(&f->tiles_done, 1u, memory_order_relaxed) + 1u;
    report_progress(f, done);
}

/* Instant radiosity's tiles, final only once its filter has run over the whole frame. */
static void finished_tile(void *user, uint32_t index, uint32_t thread) {
    const render_frame *f = user;
    int ts = (int)f->tile;
    int x0 = f->rx0 + (int)(index % f->tiles_x) * ts, y0 = f->ry0 + (int)(index / f->tiles_x) * ts;
    f->desc.tile_done(f->desc.tile_user, x0, y0, x0 + ts < f->rx1 ? x0 + ts : f->rx1, y0 + ts < f->ry1 ? y0 + ts : f->ry1,
                      thread);
}

/* Traversal per ray kind. AUTO lets the core choose per packet from its coherence. */
static void choose_traversal(const rp_render_desc *d, rp_traversal out[RP_RAY_KIND_COUNT]) {
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) out[k] = d->traversal;
}

/* The desc as rp_render renders it: defaults, Whitted's depths per ray kind, direct lighting's one
 * bounce, ambient occlusion's distance. */
rp_render_desc render_desc_resolve(const rp_render_scene *scene, const rp_render_desc *desc) {
    rp_render_desc dd = rp_render_desc_defaults(desc);
    /* light in a dense medium scatters many times: its default depth is deeper (Russian roulette
     * ends most paths long before) */
    if (scene->medium && (!desc || desc->max_depth == 0)) dd.max_depth = RENDER_MEDIUM_DEPTH;
    bool pbr = dd.integrator == RP_INTEGRATOR_DIRECT || dd.integrator == RP_INTEGRATOR_PATH ||
               dd.integrator == RP_INTEGRATOR_IR || dd.integrator == RP_INTEGRATOR_AO;
    if (pbr && dd.packet < 0) dd.packet = 16; /* the physically based integrators always trace packets */
    /* instant radiosity makes no VPLs in a medium: direct lighting renders it (integrator/volume.c) */
    if (scene->medium && dd.integrator == RP_INTEGRATOR_IR) dd.integrator = RP_INTEGRATOR_DIRECT;
    if (dd.integrator == RP_INTEGRATOR_DIRECT) dd.max_depth = 1;
    /* Whitted's depths per ray kind: given ones replace max_depth for their kind, which then covers
     * both; resolved to a positive depth or -1 (none) */
    int depth_r = dd.reflect_depth > 0 ? dd.reflect_depth : dd.reflect_depth < 0 ? 0 : dd.max_depth;
    int depth_t = dd.refract_depth > 0 ? dd.refract_depth : dd.refract_depth < 0 ? 0 : dd.max_depth;
    if (dd.integrator == RP_INTEGRATOR_WHITTED && (dd.reflect_depth || dd.refract_depth)) dd.max_depth = depth_r > depth_t ? depth_r : depth_t;
    dd.reflect_depth = depth_r > 0 ? depth_r : -1;
    dd.refract_depth = depth_t > 0 ? depth_t : -1;
    if (dd.integrator == RP_INTEGRATOR_AO && !(dd.ao_distance > 0.0f)) dd.ao_distance = 0.1f * scene->radius;
    return dd;
}

/* The frame's camera, lights (a headlight when the scene has no point light) and background, from f->s and
 * f->desc. */
void render_frame_view(render_frame *f) {
    rp_render_scene *scene = f->s;
    rp_camera cam = f->desc.camera ? *f->desc.camera : rp_render_scene_default_camera(scene);
    camera_setup(&cam, f->desc.width, f->desc.height, &f->cam);
    f->lights = scene->lights;
    f->light_count = scene->light_count;
    bool any_point = false;
    for (size_t i = 0; i < f->light_count; i++) any_point |= f->lights[i].type == RP_LIGHT_SOURCE_POINT;
    if (!any_point) {
        /* A scene without (point) lights is lit from just above the eye, so that Whitted still
         * shows it with some shadows: Whitted sees no spot or directional light. */
        float dist = v3_length(v3_sub(v3_load(cam.pinhole.look), f->cam.eye));
        v3 pos = v3_madd(f->cam.eye, f->cam.u, 0.25f * dist);
        /* Inside a building the raised light could end up in a wall or on the floor above: then
         * it sits at the eye itself. */
        rp_ray probe;
        render_ray_init(&probe, f->cam.eye, f->cam.u, 0.25f * dist);
        alpha_occluded1(scene, &probe);
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
}

bool rp_render(rp_render_scene *scene, const rp_render_desc *desc, float *pixels, rp_render_stats *stats) {
    if (!scene || !pixels) return false;
    double t0 = now_ms();
    rp_render_desc dd = render_desc_resolve(scene, desc);
    bool pbr = dd.integrator == RP_INTEGRATOR_DIRECT || dd.integrator == RP_INTEGRATOR_PATH ||
               dd.integrator == RP_INTEGRATOR_IR || dd.integrator == RP_INTEGRATOR_AO;
    /* with a medium, eye light and Whitted go ray by ray, each composited with the medium's opacity */
    bool packets = (dd.integrator == RP_INTEGRATOR_WHITTED || dd.integrator == RP_INTEGRATOR_EYELIGHT) && dd.packet > 0 &&
                   !scene->medium;
    if ((packets || pbr) && dd.packet != 4 && dd.packet != 8 && dd.packet != 16 && dd.packet != 32) return false;
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
    if (dd.accumulate && dd.integrator == RP_INTEGRATOR_IR) return false;
    /* a camera with no frame would trace NaN rays (or one line of rays) into a wrong image */
    rp_camera cam = dd.camera ? *dd.camera : rp_render_scene_default_camera(scene);
    if (!camera_valid(&cam)) return false;
    render_frame *f = calloc(1, sizeof *f);
    if (!f) return false;
    f->ox0 = f->rx0 = whole ? 0 : rg[0];
    f->oy0 = f->ry0 = whole ? 0 : rg[1];
    f->ox1 = f->rx1 = whole ? dd.width : rg[2];
    f->oy1 = f->ry1 = whole ? dd.height : rg[3];
    if (dd.integrator == RP_INTEGRATOR_IR) {
        /* The discontinuity buffer averages each pixel with neighbours up to its radius away: a
         * region renders them too (each pixel's VPL sum depends only on the pixel), then filters
         * its own pixels, as the whole frame would. */
        int r = ir_filter_radius(&dd);
        f->rx0 = f->rx0 - r > 0 ? f->rx0 - r : 0;
        f->ry0 = f->ry0 - r > 0 ? f->ry0 - r : 0;
        f->rx1 = f->rx1 + r < dd.width ? f->rx1 + r : dd.width;
        f->ry1 = f->ry1 + r < dd.height ? f->ry1 + r : dd.height;
        /* Tiles start on the interleaving's N x N blocks, whose pixels see the N^2 sets in an order
         * of the block's own (ir_tile), so a region starts on a block too. */
        int n = dd.ir.interleave > 0 ? dd.ir.interleave : 5;
        f->rx0 -= f->rx0 % n;
        f->ry0 -= f->ry0 % n;
    }
    f->s = scene;
    f->desc = dd;
    f->packets = packets;
#if RENDER_X86_AVX2
    f->avx2 = rp_device_isa(scene->device) >= 8 && __builtin_cpu_supports("avx2");
#endif
    for (uint32_t n = (uint32_t)(dd.packet > 0 ? dd.packet : 4), j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            uint32_t q = rp_packet_n_index(n, i, j);
            f->lane_i[q] = (uint8_t)i;
            f->lane_j[q] = (uint8_t)j;
            f->lane_of[j * n + i] = (uint16_t)q;
        }
    choose_traversal(&dd, f->traversal);
    f->channels = rp_render_channels(&f->desc);
    f->pixels = pixels;
    render_frame_view(f);
    /* Packet blocks never straddle tiles: a tile is a whole number of packets. */
    uint32_t ts = (uint32_t)f->desc.tile_size;
    if (packets) {
        uint32_t n = (uint32_t)f->desc.packet;
        ts = (ts < n ? n : ts + n - 1) / n * n;
    }
    if (pbr) ts = pbr_tile_side(&f->desc);
    f->tile = ts;
    f->tiles_x = ((uint32_t)(f->rx1 - f->rx0) + ts - 1) / ts;
    f->tiles_y = ((uint32_t)(f->ry1 - f->ry0) + ts - 1) / ts;
    f->passes = dd.integrator == RP_INTEGRATOR_IR ? dd.spp : 1;
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
        if (ok && packets) ok = whitted_thread_init(f, &f->threads[i]);
        if (ok && pbr) ok = pbr_thread_init(f, &f->threads[i]);
    }
    if (ok && pbr) ok = pbr_frame_init(f);
    if (ok && dd.bounce_rays && dd.integrator == RP_INTEGRATOR_PATH)
        for (size_t i = 0; i < 2 * (size_t)dd.width * (size_t)dd.height; i++)
            render_ray_init(&dd.bounce_rays[i], v3_make(0, 0, 0), v3_make(0, 0, 1), -1.0f);
    if (ok) {
        /* Instant radiosity filters each sample's image across tiles: one pass of tiles a sample. */
        for (int pass = 0; ok && pass < f->passes; pass++) {
            f->pass = pass;
            rp_device_parallel_for(scene->device, f->tiles_x * f->tiles_y, render_tile, f);
            ok = !atomic_load(&f->failed);
            if (ok && pbr) pbr_frame_finish(f);
        }
        if (ok && f->desc.tile_done && f->desc.integrator == RP_INTEGRATOR_IR)
            rp_device_parallel_for(scene->device, f->tiles_x * f->tiles_y, finished_tile, f);
        if (ok && f->desc.progress)
            f->desc.progress(f->desc.progress_user, f->tiles_x * f->tiles_y * (uint32_t)f->passes,
                             f->tiles_x * f->tiles_y * (uint32_t)f->passes,
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
    for (int i = 0; f->threads && i < nthreads; i++) {
        free(f->threads[i].rayhits);
        free(f->threads[i].accum);
        whitted_thread_free(f, &f->threads[i]);
        pbr_thread_free(f, &f->threads[i]);
    }
    pbr_frame_free(f);
    free(f->threads);
    free(f);
    return ok;
}
