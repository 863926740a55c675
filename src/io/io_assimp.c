/* glTF 2.0 (.gltf, .glb) and the other formats assimp reads (FBX, COLLADA, 3DS, STL, ...) through
 * assimp's C API. OBJ, PLY, NFF and AFF never come here: raypack's own loaders read them.
 *
 * The node hierarchy is flattened: every mesh a node names is appended once per node, its
 * positions and normals taken through the node's world transform (raypack has no instancing to map
 * nodes onto yet). Cameras become the pinhole camera of DESIGN.md (an orthographic one is left out
 * with a warning), point, spot and directional lights (glTF KHR_lights_punctual, and other formats'
 * lights) rp_light_data's (area and ambient lights are left out with a warning). Materials: see
 * material_from_assimp. assimp reads from the disk itself (external .bin buffers and images), so these formats load neither
 * gzip'd nor from inside a tar archive. */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <sys/stat.h>

#include "io/io_internal.h"

#if defined(RP_IO_HAVE_ASSIMP)
#include <assimp/GltfMaterial.h>
#include <assimp/cimport.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/version.h>

bool assimp_can_load(const char *ext) {
    char dotted[24];
    if (!ext[0] || strlen(ext) > 16) return false;
    snprintf(dotted, sizeof dotted, ".%s", ext);
    return aiIsExtensionSupported(dotted) == AI_TRUE;
}

typedef struct mat4 {
    float m[4][4]; /* row-major, column vectors: p' = m p (assimp's aiMatrix4x4 layout) */
} mat4;

static mat4 mat4_from_ai(const struct aiMatrix4x4 *a) {
    mat4 r = {{{a->a1, a->a2, a->a3, a->a4},
               {a->b1, a->b2, a->b3, a->b4},
               {a->c1, a->c2, a->c3, a->c4},
               {a->d1, a->d2, a->d3, a->d4}}};
    return r;
}

static mat4 mat4_mul(const mat4 *a, const mat4 *b) {
    mat4 r;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            r.m[i][j] = a->m[i][0] * b->m[0][j] + a->m[i][1] * b->m[1][j] + a->m[i][2] * b->m[2][j] +
                        a->m[i][3] * b->m[3][j];
    return r;
}

static void xform_point(const mat4 *t, const float p[3], float out[3]) {
    for (int i = 0; i < 3; i++)
        out[i] = t->m[i][0] * p[0] + t->m[i][1] * p[1] + t->m[i][2] * p[2] + t->m[i][3];
}

static void xform_dir(const mat4 *t, const float d[3], float out[3]) {
    for (int i = 0; i < 3; i++) out[i] = t->m[i][0] * d[0] + t->m[i][1] * d[1] + t->m[i][2] * d[2];
}

/* Cofactor matrix of the upper 3x3: normals go through its inverse transpose, which is the
 * cofactor matrix up to the determinant's scale (normals are renormalized anyway). */
static void normal_matrix(const mat4 *t, float n[3][3], float *det) {
    const float(*a)[4] = t->m;
    n[0][0] = a[1][1] * a[2][2] - a[1][2] * a[2][1];
    n[0][1] = a[1][2] * a[2][0] - a[1][0] * a[2][2];
    n[0][2] = a[1][0] * a[2][1] - a[1][1] * a[2][0];
    n[1][0] = a[0][2] * a[2][1] - a[0][1] * a[2][2];
    n[1][1] = a[0][0] * a[2][2] - a[0][2] * a[2][0];
    n[1][2] = a[0][1] * a[2][0] - a[0][0] * a[2][1];
    n[2][0] = a[0][1] * a[1][2] - a[0][2] * a[1][1];
    n[2][1] = a[0][2] * a[1][0] - a[0][0] * a[1][2];
    n[2][2] = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    *det = a[0][0] * n[0][0] + a[0][1] * n[0][1] + a[0][2] * n[0][2];
}

typedef struct load_state {
    io_ctx *ctx;
    const char *path;
    const struct aiScene *scene;
    uint32_t *materials; /* aiMaterial index -> builder material */
    bool *light_done;    /* a light binds to the first node of its name only */
    bool have_camera;
    bool gltf;
    struct gltf_material *json; /* glTF: what its JSON says of each material that assimp 5.2 does not, or NULL */
    size_t json_n, json_cap;
} load_state;

/* ---- glTF extensions read from the JSON --------------------------------------------------------- */

/* The texture slots of a glTF material that raypack reads. */
enum { GLTF_BASE, GLTF_METAL_ROUGH, GLTF_NORMAL, GLTF_EMISSIVE, GLTF_SLOTS };

typedef struct gltf_material {
    float strength;                /* KHR_materials_emissive_strength, 1 without */
    bool transform[GLTF_SLOTS];    /* the slot's textureInfo has a KHR_texture_transform: */
    float offset[GLTF_SLOTS][2], scale[GLTF_SLOTS][2], rotation[GLTF_SLOTS];
    int32_t tex_coord[GLTF_SLOTS]; /* its texCoord, -1 when it gives none */
} gltf_material;

/* assimp 5.2 does not know KHR_materials_emissive_strength (5.3 reads it into
 * AI_MATKEY_EMISSIVE_INTENSITY), so a Blender export's emission above 1 came out that many times
 * too dim; and it gives KHR_texture_transform as an aiUVTransform re-expressed for its own
 * post-processing step (rotation negated, translation moved about the image centre), which is
 * not the extension's. The glTF's JSON is read here for both: a scanner that skips any value and
 * walks materials[i].extensions.KHR_materials_emissive_strength.emissiveStrength and the
 * extensions.KHR_texture_transform of materials[i]'s textureInfos. glTF's material i is assimp's
 * material i. Anything it cannot follow leaves the defaults (assimp has already read and checked
 * the file). */
typedef struct json_scan {
    const char *p, *end;
    const char *start; /* the JSON's first byte, for line numbers */
} json_scan;

