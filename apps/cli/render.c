/* `raypack render`: load a scene (or build the default room), render it, write an image, report. */
#include "cli.h"

#include <errno.h>
#include <libgen.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"

static const char *const CMD = "render";
/* --width x --height at most: 8192 x 8192, or any shape of as many pixels (each side up to 16384) */
#define RENDER_MAX_PIXELS 67108864

static void render_usage(FILE *out) {
    fprintf(out,
            "usage: raypack render [SCENE] [options]\n"
            "\n"
            "Renders SCENE (OBJ, PLY, NFF, AFF; .gz and .tar.gz too; glTF and assimp's formats), or the built-in room without one.\n"
            "\n"
            "options:\n"
            "  -o, --output FILE      image to write; the format follows the extension:\n"
            "                         .png, .ppm (8-bit: exposure, tone map, sRGB), .pfm, .hdr or .exr\n"
            "                         (float, linear radiance as is) [raypack.png]\n"
            "  --width W, --height H  image size in pixels, 1..16384 each and at most 67108864\n"
            "                         (8192x8192) in all [the scene's, else 512x512]; one of them\n"
            "                         alone keeps the scene's aspect ratio\n"
            "  --spp N                samples per pixel, jittered deterministically when N > 1 [1];\n"
            "                         with --time, per frame\n"
            "  --time S               render frames of --spp samples each, accumulated, until S\n"
            "                         seconds have passed (at least one frame)\n"
            "  --integrator NAME      whitted (point lights, mirrors, glass), eyelight, direct\n"
            "                         (direct lighting, MIS), path (path tracing: NEE, MIS,\n"
            "                         Russian roulette), ir (instant radiosity) or ao (ambient\n"
            "                         occlusion) [whitted]. direct, path and ir are physically\n"
            "                         based: radiance in the scene's units, lit only by the scene's\n"
            "                         emitters (MTL Ke; Ka > 1), point lights and --env\n"
            "  --engine stream        the stream tracer over a uniform grid (see --engine stream --help)\n"
            "  --engine cuda          every ray traced by the CUDA BVH kernels, shading on the CPU\n"
            "                         (eyelight, whitted, path, direct, ao): the CPU's image with\n"
            "                         --anim-flat, byte for byte; --cuda-kernel simple|persistent|\n"
            "                         speculative, --cuda-emulate (the kernels on the CPU) (docs/gpu.md)\n"
            "  --max-depth N          Whitted reflection/refraction depth; path, ir: bounces, 0..64 [5]\n"
            "  --reflect-depth N      Whitted: reflection rays only from hits at depth < N (primary\n"
            "  --refract-depth N      0), the same for refraction; 0..64, either replaces --max-depth\n"
            "                         for its kind (Overbeck et al.'s fig. 1: 1 and 4)\n"
            "  --lights LIST          keep only the scene's point lights of these indices (0-based,\n"
            "                         comma separated, as `raypack info` lists them)\n"
            "  --anim-time T          animated scenes (BART AFF): the scene and camera at time T of\n"
            "                         the animation [its start]; `raypack animate` renders frames\n"
            "                         (--time is the progressive time budget)\n"
            "  --anim-flat            animated scenes: one flat structure instead of an instance\n"
            "                         per keyframed block (same image, for comparisons)\n"
            "  --point-radius R       point clouds (vertices alone: a PLY without faces): a sphere of\n"
            "                         radius R at each point [half the spacing of neighbours]\n"
            "  --anim-refit           animated scenes: keyframed blocks' vertices moved and their\n"
            "                         sub-scenes refitted each frame instead of instance transforms\n"
            "  --density-scale S      volumes (.vdb): extinction = S x density per world unit [1]\n"
            "  --albedo A|R,G,B       volumes: single-scattering albedo, in [0, 1] [1]\n"
            "  --hg-g G               volumes: Henyey-Greenstein asymmetry, in (-1, 1) [0, isotropic]\n"
            "  --vdb-grid NAME        volumes: the float grid to read [density, else the first]\n"
            "  --medium-box X0,Y0,Z0,X1,Y1,Z1  a homogeneous medium (density 1 x --density-scale)\n"
            "                         filling that box, in any scene (fog in a room)\n"
            "  --volume FILE.vdb      the volume of a .vdb file in this scene, beside its surfaces\n"
            "                         (in the .vdb's own world units unless --volume-fit)\n"
            "  --volume-fit X0,Y0,Z0,X1,Y1,Z1  scales the volume uniformly and centres it in that box\n"
            "                         (--density-scale stays per world unit of the scene)\n"
            "  --env FILE.hdr         lat-long environment (+y up) for direct, path and ir\n"
            "  --env-scale R,G,B      multiplies --env; without --env, a constant environment\n"
            "  --exposure EV          PNG/PPM: multiply by 2^EV before the tone map [0]\n"
            "  --tonemap NAME         PNG/PPM: srgb (clamp) or aces (filmic) [srgb]\n"
            "  --sampler NAME         direct, path, ao, ir: the pixels' numbers, pcg (hashed) or sobol\n"
            "                         (Owen-scrambled, lower error per sample) [pcg]\n"
            "  --ir-interleave N      ir: N x N interleaved VPL sets, 1..16 [5]\n"
            "  --ir-vpls N            ir: VPLs per set (per pixel and sample), 1..4096 [16]\n"
            "  --ir-filter N          ir: discontinuity buffer side (odd; 1: off) [3]\n"
            "  --ir-clamp C           ir: geometry term distance at least C x the scene's bounding\n"
            "                         radius; 0 or negative: no clamping (unbiased) [0.02]\n"
            "  --ir-rr X              ir: Russian roulette on the shadow rays of contributions under X\n"
            "                         x the pixel's mean (unbiased, noisier, fewer rays); 0: off [2]\n"
            "  --ao-distance D        ao: occlusion ray length [0.1 x the bounding radius]\n"
            "  --aovs                 also write the albedo and normal AOVs (for denoisers) beside\n"
            "                         the image: NAME.albedo.EXT and NAME.normal.EXT\n"
            "  --aov NAME             debug output instead of shading: depth (PFM: distance along\n"
            "                         the primary ray, +inf on a miss), normal, primid or albedo\n"
            "  --threads N            worker threads (they also parse the scene file), 1..%d;\n"
            "                         0 for all hardware threads [0]\n"
            "  --isa NAME             kernels: auto (the widest the CPU has; AVX2 on Intel CPUs\n"
            "                         that clock down under AVX-512), scalar, sse, avx2 or\n"
            "                         avx512 [auto]; every choice gives the same image\n"
            "  --accel KIND           the triangles' structure: bvh, kdtree, bih or grid [bvh]\n"
            "  --density F            --accel grid: about F voxels per triangle (Cleary-Wyvill) [4]\n"
            "  --traversal NAME       how Whitted's ray packets walk the BVH: auto (per packet, from\n"
            "                         its coherence: span, partition or its SIMD rays alone),\n"
            "                         masked, ranged, partition, span (ranged narrowed from both\n"
            "                         ends), single (each ray alone), simd (each SIMD ray alone) or\n"
            "                         mlrt (multi-level: entry points found by the packets' and\n"
            "                         their quadrants' frusta, then span; needs --frustum on)\n"
            "                         [auto]; every choice gives the same image\n"
            "  --packet N             Whitted traces packets of N x N rays, N = 4, 8, 16 or 32, and\n"
            "                         every integrator its primary rays (ir: 8) [16]\n"
            "  --frustum on|off       cull with the packets' frusta [on]\n"
            "  --eye X,Y,Z  --look X,Y,Z  --up X,Y,Z  --fov DEG\n"
            "                         camera (pinhole; vertical fov in (0, 180)); each replaces that\n"
            "                         part of the scene's camera, or of one framing the scene\n"
            "  --stats                also print the BVH statistics and, per ray kind, the packets'\n"
            "                         ray-box and ray-triangle tests, frustum culls and the tests by\n"
            "                         BVH depth (counted in SIMD rays)\n"
            "  --stats-json FILE      write times, ray counts, Mrays/s and those counters as JSON\n"
            "  --mpi                  distributed rendering under mpirun (raypack render --mpi --help)\n"
            "  --quiet                no progress and no report\n"
            "  -h, --help             this help\n"
            "\n"
            "exit status: 0 ok, 1 the scene could not be loaded or the image written, 2 usage error\n",
            CLI_MAX_THREADS);
}

