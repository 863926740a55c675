/* The C side of the Python bindings (compiled by cffi in API mode, see _build.py): numpy arrays in
 * and out, tracing split into chunks that run on the device's threads (rp_device_parallel_for),
 * while cffi has released the GIL. A Python scene is always a render scene over an rp_scene_data
 * (loaded from a file, or copied from the caller's arrays with one grey diffuse material), so every
 * scene can be traced and rendered alike. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <raypack.h>
#include <raypack_io.h>
#include <raypack_render.h>

typedef struct rpy_scene {
    rp_device *dev;
    rp_scene_data data; /* borrowed by rs: freed after it */
    rp_render_scene *rs;
    rp_scene *core;
} rpy_scene;

static rp_device *rpy_device_new(int threads) {
    return rp_device_new(&(rp_device_desc){.threads = threads});
}

static rpy_scene *finish(rp_device *dev, rpy_scene *s, char *err, size_t err_size) {
    s->dev = dev;
    s->rs = rp_render_scene_new(dev, &s->data, NULL, err, err_size);
    if (!s->rs) {
        rp_scene_data_free(&s->data);
        free(s);
        return NULL;
    }
    s->core = rp_render_scene_core(s->rs);
    rp_device_retain(dev);
    return s;
}

static rpy_scene *rpy_scene_from_arrays(rp_device *dev, const float *vertices, size_t vertex_count,
                                        const uint32_t *indices, size_t triangle_count, const float *colors,
                                        char *err, size_t err_size) {
    for (size_t i = 0; i < 3 * triangle_count; i++)
        if (indices[i] >= vertex_count) {
            snprintf(err, err_size, "index %u of triangle %zu is out of range (%zu vertices)", indices[i], i / 3,
                     vertex_count);
            return NULL;
        }
    rpy_scene *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    rp_scene_data *d = &s->data;
    d->positions = malloc(3 * sizeof(float) * (vertex_count ? vertex_count : 1));
    d->indices = malloc(3 * sizeof(uint32_t) * (triangle_count ? triangle_count : 1));
    d->tri_materials = calloc(triangle_count ? triangle_count : 1, sizeof(uint32_t));
    d->materials = calloc(1, sizeof(rp_material_data));
    if (colors) d->colors = malloc(3 * sizeof(float) * (vertex_count ? vertex_count : 1));
    if (!d->positions || !d->indices || !d->tri_materials || !d->materials || (colors && !d->colors)) {
        rp_scene_data_free(d);
        free(s);
        snprintf(err, err_size, "out of memory");
        return NULL;
    }
    memcpy(d->positions, vertices, 3 * sizeof(float) * vertex_count);
    memcpy(d->indices, indices, 3 * sizeof(uint32_t) * triangle_count);
    if (colors) memcpy(d->colors, colors, 3 * sizeof(float) * vertex_count);
    d->vertex_count = vertex_count;
    d->triangle_count = triangle_count;
    d->material_count = 1;
    rp_material_data *m = d->materials;
    snprintf(m->name, sizeof m->name, "default");
    m->kd[0] = m->kd[1] = m->kd[2] = 0.8f;
    m->ior = 1.0f;
    m->illum = -1;
    m->map_kd = -1;
    return finish(dev, s, err, err_size);
}

static rpy_scene *rpy_scene_load(rp_device *dev, const char *path, char *err, size_t err_size) {
    rpy_scene *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    if (!rp_scene_data_load(path, &s->data, err, err_size)) {
        free(s);
        return NULL;
    }
    return finish(dev, s, err, err_size);
}

static void rpy_scene_free(rpy_scene *s) {
    if (!s) return;
    rp_render_scene_release(s->rs);
    rp_scene_data_free(&s->data);
    rp_device_release(s->dev);
    free(s);
}

static size_t rpy_scene_triangle_count(const rpy_scene *s) { return s->data.triangle_count; }

static void rpy_scene_bounds(const rpy_scene *s, float *lower, float *upper) {
    rp_bounds b;
    rp_scene_get_bounds(s->core, &b);
    lower[0] = b.lower_x, lower[1] = b.lower_y, lower[2] = b.lower_z;
    upper[0] = b.upper_x, upper[1] = b.upper_y, upper[2] = b.upper_z;
}

/* ---- tracing on the device's threads ---------------------------------------------------------- */

#define RPY_CHUNK 1024

typedef struct trace_job {
    rpy_scene *s;
    const float *org, *dir, *tnear, *tfar;
    size_t n;
    uint32_t flags;
    rp_rayhit *scratch; /* RPY_CHUNK per thread */
    float *t, *u, *v, *ng;
    int32_t *geom_id, *prim_id;
    uint8_t *occluded;
} trace_job;

static void make_ray(const trace_job *j, size_t i, rp_ray *r) {
    memset(r, 0, sizeof *r);
    r->org_x = j->org[3 * i], r->org_y = j->org[3 * i + 1], r->org_z = j->org[3 * i + 2];
    r->dir_x = j->dir[3 * i], r->dir_y = j->dir[3 * i + 1], r->dir_z = j->dir[3 * i + 2];
    r->tnear = j->tnear[i];
    r->tfar = j->tfar[i];
    r->mask = 0xFFFFFFFFu;
    r->id = (uint32_t)i;
}