static bool js_is_blank(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

static void js_blank(json_scan *j) {
    while (j->p < j->end && js_is_blank(*j->p)) j->p++;
}

/* A string at j->p: its raw bytes (escapes left as they are) in [*s, *s + *n). */
static bool js_string(json_scan *j, const char **s, size_t *n) {
    js_blank(j);
    if (j->p >= j->end || *j->p != '"') return false;
    const char *q = ++j->p;
    while (j->p < j->end && *j->p != '"') j->p += *j->p == '\\' ? 2 : 1;
    if (j->p >= j->end) return false;
    *s = q, *n = (size_t)(j->p++ - q);
    return true;
}

static bool js_char(json_scan *j, char c) {
    js_blank(j);
    if (j->p >= j->end || *j->p != c) return false;
    j->p++;
    return true;
}

static bool js_skip(json_scan *j, int depth) {
    js_blank(j);
    if (j->p >= j->end || depth > 64) return false;
    const char *s;
    size_t n;
    if (*j->p == '"') return js_string(j, &s, &n);
    if (*j->p == '{' || *j->p == '[') {
        char close = *j->p++ == '{' ? '}' : ']';
        if (js_char(j, close)) return true;
        do {
            if (close == '}' && (!js_string(j, &s, &n) || !js_char(j, ':'))) return false;
            if (!js_skip(j, depth + 1)) return false;
        } while (js_char(j, ','));
        return js_char(j, close);
    }
    while (j->p < j->end && !strchr(",]} \t\r\n", *j->p)) j->p++; /* number, true, false, null */
    return true;
}

static bool js_key_is(const char *s, size_t n, const char *key) { return n == strlen(key) && memcmp(s, key, n) == 0; }

/* At an object: calls field(j, key, user) for each key (which must consume the value). */
typedef bool (*js_field_fn)(json_scan *j, const char *key, size_t n, void *user);
static bool js_object(json_scan *j, js_field_fn field, void *user) {
    if (!js_char(j, '{')) return false;
    if (js_char(j, '}')) return true;
    do {
        const char *s;
        size_t n;
        if (!js_string(j, &s, &n) || !js_char(j, ':') || !field(j, s, n, user)) return false;
    } while (js_char(j, ','));
    return js_char(j, '}');
}

/* A number at j->p; false (the value skipped) when it is none. */
static bool js_number(json_scan *j, double *v) {
    js_blank(j);
    char num[64];
    size_t k = 0;
    while (j->p < j->end && k + 1 < sizeof num && !strchr(",]} \t\r\n", *j->p)) num[k++] = *j->p++;
    num[k] = '\0';
    char *e;
    *v = strtod(num, &e);
    if (k == sizeof num - 1) js_skip(j, 0);
    return k && !*e && isfinite(*v);
}

/* An array of two numbers into v (left as they were where it is not one). */
static bool js_pair(json_scan *j, float v[2]) {
    double a, b;
    if (!js_char(j, '[')) return js_skip(j, 0);
    bool ok = js_number(j, &a) && js_char(j, ',') && js_number(j, &b) && js_char(j, ']');
    if (ok) v[0] = (float)a, v[1] = (float)b;
    return ok;
}

static bool js_strength(json_scan *j, const char *key, size_t n, void *user) {
    if (!js_key_is(key, n, "emissiveStrength")) return js_skip(j, 0);
    double v;
    if (js_number(j, &v) && v >= 0.0 && v < 1e30) *(float *)user = (float)v;
    return true;
}

static bool js_extension(json_scan *j, const char *key, size_t n, void *user) {
    if (!js_key_is(key, n, "KHR_materials_emissive_strength")) return js_skip(j, 0);
    return js_object(j, js_strength, &((gltf_material *)user)->strength);
}

typedef struct js_slot {
    gltf_material *m;
    int slot;
} js_slot;

static bool js_transform(json_scan *j, const char *key, size_t n, void *user) {
    const js_slot *t = user;
    double v;
    if (js_key_is(key, n, "offset")) return js_pair(j, t->m->offset[t->slot]);
    if (js_key_is(key, n, "scale")) return js_pair(j, t->m->scale[t->slot]);
    if (js_key_is(key, n, "rotation")) {
        if (js_number(j, &v)) t->m->rotation[t->slot] = (float)v;
        return true;
    }
    if (js_key_is(key, n, "texCoord")) {
        if (js_number(j, &v) && v >= 0.0 && v < 1e6) t->m->tex_coord[t->slot] = (int32_t)v;
        return true;
    }
    return js_skip(j, 0);
}

static bool js_texture_extension(json_scan *j, const char *key, size_t n, void *user) {
    if (!js_key_is(key, n, "KHR_texture_transform")) return js_skip(j, 0);
    const js_slot *t = user;
    t->m->transform[t->slot] = true;
    return js_object(j, js_transform, user);
}

static bool js_texture_info(json_scan *j, const char *key, size_t n, void *user) {
    if (!js_key_is(key, n, "extensions")) return js_skip(j, 0);
    return js_object(j, js_texture_extension, user);
}

static bool js_pbr(json_scan *j, const char *key, size_t n, void *user) {
    js_slot t = {user, js_key_is(key, n, "baseColorTexture") ? GLTF_BASE : GLTF_METAL_ROUGH};
    if (!js_key_is(key, n, "baseColorTexture") && !js_key_is(key, n, "metallicRoughnessTexture")) return js_skip(j, 0);
    return js_object(j, js_texture_info, &t);
}

static bool js_material(json_scan *j, const char *key, size_t n, void *user) {
    if (js_key_is(key, n, "extensions")) return js_object(j, js_extension, user);
    if (js_key_is(key, n, "pbrMetallicRoughness")) return js_object(j, js_pbr, user);
    js_slot t = {user, js_key_is(key, n, "normalTexture") ? GLTF_NORMAL : GLTF_EMISSIVE};
    if (js_key_is(key, n, "normalTexture") || js_key_is(key, n, "emissiveTexture")) return js_object(j, js_texture_info, &t);
    return js_skip(j, 0);
}

/* The line of the JSON j is at. */
static uint32_t js_line(const json_scan *j) {
    uint32_t line = 1;
    for (const char *q = j->start; q < j->p; q++) line += *q == '\n';
    return line;
}

typedef struct js_sampler_at {
    load_state *s;
    int index;
} js_sampler_at;

/* A sampler's wrapS, wrapT, magFilter and minFilter: values that are not the specification's warn
 * (assimp 5.2 reads an unknown wrap mode as REPEAT and an unknown filter as none, quietly). */
static bool js_sampler(json_scan *j, const char *key, size_t n, void *user) {
    const js_sampler_at *at = user;
    bool wrap = js_key_is(key, n, "wrapS") || js_key_is(key, n, "wrapT");
    bool mag = js_key_is(key, n, "magFilter"), min = js_key_is(key, n, "minFilter");
    if (!wrap && !mag && !min) return js_skip(j, 0);
    js_blank(j);
    uint32_t line = js_line(j);
    double v;
    bool num = js_number(j, &v);
    bool known = num && (wrap ? v == 10497 || v == 33071 || v == 33648
                              : v == 9728 || v == 9729 || (min && v >= 9984 && v <= 9987 && v == floor(v)));
    if (!known)
        io_warning(at->s->ctx, at->s->path, line,
                   wrap ? "sampler %d: %.*s is not a glTF wrap mode (10497 REPEAT, 33071 CLAMP_TO_EDGE, 33648 MIRRORED_REPEAT): read as REPEAT"
                        : "sampler %d: %.*s is not a glTF texture filter (9728 NEAREST, 9729 LINEAR, 9984-9987 mipmapped): read as LINEAR",
                   at->index, (int)n, key);
    return true;
}

static bool js_samplers(json_scan *j, load_state *s) {
    if (!js_char(j, '[')) return false;
    if (js_char(j, ']')) return true;
    js_sampler_at at = {s, 0};
    do {
        if (!js_object(j, js_sampler, &at)) return false;
        at.index++;
    } while (js_char(j, ','));
    return js_char(j, ']');
}

static bool js_top(json_scan *j, const char *key, size_t n, void *user) {
    load_state *s = user;
    if (js_key_is(key, n, "samplers")) return js_samplers(j, s);
    if (!js_key_is(key, n, "materials") || s->json) return js_skip(j, 0);
    if (!js_char(j, '[')) return false;
    if (js_char(j, ']')) return true;
    do {
        if (!io_reserve((void **)&s->json, &s->json_cap, s->json_n + 1, sizeof *s->json)) return false;
        gltf_material *m = &s->json[s->json_n++];
        memset(m, 0, sizeof *m);
        m->strength = 1.0f;
        for (int k = 0; k < GLTF_SLOTS; k++) m->scale[k][0] = m->scale[k][1] = 1.0f, m->tex_coord[k] = -1;
        if (!js_object(j, js_material, m)) return false;
    } while (js_char(j, ','));
    return js_char(j, ']');
}

static bool mem_has(const char *p, const char *end, const char *word) {
    size_t n = strlen(word);
    for (const char *at = p; (at = memchr(at, word[0], (size_t)(end - at))); at++)
        if ((size_t)(end - at) >= n && memcmp(at, word, n) == 0) return true;
    return false;
}

/* The JSON of a glTF file's bytes: all of a .gltf, a .glb's first chunk. */
static void gltf_json_bytes(const io_buf *buf, const char **p, const char **end) {
    *p = buf->data, *end = buf->data + buf->size;
    if (buf->size >= 20 && memcmp(*p, "glTF", 4) == 0) {
        const unsigned char *h = (const unsigned char *)*p;
        uint32_t len = (uint32_t)h[12] | (uint32_t)h[13] << 8 | (uint32_t)h[14] << 16 | (uint32_t)h[15] << 24;
        *p += 20;
        if (len < (size_t)(*end - *p)) *end = *p + len;
    }
}

/* Fills s->json from the glTF's JSON (a .gltf file, or a .glb's JSON chunk), and warns of its
 * samplers' unknown values; leaves s->json NULL when the file names neither extension nor samplers
 * or cannot be scanned. */
static void gltf_json_materials(load_state *s, const char *p, const char *end) {
    /* most files name neither: no scan at all */
    if (mem_has(p, end, "emissiveStrength") || mem_has(p, end, "KHR_texture_transform") || mem_has(p, end, "\"samplers\"")) {
        json_scan j = {p, end, p};
        if (!js_object(&j, js_top, s)) {
            free(s->json);
            s->json = NULL;
            s->json_n = s->json_cap = 0;
        }
    }
}

/* The material's texture transform: its base colour texture's KHR_texture_transform (else that of
 * the first texture it has), for all its textures; a texture whose transform differs warns, once. */
static void gltf_uv_transform(load_state *s, unsigned index, rp_material_data *m) {
    if (index >= s->json_n) return;
    const gltf_material *g = &s->json[index];
    const bool has[GLTF_SLOTS] = {m->map_kd >= 0, m->map_metal_rough > 0, m->map_normal > 0, m->map_ke > 0};
    int pick = -1;
    for (int k = 0; k < GLTF_SLOTS && pick < 0; k++)
        if (has[k]) pick = k;
    if (pick < 0) return;
    for (int k = 0; k < GLTF_SLOTS; k++)
        if (has[k] && (g->offset[k][0] != g->offset[pick][0] || g->offset[k][1] != g->offset[pick][1] ||
                       g->scale[k][0] != g->scale[pick][0] || g->scale[k][1] != g->scale[pick][1] ||
                       g->rotation[k] != g->rotation[pick])) {
            static const char *const names[GLTF_SLOTS] = {"base colour", "metallic-roughness", "normal", "emissive"};
            io_warning(s->ctx, s->path, 0,
                       "material '%s': its %s texture's KHR_texture_transform differs from its %s texture's; one transform a material: the %s one's is used",
                       m->name, names[k], names[pick], names[pick]);
            break;
        }
    if (!g->transform[pick]) return;
    if (g->tex_coord[pick] > 0)
        io_warning(s->ctx, s->path, 0, "material '%s': KHR_texture_transform names texture coordinate set %d; raypack reads set 0",
                   m->name, g->tex_coord[pick]);
    /* glTF's uv' = T(offset) R(rotation) S(scale) uv, R = (c s; -s c) (the extension's example:
     * offset (0, 1), rotation pi/2, scale 0.5 shows the lower left quadrant turned clockwise), in
     * glTF's texture space, v down; raypack's v is 1 - v (assimp flips it) */
    float c = cosf(g->rotation[pick]), sn = sinf(g->rotation[pick]);
    const float *sc = g->scale[pick], *o = g->offset[pick];
    float a = sc[0] * c, b = sc[1] * sn, d = -sc[0] * sn, e = sc[1] * c;
    const float t[6] = {a, -b, b + o[0], -d, e, 1.0f - e - o[1]};
    if (t[0] == 1.0f && t[1] == 0.0f && t[2] == 0.0f && t[3] == 0.0f && t[4] == 1.0f && t[5] == 0.0f) return;
    m->uv_transform = true;
    memcpy(m->uv_matrix, t, sizeof t);
}

/* ---- materials -------------------------------------------------------------------------------- */

/* Texture `image` (IO_NONE: failed, -2) under the sampler assimp gives its slot: the wrap modes
 * (glTF's wrapS and wrapT; other formats' too) and glTF's magFilter (raypack has no mipmaps: the
 * magnification filter serves every lookup; minFilter is not read). */
static int32_t texture_sampled(load_state *s, const struct aiMaterial *am, enum aiTextureType type,
                               const enum aiTextureMapMode mode[2], uint32_t image, const char *mat_name) {
    if (image == IO_NONE) return -2;
    tex_sampler smp = TEX_SAMPLER_DEFAULT;
    rp_texture_wrap *wrap[2] = {&smp.wrap_u, &smp.wrap_v};
    for (int k = 0; k < 2; k++) switch (mode[k]) {
        case aiTextureMapMode_Clamp:
            *wrap[k] = RP_TEXTURE_CLAMP;
            break;
        case aiTextureMapMode_Mirror:
            *wrap[k] = RP_TEXTURE_MIRROR;
            break;
        case aiTextureMapMode_Decal: /* nothing beyond the edge: the nearest that raypack has */
            *wrap[k] = RP_TEXTURE_CLAMP;
            io_warning(s->ctx, s->path, 0, "material '%s': decal texture wrapping is not supported: clamped to the edge",
                       mat_name);
            break;
        case aiTextureMapMode_Wrap:
        case _aiTextureMapMode_Force32Bit:
        default:
            break;
        }
    int mag = 0;
    if (aiGetMaterialIntegerArray(am, AI_MATKEY_GLTF_MAPPINGFILTER_MAG(type, 0), &mag, NULL) == aiReturn_SUCCESS &&
        mag == 9728 /* NEAREST */)
        smp.filter = RP_TEXTURE_NEAREST;
    uint32_t idx = tex_sampled(s->ctx, image, &smp, s->path, 0);
    return idx == IO_NONE ? -2 : (int32_t)idx;
}

/* The texture of `type` (first slot) as a builder texture index, -1 when there is none. External
 * images resolve against the scene file's folder; "*N" names scene->mTextures[N] (glTF data URIs
 * and .glb buffer views), compressed (PNG, JPEG: mHeight 0) or raw BGRA texels. */
static int32_t material_texture(load_state *s, const struct aiMaterial *am, enum aiTextureType type,
                                const char *mat_name) {
    if (aiGetMaterialTextureCount(am, type) == 0) return -1;
    struct aiString name;
    enum aiTextureMapMode mode[2] = {aiTextureMapMode_Wrap, aiTextureMapMode_Wrap};
    if (aiGetMaterialTexture(am, type, 0, &name, NULL, NULL, NULL, NULL, mode, NULL) != aiReturn_SUCCESS)
        return -1;
    io_ctx *ctx = s->ctx;
    const char *tex = name.data;
    /* other formats' UV transforms (assimp's aiUVTransform): not applied, so said; glTF's
     * KHR_texture_transform is read from its JSON (gltf_uv_transform) */
    float tr[5] = {0, 0, 1, 1, 0}; /* translation, scaling, rotation */
    unsigned five = 5;
    if (!s->gltf && aiGetMaterialFloatArray(am, AI_MATKEY_UVTRANSFORM(type, 0), tr, &five) == aiReturn_SUCCESS && five == 5 &&
        (tr[0] != 0.0f || tr[1] != 0.0f || tr[2] != 1.0f || tr[3] != 1.0f || tr[4] != 0.0f))
        io_warning(ctx, s->path, 0, "material '%s': texture '%s' has a texture transform, which is not applied",
                   mat_name, tex);
    if (tex[0] == '*') {
        char *end;
        unsigned long k = strtoul(tex + 1, &end, 10);
        if (*end != '\0' || k >= s->scene->mNumTextures) {
            io_error(ctx, s->path, 0, "material '%s': embedded texture '%s' does not exist", mat_name, tex);
            return -2;
        }
        const struct aiTexture *t = s->scene->mTextures[k];
        char key[IO_PATH_MAX + 32];
        snprintf(key, sizeof key, "%s#%s", s->path, tex); /* shared by every material using it */
        uint32_t idx;
        if (t->mHeight == 0) {
            idx = tex_add_encoded(ctx, key, tex, t->pcData, t->mWidth, s->path, 0);
        } else {
            size_t n = (size_t)t->mWidth * t->mHeight;
            bool opaque = true;
            for (size_t i = 0; i < n && opaque; i++) opaque = t->pcData[i].a == 255;
            uint8_t *rgb = t->mWidth <= 65536 && t->mHeight <= 65536 ? io_malloc(n * 3) : NULL;
            uint8_t *alpha = rgb && !opaque ? io_malloc(n) : NULL;
            if (!rgb || (!opaque && !alpha)) {
                free(rgb);
                io_error(ctx, s->path, 0, "material '%s': embedded texture '%s' too large", mat_name, tex);
                return -2;
            }
            for (size_t i = 0; i < n; i++) { /* aiTexel is BGRA */
                rgb[3 * i] = t->pcData[i].r;
                rgb[3 * i + 1] = t->pcData[i].g;
                rgb[3 * i + 2] = t->pcData[i].b;
                if (alpha) alpha[i] = t->pcData[i].a;
            }
            idx = tex_add(ctx, key, tex, (int32_t)t->mWidth, (int32_t)t->mHeight, rgb, alpha, s->path, 0);
        }
        return texture_sampled(s, am, type, mode, idx, mat_name);
    }
    char full[IO_PATH_MAX];
    vfs_join(&ctx->vfs, s->path, tex, full, sizeof full);
    return texture_sampled(s, am, type, mode, tex_load(ctx, full, tex, s->path, 0), mat_name);
}

/* glTF's alphaMode and alphaCutoff (assimp's $mat.gltf.alphaMode, ...): "MASK" and "BLEND" cut the
 * surface out where the base colour's alpha (factor times the base colour texture's alpha channel,
 * where it has one) is below the cutoff, or stochastically; "OPAQUE" or none ignores alpha. An
 * unknown mode warns and is taken as OPAQUE. False after an error. */
static bool alpha_mode(load_state *s, const struct aiMaterial *am, rp_material_data *m) {
    struct aiString mode;
    if (aiGetMaterialString(am, AI_MATKEY_GLTF_ALPHAMODE, &mode) != aiReturn_SUCCESS || strcmp(mode.data, "OPAQUE") == 0) {
        m->alpha = 1.0f;
        return true;
    }
    if (strcmp(mode.data, "MASK") == 0) {
        m->alpha_mode = RP_ALPHA_MASK;
        float cutoff = 0.5f;
        if (aiGetMaterialFloatArray(am, AI_MATKEY_GLTF_ALPHACUTOFF, &cutoff, NULL) == aiReturn_SUCCESS && isfinite(cutoff))
            m->alpha_cutoff = cutoff;
    } else if (strcmp(mode.data, "BLEND") == 0) {
        m->alpha_mode = RP_ALPHA_BLEND;
    } else {
        io_warning(s->ctx, s->path, 0, "material '%s': alphaMode '%s' is not MASK, BLEND or OPAQUE; taken as OPAQUE",
                   m->name, mode.data);
        m->alpha = 1.0f;
        return true;
    }
    if (m->map_kd >= 0 && s->ctx->b.textures[m->map_kd].alpha) m->map_alpha = m->map_kd + 1;
    return true;
}

/* assimp's material -> rp_material_data, the one place the mapping lives. glTF's
 * metallic-roughness model is read as: base colour factor (and base colour texture, which
 * multiplies it, as in glTF) -> kd, the base colour; emissive factor -> ke (emitted
 * radiance, DESIGN.md), times the emissive texture (map_ke); metallic and roughness factors and
 * the metallic-roughness texture -> metal_rough (the renderer's mapping: material.c); transmission
 * (KHR_materials_transmission, ior) -> a dielectric tinted by the base colour; the normal texture ->
 * map_normal; occlusion textures are not used.
 * Formats without base colour give their diffuse colour and texture. Returns false after an error. */
static bool material_from_assimp(load_state *s, unsigned index, const struct aiMaterial *am, rp_material_data *m) {
    struct aiString name;
    if (aiGetMaterialString(am, AI_MATKEY_NAME, &name) != aiReturn_SUCCESS) name.data[0] = '\0';
    builder_material_defaults(m, name.data[0] ? name.data : "assimp");
    struct aiColor4D c;
    if (aiGetMaterialColor(am, AI_MATKEY_BASE_COLOR, &c) == aiReturn_SUCCESS ||
        aiGetMaterialColor(am, AI_MATKEY_COLOR_DIFFUSE, &c) == aiReturn_SUCCESS) {
        m->kd[0] = c.r, m->kd[1] = c.g, m->kd[2] = c.b;
        m->alpha = isfinite(c.a) ? fminf(fmaxf(c.a, 0.0f), 1.0f) : 1.0f; /* glTF's baseColorFactor[3] */
    }
    if (aiGetMaterialColor(am, AI_MATKEY_COLOR_EMISSIVE, &c) == aiReturn_SUCCESS) {
        m->ke[0] = c.r, m->ke[1] = c.g, m->ke[2] = c.b;
        float strength; /* KHR_materials_emissive_strength: assimp 5.3's, else the file's (gltf_strengths) */
        if (aiGetMaterialFloatArray(am, AI_MATKEY_EMISSIVE_INTENSITY, &strength, NULL) == aiReturn_SUCCESS &&
            strength >= 0.0f)
            for (int i = 0; i < 3; i++) m->ke[i] *= strength;
        else if (index < s->json_n)
            for (int i = 0; i < 3; i++) m->ke[i] *= s->json[index].strength;
    }
    int32_t tex = material_texture(s, am, aiTextureType_BASE_COLOR, m->name);
    if (tex == -1) tex = material_texture(s, am, aiTextureType_DIFFUSE, m->name);
    if (tex == -2) return false;
    m->map_kd = tex;
    if (!alpha_mode(s, am, m)) return false;
    int32_t etex = material_texture(s, am, aiTextureType_EMISSIVE, m->name); /* glTF: multiplies the factor */
    if (etex == -2) return false;
    m->map_ke = etex + 1;
    float metallic;
    if (aiGetMaterialFloatArray(am, AI_MATKEY_METALLIC_FACTOR, &metallic, NULL) == aiReturn_SUCCESS) {
        /* glTF (assimp gives the factors with glTF's defaults, 1 and 1, filled in) */
        float roughness = 1.0f;
        aiGetMaterialFloatArray(am, AI_MATKEY_ROUGHNESS_FACTOR, &roughness, NULL);
        m->metal_rough = true;
        m->metallic = isfinite(metallic) ? fminf(fmaxf(metallic, 0.0f), 1.0f) : 1.0f;
        m->roughness = isfinite(roughness) ? fminf(fmaxf(roughness, 0.0f), 1.0f) : 1.0f;
        /* the one texture glTF has for both: assimp lists it as the metalness texture, and as glTF's
         * own key (aiTextureType_UNKNOWN) */
        int32_t mr = material_texture(s, am, aiTextureType_METALNESS, m->name);
        if (mr == -1) mr = material_texture(s, am, aiTextureType_UNKNOWN, m->name);
        if (mr == -2) return false;
        m->map_metal_rough = mr + 1;
        /* KHR_materials_transmission: glass of the base colour, index KHR_materials_ior's (glTF's
         * 1.5 without it) */
        float transmission = 0.0f, ior = 1.5f;
        if (aiGetMaterialFloatArray(am, AI_MATKEY_TRANSMISSION_FACTOR, &transmission, NULL) == aiReturn_SUCCESS &&
            transmission > 0.0f && isfinite(transmission)) {
            aiGetMaterialFloatArray(am, AI_MATKEY_REFRACTI, &ior, NULL);
            for (int k = 0; k < 3; k++) m->kt[k] = fminf(fmaxf(m->kd[k], 0.0f), 1.0f) * fminf(transmission, 1.0f);
            m->ior = ior >= 1.0f && ior < 10.0f ? ior : 1.5f;
            m->metal_rough = false;
        }
    }
    if (!m->metal_rough && strcmp(name.data, AI_DEFAULT_MATERIAL_NAME) != 0) {
        /* the Phong formats (COLLADA, FBX, 3DS, ...): specular colour times its strength -> ks,
         * shininess -> ns, as MTL's Ks and Ns (the plastic BSDF; Phong highlights in Whitted).
         * Not assimp's own default material (STL's is specular white: a mirror-like plastic) */
        struct aiColor4D sc;
        float strength = 1.0f, shininess = 0.0f;
        if (aiGetMaterialColor(am, AI_MATKEY_COLOR_SPECULAR, &sc) == aiReturn_SUCCESS) {
            aiGetMaterialFloatArray(am, AI_MATKEY_SHININESS_STRENGTH, &strength, NULL);
            if (!(strength >= 0.0f && isfinite(strength))) strength = 1.0f;
            const float spec[3] = {sc.r, sc.g, sc.b};
            for (int k = 0; k < 3; k++)
                m->ks[k] = isfinite(spec[k] * strength) ? fminf(fmaxf(spec[k] * strength, 0.0f), 1.0f) : 0.0f;
        }
        if (aiGetMaterialFloatArray(am, AI_MATKEY_SHININESS, &shininess, NULL) == aiReturn_SUCCESS &&
            shininess > 0.0f && isfinite(shininess))
            m->ns = shininess;
    }
    /* a tangent-space normal map (glTF's normalTexture: +y along v), as MTL's norm */
    int32_t ntex = material_texture(s, am, aiTextureType_NORMALS, m->name);
    if (ntex == -2) return false;
    m->map_normal = ntex + 1;
    gltf_uv_transform(s, index, m);
    return true;
}

/* ---- meshes, cameras, lights ------------------------------------------------------------------ */

static bool add_mesh(load_state *s, const struct aiMesh *mesh, const mat4 *t) {
    io_ctx *ctx = s->ctx;
    io_builder *b = &ctx->b;
    if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) || mesh->mNumVertices == 0) return true;
    size_t nv = mesh->mNumVertices;
    if (b->pos_n + nv >= UINT32_MAX || b->nrm_n + nv >= UINT32_MAX || b->uv_n + nv >= UINT32_MAX)
        return io_error(ctx, s->path, 0, "mesh '%s': more than 2^32 vertices", mesh->mName.data);
    bool normals = mesh->mNormals != NULL, uvs = mesh->mTextureCoords[0] != NULL;
    if (!builder_reserve_vertices(ctx, nv) || (normals && !builder_reserve_normals(ctx, nv)) ||
        (uvs && !builder_reserve_texcoords(ctx, nv)) || !builder_reserve_triangles(ctx, mesh->mNumFaces))
        return io_error(ctx, s->path, 0, "out of memory");
    /* the first colour set (glTF's COLOR_0, linear by its specification; alpha is not read) */
    if (mesh->mColors[0]) {
        static const float white[3] = {1, 1, 1};
        if (!builder_set_colors(ctx, b->pos_n + nv - 1, white, 1)) return io_error(ctx, s->path, 0, "out of memory");
        for (size_t i = 0; i < nv; i++) {
            const struct aiColor4D *c = &mesh->mColors[0][i];
            float *o = b->col + 3 * (b->pos_n + i);
            o[0] = isfinite(c->r) ? fmaxf(c->r, 0.0f) : 0.0f;
            o[1] = isfinite(c->g) ? fmaxf(c->g, 0.0f) : 0.0f;
            o[2] = isfinite(c->b) ? fmaxf(c->b, 0.0f) : 0.0f;
        }
    }
    uint32_t v0 = (uint32_t)b->pos_n, n0 = (uint32_t)b->nrm_n, t0 = (uint32_t)b->uv_n;
    float nm[3][3], det;
    normal_matrix(t, nm, &det);
    for (size_t i = 0; i < nv; i++) {
        const float p[3] = {mesh->mVertices[i].x, mesh->mVertices[i].y, mesh->mVertices[i].z};
        xform_point(t, p, b->pos + 3 * (b->pos_n + i));
        if (normals) {
            const struct aiVector3D *a = &mesh->mNormals[i];
            float *n = b->nrm + 3 * (b->nrm_n + i);
            for (int k = 0; k < 3; k++) n[k] = nm[k][0] * a->x + nm[k][1] * a->y + nm[k][2] * a->z;
            float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            if (det < 0.0f) len = -len; /* the cofactor matrix is det times the inverse transpose */
            if (len != 0.0f && isfinite(len)) n[0] /= len, n[1] /= len, n[2] /= len;
            else n[0] = 0.0f, n[1] = 0.0f, n[2] = 1.0f;
        }
        if (uvs) {
            b->uv[2 * (b->uv_n + i)] = mesh->mTextureCoords[0][i].x;
            b->uv[2 * (b->uv_n + i) + 1] = mesh->mTextureCoords[0][i].y;
        }
    }
    b->pos_n += nv;
    if (normals) b->nrm_n += nv;
    if (uvs) b->uv_n += nv;
    uint32_t mat = mesh->mMaterialIndex < s->scene->mNumMaterials ? s->materials[mesh->mMaterialIndex]
                                                                  : builder_default_material(ctx);
    if (mat == IO_NONE) return io_error(ctx, s->path, 0, "out of memory");
    /* A mirroring transform (negative determinant) turns the winding around (glTF 2.0, 3.7.4):
     * swapping two corners keeps front faces in front. */
    int a1 = det < 0.0f ? 2 : 1, a2 = det < 0.0f ? 1 : 2;
    for (unsigned f = 0; f < mesh->mNumFaces; f++) {
        const struct aiFace *face = &mesh->mFaces[f];
        if (face->mNumIndices != 3) continue; /* points and lines of a mixed mesh */
        uint32_t v[3], n[3], tc[3];
        const uint32_t c[3] = {face->mIndices[0], face->mIndices[a1], face->mIndices[a2]};
        for (int k = 0; k < 3; k++) {
            if (c[k] >= nv)
                return io_error(ctx, s->path, 0, "mesh '%s': face %u indexes vertex %u of %zu",
                                mesh->mName.data, f, c[k], nv);
            v[k] = v0 + c[k], n[k] = n0 + c[k], tc[k] = t0 + c[k];
        }
        if (!builder_add_triangle(ctx, v, normals ? n : NULL, uvs ? tc : NULL, mat))
            return io_error(ctx, s->path, 0, "out of memory");
    }
    return true;
}