typedef struct render_options {
    const char *scene;
    const char *output;
    const char *stats_json;
    int width, height, spp, max_depth, threads, isa;
    rp_integrator_type integrator;
    const char *integrator_name;
    bool use_aov;
    rp_aov aov;
    const char *aov_name;
    bool has_eye, has_look, has_up, has_fov;
    float eye[3], look[3], up[3], fov;
    bool stats, quiet;
    float time_s, exposure, ir_clamp, ir_rr, ao_distance;
    rp_tonemap tonemap;
    rp_sampler_type sampler;
    const char *env;
    bool has_env_scale;
    float env_scale[3];
    int ir_interleave, ir_vpls, ir_filter;
    bool aovs;
    rp_traversal traversal;
    const char *traversal_name;
    int packet;
    bool no_frustum;
    rp_accel_type accel;
    float grid_density;
    int reflect_depth, refract_depth; /* -1: not given */
    bool has_anim_time, anim_flat, anim_refit;
    float anim_time;
    float point_radius;               /* 0: automatic */
    cli_medium_opts vol;              /* --density-scale, --albedo, --hg-g, --medium-box, --vdb-grid */
    uint32_t lights[CLI_MAX_LIGHTS];
    int light_count;                  /* -1: all lights */
} render_options;

static const struct {
    const char *name;
    rp_traversal traversal;
} TRAVERSALS[] = {{"auto", RP_TRAVERSAL_AUTO},           {"masked", RP_TRAVERSAL_MASKED},
                  {"ranged", RP_TRAVERSAL_RANGED},       {"partition", RP_TRAVERSAL_PARTITION},
                  {"span", RP_TRAVERSAL_SPAN},           {"single", RP_TRAVERSAL_SINGLE},
                  {"simd", RP_TRAVERSAL_SIMD},           {"mlrt", RP_TRAVERSAL_MLRT}};

