/* Internals of the rendering layer, shared by the files of src/render. Built on the public headers
 * only. */
#ifndef RP_RENDER_INTERNAL_H
#define RP_RENDER_INTERNAL_H

#include <math.h>
#include <stdatomic.h>
#include <stdint.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"

typedef struct v3 {
    float x, y, z;
} v3;

/* fmaxf and fminf inline, with glibc's results: the other argument where one is NaN, the first
 * where the two are equal (signed zeros). GCC calls the library for each use (the instructions
 * differ from C's rules on NaN), and the calls were 2-3% of a path-traced frame and kept the loops
 * around them scalar. */
static inline float render_fmaxf(float a, float b) {
    float m = b > a ? b : a;
    return a != a ? b : m;
}
static inline float render_fminf(float a, float b) {
    float m = b < a ? b : a;
    return a != a ? b : m;
}

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

/* An environment map prepared for importance sampling: radiance per texel and the piecewise-constant
 * distributions of rows (marginal) and of texels within a row (conditional), sin(theta) weighted. */
typedef struct render_envmap {
    int width, height;
    float *rgb;          /* width * height * 3, top row (+y) first */
    float *row_cdf;      /* height + 1 */
    float *col_cdf;      /* height * (width + 1) */
    float integral;
} render_envmap;

/* Alias table (Walker; Vose's construction) over the lights, by power. */
typedef struct light_sampler {
    float *prob;
    uint32_t *alias;
    float *pmf;
    size_t count;
} light_sampler;

/* An animated scene's sub-scene and the instance placing it (anim.c). */
typedef struct render_group {
    rp_scene *sub;
    rp_geometry *inst;       /* in the top scene (owned by it) */
    rp_geometry *tri_geom;   /* the sub-scene's triangles (owned by it), NULL if none */
    uint32_t top_id;         /* the instance's geom_id in the top scene */
    int32_t node;            /* the keyframed block placing it, -1: none (identity) */
    bool tpa;                /* `tpa` triangles: their vertices move, a frame refits the sub-scene */
    bool deform;             /* its vertices move in place (tpa, or a block with refit_blocks): refit per frame */
    uint32_t sub_ids[3];     /* geom_id in the sub-scene per render_geom_kind, RP_INVALID_ID if none */
    uint32_t *map[3];        /* per kind: prim_id in the sub-scene -> index in the flat arrays */
    uint32_t *idx;           /* the sub-scene's index buffer (into the rest positions) */
    render_cone *cones;      /* rest-space cones of the sub-scene's user geometry */
} render_group;

struct rp_render_scene {
    rp_device *device;
    rp_scene *scene;
    const rp_scene_data *data;
    uint32_t geom_ids[3];          /* per render_geom_kind, RP_INVALID_ID when absent */
    rp_material *materials;        /* data->material_count */
    v3 *material_ke;               /* per material, material_ke's value (set once at creation: the
                                    * emission of every path vertex read it through five calls) */
    size_t material_ke_count;      /* its entries: data->material_count at creation */
    rp_light_source *lights;
    size_t light_count;
    render_cone *cones;            /* data->cone_count */
    rp_bounds bounds;
    float scale;                   /* largest absolute coordinate of the bounds, > 0 */
    float extent;                  /* largest side of the bounds, at least 1e-3 (bounds_extent) */
    float srgb_to_linear[256];
    /* physically based lights (light.c) */
    rp_light_source *pb_lights;
    size_t pb_light_count;
    light_sampler light_pick;
    int32_t *tri_light;            /* triangle_count: index into pb_lights of an emissive one, or -1 */
    render_envmap env;
    int32_t env_light;             /* index into pb_lights, or -1 */
    float radius;                  /* bounding sphere radius of the scene */
    v3 center;
    render_group *groups;          /* animated scenes built with instances, else NULL */
    uint32_t group_count;
    uint32_t *group_of_top;        /* top-level geom_id -> index into groups */
    float anim_still[6];           /* animated scenes: bounds of what never moves (lo xyz, hi xyz) */
    bool anim_still_ok;
    uint32_t *anim_moving;         /* ... and the vertices that move */
    size_t anim_moving_n;
    struct render_medium *medium;  /* the participating medium (medium.h), NULL: none */
    bool cutouts;                  /* a material is alpha-tested: queries go through alpha.c's fix-ups */
    /* A frame's large scratch, handed back for the next frame (render_scratch_take/give). Mutable
     * through a const scene, as frames see it; NULL: every frame allocates its own. */
    struct render_scratch *scratch;
};