/* The camera, in its node's frame: mPosition, mLookAt (a direction) and mUp. assimp documents
 * mHorizontalFOV as the half horizontal angle, but its importers store the whole one (COLLADA:
 * 2 atan(aspect tan(yfov / 2)) from a yfov; FBX: FieldOfView). The glTF 2.0 importer of assimp 5.2
 * differs twice: it stores glTF's yfov times aspectRatio, and it copies the node's translation
 * into mPosition although a glTF camera sits at its node's origin (so mPosition is ignored for
 * glTF). Either way the vertical angle of DESIGN.md's pinhole is recovered; without an aspect
 * ratio the image is taken as square. */
static void add_camera(load_state *s, const struct aiCamera *cam, const mat4 *t, bool gltf) {
    if (s->have_camera) return; /* the first camera the hierarchy reaches */
    rp_camera_data *c = &s->ctx->b.camera;
    const float p[3] = {gltf ? 0.0f : cam->mPosition.x, gltf ? 0.0f : cam->mPosition.y,
                        gltf ? 0.0f : cam->mPosition.z};
    const float d[3] = {cam->mLookAt.x, cam->mLookAt.y, cam->mLookAt.z};
    const float u[3] = {cam->mUp.x, cam->mUp.y, cam->mUp.z};
    float dir[3];
    xform_point(t, p, c->eye);
    xform_dir(t, d, dir);
    xform_dir(t, u, c->up);
    for (int i = 0; i < 3; i++) c->look[i] = c->eye[i] + dir[i];
    double aspect = cam->mAspect > 0.0f ? (double)cam->mAspect : 1.0, h = (double)cam->mHorizontalFOV, fov;
    if (gltf && aiGetVersionMajor() == 5 && aiGetVersionMinor() < 3)
        fov = h / aspect;
    else
        fov = 2.0 * atan(tan(0.5 * h) / aspect);
    fov *= 180.0 / M_PI;
    c->fov_deg = (float)fov;
    c->valid = fov > 0.0 && fov < 180.0 && isfinite(fov);
    s->have_camera = c->valid;
    if (!c->valid)
        io_warning(s->ctx, s->path, 0, "camera '%s': %s; the camera is left out", cam->mName.data,
                   cam->mOrthographicWidth > 0.0f ? "orthographic (raypack's cameras are pinhole)" : "no usable field of view");
}