/* Returns CLI_EXIT_OK when the options parsed, else the exit status. */
static int parse_options(int argc, char **argv, render_options *o, bool *help) {
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = NULL;
#define VALUE()                                                           \
    do {                                                                  \
        if (!(v = cli_flag_value(CMD, argc, argv, &i))) return CLI_EXIT_USAGE; \
    } while (0)
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            *help = true;
            return CLI_EXIT_OK;
        } else if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) {
            VALUE();
            o->output = v;
        } else if (strcmp(a, "--width") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 16384, &o->width)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--height") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 16384, &o->height)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--spp") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 65536, &o->spp)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--max-depth") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 0, 64, &o->max_depth)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--threads") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 0, CLI_MAX_THREADS, &o->threads)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--isa") == 0) {
            VALUE();
            if (!cli_parse_isa(CMD, a, v, &o->isa)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--accel") == 0) {
            VALUE();
            if (!cli_parse_accel(CMD, a, v, &o->accel)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--density") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 1000.0, true, &o->grid_density)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--integrator") == 0) {
            VALUE();
            static const struct { const char *name; rp_integrator_type type; } integrators[] = {
                {"whitted", RP_INTEGRATOR_WHITTED}, {"eyelight", RP_INTEGRATOR_EYELIGHT},
                {"direct", RP_INTEGRATOR_DIRECT},   {"path", RP_INTEGRATOR_PATH},
                {"ir", RP_INTEGRATOR_IR},           {"ao", RP_INTEGRATOR_AO}};
            bool found = false;
            for (size_t k = 0; k < sizeof integrators / sizeof integrators[0]; k++)
                if (strcmp(v, integrators[k].name) == 0) {
                    o->integrator = integrators[k].type;
                    found = true;
                }
            if (!found) {
                fprintf(stderr, "raypack render: --integrator expects whitted, eyelight, direct, path, ir or ao, got "
                                "'%s'\n", v);
                return CLI_EXIT_USAGE;
            }
            o->integrator_name = v;
        } else if (strcmp(a, "--time") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 1e6, true, &o->time_s)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--exposure") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, -64.0, 64.0, false, &o->exposure)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--tonemap") == 0) {
            VALUE();
            if (strcmp(v, "srgb") == 0) {
                o->tonemap = RP_TONEMAP_SRGB;
            } else if (strcmp(v, "aces") == 0) {
                o->tonemap = RP_TONEMAP_ACES;
            } else {
                fprintf(stderr, "raypack render: --tonemap expects srgb or aces, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--sampler") == 0) {
            VALUE();
            if (strcmp(v, "pcg") != 0 && strcmp(v, "sobol") != 0) {
                fprintf(stderr, "raypack render: --sampler expects pcg or sobol, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
            o->sampler = v[0] == 's' ? RP_SAMPLER_SOBOL : RP_SAMPLER_PCG;
        } else if (strcmp(a, "--env") == 0) {
            VALUE();
            o->env = v;
        } else if (strcmp(a, "--env-scale") == 0) {
            VALUE();
            if (!cli_parse_vec3(CMD, a, v, o->env_scale)) return CLI_EXIT_USAGE;
            if (o->env_scale[0] < 0.0f || o->env_scale[1] < 0.0f || o->env_scale[2] < 0.0f) {
                /* a negative radiance has no meaning: it rendered negative pixels */
                fprintf(stderr, "raypack render: --env-scale expects three numbers >= 0, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
            o->has_env_scale = true;
        } else if (strcmp(a, "--ir-interleave") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 16, &o->ir_interleave)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--ir-vpls") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 4096, &o->ir_vpls)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--ir-filter") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 31, &o->ir_filter) || o->ir_filter % 2 == 0) {
                if (o->ir_filter % 2 == 0) fprintf(stderr, "raypack render: --ir-filter expects an odd side, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--ir-clamp") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, -1.0, 1.0, false, &o->ir_clamp)) return CLI_EXIT_USAGE;
            if (o->ir_clamp == 0.0f) o->ir_clamp = -1.0f;
        } else if (strcmp(a, "--ir-rr") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 16.0, false, &o->ir_rr)) return CLI_EXIT_USAGE;
            if (o->ir_rr == 0.0f) o->ir_rr = -1.0f;
        } else if (strcmp(a, "--ao-distance") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 1e30, true, &o->ao_distance)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--aovs") == 0) {
            o->aovs = true;
        } else if (strcmp(a, "--aov") == 0) {
            VALUE();
            static const struct { const char *name; rp_aov aov; } aovs[] = {
                {"depth", RP_AOV_DEPTH}, {"normal", RP_AOV_NORMAL}, {"primid", RP_AOV_PRIMID}, {"albedo", RP_AOV_ALBEDO}};
            o->use_aov = false;
            for (size_t k = 0; k < sizeof aovs / sizeof aovs[0]; k++) {
                if (strcmp(v, aovs[k].name) == 0) {
                    o->use_aov = true;
                    o->aov = aovs[k].aov;
                    o->aov_name = aovs[k].name;
                }
            }
            if (!o->use_aov) {
                fprintf(stderr, "raypack render: --aov expects depth, normal, primid or albedo, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--traversal") == 0) {
            VALUE();
            o->traversal_name = NULL;
            for (size_t k = 0; k < sizeof TRAVERSALS / sizeof TRAVERSALS[0]; k++) {
                if (strcmp(v, TRAVERSALS[k].name) == 0) {
                    o->traversal = TRAVERSALS[k].traversal;
                    o->traversal_name = TRAVERSALS[k].name;
                }
            }
            if (!o->traversal_name) {
                fprintf(stderr, "raypack render: --traversal expects auto, masked, ranged, partition, span, single, "
                                "simd or mlrt, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--packet") == 0) {
            VALUE();
            char *end;
            long n = strtol(v, &end, 10);
            if (end == v || *end != '\0' || (n != 4 && n != 8 && n != 16 && n != 32)) {
                fprintf(stderr, "raypack render: --packet expects 4, 8, 16 or 32 (packets of N x N rays; the "
                                "traversal kernels take sides that are multiples of 4, up to 32), got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
            o->packet = (int)n;
        } else if (strcmp(a, "--frustum") == 0) {
            VALUE();
            if (strcmp(v, "on") == 0) {
                o->no_frustum = false;
            } else if (strcmp(v, "off") == 0) {
                o->no_frustum = true;
            } else {
                fprintf(stderr, "raypack render: --frustum expects on or off, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--eye") == 0) {
            VALUE();
            if (!cli_parse_vec3(CMD, a, v, o->eye)) return CLI_EXIT_USAGE;
            o->has_eye = true;
        } else if (strcmp(a, "--look") == 0) {
            VALUE();
            if (!cli_parse_vec3(CMD, a, v, o->look)) return CLI_EXIT_USAGE;
            o->has_look = true;
        } else if (strcmp(a, "--up") == 0) {
            VALUE();
            if (!cli_parse_vec3(CMD, a, v, o->up)) return CLI_EXIT_USAGE;
            o->has_up = true;
        } else if (strcmp(a, "--fov") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 180.0, true, &o->fov)) return CLI_EXIT_USAGE;
            o->has_fov = true;
        } else if (strcmp(a, "--reflect-depth") == 0 || strcmp(a, "--refract-depth") == 0) {
            VALUE();
            int *d = strcmp(a, "--reflect-depth") == 0 ? &o->reflect_depth : &o->refract_depth;
            if (!cli_parse_int(CMD, a, v, 0, 64, d)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--anim-time") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, -1e30, 1e30, true, &o->anim_time)) return CLI_EXIT_USAGE;
            o->has_anim_time = true;
        } else if (strcmp(a, "--anim-flat") == 0) {
            o->anim_flat = true;
        } else if (strcmp(a, "--anim-refit") == 0) {
            o->anim_refit = true;
        } else if (strcmp(a, "--point-radius") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 1e30, true, &o->point_radius)) return CLI_EXIT_USAGE;
        } else if (cli_is_medium_flag(a)) {
            VALUE();
            if (!cli_parse_medium_flag(CMD, a, v, &o->vol)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--lights") == 0) {
            VALUE();
            o->light_count = cli_parse_list(CMD, a, v, o->lights, CLI_MAX_LIGHTS);
            if (o->light_count < 0) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--stats") == 0) {
            o->stats = true;
        } else if (strcmp(a, "--stats-json") == 0) {
            VALUE();
            o->stats_json = v;
        } else if (strcmp(a, "--quiet") == 0 || strcmp(a, "-q") == 0) {
            o->quiet = true;
        } else if (a[0] == '-' && a[1] != '\0') {
            fprintf(stderr, "raypack render: unknown option '%s' (see raypack render --help)\n", a);
            return CLI_EXIT_USAGE;
        } else if (!o->scene) {
            o->scene = a;
        } else {
            fprintf(stderr, "raypack render: expected one SCENE, got '%s' and '%s'\n", o->scene, a);
            return CLI_EXIT_USAGE;
        }
#undef VALUE
    }
    /* What the flags alone say is wrong is a usage error before the scene is loaded. */
    if (o->width && o->height && (double)o->width * (double)o->height > RENDER_MAX_PIXELS) {
        fprintf(stderr, "raypack render: --width %d --height %d is too many pixels (at most %d in all)\n", o->width,
                o->height, RENDER_MAX_PIXELS);
        return CLI_EXIT_USAGE;
    }
    int cam_status = cli_camera_flags_check(CMD, o->has_eye ? o->eye : NULL, o->has_look ? o->look : NULL,
                                            o->has_up ? o->up : NULL);
    if (cam_status != CLI_EXIT_OK) return cam_status;
    const char *dot = strrchr(o->output, '.');
    if (!dot || (strcasecmp(dot, ".png") != 0 && strcasecmp(dot, ".pfm") != 0 && strcasecmp(dot, ".ppm") != 0 &&
                 strcasecmp(dot, ".hdr") != 0 && strcasecmp(dot, ".exr") != 0)) {
        fprintf(stderr, "raypack render: -o expects a file ending in .png, .pfm, .ppm, .hdr or .exr, got '%s'\n",
                o->output);
        return CLI_EXIT_USAGE;
    }
    return CLI_EXIT_OK;
}

typedef struct progress_state {
    double start_ms, last_ms;
    bool tty, quiet;
    int last_quarter;
} progress_state;

static void on_progress(void *user, uint32_t done, uint32_t total, uint64_t rays) {
    progress_state *p = user;
    if (p->quiet || total == 0) return;
    double now = cli_now_ms(), elapsed = now - p->start_ms;
    double frac = (double)done / (double)total;
    double mrays = elapsed > 0.0 ? (double)rays / (elapsed * 1e3) : 0.0;
    if (p->tty) {
        if (done < total && now - p->last_ms < 100.0) return;
        p->last_ms = now;
        enum { BAR = 30 };
        char bar[BAR + 1];
        int fill = (int)(frac * BAR);
        for (int i = 0; i < BAR; i++) bar[i] = i < fill ? '#' : '-';
        bar[BAR] = '\0';
        double eta = frac > 0.0 ? elapsed * (1.0 - frac) / frac / 1e3 : 0.0;
        fprintf(stderr, "\rrender [%s] %3d%%  ETA %5.1f s  %7.2f Mrays/s ", bar, (int)(frac * 100.0), eta, mrays);
        if (done == total) fputc('\n', stderr);
        fflush(stderr);
    } else {
        int quarter = (int)(frac * 4.0);
        if (quarter <= p->last_quarter) return;
        p->last_quarter = quarter;
        fprintf(stderr, "render: %3d%% after %.2f s, %.2f Mrays/s\n", quarter * 25, elapsed / 1e3, mrays);
    }
}

/* Depth for an 8-bit image: near is bright, far dark, misses black. */
static void depth_to_grey(float *px, size_t n) {
    float maxd = 0.0f;
    for (size_t i = 0; i < n; i++)
        if (isfinite(px[i]) && px[i] > maxd) maxd = px[i];
    for (size_t i = 0; i < n; i++) px[i] = isfinite(px[i]) && maxd > 0.0f ? 1.0f - 0.9f * px[i] / maxd : 0.0f;
}

static const char *basename_of(const char *path) {
    const char *s = strrchr(path, '/');
    return s ? s + 1 : path;
}

static void json_string(FILE *f, const char *s) {
    fputc('"', f);
    for (; *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\') fprintf(f, "\\%c", c);
        else if (c < 0x20) fprintf(f, "\\u%04x", c);
        else fputc(c, f);
    }
    fputc('"', f);
}

static const char *const KIND_NAMES[RP_RAY_KIND_COUNT] = {"primary", "shadow", "reflection", "refraction", "bounce"};

/* Number of entries of a depth histogram up to its last nonzero one. */
static int depth_used(const uint64_t *h) {
    int n = RP_COUNTERS_N_DEPTH;
    while (n > 0 && h[n - 1] == 0) n--;
    return n;
}

/* A count in at most 6 characters (k, M, G suffixes), for the compact histograms. */
static void print_count(uint64_t v) {
    double d = (double)v;
    if (v < 10000) printf("%llu", (unsigned long long)v);
    else if (d < 1e6) printf("%.3gk", d / 1e3);
    else if (d < 1e9) printf("%.3gM", d / 1e6);
    else printf("%.3gG", d / 1e9);
}

/* Fig. 6 of the paper per ray kind: tests by BVH depth, root first, in one line each. */
static void print_work(const rp_render_stats *rs) {
    printf("work     %-10s %9s %13s %13s %25s %25s\n", "(SIMD rays)", "packets", "box tests", "tri tests",
           "frustum box culls/tests", "frustum tri culls/tests");
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
        const rp_counters_n *c = &rs->work[k];
        if (!c->packets) continue;
        printf("         %-10s %9llu %13llu %13llu %12llu/%-12llu %12llu/%-12llu\n", KIND_NAMES[k],
               (unsigned long long)c->packets, (unsigned long long)c->box_tests, (unsigned long long)c->tri_tests,
               (unsigned long long)c->frustum_box_culls, (unsigned long long)c->frustum_box_tests,
               (unsigned long long)c->frustum_tri_culls, (unsigned long long)c->frustum_tri_tests);
    }
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
        const rp_counters_n *c = &rs->work[k];
        if (!c->traversal[0]) continue;
        printf("auto     %-10s %9llu packets: span %llu, partition %llu, SIMD rays alone %llu\n", KIND_NAMES[k],
               (unsigned long long)c->traversal[0], (unsigned long long)c->traversal[4],
               (unsigned long long)c->traversal[3], (unsigned long long)c->traversal[5]);
    }
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
        const rp_counters_n *c = &rs->work[k];
        if (!c->traversal[6]) continue;
        uint64_t rays = c->rays ? c->rays : 1, below = c->mlrt_rays_below_root;
        printf("mlrt     %-10s %9llu packets, %llu sub-packets from entry points, %.1f%% of rays below the root "
               "(mean depth %.1f)\n", KIND_NAMES[k], (unsigned long long)c->traversal[6],
               (unsigned long long)c->mlrt_entries, 100.0 * (double)below / (double)rays,
               below ? (double)c->mlrt_entry_depth / (double)below : 0.0);
    }
    for (int which = 0; which < 2; which++) {
        printf("%s\n", which ? "tri tests by leaf depth (root 0):" : "box tests by BVH depth (root 0):");
        for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
            const uint64_t *h = which ? rs->work[k].tri_tests_depth : rs->work[k].box_tests_depth;
            int n = depth_used(h);
            if (!n) continue;
            printf("  %-10s", KIND_NAMES[k]);
            for (int i = 0; i < n; i++) {
                putchar(' ');
                print_count(h[i]);
            }
            putchar('\n');
        }
    }
}

