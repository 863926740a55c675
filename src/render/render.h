/* Internals of the rendering layer, shared by the files of src/render. Built on the public headers
 * only. */
#ifndef RP_RENDER_INTERNAL_H
#define RP_RENDER_INTERNAL_H

#include <math.h>
#include <stdint.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"

typedef struct v3 {
    float x, y, z;
} v3;

static inline v3 v3_make(float x, float y, float z) { return (v3){x, y, z}; }
static inline v3 v3_load(const float *p) { return (v3){p[0], p[1], p[2]}; }
static inline v3 v3_add(v3 a, v3 b) { return (v3){a.x + b.x, a.y + b.y, a.z + b.z}; }
static inline v3 v3_sub(v3 a, v3 b) { return (v3){a.x - b.x, a.y - b.y, a.z - b.z}; }
static inline v3 v3_mul(v3 a, v3 b) { return (v3){a.x * b.x, a.y * b.y, a.z * b.z}; }
static inline v3 v3_scale(v3 a, float s) { return (v3){a.x * s, a.y * s, a.z * s}; }
static inline v3 v3_neg(v3 a) { return (v3){-a.x, -a.y, -a.z}; }
static inline float v3_dot(v3 a, v3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline v3 v3_cross(v3 a, v3 b) {
    return (v3){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
static inline float v3_length(v3 a) { return sqrtf(v3_dot(a, a)); }
static inline v3 v3_normalize(v3 a) {
    float l = v3_length(a);
    return l > 0.0f ? v3_scale(a, 1.0f / l) : a;
}
/* a + b * s */
static inline v3 v3_madd(v3 a, v3 b, float s) { return (v3){a.x + b.x * s, a.y + b.y * s, a.z + b.z * s}; }
static inline float v3_max_abs(v3 a) {
    float m = fabsf(a.x);
    if (fabsf(a.y) > m) m = fabsf(a.y);
    if (fabsf(a.z) > m) m = fabsf(a.z);
    return m;
}
static inline float v3_at(v3 a, int k) { return k == 0 ? a.x : (k == 1 ? a.y : a.z); }
static inline bool v3_is_zero(v3 a) { return a.x == 0.0f && a.y == 0.0f && a.z == 0.0f; }

/* A cone or cylinder frustum prepared for intersection (NFF `c`: open-ended, no caps). */
typedef struct render_cone {
    double base[3], axis[3]; /* axis: unit vector from base to apex */
    double height, base_radius, slope; /* radius(z) = base_radius + slope * z, z in [0, height] */
} render_cone;

/* What kind of primitive a geom_id holds. */
typedef enum render_geom_kind {
    RENDER_GEOM_TRIANGLES = 0,
    RENDER_GEOM_SPHERES = 1,
    RENDER_GEOM_CONES = 2
} render_geom_kind;

struct rp_render_scene {
    rp_device *device;
    rp_scene *scene;
    const rp_scene_data *data;
    uint32_t geom_ids[3];          /* per render_geom_kind, RP_INVALID_ID when absent */
    rp_material *materials;        /* data->material_count */
    rp_light_source *lights;
    size_t light_count;
    render_cone *cones;            /* data->cone_count */
    rp_bounds bounds;
    float scale;                   /* largest absolute coordinate of the bounds, > 0 */
    float srgb_to_linear[256];
};

/* Result of turning a hit into a shading point. */
typedef struct render_surface {
    v3 p;        /* hit point */
    v3 ng;       /* unit geometric normal, facing the incoming ray */
    v3 ns;       /* unit shading normal, same hemisphere as ng */
    v3 ns_raw;   /* unit shading normal as stored (for the normal AOV) */
    float uv[2];
    bool has_uv;
    bool entering; /* the ray hit the front side (outside) of the surface */
    uint32_t material;
} render_surface;

/* Cone user geometry callbacks (cone.c). */
void cone_prepare(const rp_cone_data *in, render_cone *out);
void cone_bounds(void *user, uint32_t prim, rp_bounds *out);
bool cone_intersect(void *user, uint32_t prim, rp_ray *ray, rp_hit *hit);
bool cone_occluded(void *user, uint32_t prim, const rp_ray *ray);

/* Builds the shading point of a hit (scene.c). */
void scene_surface(const rp_render_scene *s, const rp_ray *ray, const rp_hit *hit, render_surface *out);
/* Linear RGB of a texture at uv, bilinear (material.c). */
v3 material_texture(const rp_render_scene *s, int32_t texture, const float uv[2]);
/* Base colour of a material at a surface: kd times its texture (material.c). */
v3 material_albedo(const rp_render_scene *s, const rp_material *m, const render_surface *surf);
/* Exact Fresnel reflectance of a dielectric interface; cos_i > 0, eta = n_incident / n_transmitted. */
float material_fresnel(float cos_i, float eta);

/* Primary ray of a pixel position (x, y in pixels, (0,0) the top-left corner) (camera.c). */
typedef struct render_camera {
    v3 eye, f, r, u;
    float tan_half, aspect, width, height;
} render_camera;
void camera_setup(const rp_camera *cam, int width, int height, render_camera *out);
/* A ray from org along dir over [0, tfar], visible to every geometry. */
static inline void render_ray_init(rp_ray *r, v3 org, v3 dir, float tfar) {
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

void camera_ray(const render_camera *c, float x, float y, rp_ray *ray);
/* A camera framing the bounds of a committed scene (camera.c). */
rp_camera camera_frame_bounds(rp_scene *scene, const rp_bounds *b);

/* Deterministic random number in [0,1) from (pixel x, pixel y, sample, dimension). */
static inline uint32_t render_hash(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}
static inline float render_random(uint32_t px, uint32_t py, uint32_t sample, uint32_t dim) {
    uint32_t h = render_hash(px ^ render_hash(py ^ render_hash(sample ^ render_hash(dim + 0x9e3779b9u))));
    return (float)(h >> 8) * (1.0f / 16777216.0f);
}

#endif
