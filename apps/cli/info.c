/* `raypack info`: what a scene holds and what its acceleration structure looks like. */
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"

static void info_usage(FILE *out) {
    fprintf(out,
            "usage: raypack info [SCENE] [--threads N] [--accel bvh|kdtree|bih|grid] [--density F]\n"
            "\n"
            "Loads SCENE (the built-in room without one), builds its BVH and prints its primitives, bounds,\n"
            "materials, textures, lights, camera, and the BVH's nodes, depth, SAH cost and build time.\n"
            "\n"
            "options:\n"
            "  --threads N   load and build threads, 1..%d; 0 for all hardware threads [0]\n"
            "  --accel KIND  the triangles' structure: bvh, kdtree, bih or grid [bvh]\n"
            "  --density F   --accel grid: about F voxels per triangle (Cleary-Wyvill) [4]\n"
            "  --materials   list every material (else the first 16)\n"
            "  -h, --help    this help\n",
            CLI_MAX_THREADS);
}

static const char *material_type_name(rp_material_type t) {
    switch (t) {
    case RP_MATERIAL_DIFFUSE: return "diffuse";
    case RP_MATERIAL_PHONG: return "phong";
    case RP_MATERIAL_MIRROR: return "mirror";
    case RP_MATERIAL_DIELECTRIC: return "dielectric";
    }
    return "?";
}

