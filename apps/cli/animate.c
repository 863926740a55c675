/* `raypack animate`: render the frames of an animated scene (BART's AFF), updating the scene for
 * every frame (instance transforms, refits), and report per frame and for the whole animation what
 * BART asks for: the frames per second, updates included. */
#include "cli.h"

#include <errno.h>
#include <libgen.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

static const char *const CMD = "animate";

static void animate_usage(FILE *out) {
    fprintf(out,
            "usage: raypack animate SCENE [-o PATTERN] [--frames N | --fps F] [options of raypack render]\n"
            "\n"
            "Renders the animation of SCENE (a BART AFF scene: keyframed blocks, tpa triangles, the camera's\n"
            "path) frame by frame. Every frame first updates the scene to its time (instances of the\n"
            "keyframed blocks placed anew, tpa sub-scenes refitted, the top level rebuilt), then renders it.\n"
            "Prints each frame's update and render times and, at the end, the animation's frames per second\n"
            "with the updates included (BART's measure; writing the images is not counted).\n"
            "\n"
            "options:\n"
            "  -o, --output PATTERN   write frame i to PATTERN with one printf integer conversion,\n"
            "                         e.g. frames/%%04d.png (.png, .ppm, .pfm, .hdr, .exr); without\n"
            "                         -o nothing is written (a measurement)\n"
            "  --frames N             N frames spread evenly over the animation's time range, first\n"
            "                         and last included [the file's frame count, its `a` line]\n"
            "  --fps F                frames F per unit of scene time, from the start (instead of\n"
            "                         --frames)\n"
            "  --first I, --last I    render only frames I..I' of those (0-based, inclusive)\n"
            "  --anim-flat            one flat structure refitted every frame instead of instances\n"
            "  --anim-refit           the keyframed blocks' vertices moved and refitted every frame\n"
            "                         instead of their instance transforms set (what a refit costs)\n"
            "  --quiet                only the summary\n"
            "  -h, --help             this help\n"
            "Every other option is raypack render's (--width, --height, --threads, --integrator,\n"
            "--max-depth, --reflect-depth, --refract-depth, --lights, --spp, --accel, ...).\n"
            "Overbeck et al.'s fig. 1: --width 1024 --height 1024 --lights 0 --reflect-depth 1\n"
            "--refract-depth 4.\n"
            "\n"
            "exit status: 0 ok, 1 the scene could not be loaded or a frame written, 2 usage error\n");
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* True when pattern holds exactly one integer conversion (%d, %04d, ...) and no other, of a width
 * up to 2 digits (%999999999d made every frame's name a 4 KiB run of blanks, cut short). */
static bool pattern_ok(const char *p) {
    int conv = 0;
    for (; *p; p++) {
        if (*p != '%') continue;
        if (p[1] == '%') {
            p++;
            continue;
        }
        p++;
        const char *digits = p;
        while (*p >= '0' && *p <= '9') p++;
        if (*p != 'd' || p - digits > 2) return false;
        conv++;
    }
    return conv == 1;
}

int cli_animate(int argc, char **argv) {
    const char *pattern = NULL;
    int frames_wanted = 0, first = 0, last = -1;
    float fps = 0.0f;
    bool quiet = false;
    /* animate's own flags out, the rest to raypack render's parser */
    char **rest = malloc((size_t)(argc + 1) * sizeof *rest);
    if (!rest) return CLI_EXIT_FAILURE;
    int nrest = 0;
    rest[nrest++] = argv[0];
    int rc = CLI_EXIT_OK;
    for (int i = 1; i < argc && rc == CLI_EXIT_OK; i++) {
        const char *a = argv[i], *v;
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            animate_usage(stdout);
            free(rest);
            return CLI_EXIT_OK;
        } else if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) {
            if (!(v = cli_flag_value(CMD, argc, argv, &i))) rc = CLI_EXIT_USAGE;
            else pattern = v;
        } else if (strcmp(a, "--frames") == 0) {
            if (!(v = cli_flag_value(CMD, argc, argv, &i)) || !cli_parse_int(CMD, a, v, 1, 10000000, &frames_wanted))
                rc = CLI_EXIT_USAGE;
        } else if (strcmp(a, "--fps") == 0) {
            if (!(v = cli_flag_value(CMD, argc, argv, &i)) || !cli_parse_float(CMD, a, v, 0.0, 1e6, true, &fps))
                rc = CLI_EXIT_USAGE;
        } else if (strcmp(a, "--first") == 0 || strcmp(a, "--last") == 0) {
            if (!(v = cli_flag_value(CMD, argc, argv, &i)) ||
                !cli_parse_int(CMD, a, v, 0, 10000000, strcmp(a, "--first") == 0 ? &first : &last))
                rc = CLI_EXIT_USAGE;
        } else if (strcmp(a, "--quiet") == 0 || strcmp(a, "-q") == 0) {
            quiet = true;
        } else if (strcmp(a, "--anim-time") == 0 || strcmp(a, "--time") == 0 || strcmp(a, "--mpi") == 0 ||
                   strcmp(a, "--engine") == 0 || strcmp(a, "--aovs") == 0 || strcmp(a, "--stats-json") == 0) {
            fprintf(stderr, "raypack animate: %s is raypack render's, not animate's\n", a);
            rc = CLI_EXIT_USAGE;
        } else {
            rest[nrest++] = argv[i];
        }
    }
    rest[nrest] = NULL;
    if (rc == CLI_EXIT_OK && frames_wanted && fps > 0.0f) {
        fprintf(stderr, "raypack animate: --frames and --fps exclude each other\n");
        rc = CLI_EXIT_USAGE;
    }
    if (rc == CLI_EXIT_OK && pattern) {
        const char *dot = strrchr(pattern, '.');
        if (!pattern_ok(pattern)) {
            fprintf(stderr, "raypack animate: -o expects a pattern with one integer conversion (of width 99 at most) such as "
                            "frames/%%04d.png, got '%s'\n", pattern);
            rc = CLI_EXIT_USAGE;
        } else if (!dot || (strcasecmp(dot, ".png") != 0 && strcasecmp(dot, ".pfm") != 0 && strcasecmp(dot, ".ppm") != 0 &&
                            strcasecmp(dot, ".hdr") != 0 && strcasecmp(dot, ".exr") != 0)) {
            fprintf(stderr, "raypack animate: -o expects a pattern ending in .png, .pfm, .ppm, .hdr or .exr, got '%s'\n",
                    pattern);
            rc = CLI_EXIT_USAGE;
        }
    }
    cli_render_setup setup;
    bool help = false;
    if (rc == CLI_EXIT_OK) rc = cli_render_parse(nrest, rest, &setup, &help);
    free(rest);
    if (rc != CLI_EXIT_OK) return rc;
    if (help) {
        animate_usage(stdout);
        return CLI_EXIT_OK;
    }
    if (!setup.scene) {
        fprintf(stderr, "raypack animate: expected an animated SCENE (see raypack animate --help)\n");
        return CLI_EXIT_USAGE;
    }
    if (pattern) {
        /* the frames' folder must exist before hours of rendering */
        char probe[4096];
        snprintf(probe, sizeof probe, pattern, 0);
        char *copy = strdup(probe);
        struct stat st;
        const char *dir = copy ? dirname(copy) : ".";
        bool ok = stat(dir, &st) == 0 && S_ISDIR(st.st_mode);
        if (!ok) fprintf(stderr, "raypack animate: cannot write %s: folder %s does not exist\n", probe, dir);
        free(copy);
        if (!ok) return CLI_EXIT_FAILURE;
    }

    rp_scene_data data;
    if (!cli_render_load(CMD, &setup, &data)) return CLI_EXIT_FAILURE;
    int status = CLI_EXIT_FAILURE;
    rp_device *device = NULL;
    rp_render_scene *scene = NULL;
    float *pixels = NULL;
    double *upd = NULL, *ren = NULL;
    rc = cli_render_scene_flags(CMD, &setup, &data);
    if (rc != CLI_EXIT_OK) {
        status = rc;
        goto done;
    }
    const rp_animation_data *anim = data.animation;
    if (!anim) {
        fprintf(stderr, "raypack animate: %s is not animated (no AFF keyframes, tpa or camera path)\n", setup.scene);
        status = CLI_EXIT_USAGE;
        goto done;
    }
    int count = frames_wanted ? frames_wanted : anim->frames > 0 ? anim->frames : 1;
    if (fps > 0.0f) {
        double c = floor(((double)anim->end - anim->start) * fps + 1e-6) + 1.0;
        if (!(c <= 10000000.0)) {
            fprintf(stderr, "raypack animate: --fps %g makes %.3g frames (at most 10^7)\n", (double)fps, c);
            status = CLI_EXIT_USAGE;
            goto done;
        }
        count = (int)c;
    }
    if (last < 0 || last >= count) last = count - 1;
    if (first > last) {
        fprintf(stderr, "raypack animate: --first %d is past the last frame (%d)\n", first, last);
        status = CLI_EXIT_USAGE;
        goto done;
    }
    device = cli_device_new(CMD, setup.threads, setup.isa);
    if (!device) goto done;
    char err[512] = "";
    double b0 = cli_now_ms();
    scene = rp_render_scene_new(device, &data, &setup.scene_desc, err, sizeof err);
    if (!scene) {
        fprintf(stderr, "raypack animate: %s\n", err);
        goto done;
    }
    double build_ms = cli_now_ms() - b0;
    int w, h;
    cli_render_size(&setup, &data, &w, &h);
    if ((double)w * (double)h > 67108864.0) {
        fprintf(stderr, "raypack animate: %dx%d is too many pixels\n", w, h);
        status = CLI_EXIT_USAGE;
        goto done;
    }
    rp_render_desc desc = setup.desc;
    desc.width = w, desc.height = h;
    int channels = rp_render_channels(&desc);
    pixels = malloc((size_t)w * (size_t)h * (size_t)channels * sizeof(float));
    if (!pixels) {
        fprintf(stderr, "raypack animate: out of memory for a %dx%d image\n", w, h);
        goto done;
    }
    if (!quiet)
        printf("animate  %s: %d frames over [%g, %g] (frames %d..%d here), %dx%d, %s, %d threads, %s; build %.1f ms\n",
               setup.scene, count, (double)anim->start, (double)anim->end, first, last, w, h, setup.integrator_name,
               rp_device_thread_count(device), setup.scene_desc.flatten_animation ? "flat" : setup.scene_desc.refit_blocks ? "instanced, blocks refitted" : "instanced", build_ms);
    upd = malloc((size_t)(last - first + 1) * 2 * sizeof *upd);
    if (!upd) goto done;
    ren = upd + (last - first + 1);
    double sum_update = 0.0, sum_refit = 0.0, sum_top = 0.0, sum_render = 0.0, max_update = 0.0, sum_write = 0.0;
    double sum_cpu = 0.0;
    uint64_t rays = 0;
    int done_frames = 0;
    for (int i = first; i <= last; i++) {
        float t = fps > 0.0f ? anim->start + (float)((double)i / fps) : rp_anim_frame_time(anim, i, count);
        rp_render_update_stats us;
        double c0 = cli_cpu_ms();
        if (!rp_render_scene_set_time(scene, &data, t, &us)) {
            fprintf(stderr, "raypack animate: updating the scene to time %g failed\n", (double)t);
            goto done;
        }
        rp_camera cam = cli_render_camera(&setup, scene);
        if (!cli_scene_in_reach(CMD, setup.scene, scene, &cam)) goto done; /* the blocks moved out of range */
        desc.camera = &cam;
        rp_render_stats rs;
        if (!rp_render(scene, &desc, pixels, &rs)) {
            fprintf(stderr, "raypack animate: rendering frame %d failed (out of memory?)\n", i);
            goto done;
        }
        double cpu = cli_cpu_ms() - c0; /* update and render, every thread */
        uint64_t fr = 0;
        for (int k = 0; k < RP_RAY_KIND_COUNT; k++) fr += rs.rays[k];
        rays += fr;
        double w0 = cli_now_ms();
        if (pattern) {
            char path[4096];
            snprintf(path, sizeof path, pattern, i);
            const char *dot = strrchr(pattern, '.');
            bool eight_bit = strcasecmp(dot, ".png") == 0 || strcasecmp(dot, ".ppm") == 0;
            if (eight_bit && desc.integrator != RP_INTEGRATOR_AOV)
                rp_film_tonemap(pixels, (size_t)w * (size_t)h, channels, 0.0f, RP_TONEMAP_SRGB);
            if (!rp_image_write(path, w, h, channels, pixels, err, sizeof err)) {
                fprintf(stderr, "raypack animate: %s\n", err);
                goto done;
            }
        }
        double write_ms = cli_now_ms() - w0;
        sum_write += write_ms;
        sum_cpu += cpu;
        sum_update += us.update_ms, sum_refit += us.refit_ms, sum_top += us.top_ms, sum_render += rs.render_ms;
        if (us.update_ms > max_update) max_update = us.update_ms;
        upd[done_frames] = us.update_ms, ren[done_frames] = rs.render_ms;
        done_frames++;
        if (!quiet)
            printf("frame %5d t %8.4f  update %7.3f ms (eval %.3f, refit %.3f, top %.3f; %u instances, %u refit, %u rebuilt)"
                   "  render %8.1f ms  %.2f Mrays/s  cpu %.1f ms\n",
                   i, (double)t, us.update_ms, us.eval_ms, us.refit_ms, us.top_ms, us.instances, us.refits, us.rebuilds,
                   rs.render_ms, rs.render_ms > 0.0 ? (double)fr / (rs.render_ms * 1e3) : 0.0, cpu);
    }
    double total = sum_update + sum_render, n = done_frames > 0 ? done_frames : 1;
    qsort(upd, (size_t)done_frames, sizeof *upd, cmp_double);
    qsort(ren, (size_t)done_frames, sizeof *ren, cmp_double);
    printf("summary  %d frames: update %.3f ms a frame (median %.3f, max %.3f; refit %.3f, top level %.3f), render %.1f ms "
           "a frame (median %.1f)\n",
           done_frames, sum_update / n, upd[done_frames / 2], max_update, sum_refit / n, sum_top / n, sum_render / n,
           ren[done_frames / 2]);
    printf("fps      %.3f frames/s with updates (BART), %.3f rendering alone; updates %.2f%% of the time; "
           "%.2f Mrays/s%s\n",
           total > 0.0 ? 1e3 * n / total : 0.0, sum_render > 0.0 ? 1e3 * n / sum_render : 0.0,
           total > 0.0 ? 100.0 * sum_update / total : 0.0, sum_render > 0.0 ? (double)rays / (sum_render * 1e3) : 0.0,
           pattern ? "" : " (no images written)");
    /* the machine's other jobs stretch the wall clock, not the CPU time: the rate the frames would
     * reach on `threads` idle cores, were they spread evenly over them */
    int nth = rp_device_thread_count(device);
    printf("cpu      %.1f ms a frame (update and render, all %d threads): %.3f frames/s on %d idle cores, "
           "%.2f Mrays per CPU second\n",
           sum_cpu / n, nth, sum_cpu > 0.0 ? 1e3 * n * nth / sum_cpu : 0.0, nth,
           sum_cpu > 0.0 ? (double)rays / (sum_cpu * 1e3) : 0.0);
    if (pattern) printf("written  %d images, %.1f ms a frame (not counted above)\n", done_frames, sum_write / n);
    status = CLI_EXIT_OK;
done:
    free(upd);
    free(pixels);
    rp_render_scene_release(scene);
    if (device) rp_device_release(device);
    cli_render_unload(&setup, &data);
    return status;
}