/* Full-frame scratch that outlives a frame: instant radiosity's discontinuity-buffer planes (16 MB
 * at 640x480). Allocated fresh each frame, their pages were faulted in anew every frame, which took
 * half of cornell_original's CPU time on these virtual machines; a frame now takes the block the
 * last one gave back (one is kept per scene; concurrent frames each get their own). take returns
 * at least bytes, zeroed and 64-byte aligned, or NULL when out of memory; give keeps it (NULL is
 * ignored), freeing the one it replaces. */
void *render_scratch_take(const rp_render_scene *s, size_t bytes);
void render_scratch_give(const rp_render_scene *s, void *block);

/* Result of turning a hit into a shading point. */
typedef struct render_surface {
    v3 p;        /* hit point */
    v3 ng;       /* unit geometric normal, facing the incoming ray */
    v3 ns;       /* unit shading normal, same hemisphere as ng */
    v3 ns_raw;   /* unit shading normal as stored (for the normal AOV) */
    float uv[2];   /* texture coordinates, where has_uv: triangles with them whose material reads a texture */
    bool has_uv;
    bool entering; /* the ray hit the front side (outside) of the surface */
    uint32_t material;
    v3 dpdu;     /* triangles with texture coordinates whose material has a normal map: the position's
                  * derivative along u (for the tangent-space normal map), else 0 */
    float eps;   /* how far rays leaving the point start off it (ray_offset_at) */
    v3 color;    /* the vertex colours interpolated (a point's sphere's colour), multiplying the base
                  * colour (material_albedo); white where the scene has none */
} render_surface;

/* Cone user geometry callbacks (cone.c). */
void cone_prepare(const rp_cone_data *in, render_cone *out);
void cone_bounds(void *user, uint32_t prim, rp_bounds *out);
bool cone_intersect(void *user, uint32_t prim, rp_ray *ray, rp_hit *hit);
bool cone_occluded(void *user, uint32_t prim, const rp_ray *ray);

/* Builds the shading point of a hit (scene.c). */
void scene_surface(const rp_render_scene *s, const rp_ray *ray, const rp_hit *hit, render_surface *out);
/* A hit inside an animated scene's instance rewritten to the flat build's geom_id and prim_id (and
 * inst_id RP_INVALID_ID); other hits unchanged. */
void scene_hit_flat(const rp_render_scene *s, rp_hit *h);
/* scene_hit_flat on the three ids alone, inline: scene_surface reads a hit's fields one at a time,
 * as the packet tracers have just stored them (a copy of the whole record as 16-byte loads waited
 * on those stores, a tenth of scene_surface on the kitchen's animation). */
static inline void scene_ids_flat(const rp_render_scene *s, uint32_t *geom, uint32_t *prim, uint32_t *inst) {
    if (!s->groups || *inst == RP_INVALID_ID || *geom == RP_INVALID_ID || *inst >= s->group_count) return;
    uint32_t gi = s->group_of_top[*inst];
    if (gi == RP_INVALID_ID) return;
    const render_group *g = &s->groups[gi];
    for (int k = 0; k < 3; k++)
        if (g->sub_ids[k] == *geom) {
            *prim = g->map[k][*prim];
            *geom = s->geom_ids[k];
            *inst = RP_INVALID_ID;
            return;
        }
}
/* Animated scenes (anim.c): one sub-scene and instance per keyframed block, `tpa` group and the
 * still rest; their bounds (and ray offsets) from the data; freeing them. */
bool anim_build_geometry(rp_render_scene *s, const rp_scene_data *d, const rp_render_scene_desc *desc);
void anim_scene_bounds(rp_render_scene *s);
void anim_groups_free(rp_render_scene *s);
/* Linear RGB of a texture at uv, under its wrap modes and filter (material.c). */
v3 material_texture(const rp_render_scene *s, int32_t texture, const float uv[2]);
/* Coverage of an alpha texture at uv, sampled as material_texture: its alpha plane, or its red
 * channel where it has none (material.c). */
