/* `raypack render SCENE --engine cuda`: the renderer with its rays traced on the GPU by the CUDA BVH
 * kernels (gpu/cuda), whose hits are the CPU's bit for bit.
 * - Eye light: the rays are rp_render's (rp_render_primary_rays), traced in one batch, and shaded as
 *   rp_render shades them (rp_render_eyelight).
 * - Whitted, path, direct, AO: the stream tracer (src/stream) with the GPU as its tracer
 *   (rp_cuda_trace): each depth's eye, shadow, reflection, refraction and bounce rays are a stream
 *   traced on the GPU in one batch, shaded on the CPU by the renderer's own shading.
 * Either way the image is the one `raypack render --anim-flat` writes with the same flags, byte for
 * byte. Every other flag is render's; --cuda-kernel picks the kernel and --cuda-emulate runs the
 * kernels' code on the CPU (no GPU needed: for checking). */
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
#include "cuda_tracer.h"
#include "stream/stream.h"

static const char *const CMD = "render";

/* The image of an integrator other than eye light: the stream tracer, its rays on the GPU. */
static bool render_stream(rp_render_scene *scene, const cli_render_setup *setup, rp_cuda_tracer *tracer,
                          const rp_camera *cam, int w, int h, float *pixels, stream_stats *st) {
    rp_render_desc rd = setup->desc;
    stream_desc sd = {.width = w, .height = h, .camera = cam, .render = &rd, .trace = rp_cuda_trace,
                      .trace_user = tracer};
    char err[512] = "";
    if (stream_render(scene, NULL, &sd, pixels, NULL, st, err, sizeof err)) return true;
    fprintf(stderr, "raypack %s: %s\n", CMD, err);
    return false;
}

/* The eye-light image: rp_render's primary rays, traced in one batch, shaded as rp_render does. */
static bool render_eyelight(rp_cuda_tracer *tracer, const rp_camera *cam, int w, int h, float *pixels) {
    size_t np = (size_t)w * (size_t)h;
    rp_ray *rays = malloc(np * sizeof *rays);
    rp_rayhit *rh = malloc(np * sizeof *rh);
    char err[512] = "";
    bool ok = rays && rh;
    if (!ok) {
        fprintf(stderr, "raypack %s: out of memory\n", CMD);
    } else {
        rp_render_primary_rays(cam, w, h, rays);
        for (size_t i = 0; i < np; i++)
            rh[i] = (rp_rayhit){.ray = rays[i],
                                .hit = {.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID}};
        if (!(ok = rp_cuda_trace(tracer, rh, np, false, err, sizeof err)))
            fprintf(stderr, "raypack %s: %s\n", CMD, err);
        for (size_t i = 0; ok && i < np; i++) {
            float c = rp_render_eyelight(&rh[i]);
            pixels[3 * i] = pixels[3 * i + 1] = pixels[3 * i + 2] = c;
        }
    }
    free(rh);
    free(rays);
    return ok;
}

