/* `raypack bench --render`: frames of every integrator on the scenes given, timed as a user sees
 * them (rp_render, all of it: camera rays, traversal, shading, VPLs, the discontinuity buffer): ms a
 * frame, fps, samples/s and Mrays/s per ray kind. Frames advance sample_start, so each one traces
 * fresh samples (and fresh VPLs), as a progressive viewer would. */
#include "cli.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"

static const char *const CMD = "bench";

static void usage(FILE *out) {
    fprintf(out,
            "usage: raypack bench --render SCENE... [options]\n"
            "\n"
            "Times frames of each integrator on each scene and prints ms a frame, fps, samples/s and\n"
            "Mrays/s by ray kind (the whole frame's time, not the kernels' alone), and the process's CPU\n"
            "time a frame (all threads).\n"
            "\n"
            "options:\n"
            "  --integrators LIST     comma-separated: eyelight,whitted,direct,path,ao,ir [all]\n"
            "  --width W --height H   frame size [640x480]\n"
            "  --spp N                samples per pixel a frame [1]\n"
            "  --frames N             timed frames per integrator, after one warm-up frame [5]\n"
            "  --threads N            worker threads; 0 for all hardware threads [0]\n"
            "  --isa NAME             raypack's kernels: auto, scalar, sse, avx2 or avx512 [auto]\n"
            "  --ir-interleave N --ir-vpls N --ir-filter N --ir-rr X (0: off)\n"
            "                         instant radiosity's settings [5, 16, 3: the issue's goal]\n"
            "  --eye X,Y,Z --look X,Y,Z --fov DEG\n"
            "                         camera (each replaces that part of the scene's)\n"
            "  --anim-flat            an animated scene as one flat structure (refitted each frame)\n"
            "                         instead of instances under a top level\n"
            "  --kernels              also time the frame's primary rays alone in the kernel\n"
            "                         (rp_intersect_n, 16x16 packets, auto traversal, primary frustum:\n"
            "                         raypack bench's n16_auto_frustum), taking turns with the frames,\n"
            "                         both in the process's CPU time (which other load does not\n"
            "                         inflate), every frame sample 0 (pixel centres, the kernel's\n"
            "                         rays); prints frame CPU ms, kernel CPU ms, kernel/frame\n"
            "  -h, --help             this help\n");
}

