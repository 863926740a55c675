/* raypack rendering: cameras, materials, textures, lights, integrators and the tile renderer, built
 * on the public core API (raypack.h) and the loaders' flat scene data (raypack_io.h).
 *
 * A render scene turns an rp_scene_data into core geometries (triangles, spheres, cones as user
 * geometry) plus the renderer's own tagged-union materials and lights, and commits it. rp_render
 * then traces a frame on the device's threads, tile by tile; every random number is a function of
 * (pixel, sample, dimension), so an image is bit-identical whatever the thread count.
 *
 * Ownership: a render scene borrows the rp_scene_data it was made from (positions are shared with
 * the core, shading attributes, materials and textures are read in place): the data must stay alive
 * and unchanged until the render scene is released.
 */
#ifndef RAYPACK_RENDER_H
#define RAYPACK_RENDER_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "raypack.h"
#include "raypack_io.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- cameras ---------------------------------------------------------------------------------- */

typedef enum rp_camera_type { RP_CAMERA_PINHOLE = 0 } rp_camera_type;

/* The pinhole camera of DESIGN.md: eye, look-at point, up vector, vertical field of view. */
typedef struct rp_pinhole_camera {
    float eye[3], look[3], up[3];
    float fov_deg;
} rp_pinhole_camera;

typedef struct rp_camera {
    rp_camera_type type;
    union {
        rp_pinhole_camera pinhole;
    };
} rp_camera;

/* ---- materials -------------------------------------------------------------------------------- */

/* Every material has a local Phong lobe (kd, optional texture, ks, ns) lit by the point lights and
 * an emission ke; the type says which perfect-specular transport it adds on top. */
typedef enum rp_material_type {
    RP_MATERIAL_DIFFUSE = 0,   /* kd only */
    RP_MATERIAL_PHONG = 1,     /* kd + Phong highlight ks^ns */
    RP_MATERIAL_MIRROR = 2,    /* Phong + mirror reflection weighted by kr */
    RP_MATERIAL_DIELECTRIC = 3 /* Phong + Fresnel reflection and refraction (ior), tinted by kt */
} rp_material_type;

typedef struct rp_mirror_params {
    float kr[3];
} rp_mirror_params;

typedef struct rp_dielectric_params {
    float kt[3];
    float ior;
} rp_dielectric_params;

typedef struct rp_material {
    rp_material_type type;
    float kd[3];
    int32_t texture;    /* index into the scene's textures multiplying kd, or -1 */
    float ks[3];
    float ns;
    float ke[3];
    int32_t roughness_texture; /* physically based: roughness map (its red channel, linear), or -1 */
    int32_t normal_texture;    /* physically based: tangent-space normal map, or -1 */
    int32_t emission_texture;  /* texture multiplying ke (sRGB decoded), or -1; such an emitter is not
                                * sampled as a light: it adds radiance where rays hit it */
    /* glTF's metallic-roughness model (type PHONG; kd and texture are the base colour; ks and ns
     * its Phong look for Whitted): the physically based integrators read these per hit */
    bool metal_rough;
    float metallic, roughness;     /* factors, [0, 1] */
    int32_t metal_rough_texture;   /* green: roughness, blue: metallic (linear), times the factors; or -1 */
    /* Alpha cutouts (rp_material_data's): rays pass through where the surface is cut out */
    rp_alpha_mode alpha_mode;
    float alpha, alpha_cutoff;     /* factor; MASK's threshold */
    int32_t alpha_texture;         /* its alpha plane (else its red channel) times alpha, or -1 */
    bool uv_transform;             /* the textures are read at uv mapped by uv_matrix (rp_material_data's) */
    float uv_matrix[6];
    int32_t specular_texture;      /* texture multiplying ks (sRGB decoded: MTL map_Ks), or -1 */
    union {
        rp_mirror_params mirror;
        rp_dielectric_params dielectric;
    };
} rp_material;

/* Maps a material as the scene file states it (MTL / NFF parameters) to a renderer material. */
RP_API rp_material rp_material_from_data(const rp_material_data *data);

/* ---- lights ----------------------------------------------------------------------------------- */

/* Lights. Radiometric units are the scene's: a point or spot light's intensity is radiant
 * intensity (radiance times area per steradian), an area triangle's and the environment's values are
 * radiance, a directional light's is irradiance on a surface facing it. The physically based
 * integrators apply the inverse square law to point and spot lights (Whitted keeps the NFF
 * convention, inverse_square false, of the scene files). */
