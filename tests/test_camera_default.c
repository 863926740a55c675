/* The camera a scene without one gets (rp_render_scene_default_camera): it shows the scene. Rooms
 * and buildings whose walls face inwards (the conference room, sponza's atrium) are looked at from
 * inside, where the outside views see back faces or one flat wall; objects (the bunny, suzanne) and
 * the Cornell box (through its opening) from outside. Checked on 32x32 eye rays: most of them hit,
 * most hits see front faces, and many distinct primitives are seen. */
#include <stdint.h>
#include <stdlib.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"

enum { N = 32 };

static int cmp_u64(const void *a, const void *b) {
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

/* from_z: +1 when the eye must be on the +z side of the look-at point (a model's front, glTF's +z), -1 on
 * the -z side, 0 either */
static void check(rp_device *dev, const char *file, double min_hit, int min_distinct, bool inside, int from_z) {
    char buf[512], err[512] = "";
    const char *path = rp_test_scene(file, buf, sizeof buf);
    CHECKF(path != NULL, "%s", file);
    if (!path) return;
    rp_scene_data d;
    if (!rp_scene_data_load(path, &d, err, sizeof err)) {
        CHECKF(0, "%s: %s", file, err);
        return;
    }
    rp_render_scene *rs = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s: %s", file, err);
    if (rs) {
        CHECKF(!d.camera.valid, "%s brings a camera: not a test of the default one", file);
        rp_camera cam = rp_render_scene_default_camera(rs);
        rp_ray rays[N * N];
        rp_render_primary_rays(&cam, N, N, rays);
        uint64_t ids[N * N];
        int hits = 0, front = 0;
        for (int i = 0; i < N * N; i++) {
            rp_rayhit rh = {.ray = rays[i], .hit = {.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID,
                                                    .inst_id = RP_INVALID_ID}};
            rp_intersect1(rp_render_scene_core(rs), &rh);
            if (rh.hit.geom_id == RP_INVALID_ID) continue;
            float dn = rh.hit.Ng_x * rh.ray.dir_x + rh.hit.Ng_y * rh.ray.dir_y + rh.hit.Ng_z * rh.ray.dir_z;
            front += dn < 0.0f;
            ids[hits++] = (uint64_t)rh.hit.geom_id << 32 | rh.hit.prim_id;
        }
        qsort(ids, (size_t)hits, sizeof ids[0], cmp_u64);
        int distinct = 0;
        for (int i = 0; i < hits; i++) distinct += i == 0 || ids[i] != ids[i - 1];
        /* inside: the eye within the scene's box */
        rp_bounds b;
        rp_scene_get_bounds(rp_render_scene_core(rs), &b);
        const float *e = cam.pinhole.eye;
        bool in = e[0] >= b.lower_x && e[0] <= b.upper_x && e[1] >= b.lower_y && e[1] <= b.upper_y &&
                  e[2] >= b.lower_z && e[2] <= b.upper_z;
        printf("%s: eye (%g %g %g) %s, %d of %d rays hit, %d front faces, %d distinct primitives\n", file, e[0],
               e[1], e[2], in ? "inside" : "outside", hits, N * N, front, distinct);
        CHECKF(hits >= min_hit * N * N, "%s: %d of %d eye rays hit", file, hits, N * N);
        CHECKF(front >= 0.8 * hits, "%s: %d of %d hits see back faces", file, hits - front, hits);
        CHECKF(distinct >= min_distinct, "%s: only %d distinct primitives in view", file, distinct);
        CHECKF(in == inside, "%s: the eye is %s the scene's box", file, in ? "inside" : "outside");
        float dz = cam.pinhole.eye[2] - cam.pinhole.look[2];
        CHECKF(from_z == 0 || (from_z > 0 ? dz > 0.0f : dz < 0.0f), "%s: seen from %sz, not from %s (its %s)", file,
               dz > 0.0f ? "+" : "-", from_z > 0 ? "+z" : "-z", from_z > 0 ? "front" : "opening");
        rp_render_scene_release(rs);
    }
    rp_scene_data_free(&d);
}

int main(void) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    CHECK(dev != NULL);
    if (!dev) return RP_TEST_END();
    check(dev, "dabrovic_sponza.obj.gz", 0.95, 200, true, 0);
    check(dev, "conference_geom.obj.gz", 0.95, 150, true, 0);
    check(dev, "stanford_bunny_bun_zipper.ply.gz", 0.15, 150, false, 1);
    /* her back of the head sees a few more front faces than her face did, and was the view */
    check(dev, "gltf_suzanne/Suzanne.gltf", 0.15, 150, false, 1);
    check(dev, "cornell_box/cornell_box.obj", 0.4, 10, false, -1);
    check(dev, "cornell_original/CornellBox-Original.obj", 0.4, 10, false, 1);
    rp_device_release(dev);
    return RP_TEST_END();
}