/* CPU time of the process in ms (all its threads). */
static double cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* The primary rays of a w x h frame through pixel centres (DESIGN.md's camera), as 16x16 packets of
 * screen tiles in rp_packet_n_index order: directions, 3 * 256 floats a packet. */
static float *kernel_rays(const rp_camera *cam, int w, int h, size_t *packets) {
    const rp_pinhole_camera *c = &cam->pinhole;
    float f[3], r[3], u[3], len;
    for (int k = 0; k < 3; k++) f[k] = c->look[k] - c->eye[k];
    len = sqrtf(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    for (int k = 0; k < 3; k++) f[k] /= len;
    r[0] = f[1] * c->up[2] - f[2] * c->up[1], r[1] = f[2] * c->up[0] - f[0] * c->up[2], r[2] = f[0] * c->up[1] - f[1] * c->up[0];
    len = sqrtf(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    for (int k = 0; k < 3; k++) r[k] /= len;
    u[0] = r[1] * f[2] - r[2] * f[1], u[1] = r[2] * f[0] - r[0] * f[2], u[2] = r[0] * f[1] - r[1] * f[0];
    float th = tanf(c->fov_deg * 0.5f * 3.14159265f / 180.0f), aspect = (float)w / (float)h;
    size_t px = (size_t)(w + 15) / 16, py = (size_t)(h + 15) / 16;
    float *d = malloc(px * py * 3 * 256 * sizeof *d);
    if (!d) return NULL;
    for (size_t p = 0; p < px * py; p++)
        for (uint32_t j = 0; j < 16; j++)
            for (uint32_t i = 0; i < 16; i++) {
                float x = (float)((p % px) * 16 + i) + 0.5f, y = (float)((p / px) * 16 + j) + 0.5f;
                float a = (2.0f * x / (float)w - 1.0f) * th * aspect, b = (1.0f - 2.0f * y / (float)h) * th;
                float v[3] = {f[0] + a * r[0] + b * u[0], f[1] + a * r[1] + b * u[1], f[2] + a * r[2] + b * u[2]};
                float l = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
                uint32_t q = rp_packet_n_index(16, i, j);
                for (int k = 0; k < 3; k++) d[p * 768 + (size_t)k * 256 + q] = v[k] / l;
            }
    *packets = px * py;
    return d;
}

/* One pass of the kernel over those rays (copied into one packet a call, as the bench does). */
static void kernel_pass(rp_scene *scene, const rp_camera *cam, const float *d, size_t packets, rp_rayhit_n *pk) {
    rp_auto_tally tally;
    memset(&tally, 0, sizeof tally);
    rp_query_n_desc qd = {.traversal = RP_TRAVERSAL_AUTO, .frustum = RP_FRUSTUM_PRIMARY, .tally = &tally};
    for (size_t p = 0; p < packets; p++) {
        memcpy(pk->dir_x, d + p * 768, 256 * sizeof(float));
        memcpy(pk->dir_y, d + p * 768 + 256, 256 * sizeof(float));
        memcpy(pk->dir_z, d + p * 768 + 512, 256 * sizeof(float));
        for (uint32_t q = 0; q < 256; q++) {
            pk->org_x[q] = cam->pinhole.eye[0], pk->org_y[q] = cam->pinhole.eye[1], pk->org_z[q] = cam->pinhole.eye[2];
            pk->tnear[q] = 0.0f, pk->tfar[q] = INFINITY, pk->geom_id[q] = RP_INVALID_ID;
        }
        rp_intersect_n(scene, &qd, pk);
    }
}

static const struct {
    const char *name;
    rp_integrator_type type;
} INTEGRATORS[] = {{"eyelight", RP_INTEGRATOR_EYELIGHT}, {"whitted", RP_INTEGRATOR_WHITTED},
                   {"direct", RP_INTEGRATOR_DIRECT},     {"path", RP_INTEGRATOR_PATH},
                   {"ao", RP_INTEGRATOR_AO},             {"ir", RP_INTEGRATOR_IR}};
enum { N_INTEGRATORS = sizeof INTEGRATORS / sizeof INTEGRATORS[0] };

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

int cli_bench_render(int argc, char **argv) {
    int w = 640, h = 480, spp = 1, frames = 5, threads = 0, inter = 0, vpls = 0, filter = 0;
    float rr = 0.0f;
    int isa = 0; /* auto */
    bool kernels = false, anim_flat = false, has_eye = false, has_look = false, has_fov = false;
    float eye[3], look[3], fov = 0.0f;
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
        } else if (strcmp(a, "--ir-rr") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 16.0, false, &rr)) return CLI_EXIT_USAGE;
            if (rr == 0.0f) rr = -1.0f;
        } else if (strcmp(a, "--isa") == 0) {
            VALUE();
            if (!cli_parse_isa(CMD, a, v, &isa)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--kernels") == 0) {
            kernels = true;
        } else if (strcmp(a, "--anim-flat") == 0) {
            anim_flat = true;
        } else if (strcmp(a, "--eye") == 0 || strcmp(a, "--look") == 0) {
            VALUE();
            bool e = a[2] == 'e';
            if (!cli_parse_vec3(CMD, a, v, e ? eye : look)) return CLI_EXIT_USAGE;
            *(e ? &has_eye : &has_look) = true;
        } else if (strcmp(a, "--fov") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 180.0, true, &fov)) return CLI_EXIT_USAGE;
            has_fov = true;
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
    int cam_status = cli_camera_flags_check(CMD, has_eye ? eye : NULL, has_look ? look : NULL, NULL);
    if (cam_status != CLI_EXIT_OK) return cam_status;
    rp_device *dev = cli_device_new(CMD, threads, isa);
    if (!dev) return CLI_EXIT_FAILURE;
    float *px = malloc((size_t)w * (size_t)h * 3 * sizeof(float));
    int status = px ? CLI_EXIT_OK : CLI_EXIT_FAILURE;
    printf("%-22s %-9s %10s %8s %12s %9s %9s %9s %9s %9s %9s\n", "scene", "integr.", "ms/frame", "fps", "Msamples/s",
           "Mrays/s", "primary", "shadow", "bounce", "refl+refr", "CPU ms");
    for (int si = 0; px && si < nscenes; si++) {
        rp_scene_data data;
        char err[512] = "";
        if (!rp_scene_data_load(scenes[si], &data, err, sizeof err)) {
            fprintf(stderr, "%s\n", err);
            status = CLI_EXIT_FAILURE;
            continue;
        }
        rp_render_scene *scene = rp_render_scene_new(dev, &data, &(rp_render_scene_desc){.flatten_animation = anim_flat},
                                                     err, sizeof err);
        if (!scene) {
            fprintf(stderr, "raypack bench: %s\n", err);
            rp_scene_data_free(&data);
            status = CLI_EXIT_FAILURE;
            continue;
        }
        const char *base = strrchr(scenes[si], '/');
        base = base ? base + 1 : scenes[si];
        rp_camera cam = rp_render_scene_default_camera(scene);
        for (int k = 0; k < 3; k++) {
            if (has_eye) cam.pinhole.eye[k] = eye[k];
            if (has_look) cam.pinhole.look[k] = look[k];
        }
        if (has_fov) cam.pinhole.fov_deg = fov;
        if (cam.type == RP_CAMERA_PINHOLE && cli_camera_check(CMD, scenes[si], cam.pinhole.eye, cam.pinhole.look,
                                                              cam.pinhole.up, has_eye, has_look, false) != CLI_EXIT_OK) {
            rp_render_scene_release(scene);
            rp_scene_data_free(&data);
            status = CLI_EXIT_FAILURE;
            continue;
        }
        if (!cli_scene_in_reach(CMD, scenes[si], scene, &cam)) {
            rp_render_scene_release(scene);
            rp_scene_data_free(&data);
            status = CLI_EXIT_FAILURE;
            continue;
        }
        size_t packets = 0;
        float *krays = kernels ? kernel_rays(&cam, w, h, &packets) : NULL;
        rp_rayhit_n pk = {0};
        if (kernels && (!krays || !rp_rayhit_n_alloc(dev, 16, &pk))) {
            fprintf(stderr, "raypack bench: out of memory\n");
            status = CLI_EXIT_FAILURE;
            free(krays);
            krays = NULL;
        }
        for (int k = 0; k < N_INTEGRATORS; k++) {
            if (!use[k]) continue;
            rp_render_desc d = {.width = w, .height = h, .spp = spp, .integrator = INTEGRATORS[k].type,
                                .ir = {.interleave = inter, .vpls = vpls, .filter = filter, .rr = rr}, .camera = &cam};
            rp_render_stats st;
            double ms = 0.0, cpu = 0.0, cpu_frame[64], cpu_kernel[64];
            uint64_t rays[RP_RAY_KIND_COUNT] = {0};
            bool ok = rp_render(scene, &d, px, &st); /* warm-up */
            if (ok && krays) kernel_pass(rp_render_scene_core(scene), &cam, krays, packets, &pk);
            for (int fr = 0; ok && fr < frames; fr++) {
                d.sample_start = krays ? 0 : (fr + 1) * spp; /* --kernels: the kernel's rays, pixel centres */
                double c0 = cpu_ms();
                ok = rp_render(scene, &d, px, &st);
                double c1 = cpu_ms();
                ms += st.render_ms;
                cpu += c1 - c0;
                for (int r = 0; r < RP_RAY_KIND_COUNT; r++) rays[r] += st.rays[r];
                if (krays && fr < 64) {
                    kernel_pass(rp_render_scene_core(scene), &cam, krays, packets, &pk);
                    cpu_frame[fr] = c1 - c0;
                    cpu_kernel[fr] = cpu_ms() - c1;
                }
            }
            if (!ok) {
                fprintf(stderr, "raypack bench: rendering failed\n");
                status = CLI_EXIT_FAILURE;
                break;
            }
            double per = ms / frames, s = ms * 1e-3, total = 0;
            for (int r = 0; r < RP_RAY_KIND_COUNT; r++) total += (double)rays[r];
            printf("%-22.22s %-9s %10.1f %8.2f %12.3f %9.2f %9.2f %9.2f %9.2f %9.2f %9.1f\n", base, INTEGRATORS[k].name, per,
                   1e3 / per, (double)w * h * spp * frames / s * 1e-6, total / s * 1e-6,
                   (double)rays[RP_RAY_PRIMARY] / s * 1e-6, (double)rays[RP_RAY_SHADOW] / s * 1e-6,
                   (double)rays[RP_RAY_BOUNCE] / s * 1e-6,
                   (double)(rays[RP_RAY_REFLECTION] + rays[RP_RAY_REFRACTION]) / s * 1e-6, cpu / frames);
            if (krays) {
                int n = frames < 64 ? frames : 64;
                qsort(cpu_frame, (size_t)n, sizeof(double), cmp_double);
                qsort(cpu_kernel, (size_t)n, sizeof(double), cmp_double);
                double fm = cpu_frame[n / 2], km = cpu_kernel[n / 2];
                printf("%-22s %-9s frame %.1f CPU ms, its %zu primary rays in the kernel alone %.1f CPU ms "
                       "(medians of %d, taking turns): kernel/frame %.3f\n",
                       "", "", fm, packets * 256, km, n, fm > 0.0 ? km / fm : 0.0);
            }
        }
        if (pk.n) rp_rayhit_n_free(dev, &pk);
        free(krays);
        rp_render_scene_release(scene);
        rp_scene_data_free(&data);
    }
    printf("(%d threads, %s kernels, %dx%d, %d spp a frame, %d frames; Mrays/s by kind: that kind's rays over the whole frame time;\n"
           " CPU ms: the process's CPU time a frame, all threads, which the machine's other load does not inflate)\n",
           rp_device_thread_count(dev), cli_isa_name(rp_device_isa(dev)), w, h, spp, frames);
    free(px);
    rp_device_release(dev);
    return status;
}
