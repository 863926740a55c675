/* The MPI renderer's byte formats (apps/mpi/wire.c), without MPI: every shared scene kind (meshes
 * with normals, texcoords and textures, spheres, cones, BART animations, volumes) survives
 * wire_scene_pack/unpack array for array and renders the same image (an animation at two more
 * times); truncated and corrupted messages are refused with a message (never a crash); tiles of
 * real pixels and of odd floats (NaN, infinities, denormals) come back bit for bit, and broken
 * compressed tiles are refused. */
#include <math.h>
#include <stdint.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"
#include "wire.h"

enum { W = 64, H = 48 };

static bool same(const void *a, const void *b, size_t n) {
    if (!a || !b) return a == b;
    return memcmp(a, b, n) == 0;
}

/* The image of data, or of frames images at the animation's times t[] (the render scene moved there
 * with rp_render_scene_set_time, as the MPI ranks do), one after the other in one buffer. */
static float *render_times(rp_scene_data *data, const float *t, int frames) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    char err[256] = "";
    rp_render_scene *rs = dev ? rp_render_scene_new(dev, data, NULL, err, sizeof err) : NULL;
    CHECKF(rs != NULL, "%s", err);
    float *px = NULL;
    if (rs) {
        int n = frames > 0 ? frames : 1;
        px = malloc(sizeof(float) * W * H * 3 * (size_t)n);
        for (int f = 0; px && f < n; f++) {
            if (frames > 0) CHECK(rp_render_scene_set_time(rs, data, t[f], NULL));
            rp_camera cam = rp_render_scene_default_camera(rs);
            rp_render_desc d = {.width = W, .height = H, .camera = &cam};
            CHECK(rp_render(rs, &d, px + (size_t)f * W * H * 3, NULL));
        }
        rp_render_scene_release(rs);
    }
    if (dev) rp_device_release(dev);
    return px;
}

static float *render(rp_scene_data *data) { return render_times(data, NULL, 0); }

/* n bytes the same, where an empty array may be NULL on one side (the loader allocates some anyway). */
static bool same_n(const void *a, const void *b, size_t n) { return n == 0 || same(a, b, n); }

/* The animation's arrays, one by one. */
static void check_animation(const char *name, const rp_scene_data *s, const rp_scene_data *u) {
    const rp_animation_data *a = s->animation, *b = u->animation;
    CHECKF(!a == !b, "%s: animation %s", name, a ? "lost" : "appeared");
    if (!a || !b) return;
    CHECK(a->start == b->start && a->end == b->end && a->frames == b->frames && a->time == b->time);
    CHECK(a->node_count == b->node_count && a->key_count == b->key_count && a->vis_count == b->vis_count &&
          a->tpa_count == b->tpa_count);
    CHECK(same_n(a->camera, b->camera, sizeof a->camera) && same_n(&a->rest_camera, &b->rest_camera, sizeof a->rest_camera));
    CHECK(same_n(a->nodes, b->nodes, a->node_count * sizeof *a->nodes));
    CHECK(same_n(a->keys, b->keys, a->key_count * sizeof *a->keys));
    CHECK(same_n(a->vis_times, b->vis_times, a->vis_count * 4) && same_n(a->vis_values, b->vis_values, a->vis_count));
    CHECK(same_n(a->tpas, b->tpas, a->tpa_count * sizeof *a->tpas));
    size_t keys = 0;
    for (size_t i = 0; i < a->tpa_count; i++)
        if (a->tpas[i].first + a->tpas[i].count > keys) keys = a->tpas[i].first + a->tpas[i].count;
    CHECK(same_n(a->tpa_keys, b->tpa_keys, 19 * keys * sizeof(float)));
    CHECK(same_n(a->tri_node, b->tri_node, s->triangle_count * 4) && same_n(a->tri_tpa, b->tri_tpa, s->triangle_count));
    CHECK(same_n(a->sphere_node, b->sphere_node, s->sphere_count * 4) && same_n(a->cone_node, b->cone_node, s->cone_count * 4));
    CHECK(same_n(a->light_node, b->light_node, s->light_count * 4));
    CHECK(same_n(a->vertex_node, b->vertex_node, s->vertex_count * 4) &&
          same_n(a->normal_node, b->normal_node, s->normal_count * 4));
    CHECK(same_n(a->rest_positions, b->rest_positions, 3 * s->vertex_count * 4));
    CHECK(!a->rest_normals == !b->rest_normals &&
          (!a->rest_normals || same_n(a->rest_normals, b->rest_normals, 3 * s->normal_count * 4)));
    CHECK(same_n(a->rest_spheres, b->rest_spheres, s->sphere_count * sizeof *a->rest_spheres));
    CHECK(same_n(a->rest_cones, b->rest_cones, s->cone_count * sizeof *a->rest_cones));
    CHECK(same_n(a->rest_lights, b->rest_lights, s->light_count * sizeof *a->rest_lights));
}