float material_texture_alpha(const rp_render_scene *s, int32_t texture, const float uv[2]);
/* Base colour of a material at a surface: kd times its texture (material.c). */
v3 material_albedo(const rp_render_scene *s, const rp_material *m, const render_surface *surf);
/* Whitted's Phong terms at a hit: the diffuse kd (textured), the highlight's ks and exponent ns (a
 * metallic-roughness material's from its textures there; its kd is the base colour, metal or not). */
void material_phong(const rp_render_scene *s, const rp_material *m, const render_surface *surf, v3 *kd, v3 *ks,
                    float *ns);
/* Exact Fresnel reflectance of a dielectric interface; cos_i > 0, eta = n_incident / n_transmitted. */
float material_fresnel(float cos_i, float eta);

/* The rendering layer's queries (alpha.c): the core's, passing through the cut-out points of
 * alpha-tested surfaces (rp_material.alpha_mode) where the scene has them (s->cutouts); the core's
 * alone otherwise. The same arguments and results as rp_intersect1, rp_occluded1, ... */
bool alpha_scene_has_cutouts(const rp_render_scene *s);
void alpha_intersect1(const rp_render_scene *s, rp_rayhit *rayhit);
void alpha_occluded1(const rp_render_scene *s, rp_ray *ray);
void alpha_intersect_array(const rp_render_scene *s, rp_rayhit *rayhits, size_t count, uint32_t flags);
void alpha_occluded_array(const rp_render_scene *s, rp_ray *rays, size_t count, uint32_t flags);
void alpha_intersect_n(const rp_render_scene *s, const rp_query_n_desc *desc, rp_rayhit_n *packet);
void alpha_occluded_n(const rp_render_scene *s, const rp_query_n_desc *desc, rp_rayhit_n *packet);
/* Whether a hit (rayhit->hit, at rayhit->ray.tfar) is on a cut-out point of its surface: the test
 * the queries above apply, for engines that trace on their own (the stream engine's intersection
 * kernel). */
bool alpha_rayhit_cut(const rp_render_scene *s, const rp_rayhit *rayhit);
/* The fix-up alpha_intersect1 (occlusion: alpha_occluded1) applies to the core's answer, applied to
 * the answer of a tracer that gives the core's hits (the CUDA kernels): rayhit as the tracer left
 * it, tfar its ray's segment end before it; the passes past cut-out points are traced by the core on
 * the CPU. Nothing without cutouts. */
void alpha_fix_traced(const rp_render_scene *s, rp_rayhit *rayhit, float tfar, bool occlusion);

/* Primary ray of a pixel position (x, y in pixels, (0,0) the top-left corner) (camera.c). */
typedef struct render_camera {
    v3 eye, f, r, u;
    float tan_half, aspect, width, height;
} render_camera;
void camera_setup(const rp_camera *cam, int width, int height, render_camera *out);
/* A camera camera_setup can frame: finite, eye != look, up not along the view (sin^2 > 1e-10), the
 * vertical fov in (0, 180) degrees. */
bool camera_valid(const rp_camera *cam);
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
/* The per-lane loops of the packets' primary rays (camera_rays_n), eye light's shading, Whitted's
 * shadow pass and instant radiosity's tile pass are compiled twice, for the baseline (SSE2) and for
 * AVX2 (GCC's and Clang's target attribute on a wrapper of an always-inlined body), the copy picked
 * per frame (render_frame.avx2). AVX2 without FMA: no multiply-add is contracted, so both copies
 * make the same IEEE operations in the same order and give the same values (test_isa_images);
 * AVX2's 8 lanes and 32-bit multiplies (the sample offsets' hashes) are what they gain. */
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define RENDER_X86_AVX2 1
#else
#define RENDER_X86_AVX2 0
#endif
#define RENDER_INLINE static inline __attribute__((always_inline))

/* Lanes of the largest packet (32 x 32). */
#define RENDER_LANES_MAX 1024
/* camera_ray's rays of sample s into the first count lanes of packet p, lane q the one of pixel
 * (bx + li[q], by + lj[q]) (tnear 0, tfar inf, no hit yet); avx2: by the AVX2 copy of its loops
 * (render_frame.avx2), the same rays. */
void camera_rays_n(const render_camera *c, int bx, int by, int s, uint32_t count, const uint8_t *li,
                   const uint8_t *lj, bool avx2, rp_rayhit_n *p);
