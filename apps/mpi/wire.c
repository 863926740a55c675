/* Byte formats of the MPI renderer (see wire.h). A scene is a header (magic, format version, the
 * sizes of the structs it carries) followed by each array as a 64-bit count and its bytes, and for
 * an animated scene its rp_animation_data (format 2 on). */
#include "wire.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#define WIRE_MAGIC 0x43535052u /* "RPSC" */
/* 1: the flat arrays only; 2: and the animation (an animated scene sent as format 1 stood still at
 * its start on every client); 3: and the volume (a .vdb or --medium-box sent as format 2 was
 * missing on every client); 4: and vertex colours and textures' alpha planes; 5: and their samplers (wrap modes, filter:
 * a format 4 rank reads rp_texture_data of another size) */
#define WIRE_VERSION 5u

typedef struct writer {
    uint8_t *buf;
    size_t size, cap;
    bool failed;
} writer;

static void put(writer *w, const void *p, size_t n) {
    if (w->failed || n == 0) return;
    if (w->size + n > w->cap) {
        size_t cap = w->cap ? w->cap : 4096;
        while (cap < w->size + n) cap *= 2;
        uint8_t *b = realloc(w->buf, cap);
        if (!b) {
            w->failed = true;
            return;
        }
        w->buf = b;
        w->cap = cap;
    }
    memcpy(w->buf + w->size, p, n);
    w->size += n;
}

static void put_u64(writer *w, uint64_t v) { put(w, &v, sizeof v); }

/* An optional array: its element count (0 when absent) and its bytes. */
static void put_array(writer *w, const void *p, size_t count, size_t elem) {
    put_u64(w, p ? count : 0);
    if (p) put(w, p, count * elem);
}

/* The struct sizes a message's arrays are made of: the ends must agree on every layout. */
enum { WIRE_STRUCTS = 8 };
static void struct_sizes(uint32_t out[WIRE_STRUCTS]) {
    const uint32_t sizes[WIRE_STRUCTS] = {(uint32_t)sizeof(rp_material_data), (uint32_t)sizeof(rp_texture_data),
                                          (uint32_t)sizeof(rp_light_data),    (uint32_t)sizeof(rp_camera_data),
                                          (uint32_t)sizeof(rp_anim_node),     (uint32_t)sizeof(rp_anim_key),
                                          (uint32_t)sizeof(rp_anim_tpa),      (uint32_t)sizeof(rp_volume_data)};
    memcpy(out, sizes, sizeof sizes);
}

/* Floats of tpa_keys: 19 per key, up to the last key a `tpa` names (the loader keeps no count). */
static size_t tpa_key_floats(const rp_animation_data *a) {
    size_t keys = 0;
    for (size_t i = 0; i < a->tpa_count; i++)
        if ((size_t)a->tpas[i].first + a->tpas[i].count > keys) keys = (size_t)a->tpas[i].first + a->tpas[i].count;
    return 19 * keys;
}

/* Everything rp_scene_data_set_time and the instanced render scene read, so that a client's frames
 * at any time equal rank 0's. */
static void put_animation(writer *w, const rp_scene_data *s) {
    const rp_animation_data *a = s->animation;
    put(w, &a->start, sizeof a->start);
    put(w, &a->end, sizeof a->end);
    put(w, &a->frames, sizeof a->frames);
    put(w, &a->time, sizeof a->time);
    put(w, a->camera, sizeof a->camera);
    put(w, &a->rest_camera, sizeof a->rest_camera);
    put_array(w, a->nodes, a->node_count, sizeof(rp_anim_node));
    put_array(w, a->keys, a->key_count, sizeof(rp_anim_key));
    put_array(w, a->vis_times, a->vis_count, sizeof(float));
    put_array(w, a->vis_values, a->vis_count, 1);
    put_array(w, a->tpas, a->tpa_count, sizeof(rp_anim_tpa));
    put_array(w, a->tpa_keys, tpa_key_floats(a), sizeof(float));
    put_array(w, a->tri_node, s->triangle_count, sizeof(int32_t));
    put_array(w, a->sphere_node, s->sphere_count, sizeof(int32_t));
    put_array(w, a->cone_node, s->cone_count, sizeof(int32_t));
    put_array(w, a->light_node, s->light_count, sizeof(int32_t));
    put_array(w, a->vertex_node, s->vertex_count, sizeof(int32_t));
    put_array(w, a->normal_node, s->normal_count, sizeof(int32_t));
    put_array(w, a->tri_tpa, s->triangle_count, 1);
    put_array(w, a->rest_positions, 3 * s->vertex_count, sizeof(float));
    put_array(w, a->rest_normals, 3 * s->normal_count, sizeof(float));
    put_array(w, a->rest_spheres, s->sphere_count, sizeof(rp_sphere_data));
    put_array(w, a->rest_cones, s->cone_count, sizeof(rp_cone_data));
    put_array(w, a->rest_lights, s->light_count, sizeof(rp_light_data));
}