/* A direction through the node's transform (its upper 3x3), unit; false when it has none left. */
static bool xform_direction(const mat4 *t, const struct aiVector3D *v, float out[3]) {
    const float o[3] = {0, 0, 0}, p[3] = {v->x, v->y, v->z};
    float a[3], b[3];
    xform_point(t, o, a);
    xform_point(t, p, b);
    double d[3] = {(double)b[0] - a[0], (double)b[1] - a[1], (double)b[2] - a[2]};
    double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (!(len > 0.0) || !isfinite(len)) return false;
    for (int k = 0; k < 3; k++) out[k] = (float)(d[k] / len);
    return true;
}

/* Point, spot and directional lights (glTF's KHR_lights_punctual); area and ambient lights are left out. */
static bool add_light(load_state *s, const struct aiLight *l, const mat4 *t, bool gltf) {
    if (l->mType != aiLightSource_POINT && l->mType != aiLightSource_SPOT && l->mType != aiLightSource_DIRECTIONAL) {
        io_warning(s->ctx, s->path, 0, "light '%s': an area or ambient light, which raypack has no kind for; it is left out",
                   l->mName.data);
        return true;
    }
    io_builder *b = &s->ctx->b;
    if (!io_reserve((void **)&b->lights, &b->light_cap, b->light_n + 1, sizeof *b->lights))
        return io_error(s->ctx, s->path, 0, "out of memory");
    rp_light_data *d = &b->lights[b->light_n];
    memset(d, 0, sizeof *d);
    d->type = l->mType == aiLightSource_SPOT ? RP_LIGHT_DATA_SPOT
              : l->mType == aiLightSource_DIRECTIONAL ? RP_LIGHT_DATA_DIRECTIONAL : RP_LIGHT_DATA_POINT;
    if (d->type != RP_LIGHT_DATA_POINT && !xform_direction(t, &l->mDirection, d->direction))
        return true; /* no direction: nothing to light */
    if (d->type == RP_LIGHT_DATA_SPOT) {
        /* assimp passes glTF's angles as they are, half-angles from the axis; its other readers give
         * the cone's full angle, as its documentation says */
        double inner = l->mAngleInnerCone, outer = l->mAngleOuterCone;
        if (!gltf) inner *= 0.5, outer *= 0.5;
        if (!(outer > 0.0) || !isfinite(outer)) return true;
        if (!(inner >= 0.0 && inner <= outer)) inner = outer;
        outer = fmin(outer, M_PI / 2), inner = fmin(inner, outer);
        d->cos_inner = (float)cos(inner);
        d->cos_outer = (float)cos(outer);
    }
    b->light_n++;
    const float p[3] = {l->mPosition.x, l->mPosition.y, l->mPosition.z};
    xform_point(t, p, d->position);
    /* glTF: colour times intensity (candela; a directional light's lux), as assimp's importer
     * multiplies them */
    d->color[0] = l->mColorDiffuse.r, d->color[1] = l->mColorDiffuse.g, d->color[2] = l->mColorDiffuse.b;
    return true;
}

