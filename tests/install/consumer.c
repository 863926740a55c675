/* An out-of-tree program built against an installed raypack (see run.cmake): the core API on a
 * mesh of its own, then a scene file through the loaders and the renderer. Prints
 * "N passed, N failed" like the in-tree tests; exit status 0 only when everything passed. */
#include <math.h>
#include <stdio.h>

#include <raypack.h>
#include <raypack_io.h>
#include <raypack_render.h>

static int passed, failed;

static void check(int ok, const char *what) {
    if (ok) passed++;
    else failed++, printf("FAIL: %s\n", what);
}

int main(int argc, char **argv) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    check(dev != NULL, "rp_device_new");
    if (!dev) return 1;

    /* A unit quad in z = 0, two triangles. */
    static const float vertices[] = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
    static const uint32_t indices[] = {0, 1, 2, 0, 2, 3};
    rp_scene *scene = rp_scene_new(dev, NULL);
    rp_geometry *mesh = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(mesh, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, vertices, 0, 0, 4);
    rp_geometry_set_buffer(mesh, RP_BUFFER_INDEX, RP_FORMAT_UINT3, indices, 0, 0, 2);
    rp_geometry_commit(mesh);
    uint32_t id = rp_scene_attach(scene, mesh);
    rp_geometry_release(mesh);
    check(rp_scene_commit(scene) == RP_ERROR_NONE, "rp_scene_commit");
    rp_rayhit rh = {.ray = {.org_x = 0.25f, .org_y = 0.5f, .org_z = -5, .dir_z = 1, .tfar = INFINITY, .mask = ~0u}};
    rh.hit.geom_id = RP_INVALID_ID;
    rp_intersect1(scene, &rh);
    check(rh.hit.geom_id == id && fabsf(rh.ray.tfar - 5.0f) < 1e-5f, "ray hits the quad at t = 5");
    check(rh.hit.prim_id == 1, "the upper-left triangle");
    rp_ray miss = {.org_x = 3, .org_z = -5, .dir_z = 1, .tfar = INFINITY, .mask = ~0u};
    rp_occluded1(scene, &miss);
    check(miss.tfar == INFINITY, "a ray beside the quad is not occluded");
    rp_scene_release(scene);

    /* A scene file, loaded and rendered by the installed libraries. */
    for (int a = 1; a < argc; a++) {
        rp_scene_data data;
        char err[512];
        bool ok = rp_scene_data_load(argv[a], &data, err, sizeof err);
        if (!ok) printf("%s\n", err);
        check(ok && data.triangle_count > 0, "rp_scene_data_load");
        if (!ok) continue;
        rp_render_scene *rs = rp_render_scene_new(dev, &data, NULL, err, sizeof err);
        check(rs != NULL, "rp_render_scene_new");
        if (rs) {
            enum { W = 48, H = 48 };
            static float px[W * H * 3];
            rp_render_desc rd = {.width = W, .height = H, .integrator = RP_INTEGRATOR_EYELIGHT};
            check(rp_render(rs, &rd, px, NULL), "rp_render");
            int lit = 0;
            for (int i = 0; i < W * H * 3; i++) lit += px[i] > 0.0f && isfinite(px[i]);
            check(lit > W * H / 10, "the render shows the scene");
            printf("%s: %zu triangles, %d of %d channel values lit\n", argv[a], data.triangle_count, lit, W * H * 3);
            rp_render_scene_release(rs);
        }
        rp_scene_data_free(&data);
    }
    rp_device_release(dev);
    printf("%d passed, %d failed\n", passed, failed);
    return failed != 0;
}