#define BRICK_VOXELS ((size_t)RP_VOLUME_BRICK * RP_VOLUME_BRICK * RP_VOLUME_BRICK)

/* The volume: its struct (pointers cleared), then its three arrays. */
static void put_volume(writer *w, const rp_volume_data *v) {
    rp_volume_data head = *v;
    head.brick_slot = NULL, head.density = NULL, head.brick_max = NULL;
    put(w, &head, sizeof head);
    put_array(w, v->brick_slot, (size_t)v->dims[0] * v->dims[1] * v->dims[2], sizeof(uint32_t));
    put_array(w, v->density, (size_t)v->brick_count * BRICK_VOXELS, sizeof(float));
    put_array(w, v->brick_max, v->brick_count, sizeof(float));
}

bool wire_scene_pack(const rp_scene_data *s, uint8_t **out, size_t *size) {
    writer w = {0};
    uint32_t head[2 + WIRE_STRUCTS] = {WIRE_MAGIC, WIRE_VERSION};
    struct_sizes(head + 2);
    put(&w, head, sizeof head);
    put_array(&w, s->positions, 3 * s->vertex_count, sizeof(float));
    put_array(&w, s->normals, 3 * s->normal_count, sizeof(float));
    put_array(&w, s->texcoords, 2 * s->texcoord_count, sizeof(float));
    put_array(&w, s->indices, 3 * s->triangle_count, sizeof(uint32_t));
    put_array(&w, s->normal_indices, 3 * s->triangle_count, sizeof(uint32_t));
    put_array(&w, s->texcoord_indices, 3 * s->triangle_count, sizeof(uint32_t));
    put_array(&w, s->tri_materials, s->triangle_count, sizeof(uint32_t));
    put_array(&w, s->colors, 3 * s->vertex_count, sizeof(float));
    put_array(&w, s->spheres, s->sphere_count, sizeof(rp_sphere_data));
    put_array(&w, s->sphere_colors, 3 * s->sphere_count, sizeof(float));
    put_array(&w, s->cones, s->cone_count, sizeof(rp_cone_data));
    put_array(&w, s->materials, s->material_count, sizeof(rp_material_data));
    put_array(&w, s->lights, s->light_count, sizeof(rp_light_data));
    put_u64(&w, s->texture_count);
    for (size_t i = 0; i < s->texture_count; i++) {
        rp_texture_data t = s->textures[i];
        const uint8_t *rgb = t.rgb, *alpha = t.alpha;
        t.rgb = NULL;
        t.alpha = NULL;
        put(&w, &t, sizeof t);
        put_array(&w, rgb, (size_t)t.width * (size_t)t.height * 3, 1);
        uint8_t has_alpha = alpha != NULL;
        put(&w, &has_alpha, 1);
        if (alpha) put_array(&w, alpha, (size_t)t.width * (size_t)t.height, 1);
    }
    put(&w, &s->camera, sizeof s->camera);
    put(&w, s->background, sizeof s->background);
    uint8_t bg = s->has_background;
    put(&w, &bg, 1);
    put_u64(&w, s->file_bytes);
    put(&w, &s->parse_ms, sizeof s->parse_ms);
    uint8_t animated = s->animation != NULL;
    put(&w, &animated, 1);
    if (animated) put_animation(&w, s);
    uint8_t volume = s->volume != NULL;
    put(&w, &volume, 1);
    if (volume) put_volume(&w, s->volume);
    if (w.failed) {
        free(w.buf);
        return false;
    }
    *out = w.buf;
    *size = w.size;
    return true;
}

