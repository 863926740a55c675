/* Shared by test_packets_n.c and test_packets_n_bench.c: a shared scene with a camera and a point
 * light, and the rays of a Whitted frame (primary, shadow, reflection, refraction) with their
 * single-ray reference answers. */
#ifndef PACKETS_N_GEN_H
#define PACKETS_N_GEN_H
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "raypack.h"
#include "raypack_io.h"
#include "rp_test.h"

enum { RAY_PRIMARY, RAY_SHADOW, RAY_REFLECT, RAY_REFRACT, RAY_TYPES };
static const char *ray_names[RAY_TYPES] __attribute__((unused)) = {"primary", "shadow", "reflection", "refraction"};
static const rp_frustum_kind ray_frustum[RAY_TYPES] __attribute__((unused)) = {RP_FRUSTUM_PRIMARY, RP_FRUSTUM_SHADOW, RP_FRUSTUM_SECONDARY,
                                                       RP_FRUSTUM_SECONDARY};
static const rp_traversal modes[] = {RP_TRAVERSAL_MASKED, RP_TRAVERSAL_RANGED, RP_TRAVERSAL_PARTITION,
                                     RP_TRAVERSAL_SPAN,   RP_TRAVERSAL_AUTO,   RP_TRAVERSAL_SINGLE,
                                     RP_TRAVERSAL_SIMD,   RP_TRAVERSAL_MLRT};
static const char *mode_names[] = {"masked", "ranged", "partition", "span", "auto", "single", "simd", "mlrt"};

/* One ray of the image, with its single-ray reference answers. */
typedef struct test_ray {
    rp_ray ray;
    bool live;
    rp_rayhit ref;  /* rp_intersect1 */
    bool occluded;  /* rp_occluded1 */
} test_ray;

typedef struct world {
    const char *name;
    rp_scene_data sd;
    float lo[3], hi[3], light[3];
    float eye[3], look[3], up[3], fov;
} world;

static inline void normalize(float v[3]) {
    float l = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int a = 0; a < 3; a++) v[a] /= l;
}
static inline void cross(const float a[3], const float b[3], float o[3]) {
    o[0] = a[1] * b[2] - a[2] * b[1], o[1] = a[2] * b[0] - a[0] * b[2], o[2] = a[0] * b[1] - a[1] * b[0];
}
static inline float dot(const float a[3], const float b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* The scene of sd with the acceleration structure accel (RP_ACCEL_BVH: the default). */
static inline rp_scene *make_scene_accel(rp_device *dev, const rp_scene_data *sd, rp_accel_type accel) {
    rp_scene *scene = rp_scene_new(dev, &(rp_scene_desc){.accel = accel});
    rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, sd->positions, 0, 0, sd->vertex_count);
    rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, sd->indices, 0, 0, sd->triangle_count);
    rp_geometry_commit(g);
    rp_scene_attach(scene, g);
    rp_geometry_release(g);
    if (sd->sphere_count) {
        rp_geometry *s = rp_geometry_new(dev, RP_GEOMETRY_SPHERE);
        float *c = rp_geometry_new_buffer(s, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, 0, sd->sphere_count);
        for (size_t i = 0; i < sd->sphere_count; i++) {
            memcpy(&c[4 * i], sd->spheres[i].center, 3 * sizeof(float));
            c[4 * i + 3] = sd->spheres[i].radius;
        }
        rp_geometry_commit(s);
        rp_scene_attach(scene, s);
        rp_geometry_release(s);
    }
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    return scene;
}

static inline rp_scene *make_scene(rp_device *dev, const rp_scene_data *sd) {
    return make_scene_accel(dev, sd, RP_ACCEL_BVH);
}

static inline bool load_world(const char *file, const char *name, world *w) {
    char path[1024], err[512];
    memset(w, 0, sizeof *w);
    w->name = name;
    if (!rp_test_scene(file, path, sizeof path)) return false;
    if (!rp_scene_data_load(path, &w->sd, err, sizeof err)) {
        fprintf(stderr, "%s\n", err);
        return false;
    }
    for (int a = 0; a < 3; a++) w->lo[a] = INFINITY, w->hi[a] = -INFINITY;
    for (size_t i = 0; i < w->sd.vertex_count; i++)
        for (int a = 0; a < 3; a++) {
            w->lo[a] = fminf(w->lo[a], w->sd.positions[3 * i + a]);
            w->hi[a] = fmaxf(w->hi[a], w->sd.positions[3 * i + a]);
        }
    float c[3], e[3];
    for (int a = 0; a < 3; a++) c[a] = 0.5f * (w->lo[a] + w->hi[a]), e[a] = w->hi[a] - w->lo[a];
    if (w->sd.camera.valid) {
        memcpy(w->eye, w->sd.camera.eye, sizeof w->eye);
        memcpy(w->look, w->sd.camera.look, sizeof w->look);
        memcpy(w->up, w->sd.camera.up, sizeof w->up);
        w->fov = w->sd.camera.fov_deg;
    } else {
        const float off[3] = {0.15f, 0.1f, 0.42f};
        for (int a = 0; a < 3; a++) w->eye[a] = c[a] + off[a] * e[a], w->look[a] = c[a] - 0.1f * e[a] * (a == 1);
        w->up[0] = 0, w->up[1] = 1, w->up[2] = 0;
        w->fov = 60.0f;
    }
    if (w->sd.light_count) {
        memcpy(w->light, w->sd.lights[0].position, sizeof w->light);
    } else {
        const float off[3] = {-0.2f, 0.45f, 0.1f};
        for (int a = 0; a < 3; a++) w->light[a] = c[a] + off[a] * e[a];
    }
    return true;
}