/* A camera framing the bounds of a committed scene (camera.c). */
rp_camera camera_frame_bounds(const rp_render_scene *scene, const rp_bounds *b);


/* The largest side of a box, at least 1e-3 (1e-3 for an empty or non-finite box). */
static inline float bounds_extent(const rp_bounds *b) {
    float e = 1e-3f;
    const float d[3] = {b->upper_x - b->lower_x, b->upper_y - b->lower_y, b->upper_z - b->lower_z};
    for (int k = 0; k < 3; k++)
        if (isfinite(d[k]) && d[k] > e) e = d[k];
    return e;
}
/* The offset of rays leaving a surface point whose float spacing is that of coordinates of size
 * mag: the largest coordinate of the point, of the ray that found it and of its triangle's
 * vertices (scene_surface). It had been the scene's (ray_offset): a bunny on a ground 10^5 times
 * its size started its shadow and bounce rays 2 units off a 0.15-unit bunny, which lost its
 * shadows and grew black blotches. 2e-5 of mag (about 170 float spacings) while mag is within 4
 * times the scene's extent (scenes around the origin or near it: as before); beyond, the float
 * spacing and not the scene calls for it: 2e-5 of 4 extents, at least 2e-6 of mag (17-34
 * spacings). With 2e-5 of mag a Cornell box 2 units tall moved 1e5 from the origin started its
 * rays 2 units off the walls (a black image, path traced) and a bunny moved 1e4 lost its shadow. */
static inline float ray_offset_at(const rp_render_scene *s, float mag) {
    float m = mag > 1e-3f ? mag : 1e-3f, near = m < 4.0f * s->extent ? m : 4.0f * s->extent;
    return render_fmaxf(2e-5f * near, 2e-6f * m);
}
/* Distance secondary rays start off the surface, along the geometric normal, where the surface is
 * not known (a light's sampled point, a medium's shadow rays): the scene's largest coordinate's. */
static inline float ray_offset(const rp_render_scene *s) { return ray_offset_at(s, s->scale); }

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

/* Where in pixel (x, y) sample `sample` (counted from the pixel's first sample, not the frame's)
 * goes, for the Whitted, eye light and AOV cameras: sample 0 at the centre, the others jittered. So
 * frames of samples [k, k+1) accumulated for k = 0..n-1 sum what one n-spp frame sums, in the same
 * order (the viewer's progressive refinement), and a 1-spp frame is the pixel centre. */
static inline void render_sample_offset(int x, int y, int sample, float *ox, float *oy) {
    *ox = *oy = 0.5f;
    if (sample == 0) return;
    *ox = render_random((uint32_t)x, (uint32_t)y, (uint32_t)sample, 0);
    *oy = render_random((uint32_t)x, (uint32_t)y, (uint32_t)sample, 1);
}

/* ---- sampler (sampler.c) ---- */

/* The random numbers of one pixel sample: dimension d of sample `sample` of pixel (x, y) is a hashed
 * PCG output of the four, so it depends on nothing else (thread, tile order, other pixels). */
typedef struct render_sampler {
    uint32_t key;    /* hash of (x, y, sample); Sobol: of (x, y) */
    uint32_t dim;    /* next dimension */
    uint32_t index;  /* Sobol: the sample index */
    bool sobol;      /* scrambled Sobol (sampler.c) instead of hashed PCG */
} render_sampler;
render_sampler sampler_start(uint32_t x, uint32_t y, uint32_t sample);
/* The PCG hash of the hashed sampler (Jarzynski and Olano 2020). */
static inline uint32_t render_pcg_hash(uint32_t v) {
    uint32_t state = v * 747796405u + 2891336453u;
    uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}
/* A PCG sampler's dimension d of key (sampler_at without Sobol) as two halves, so that loops over
 * many keys and one dimension hash the dimension once: sampler_pcg_number(key, sampler_pcg_dim(d)). */