typedef enum rp_light_source_type {
    RP_LIGHT_SOURCE_POINT = 0,
    RP_LIGHT_SOURCE_SPOT = 1,
    RP_LIGHT_SOURCE_DIRECTIONAL = 2,
    RP_LIGHT_SOURCE_TRIANGLE = 3,   /* an emissive triangle of the mesh (MTL Ke), one sided */
    RP_LIGHT_SOURCE_ENVIRONMENT = 4 /* radiance from every direction: a lat-long map or a constant */
} rp_light_source_type;

typedef struct rp_point_light {
    float position[3];
    float intensity[3];
    bool inverse_square; /* false: no distance falloff (the NFF convention of the scene files) */
} rp_point_light;

typedef struct rp_spot_light {
    float position[3], direction[3]; /* direction: unit, where the cone points */
    float intensity[3];              /* on the axis */
    float cos_inner, cos_outer;      /* full intensity inside cos_inner, none outside cos_outer */
} rp_spot_light;

typedef struct rp_directional_light {
    float direction[3];  /* unit, the direction the light travels */
    float irradiance[3];
} rp_directional_light;

typedef struct rp_triangle_light {
    float p[3][3];       /* corners; the emitting side is that of (p1 - p0) x (p2 - p0) */
    float radiance[3];
    uint32_t prim;       /* the mesh triangle it is */
} rp_triangle_light;

typedef struct rp_environment_light {
    float scale[3];      /* radiance multiplier (the radiance itself without a map) */
    bool has_map;        /* the render scene's environment map (rp_render_scene_desc.environment) */
} rp_environment_light;

typedef struct rp_light_source {
    rp_light_source_type type;
    union {
        rp_point_light point;
        rp_spot_light spot;
        rp_directional_light directional;
        rp_triangle_light triangle;
        rp_environment_light environment;
    };
} rp_light_source;

/* ---- render scene ----------------------------------------------------------------------------- */

typedef struct rp_render_scene rp_render_scene;

/* The participating medium of a scene whose data holds a volume (rp_scene_data.volume, a .vdb):
 * extinction sigma_t = density_scale * density per world unit (the grid's world units), of which
 * the fraction albedo scatters (the rest is absorbed), by the Henyey-Greenstein phase function of
 * asymmetry hg_g. docs/rendering.md says what each integrator does with it. */
typedef struct rp_medium_desc {
    float density_scale;  /* 0: 1 */
    float albedo[3];      /* single-scattering albedo in [0, 1]; all 0: 1, 1, 1 (cloud droplets
                           * barely absorb); a black medium: any negative value, clamped to 0 */
    float hg_g;           /* asymmetry in (-1, 1), clamped to 0.99 in magnitude; 0: isotropic */
} rp_medium_desc;

typedef struct rp_render_scene_desc {
    rp_scene_desc accel;  /* acceleration structure settings of the core scene */
    rp_medium_desc medium; /* with a volume in the data */
    /* Environment of the physically based integrators: a lat-long Radiance .hdr (+y up, u = 0.5 at
     * -z; the radiance arriving from each direction) times environment_scale, or, without a file,
     * the constant radiance environment_scale (all 0: no environment). */
    const char *environment;
    float environment_scale[3];
    /* Animated scenes (rp_scene_data.animation): false (the default) puts the geometry of every
     * keyframed block in a sub-scene of its own placed by an instance (RP_GEOMETRY_INSTANCE), the
     * still geometry in another under the identity and each block's `tpa` triangles in one more,
     * so a frame only sets transforms, refits the `tpa` sub-scenes and rebuilds the top level;
     * true builds the one flat structure of a still scene (a frame then refits all of it). */
    bool flatten_animation;
    /* Animated scenes, instanced: true moves the world-space vertices of keyframed blocks of
     * triangles (no spheres or cones) under the identity and refits their sub-scenes every frame,
     * instead of setting their transforms (to measure what a refit of them costs) */
    bool refit_blocks;
} rp_render_scene_desc;

/* Returns the defaults for every zero field of desc (NULL gives all defaults). */
RP_API rp_render_scene_desc rp_render_scene_desc_defaults(const rp_render_scene_desc *desc);
/* Builds and commits a render scene from loaded data (borrowed, see above); NULL desc means the
 * defaults. On failure returns NULL and writes a message into err. */
RP_API rp_render_scene *rp_render_scene_new(rp_device *device, const rp_scene_data *data,
                                            const rp_render_scene_desc *desc, char *err,
                                            size_t err_size);