static void json_histogram(FILE *f, const uint64_t *h) {
    int n = depth_used(h);
    fputc('[', f);
    for (int i = 0; i < n; i++) fprintf(f, "%s%llu", i ? ", " : "", (unsigned long long)h[i]);
    fputc(']', f);
}

/* The work counters per ray kind as a JSON object. */
static void json_work(FILE *f, const rp_render_stats *rs) {
    fprintf(f, "  \"work\": {");
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
        const rp_counters_n *c = &rs->work[k];
        fprintf(f, "%s\n    \"%s\": {\"packets\": %llu, \"rays\": %llu, \"box_tests\": %llu, \"tri_tests\": %llu, "
                   "\"frustum_box_tests\": %llu, \"frustum_box_culls\": %llu, \"frustum_tri_tests\": %llu, "
                   "\"frustum_tri_culls\": %llu,\n      ",
                k ? "," : "", KIND_NAMES[k], (unsigned long long)c->packets, (unsigned long long)c->rays,
                (unsigned long long)c->box_tests, (unsigned long long)c->tri_tests,
                (unsigned long long)c->frustum_box_tests, (unsigned long long)c->frustum_box_culls,
                (unsigned long long)c->frustum_tri_tests, (unsigned long long)c->frustum_tri_culls);
        cli_json_traversal(f, c);
        fputs(",\n      \"box_tests_depth\": ", f);
        json_histogram(f, c->box_tests_depth);
        fprintf(f, ",\n      \"tri_tests_depth\": ");
        json_histogram(f, c->tri_tests_depth);
        fputc('}', f);
    }
    fprintf(f, "\n  },\n");
}