typedef struct reader {
    const uint8_t *p;
    size_t left;
    const char *what; /* the first field that did not fit */
} reader;

static bool get(reader *r, void *dst, size_t n, const char *what) {
    if (r->what) return false;
    if (n > r->left) {
        r->what = what;
        return false;
    }
    memcpy(dst, r->p, n);
    r->p += n;
    r->left -= n;
    return true;
}

/* Reads an array of `expect` elements (or any count when expect is SIZE_MAX, returned in *count).
 * An optional one (always false) may be absent: NULL in *dst when the sender had none. One that
 * every animated scene has (always) is allocated even empty, one element more, as the loader does:
 * the renderer indexes those without a NULL check. */
static bool get_array_of(reader *r, void **dst, size_t elem, size_t expect, size_t *count, bool always,
                         const char *what) {
    uint64_t n = 0;
    *dst = NULL;
    if (!get(r, &n, sizeof n, what)) return false;
    if (count) *count = (size_t)n;
    if (n == 0 && !always) return true;
    if ((expect != SIZE_MAX && n != expect) || n > r->left / elem) {
        r->what = what;
        return false;
    }
    *dst = malloc(((size_t)n + (always ? 1 : 0)) * elem);
    if (!*dst) {
        r->what = "memory";
        return false;
    }
    return get(r, *dst, (size_t)n * elem, what);
}

static bool get_array(reader *r, void **dst, size_t elem, size_t expect, size_t *count, const char *what) {
    return get_array_of(r, dst, elem, expect, count, false, what);
}

static bool get_anim_array(reader *r, void **dst, size_t elem, size_t expect, size_t *count, const char *what) {
    return get_array_of(r, dst, elem, expect, count, true, what);
}

static bool nodes_below(const int32_t *node, size_t n, size_t limit) {
    for (size_t i = 0; node && i < n; i++)
        if (node[i] < -1 || node[i] >= (int64_t)limit) return false;
    return true;
}

static bool track_ok(rp_anim_track t, size_t keys) { return (size_t)t.first + t.count <= keys; }

/* The animation after the flat arrays (s's counts are known); NULL in r->what when it fits and
 * every index in it points inside what it indexes. */