/* The volume's fields and arrays. */
static void check_volume(const char *name, const rp_scene_data *s, const rp_scene_data *u) {
    const rp_volume_data *a = s->volume, *b = u->volume;
    CHECKF(!a == !b, "%s: volume %s", name, a ? "lost" : "appeared");
    if (!a || !b) return;
    size_t cells = (size_t)a->dims[0] * a->dims[1] * a->dims[2], voxels = (size_t)RP_VOLUME_BRICK * RP_VOLUME_BRICK * RP_VOLUME_BRICK;
    CHECK(strcmp(a->grid_name, b->grid_name) == 0 && same(a->index_to_world, b->index_to_world, sizeof a->index_to_world));
    CHECK(same(a->active_min, b->active_min, sizeof a->active_min) && same(a->active_max, b->active_max, sizeof a->active_max));
    CHECK(a->active_voxels == b->active_voxels && same(a->origin, b->origin, sizeof a->origin) &&
          same(a->dims, b->dims, sizeof a->dims) && a->brick_count == b->brick_count && a->max_density == b->max_density);
    CHECK(same(a->brick_slot, b->brick_slot, cells * 4) && same_n(a->brick_max, b->brick_max, a->brick_count * 4));
    CHECK(same_n(a->density, b->density, a->brick_count * voxels * 4));
}

/* A corrupted animation or volume (made so before packing) is refused naming what is wrong. */
static void check_bad_animation(const char *name, rp_scene_data *s, const char *what) {
    uint8_t *buf = NULL;
    size_t size = 0;
    rp_scene_data u;
    char err[512] = "";
    CHECK(wire_scene_pack(s, &buf, &size));
    CHECKF(buf && !wire_scene_unpack(buf, size, &u, err, sizeof err) && strstr(err, what), "%s: %s: got '%s'", name,
           what, err);
    free(buf);
}

