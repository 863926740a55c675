/* The built-in demo scene, after ERW6 (Wald's "empty room" test scene): a box room with two boxes,
 * a mirror on the back wall, a glass sphere, a chequered floor and one point light. */
#include "render.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { MAX_VERTS = 256, MAX_TRIS = 128, TEX_SIZE = 64 };

enum {
    MAT_WALL, MAT_RED, MAT_BLUE, MAT_FLOOR, MAT_TALL_BOX, MAT_SHORT_BOX, MAT_MIRROR, MAT_GLASS,
    MAT_FRAME, MAT_COUNT
};

typedef struct builder {
    rp_scene_data *d;
} builder;

static uint32_t add_vertex(builder *b, v3 p, float u, float v) {
    rp_scene_data *d = b->d;
    size_t i = d->vertex_count++;
    d->positions[3 * i + 0] = p.x;
    d->positions[3 * i + 1] = p.y;
    d->positions[3 * i + 2] = p.z;
    d->texcoords[2 * i + 0] = u;
    d->texcoords[2 * i + 1] = v;
    d->texcoord_count = d->vertex_count;
    return (uint32_t)i;
}

static void add_triangle(builder *b, uint32_t i0, uint32_t i1, uint32_t i2, uint32_t material) {
    rp_scene_data *d = b->d;
    size_t t = d->triangle_count++;
    uint32_t idx[3] = {i0, i1, i2};
    memcpy(d->indices + 3 * t, idx, sizeof idx);
    memcpy(d->texcoord_indices + 3 * t, idx, sizeof idx);
    d->tri_materials[t] = material;
}

/* A quad a b c d (in order around it) facing `facing`, with texture coordinates 0..uv_scale. */
static void add_quad(builder *b, v3 a, v3 bb, v3 c, v3 dd, v3 facing, uint32_t material, float uv_scale) {
    v3 n = v3_cross(v3_sub(bb, a), v3_sub(c, a));
    if (v3_dot(n, facing) < 0.0f) {
        v3 t = bb;
        bb = dd;
        dd = t;
    }
    uint32_t i0 = add_vertex(b, a, 0, 0);
    uint32_t i1 = add_vertex(b, bb, uv_scale, 0);
    uint32_t i2 = add_vertex(b, c, uv_scale, uv_scale);
    uint32_t i3 = add_vertex(b, dd, 0, uv_scale);
    add_triangle(b, i0, i1, i2, material);
    add_triangle(b, i0, i2, i3, material);
}

/* A box standing on the floor: centre (cx, cz), size sx, sy, sz, turned by `angle` radians about y. */
static void add_box(builder *b, float cx, float cz, float sx, float sy, float sz, float angle,
                    uint32_t material) {
    float ca = cosf(angle), sa = sinf(angle);
    v3 c[8];
    for (int i = 0; i < 8; i++) {
        float lx = (i & 1 ? 0.5f : -0.5f) * sx, ly = i & 2 ? sy : 0.0f, lz = (i & 4 ? 0.5f : -0.5f) * sz;
        c[i] = v3_make(cx + ca * lx + sa * lz, ly, cz - sa * lx + ca * lz);
    }
    v3 ex = v3_make(ca, 0, -sa), ez = v3_make(sa, 0, ca), ey = v3_make(0, 1, 0);
    add_quad(b, c[1], c[3], c[7], c[5], ex, material, 1);          /* +x */
    add_quad(b, c[0], c[2], c[6], c[4], v3_neg(ex), material, 1);  /* -x */
    add_quad(b, c[2], c[3], c[7], c[6], ey, material, 1);          /* top */
    add_quad(b, c[4], c[5], c[7], c[6], ez, material, 1);          /* +z */
    add_quad(b, c[0], c[1], c[3], c[2], v3_neg(ez), material, 1);  /* -z */
}

static void set_material(rp_material_data *m, const char *name, float r, float g, float bl) {
    memset(m, 0, sizeof *m);
    snprintf(m->name, sizeof m->name, "%s", name);
    m->kd[0] = r;
    m->kd[1] = g;
    m->kd[2] = bl;
    m->ns = 1.0f;
    m->ior = 1.0f;
    m->illum = -1;
    m->map_kd = -1;
}