int cli_render(int argc, char **argv) {
    if (cli_stream_wanted(argc, argv, "--engine", "cuda")) return cli_cuda_render(argc, argv);
    if (cli_stream_wanted(argc, argv, "--engine", NULL)) return cli_stream_render(argc, argv);
    for (int i = 1; i < argc; i++)
        if (strcmp(argv[i], "--mpi") == 0) {
#ifdef RP_HAVE_MPI
            return cli_render_mpi(argc, argv);
#else
            fprintf(stderr, "raypack render: --mpi: this raypack was built without MPI (install libopenmpi-dev "
                            "and openmpi-bin, then rebuild)\n");
            return CLI_EXIT_USAGE;
#endif
        }
    render_options o = {.output = "raypack.png", .max_depth = -1, .integrator = RP_INTEGRATOR_WHITTED,
                        .integrator_name = "whitted", .traversal_name = "auto", .packet = 16,
                        .reflect_depth = -1, .refract_depth = -1, .light_count = -1};
    bool help = false;
    int rc = parse_options(argc, argv, &o, &help);
    if (rc != CLI_EXIT_OK) return rc;
    if (help) {
        render_usage(stdout);
        return CLI_EXIT_OK;
    }
    /* --aovs writes NAME.albedo.EXT and NAME.normal.EXT beside -o */
    char guide_path[2][4096] = {"", ""};
    const char *odot = strrchr(o.output, '.');
    for (int g = 0; g < 2 && o.aovs && !o.use_aov && odot; g++)
        snprintf(guide_path[g], sizeof guide_path[g], "%.*s.%s%s", (int)(odot - o.output), o.output,
                 g ? "normal" : "albedo", odot);
    const cli_path paths[] = {{"SCENE", o.scene, true},
                              {"--env", o.env, true},
                              {"-o", o.output, false},
                              {"--stats-json", o.stats_json, false},
                              {"--aovs (albedo)", guide_path[0][0] ? guide_path[0] : NULL, false},
                              {"--aovs (normal)", guide_path[1][0] ? guide_path[1] : NULL, false}};
    if (!cli_check_paths(CMD, paths, (int)(sizeof paths / sizeof paths[0]))) return CLI_EXIT_USAGE;
    if (!cli_output_writable(CMD, o.output)) return CLI_EXIT_FAILURE;
    if (o.stats_json && !cli_output_writable(CMD, o.stats_json)) return CLI_EXIT_FAILURE;

    /* Load. */
    double t0 = cli_now_ms();
    rp_scene_data data;
    memset(&data, 0, sizeof data);
    bool builtin = o.scene == NULL;
    if (builtin) {
        if (!rp_default_scene(&data)) {
            fprintf(stderr, "raypack render: out of memory building the default scene\n");
            return CLI_EXIT_FAILURE;
        }
    } else {
        /* stat, not open: opening a FIFO here would block, and the loader reads it once as a stream */
        if (!cli_scene_readable(CMD, o.scene)) return CLI_EXIT_FAILURE;
        char err[512] = "";
        if (!rp_scene_data_load_ex(o.scene, &(rp_scene_load_desc){.threads = o.threads, .point_radius = o.point_radius,
                                                                  .volume_grid = o.vol.vdb_grid,
                                                                  .warning = cli_load_warning},
                                   &data, err, sizeof err)) {
            fprintf(stderr, "%s\n", err[0] ? err : "raypack render: cannot load the scene");
            return CLI_EXIT_FAILURE;
        }
    }
    double load_ms = cli_now_ms() - t0;
    char merr[640] = "";
    if (!cli_apply_medium(&o.vol, &data, merr, sizeof merr)) {
        fprintf(stderr, "raypack render: %s\n", merr);
        if (builtin) rp_default_scene_free(&data);
        else rp_scene_data_free(&data);
        return CLI_EXIT_FAILURE;
    }
    {
        cli_render_setup anim = {.has_anim_time = o.has_anim_time, .anim_time = o.anim_time, .light_count = o.light_count};
        memcpy(anim.lights, o.lights, sizeof o.lights);
        int arc = cli_render_scene_flags(CMD, &anim, &data);
        if (arc != CLI_EXIT_OK) {
            if (builtin) rp_default_scene_free(&data);
            else rp_scene_data_free(&data);
            return arc;
        }
    }

    int status = CLI_EXIT_FAILURE;
    rp_device *device = cli_device_new(CMD, o.threads, o.isa);
    rp_render_scene *scene = NULL;
    float *pixels = NULL;
    if (!device) goto done;
    double t1 = cli_now_ms();
    char err[512] = "";
    rp_render_scene_desc sdesc = {.accel = {.accel = o.accel, .grid_density = o.grid_density}, .environment = o.env, .flatten_animation = o.anim_flat,
                                  .refit_blocks = o.anim_refit, .medium = o.vol.medium};
    if (o.has_env_scale) memcpy(sdesc.environment_scale, o.env_scale, sizeof o.env_scale);
    scene = rp_render_scene_new(device, &data, &sdesc, err, sizeof err);
    if (!scene) {
        fprintf(stderr, "raypack render: %s\n", err);
        goto done;
    }
    double build_ms = cli_now_ms() - t1;
    bool physical = !o.use_aov && (o.integrator == RP_INTEGRATOR_DIRECT || o.integrator == RP_INTEGRATOR_PATH ||
                                   o.integrator == RP_INTEGRATOR_IR);
    size_t pb_lights = 0;
    rp_render_scene_lights(scene, &pb_lights);
    bool emits = false; /* textured emitters are not sampled lights, but light the scene */
    for (size_t i = 0; i < data.material_count && !emits; i++)
        for (int c = 0; c < 3; c++) emits |= data.materials[i].ke[c] > 0.0f && data.materials[i].map_ke > 0;
    if (physical && pb_lights == 0 && !emits)
        fprintf(stderr, "raypack render: warning: %s has no light (no emissive material, no point, spot or directional light; no --env): "
                        "the physically based image is black, as no fallback light is added\n",
                builtin ? "the built-in room" : o.scene);
    rp_scene_stats sst;
    rp_scene_get_stats(rp_render_scene_core(scene), &sst);

    /* Camera and size. */
    rp_camera cam = rp_render_scene_default_camera(scene);
    if (o.has_eye) memcpy(cam.pinhole.eye, o.eye, sizeof o.eye);
    if (o.has_look) memcpy(cam.pinhole.look, o.look, sizeof o.look);
    if (o.has_up) memcpy(cam.pinhole.up, o.up, sizeof o.up);
    if (o.has_fov) cam.pinhole.fov_deg = o.fov;
    int sw = data.camera.width > 0 ? data.camera.width : 512, sh = data.camera.height > 0 ? data.camera.height : 512;
    int w = o.width, h = o.height;
    if (!w && !h) {
        w = sw;
        h = sh;
    } else if (!h) {
        h = (int)fmax(1.0, floor((double)w * sh / sw + 0.5));
    } else if (!w) {
        w = (int)fmax(1.0, floor((double)h * sw / sh + 0.5));
    }
    if ((double)w * (double)h > RENDER_MAX_PIXELS || w > 16384 || h > 16384) {
        fprintf(stderr, "raypack render: %dx%d (from the scene's aspect ratio) is too many pixels (at most %d in all, "
                        "16384 a side)\n", w, h, RENDER_MAX_PIXELS);
        status = CLI_EXIT_USAGE;
        goto done;
    }
    if (cam.type == RP_CAMERA_PINHOLE) {
        int cs = cli_camera_check(CMD, o.scene, cam.pinhole.eye, cam.pinhole.look, cam.pinhole.up, o.has_eye, o.has_look, o.has_up);
        if (cs != CLI_EXIT_OK) {
            status = cs;
            goto done;
        }
    }
    if (!cli_scene_in_reach(CMD, o.scene, scene, &cam)) {
        status = CLI_EXIT_FAILURE;
        goto done;
    }
    if (sst.rejected_prims)
        fprintf(stderr, "raypack render: warning: %llu primitives with NaN/Inf coordinates (an overflowing "
                        "transform?) left out\n", (unsigned long long)sst.rejected_prims);
    if (o.integrator == RP_INTEGRATOR_IR && !o.use_aov && data.volume)
        fprintf(stderr, "raypack render: note: instant radiosity makes no VPLs in a medium: the volume is rendered "
                        "with direct lighting (single scattering)\n");
    if (sst.triangles + sst.spheres + sst.user_prims == 0 && !data.volume)
        fprintf(stderr, "raypack render: warning: the scene has nothing to hit; the image is its background\n");

    rp_render_desc desc = {
        .width = w, .height = h, .spp = o.spp, .integrator = o.use_aov ? RP_INTEGRATOR_AOV : o.integrator,
        .aov = o.aov, .camera = &cam,
        /* rp_render_desc: 0 is the default depth (5), negative is none. */
        .max_depth = o.max_depth < 0 ? 0 : (o.max_depth == 0 ? -1 : o.max_depth),
        .reflect_depth = o.reflect_depth < 0 ? 0 : (o.reflect_depth == 0 ? -1 : o.reflect_depth),
        .refract_depth = o.refract_depth < 0 ? 0 : (o.refract_depth == 0 ? -1 : o.refract_depth),
        .packet = o.packet, .traversal = o.traversal, .no_frustum = o.no_frustum,
        /* counting costs a little, so only when it is reported */
        .count_work = o.stats || o.stats_json,
        .ir = {.interleave = o.ir_interleave, .vpls = o.ir_vpls, .filter = o.ir_filter, .clamp = o.ir_clamp, .rr = o.ir_rr},
        .sampler = o.sampler,
        .ao_distance = o.ao_distance,
    };
    progress_state ps = {.start_ms = cli_now_ms(), .tty = isatty(2) != 0, .quiet = o.quiet, .last_quarter = 0};
    desc.progress = on_progress;
    desc.progress_user = &ps;
    int channels = rp_render_channels(&desc);
    pixels = malloc((size_t)w * (size_t)h * (size_t)channels * sizeof(float));
    if (!pixels) {
        fprintf(stderr, "raypack render: out of memory for a %dx%d image\n", w, h);
        goto done;
    }
    rp_render_stats rs;
    if (!rp_render(scene, &desc, pixels, &rs)) {
        fprintf(stderr, "raypack render: rendering failed (out of memory?)\n");
        goto done;
    }
    int frames = 1;
    if (o.time_s > 0.0f && !o.use_aov) {
        /* Progressive: frames of spp samples each, from where the last ended, averaged in linear float. */
        size_t np = (size_t)w * (size_t)h * (size_t)channels;
        float *frame = malloc(np * sizeof(float));
        if (!frame) {
            fprintf(stderr, "raypack render: out of memory for a %dx%d image\n", w, h);
            goto done;
        }
        desc.progress = NULL;
        double total_ms = rs.render_ms;
        int per = o.spp ? o.spp : 1;
        while (total_ms < (double)o.time_s * 1e3) {
            desc.sample_start = frames * per;
            rp_render_stats fs;
            if (!rp_render(scene, &desc, frame, &fs)) {
                free(frame);
                fprintf(stderr, "raypack render: rendering failed (out of memory?)\n");
                goto done;
            }
            frames++;
            for (size_t i = 0; i < np; i++) pixels[i] += (frame[i] - pixels[i]) / (float)frames;
            for (int k = 0; k < RP_RAY_KIND_COUNT; k++) rs.rays[k] += fs.rays[k];
            total_ms += fs.render_ms;
        }
        rs.render_ms = total_ms;
        free(frame);
    }

    /* Write. */
    const char *dot = strrchr(o.output, '.');
    bool eight_bit = strcasecmp(dot, ".png") == 0 || strcasecmp(dot, ".ppm") == 0;
    if (channels == 1 && strcasecmp(dot, ".pfm") != 0) depth_to_grey(pixels, (size_t)w * (size_t)h);
    else if (eight_bit && !o.use_aov) rp_film_tonemap(pixels, (size_t)w * (size_t)h, channels, o.exposure, o.tonemap);
    if (!rp_image_write(o.output, w, h, channels, pixels, err, sizeof err)) {
        fprintf(stderr, "raypack render: %s\n", err);
        goto done;
    }

    if (o.aovs && !o.use_aov) {
        /* The denoiser's guides: albedo and normal of the primary hits, written as the image is. */
        static const struct { rp_aov aov; const char *name; } guides[] = {{RP_AOV_ALBEDO, "albedo"},
                                                                          {RP_AOV_NORMAL, "normal"}};
        for (size_t g = 0; g < 2; g++) {
            rp_render_desc ad = desc;
            ad.integrator = RP_INTEGRATOR_AOV;
            ad.aov = guides[g].aov;
            ad.progress = NULL;
            ad.sample_start = 0;
            char name[4096];
            snprintf(name, sizeof name, "%.*s.%s%s", (int)(dot - o.output), o.output, guides[g].name, dot);
            if (!rp_render(scene, &ad, pixels, NULL) ||
                !rp_image_write(name, w, h, 3, pixels, err, sizeof err)) {
                fprintf(stderr, "raypack render: %s\n", err[0] ? err : "rendering an AOV failed");
                goto done;
            }
        }
    }

    uint64_t total = 0;
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) total += rs.rays[k];
    double mrays = rs.render_ms > 0.0 ? (double)total / (rs.render_ms * 1e3) : 0.0;
    const char *scene_name = builtin ? "(built-in room)" : basename_of(o.scene);
    const char *mode = o.use_aov ? o.aov_name : o.integrator_name;
    int threads = rp_device_thread_count(device);
    bool packets = !o.use_aov && o.integrator == RP_INTEGRATOR_WHITTED;
    if (!o.quiet) {
        printf("scene    %s: %zu triangles, %zu spheres, %zu cones, %zu materials, %zu lights\n", scene_name,
               data.triangle_count, data.sphere_count, data.cone_count, data.material_count, data.light_count);
        printf("image    %s: %dx%d, %d spp, %s", o.output, w, h, o.use_aov ? 1 : (o.spp ? o.spp : 1) * frames, mode);
        if (frames > 1) printf(" (%d frames, %.1f ms a frame)", frames, rs.render_ms / frames);
        if (packets)
            printf(" (max depth %d, %dx%d packets, %s traversal, frusta %s)", o.max_depth < 0 ? 5 : o.max_depth,
                   o.packet, o.packet, o.traversal_name, o.no_frustum ? "off" : "on");
        printf(", %d threads, %s kernels\n", threads, cli_isa_name(rp_device_isa(device)));
        printf("time     load %.1f ms, build %.1f ms, render %.1f ms\n", load_ms, build_ms, rs.render_ms);
        if (data.animation)
            printf("anim     time %g of [%g, %g] (%d frames), %zu keyframed blocks, %zu tpa triangles, %s\n",
                   (double)data.animation->time, (double)data.animation->start, (double)data.animation->end,
                   data.animation->frames, data.animation->node_count, data.animation->tpa_count,
                   o.anim_flat ? "flat" : "instanced");
        printf("rays     primary %llu, shadow %llu, reflection %llu, refraction %llu, bounce %llu, total %llu\n",
               (unsigned long long)rs.rays[RP_RAY_PRIMARY], (unsigned long long)rs.rays[RP_RAY_SHADOW],
               (unsigned long long)rs.rays[RP_RAY_REFLECTION], (unsigned long long)rs.rays[RP_RAY_REFRACTION],
               (unsigned long long)rs.rays[RP_RAY_BOUNCE], (unsigned long long)total);
        printf("speed    %.2f Mrays/s\n", mrays);
        if (o.stats) {
            printf("bvh      %llu binary nodes, %llu wide nodes (width %u), %llu leaves, depth %u, SAH cost %.2f, "
                   "%.2f MiB, commit %.1f ms\n",
                   (unsigned long long)sst.binary_nodes, (unsigned long long)sst.wide_nodes, sst.bvh_width,
                   (unsigned long long)sst.leaves, sst.depth, sst.sah_cost, (double)sst.bytes / 1048576.0,
                   sst.build_ms);
            if (packets) print_work(&rs);
        }
    }
    if (o.stats_json) {
        rp_atomic_file *af = rp_atomic_open(o.stats_json, err, sizeof err);
        if (!af) {
            fprintf(stderr, "raypack render: %s\n", err);
            goto done;
        }
        FILE *f = rp_atomic_stream(af);
        fprintf(f, "{\n  \"scene\": ");
        json_string(f, builtin ? "" : o.scene);
        fprintf(f, ",\n  \"output\": ");
        json_string(f, o.output);
        fprintf(f, ",\n  \"width\": %d,\n  \"height\": %d,\n  \"spp\": %d,\n  \"integrator\": \"%s\",\n", w, h,
                o.use_aov ? 1 : (o.spp ? o.spp : 1), mode);
        fprintf(f, "  \"threads\": %d,\n  \"isa\": \"%s\",\n  \"triangles\": %zu,\n", threads,
                cli_isa_name(rp_device_isa(device)), data.triangle_count);
        fprintf(f, "  \"load_ms\": %.3f,\n  \"build_ms\": %.3f,\n  \"render_ms\": %.3f,\n", load_ms, build_ms,
                rs.render_ms);
        fprintf(f, "  \"rays\": {\"primary\": %llu, \"shadow\": %llu, \"reflection\": %llu, \"refraction\": %llu, "
                   "\"bounce\": %llu, \"total\": %llu},\n",
                (unsigned long long)rs.rays[RP_RAY_PRIMARY], (unsigned long long)rs.rays[RP_RAY_SHADOW],
                (unsigned long long)rs.rays[RP_RAY_REFLECTION], (unsigned long long)rs.rays[RP_RAY_REFRACTION],
                (unsigned long long)rs.rays[RP_RAY_BOUNCE], (unsigned long long)total);
        fprintf(f, "  \"frames\": %d,\n  \"frame_ms\": %.3f,\n", frames, rs.render_ms / frames);
        fprintf(f, "  \"mrays_per_s\": %.3f,\n", mrays);
        if (packets) {
            fprintf(f, "  \"packet\": %d,\n  \"traversal\": \"%s\",\n  \"frustum\": %s,\n", o.packet, o.traversal_name,
                    o.no_frustum ? "false" : "true");
            json_work(f, &rs);
        }
        fprintf(f, "  \"bvh\": {\"binary_nodes\": %llu, \"wide_nodes\": %llu, \"leaves\": %llu, \"depth\": %u, "
                   "\"sah_cost\": %.4f, \"bytes\": %zu, \"build_ms\": %.3f}\n}\n",
                (unsigned long long)sst.binary_nodes, (unsigned long long)sst.wide_nodes,
                (unsigned long long)sst.leaves, sst.depth, sst.sah_cost, sst.bytes, sst.build_ms);
        if (!rp_atomic_commit(af, err, sizeof err)) {
            fprintf(stderr, "raypack render: %s\n", err);
            goto done;
        }
    }
    status = CLI_EXIT_OK;