static void get_animation(reader *r, rp_scene_data *s) {
    rp_animation_data *a = calloc(1, sizeof *a);
    if (!a) {
        r->what = "memory";
        return;
    }
    s->animation = a; /* rp_scene_data_free frees it, and what came of it, on failure */
    get(r, &a->start, sizeof a->start, "animation range");
    get(r, &a->end, sizeof a->end, "animation range");
    get(r, &a->frames, sizeof a->frames, "animation range");
    get(r, &a->time, sizeof a->time, "animation time");
    get(r, a->camera, sizeof a->camera, "camera path");
    get(r, &a->rest_camera, sizeof a->rest_camera, "camera path");
    void *p;
    size_t n = 0;
    get_anim_array(r, &p, sizeof(rp_anim_node), SIZE_MAX, &a->node_count, "animation blocks");
    a->nodes = p;
    get_array(r, &p, sizeof(rp_anim_key), SIZE_MAX, &a->key_count, "animation keys");
    a->keys = p;
    get_array(r, &p, sizeof(float), SIZE_MAX, &a->vis_count, "visibility keys");
    a->vis_times = p;
    get_array(r, &p, 1, a->vis_count, NULL, "visibility keys");
    a->vis_values = p;
    get_array(r, &p, sizeof(rp_anim_tpa), SIZE_MAX, &a->tpa_count, "tpa triangles");
    a->tpas = p;
    get_array(r, &p, sizeof(float), SIZE_MAX, &n, "tpa keys");
    a->tpa_keys = p;
    if (r->what) return;
    if (n != tpa_key_floats(a)) r->what = "tpa keys";
    get_anim_array(r, &p, sizeof(int32_t), s->triangle_count, NULL, "triangle blocks");
    a->tri_node = p;
    get_anim_array(r, &p, sizeof(int32_t), s->sphere_count, NULL, "sphere blocks");
    a->sphere_node = p;
    get_anim_array(r, &p, sizeof(int32_t), s->cone_count, NULL, "cone blocks");
    a->cone_node = p;
    get_anim_array(r, &p, sizeof(int32_t), s->light_count, NULL, "light blocks");
    a->light_node = p;
    get_anim_array(r, &p, sizeof(int32_t), s->vertex_count, NULL, "vertex blocks");
    a->vertex_node = p;
    get_anim_array(r, &p, sizeof(int32_t), s->normal_count, NULL, "normal blocks");
    a->normal_node = p;
    get_anim_array(r, &p, 1, s->triangle_count, NULL, "tpa flags");
    a->tri_tpa = p;
    get_anim_array(r, &p, sizeof(float), 3 * s->vertex_count, NULL, "rest positions");
    a->rest_positions = p;
    get_array(r, &p, sizeof(float), 3 * s->normal_count, NULL, "rest normals");
    a->rest_normals = p;
    if (!r->what && !a->rest_normals != !s->normals) r->what = "rest normals";
    get_anim_array(r, &p, sizeof(rp_sphere_data), s->sphere_count, NULL, "rest spheres");
    a->rest_spheres = p;
    get_anim_array(r, &p, sizeof(rp_cone_data), s->cone_count, NULL, "rest cones");
    a->rest_cones = p;
    get_anim_array(r, &p, sizeof(rp_light_data), s->light_count, NULL, "rest lights");
    a->rest_lights = p;
    if (r->what) return;
    /* what the loader guarantees and set_time and the render scene rely on */
    for (size_t i = 0; !r->what && i < a->node_count; i++) {
        rp_anim_node *nd = &a->nodes[i];
        nd->name[sizeof nd->name - 1] = '\0';
        if (nd->parent < -1 || nd->parent >= (int64_t)i) r->what = "animation block parents";
        else if (!track_ok(nd->track[0], a->key_count) || !track_ok(nd->track[1], a->key_count) ||
                 !track_ok(nd->track[2], a->key_count))
            r->what = "animation block keys";
        else if ((size_t)nd->vis_first + nd->vis_count > a->vis_count) r->what = "visibility keys";
    }
    if (!r->what && (!track_ok(a->camera[0], a->key_count) || !track_ok(a->camera[1], a->key_count)))
        r->what = "camera path";
    size_t tpa_keys = n / 19;
    for (size_t i = 0; !r->what && i < a->tpa_count; i++) {
        const rp_anim_tpa *t = &a->tpas[i];
        if (t->triangle >= s->triangle_count || (size_t)t->vertex + 3 > s->vertex_count ||
            (a->rest_normals && (size_t)t->normal + 3 > s->normal_count) || t->count == 0 ||
            (size_t)t->first + t->count > tpa_keys)
            r->what = "tpa triangles";
    }
    if (r->what) return;
    if (!nodes_below(a->tri_node, s->triangle_count, a->node_count) ||
        !nodes_below(a->sphere_node, s->sphere_count, a->node_count) ||
        !nodes_below(a->cone_node, s->cone_count, a->node_count) ||
        !nodes_below(a->light_node, s->light_count, a->node_count) ||
        !nodes_below(a->vertex_node, s->vertex_count, a->node_count) ||
        !nodes_below(a->normal_node, s->normal_count, a->node_count))
        r->what = "animation block indices";
}

static bool finite_nonneg(const float *x, size_t n) {
    for (size_t i = 0; i < n; i++)
        if (!(x[i] >= 0.0f && x[i] <= FLT_MAX)) return false;
    return true;
}

/* The volume after the animation; NULL in r->what when it fits and holds what the loader
 * guarantees (every brick slot inside the bricks, densities finite and not negative). */