int cli_info(int argc, char **argv) {
    const char *path = NULL;
    int threads = 0;
    bool all_materials = false;
    rp_accel_type accel = RP_ACCEL_BVH;
    float density = 0.0f;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            info_usage(stdout);
            return CLI_EXIT_OK;
        } else if (strcmp(a, "--threads") == 0) {
            const char *v = cli_flag_value("info", argc, argv, &i);
            if (!v || !cli_parse_int("info", a, v, 0, CLI_MAX_THREADS, &threads)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--accel") == 0) {
            const char *v = cli_flag_value("info", argc, argv, &i);
            if (!v || !cli_parse_accel("info", a, v, &accel)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--density") == 0) {
            const char *v = cli_flag_value("info", argc, argv, &i);
            if (!v || !cli_parse_float("info", a, v, 0.0, 1000.0, true, &density)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--materials") == 0) {
            all_materials = true;
        } else if (a[0] == '-' && a[1] != '\0') {
            fprintf(stderr, "raypack info: unknown option '%s' (see raypack info --help)\n", a);
            return CLI_EXIT_USAGE;
        } else if (!path) {
            path = a;
        } else {
            fprintf(stderr, "raypack info: expected one SCENE, got '%s' and '%s'\n", path, a);
            return CLI_EXIT_USAGE;
        }
    }

    double t0 = cli_now_ms();
    rp_scene_data d;
    memset(&d, 0, sizeof d);
    bool builtin = path == NULL;
    if (builtin) {
        if (!rp_default_scene(&d)) {
            fprintf(stderr, "raypack info: out of memory\n");
            return CLI_EXIT_FAILURE;
        }
    } else {
        /* stat, not open: opening a FIFO here would block, and the loader reads it once as a stream */
        if (!cli_scene_readable("info", path)) return CLI_EXIT_FAILURE;
        char err[512] = "";
        if (!rp_scene_data_load_ex(path, &(rp_scene_load_desc){.threads = threads, .warning = cli_load_warning}, &d, err, sizeof err)) {
            fprintf(stderr, "%s\n", err[0] ? err : "raypack info: cannot load the scene");
            return CLI_EXIT_FAILURE;
        }
    }
    double load_ms = cli_now_ms() - t0;

    int status = CLI_EXIT_FAILURE;
    rp_device *device = rp_device_new(&(rp_device_desc){.threads = threads});
    rp_render_scene *rs = NULL;
    if (!device) {
        fprintf(stderr, "raypack info: cannot create a device\n");
        goto done;
    }
    char err[512] = "";
    rp_render_scene_desc rdesc = {.accel = {.accel = accel, .grid_density = density}};
    rs = rp_render_scene_new(device, &d, &rdesc, err, sizeof err);
    if (!rs) {
        fprintf(stderr, "raypack info: %s\n", err);
        goto done;
    }
    rp_scene *scene = rp_render_scene_core(rs);
    rp_scene_stats st;
    rp_scene_get_stats(scene, &st);
    rp_bounds b;
    rp_scene_get_bounds(scene, &b);

    printf("scene       %s\n", builtin ? "(built-in room)" : path);
    printf("file        %zu bytes parsed in %.1f ms (load %.1f ms)\n", d.file_bytes, d.parse_ms, load_ms);
    printf("primitives  %zu triangles (%llu valid, %llu rejected, %llu degenerate), %zu spheres, %zu cones\n",
           d.triangle_count, (unsigned long long)st.triangles, (unsigned long long)st.rejected_prims,
           (unsigned long long)st.degenerate_prims, d.sphere_count, d.cone_count);
    printf("vertices    %zu positions, %zu normals, %zu texcoords%s\n", d.vertex_count, d.normal_count, d.texcoord_count,
           d.colors || d.sphere_colors ? ", colours" : "");
    printf("bounds      (%g, %g, %g) - (%g, %g, %g)\n", b.lower_x, b.lower_y, b.lower_z, b.upper_x, b.upper_y,
           b.upper_z);
    printf("materials   %zu\n", d.material_count);
    size_t shown = all_materials ? d.material_count : (d.material_count < 16 ? d.material_count : 16);
    for (size_t i = 0; i < shown; i++) {
        const rp_material_data *m = &d.materials[i];
        const rp_material *rm = rp_render_scene_material(rs, i);
        printf("  %-3zu %-24s %-10s kd (%.2f %.2f %.2f) ks (%.2f %.2f %.2f) ns %g kr (%.2f %.2f %.2f) "
               "kt (%.2f %.2f %.2f) ior %g%s",
               i, m->name[0] ? m->name : "-", material_type_name(rm->type), m->kd[0], m->kd[1], m->kd[2], m->ks[0],
               m->ks[1], m->ks[2], m->ns, m->kr[0], m->kr[1], m->kr[2], m->kt[0], m->kt[1], m->kt[2], m->ior,
               m->map_kd >= 0 ? " textured" : "");
        if (m->metal_rough)
            printf(" metallic %.2f roughness %.2f%s", m->metallic, m->roughness,
                   m->map_metal_rough ? " (times the metallic-roughness texture)" : "");
        if (rm->alpha_mode != RP_ALPHA_OPAQUE)
            printf(" alpha %s %.2f%s", rm->alpha_mode == RP_ALPHA_MASK ? "mask" : "blend", rm->alpha,
                   rm->alpha_texture >= 0 ? " (times its texture)" : "");
        if (rm->alpha_mode == RP_ALPHA_MASK) printf(" cutoff %.2f", rm->alpha_cutoff);
        printf("\n");
    }
    if (shown < d.material_count) printf("  ... %zu more (--materials lists all)\n", d.material_count - shown);
    printf("textures    %zu\n", d.texture_count);
    for (size_t i = 0; i < d.texture_count && i < 16; i++) {
        const rp_texture_data *t = &d.textures[i];
        static const char *const wraps[] = {"repeat", "clamp", "mirror"};
        /* the sampler, where it is not the default (repeat, bilinear) */
        char smp[64] = "";
        if (t->wrap_u != RP_TEXTURE_REPEAT || t->wrap_v != RP_TEXTURE_REPEAT)
            snprintf(smp, sizeof smp, ", %s %s", wraps[(unsigned)t->wrap_u % 3], wraps[(unsigned)t->wrap_v % 3]);
        if (t->filter == RP_TEXTURE_NEAREST) snprintf(smp + strlen(smp), sizeof smp - strlen(smp), ", nearest");
        printf("  %-3zu %s (%dx%d%s%s)\n", i, t->path, t->width, t->height, t->alpha ? ", alpha" : "", smp);
    }
    printf("lights      %zu%s\n", d.light_count, d.light_count ? "" : " (renders light the scene from the eye)");
    for (size_t i = 0; i < d.light_count && i < 16; i++) {
        const rp_light_data *l = &d.lights[i];
        if (l->type == RP_LIGHT_DATA_DIRECTIONAL)
            printf("  directional along (%g, %g, %g), irradiance (%g, %g, %g) (not in Whitted)\n", l->direction[0],
                   l->direction[1], l->direction[2], l->color[0], l->color[1], l->color[2]);
        else if (l->type == RP_LIGHT_DATA_SPOT)
            printf("  spot at (%g, %g, %g) along (%g, %g, %g), cone %g..%g degrees, colour (%g, %g, %g) (not in "
                   "Whitted)\n", l->position[0], l->position[1], l->position[2], l->direction[0], l->direction[1],
                   l->direction[2], acos(fmin(1.0, l->cos_inner)) * 180.0 / M_PI, acos(fmin(1.0, l->cos_outer)) * 180.0 / M_PI,
                   l->color[0], l->color[1], l->color[2]);
        else
            printf("  point at (%g, %g, %g), colour (%g, %g, %g)\n", l->position[0], l->position[1], l->position[2],
                   l->color[0], l->color[1], l->color[2]);
    }
    rp_bounds mb;
    if (d.volume && rp_render_scene_medium(rs, &mb)) {
        const rp_volume_data *v = d.volume;
        printf("volume      grid '%s': %llu active voxels in (%d, %d, %d) - (%d, %d, %d), %u of %u bricks of %d^3 "
               "stored, max density %g\n",
               v->grid_name, (unsigned long long)v->active_voxels, v->active_min[0], v->active_min[1], v->active_min[2],
               v->active_max[0], v->active_max[1], v->active_max[2], v->brick_count, v->dims[0] * v->dims[1] * v->dims[2],
               RP_VOLUME_BRICK, v->max_density);
        printf("            world box (%g, %g, %g) - (%g, %g, %g)\n", mb.lower_x, mb.lower_y, mb.lower_z, mb.upper_x,
               mb.upper_y, mb.upper_z);
    }
    rp_camera cam = rp_render_scene_default_camera(rs);
    printf("camera      %s: eye (%g, %g, %g) look (%g, %g, %g) up (%g, %g, %g) fov %g", d.camera.valid ? "file" : "framed",
           cam.pinhole.eye[0], cam.pinhole.eye[1], cam.pinhole.eye[2], cam.pinhole.look[0], cam.pinhole.look[1],
           cam.pinhole.look[2], cam.pinhole.up[0], cam.pinhole.up[1], cam.pinhole.up[2], cam.pinhole.fov_deg);
    if (d.camera.width > 0) printf(", %dx%d", d.camera.width, d.camera.height);
    printf("\n");
    if (d.has_background) printf("background  (%g, %g, %g)\n", d.background[0], d.background[1], d.background[2]);
    if (st.accel == RP_ACCEL_BVH) {
        printf("bvh         %llu binary nodes, %llu leaves, depth %u, SAH cost %.2f\n",
               (unsigned long long)st.binary_nodes, (unsigned long long)st.leaves, st.depth, st.sah_cost);
        printf("layout      %llu inner nodes of width %u, %.2f MiB\n", (unsigned long long)st.wide_nodes, st.bvh_width,
               (double)st.bytes / 1048576.0);
    } else if (st.accel == RP_ACCEL_GRID) {
        printf("grid        %llu voxels, %llu not empty, %llu triangle references (%.2f per triangle), %.2f MiB\n",
               (unsigned long long)st.binary_nodes, (unsigned long long)st.leaves, (unsigned long long)st.tri_refs,
               st.triangles ? (double)st.tri_refs / (double)st.triangles : 0.0, (double)st.bytes / 1048576.0);
    } else {
        printf("%-11s %llu nodes (%llu inner), %llu leaves, depth %u, %llu triangle references, SAH cost %.2f, %.2f MiB\n",
               rp_accel_name(st.accel), (unsigned long long)st.binary_nodes, (unsigned long long)st.wide_nodes,
               (unsigned long long)st.leaves, st.depth, (unsigned long long)st.tri_refs, st.sah_cost,
               (double)st.bytes / 1048576.0);
    }
    int nthreads = rp_device_thread_count(device);
    printf("build       %.1f ms on %d thread%s\n", st.build_ms, nthreads, nthreads == 1 ? "" : "s");
    status = CLI_EXIT_OK;

done:
    rp_render_scene_release(rs);
    if (device) rp_device_release(device);
    if (builtin) rp_default_scene_free(&d);
    else rp_scene_data_free(&d);
    return status;
}