/* Frees the render scene and releases its core scene. */
RP_API void rp_render_scene_release(rp_render_scene *scene);
/* The committed core scene (not retained; valid while the render scene lives). */
RP_API rp_scene *rp_render_scene_core(rp_render_scene *scene);
/* The closest hit of one ray as the renderer sees it: rp_intersect1 on the core scene, passing
 * through the cut-out points of alpha-tested surfaces (map_d, glTF alphaMode MASK/BLEND), as every
 * integrator's rays do (a viewer's pick ray; the core alone stops at a leaf's holes). */
RP_API void rp_render_scene_intersect1(rp_render_scene *scene, rp_rayhit *rayhit);
/* The scene file's camera, or one that frames the scene's bounds when the file had none: y up, fov 45,
 * from +z (glTF's front) unless -z, +x or -x sees clearly more front faces (an eighth more of a 12 x 12
 * grid of rays); a room or building that shows back faces from every side is seen from inside. */
RP_API rp_camera rp_render_scene_default_camera(rp_render_scene *scene);
/* True when the scene holds a participating medium (its data had a volume); its world box in
 * *bounds when bounds is not NULL. */
RP_API bool rp_render_scene_medium(const rp_render_scene *scene, rp_bounds *bounds);
/* The physically based lights of the scene (area triangles, point, spot, directional,
 * environment; valid while the render scene lives) and their count. */
RP_API const rp_light_source *rp_render_scene_lights(const rp_render_scene *scene, size_t *count);
/* The renderer's material of index i (i < material count of the data). */
RP_API const rp_material *rp_render_scene_material(const rp_render_scene *scene, size_t i);

/* What rp_render_scene_set_time did (wall times in milliseconds). */
typedef struct rp_render_update_stats {
    double update_ms;         /* all of it: eval_ms + refit_ms + top_ms + lights and bounds */
    double eval_ms;           /* rp_scene_data_set_time: the splines and the flat arrays */
    double refit_ms;          /* commits of the sub-scenes whose vertices moved (the flat build: its one commit) */
    double top_ms;            /* commit of the top level (the instances) */
    uint32_t instances;       /* instances placed anew */
    uint32_t refits, rebuilds; /* structures the update's commits refitted / rebuilt */
} rp_render_update_stats;

/* Moves an animated render scene to time t: data (the rp_scene_data the scene was made from, passed
 * again non-const: the only change to it a render scene allows) goes to t with
 * rp_scene_data_set_time, then instance transforms, moved `tpa` vertices (refit), the top level,
 * the lights and the bounds follow. The camera is the data's (rp_render_scene_default_camera).
 * Not while a frame renders. stats may be NULL. False for a still scene, other data or a failed
 * commit. */
RP_API bool rp_render_scene_set_time(rp_render_scene *scene, rp_scene_data *data, float time,
                                     rp_render_update_stats *stats);

/* ---- rendering -------------------------------------------------------------------------------- */

typedef enum rp_integrator_type {
    RP_INTEGRATOR_WHITTED = 0,  /* point lights, hard shadows, mirror reflection, refraction */
    RP_INTEGRATOR_EYELIGHT = 1, /* primary rays only: |cos| between geometric normal and ray */
    RP_INTEGRATOR_AOV = 2,      /* one debug output of the primary hit, see rp_aov */
    RP_INTEGRATOR_DIRECT = 3,   /* direct lighting: light and BSDF sampling with MIS */
    RP_INTEGRATOR_PATH = 4,     /* path tracing: NEE, MIS (power heuristic), Russian roulette */
    RP_INTEGRATOR_IR = 5,       /* instant radiosity, interleaved sampling, discontinuity buffer */
    RP_INTEGRATOR_AO = 6        /* ambient occlusion: the unoccluded fraction of the hemisphere */
} rp_integrator_type;

/* Instant radiosity (Keller 1997; Wald et al. 2002, interleaved sampling and the discontinuity
 * buffer). Every sample of a frame traces fresh VPLs: interleave^2 sets of vpls each; every N x N
 * block of pixels sees each set once, pixel (x, y) set (x mod N) + N (y mod N) when the filter is N
 * wide or more, else in an order hashed from the block and the sample (so the error is noise, not
 * a pattern of period N). */