static void set_rgb(float *c, float r, float g, float b) {
    c[0] = r;
    c[1] = g;
    c[2] = b;
}

bool rp_default_scene(rp_scene_data *out) {
    if (!out) return false;
    memset(out, 0, sizeof *out);
    rp_scene_data *d = out;
    d->positions = malloc(MAX_VERTS * 3 * sizeof(float));
    d->texcoords = malloc(MAX_VERTS * 2 * sizeof(float));
    d->indices = malloc(MAX_TRIS * 3 * sizeof(uint32_t));
    d->texcoord_indices = malloc(MAX_TRIS * 3 * sizeof(uint32_t));
    d->tri_materials = malloc(MAX_TRIS * sizeof(uint32_t));
    d->spheres = calloc(1, sizeof *d->spheres);
    d->materials = calloc(MAT_COUNT, sizeof *d->materials);
    d->textures = calloc(1, sizeof *d->textures);
    d->lights = calloc(1, sizeof *d->lights);
    uint8_t *tex = malloc(TEX_SIZE * TEX_SIZE * 3);
    if (!d->positions || !d->texcoords || !d->indices || !d->texcoord_indices || !d->tri_materials ||
        !d->spheres || !d->materials || !d->textures || !d->lights || !tex) {
        free(tex);
        rp_default_scene_free(d);
        return false;
    }

    /* Materials. */
    rp_material_data *m = d->materials;
    set_material(&m[MAT_WALL], "wall", 0.75f, 0.73f, 0.68f);
    set_material(&m[MAT_RED], "red_wall", 0.70f, 0.16f, 0.12f);
    set_material(&m[MAT_BLUE], "blue_wall", 0.16f, 0.30f, 0.65f);
    set_material(&m[MAT_FLOOR], "floor", 1.0f, 1.0f, 1.0f);
    m[MAT_FLOOR].map_kd = 0;
    set_material(&m[MAT_TALL_BOX], "tall_box", 0.80f, 0.62f, 0.30f);
    set_rgb(m[MAT_TALL_BOX].ks, 0.35f, 0.35f, 0.35f);
    m[MAT_TALL_BOX].ns = 40.0f;
    set_material(&m[MAT_SHORT_BOX], "short_box", 0.78f, 0.78f, 0.76f);
    set_material(&m[MAT_MIRROR], "mirror", 0.02f, 0.02f, 0.02f);
    set_rgb(m[MAT_MIRROR].kr, 0.90f, 0.90f, 0.92f);
    set_rgb(m[MAT_MIRROR].ks, 0.5f, 0.5f, 0.5f);
    m[MAT_MIRROR].ns = 200.0f;
    set_material(&m[MAT_GLASS], "glass", 0.0f, 0.0f, 0.0f);
    set_rgb(m[MAT_GLASS].kt, 0.95f, 0.97f, 0.96f);
    set_rgb(m[MAT_GLASS].ks, 0.8f, 0.8f, 0.8f);
    m[MAT_GLASS].ns = 300.0f;
    m[MAT_GLASS].ior = 1.5f;
    set_material(&m[MAT_FRAME], "frame", 0.25f, 0.17f, 0.10f);
    d->material_count = MAT_COUNT;

    /* Chequered floor texture: 8 x 8 squares, sRGB bytes like a loaded image. */
    for (int y = 0; y < TEX_SIZE; y++) {
        for (int x = 0; x < TEX_SIZE; x++) {
            bool dark = ((x / 8) + (y / 8)) & 1;
            uint8_t *p = tex + (y * TEX_SIZE + x) * 3;
            p[0] = dark ? 70 : 225;
            p[1] = dark ? 72 : 220;
            p[2] = dark ? 80 : 205;
        }
    }
    snprintf(d->textures[0].path, sizeof d->textures[0].path, "%s", "builtin:checker");
    d->textures[0].width = TEX_SIZE;
    d->textures[0].height = TEX_SIZE;
    d->textures[0].rgb = tex;
    d->texture_count = 1;

    /* Room: x in [-3, 3], y in [0, 3.2], z in [-3, 3]; every face looks inside. */
    builder b = {d};
    const float X = 3.0f, Y = 3.2f, Z = 3.0f;
    v3 p000 = v3_make(-X, 0, -Z), p100 = v3_make(X, 0, -Z), p010 = v3_make(-X, Y, -Z),
       p110 = v3_make(X, Y, -Z), p001 = v3_make(-X, 0, Z), p101 = v3_make(X, 0, Z),
       p011 = v3_make(-X, Y, Z), p111 = v3_make(X, Y, Z);
    add_quad(&b, p000, p100, p101, p001, v3_make(0, 1, 0), MAT_FLOOR, 1.0f);
    add_quad(&b, p010, p110, p111, p011, v3_make(0, -1, 0), MAT_WALL, 1.0f);
    add_quad(&b, p000, p100, p110, p010, v3_make(0, 0, 1), MAT_WALL, 1.0f);
    add_quad(&b, p001, p101, p111, p011, v3_make(0, 0, -1), MAT_WALL, 1.0f);
    add_quad(&b, p000, p001, p011, p010, v3_make(1, 0, 0), MAT_RED, 1.0f);
    add_quad(&b, p100, p101, p111, p110, v3_make(-1, 0, 0), MAT_BLUE, 1.0f);

    /* Mirror on the back wall, in a dark frame just behind it. */
    const float mz = -Z + 0.02f, fz = -Z + 0.01f;
    add_quad(&b, v3_make(-0.1f, 0.55f, fz), v3_make(2.3f, 0.55f, fz), v3_make(2.3f, 2.65f, fz),
             v3_make(-0.1f, 2.65f, fz), v3_make(0, 0, 1), MAT_FRAME, 1.0f);
    add_quad(&b, v3_make(0.0f, 0.65f, mz), v3_make(2.2f, 0.65f, mz), v3_make(2.2f, 2.55f, mz),
             v3_make(0.0f, 2.55f, mz), v3_make(0, 0, 1), MAT_MIRROR, 1.0f);

    /* Boxes. */
    add_box(&b, -1.45f, -1.2f, 1.0f, 1.9f, 1.0f, 0.35f, MAT_TALL_BOX);
    add_box(&b, 1.35f, -0.2f, 1.1f, 0.8f, 1.1f, -0.3f, MAT_SHORT_BOX);

    /* Glass sphere on the floor, in front. */
    d->spheres[0] = (rp_sphere_data){.center = {-0.15f, 0.6f, 0.55f}, .radius = 0.6f, .material = MAT_GLASS};
    d->sphere_count = 1;

    d->lights[0] = (rp_light_data){.type = RP_LIGHT_DATA_POINT, .position = {0.3f, 2.55f, 0.9f},
                                   .color = {0.95f, 0.92f, 0.85f}};
    d->light_count = 1;

    d->camera = (rp_camera_data){.valid = true, .eye = {0.6f, 1.65f, 2.85f}, .look = {-0.2f, 1.0f, -1.5f},
                                 .up = {0, 1, 0}, .fov_deg = 60.0f, .width = 640, .height = 480};
    return true;
}

void rp_default_scene_free(rp_scene_data *scene) {
    if (!scene) return;
    free(scene->positions);
    free(scene->normals);
    free(scene->texcoords);
    free(scene->indices);
    free(scene->normal_indices);
    free(scene->texcoord_indices);
    free(scene->tri_materials);
    free(scene->spheres);
    free(scene->cones);
    free(scene->materials);
    for (size_t i = 0; scene->textures && i < scene->texture_count; i++) {
        free(scene->textures[i].rgb);
        free(scene->textures[i].alpha);
    }
    free(scene->textures);
    free(scene->lights);
    if (scene->volume) { /* a medium given to the room (raypack render --medium-box) */
        free(scene->volume->brick_slot);
        free(scene->volume->density);
        free(scene->volume->brick_max);
        free(scene->volume);
    }
    memset(scene, 0, sizeof *scene);
}