static bool visit(load_state *s, const struct aiNode *node, const mat4 *parent, bool gltf, int depth) {
    if (depth > 256)
        return io_error(s->ctx, s->path, 0, "node hierarchy deeper than 256 at '%s'", node->mName.data);
    mat4 local = mat4_from_ai(&node->mTransformation);
    mat4 t = mat4_mul(parent, &local);
    for (unsigned i = 0; i < node->mNumMeshes; i++) {
        unsigned k = node->mMeshes[i];
        if (k >= s->scene->mNumMeshes)
            return io_error(s->ctx, s->path, 0, "node '%s' names mesh %u of %u", node->mName.data, k,
                            s->scene->mNumMeshes);
        if (!add_mesh(s, s->scene->mMeshes[k], &t)) return false;
    }
    /* cameras and lights are bound to the node of the same name */
    for (unsigned i = 0; i < s->scene->mNumCameras; i++)
        if (strcmp(s->scene->mCameras[i]->mName.data, node->mName.data) == 0)
            add_camera(s, s->scene->mCameras[i], &t, gltf);
    for (unsigned i = 0; i < s->scene->mNumLights; i++)
        if (!s->light_done[i] && strcmp(s->scene->mLights[i]->mName.data, node->mName.data) == 0) {
            s->light_done[i] = true;
            if (!add_light(s, s->scene->mLights[i], &t, gltf)) return false;
        }
    for (unsigned i = 0; i < node->mNumChildren; i++)
        if (!visit(s, node->mChildren[i], &t, gltf, depth + 1)) return false;
    return true;
}