static inline uint32_t sampler_pcg_dim(uint32_t d) { return render_pcg_hash(d * 0x9e3779b9u + 0x1b873593u); }
static inline float sampler_pcg_number(uint32_t key, uint32_t dim_hash) {
    return (float)(render_pcg_hash(key ^ dim_hash) >> 8) * (1.0f / 16777216.0f);
}
/* A pixel's sampler of the kind desc.sampler names (PCG: sampler_start). */
render_sampler sampler_start_pixel(rp_sampler_type type, uint32_t x, uint32_t y, uint32_t sample);
/* Dimension d's number of a Sobol sampler (sampler.c). */
float sampler_sobol_at(const render_sampler *s, uint32_t d);
/* Dimension d's number without advancing. Inline for PCG (two hashes): out of line, the calls were
 * a fifth of its 34 instructions, and the integrators take 6 to 7 numbers a path vertex. */
static inline float sampler_at(const render_sampler *s, uint32_t d) {
    if (s->sobol) return sampler_sobol_at(s, d);
    return sampler_pcg_number(s->key, sampler_pcg_dim(d));
}
/* The next dimension's number in [0, 1). */
static inline float sampler_1d(render_sampler *s) { return sampler_at(s, s->dim++); }

/* ---- BSDFs (bsdf.c), in a local frame whose z axis is the shading normal ---- */

typedef enum bsdf_type {
    BSDF_LAMBERT = 0,    /* kd / pi */
    BSDF_CONDUCTOR = 1,  /* Fresnel with complex IOR (eta, k); GGX with alpha, a mirror at alpha 0 */
    BSDF_DIELECTRIC = 2, /* Fresnel reflection and refraction (ior, kt tints the transmission); GGX
                          * microfacets with alpha (reflection and transmission), smooth at alpha 0 */
    BSDF_PLASTIC = 3     /* diffuse kd (1 - max ks) / pi under a ks-weighted GGX coat (a mirror at
                          * alpha 0); with schlick, glTF's BRDF: the coat's reflectance is Schlick's
                          * Fresnel of F0 = ks and the base kd (1 - F(0.04)) / pi */
} bsdf_type;

typedef struct render_bsdf {
    bsdf_type type;
    v3 kd, ks;           /* plastic's base and coat; conductor: ks multiplies the Fresnel term */
    v3 eta, k;           /* conductor's complex index of refraction per channel */
    v3 kt;               /* dielectric's transmission tint */
    float ior;           /* dielectric: inside over outside */
    float alpha;         /* GGX roughness (pbrt's alpha), 0: smooth */
    bool entering;       /* dielectric: the ray comes from outside */
    bool schlick;        /* plastic: glTF's metallic-roughness BRDF (see BSDF_PLASTIC) */
} render_bsdf;

typedef struct bsdf_sample {
    v3 wi;
    v3 f;         /* the BSDF value (delta lobes: the weight times cos / pdf, as pbrt does) */
    float pdf;    /* solid angle; for delta lobes the discrete lobe probability */
    bool delta;
} bsdf_sample;

/* f(wo, wi) for the non-delta lobes (wo, wi local, unit, pointing away from the surface). */
v3 bsdf_eval(const render_bsdf *b, v3 wo, v3 wi);
/* Whether bsdf_eval(b, wo, wi) is *f for every wi with wi.z > 0 (the smooth plastic's diffuse base,
 * 0 when wo.z <= 0: its mirror coat is a delta lobe), so that instant radiosity gathers the point's
 * VPLs as a Lambert point's; the same values as bsdf_eval gives there. Lambert itself: false. */
bool bsdf_eval_constant(const render_bsdf *b, v3 wo, v3 *f);
/* The solid angle density bsdf_sample picks wi with (non-delta lobes). */
float bsdf_pdf(const render_bsdf *b, v3 wo, v3 wi);
/* Samples wi from u (3 numbers); false when no direction results. */
bool bsdf_sample_dir(const render_bsdf *b, v3 wo, const float u[3], bsdf_sample *out);
/* True when every lobe is a delta (no light sampling pays). */
bool bsdf_is_delta(const render_bsdf *b);
/* Fresnel reflectance of a conductor, per channel, at cos_i > 0. */
v3 bsdf_fresnel_conductor(float cos_i, v3 eta, v3 k);
/* The conductor (eta = 1, k) whose normal-incidence reflectance is r (0 <= r < 1). */
v3 bsdf_conductor_k_from_reflectance(v3 r);
/* Orthonormal frame around n. */
void bsdf_frame(v3 n, v3 *t, v3 *b);
static inline v3 bsdf_to_local(v3 v, v3 t, v3 b, v3 n) { return v3_make(v3_dot(v, t), v3_dot(v, b), v3_dot(v, n)); }
static inline v3 bsdf_to_world(v3 v, v3 t, v3 b, v3 n) {
    return v3_add(v3_add(v3_scale(t, v.x), v3_scale(b, v.y)), v3_scale(n, v.z));
}
/* Cosine-weighted direction of the upper hemisphere (z up) from u in [0,1)^2. */
v3 bsdf_cosine_hemisphere(float u0, float u1);

