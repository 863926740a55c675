/* raypack I/O: scene loaders and image files.
 *
 * A loader turns a scene file into plain flat arrays (rp_scene_data): no pointers into other
 * objects, so a scene can be handed to the core API, sent to MPI ranks or copied to a GPU.
 * Formats: Wavefront OBJ+MTL, PLY (ASCII, binary LE/BE), NFF and BART's AFF; any of them gzip'd
 * (.gz), and tar archives (.tar, .tar.gz) holding a scene (BART's kitchen and museum). glTF 2.0
 * (.gltf, .glb) and the other formats assimp reads (FBX, COLLADA, 3DS, STL, ...) through assimp,
 * from plain files: node hierarchies flattened, the first camera, point lights, and materials with
 * the base colour (factor x texture, external or embedded) as kd and the emissive colour as ke.
 * OpenVDB (.vdb): a float density grid as a volume (rp_volume_data), no surfaces.
 *
 * Ownership: every array in rp_scene_data is owned by it and freed by rp_scene_data_free.
 */
#ifndef RAYPACK_IO_H
#define RAYPACK_IO_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if !defined(RP_API)
#if defined(_WIN32)
#define RP_API __declspec(dllexport)
#else
#define RP_API __attribute__((visibility("default")))
#endif
#endif

/* How a material's alpha (coverage) is used: alpha-tested geometry (leaves and fences as textured
 * quads). OPAQUE ignores it; MASK cuts the surface out where alpha < alpha_cutoff (glTF's "MASK",
 * MTL map_d); BLEND cuts it out with probability 1 - alpha, a stochastic alpha test (glTF's
 * "BLEND"): the renderer compares alpha with a hash of the ray, so images stay deterministic. */
typedef enum rp_alpha_mode { RP_ALPHA_OPAQUE = 0, RP_ALPHA_MASK = 1, RP_ALPHA_BLEND = 2 } rp_alpha_mode;

/* Material as the scene file states it (MTL and NFF/AFF parameters); the renderer maps it to its
 * own BSDFs. Colours are linear RGB. */
typedef struct rp_material_data {
    char name[64];
    float kd[3];        /* diffuse (MTL Kd, NFF colour * Kd) */
    float ks[3];        /* Phong specular highlight (MTL Ks, NFF colour-less Ks) */
    float ke[3];        /* emission (MTL Ke) */
    float kr[3];        /* mirror reflectance (MTL illum 3/5/7 uses Ks; NFF Ks) */
    float kt[3];        /* transmittance (MTL 1-d or Tf with illum 4/6/7/9; NFF T) */
    float ns;           /* Phong exponent (MTL Ns, NFF Shine) */
    float ior;          /* index of refraction (MTL Ni, NFF index_of_refraction); 1 if absent */
    int32_t illum;      /* MTL illum model; -1 for NFF/AFF/PLY */
    int32_t map_kd;     /* index into textures of the diffuse texture, or -1 */
    float ka[3];        /* ambient (MTL Ka, AFF fm); an MTL Ka above 1 is emission by tinyobjloader's convention */
    int32_t map_roughness; /* 1 + index into textures of a roughness map (MTL map_Pr), 0 if none */
    int32_t map_normal;    /* 1 + index into textures of a tangent-space normal map (MTL norm), 0 if none */
    int32_t map_ke;        /* 1 + index into textures multiplying ke (MTL map_Ke, glTF emissive texture,
                            * AFF's textured ambient-only surfaces), 0 if none */
    /* glTF's metallic-roughness model (base colour: kd, map_kd), when metal_rough is true; the
     * Phong fields above then say nothing more */
    bool metal_rough;
    float metallic;        /* metallic factor in [0, 1] */
    float roughness;       /* perceptual roughness factor r in [0, 1] (GGX alpha = r^2) */
    int32_t map_metal_rough; /* 1 + index into textures whose green channel (roughness) and blue
                              * channel (metallic), linear, multiply the factors; 0 if none */
    /* Alpha cutouts (rp_alpha_mode): a surface point's alpha is `alpha` times the alpha texture's
     * alpha plane there (its red channel where the texture has none). MTL map_d: MASK, cutoff 0.5;
     * glTF: alphaMode, alphaCutoff, baseColorFactor[3] and the base colour texture's alpha. MTL `d`
     * is not this: it makes a dielectric (kt). */
    rp_alpha_mode alpha_mode;
    float alpha;           /* factor in [0, 1]; 1 after builder defaults */
    float alpha_cutoff;    /* MASK: cut out below it; 0.5 after builder defaults */
    int32_t map_alpha;     /* 1 + index into textures of the alpha texture, 0 if none */
    /* Where uv_transform is true, every texture of the material is read at the texture coordinates
     * (u, v) mapped to (t[0] u + t[1] v + t[2], t[3] u + t[4] v + t[5]) (MTL -s and -o, glTF
     * KHR_texture_transform; v up, as in OBJ); false: as they are (t is then ignored) */
    bool uv_transform;
    float uv_matrix[6];
    int32_t map_ks;        /* 1 + index into textures multiplying ks (MTL map_Ks, sRGB decoded), 0 if none */
} rp_material_data;