static void check_scene(const char *name, rp_scene_data *s) {
    uint8_t *buf = NULL;
    size_t size = 0;
    CHECK(wire_scene_pack(s, &buf, &size));
    if (!buf) return;
    rp_scene_data u;
    char err[512] = "";
    CHECKF(wire_scene_unpack(buf, size, &u, err, sizeof err), "%s: %s", name, err);
    CHECK(u.vertex_count == s->vertex_count && u.normal_count == s->normal_count &&
          u.texcoord_count == s->texcoord_count && u.triangle_count == s->triangle_count &&
          u.sphere_count == s->sphere_count && u.cone_count == s->cone_count &&
          u.material_count == s->material_count && u.texture_count == s->texture_count &&
          u.light_count == s->light_count);
    CHECK(same(u.positions, s->positions, 3 * s->vertex_count * sizeof(float)));
    CHECK(same(u.normals, s->normals, 3 * s->normal_count * sizeof(float)));
    CHECK(same(u.texcoords, s->texcoords, 2 * s->texcoord_count * sizeof(float)));
    CHECK(same(u.indices, s->indices, 3 * s->triangle_count * 4));
    CHECK(same(u.normal_indices, s->normal_indices, 3 * s->triangle_count * 4));
    CHECK(same(u.texcoord_indices, s->texcoord_indices, 3 * s->triangle_count * 4));
    CHECK(same(u.tri_materials, s->tri_materials, s->triangle_count * 4));
    CHECK(same(u.spheres, s->spheres, s->sphere_count * sizeof *s->spheres));
    CHECK(same(u.cones, s->cones, s->cone_count * sizeof *s->cones));
    CHECK(same(u.materials, s->materials, s->material_count * sizeof *s->materials));
    CHECK(same(u.lights, s->lights, s->light_count * sizeof *s->lights));
    for (size_t i = 0; i < s->texture_count && i < u.texture_count; i++) {
        const rp_texture_data *a = &s->textures[i], *b = &u.textures[i];
        CHECK(a->width == b->width && a->height == b->height && strcmp(a->path, b->path) == 0);
        CHECK(a->wrap_u == b->wrap_u && a->wrap_v == b->wrap_v && a->filter == b->filter);
        CHECK(same(a->rgb, b->rgb, (size_t)a->width * (size_t)a->height * 3));
        CHECK(!a->alpha == !b->alpha && (!a->alpha || same(a->alpha, b->alpha, (size_t)a->width * (size_t)a->height)));
    }
    CHECK(u.camera.valid == s->camera.valid && same(u.camera.eye, s->camera.eye, sizeof u.camera.eye) &&
          u.camera.width == s->camera.width && u.has_background == s->has_background);
    check_animation(name, s, &u);
    check_volume(name, s, &u);
    float *a = render(s), *b = render(&u);
    CHECKF(a && b && memcmp(a, b, sizeof(float) * W * H * 3) == 0, "%s: the unpacked scene renders differently",
           name);
    free(a);
    free(b);
    if (s->animation && u.animation) {
        /* a client's frames: the unpacked animation moves as the loaded one (then back to the start) */
        const rp_animation_data *an = s->animation;
        float t[3] = {rp_anim_frame_time(an, 1, 3), an->end, an->start};
        a = render_times(s, t, 3);
        b = render_times(&u, t, 3);
        CHECKF(a && b && memcmp(a, b, sizeof(float) * W * H * 3 * 3) == 0,
               "%s: the unpacked animation renders differently at t %g or %g", name, (double)t[0], (double)t[1]);
        CHECKF(a && memcmp(a, a + W * H * 3, sizeof(float) * W * H * 3) != 0, "%s: nothing moved from t %g to %g", name,
               (double)t[0], (double)t[1]);
        free(a);
        free(b);
    }
    rp_scene_data_free(&u);
    if (s->animation) {
        rp_animation_data *an = s->animation;
        if (an->node_count) {
            int32_t keep = an->nodes[0].parent;
            an->nodes[0].parent = 0; /* its own parent */
            check_bad_animation(name, s, "animation block parents");
            an->nodes[0].parent = keep;
        }
        if (s->triangle_count) {
            int32_t keep = an->tri_node[0];
            an->tri_node[0] = (int32_t)an->node_count;
            check_bad_animation(name, s, "animation block indices");
            an->tri_node[0] = keep;
        }
        if (an->tpa_count) {
            uint32_t keep = an->tpas[0].vertex;
            an->tpas[0].vertex = (uint32_t)s->vertex_count - 2;
            check_bad_animation(name, s, "tpa triangles");
            an->tpas[0].vertex = keep;
        }
    }

    if (s->material_count) { /* a texture index past the textures, in each of a material's maps */
        rp_material_data keep = s->materials[0];
        int32_t *maps[4] = {&s->materials[0].map_roughness, &s->materials[0].map_normal, &s->materials[0].map_ke,
                            &s->materials[0].map_alpha};
        for (int k = 0; k < 4; k++) {
            *maps[k] = (int32_t)s->texture_count + 1;
            check_bad_animation(name, s, "material textures");
            s->materials[0] = keep;
        }
        s->materials[0].map_kd = (int32_t)s->texture_count;
        check_bad_animation(name, s, "material textures");
        s->materials[0] = keep;
    }
    if (s->volume && s->volume->brick_count) {
        rp_volume_data *v = s->volume;
        size_t cells = (size_t)v->dims[0] * v->dims[1] * v->dims[2], k = 0;
        while (k < cells && v->brick_slot[k] == RP_VOLUME_EMPTY) k++;
        uint32_t keep = v->brick_slot[k];
        v->brick_slot[k] = v->brick_count; /* a slot past the bricks */
        check_bad_animation(name, s, "volume bricks");
        v->brick_slot[k] = keep;
        float d = v->density[5];
        v->density[5] = NAN;
        check_bad_animation(name, s, "volume densities");
        v->density[5] = -1.0f;
        check_bad_animation(name, s, "volume densities");
        v->density[5] = d;
    }

    /* Truncated anywhere: refused, with the reason. */
    int refused = 0, cuts = 0;
    for (size_t cut = 0; cut < size; cut += 1 + size / 97) {
        cuts++;
        err[0] = '\0';
        if (!wire_scene_unpack(buf, cut, &u, err, sizeof err) && err[0]) refused++;
        else rp_scene_data_free(&u);
    }
    CHECKF(refused == cuts, "%s: %d of %d truncations refused", name, refused, cuts);
    /* A vertex index past the positions (the last index of the first triangle). */
    if (s->triangle_count) {
        size_t at = 40 + 8 + 3 * s->vertex_count * 4 + 8 + (s->normals ? 3 * s->normal_count * 4 : 0) + 8 +
                    (s->texcoords ? 2 * s->texcoord_count * 4 : 0) + 8;
        uint32_t big = (uint32_t)s->vertex_count;
        memcpy(buf + at + 8, &big, 4);
        CHECKF(!wire_scene_unpack(buf, size, &u, err, sizeof err) && strstr(err, "indices"), "%s: bad index: %s",
               name, err);
    }
    /* a message of format 1 (no animation): named, not misread */
    uint32_t v1 = 1;
    memcpy(buf + 4, &v1, 4);
    CHECKF(!wire_scene_unpack(buf, size, &u, err, sizeof err) && strstr(err, "format 1;"), "%s: format 1: %s", name, err);
    buf[0] ^= 0xff;
    CHECK(!wire_scene_unpack(buf, size, &u, err, sizeof err) && strstr(err, "not a raypack scene"));
    free(buf);
}