typedef struct rp_ir_desc {
    int interleave;   /* N of N x N interleaved sampling; 0: 5 */
    int vpls;         /* VPLs per set (= per pixel and sample); 0: 16 */
    int filter;       /* discontinuity buffer side (odd); 0: 3, 1 or negative: no filter */
    float clamp;      /* the geometry term's distance is at least clamp times the scene's bounding
                       * radius (cos cos / max(d, c)^2, which bounds the spikes near a VPL); 0:
                       * 0.02; negative: no clamping (unbiased) */
    int depth;        /* bounces of the light paths; 0: max_depth - 1 (reflections as path counts them) */
    float rr;         /* Russian roulette on the shadow rays of small contributions: a contribution
                       * of luminance l under rr times its pixel's mean unoccluded contribution
                       * over the VPLs (t) traces its shadow ray with probability l / t and is then
                       * weighted t / l (unbiased, noisier, fewer rays); 0: 2; negative: off */
} rp_ir_desc;

typedef enum rp_aov {
    RP_AOV_DEPTH = 0,  /* 1 channel: distance along the normalized primary ray, +inf on a miss */
    RP_AOV_NORMAL = 1, /* 3 channels: shading normal mapped to [0,1] as 0.5 n + 0.5 */
    RP_AOV_PRIMID = 2, /* 3 channels: a colour hashed from (geom_id, prim_id), black on a miss */
    RP_AOV_ALBEDO = 3  /* 3 channels: the material's base colour, textures included */
} rp_aov;

typedef enum rp_ray_kind {
    RP_RAY_PRIMARY = 0,
    RP_RAY_SHADOW = 1,
    RP_RAY_REFLECTION = 2,
    RP_RAY_REFRACTION = 3,
    RP_RAY_BOUNCE = 4,    /* path tracing's diffuse and glossy bounces, and VPL paths */
    RP_RAY_KIND_COUNT = 5
} rp_ray_kind;

/* Called while a frame renders, never by two threads at once; rays counts all kinds so far. */
typedef void (*rp_render_progress_fn)(void *user, uint32_t tiles_done, uint32_t tiles_total,
                                      uint64_t rays);
/* Called on device thread `thread` (in [0, rp_device_thread_count)) once per tile, when the tile's
 * pixels [x0, x1) x [y0, y1) are final, while other tiles render (instant radiosity's: after every
 * tile, whose filter reads neighbours); lets a caller consume a tile while it is in cache. */
typedef void (*rp_render_tile_fn)(void *user, int x0, int y0, int x1, int y1, uint32_t thread);

/* Where the physically based integrators' per-pixel numbers come from; both are functions of
 * (pixel, sample index, dimension). */
typedef enum rp_sampler_type {
    RP_SAMPLER_PCG = 0,  /* hashed PCG, independent per dimension */
    RP_SAMPLER_SOBOL = 1 /* Owen-scrambled Sobol, padded in 4D (Burley 2020): lower error per sample */
} rp_sampler_type;

typedef struct rp_render_desc {
    int width, height;          /* 0: 512 */
    int spp;                    /* samples per pixel, 0: 1; sample 0 is the pixel centre, the others
                                 * are jittered from (pixel, sample index) */
    rp_integrator_type integrator;
    rp_aov aov;                 /* with RP_INTEGRATOR_AOV; AOVs trace the pixel centre only */
    int max_depth;              /* Whitted: reflection/refraction bounces; path: bounces (and
                                 * scattering events in a medium); 0: 5 (64 with a medium),
                                 * negative: none */
    int reflect_depth;          /* Whitted: a hit at depth d (primary: 0) spawns a reflection ray
                                 * only when d < reflect_depth; 0: max_depth, negative: none */
    int refract_depth;          /* Whitted: the same for refraction rays (Overbeck et al.'s fig. 1:
                                 * reflect 1, refract 4); giving either makes max_depth the larger */
    rp_ir_desc ir;              /* with RP_INTEGRATOR_IR */
    float ao_distance;          /* ambient occlusion ray length; 0: 0.1 of the bounding radius */
    const rp_camera *camera;    /* NULL: rp_render_scene_default_camera */
    int tile_size;              /* 0: 16 */
    float ambient;              /* Whitted ambient term relative to kd; 0: 0.08, negative: none */
    rp_render_progress_fn progress;
    void *progress_user;
    /* Whitted traces n x n packets breadth first per ray kind (Overbeck et al. 2008): a tile block's
     * primary packet, one shadow packet per light, then its reflection and refraction packets, down
     * to max_depth. Every setting gives the same image. */
    int packet;                 /* rays per packet side: 4, 8, 16 or 32; 0: 16; negative: one ray at
                                 * a time, depth first (the reference tracer) */
    rp_traversal traversal;     /* packet traversal of every ray kind; 0 (AUTO): chosen per kind */
    bool no_frustum;            /* true: packets are traced without frustum culling */
    bool count_work;            /* true: fill rp_render_stats.work (packet tracing only) */
    int sample_start;           /* first sample index: a frame renders samples [sample_start, sample_start + spp), so callers can accumulate frames progressively; 0: from the first */
    int region[4];              /* x0, y0, x1, y1 of the pixels to render (others untouched); all 0: the whole image */
    rp_ray *bounce_rays;        /* path tracing, when not NULL (2 * width * height rays, the caller's):
                                 * sample sample_start's bounce rays of depth d = 1, 2 (leaving the
                                 * primary hit, then the next), pixel (x, y)'s at [(d - 1) * width *
                                 * height + y * width + x]; tfar < 0 where the path had no such ray */
    rp_sampler_type sampler;    /* direct, path, ao, ir: the pixels' numbers; 0: PCG */
    /* true: pixels hold a sum of earlier samples; the frame's samples are added to it in order and
     * the sum is written back unscaled, so frames of samples [0, k), [k, m), ... leave the sum a
     * single [0, m) render adds up (its mean is the sum / m). Not with instant radiosity. */
    bool accumulate;
    rp_render_tile_fn tile_done; /* NULL: none */
    void *tile_user;
} rp_render_desc;

