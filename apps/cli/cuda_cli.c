/* `raypack render SCENE --engine cuda`: the eye-light image with its primary rays traced on the GPU
 * by the CUDA BVH kernels (gpu/cuda). The rays are rp_render's (rp_render_primary_rays), the hits
 * the CPU's bit for bit, and the shading rp_render's (rp_render_eyelight), so the image is the one
 * `raypack render --integrator eyelight` writes, byte for byte. Every other flag is render's. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "cli.h"

#if !defined(RP_HAVE_CUDA)
int cli_cuda_render(int argc, char **argv) {
    (void)argc, (void)argv;
    fprintf(stderr, "raypack render: --engine cuda: raypack was built without CUDA (nvcc not found)\n");
    return CLI_EXIT_USAGE;
}
#else
#include "cuda_bvh.h"

static const char *const CMD = "render";

/* The GPU's part: the layout, the rays, the kernel; false after a message. */
static bool trace_on_gpu(rp_scene *core, const rp_ray *rays, size_t n, rp_cuda_bvh_hit *hits, float *ms,
                         char *device, size_t device_size) {
    char err[512] = "";
    rp_cuda_bvh_src src;
    if (!rp_cuda_bvh_src_from_scene(core, &src, err, sizeof err)) {
        fprintf(stderr, "raypack %s: %s\n", CMD, err);
        return false;
    }
    bool ok = false;
    rp_cuda_bvh *gpu = NULL;
    rp_cuda_batch *batch = NULL;
    rp_cuda_bvh_ray *gr = malloc((n ? n : 1) * sizeof *gr);
    if (src.skipped) {
        fprintf(stderr,
                "raypack %s: --engine cuda: the scene has %zu spheres, cones, instances or user primitives; the GPU "
                "traces triangles only (an animated scene: --anim-flat)\n",
                CMD, src.skipped);
    } else if (!rp_cuda_device_info(device, device_size)) {
        fprintf(stderr, "raypack %s: --engine cuda: no CUDA device found\n", CMD);
    } else if (!gr) {
        fprintf(stderr, "raypack %s: out of memory\n", CMD);
    } else {
        for (size_t i = 0; i < n; i++) {
            const rp_ray *r = &rays[i];
            gr[i] = (rp_cuda_bvh_ray){{r->org_x, r->org_y, r->org_z}, r->tnear, {r->dir_x, r->dir_y, r->dir_z}, r->tfar};
        }
        ok = (gpu = rp_cuda_bvh_upload(&src, err, sizeof err)) && (batch = rp_cuda_batch_new(gr, n, err, sizeof err)) &&
             rp_cuda_bvh_trace(gpu, batch, RP_CUDA_KERNEL_SIMPLE, false, ms, err, sizeof err) &&
             rp_cuda_batch_hits(batch, hits, err, sizeof err);
        if (!ok) fprintf(stderr, "raypack %s: %s\n", CMD, err);
    }
    free(gr);
    rp_cuda_batch_free(batch);
    rp_cuda_bvh_free(gpu);
    rp_cuda_bvh_src_free(&src);
    return ok;
}

int cli_cuda_render(int argc, char **argv) {
    /* render's own flags, less --engine cuda */
    char **args = malloc((size_t)argc * sizeof *args);
    if (!args) return CLI_EXIT_FAILURE;
    int n = 0;
    for (int i = 0; i < argc; i++) {
        if (strcmp(argv[i], "--engine") == 0 && i + 1 < argc && strcmp(argv[i + 1], "cuda") == 0) {
            i++;
            continue;
        }
        args[n++] = argv[i];
    }
    cli_render_setup setup;
    bool help = false;
    int rc = cli_render_parse(n, args, &setup, &help);
    free(args);
    if (rc != CLI_EXIT_OK || help) return rc;
    if (setup.desc.integrator != RP_INTEGRATOR_EYELIGHT || setup.spp > 1) {
        fprintf(stderr, "raypack %s: --engine cuda renders the eye-light integrator at 1 spp (--integrator eyelight)\n",
                CMD);
        return CLI_EXIT_USAGE;
    }
    rp_scene_data data;
    if (!cli_render_load(CMD, &setup, &data)) return CLI_EXIT_FAILURE;
    rc = cli_render_scene_flags(CMD, &setup, &data);
    rp_device *device = rc == CLI_EXIT_OK ? cli_device_new(CMD, setup.threads, setup.isa) : NULL;
    rp_render_scene *scene = NULL;
    rp_ray *rays = NULL;
    rp_cuda_bvh_hit *hits = NULL;
    float *pixels = NULL;
    char err[512] = "", gpu_name[256] = "";
    if (rc != CLI_EXIT_OK) goto done;
    rc = CLI_EXIT_FAILURE;
    if (!device) goto done;
    scene = rp_render_scene_new(device, &data, &setup.scene_desc, err, sizeof err);
    if (!scene) {
        fprintf(stderr, "raypack %s: %s\n", CMD, err);
        goto done;
    }
    rp_camera cam = cli_render_camera(&setup, scene);
    int w, h;
    cli_render_size(&setup, &data, &w, &h);
    size_t np = (size_t)w * (size_t)h;
    rays = malloc(np * sizeof *rays);
    hits = malloc(np * sizeof *hits);
    pixels = malloc(np * 3 * sizeof *pixels);
    if (!rays || !hits || !pixels) {
        fprintf(stderr, "raypack %s: out of memory\n", CMD);
        goto done;
    }
    rp_render_primary_rays(&cam, w, h, rays);
    float ms = 0.0f;
    if (!trace_on_gpu(rp_render_scene_core(scene), rays, np, hits, &ms, gpu_name, sizeof gpu_name)) goto done;
    for (size_t i = 0; i < np; i++) {
        rp_rayhit rh = {.ray = rays[i]};
        rh.ray.tfar = hits[i].t;
        rh.hit = (rp_hit){.Ng_x = hits[i].ng[0], .Ng_y = hits[i].ng[1], .Ng_z = hits[i].ng[2], .u = hits[i].u,
                          .v = hits[i].v, .prim_id = hits[i].prim, .geom_id = hits[i].geom, .inst_id = RP_INVALID_ID};
        float c = rp_render_eyelight(&rh);
        pixels[3 * i] = pixels[3 * i + 1] = pixels[3 * i + 2] = c;
    }
    const char *dot = strrchr(setup.output, '.');
    if (dot && (strcasecmp(dot, ".png") == 0 || strcasecmp(dot, ".ppm") == 0))
        rp_film_tonemap(pixels, np, 3, setup.exposure, setup.tonemap);
    if (!rp_image_write(setup.output, w, h, 3, pixels, err, sizeof err)) {
        fprintf(stderr, "raypack %s: %s\n", CMD, err);
        goto done;
    }
    if (!setup.quiet)
        printf("image    %s: %dx%d, eyelight, primary rays on %s: %.3f ms in the kernel (%.1f Mrays/s)\n",
               setup.output, w, h, gpu_name, (double)ms, ms > 0.0f ? (double)np / ((double)ms * 1e3) : 0.0);
    rc = CLI_EXIT_OK;
done:
    free(pixels);
    free(hits);
    free(rays);
    if (scene) rp_render_scene_release(scene);
    if (device) rp_device_release(device);
    cli_render_unload(&setup, &data);
    return rc;
}
#endif