/* How a texture lookup treats texture coordinates outside [0, 1], per axis (glTF's sampler wrapS
 * and wrapT, MTL's -clamp): REPEAT tiles the image, CLAMP reads the edge texels beyond it
 * (CLAMP_TO_EDGE), MIRROR tiles it flipped every other time (MIRRORED_REPEAT). */
typedef enum rp_texture_wrap { RP_TEXTURE_REPEAT = 0, RP_TEXTURE_CLAMP = 1, RP_TEXTURE_MIRROR = 2 } rp_texture_wrap;
/* How texels are filtered: LINEAR blends the four nearest (bilinear), NEAREST reads the one texel
 * the point falls in (glTF's magFilter NEAREST: pixel art stays blocky). */
typedef enum rp_texture_filter { RP_TEXTURE_LINEAR = 0, RP_TEXTURE_NEAREST = 1 } rp_texture_filter;

/* Image texture, decoded to 8-bit RGB (sRGB encoded, as stored in the file), and its alpha channel
 * where the file has one (RGBA or grey-alpha PNG, TGA, BMP).
 *
 * A texture is an image together with the way it is sampled (wrap, filter): every lookup of it,
 * in every material, integrator, engine and the alpha test, uses these. Loaders share an entry
 * between the materials that read the same image the same way; where a scene reads one image
 * under two samplers (or with MTL -mm's remap, baked into the texels), each gets an entry of its
 * own with its own copy of the texels, so entries never share memory. All zero (repeat, bilinear)
 * is the default, and what a texture built by hand gets from calloc. */
typedef struct rp_texture_data {
    char path[256];     /* the path the scene named, as written */
    int32_t width, height;
    uint8_t *rgb;       /* width * height * 3 bytes, top row first */
    uint8_t *alpha;     /* width * height bytes (linear coverage, 255 opaque), top row first; NULL
                         * when the file has no alpha channel. Owned like rgb */
    rp_texture_wrap wrap_u, wrap_v; /* outside [0, 1] along u and v (v up, as texture coordinates) */
    rp_texture_filter filter;
} rp_texture_data;

/* Point lights (NFF/AFF, glTF); spot and directional lights come from glTF's KHR_lights_punctual
 * (and assimp's other formats). Whitted renders the point lights; the physically based integrators
 * all three. */
typedef enum rp_light_type {
    RP_LIGHT_DATA_POINT = 0,
    RP_LIGHT_DATA_SPOT = 1,
    RP_LIGHT_DATA_DIRECTIONAL = 2
} rp_light_type;