/* The BSDF of a material at a surface point (material.c). */
render_bsdf material_bsdf(const rp_render_scene *s, const rp_material *m, const render_surface *surf);
/* A data texture (roughness, normals) at uv, linear as stored (no sRGB decoding) (material.c). */
v3 material_texture_linear(const rp_render_scene *s, int32_t texture, const float uv[2]);
/* Replaces surf->ns by the material's tangent-space normal map, where it has one (material.c). */
void material_normal_map(const rp_render_scene *s, const rp_material *m, render_surface *surf);
/* Emitted radiance of a material towards the side the surface was hit from (material.c). */
v3 material_emission(const rp_render_scene *s, uint32_t material, const render_surface *surf);
/* Emitted radiance of material i on its front side, whatever the side it is seen from. */
v3 material_ke(const rp_render_scene *s, uint32_t material);
/* What material_ke returns, computed (rp_render_scene.material_ke holds it per material). */
v3 material_ke_compute(const rp_render_scene *s, uint32_t material);
/* ke times the material's emission texture at the hit (ke itself where it has none). */
v3 material_ke_textured(const rp_render_scene *s, const rp_material *m, v3 ke, const render_surface *surf);

/* ---- lights (light.c) ---- */

typedef struct light_sample {
    v3 wi;         /* unit, from the shading point to the light */
    float dist;    /* to the light's point; INFINITY for directional and environment */
    v3 L;          /* radiance (area, environment) or intensity / d^2 (point, spot), irradiance
                    * (directional) arriving along -wi */
    float pdf;     /* solid angle density of wi given this light; 1 for delta lights */
    bool delta;
} light_sample;

/* Builds the scene's physically based light list (area triangles from emissive materials, the
 * file's point lights, the environment) and the light sampler; false when out of memory or when the
 * environment file cannot be read (message in err). */
bool light_scene_init(rp_render_scene *s, const rp_render_scene_desc *desc, char *err, size_t err_size);
void light_scene_free(rp_render_scene *s);
/* Picks a light index by power from u; *pmf is its probability. */
uint32_t light_pick(const light_sampler *ls, float u, float *pmf);
/* Samples light l as seen from p (u: 2 numbers); false when it sends nothing towards p. */
/* A file's spot or directional light as a light source (its physically based units: intensity on the
 * spot's axis, a directional light's irradiance); a point light with the inverse square law. */
void light_from_data(const rp_light_data *d, rp_light_source *out);
bool light_sample_li(const rp_render_scene *s, const rp_light_source *l, v3 p, float u0, float u1,
                     light_sample *out);
/* Radiance of the environment along direction d (0 without one). */
v3 light_env_radiance(const rp_render_scene *s, v3 d);
/* Solid angle density the environment light samples direction d with. */
float light_env_pdf(const rp_render_scene *s, v3 d);
/* Solid angle density with which triangle light l is sampled from p towards its point q (normal
 * ng, unit, any side). */
float light_triangle_pdf(const rp_light_source *l, v3 p, v3 q, v3 ng);
/* Emission sampling for VPLs: a point on light l, its normal (0 for point lights), and the power
 * carried (flux over the densities of the point and of the direction sampled from it); u: 4 numbers.
 * False when the light has no VPL sampling (environment, directional). */
bool light_sample_le(const rp_render_scene *s, const rp_light_source *l, const float u[4], v3 *p, v3 *n, v3 *dir,
                     v3 *power);

/* ---- frame and thread state of the tile renderer (tile.c) ---- */

/* What one Whitted ray found: the radiance so far and what is still to be traced for it (shadow
 * rays to the lights, a reflection and a refraction ray with their multipliers). Shared by the
 * depth-first and the packet tracer, so that both do the same float operations in the same order. */