static void get_volume(reader *r, rp_scene_data *s) {
    rp_volume_data *v = calloc(1, sizeof *v);
    if (!v) {
        r->what = "memory";
        return;
    }
    s->volume = v; /* rp_scene_data_free frees it, and its arrays, on failure */
    if (!get(r, v, sizeof *v, "volume")) return;
    v->brick_slot = NULL, v->density = NULL, v->brick_max = NULL;
    v->grid_name[sizeof v->grid_name - 1] = '\0';
    uint64_t cells = (uint64_t)v->dims[0] * v->dims[1] * v->dims[2];
    if (!v->dims[0] || !v->dims[1] || !v->dims[2] || cells > UINT32_MAX || v->brick_count > cells ||
        !finite_nonneg(&v->max_density, 1)) {
        r->what = "volume";
        return;
    }
    for (int k = 0; k < 12; k++)
        if (!isfinite(v->index_to_world[k])) r->what = "volume transform";
    void *p;
    get_array(r, &p, sizeof(uint32_t), (size_t)cells, NULL, "volume bricks");
    v->brick_slot = p;
    get_array(r, &p, sizeof(float), (size_t)v->brick_count * BRICK_VOXELS, NULL, "volume densities");
    v->density = p;
    get_array(r, &p, sizeof(float), v->brick_count, NULL, "volume brick maxima");
    v->brick_max = p;
    if (r->what) return;
    if (!v->brick_slot || (v->brick_count && (!v->density || !v->brick_max))) {
        r->what = "volume bricks";
        return;
    }
    for (size_t i = 0; !r->what && i < (size_t)cells; i++)
        if (v->brick_slot[i] != RP_VOLUME_EMPTY && v->brick_slot[i] >= v->brick_count) r->what = "volume bricks";
    if (!r->what && (!finite_nonneg(v->density, (size_t)v->brick_count * BRICK_VOXELS) ||
                     !finite_nonneg(v->brick_max, v->brick_count)))
        r->what = "volume densities";
}

static bool indices_below(const uint32_t *idx, size_t n, size_t limit) {
    for (size_t i = 0; idx && i < n; i++)
        if (idx[i] >= limit) return false;
    return true;
}

