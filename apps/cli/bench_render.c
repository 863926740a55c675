/* `raypack bench --render`: frames of every integrator on the scenes given, timed as a user sees
 * them (rp_render, all of it: camera rays, traversal, shading, VPLs, the discontinuity buffer): ms a
 * frame, fps, samples/s and Mrays/s per ray kind. Frames advance sample_start, so each one traces
 * fresh samples (and fresh VPLs), as a progressive viewer would. */
#include "cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"

static const char *const CMD = "bench";

static void usage(FILE *out) {
    fprintf(out,
            "usage: raypack bench --render SCENE... [options]\n"
            "\n"
            "Times frames of each integrator on each scene and prints ms a frame, fps, samples/s and\n"
            "Mrays/s by ray kind (the whole frame's time, not the kernels' alone).\n"
            "\n"
            "options:\n"
            "  --integrators LIST     comma-separated: eyelight,whitted,direct,path,ao,ir [all]\n"
            "  --width W --height H   frame size [640x480]\n"
            "  --spp N                samples per pixel a frame [1]\n"
            "  --frames N             timed frames per integrator, after one warm-up frame [5]\n"
            "  --threads N            worker threads; 0 for all hardware threads [0]\n"
            "  --ir-interleave N --ir-vpls N --ir-filter N\n"
            "                         instant radiosity's settings [5, 16, 3: the issue's goal]\n"
            "  -h, --help             this help\n");
}

static const struct {
    const char *name;
    rp_integrator_type type;
} INTEGRATORS[] = {{"eyelight", RP_INTEGRATOR_EYELIGHT}, {"whitted", RP_INTEGRATOR_WHITTED},
                   {"direct", RP_INTEGRATOR_DIRECT},     {"path", RP_INTEGRATOR_PATH},
                   {"ao", RP_INTEGRATOR_AO},             {"ir", RP_INTEGRATOR_IR}};
enum { N_INTEGRATORS = sizeof INTEGRATORS / sizeof INTEGRATORS[0] };

int cli_bench_render(int argc, char **argv) {
    int w = 640, h = 480, spp = 1, frames = 5, threads = 0, inter = 0, vpls = 0, filter = 0;
    bool use[N_INTEGRATORS];
    for (int k = 0; k < N_INTEGRATORS; k++) use[k] = true;
    const char *scenes[64];
    int nscenes = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = NULL;
#define VALUE()                                                                \
    do {                                                                       \
        if (!(v = cli_flag_value(CMD, argc, argv, &i))) return CLI_EXIT_USAGE; \
    } while (0)
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            usage(stdout);
            return CLI_EXIT_OK;
        } else if (strcmp(a, "--integrators") == 0) {
            VALUE();
            for (int k = 0; k < N_INTEGRATORS; k++) use[k] = false;
            char list[256];
            snprintf(list, sizeof list, "%s", v);
            for (char *tok = strtok(list, ","); tok; tok = strtok(NULL, ",")) {
                bool found = false;
                for (int k = 0; k < N_INTEGRATORS; k++)
                    if (strcmp(tok, INTEGRATORS[k].name) == 0) use[k] = found = true;
                if (!found) {
                    fprintf(stderr, "raypack bench: --integrators: unknown integrator '%s'\n", tok);
                    return CLI_EXIT_USAGE;
                }
            }
        } else if (strcmp(a, "--width") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 8192, &w)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--height") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 8192, &h)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--spp") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 4096, &spp)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--frames") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 10000, &frames)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--threads") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 0, CLI_MAX_THREADS, &threads)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--ir-interleave") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 16, &inter)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--ir-vpls") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 4096, &vpls)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--ir-filter") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 31, &filter)) return CLI_EXIT_USAGE;
        } else if (a[0] == '-') {
            fprintf(stderr, "raypack bench: unknown option '%s' for --render (see raypack bench --render --help)\n", a);
            return CLI_EXIT_USAGE;
        } else if (nscenes < 64) {
            scenes[nscenes++] = a;
        }
#undef VALUE
    }
    if (!nscenes) {
        fprintf(stderr, "raypack bench --render: expected at least one SCENE\n");
        return CLI_EXIT_USAGE;
    }
    rp_device *dev = cli_device_new(CMD, threads, 0);
    if (!dev) return CLI_EXIT_FAILURE;
    float *px = malloc((size_t)w * (size_t)h * 3 * sizeof(float));
    int status = px ? CLI_EXIT_OK : CLI_EXIT_FAILURE;
    printf("%-22s %-9s %10s %8s %12s %9s %9s %9s %9s %9s\n", "scene", "integr.", "ms/frame", "fps", "Msamples/s",
           "Mrays/s", "primary", "shadow", "bounce", "refl+refr");
    for (int si = 0; px && si < nscenes; si++) {
        rp_scene_data data;
        char err[512] = "";
        if (!rp_scene_data_load(scenes[si], &data, err, sizeof err)) {
            fprintf(stderr, "%s\n", err);
            status = CLI_EXIT_FAILURE;
            continue;
        }
        rp_render_scene *scene = rp_render_scene_new(dev, &data, NULL, err, sizeof err);
        if (!scene) {
            fprintf(stderr, "raypack bench: %s\n", err);
            rp_scene_data_free(&data);
            status = CLI_EXIT_FAILURE;
            continue;
        }
        const char *base = strrchr(scenes[si], '/');
        base = base ? base + 1 : scenes[si];
        for (int k = 0; k < N_INTEGRATORS; k++) {
            if (!use[k]) continue;
            rp_render_desc d = {.width = w, .height = h, .spp = spp, .integrator = INTEGRATORS[k].type,
                                .ir = {.interleave = inter, .vpls = vpls, .filter = filter}};
            rp_render_stats st;
            double ms = 0.0;
            uint64_t rays[RP_RAY_KIND_COUNT] = {0};
            bool ok = rp_render(scene, &d, px, &st); /* warm-up */
            for (int fr = 0; ok && fr < frames; fr++) {
                d.sample_start = (fr + 1) * spp;
                ok = rp_render(scene, &d, px, &st);
                ms += st.render_ms;
                for (int r = 0; r < RP_RAY_KIND_COUNT; r++) rays[r] += st.rays[r];
            }
            if (!ok) {
                fprintf(stderr, "raypack bench: rendering failed\n");
                status = CLI_EXIT_FAILURE;
                break;
            }
            double per = ms / frames, s = ms * 1e-3, total = 0;
            for (int r = 0; r < RP_RAY_KIND_COUNT; r++) total += (double)rays[r];
            printf("%-22.22s %-9s %10.1f %8.2f %12.3f %9.2f %9.2f %9.2f %9.2f %9.2f\n", base, INTEGRATORS[k].name, per,
                   1e3 / per, (double)w * h * spp * frames / s * 1e-6, total / s * 1e-6,
                   (double)rays[RP_RAY_PRIMARY] / s * 1e-6, (double)rays[RP_RAY_SHADOW] / s * 1e-6,
                   (double)rays[RP_RAY_BOUNCE] / s * 1e-6,
                   (double)(rays[RP_RAY_REFLECTION] + rays[RP_RAY_REFRACTION]) / s * 1e-6);
        }
        rp_render_scene_release(scene);
        rp_scene_data_free(&data);
    }
    printf("(%d threads, %dx%d, %d spp a frame, %d frames; Mrays/s by kind: that kind's rays over the whole frame time)\n",
           rp_device_thread_count(dev), w, h, spp, frames);
    free(px);
    rp_device_release(dev);
    return status;
}