typedef struct whitted_slot {
    v3 color;               /* background on a miss; ke + ambient, then + direct, then + children */
    v3 direct;              /* sum of the unoccluded lights, in light order */
    v3 org, ns, ng, kd, dir; /* shading point (lifted off the surface) for the shadow rays */
    float eps;              /* the surface's ray offset (render_surface.eps) */
    const rp_material *m;
    v3 ks;                  /* the highlight's colour and exponent (material_phong) */
    float shininess;
    bool lit, highlight;    /* lit: the ray hit a surface, whose lights must be gathered */
    bool has_r, has_t;      /* a reflection / refraction ray follows */
    float w_r, w_t;         /* path weights of the children */
    v3 mul_r, mul_t;        /* what the children's radiance is multiplied by */
    v3 org_r, dir_r, org_t, dir_t;
} whitted_slot;

/* What a light brings a Whitted slot, but the highlight's powf (whitted.c). */
typedef struct whitted_light_term {
    v3 intensity, term;
    float rv; /* cos of the mirrored light direction and the eye; > 0: a highlight */
} whitted_light_term;

/* The lit slots of a level and their way to one light, lane by lane (whitted.c, packet_shadows);
 * each array 64 bytes longer than the lanes, so that the streams do not share L1 sets. */
#define WHITTED_SOA (RENDER_LANES_MAX + 16)
typedef struct whitted_shadow_soa {
    float ox[WHITTED_SOA], oy[WHITTED_SOA], oz[WHITTED_SOA]; /* shading point */
    float nx[WHITTED_SOA], ny[WHITTED_SOA], nz[WHITTED_SOA]; /* shading normal */
    float gx[WHITTED_SOA], gy[WHITTED_SOA], gz[WHITTED_SOA]; /* geometric normal */
    float ex[WHITTED_SOA], ey[WHITTED_SOA], ez[WHITTED_SOA]; /* the ray's direction */
    float dist[WHITTED_SOA], cs[WHITTED_SOA], rv[WHITTED_SOA]; /* to the light, its cos, the highlight's */
    float eps[WHITTED_SOA];                                   /* the surface's ray offset */
    int32_t lit[WHITTED_SOA];
} whitted_shadow_soa;

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
    struct whitted_shadow_soa *shadow_soa; /* the shadow pass's per-lane arrays (whitted.c) */
    rp_counters_n *work;     /* RP_RAY_KIND_COUNT, or NULL when work is not counted */
    struct pbr_thread *pbr;  /* the physically based integrators' buffers (integrator/pbr.c) */
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
    int passes, pass;          /* passes over the tiles (instant radiosity's spp, else 1); the current one */
    int rx0, ry0, rx1, ry1;    /* the region rendered (desc.region, or the whole image); tiles start at its corner */
    int ox0, oy0, ox1, oy1;    /* the pixels written: the region, which instant radiosity renders with a
                                * margin of its filter's radius around it */
    uint32_t tile;             /* tile side in pixels (a multiple of the packet side) */
    uint8_t lane_i[RENDER_LANES_MAX], lane_j[RENDER_LANES_MAX]; /* pixel (i, j) of lane q of an n x n packet */
    uint16_t lane_of[RENDER_LANES_MAX];                          /* the lane of pixel (i, j): lane_of[j n + i] */
    bool packets;              /* Whitted in n x n packets */
    bool avx2;                 /* the AVX2 copies of the per-lane loops (RENDER_X86_AVX2): the CPU has
                                * AVX2 and the device's kernels are 8 or 16 wide (not --isa sse/scalar) */
    rp_traversal traversal[RP_RAY_KIND_COUNT];
    render_thread *threads;
    struct pbr_frame *pbr;     /* per-frame state of the physically based integrators */
    atomic_bool failed;        /* a thread ran out of memory */
    /* written by every tile when there is a progress callback: 64 bytes away from what the
     * threads read (the frame is calloc'd, so padding rather than _Alignas) */
    unsigned char apart[64];
    atomic_uint tiles_done;
    atomic_uint_least64_t rays_done;
    atomic_flag reporting;
} render_frame;

/* The desc as rp_render renders it (defaults and depths resolved), and the frame's camera, lights
 * and background from f->s and f->desc (tile.c); the stream tracer (src/stream) shades with them. */