done:
    free(pixels);
    rp_render_scene_release(scene);
    if (device) rp_device_release(device);
    if (builtin) rp_default_scene_free(&data);
    else rp_scene_data_free(&data);
    return status;
}

/* ---- the same setup for other commands (the viewer) ---- */

int cli_render_parse(int argc, char **argv, cli_render_setup *out, bool *help) {
    render_options o = {.output = "raypack.png", .max_depth = -1, .integrator = RP_INTEGRATOR_WHITTED,
                        .integrator_name = "whitted", .traversal_name = "auto", .packet = 16,
                        .reflect_depth = -1, .refract_depth = -1, .light_count = -1};
    int rc = parse_options(argc, argv, &o, help);
    if (rc != CLI_EXIT_OK) return rc;
    memset(out, 0, sizeof *out);
    out->scene = o.scene;
    out->width = o.width;
    out->height = o.height;
    out->spp = o.spp;
    out->threads = o.threads;
    out->point_radius = o.point_radius;
    out->vol = o.vol;
    out->isa = o.isa;
    /* as cli_render fills its rp_render_desc */
    out->desc = (rp_render_desc){
        .spp = o.spp, .integrator = o.use_aov ? RP_INTEGRATOR_AOV : o.integrator, .aov = o.aov,
        .max_depth = o.max_depth < 0 ? 0 : (o.max_depth == 0 ? -1 : o.max_depth),
        .reflect_depth = o.reflect_depth < 0 ? 0 : (o.reflect_depth == 0 ? -1 : o.reflect_depth),
        .refract_depth = o.refract_depth < 0 ? 0 : (o.refract_depth == 0 ? -1 : o.refract_depth),
        .packet = o.packet, .traversal = o.traversal, .no_frustum = o.no_frustum,
        .ir = {.interleave = o.ir_interleave, .vpls = o.ir_vpls, .filter = o.ir_filter, .clamp = o.ir_clamp, .rr = o.ir_rr},
        .sampler = o.sampler,
        .ao_distance = o.ao_distance,
    };
    out->scene_desc = (rp_render_scene_desc){.accel = {.accel = o.accel, .grid_density = o.grid_density}, .environment = o.env,
                                             .flatten_animation = o.anim_flat, .refit_blocks = o.anim_refit,
                                             .medium = o.vol.medium};
    out->has_anim_time = o.has_anim_time;
    out->anim_time = o.anim_time;
    out->light_count = o.light_count;
    memcpy(out->lights, o.lights, sizeof o.lights);
    if (o.has_env_scale) memcpy(out->scene_desc.environment_scale, o.env_scale, sizeof o.env_scale);
    out->integrator_name = o.use_aov ? o.aov_name : o.integrator_name;
    out->traversal_name = o.traversal_name;
    out->has_eye = o.has_eye;
    out->has_look = o.has_look;
    out->has_up = o.has_up;
    out->has_fov = o.has_fov;
    memcpy(out->eye, o.eye, sizeof o.eye);
    memcpy(out->look, o.look, sizeof o.look);
    memcpy(out->up, o.up, sizeof o.up);
    out->fov = o.fov;
    out->output = o.output;
    out->exposure = o.exposure;
    out->tonemap = o.tonemap;
    out->quiet = o.quiet;
    return CLI_EXIT_OK;
}

