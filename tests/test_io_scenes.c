// rp-test: labels=io,slow timeout=600 sanitized=no
/* Every shared scene loads with the triangle count of MANIFEST.tsv (and the sphere, cone, light and
 * material counts the files state). Too slow under ASan for the 1M-triangle tree: test_io.c checks
 * the small scenes there. Prints the parse time per scene (a test does not judge timings). */
#include <math.h>

#include "raypack_io.h"
#include "rp_test.h"

typedef struct scene_case {
    const char *file;
    size_t triangles;
    long spheres, cones, lights, materials, textures; /* -1: not checked */
    int camera;                                        /* 1: the file has a viewpoint */
} scene_case;

static const scene_case cases[] = {
    {"cornell_box/cornell_box.obj", 36, 0, 0, 0, 5, 0, 0},
    {"spd_teapot.nff.gz", 2328, 0, 0, 2, 3, 0, 1},
    {"stanford_bunny_bun_zipper.ply.gz", 69451, 0, 0, 0, 1, 0, 0},
    {"dabrovic_sponza.obj.gz", 66454, 0, 0, 0, 1, 0, 0},
    {"bart_kitchen.tar.gz", 110561, 0, 0, 6, -1, 8, 1},
    {"bart_museum5.tar.gz", 11308, 0, 8, 2, -1, 5, 1},
    {"spd_rings_s5.nff.gz", 217802, 0, 0, 3, 331, 0, 1},
    {"conference_geom.obj.gz", 331179, 0, 0, 0, 1, 0, 0},
    {"spd_tree_s12.nff.gz", 1081214, 0, 0, 7, 2, 0, 1},
};

int main(void) {
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        const scene_case *c = &cases[k];
        char path[1024];
        if (!rp_test_scene(c->file, path, sizeof path)) {
            CHECKF(0, "missing scene %s", c->file);
            continue;
        }
        rp_scene_data s;
        char err[1024];
        bool ok = rp_scene_data_load(path, &s, err, sizeof err);
        CHECKF(ok, "%s: %s", c->file, err);
        if (!ok) continue;
        CHECKF(s.triangle_count == c->triangles, "%s: %zu triangles, want %zu", c->file, s.triangle_count, c->triangles);
        if (c->spheres >= 0) CHECKF(s.sphere_count == (size_t)c->spheres, "%s: %zu spheres", c->file, s.sphere_count);
        if (c->cones >= 0) CHECKF(s.cone_count == (size_t)c->cones, "%s: %zu cones", c->file, s.cone_count);
        if (c->lights >= 0) CHECKF(s.light_count == (size_t)c->lights, "%s: %zu lights", c->file, s.light_count);
        if (c->materials >= 0)
            CHECKF(s.material_count == (size_t)c->materials, "%s: %zu materials", c->file, s.material_count);
        if (c->textures >= 0)
            CHECKF(s.texture_count == (size_t)c->textures, "%s: %zu textures", c->file, s.texture_count);
        CHECKF(s.camera.valid == (c->camera != 0), "%s: camera %d", c->file, s.camera.valid);
        bool good = true;
        for (size_t i = 0; i < 3 * s.triangle_count; i++) {
            good &= s.indices[i] < s.vertex_count;
            if (s.normal_indices) good &= s.normal_indices[i] < s.normal_count;
            if (s.texcoord_indices) good &= s.texcoord_indices[i] < s.texcoord_count;
        }
        for (size_t i = 0; i < s.triangle_count; i++) good &= s.tri_materials[i] < s.material_count;
        for (size_t i = 0; i < 3 * s.vertex_count; i++) good &= isfinite(s.positions[i]);
        for (size_t i = 0; i < s.texture_count; i++)
            good &= s.textures[i].rgb && s.textures[i].width > 0 && s.textures[i].height > 0;
        CHECKF(good, "%s: an index out of range, a non-finite position or an empty texture", c->file);
        printf("%-34s %8zu tris %6zu mats %2zu tex %7.1f MB %8.1f ms %6.0f MB/s\n", c->file, s.triangle_count,
               s.material_count, s.texture_count, (double)s.file_bytes / 1e6, s.parse_ms,
               (double)s.file_bytes / 1e3 / s.parse_ms);
        rp_scene_data_free(&s);
    }
    return RP_TEST_END();
}