/* assimp 5.2 trusts a binary glTF's first chunk length (the JSON): it allocates that many bytes
 * plus one before reading them, so a 1 kB .glb claiming 0x69040000 bytes asked for
 * malloc(1761869825) (found by fuzz_gltf). The chunk must fit in the file. The sizes inside the
 * JSON (buffers, buffer views, accessors) assimp checks against the data itself. Only a regular
 * file is read ahead here: a FIFO's bytes are assimp's. */
static bool glb_header_ok(io_ctx *ctx, const char *path) {
    struct stat st;
    if (stat(path, &st) != 0 || !S_ISREG(st.st_mode)) return true; /* assimp says why */
    FILE *f = fopen(path, "rb");
    if (!f) return true;
    unsigned char h[20];
    size_t got = fread(h, 1, sizeof h, f);
    fclose(f);
    if (got < sizeof h || memcmp(h, "glTF", 4) != 0) return true;
    uint32_t json = (uint32_t)h[12] | (uint32_t)h[13] << 8 | (uint32_t)h[14] << 16 | (uint32_t)h[15] << 24;
    uint64_t left = (uint64_t)st.st_size - sizeof h;
    if (json > left)
        return io_error(ctx, path, 0, "binary glTF: its JSON chunk claims %" PRIu32 " bytes, but the file holds %" PRIu64 " after the header",
                        json, left);
    /* assimp's glTF 2 importer refuses any other (gltf_json_valid says what follows a refusal) */
    uint32_t version = (uint32_t)h[4] | (uint32_t)h[5] << 8 | (uint32_t)h[6] << 16 | (uint32_t)h[7] << 24;
    if (version != 2) return io_error(ctx, path, 0, "binary glTF version %" PRIu32 ": only version 2 is read", version);
    if (memcmp(h + 16, "JSON", 4) != 0) return io_error(ctx, path, 0, "binary glTF: its first chunk is not the JSON chunk");
    return true;
}

/* ---- the glTF importers must take the file (fuzz_gltf) ----
 * assimp 5.2 gives a .gltf or .glb that neither of its glTF importers opens (JSON they cannot
 * parse, no asset.version of 1.x or 2.x) to every other importer, each of which looks for its own
 * words in it: a 23-byte .gltf holding "geometrynode{" went to the OpenGEX importer, which read past
 * its buffer (ASan; tests/fuzz/crashes/gltf/opengex_fallback_overread). So a glTF's JSON is checked
 * first against rules at least as strict as RapidJSON's, which those importers parse with in
 * place: the bytes up to the first NUL (where an in-place parse ends) hold one value and blanks;
 * strings without control characters, with only JSON's escapes and \u surrogates in pairs; numbers
 * in JSON's form and under 1e300 in size; nesting at most 64 deep (RapidJSON recurses without a
 * limit). Then the value must be an object whose asset.version is a string starting with 1 or 2. */
/* Where a value lies, for asset.version: the root, the root's "asset", its "version", elsewhere. */
typedef enum { JV_ROOT, JV_ASSET, JV_VERSION, JV_OTHER } jv_at;
static bool jv_value(json_scan *j, int depth, jv_at at, char *version);

static bool jv_hex4(const char *p, const char *end, unsigned *cp) {
    if (end - p < 4) return false;
    unsigned v = 0;
    for (int k = 0; k < 4; k++) {
        char c = p[k], l = (char)(c | 32);
        unsigned d = c >= '0' && c <= '9' ? (unsigned)(c - '0') : l >= 'a' && l <= 'f' ? (unsigned)(l - 'a' + 10) : 16u;
        if (d > 15) return false;
        v = v << 4 | d;
    }
    *cp = v;
    return true;
}