/* The primary ray of pixel (x, y), DESIGN.md's pinhole camera. jitter moves it inside its pixel. */
static inline void primary_ray(const world *w, int x, int y, int res, float jx, float jy, rp_ray *r) {
    float f[3], rt[3], u[3];
    for (int a = 0; a < 3; a++) f[a] = w->look[a] - w->eye[a];
    normalize(f);
    cross(f, w->up, rt);
    normalize(rt);
    cross(rt, f, u);
    float th = tanf(w->fov * 0.5f * 3.14159265f / 180.0f);
    float sx = (2.0f * ((float)x + jx) / (float)res - 1.0f) * th, sy = (1.0f - 2.0f * ((float)y + jy) / (float)res) * th;
    float d[3];
    for (int a = 0; a < 3; a++) d[a] = f[a] + sx * rt[a] + sy * u[a];
    normalize(d);
    *r = (rp_ray){.org_x = w->eye[0], .org_y = w->eye[1], .org_z = w->eye[2], .tnear = 0.0f, .dir_x = d[0],
                  .dir_y = d[1], .dir_z = d[2], .tfar = INFINITY, .mask = 0xFFFFFFFFu};
}

static inline void reference(rp_scene *scene, test_ray *t) {
    t->ref = (rp_rayhit){.ray = t->ray};
    t->ref.hit.geom_id = RP_INVALID_ID;
    rp_intersect1(scene, &t->ref);
    rp_ray o = t->ray;
    rp_occluded1(scene, &o);
    t->occluded = o.tfar == -INFINITY;
}

/* The rays of one type over a res x res image, from the primary hits. */
static inline void make_rays(const world *w, rp_scene *scene, int type, int res, float eps, const test_ray *prim,
                      test_ray *out) {
    for (int i = 0; i < res * res; i++) {
        test_ray *t = &out[i];
        memset(t, 0, sizeof *t);
        if (type == RAY_PRIMARY) {
            primary_ray(w, i % res, i / res, res, 0.5f, 0.5f, &t->ray);
            t->live = (i % 29) != 5; /* a few dead rays: never written */
        } else {
            const rp_rayhit *h = &prim[i].ref;
            t->live = h->hit.geom_id != RP_INVALID_ID;
            float d[3] = {h->ray.dir_x, h->ray.dir_y, h->ray.dir_z};
            float p[3] = {h->ray.org_x + h->ray.tfar * d[0], h->ray.org_y + h->ray.tfar * d[1],
                          h->ray.org_z + h->ray.tfar * d[2]};
            float n[3] = {h->hit.Ng_x, h->hit.Ng_y, h->hit.Ng_z}, nd[3];
            if (t->live && !(dot(n, n) > 0.0f)) t->live = false;
            if (!t->live) n[0] = 0, n[1] = 1, n[2] = 0;
            normalize(n);
            float c = dot(d, n);
            if (type == RAY_SHADOW) {
                for (int a = 0; a < 3; a++) nd[a] = w->light[a] - p[a];
                t->ray = (rp_ray){.org_x = p[0], .org_y = p[1], .org_z = p[2], .tnear = 1e-4f, .dir_x = nd[0],
                                  .dir_y = nd[1], .dir_z = nd[2], .tfar = 1.0f - 1e-4f, .mask = 0xFFFFFFFFu};
            } else {
                bool refl = true;
                if (type == RAY_REFRACT) {
                    float eta = c < 0.0f ? 1.0f / 1.5f : 1.5f, cn = c < 0.0f ? -c : c;
                    float sn = c < 0.0f ? 1.0f : -1.0f; /* normal facing the incoming side */
                    float k = 1.0f - eta * eta * (1.0f - cn * cn);
                    if (k >= 0.0f) {
                        for (int a = 0; a < 3; a++) nd[a] = eta * d[a] + (eta * cn - sqrtf(k)) * sn * n[a];
                        refl = false;
                    }
                }
                if (refl)
                    for (int a = 0; a < 3; a++) nd[a] = d[a] - 2.0f * c * n[a];
                t->ray = (rp_ray){.org_x = p[0], .org_y = p[1], .org_z = p[2], .tnear = eps, .dir_x = nd[0],
                                  .dir_y = nd[1], .dir_z = nd[2], .tfar = INFINITY, .mask = 0xFFFFFFFFu};
            }
        }
        if (t->live) reference(scene, t);
    }
}

#endif