/* --volume, --volume-fit and --medium-box on loaded data; false (with a message, data freed) when
 * they fail. */
static bool add_medium_box(const char *cmd, const cli_render_setup *setup, rp_scene_data *data) {
    char err[640] = "";
    if (cli_apply_medium(&setup->vol, data, err, sizeof err)) return true;
    fprintf(stderr, "raypack %s: %s\n", cmd, err);
    cli_render_unload(setup, data);
    return false;
}

bool cli_render_load(const char *cmd, const cli_render_setup *setup, rp_scene_data *data) {
    memset(data, 0, sizeof *data);
    if (!setup->scene) {
        if (rp_default_scene(data)) return add_medium_box(cmd, setup, data);
        fprintf(stderr, "raypack %s: out of memory building the default scene\n", cmd);
        return false;
    }
    FILE *probe = fopen(setup->scene, "rb");
    if (!probe) {
        fprintf(stderr, "raypack %s: cannot open scene %s: %s\n", cmd, setup->scene, strerror(errno));
        return false;
    }
    fclose(probe);
    char err[512] = "";
    if (rp_scene_data_load_ex(setup->scene, &(rp_scene_load_desc){.threads = setup->threads, .point_radius = setup->point_radius,
                                                                  .volume_grid = setup->vol.vdb_grid,
                                                                  .warning = cli_load_warning},
                              data, err, sizeof err))
        return add_medium_box(cmd, setup, data);
    fprintf(stderr, "%s\n", err[0] ? err : "raypack: cannot load the scene");
    return false;
}

