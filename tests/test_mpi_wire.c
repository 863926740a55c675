/* The MPI renderer's byte formats (apps/mpi/wire.c), without MPI: every shared scene kind (meshes
 * with normals, texcoords and textures, spheres, cones) survives wire_scene_pack/unpack array for
 * array and renders the same image; truncated and corrupted messages are refused with a message
 * (never a crash); tiles of real pixels and of odd floats (NaN, infinities, denormals) come back
 * bit for bit, and broken compressed tiles are refused. */
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

static float *render(const rp_scene_data *data) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    char err[256] = "";
    rp_render_scene *rs = dev ? rp_render_scene_new(dev, data, NULL, err, sizeof err) : NULL;
    CHECKF(rs != NULL, "%s", err);
    float *px = NULL;
    if (rs) {
        px = malloc(sizeof(float) * W * H * 3);
        rp_render_desc d = {.width = W, .height = H};
        CHECK(rp_render(rs, &d, px, NULL));
        rp_render_scene_release(rs);
    }
    if (dev) rp_device_release(dev);
    return px;
}

static void check_scene(const char *name, const rp_scene_data *s) {
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
        CHECK(same(a->rgb, b->rgb, (size_t)a->width * (size_t)a->height * 3));
    }
    CHECK(u.camera.valid == s->camera.valid && same(u.camera.eye, s->camera.eye, sizeof u.camera.eye) &&
          u.camera.width == s->camera.width && u.has_background == s->has_background);
    float *a = render(s), *b = render(&u);
    CHECKF(a && b && memcmp(a, b, sizeof(float) * W * H * 3) == 0, "%s: the unpacked scene renders differently",
           name);
    free(a);
    free(b);
    rp_scene_data_free(&u);

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
        size_t at = 24 + 8 + 3 * s->vertex_count * 4 + 8 + (s->normals ? 3 * s->normal_count * 4 : 0) + 8 +
                    (s->texcoords ? 2 * s->texcoord_count * 4 : 0) + 8;
        uint32_t big = (uint32_t)s->vertex_count;
        memcpy(buf + at + 8, &big, 4);
        CHECKF(!wire_scene_unpack(buf, size, &u, err, sizeof err) && strstr(err, "indices"), "%s: bad index: %s",
               name, err);
    }
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
    float odd[] = {NAN, INFINITY, -INFINITY, 1e-40f, -0.0f, 0.0f, 3.5f, -1e30f, 1.0f, 0.25f};
    check_tile(odd, sizeof odd / sizeof odd[0]);
    return RP_TEST_END();
}