static void intersect_chunk(void *user, uint32_t index, uint32_t thread) {
    trace_job *j = user;
    size_t base = (size_t)index * RPY_CHUNK, k = j->n - base < RPY_CHUNK ? j->n - base : RPY_CHUNK;
    rp_rayhit *rh = j->scratch + (size_t)thread * RPY_CHUNK;
    for (size_t i = 0; i < k; i++) {
        make_ray(j, base + i, &rh[i].ray);
        memset(&rh[i].hit, 0, sizeof rh[i].hit);
        rh[i].hit.geom_id = RP_INVALID_ID;
    }
    rp_intersect_array(j->s->core, rh, k, j->flags);
    for (size_t i = 0; i < k; i++) {
        size_t o = base + i;
        const rp_hit *h = &rh[i].hit;
        bool hit = h->geom_id != RP_INVALID_ID;
        j->t[o] = hit ? rh[i].ray.tfar : INFINITY;
        j->geom_id[o] = hit ? (int32_t)h->geom_id : -1;
        j->prim_id[o] = hit ? (int32_t)h->prim_id : -1;
        j->u[o] = hit ? h->u : 0.0f;
        j->v[o] = hit ? h->v : 0.0f;
        j->ng[3 * o] = hit ? h->Ng_x : 0.0f;
        j->ng[3 * o + 1] = hit ? h->Ng_y : 0.0f;
        j->ng[3 * o + 2] = hit ? h->Ng_z : 0.0f;
    }
}

static void occluded_chunk(void *user, uint32_t index, uint32_t thread) {
    trace_job *j = user;
    size_t base = (size_t)index * RPY_CHUNK, k = j->n - base < RPY_CHUNK ? j->n - base : RPY_CHUNK;
    rp_ray *r = (rp_ray *)(j->scratch + (size_t)thread * RPY_CHUNK); /* an rp_ray array fits in it */
    for (size_t i = 0; i < k; i++) make_ray(j, base + i, &r[i]);
    rp_occluded_array(j->s->core, r, k, j->flags);
    for (size_t i = 0; i < k; i++) j->occluded[base + i] = r[i].tfar == -INFINITY;
}

static bool run_job(trace_job *j, rp_task_fn fn) {
    if (j->n == 0) return true;
    size_t threads = (size_t)rp_device_thread_count(j->s->dev);
    j->scratch = aligned_alloc(64, threads * RPY_CHUNK * sizeof(rp_rayhit)); /* a multiple of 64 */
    if (!j->scratch) return false;
    size_t chunks = (j->n + RPY_CHUNK - 1) / RPY_CHUNK;
    rp_device_parallel_for(j->s->dev, (uint32_t)chunks, fn, j);
    free(j->scratch);
    return true;
}

static int rpy_intersect(rpy_scene *s, const float *org, const float *dir, const float *tnear,
                          const float *tfar, size_t n, int coherent, float *t, int32_t *geom_id,
                          int32_t *prim_id, float *u, float *v, float *ng) {
    trace_job j = {.s = s, .org = org, .dir = dir, .tnear = tnear, .tfar = tfar, .n = n,
                   .flags = coherent ? RP_QUERY_COHERENT : RP_QUERY_INCOHERENT,
                   .t = t, .u = u, .v = v, .ng = ng, .geom_id = geom_id, .prim_id = prim_id};
    return run_job(&j, intersect_chunk); /* 0: out of memory */
}

static int rpy_occluded(rpy_scene *s, const float *org, const float *dir, const float *tnear,
                         const float *tfar, size_t n, int coherent, uint8_t *out) {
    trace_job j = {.s = s, .org = org, .dir = dir, .tnear = tnear, .tfar = tfar, .n = n,
                   .flags = coherent ? RP_QUERY_COHERENT : RP_QUERY_INCOHERENT, .occluded = out};
    return run_job(&j, occluded_chunk);
}

/* ---- rendering -------------------------------------------------------------------------------- */

static int rpy_render_channels(int integrator, int aov) {
    rp_render_desc d = {.integrator = (rp_integrator_type)integrator, .aov = (rp_aov)aov};
    return rp_render_channels(&d);
}

static int rpy_render(rpy_scene *s, int width, int height, int spp, int integrator, int aov,
                      int have_camera, const float *eye, const float *look, const float *up, float fov,
                      float *pixels, char *err, size_t err_size) {
    rp_camera cam = rp_render_scene_default_camera(s->rs);
    if (have_camera) {
        cam.type = RP_CAMERA_PINHOLE;
        memcpy(cam.pinhole.eye, eye, 3 * sizeof(float));
        memcpy(cam.pinhole.look, look, 3 * sizeof(float));
        memcpy(cam.pinhole.up, up, 3 * sizeof(float));
        cam.pinhole.fov_deg = fov;
    }
    rp_render_desc d = {.width = width, .height = height, .spp = spp,
                        .integrator = (rp_integrator_type)integrator, .aov = (rp_aov)aov, .camera = &cam};
    if (!rp_render(s->rs, &d, pixels, NULL)) {
        snprintf(err, err_size, "rp_render failed (bad arguments or out of memory)");
        return 0;
    }
    return 1;
}