void cli_render_unload(const cli_render_setup *setup, rp_scene_data *data) {
    if (!setup->scene) rp_default_scene_free(data);
    else rp_scene_data_free(data);
}

rp_camera cli_render_camera(const cli_render_setup *setup, rp_render_scene *scene) {
    rp_camera cam = rp_render_scene_default_camera(scene);
    if (setup->has_eye) memcpy(cam.pinhole.eye, setup->eye, sizeof setup->eye);
    if (setup->has_look) memcpy(cam.pinhole.look, setup->look, sizeof setup->look);
    if (setup->has_up) memcpy(cam.pinhole.up, setup->up, sizeof setup->up);
    if (setup->has_fov) cam.pinhole.fov_deg = setup->fov;
    return cam;
}

void cli_render_size(const cli_render_setup *setup, const rp_scene_data *data, int *w, int *h) {
    int sw = data->camera.width > 0 ? data->camera.width : 512, sh = data->camera.height > 0 ? data->camera.height : 512;
    *w = setup->width;
    *h = setup->height;
    if (!*w && !*h) {
        *w = sw;
        *h = sh;
    } else if (!*h) {
        *h = (int)fmax(1.0, floor((double)*w * sh / sw + 0.5));
    } else if (!*w) {
        *w = (int)fmax(1.0, floor((double)*h * sw / sh + 0.5));
    }
}

int cli_render_scene_flags(const char *cmd, const cli_render_setup *setup, rp_scene_data *data) {
    if (setup->light_count >= 0 && !rp_scene_data_keep_lights(data, setup->lights, (size_t)setup->light_count)) {
        if (data->light_count)
            fprintf(stderr, "raypack %s: --lights: the scene has %zu lights (indices 0..%zu)\n", cmd, data->light_count,
                    data->light_count - 1);
        else
            fprintf(stderr, "raypack %s: --lights: the scene has no lights\n", cmd);
        return CLI_EXIT_USAGE;
    }
    if (setup->has_anim_time && !rp_scene_data_set_time(data, setup->anim_time)) {
        fprintf(stderr, "raypack %s: --anim-time: the scene is not animated (no AFF keyframes, tpa or camera path)\n",
                cmd);
        return CLI_EXIT_USAGE;
    }
    return CLI_EXIT_OK;
}