typedef struct rp_render_stats {
    uint64_t rays[RP_RAY_KIND_COUNT];
    double render_ms;
    rp_counters_n work[RP_RAY_KIND_COUNT]; /* traversal work per ray kind, with desc.count_work */
} rp_render_stats;

/* Returns the defaults for every zero field of desc (NULL gives all defaults). */
RP_API rp_render_desc rp_render_desc_defaults(const rp_render_desc *desc);
/* Channels per pixel of the frame desc describes: 1 for the depth AOV, else 3. */
RP_API int rp_render_channels(const rp_render_desc *desc);
/* Renders a frame into pixels (width * height * rp_render_channels floats, linear, top row first)
 * on the device's threads; with desc.region only the pixels inside it are written, each exactly as
 * the whole frame would have it. stats may be NULL. Returns false on bad arguments (a packet size
 * other than 4, 8, 16 or 32, a region not inside the image, accumulate with instant radiosity, a
 * camera with no frame: not finite, eye == look, up along the view, fov outside (0, 180))
 * or out of memory. Instant radiosity renders a region's margin of its filter radius too (its
 * discontinuity buffer reads those neighbours). */
RP_API bool rp_render(rp_render_scene *scene, const rp_render_desc *desc, float *pixels,
                      rp_render_stats *stats);

/* The primary rays of a width x height image through the pixels' centres (sample 0), as rp_render
 * makes them, row by row from the top-left pixel into out (width * height rays, the caller's). */
RP_API void rp_render_primary_rays(const rp_camera *camera, int width, int height, rp_ray *out);
/* The eye-light integrator's value of a primary ray and its hit: |cos| between the geometric normal
 * and the ray, 0 on a miss (the pixel is this grey). */
RP_API float rp_render_eyelight(const rp_rayhit *rayhit);

/* ---- film --------------------------------------------------------------------------------------- */

typedef enum rp_tonemap {
    RP_TONEMAP_SRGB = 0, /* linear values clamped to [0, 1] (the image writer then encodes sRGB) */
    RP_TONEMAP_ACES = 1  /* the ACES filmic curve (Narkowicz's fit), then sRGB */
} rp_tonemap;

/* Scales count pixels of channels floats by 2^exposure and applies the tone curve, in place, for an
 * 8-bit image. Radiance stays linear in PFM, HDR and EXR files: do not call it for those. */
RP_API void rp_film_tonemap(float *pixels, size_t count, int channels, float exposure, rp_tonemap tonemap);

/* ---- built-in scene --------------------------------------------------------------------------- */

/* Fills out with the built-in demo scene (an ERW6-like room: boxes, a mirror, a glass sphere and a
 * point light, camera included). Free it with rp_default_scene_free. */
RP_API bool rp_default_scene(rp_scene_data *out);
/* Frees the arrays of a scene made by rp_default_scene and zeroes it. */
RP_API void rp_default_scene_free(rp_scene_data *scene);

#ifdef __cplusplus
}
#endif
#endif /* RAYPACK_RENDER_H */