static bool jv_string(json_scan *j) {
    j->p++; /* the opening quote */
    while (j->p < j->end) {
        unsigned char c = (unsigned char)*j->p;
        if (c == '"') {
            j->p++;
            return true;
        }
        if (c < 0x20) return false;
        if (c != '\\') {
            j->p++;
            continue;
        }
        if (j->end - j->p < 2) return false;
        char e = j->p[1];
        if (e == '"' || e == '\\' || e == '/' || e == 'b' || e == 'f' || e == 'n' || e == 'r' || e == 't') {
            j->p += 2;
            continue;
        }
        unsigned cp, lo;
        if (e != 'u' || !jv_hex4(j->p + 2, j->end, &cp) || (cp >= 0xDC00 && cp <= 0xDFFF)) return false;
        j->p += 6;
        if (cp >= 0xD800 && cp <= 0xDBFF) { /* a high surrogate: its low one must follow */
            if (j->end - j->p < 6 || j->p[0] != '\\' || j->p[1] != 'u' || !jv_hex4(j->p + 2, j->end, &lo) || lo < 0xDC00 ||
                lo > 0xDFFF)
                return false;
            j->p += 6;
        }
    }
    return false;
}

static bool jv_digit(const json_scan *j) { return j->p < j->end && *j->p >= '0' && *j->p <= '9'; }

static bool jv_number(json_scan *j) {
    if (j->p < j->end && *j->p == '-') j->p++;
    if (!jv_digit(j)) return false;
    long digits = 0; /* before the point, leading zero excluded */
    if (*j->p == '0') j->p++;
    else
        while (jv_digit(j)) j->p++, digits++;
    if (j->p < j->end && *j->p == '.') {
        j->p++;
        if (!jv_digit(j)) return false;
        while (jv_digit(j)) j->p++;
    }
    long exp = 0;
    if (j->p < j->end && (*j->p == 'e' || *j->p == 'E')) {
        j->p++;
        bool neg = j->p < j->end && *j->p == '-';
        if (j->p < j->end && (*j->p == '-' || *j->p == '+')) j->p++;
        if (!jv_digit(j)) return false;
        while (jv_digit(j)) {
            if (exp < 100000) exp = exp * 10 + (*j->p - '0');
            j->p++;
        }
        if (neg) exp = -exp;
    }
    return digits < 300 && exp > -300 && exp < 300 && digits + exp < 300;
}

static bool jv_word(json_scan *j, const char *w) {
    size_t n = strlen(w);
    if ((size_t)(j->end - j->p) < n || memcmp(j->p, w, n) != 0) return false;
    j->p += n;
    return true;
}

/* One value at j->p, checked, with the first character of asset.version's string put in *version
 * on the way (at: where this value lies). */
static bool jv_value(json_scan *j, int depth, jv_at at, char *version) {
    js_blank(j);
    if (j->p >= j->end || depth > 64) return false;
    char c = *j->p;
    if (c == '"') {
        const char *s = j->p + 1;
        if (!jv_string(j)) return false;
        if (at == JV_VERSION) *version = s < j->p - 1 ? *s : '\0';
        return true;
    }
    if (c == '{' || c == '[') {
        char close = c == '{' ? '}' : ']';
        j->p++;
        if (js_char(j, close)) return true;
        do {
            jv_at next = JV_OTHER;
            if (close == '}') {
                js_blank(j);
                const char *key = j->p + 1;
                if (j->p >= j->end || *j->p != '"' || !jv_string(j)) return false;
                size_t n = (size_t)(j->p - 1 - key); /* up to the closing quote */
                if (!js_char(j, ':')) return false;
                if (at == JV_ROOT && js_key_is(key, n, "asset")) next = JV_ASSET;
                else if (at == JV_ASSET && js_key_is(key, n, "version")) next = JV_VERSION;
            }
            if (!jv_value(j, depth + 1, next, version)) return false;
        } while (js_char(j, ','));
        return js_char(j, close);
    }
    if (c == 't') return jv_word(j, "true");
    if (c == 'f') return jv_word(j, "false");
    if (c == 'n') return jv_word(j, "null");
    return jv_number(j);
}

static bool gltf_json_valid(io_ctx *ctx, const char *path, const char *p, const char *end) {
    const char *nul = memchr(p, '\0', (size_t)(end - p));
    if (nul) end = nul;
    json_scan j = {p, end, p};
    char version = '\0';
    if (!jv_value(&j, 0, JV_ROOT, &version) || (js_blank(&j), j.p != end))
        return io_error(ctx, path, (int)js_line(&j), "the glTF's JSON is not valid here (at byte %zu of it)", (size_t)(j.p - p));
    if (version != '1' && version != '2') /* a root that is no object never sets it */
        return io_error(ctx, path, 0, "not a glTF assimp reads: no asset.version of 1.x or 2.x");
    return true;
}

/* A JSON string's bytes [q, close) unescaped into out (room for close - q bytes: no escape grows),
 * as assimp's JSON parser reads them; returns the length. */
static size_t js_unescape(const char *q, const char *close, char *out) {
    size_t n = 0;
    while (q < close) {
        if (*q != '\\' || q + 1 >= close) {
            out[n++] = *q++;
            continue;
        }
        char e = q[1];
        q += 2;
        if (e == 'u' && close - q >= 4) {
            unsigned cp = 0;
            for (int k = 0; k < 4; k++, q++) {
                char h = *q;
                cp = cp * 16 + (unsigned)(h >= '0' && h <= '9' ? h - '0' : h >= 'a' && h <= 'f' ? h - 'a' + 10 : h >= 'A' && h <= 'F' ? h - 'A' + 10 : 0);
            }
            if (cp < 0x80) out[n++] = (char)cp;
            else if (cp < 0x800) out[n++] = (char)(0xc0 | cp >> 6), out[n++] = (char)(0x80 | (cp & 63));
            else out[n++] = (char)(0xe0 | cp >> 12), out[n++] = (char)(0x80 | (cp >> 6 & 63)), out[n++] = (char)(0x80 | (cp & 63));
        } else {
            out[n++] = e == 'b' ? '\b' : e == 'f' ? '\f' : e == 'n' ? '\n' : e == 'r' ? '\r' : e == 't' ? '\t' : e;
        }
    }
    return n;
}

/* One "uri" value, unescaped: a data URI must be one assimp 5.2 reads right. */
static bool gltf_data_uri_ok(io_ctx *ctx, const char *path, int line, const char *u, size_t n) {
    if (n < 5 || memcmp(u, "data:", 5) != 0) return true;
    const char *comma = memchr(u, ',', n);
    if (!comma) return true;
    /* assimp keeps the data's offset in the URI in a char: past 127 it read from before the URI
     * (fuzz_gltf: a 154-byte media type, and the leak below) */
    if (comma - u > 126)
        return io_error(ctx, path, line, "a data URI's media type and parameters take %zu bytes before its ','; assimp reads at most 121",
                        (size_t)(comma - u) - 5);
    if (comma - u < 12 || memcmp(comma - 7, ";base64", 7) != 0) return true;
    const char *b64 = comma + 1, *close = u + n;
    size_t pad = 0;
    for (const char *c = b64; c < close; c++) {
        unsigned char ch = (unsigned char)*c;
        bool alpha = (ch >= 'A' && ch <= 'Z') || (ch >= 'a' && ch <= 'z') || (ch >= '0' && ch <= '9') || ch == '+' || ch == '/';
        if (ch == '=' && close - c <= 2) pad++;
        else if (!alpha || pad)
            return io_error(ctx, path, line, "a data URI's base64 holds byte 0x%02x at its character %zu, outside base64's alphabet",
                            (unsigned)ch, (size_t)(c - b64));
    }
    if ((close - b64) % 4)
        return io_error(ctx, path, line, "a data URI's base64 is %zu characters long, not a multiple of 4", (size_t)(close - b64));
    return true;
}

