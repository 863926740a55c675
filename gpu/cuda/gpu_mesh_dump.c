/* gpu_mesh_dump SCENE OUT [--eye x,y,z --look x,y,z --up x,y,z --fov deg]: writes a scene's
 * triangles, its camera (the flags, else the file's, else a view of the whole box) and its first
 * point light (else a point above the box) as a cuda_mesh.h file for the GPU programs. Spheres and
 * cones are left out (counted on stderr): the GPU traces triangles. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cuda_mesh.h"
#include "raypack_io.h"

static bool vec3_arg(const char *s, float v[3]) { return sscanf(s, "%f,%f,%f", &v[0], &v[1], &v[2]) == 3; }

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: gpu_mesh_dump SCENE OUT [--eye x,y,z --look x,y,z --up x,y,z --fov deg]\n");
        return 2;
    }
    rp_scene_data d;
    char err[512];
    if (!rp_scene_data_load(argv[1], &d, err, sizeof err)) {
        fprintf(stderr, "gpu_mesh_dump: %s\n", err);
        return 1;
    }
    cuda_mesh m = {.vertex_count = d.vertex_count, .triangle_count = d.triangle_count,
                   .positions = d.positions, .indices = d.indices};
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < d.vertex_count; i++)
        for (int a = 0; a < 3; a++) {
            float x = d.positions[3 * i + a];
            if (!isfinite(x)) continue;
            lo[a] = fminf(lo[a], x), hi[a] = fmaxf(hi[a], x);
        }
    float c[3], ext = 0.0f;
    for (int a = 0; a < 3; a++) c[a] = 0.5f * (lo[a] + hi[a]), ext = fmaxf(ext, hi[a] - lo[a]);
    if (d.camera.valid) {
        memcpy(m.eye, d.camera.eye, 12), memcpy(m.look, d.camera.look, 12), memcpy(m.up, d.camera.up, 12);
        m.fov_deg = d.camera.fov_deg;
    } else {
        float off[3] = {0.35f, 0.45f, 1.2f};
        for (int a = 0; a < 3; a++) m.eye[a] = c[a] + off[a] * ext, m.look[a] = c[a], m.up[a] = a == 1;
        m.fov_deg = 50.0f;
    }
    for (int a = 0; a < 3; a++) m.light[a] = c[a] + (a == 1 ? 0.45f * (hi[1] - lo[1]) : 0.0f);
    for (size_t i = 0; i < d.light_count; i++)
        if (d.lights[i].type == RP_LIGHT_DATA_POINT) {
            memcpy(m.light, d.lights[i].position, 12);
            break;
        }
    for (int i = 3; i + 1 < argc; i += 2) {
        bool ok = strcmp(argv[i], "--eye") == 0   ? vec3_arg(argv[i + 1], m.eye)
                  : strcmp(argv[i], "--look") == 0 ? vec3_arg(argv[i + 1], m.look)
                  : strcmp(argv[i], "--up") == 0   ? vec3_arg(argv[i + 1], m.up)
                  : strcmp(argv[i], "--fov") == 0  ? sscanf(argv[i + 1], "%f", &m.fov_deg) == 1
                                                   : false;
        if (!ok) {
            fprintf(stderr, "gpu_mesh_dump: bad option %s %s\n", argv[i], argv[i + 1]);
            rp_scene_data_free(&d);
            return 2;
        }
    }
    if (d.sphere_count || d.cone_count)
        fprintf(stderr, "gpu_mesh_dump: %s: %zu spheres and %zu cones left out (the GPU traces triangles)\n", argv[1],
                d.sphere_count, d.cone_count);
    bool ok = cuda_mesh_write(argv[2], &m);
    if (!ok) fprintf(stderr, "gpu_mesh_dump: cannot write %s\n", argv[2]);
    else
        printf("%s: %zu triangles -> %s\n", argv[1], d.triangle_count, argv[2]);
    rp_scene_data_free(&d);
    return ok ? 0 : 1;
}