rp_render_desc render_desc_resolve(const rp_render_scene *scene, const rp_render_desc *desc);
void render_frame_view(render_frame *f);

/* Whitted (integrator/whitted.c). */
/* A hit's shading without the rays it spawns: ke + ambient, the lifted point for the shadow rays,
 * the reflection and refraction rays with their weights (o->lit false on a miss). */
void whitted_surface(const render_frame *f, const rp_ray *ray, const rp_hit *hit, int depth, float weight,
                     whitted_slot *o);
/* The shadow ray of a lit slot towards a light and its term; false when none is needed. */
bool whitted_light(const render_frame *f, const whitted_slot *o, const rp_light_source *light, rp_ray *sr,
                   whitted_light_term *lt);
/* What an unoccluded light brings (the highlight's powf included). */
v3 whitted_light_contrib(const whitted_slot *o, const whitted_light_term *lt);
v3 whitted_shade(const render_frame *f, render_thread *th, const rp_ray *ray, const rp_hit *hit, int depth,
                 float weight);
/* Whitted radiance of one n x n block of a tile for sample s, added to the tile's accumulator. */
bool whitted_block(const render_frame *f, render_thread *th, int bx, int by, int x0, int y0, int tw, int tile_h,
                   int s);
bool whitted_thread_init(const render_frame *f, render_thread *th);
void whitted_thread_free(const render_frame *f, render_thread *th);
/* Level `level` of the thread's packet stack, made on first use; NULL when out of memory. */
whitted_level *whitted_packet_level(const render_frame *f, render_thread *th, int level);
/* Fills level lv's packet with the primary rays of the n x n block at (bx, by), sample s; rays of
 * the block outside the tile (x0, y0, tw x tile_h) are made but not live. Returns the live count. */
uint64_t whitted_primary_rays(const render_frame *f, whitted_level *lv, int bx, int by, int x0, int y0, int tw,
                              int tile_h, int s);
/* The query of a packet of that level and ray kind (traversal, frustum, counters, auto's tally). */
rp_query_n_desc whitted_packet_query(const render_frame *f, render_thread *th, whitted_level *lv, rp_ray_kind kind);
/* Sets ray q of a packet (tnear 0, no hit yet). */
void packet_set_ray(rp_rayhit_n *p, uint32_t q, v3 org, v3 dir, float tfar);

/* The physically based integrators (integrator/pbr.c, path.c, instant_radiosity.c). */
bool pbr_frame_init(render_frame *f);
void pbr_frame_free(render_frame *f);
bool pbr_thread_init(const render_frame *f, render_thread *th);
void pbr_thread_free(const render_frame *f, render_thread *th);
/* Renders the tile's samples; the mean radiance per pixel goes into th->accum (3 floats a pixel). */
bool pbr_tile(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1);
/* After every tile: instant radiosity's discontinuity buffer writes the frame's pixels. */
void pbr_frame_finish(render_frame *f);
/* Tile side the integrator wants (a multiple of its packet side), from the desc's tile size. */
uint32_t pbr_tile_side(const rp_render_desc *d);
/* Instant radiosity's discontinuity buffer radius in pixels (0: no filter). */
int ir_filter_radius(const rp_render_desc *d);

/* Eye light and the debug AOVs of a primary hit (integrator/aov.c). */
v3 eyelight_shade(const rp_rayhit *rh);
/* Eye light of one n x n block of a tile for sample s, its primary rays one packet (rp_intersect_n),
 * added to the tile's accumulator; the same image as the array tracer's. */
bool eyelight_block(const render_frame *f, render_thread *th, int bx, int by, int x0, int y0, int tw, int tile_h,
                    int s);
v3 aov_shade(const render_frame *f, const rp_ray *ray, const rp_hit *hit);
/* The default max_depth of scenes with a participating medium. */
#define RENDER_MEDIUM_DEPTH 64
/* Eye light and Whitted with a participating medium: its opacity along the primary ray (up to its
 * hit) over the colour seen behind it (integrator/volume.c). */
v3 volume_composite(const render_frame *f, const rp_ray *ray, v3 behind);
/* The same with the primary ray's opacity (volume_primary_opacity) already known: the stream
 * tracer's Whitted knows it from the eye stream, before the pixel's colour is complete. */
v3 volume_composite_opacity(const render_frame *f, float a, v3 behind);

#endif