typedef struct rp_light_data {
    rp_light_type type;
    float position[3];  /* point and spot */
    float color[3];     /* point, spot (on its axis): intensity; directional: irradiance. NFF lights
                         * without a colour get 1,1,1 */
    float direction[3]; /* spot: unit, where its cone points; directional: unit, where the light travels */
    float cos_inner, cos_outer; /* spot: full intensity inside cos_inner, none outside cos_outer */
} rp_light_data;

/* Pinhole camera of DESIGN.md (eye, look-at point, up, vertical field of view in degrees). */
typedef struct rp_camera_data {
    bool valid;         /* false: the file had no camera */
    float eye[3], look[3], up[3];
    float fov_deg;      /* vertical */
    int32_t width, height; /* resolution the file asks for, 0 if none */
} rp_camera_data;

typedef struct rp_sphere_data {
    float center[3];
    float radius;
    uint32_t material;
} rp_sphere_data;

/* Cone or cylinder (NFF `c`): a frustum between two capped-off circles; not counted as triangles. */
typedef struct rp_cone_data {
    float base[3];
    float base_radius;
    float apex[3];
    float apex_radius;
    uint32_t material;
} rp_cone_data;

/* ---- animation (BART's AFF: Lext, Assarsson, Moller 2001) --------------------------------------
 * An AFF scene is animated by `x name { ... }` blocks whose transform comes from a `k name { ... }`
 * block of keyframes (translation, rotation, scale: Kochanek-Bartels splines, BART's reference
 * interpolation; visibility: steps), by `tpa` triangles whose corners are keyed (linear between
 * keys), and by `k camera` (the viewpoint's path: eye from the translation, view direction -z and up
 * +y of the rotation). The flat arrays of rp_scene_data always hold the scene at one time (after
 * loading: the animation's start, BART's frame 0); rp_scene_data_set_time moves them to another. */

typedef enum rp_anim_channel { RP_ANIM_TRANSL = 0, RP_ANIM_ROT = 1, RP_ANIM_SCALE = 2 } rp_anim_channel;

/* One keyframe. value: xyz for translation and scale; axis xyz and angle in degrees for rotation.
 * A spline of n >= 4 keys runs from key 1 to key n-2 (clamped outside); keys 0 and n-1 only shape
 * the tangents at its ends, as in BART. */
typedef struct rp_anim_key {
    float time;
    float value[4];
    float tension, continuity, bias;
} rp_anim_key;

/* Keys [first, first + count) of rp_animation_data.keys; count 0: the channel is absent. */
typedef struct rp_anim_track {
    uint32_t first, count;
} rp_anim_track;

/* An `x name` block. Elements inside it (innermost block) are stored in "rest" space: as the file
 * places them with every keyframed transform left out; xfm maps rest space to the world at the
 * current time: xfm = xfm(parent) * rest * K(t) * rest^-1, K(t) = T R S of the block's keys. */
typedef struct rp_anim_node {
    char name[64];
    int32_t parent;          /* enclosing `x` block, -1 for none */
    float rest[12];          /* 3x4 transform in force where the block opens (keys left out) */
    rp_anim_track track[3];  /* by rp_anim_channel */
    uint32_t vis_first, vis_count; /* visibility keys (vis_times, vis_values) */
    float xfm[12];           /* rest space -> world at the current time (set by rp_scene_data_set_time) */
    bool visible;            /* at the current time (this block and every enclosing one) */
} rp_anim_node;

/* A `tpa` triangle: count keys of 19 floats each (time, then per corner position xyz and normal
 * xyz) in tpa_keys from first; between two keys its corners move linearly, before the first and
 * after the last they stay (BART). */
typedef struct rp_anim_tpa {
    uint32_t triangle;       /* index of the triangle in the mesh */
    uint32_t vertex, normal; /* its corners' first position and normal (three in a row, file order) */
    uint32_t first, count;
} rp_anim_tpa;