bool wire_scene_unpack(const uint8_t *buf, size_t size, rp_scene_data *s, char *err, size_t err_size) {
    memset(s, 0, sizeof *s);
    reader r = {.p = buf, .left = size};
    uint32_t head[2 + WIRE_STRUCTS], want[WIRE_STRUCTS];
    if (!get(&r, head, 2 * sizeof(uint32_t), "header") || head[0] != WIRE_MAGIC) {
        snprintf(err, err_size, "not a raypack scene message (%zu bytes)", size);
        return false;
    }
    /* the version first: another format's header may be of another length */
    if (head[1] != WIRE_VERSION) {
        snprintf(err, err_size, "scene message of format %u; this build reads format %u (run the same build on every "
                                "rank)", head[1], WIRE_VERSION);
        return false;
    }
    struct_sizes(want);
    if (!get(&r, head + 2, sizeof want, "header") || memcmp(head + 2, want, sizeof want) != 0) {
        snprintf(err, err_size, "scene message of format %u with structs of other sizes (material, texture, light, "
                                "camera, block, key, tpa, volume: %u/%u/%u/%u/%u/%u/%u/%u bytes; here "
                                "%u/%u/%u/%u/%u/%u/%u/%u)",
                 head[1], head[2], head[3], head[4], head[5], head[6], head[7], head[8], head[9], want[0], want[1],
                 want[2], want[3], want[4], want[5], want[6], want[7]);
        return false;
    }
    size_t n = 0, tris = 0;
    void *p;
    get_array(&r, &p, sizeof(float), SIZE_MAX, &n, "positions");
    s->positions = p;
    s->vertex_count = n / 3;
    get_array(&r, &p, sizeof(float), SIZE_MAX, &n, "normals");
    s->normals = p;
    s->normal_count = n / 3;
    get_array(&r, &p, sizeof(float), SIZE_MAX, &n, "texcoords");
    s->texcoords = p;
    s->texcoord_count = n / 2;
    get_array(&r, &p, sizeof(uint32_t), SIZE_MAX, &tris, "indices");
    s->indices = p;
    s->triangle_count = tris / 3;
    get_array(&r, &p, sizeof(uint32_t), tris, NULL, "normal indices");
    s->normal_indices = p;
    get_array(&r, &p, sizeof(uint32_t), tris, NULL, "texcoord indices");
    s->texcoord_indices = p;
    get_array(&r, &p, sizeof(uint32_t), tris / 3, NULL, "triangle materials");
    s->tri_materials = p;
    get_array(&r, &p, sizeof(float), 3 * s->vertex_count, NULL, "vertex colours");
    s->colors = p;
    get_array(&r, &p, sizeof(rp_sphere_data), SIZE_MAX, &s->sphere_count, "spheres");
    s->spheres = p;
    get_array(&r, &p, sizeof(float), 3 * s->sphere_count, NULL, "sphere colours");
    s->sphere_colors = p;
    get_array(&r, &p, sizeof(rp_cone_data), SIZE_MAX, &s->cone_count, "cones");
    s->cones = p;
    get_array(&r, &p, sizeof(rp_material_data), SIZE_MAX, &s->material_count, "materials");
    s->materials = p;
    get_array(&r, &p, sizeof(rp_light_data), SIZE_MAX, &s->light_count, "lights");
    s->lights = p;
    uint64_t textures = 0;
    if (get(&r, &textures, sizeof textures, "texture count")) {
        if (textures > r.left / sizeof(rp_texture_data)) {
            r.what = "texture count";
        } else if (textures) {
            s->textures = calloc((size_t)textures, sizeof *s->textures);
            if (!s->textures) r.what = "memory";
            else s->texture_count = (size_t)textures;
        }
    }
    for (size_t i = 0; i < s->texture_count && !r.what; i++) {
        rp_texture_data *t = &s->textures[i];
        if (!get(&r, t, sizeof *t, "texture")) break;
        t->rgb = NULL;
        if (t->width < 0 || t->height < 0) {
            r.what = "texture size";
            break;
        }
        t->alpha = NULL;
        get_array(&r, &p, 1, (size_t)t->width * (size_t)t->height * 3, NULL, "texture pixels");
        t->rgb = p;
        uint8_t has_alpha = 0;
        if (get(&r, &has_alpha, 1, "texture alpha flag") && has_alpha > 1) r.what = "texture alpha flag";
        if (has_alpha == 1 && !r.what) {
            get_array(&r, &p, 1, (size_t)t->width * (size_t)t->height, NULL, "texture alpha");
            t->alpha = p;
        }
        t->path[sizeof t->path - 1] = '\0';
    }
    get(&r, &s->camera, sizeof s->camera, "camera");
    get(&r, s->background, sizeof s->background, "background");
    uint8_t bg = 0;
    get(&r, &bg, 1, "background");
    s->has_background = bg != 0;
    uint64_t fb = 0;
    get(&r, &fb, sizeof fb, "file size");
    s->file_bytes = (size_t)fb;
    get(&r, &s->parse_ms, sizeof s->parse_ms, "parse time");
    uint8_t animated = 0;
    if (get(&r, &animated, 1, "animation flag") && animated > 1) r.what = "animation flag";
    if (animated == 1 && !r.what) get_animation(&r, s);
    uint8_t volume = 0;
    if (!r.what && get(&r, &volume, 1, "volume flag") && volume > 1) r.what = "volume flag";
    if (volume == 1 && !r.what) get_volume(&r, s);
    if (!r.what && r.left) r.what = "trailing bytes";
    /* The renderer trusts a loader's indices; these came over the wire, so check them. */
    if (!r.what) {
        size_t nt = s->triangle_count * 3;
        if (!s->indices != !s->tri_materials && s->triangle_count) r.what = "triangle materials";
        else if (s->material_count == 0) r.what = "materials";
        else if (!indices_below(s->indices, nt, s->vertex_count)) r.what = "indices";
        else if (!indices_below(s->normal_indices, nt, s->normal_count)) r.what = "normal indices";
        else if (!indices_below(s->texcoord_indices, nt, s->texcoord_count)) r.what = "texcoord indices";
        else if (!indices_below(s->tri_materials, s->triangle_count, s->material_count)) r.what = "triangle materials";
        for (size_t i = 0; !r.what && i < s->sphere_count; i++)
            if (s->spheres[i].material >= s->material_count) r.what = "sphere materials";
        for (size_t i = 0; !r.what && i < s->cone_count; i++)
            if (s->cones[i].material >= s->material_count) r.what = "cone materials";
        for (size_t i = 0; !r.what && i < s->light_count; i++)
            if ((unsigned)s->lights[i].type > (unsigned)RP_LIGHT_DATA_DIRECTIONAL) r.what = "light types";
        for (size_t i = 0; !r.what && i < s->material_count; i++) {
            const rp_material_data *m = &s->materials[i];
            int32_t t = m->map_kd, more[6] = {m->map_roughness, m->map_normal, m->map_ke, m->map_metal_rough, m->map_alpha,
                                              m->map_ks}; /* 1 + index, 0: none */
            if (t < -1 || (t >= 0 && (size_t)t >= s->texture_count)) r.what = "material textures";
            if ((unsigned)m->alpha_mode > (unsigned)RP_ALPHA_BLEND) r.what = "material alpha mode";
            for (int k = 0; k < 6; k++)
                if (more[k] < 0 || (size_t)more[k] > s->texture_count) r.what = "material textures";
        }
        for (size_t i = 0; !r.what && i < s->texture_count; i++) {
            const rp_texture_data *t = &s->textures[i];
            if (!t->rgb && t->width && t->height) r.what = "texture pixels";
            if ((unsigned)t->wrap_u > (unsigned)RP_TEXTURE_MIRROR || (unsigned)t->wrap_v > (unsigned)RP_TEXTURE_MIRROR ||
                (unsigned)t->filter > (unsigned)RP_TEXTURE_NEAREST)
                r.what = "texture samplers";
        }
    }
    if (r.what) {
        snprintf(err, err_size, "bad scene message (%zu bytes): %s %s", size, r.what,
                 strcmp(r.what, "memory") == 0 ? "ran out" : "do not fit");
        rp_scene_data_free(s);
        return false;
    }
    return true;
}