static void check_tile(const float *px, size_t n) {
    size_t cap = wire_tile_bound(n);
    uint8_t *out = malloc(cap), *scratch = malloc(4 * n);
    float *back = malloc(4 * n);
    wire_codec *c = wire_codec_new();
    CHECK(c != NULL);
    for (int round = 0; round < 4 && c; round++) { /* fast and small, twice: the streams are reused */
        int raw = 2 + round % 2;
        size_t len = wire_tile_pack(c, px, n, raw, scratch, out, cap);
        CHECK(len > 0 && len <= cap);
        CHECK(wire_tile_unpack(c, out, len, n, scratch, back) && memcmp(px, back, 4 * n) == 0);
        CHECK(!wire_tile_unpack(c, out, len - 1, n, scratch, back));        /* truncated */
        CHECK(!wire_tile_unpack(c, out, 1 + (size_t)raw * n + 1, n, scratch, back)); /* deflated part cut */
        CHECK(!wire_tile_unpack(c, out, len, n + 1, scratch, back));        /* another size */
        CHECK(!wire_tile_pack(c, px, n, raw, scratch, out, cap - 1));        /* too small a buffer */
        out[0] = 7;
        CHECK(!wire_tile_unpack(c, out, len, n, scratch, back));            /* unknown plane split */
    }
    wire_codec_free(c);
    free(out);
    free(scratch);
    free(back);
}

int main(void) {
    char buf[512], err[512];
    rp_scene_data room;
    CHECK(rp_default_scene(&room));
    check_scene("room", &room);
    float *px = render(&room);
    if (px) check_tile(px, W * H * 3);
    free(px);
    /* an alpha cutout: the texture's alpha plane and the material's mode travel */
    rp_texture_data *tex = &room.textures[0];
    tex->alpha = malloc((size_t)tex->width * (size_t)tex->height);
    if (tex->alpha) {
        for (size_t i = 0; i < (size_t)tex->width * (size_t)tex->height; i++) tex->alpha[i] = (uint8_t)(i * 37 % 256);
        for (size_t i = 0; i < room.material_count; i++)
            if (room.materials[i].map_kd == 0) room.materials[i].alpha_mode = RP_ALPHA_MASK, room.materials[i].map_alpha = 1;
        check_scene("room with a cutout", &room);
    }
    /* a texture's sampler travels; an unknown wrap mode is refused */
    tex->wrap_u = RP_TEXTURE_CLAMP, tex->wrap_v = RP_TEXTURE_MIRROR, tex->filter = RP_TEXTURE_NEAREST;
    check_scene("room with a clamped, mirrored, nearest texture", &room);
    tex->wrap_v = (rp_texture_wrap)7;
    check_bad_animation("room", &room, "texture samplers");
    tex->wrap_v = RP_TEXTURE_MIRROR;
    rp_default_scene_free(&room);
    static const char *const scenes[] = {"bart_kitchen.tar.gz", "bart_museum5.tar.gz", "spd_rings_s5.nff.gz",
                                         "cornell_box/cornell_box.obj", "stanford_bunny_bun_zipper.ply.gz"};
    for (size_t i = 0; i < sizeof scenes / sizeof scenes[0]; i++) {
        const char *path = rp_test_scene(scenes[i], buf, sizeof buf);
        CHECK(path != NULL);
        if (!path) continue;
        rp_scene_data data;
        CHECKF(rp_scene_data_load(path, &data, err, sizeof err), "%s", err);
        check_scene(scenes[i], &data);
        rp_scene_data_free(&data);
    }
    /* volumes: a --medium-box in a mesh scene, and the shared cloud (when OpenVDB was found) */
    const char *box = rp_test_scene("cornell_box/cornell_box.obj", buf, sizeof buf);
    rp_scene_data data;
    if (box && rp_scene_data_load(box, &data, err, sizeof err)) {
        CHECK(rp_scene_data_add_medium_box(&data, (const float[3]){100, 0, 100}, (const float[3]){400, 300, 400}));
        check_scene("cornell_box with a medium box", &data);
        rp_scene_data_free(&data);
    }
    const char *cloud = rp_test_scene("volume_wdas_cloud/wdas_cloud_sixteenth.vdb", buf, sizeof buf);
    if (cloud && rp_scene_data_load(cloud, &data, err, sizeof err)) {
        check_scene("wdas_cloud_sixteenth.vdb", &data);
        rp_scene_data_free(&data);
    } else {
        CHECKF(strstr(err, "without OpenVDB") != NULL, "the cloud: %s", err);
        printf("the cloud skipped: %s\n", err);
    }
    float odd[] = {NAN, INFINITY, -INFINITY, 1e-40f, -0.0f, 0.0f, 3.5f, -1e30f, 1.0f, 0.25f};
    check_tile(odd, sizeof odd / sizeof odd[0]);
    return RP_TEST_END();
}