typedef struct rp_animation_data {
    float start, end;        /* the `a` line's time range (without one: the keys' range) */
    int32_t frames;          /* frames of the animation (`a`); a frame's time is start + i (end - start) / (frames - 1) */
    float time;              /* the time the flat arrays hold */
    size_t node_count;
    rp_anim_node *nodes;
    size_t key_count;
    rp_anim_key *keys;
    size_t vis_count;
    float *vis_times;
    uint8_t *vis_values;
    rp_anim_track camera[2]; /* `k camera`: RP_ANIM_TRANSL and RP_ANIM_ROT; counts 0: still camera */
    size_t tpa_count;
    rp_anim_tpa *tpas;
    float *tpa_keys;
    /* per element of the flat arrays: the innermost `x` block holding it, -1 for none */
    int32_t *tri_node, *sphere_node, *cone_node, *light_node;
    int32_t *vertex_node, *normal_node;
    uint8_t *tri_tpa;        /* triangle_count: 1 for `tpa` triangles */
    /* rest-space copies of the flat arrays (same counts); positions of `tpa` corners at the current time */
    float *rest_positions, *rest_normals;
    rp_sphere_data *rest_spheres;
    rp_cone_data *rest_cones;
    rp_light_data *rest_lights;
    rp_camera_data rest_camera; /* the `v` viewpoint */
} rp_animation_data;

/* ---- volumes (OpenVDB) ---------------------------------------------------------------------------
 * A density grid read from a .vdb file (src/io/io_vdb.cpp), stored as a sparse brick grid: the
 * index-space box of the active voxels, widened by one voxel on every side (trilinear lookups
 * ramp down to 0 there), is cut into bricks of RP_VOLUME_BRICK^3 voxels; a dense table over the
 * bricks gives each one's slot in `density`, or RP_VOLUME_EMPTY for a brick without active
 * voxels, which is not stored. Voxel (i, j, k) of index space is centred at index coordinates
 * (i, j, k), as in OpenVDB; index_to_world maps index coordinates to the world (the grid's linear
 * transform). Inactive voxels read as 0, and so do negative, NaN and infinite values. */
#define RP_VOLUME_BRICK 8
#define RP_VOLUME_EMPTY UINT32_MAX
typedef struct rp_volume_data {
    char grid_name[64];          /* the grid read */
    float index_to_world[12];    /* 3x4 affine, row-major: world = M (i, j, k, 1) */
    int32_t active_min[3], active_max[3]; /* active voxels' bounding box, inclusive */
    uint64_t active_voxels;      /* voxels copied (OpenVDB's active voxel count) */
    int32_t origin[3];           /* index of brick (0, 0, 0)'s first voxel: active_min - 1 */
    uint32_t dims[3];            /* bricks per axis, covering [active_min - 1, active_max + 1] */
    uint32_t *brick_slot;        /* dims[0] * dims[1] * dims[2], x fastest: slot or RP_VOLUME_EMPTY */
    uint32_t brick_count;        /* bricks stored */
    float *density;              /* brick_count * RP_VOLUME_BRICK^3, x fastest within a brick */
    float *brick_max;            /* brick_count: the largest density of each stored brick */
    float max_density;           /* over the whole grid */
} rp_volume_data;