int cli_cuda_render(int argc, char **argv) {
    /* render's own flags, less --engine cuda and the GPU's */
    char **args = malloc((size_t)argc * sizeof *args);
    if (!args) return CLI_EXIT_FAILURE;
    int n = 0;
    bool emulate = false;
    rp_cuda_kernel kernel = RP_CUDA_KERNEL_SIMPLE;
    for (int i = 0; i < argc; i++) {
        if (strcmp(argv[i], "--engine") == 0 && i + 1 < argc && strcmp(argv[i + 1], "cuda") == 0) {
            i++;
        } else if (strcmp(argv[i], "--cuda-emulate") == 0) {
            emulate = true;
        } else if (strcmp(argv[i], "--cuda-kernel") == 0) {
            bool known = false;
            for (int k = 0; i + 1 < argc && k < RP_CUDA_KERNEL_COUNT; k++)
                if (strcmp(argv[i + 1], rp_cuda_kernel_name((rp_cuda_kernel)k)) == 0) kernel = (rp_cuda_kernel)k, known = true;
            if (!known) {
                fprintf(stderr, "raypack %s: --cuda-kernel expects simple, persistent or speculative%s%s%s\n", CMD,
                        i + 1 < argc ? ", got '" : "", i + 1 < argc ? argv[i + 1] : "", i + 1 < argc ? "'" : "");
                free(args);
                return CLI_EXIT_USAGE;
            }
            i++;
        } else {
            args[n++] = argv[i];
        }
    }
    cli_render_setup setup;
    bool help = false;
    int rc = cli_render_parse(n, args, &setup, &help);
    free(args);
    if (rc != CLI_EXIT_OK || help) return rc;
    rp_integrator_type integ = setup.desc.integrator;
    bool eyelight = integ == RP_INTEGRATOR_EYELIGHT;
    if (!eyelight && integ != RP_INTEGRATOR_WHITTED && integ != RP_INTEGRATOR_PATH && integ != RP_INTEGRATOR_DIRECT &&
        integ != RP_INTEGRATOR_AO) {
        fprintf(stderr, "raypack %s: --engine cuda renders the eyelight, whitted, path, direct and ao integrators, not %s\n",
                CMD, setup.integrator_name);
        return CLI_EXIT_USAGE;
    }
    setup.scene_desc.flatten_animation = true; /* the GPU traces one level of triangles */
    rp_scene_data data;
    if (!cli_render_load(CMD, &setup, &data)) return CLI_EXIT_FAILURE;
    rc = cli_render_scene_flags(CMD, &setup, &data);
    rp_device *device = rc == CLI_EXIT_OK ? cli_device_new(CMD, setup.threads, setup.isa) : NULL;
    rp_render_scene *scene = NULL;
    rp_cuda_tracer *tracer = NULL;
    float *pixels = NULL;
    char err[512] = "";
    if (rc != CLI_EXIT_OK) goto done;
    rc = CLI_EXIT_FAILURE;
    if (!device) goto done;
    scene = rp_render_scene_new(device, &data, &setup.scene_desc, err, sizeof err);
    if (!scene) {
        fprintf(stderr, "raypack %s: %s\n", CMD, err);
        goto done;
    }
    if (!(tracer = rp_cuda_tracer_new(rp_render_scene_core(scene), kernel, emulate, err, sizeof err))) {
        fprintf(stderr, "raypack %s: --engine cuda: %s\n", CMD, err);
        goto done;
    }
    rp_camera cam = cli_render_camera(&setup, scene);
    int w, h;
    cli_render_size(&setup, &data, &w, &h);
    size_t np = (size_t)w * (size_t)h;
    if (!(pixels = malloc(np * 3 * sizeof *pixels))) {
        fprintf(stderr, "raypack %s: out of memory\n", CMD);
        goto done;
    }
    double t0 = cli_now_ms();
    stream_stats st = {0};
    /* cut-out surfaces: the stream tracer, which passes them on the CPU (alpha.c); eye light too, and
     * eye light of more than one sample a pixel (the stream's eyelight_samples) or through a medium
     * (composited there; the batch below shaded the bare surfaces: a different image) */
    if (!(eyelight && !cli_has_cutouts(&data) && setup.spp <= 1 && !data.volume ? render_eyelight(tracer, &cam, w, h, pixels)
                   : render_stream(scene, &setup, tracer, &cam, w, h, pixels, &st)))
        goto done;
    double frame_ms = cli_now_ms() - t0;
    const char *dot = strrchr(setup.output, '.');
    if (dot && (strcasecmp(dot, ".png") == 0 || strcasecmp(dot, ".ppm") == 0))
        rp_film_tonemap(pixels, np, 3, setup.exposure, setup.tonemap);
    if (!rp_image_write(setup.output, w, h, 3, pixels, err, sizeof err)) {
        fprintf(stderr, "raypack %s: %s\n", CMD, err);
        goto done;
    }
    if (!setup.quiet) {
        rp_cuda_tracer_stats ts = rp_cuda_tracer_get_stats(tracer);
        printf("image    %s: %dx%d, %s, %d spp, rays traced on %s\n", setup.output, w, h, setup.integrator_name,
               setup.spp > 0 ? setup.spp : 1, rp_cuda_tracer_device(tracer));
        printf("frame    %.1f ms: %llu rays in %llu batches, %.1f ms tracing (copies included), %.3f ms in the "
               "kernels (%.1f Mrays/s)\n",
               frame_ms, (unsigned long long)ts.rays, (unsigned long long)ts.batches, ts.total_ms, ts.kernel_ms,
               ts.kernel_ms > 0.0 ? (double)ts.rays / (ts.kernel_ms * 1e3) : 0.0);
        static const char *kinds[RP_RAY_KIND_COUNT] = {"primary", "shadow", "reflection", "refraction", "bounce"};
        for (int k = 0; !eyelight && k < RP_RAY_KIND_COUNT; k++)
            if (st.kind[k].rays)
                printf("rays     %-10s %llu (%llu %s)\n", kinds[k], (unsigned long long)st.kind[k].rays,
                       (unsigned long long)st.kind[k].hits, k == RP_RAY_SHADOW ? "blocked" : "hit");
    }
    rc = CLI_EXIT_OK;
done:
    free(pixels);
    rp_cuda_tracer_free(tracer);
    if (scene) rp_render_scene_release(scene);
    if (device) rp_device_release(device);
    cli_render_unload(&setup, &data);
    return rc;
}
#endif