struct wire_codec {
    z_stream def, inf;
    bool def_ok, inf_ok;
};

wire_codec *wire_codec_new(void) {
    wire_codec *c = calloc(1, sizeof *c);
    if (!c) return NULL;
    c->def_ok = deflateInit(&c->def, 1) == Z_OK;
    c->inf_ok = inflateInit(&c->inf) == Z_OK;
    if (!c->def_ok || !c->inf_ok) {
        wire_codec_free(c);
        return NULL;
    }
    return c;
}

void wire_codec_free(wire_codec *c) {
    if (!c) return;
    if (c->def_ok) deflateEnd(&c->def);
    if (c->inf_ok) inflateEnd(&c->inf);
    free(c);
}

size_t wire_tile_bound(size_t n) { return 1 + 3 * n + (size_t)compressBound((uLong)(2 * n)); }

size_t wire_tile_pack(wire_codec *c, const float *px, size_t n, int raw_planes, uint8_t *scratch, uint8_t *out,
                      size_t cap) {
    if (cap < wire_tile_bound(n) || raw_planes < 2 || raw_planes > 3) return 0;
    size_t raw = (size_t)raw_planes;
    const uint8_t *b = (const uint8_t *)px;
    out[0] = (uint8_t)raw;
    /* plane k holds byte k of every float; the low planes go out raw, first */
    for (size_t k = 0; k < 4; k++) {
        uint8_t *d = k < raw ? out + 1 + k * n : scratch + (k - raw) * n;
        for (size_t i = 0; i < n; i++) d[i] = b[4 * i + k];
    }
    z_stream *z = &c->def;
    if (deflateReset(z) != Z_OK) return 0;
    z->next_in = scratch;
    z->avail_in = (uInt)((4 - raw) * n);
    z->next_out = out + 1 + raw * n;
    z->avail_out = (uInt)(cap - 1 - raw * n);
    if (deflate(z, Z_FINISH) != Z_STREAM_END) return 0;
    return 1 + raw * n + (size_t)z->total_out;
}

bool wire_tile_unpack(wire_codec *c, const uint8_t *in, size_t size, size_t n, uint8_t *scratch, float *px) {
    if (size < 1 || (in[0] != 2 && in[0] != 3)) return false;
    size_t raw = in[0];
    if (size < 1 + raw * n) return false;
    z_stream *z = &c->inf;
    if (inflateReset(z) != Z_OK) return false;
    z->next_in = (Bytef *)(uintptr_t)(in + 1 + raw * n);
    z->avail_in = (uInt)(size - 1 - raw * n);
    z->next_out = scratch;
    z->avail_out = (uInt)((4 - raw) * n);
    /* all of the input, and exactly the deflated planes out of it */
    if (inflate(z, Z_FINISH) != Z_STREAM_END || z->total_out != (4 - raw) * n || z->avail_in != 0) return false;
    uint8_t *b = (uint8_t *)px;
    for (size_t k = 0; k < 4; k++) {
        const uint8_t *s = k < raw ? in + 1 + k * n : scratch + (k - raw) * n;
        for (size_t i = 0; i < n; i++) b[4 * i + k] = s[i];
    }
    return true;
}