typedef struct rp_scene_data {
    /* Triangle mesh: positions are indexed by `indices`; normals and texcoords, when present, have
     * their own per-corner index arrays (OBJ style), NULL when absent. */
    size_t vertex_count;
    float *positions;           /* 3 * vertex_count */
    size_t normal_count;
    float *normals;             /* 3 * normal_count, or NULL */
    size_t texcoord_count;
    float *texcoords;           /* 2 * texcoord_count, or NULL */
    size_t triangle_count;
    uint32_t *indices;          /* 3 * triangle_count, into positions */
    uint32_t *normal_indices;   /* 3 * triangle_count, into normals, or NULL */
    uint32_t *texcoord_indices; /* 3 * triangle_count, into texcoords, or NULL */
    uint32_t *tri_materials;    /* triangle_count, into materials */
    /* A colour per position (3 * vertex_count, linear RGB), multiplying the material's base colour
     * (kd, glTF's base colour) across each triangle; NULL when the file gives none. From PLY's
     * red/green/blue vertex properties and OBJ's `v x y z r g b` (sRGB-encoded values, decoded),
     * and assimp's first colour set (glTF's COLOR_0: linear, taken as it is). Vertices a file
     * leaves uncoloured are white. */
    float *colors;

    size_t sphere_count;
    rp_sphere_data *spheres;
    float *sphere_colors;       /* 3 * sphere_count or NULL: a coloured point cloud's colours */
    size_t cone_count;
    rp_cone_data *cones;

    size_t material_count;      /* >= 1: loaders add a default grey diffuse material if needed */
    rp_material_data *materials;
    size_t texture_count;
    rp_texture_data *textures;
    size_t light_count;
    rp_light_data *lights;

    rp_camera_data camera;
    float background[3];        /* NFF `b`; 0,0,0 if absent */
    bool has_background;

    size_t file_bytes;          /* bytes parsed, after decompression */
    double parse_ms;            /* wall time of rp_scene_data_load */
    rp_animation_data *animation; /* AFF animation, owned by the scene; NULL for a still scene */
    rp_volume_data *volume;     /* a participating medium's density (.vdb), owned; NULL: none */
} rp_scene_data;

/* Loads a scene file (format from the extension; .gz and .tar(.gz) are unpacked transparently).
 * On failure returns false and writes "file:line: error: message" into err (err_size bytes);
 * out is then empty and needs no free. */
RP_API bool rp_scene_data_load(const char *path, rp_scene_data *out, char *err, size_t err_size);
/* How rp_scene_data_load_ex loads; zero fields mean the defaults. */
typedef struct rp_scene_load_desc {
    /* Threads that parse a large OBJ, NFF/AFF or ASCII PLY file in chunks (files under 512 kB are
     * parsed on the calling thread): 0 all hardware threads, 1 the calling thread alone. The
     * result is the same for every count, to the bit and in the same order, and so are errors. */
    int threads;
    /* A point cloud (a scene of vertices alone: a PLY without faces, an OBJ of `v` lines) becomes a
     * sphere at each finite vertex, of this radius; 0: half the median distance between
     * neighbouring points (from a sample of 64), so a sampled surface is closed. */
    float point_radius;
    /* A .vdb file: the float grid to read; NULL or "": the one named "density", else the first
     * float grid of the file. */
    const char *volume_grid;
    /* Receives each warning of the load, "file:line: warning: message" (a usemtl naming no material
     * of the file's libraries, ...), on the thread that called the load; the scene still loads.
     * NULL: warnings are dropped. At most RP_LOAD_MAX_WARNINGS are passed on, then one saying how
     * many more there were. */
    void (*warning)(void *user, const char *message);
    void *warning_user;
} rp_scene_load_desc;
#define RP_LOAD_MAX_WARNINGS 20
/* Fills desc with the defaults. */
RP_API void rp_scene_load_desc_defaults(rp_scene_load_desc *desc);
/* rp_scene_data_load with options (desc NULL: the defaults, what rp_scene_data_load uses). */
RP_API bool rp_scene_data_load_ex(const char *path, const rp_scene_load_desc *desc, rp_scene_data *out, char *err,
                                  size_t err_size);
/* Gives a scene a homogeneous medium filling the box lo-hi: a volume of 16^3 voxels of density 1
 * whose centres span the box (so the density is 1 inside it and fades to 0 within a sixteenth of
 * its size outside). Replaces the scene's volume, if any; false when out of memory or the box is
 * empty or not finite. */
RP_API bool rp_scene_data_add_medium_box(rp_scene_data *scene, const float lo[3], const float hi[3]);
/* Frees every array of a loaded scene and zeroes it. */
RP_API void rp_scene_data_free(rp_scene_data *scene);
/* Moves an animated scene's flat arrays (positions, normals, spheres, cones, lights, camera) and
 * its nodes' xfm and visible to time t (clamped to nothing: BART's splines clamp at their ends).
 * Returns false for a still scene (nothing changes). */