/* assimp 5.2 decodes a glTF buffer's or image's base64 data URI into a buffer it allocates first,
 * then throws at the first byte outside the alphabet, and the buffer leaks (found by fuzz_gltf: a
 * load of such a file lost the decoded size each time, and the message read "Invalid base64 char
 * value: 18446744073709551615"); a '!' it decoded into wrong bytes without a word. Every "uri"
 * value of a .gltf (or a .glb's JSON chunk) that is a data URI is checked here first, as assimp
 * will read it (JSON escapes undone): the alphabet, '=' only as the last one or two characters, a
 * length that is a multiple of 4, and the media type's length. */
static bool gltf_data_uris_ok(io_ctx *ctx, const char *path, const char *p, const char *end) {
    bool ok = true;
    char *scratch = NULL;
    for (const char *at = p; ok && (at = memchr(at, '"', (size_t)(end - at))); at++) {
        if ((size_t)(end - at) < 5 || memcmp(at, "\"uri\"", 5) != 0) continue;
        json_scan j = {at + 5, end, p};
        js_blank(&j);
        if (j.p >= end || *j.p != ':') continue;
        j.p++;
        const char *q;
        size_t n;
        if (!js_string(&j, &q, &n)) continue;
        int line = (int)js_line(&j);
        if (memchr(q, '\\', n)) { /* unescaped into scratch, as assimp's parser reads it */
            free(scratch);
            if (!(scratch = io_malloc(n + 1))) {
                ok = io_error(ctx, path, line, "out of memory");
                break;
            }
            ok = gltf_data_uri_ok(ctx, path, line, scratch, js_unescape(q, q + n, scratch));
        } else {
            ok = gltf_data_uri_ok(ctx, path, line, q, n);
        }
        at = j.p - 1;
    }
    free(scratch);
    return ok;
}

/* The glTF's JSON, read once for the data-URI check before assimp and the material scan after it
 * (each had read the whole file): a .glb's header and JSON chunk alone, its binary chunk (the bulk
 * of such a file) left to assimp; anything else whole, through the vfs (a .gltf's data URIs are in
 * its JSON). [*p, *end) are the JSON's bytes in buf; false when the file cannot be read (assimp then
 * says why). */
static bool gltf_json_read(io_ctx *ctx, const char *path, uint64_t size, io_buf *buf, const char **p,
                           const char **end) {
    memset(buf, 0, sizeof *buf);
    FILE *f = fopen(path, "rb");
    if (!f) return false;
    unsigned char h[20];
    if (fread(h, 1, sizeof h, f) == sizeof h && memcmp(h, "glTF", 4) == 0) {
        uint32_t len = (uint32_t)h[12] | (uint32_t)h[13] << 8 | (uint32_t)h[14] << 16 | (uint32_t)h[15] << 24;
        if ((uint64_t)len > size - sizeof h) { /* glb_header_ok refuses it first */
            fclose(f);
            return false;
        }
        char *d = io_malloc((size_t)len + 1);
        bool ok = d && fread(d, 1, len, f) == len;
        fclose(f);
        if (!ok) {
            free(d);
            return false;
        }
        d[len] = '\0';
        *buf = (io_buf){.data = d, .size = len, .owned = true};
        *p = d, *end = d + len;
        return true;
    }
    fclose(f);
    if (!vfs_read(ctx, path, buf)) return false;
    gltf_json_bytes(buf, p, end);
    return true;
}

bool assimp_load(io_ctx *ctx, const char *path) {
    if (ctx->vfs.archive)
        return io_error(ctx, path, 0, "formats read through assimp cannot be loaded from inside an archive");
    size_t len = strlen(path);
    if (len > 3 && (strcmp(path + len - 3, ".gz") == 0 || strcmp(path + len - 3, ".GZ") == 0))
        return io_error(ctx, path, 0, "formats read through assimp cannot be loaded gzip'd");
    char ext[16];
    vfs_extension(path, ext, sizeof ext);
    bool gltf = strcmp(ext, "gltf") == 0 || strcmp(ext, "glb") == 0;
    /* Triangulate polygons and drop points and lines; no normals are invented (the builder gives
     * faces without normals their flat normal). Formats that store vertices per face (STL, 3DS)
     * get them merged so meshes stay shared; glTF's are indexed already, and merging would cost
     * more than the rest of the import (Suzanne: 16 ms against 1 ms). */
    unsigned flags = aiProcess_Triangulate | aiProcess_SortByPType | aiProcess_ValidateDataStructure;
    if (!gltf) flags |= aiProcess_JoinIdenticalVertices;
    if (!glb_header_ok(ctx, path)) return false;
    struct stat st;
    bool found = stat(path, &st) == 0;
    if (gltf && found && !S_ISREG(st.st_mode)) /* its JSON must be checked before assimp reads it */
        return io_error(ctx, path, 0, "a glTF must be a regular file (not a directory, FIFO or device)");
    io_buf json = {0};
    const char *jp = NULL, *jend = NULL;
    bool have_json = gltf && found && gltf_json_read(ctx, path, (uint64_t)st.st_size, &json, &jp, &jend);
    if (have_json && (!gltf_json_valid(ctx, path, jp, jend) || !gltf_data_uris_ok(ctx, path, jp, jend))) {
        vfs_buf_free(&json);
        return false;
    }
    const struct aiScene *scene = aiImportFile(path, flags);
    if (!scene) {
        vfs_buf_free(&json);
        const char *why = aiGetErrorString();
        return io_error(ctx, path, 0, "%s", why && why[0] ? why : "assimp could not read the file");
    }
    bool ok = true;
    if ((scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) || !scene->mRootNode)
        ok = io_error(ctx, path, 0, "the file holds no complete scene (assimp: incomplete)");
    load_state s = {.ctx = ctx, .path = path, .scene = scene, .gltf = gltf};
    if (ok && have_json) gltf_json_materials(&s, jp, jend);
    vfs_buf_free(&json);
    if (ok && scene->mNumMaterials) {
        s.materials = io_malloc(scene->mNumMaterials * sizeof *s.materials);
        if (!s.materials) ok = io_error(ctx, path, 0, "out of memory");
        for (unsigned i = 0; ok && i < scene->mNumMaterials; i++) {
            rp_material_data m;
            if (!material_from_assimp(&s, i, scene->mMaterials[i], &m)) ok = false;
            else if ((s.materials[i] = builder_add_material(ctx, &m)) == IO_NONE)
                ok = io_error(ctx, path, 0, "out of memory");
        }
    }
    if (ok && !(s.light_done = io_calloc(scene->mNumLights + 1, sizeof(bool))))
        ok = io_error(ctx, path, 0, "out of memory");
    mat4 identity = {{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}};
    if (ok) ok = visit(&s, scene->mRootNode, &identity, gltf, 0);
    if (ok && ctx->b.tri_n == 0) ok = io_error(ctx, path, 0, "the file holds no triangles");
    FILE *f = ok ? fopen(path, "rb") : NULL;
    if (f) { /* bytes parsed: the scene file itself (buffers and images not counted) */
        if (fseek(f, 0, SEEK_END) == 0) {
            long n = ftell(f);
            if (n > 0) ctx->bytes += (size_t)n;
        }
        fclose(f);
    }
    free(s.materials);
    free(s.json);
    free(s.light_done);
    aiReleaseImport(scene);
    return ok;
}

#else /* no assimp: the formats it reads are refused with a clear message */

bool assimp_can_load(const char *ext) {
    static const char *const known[] = {"gltf", "glb", "fbx", "dae", "3ds", "stl", "blend", "x", "lwo", "ase"};
    for (size_t i = 0; i < sizeof known / sizeof known[0]; i++)
        if (strcmp(ext, known[i]) == 0) return true;
    return false;
}

bool assimp_load(io_ctx *ctx, const char *path) {
    return io_error(ctx, path, 0,
                    "raypack was built without assimp (apt install libassimp-dev), so it cannot read this format");
}

#endif