RP_API bool rp_scene_data_set_time(rp_scene_data *scene, float time);
/* Time of frame i of the animation (start + i (end - start) / (frames - 1)); start for a still scene. */
RP_API float rp_scene_data_frame_time(const rp_scene_data *scene, int frame);
/* Time of frame i of count spread evenly over the animation's range, first and last included
 * (start + i (end - start) / (count - 1); start when count <= 1): `raypack animate --frames`'s rule,
 * shared by every command that renders a sequence. 0 for NULL. */
RP_API float rp_anim_frame_time(const rp_animation_data *anim, int frame, int count);
/* Value of one track at time t: xyz for translation and scale, a unit quaternion (x, y, z, w) for
 * rotation (BART: squad through the keys with Kochanek-Bartels tangents of the quaternion logs). */
RP_API void rp_anim_track_eval(const rp_animation_data *anim, rp_anim_track track, rp_anim_channel channel,
                               float time, float out[4]);
/* Keeps only the lights whose indices are listed (in that order); false when one is out of range. */
RP_API bool rp_scene_data_keep_lights(rp_scene_data *scene, const uint32_t *keep, size_t count);


/* Writes an image; the format follows the extension: .png and .ppm (8-bit, linear values clamped
 * to [0,1] and sRGB-encoded), .pfm (32-bit float, linear, standard PFM: rows bottom-up, negative
 * scale = little endian), .hdr (Radiance RGBE, linear), .exr
 * (OpenEXR float, linear). channels is 1 or 3; pixels are row-major, top row first.
 * Returns false and writes "path: error: message" into err on failure. */
RP_API bool rp_image_write(const char *path, int width, int height, int channels, const float *pixels,
                           char *err, size_t err_size);
/* Reads a Radiance .hdr image into a malloc'ed RGB float array, top row first (caller frees). */
RP_API float *rp_image_read_hdr(const char *path, int *width, int *height, char *err, size_t err_size);
/* Atomic output files. Every writer goes through these, so that a failed write (full disk, a
 * file-size limit) leaves the previous file intact: the bytes go to a temporary file in the same
 * folder, renamed over the destination only when all were written and flushed; on failure the
 * temporary file is removed. A symbolic link at the destination is kept and its target replaced. */
typedef struct rp_atomic_file rp_atomic_file;
/* Opens a temporary file beside path; NULL and "path: error: why" in err when it cannot. */
RP_API rp_atomic_file *rp_atomic_open(const char *path, char *err, size_t err_size);
/* The temporary file's stdio stream (a FILE *, open for binary writing); valid until commit/abort. */
RP_API void *rp_atomic_stream(rp_atomic_file *af);
/* The temporary file's path (for writers that need a file name); valid until commit/abort. */
RP_API const char *rp_atomic_temp_path(const rp_atomic_file *af);
/* Marks the output failed (errnum: the errno to report, 0 for EIO): commit then discards it. */
RP_API void rp_atomic_fail(rp_atomic_file *af, int errnum);
/* Flushes, closes and renames into place, or removes the temporary file when any write failed
 * (then false and the reason in err). Frees af either way. */
RP_API bool rp_atomic_commit(rp_atomic_file *af, char *err, size_t err_size);
/* Discards the temporary file without touching the destination; frees af. */
RP_API void rp_atomic_abort(rp_atomic_file *af);
/* The whole cycle: write(stream, user) fills the stream (a FILE *) and returns false on failure. */
RP_API bool rp_atomic_write(const char *path, bool (*write)(void *stream, void *user), void *user, char *err,
                            size_t err_size);

/* Reads a PFM (1 or 3 channels) into a malloc'ed float array, top row first (caller frees). */
RP_API float *rp_image_read_pfm(const char *path, int *width, int *height, int *channels, char *err,
                                size_t err_size);

#ifdef __cplusplus
}
#endif
#endif /* RAYPACK_IO_H */
