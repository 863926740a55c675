/* `raypack render --engine stream` and `raypack bench --stream [--purcell]`: the streaming ray
 * tracer of Purcell et al. 2002 over the uniform grid (src/stream, src/accel/grid). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "accel/grid/grid.h"
#include "cli.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "stream/stream.h"

bool cli_stream_wanted(int argc, char **argv, const char *flag, const char *value) {
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], flag) != 0) continue;
        if (!value) return true;
        if (i + 1 < argc && strcmp(argv[i + 1], value) == 0) return true;
    }
    return false;
}

typedef struct stream_opts {
    const char *scene, *output;
    int width, height, threads, isa;
    bool has_eye, has_look, has_up, has_fov, stats, quiet, purcell;
    float eye[3], look[3], up[3], fov;
    bool has_render;           /* --integrator other than eyelight: the renderer's integrator */
    int max_depth, reflect_depth, refract_depth; /* -1: not given */
    float exposure;
    rp_tonemap tonemap;
    rp_render_desc rd;
    stream_desc sd;
    grid_desc gd;
    cli_medium_opts vol;       /* --volume, --medium-box, --albedo, ...: as `render` reads them */
} stream_opts;

static void usage(FILE *out, bool bench) {
    fprintf(out,
            bench ? "usage: raypack bench SCENE --stream [--purcell] [options]\n"
                  : "usage: raypack render SCENE --engine stream [options]\n");
    fprintf(out,
            "  the streaming ray tracer (Purcell et al. 2002) over a uniform grid, one kernel per pass\n"
            "  --width N, --height N   image size [the scene's, else 512; bench: 1024x1024]\n"
            "  --eye X,Y,Z --look X,Y,Z --up X,Y,Z --fov DEG   camera\n"
            "  --shading NAME          eyelight (ray casting, = --integrator eyelight) or shadow [eyelight]\n"
            "  --integrator NAME       eyelight, whitted, path, direct or ao: the renderer's integrator with its\n"
            "                          shading on the stream's rays; the image equals `render --integrator NAME`'s\n"
            "  --spp N, --max-depth N, --reflect-depth N, --refract-depth N, --sampler pcg|sobol\n"
            "                          as `render` takes them [1, 5, max depth, max depth, pcg]\n"
            "  --exposure EV, --tonemap srgb|aces   PNG/PPM as `render` writes them [0, srgb]\n"
            "  --anim-flat             accepted for `render`'s flags: animated scenes are always built flat\n"
            "  --density F             Cleary-Wyvill grid: about F voxels per triangle [4]\n"
            "  --min-dim N             the paper's rule instead: cubic voxels, N along the shortest side\n"
            "                          (--purcell uses 64, the paper's bunny grid)\n"
            "  --oracle F              intersect once this fraction of active rays needs it [0.2]\n"
            "  --wavefront             the wavefront scheduler: per-kernel queues compacted between passes\n"
            "  --threads N, --isa NAME the device: its threads run each pass over chunks of the stream\n");
    if (bench)
        fprintf(out, "  --purcell               print the paper's table 2 and fig. 6 beside ours\n");
    else
        fprintf(out, "  -o FILE                 image [raypack.png]\n  --stats                 print the statistics\n");
}

static int parse(const char *cmd, int argc, char **argv, stream_opts *o, bool bench) {
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = NULL;
#define VALUE()                                                                \
    do {                                                                       \
        if (!(v = cli_flag_value(cmd, argc, argv, &i))) return CLI_EXIT_USAGE; \
    } while (0)
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            usage(stdout, bench);
            return -1;
        } else if (strcmp(a, "--engine") == 0) {
            VALUE();
            if (strcmp(v, "stream") != 0) {
                fprintf(stderr, "raypack %s: --engine expects stream here, got '%s'\n", cmd, v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--stream") == 0 || strcmp(a, "--stats") == 0) {
            o->stats = true;
        } else if (strcmp(a, "--wavefront") == 0) {
            o->sd.wavefront = true;
        } else if (strcmp(a, "--purcell") == 0) {
            o->purcell = true;
        } else if (strcmp(a, "-q") == 0 || strcmp(a, "--quiet") == 0) {
            o->quiet = true;
        } else if (!bench && (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0)) {
            VALUE();
            o->output = v;
        } else if (strcmp(a, "--width") == 0) {
            VALUE();
            if (!cli_parse_int(cmd, a, v, 1, 16384, &o->width)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--height") == 0) {
            VALUE();
            if (!cli_parse_int(cmd, a, v, 1, 16384, &o->height)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--threads") == 0) {
            VALUE();
            if (!cli_parse_int(cmd, a, v, 0, CLI_MAX_THREADS, &o->threads)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--isa") == 0) {
            VALUE();
            if (!cli_parse_isa(cmd, a, v, &o->isa)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--eye") == 0 || strcmp(a, "--look") == 0 || strcmp(a, "--up") == 0) {
            VALUE();
            float *dst = a[2] == 'e' ? o->eye : (a[2] == 'l' ? o->look : o->up);
            if (!cli_parse_vec3(cmd, a, v, dst)) return CLI_EXIT_USAGE;
            *(a[2] == 'e' ? &o->has_eye : (a[2] == 'l' ? &o->has_look : &o->has_up)) = true;
        } else if (strcmp(a, "--fov") == 0) {
            VALUE();
            if (!cli_parse_float(cmd, a, v, 0.0, 180.0, true, &o->fov)) return CLI_EXIT_USAGE;
            o->has_fov = true;
        } else if (strcmp(a, "--integrator") == 0 || strcmp(a, "--shading") == 0) {
            VALUE();
            static const struct { const char *name; rp_integrator_type integrator; } integrators[] = {
                {"whitted", RP_INTEGRATOR_WHITTED}, {"path", RP_INTEGRATOR_PATH},
                {"direct", RP_INTEGRATOR_DIRECT},   {"ao", RP_INTEGRATOR_AO}};
            bool known = false;
            o->has_render = false;
            if (strcmp(v, "eyelight") == 0) {
                o->sd.shading = STREAM_SHADE_EYELIGHT, known = true;
            } else if (strcmp(a, "--shading") == 0 && strcmp(v, "shadow") == 0) {
                o->sd.shading = STREAM_SHADE_SHADOW, known = true;
            } else if (strcmp(a, "--integrator") == 0) {
                for (size_t k = 0; k < sizeof integrators / sizeof integrators[0]; k++)
                    if (strcmp(v, integrators[k].name) == 0)
                        o->rd.integrator = integrators[k].integrator, o->has_render = known = true;
            }
            if (!known) {
                fprintf(stderr,
                        "raypack %s: the stream engine shades eyelight or shadow (--shading), or integrates "
                        "eyelight, whitted, path, direct or ao (--integrator), not '%s'\n",
                        cmd, v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--spp") == 0) {
            VALUE();
            if (!cli_parse_int(cmd, a, v, 1, 65536, &o->rd.spp)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--max-depth") == 0 || strcmp(a, "--reflect-depth") == 0 ||
                   strcmp(a, "--refract-depth") == 0) {
            VALUE();
            int *dst = a[2] == 'm' ? &o->max_depth : (a[4] == 'f' && a[5] == 'l' ? &o->reflect_depth : &o->refract_depth);
            if (!cli_parse_int(cmd, a, v, 0, 64, dst)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--sampler") == 0) {
            VALUE();
            if (strcmp(v, "pcg") != 0 && strcmp(v, "sobol") != 0) {
                fprintf(stderr, "raypack %s: --sampler expects pcg or sobol, got '%s'\n", cmd, v);
                return CLI_EXIT_USAGE;
            }
            o->rd.sampler = v[0] == 's' ? RP_SAMPLER_SOBOL : RP_SAMPLER_PCG;
        } else if (strcmp(a, "--exposure") == 0) {
            VALUE();
            if (!cli_parse_float(cmd, a, v, -64.0, 64.0, false, &o->exposure)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--tonemap") == 0) {
            VALUE();
            if (strcmp(v, "srgb") != 0 && strcmp(v, "aces") != 0) {
                fprintf(stderr, "raypack %s: --tonemap expects srgb or aces, got '%s'\n", cmd, v);
                return CLI_EXIT_USAGE;
            }
            o->tonemap = v[0] == 'a' ? RP_TONEMAP_ACES : RP_TONEMAP_SRGB;
        } else if (strcmp(a, "--anim-flat") == 0) {
            /* the grid holds a flat scene: animated scenes are built flat anyway */
        } else if (strcmp(a, "--density") == 0) {
            VALUE();
            if (!cli_parse_float(cmd, a, v, 0.0, 1000.0, true, &o->gd.density)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--min-dim") == 0) {
            VALUE();
            if (!cli_parse_int(cmd, a, v, 1, 4096, &o->gd.min_dim)) return CLI_EXIT_USAGE;
        } else if (cli_is_medium_flag(a)) {
            VALUE();
            if (!cli_parse_medium_flag(cmd, a, v, &o->vol)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--oracle") == 0) {
            VALUE();
            if (!cli_parse_float(cmd, a, v, 0.0, 1.0, false, &o->sd.oracle)) return CLI_EXIT_USAGE;
            if (o->sd.oracle == 0.0f) o->sd.oracle = 1e-9f; /* 0: intersect when any ray needs it */
        } else if (a[0] == '-' && a[1] != '\0') {
            fprintf(stderr, "raypack %s: unknown option '%s' with the stream engine (see --help)\n", cmd, a);
            return CLI_EXIT_USAGE;
        } else if (!o->scene) {
            o->scene = a;
        } else {
            fprintf(stderr, "raypack %s: expected one SCENE, got '%s' and '%s'\n", cmd, o->scene, a);
            return CLI_EXIT_USAGE;
        }
#undef VALUE
    }
    if (!o->scene) {
        fprintf(stderr, "raypack %s: the stream engine needs a SCENE\n", cmd);
        return CLI_EXIT_USAGE;
    }
    int cam_status = cli_camera_flags_check(cmd, o->has_eye ? o->eye : NULL, o->has_look ? o->look : NULL,
                                            o->has_up ? o->up : NULL);
    if (cam_status != CLI_EXIT_OK) return cam_status;
    /* rp_render_desc's depths as `render` sets them: 0 is the default (5), negative is none */
    const int *in[3] = {&o->max_depth, &o->reflect_depth, &o->refract_depth};
    int *out[3] = {&o->rd.max_depth, &o->rd.reflect_depth, &o->rd.refract_depth};
    for (int k = 0; k < 3; k++) *out[k] = *in[k] < 0 ? 0 : (*in[k] == 0 ? -1 : *in[k]);
    if (o->has_render) {
        o->sd.render = &o->rd;
    } else if (o->rd.spp > 1) { /* eye light's samples come with the renderer's desc */
        if (o->sd.shading == STREAM_SHADE_SHADOW) {
            fprintf(stderr, "raypack %s: --shading shadow traces one sample a pixel, not --spp %d\n", cmd, o->rd.spp);
            return CLI_EXIT_USAGE;
        }
        o->rd.integrator = RP_INTEGRATOR_EYELIGHT;
        o->sd.render = &o->rd;
    }
    return CLI_EXIT_OK;
}

static void print_stats(const stream_stats *s) {
    double r = s->rays ? (double)s->rays : 1.0;
    printf("stream   %llu rays (%llu eye, %llu shadow), %llu eye hits, %llu shadow rays blocked, %.1f ms\n",
           (unsigned long long)s->rays, (unsigned long long)s->eye_rays, (unsigned long long)s->shadow_rays,
           (unsigned long long)s->eye_hits, (unsigned long long)s->shadow_blocked, s->ms);
    printf("per ray  voxels %.2f, triangles tested %.2f, shading evaluations %.2f\n", (double)s->voxels / r,
           (double)s->tests / r, (double)s->shades / r);
    printf("passes   total %llu = traversal %llu + intersection %llu + other %llu\n", (unsigned long long)s->passes,
           (unsigned long long)s->traversal_passes, (unsigned long long)s->intersection_passes,
           (unsigned long long)s->other_passes);
    printf("max/ray  traversals %u, intersections %u; SIMD efficiency %.3f\n", s->max_voxels, s->max_tests,
           s->simd_efficiency);
    if (s->cutouts)
        printf("cutouts  %llu hits on cut-out points passed over (%.2f per ray; in the tests, not the hits)\n",
               (unsigned long long)s->cutouts, (double)s->cutouts / r);
    static const char *kinds[RP_RAY_KIND_COUNT] = {"primary", "shadow", "reflection", "refraction", "bounce"};
    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) {
        const stream_kind_stats *ks = &s->kind[k];
        if (!ks->rays) continue;
        double kr = (double)ks->rays;
        printf("%-10s %llu rays, %llu %s, %llu streams; per ray voxels %.2f, tests %.2f; passes traversal %llu + "
               "intersection %llu; max %u / %u\n",
               kinds[k], (unsigned long long)ks->rays, (unsigned long long)ks->hits,
               k == RP_RAY_SHADOW ? "blocked" : "hits", (unsigned long long)ks->batches, (double)ks->voxels / kr,
               (double)ks->tests / kr, (unsigned long long)ks->traversal_passes,
               (unsigned long long)ks->intersection_passes, ks->max_voxels, ks->max_tests);
    }
}

/* Loads the scene, builds the render scene and the grid. */
typedef struct loaded {
    rp_scene_data data;
    rp_device *device;
    rp_render_scene *rs;
    grid *g;
    rp_camera cam;
    int w, h;
} loaded;

static void unload(loaded *l) {
    grid_free(l->g);
    rp_render_scene_release(l->rs);
    if (l->device) rp_device_release(l->device);
    rp_scene_data_free(&l->data);
}

static bool load(const char *cmd, const stream_opts *o, int default_w, int default_h, loaded *l) {
    memset(l, 0, sizeof *l);
    char err[512] = "";
    rp_scene_load_desc ld;
    rp_scene_load_desc_defaults(&ld);
    ld.volume_grid = o->vol.vdb_grid;
    ld.warning = cli_load_warning;
    if (!rp_scene_data_load_ex(o->scene, &ld, &l->data, err, sizeof err)) {
        fprintf(stderr, "%s\n", err[0] ? err : "cannot load the scene");
        return false;
    }
    if (!cli_apply_medium(&o->vol, &l->data, err, sizeof err)) {
        fprintf(stderr, "raypack %s: %s\n", cmd, err);
        return false;
    }
    if (l->data.volume && o->sd.shading == STREAM_SHADE_SHADOW && !o->sd.render) {
        fprintf(stderr, "raypack %s: the stream engine's shadow shading does not show a participating medium "
                        "(use --integrator eyelight, whitted, path, direct or ao)\n", cmd);
        return false;
    }
    if (!(l->device = cli_device_new(cmd, o->threads, o->isa))) return false;
    /* flat: the grid holds one level of primitives, no instances */
    rp_render_scene_desc sdesc = {.flatten_animation = true, .medium = o->vol.medium};
    if (!(l->rs = rp_render_scene_new(l->device, &l->data, &sdesc, err, sizeof err))) {
        fprintf(stderr, "raypack %s: %s\n", cmd, err);
        return false;
    }
    if (!(l->g = grid_build_scene(rp_render_scene_core(l->rs), &o->gd, err, sizeof err))) {
        fprintf(stderr, "raypack %s: %s: %s\n", cmd, o->scene, err);
        return false;
    }
    l->cam = rp_render_scene_default_camera(l->rs);
    if (o->has_eye) memcpy(l->cam.pinhole.eye, o->eye, sizeof o->eye);
    if (o->has_look) memcpy(l->cam.pinhole.look, o->look, sizeof o->look);
    if (o->has_up) memcpy(l->cam.pinhole.up, o->up, sizeof o->up);
    if (o->has_fov) l->cam.pinhole.fov_deg = o->fov;
    if (cli_camera_check(cmd, o->scene, l->cam.pinhole.eye, l->cam.pinhole.look, l->cam.pinhole.up, o->has_eye,
                         o->has_look, o->has_up) != CLI_EXIT_OK)
        return false; /* its rays would be NaN, or one line */
    int sw = default_w ? default_w : (l->data.camera.width > 0 ? l->data.camera.width : 512);
    int sh = default_h ? default_h : (l->data.camera.height > 0 ? l->data.camera.height : 512);
    l->w = o->width, l->h = o->height;
    if (!l->w && !l->h) l->w = sw, l->h = sh;
    else if (!l->h) l->h = (int)fmax(1.0, floor((double)l->w * sh / sw + 0.5));
    else if (!l->w) l->w = (int)fmax(1.0, floor((double)l->h * sw / sh + 0.5));
    return true;
}

static void print_grid(const grid *g) {
    printf("grid     %dx%dx%d voxels, %u full, %u triangles, %u other primitives, %zu references, %.2f MiB, build %.1f ms\n",
           g->res[0], g->res[1], g->res[2], g->nonempty, g->tri_count, g->prim_count, g->item_count,
           (double)grid_bytes(g) / 1048576.0, g->build_ms);
}

int cli_stream_render(int argc, char **argv) {
    stream_opts o = {.output = "raypack.png", .max_depth = -1, .reflect_depth = -1, .refract_depth = -1};
    int rc = parse("render", argc, argv, &o, false);
    if (rc) return rc < 0 ? CLI_EXIT_OK : rc;
    loaded l;
    int status = CLI_EXIT_FAILURE;
    float *px = NULL;
    if (!load("render", &o, 0, 0, &l)) goto done;
    o.sd.width = l.w, o.sd.height = l.h, o.sd.camera = &l.cam;
    px = malloc((size_t)l.w * (size_t)l.h * 3 * sizeof(float));
    char err[512] = "";
    stream_stats st;
    if (!px || !stream_render(l.rs, l.g, &o.sd, px, NULL, &st, err, sizeof err)) {
        fprintf(stderr, "raypack render: %s\n", px ? err : "out of memory");
        goto done;
    }
    /* 8-bit outputs as `render` writes them: exposure, tone map, sRGB */
    const char *dot = strrchr(o.output, '.');
    if (dot && (strcasecmp(dot, ".png") == 0 || strcasecmp(dot, ".ppm") == 0))
        rp_film_tonemap(px, (size_t)l.w * (size_t)l.h, 3, o.exposure, o.tonemap);
    if (!rp_image_write(o.output, l.w, l.h, 3, px, err, sizeof err)) {
        fprintf(stderr, "raypack render: %s\n", err);
        goto done;
    }
    if (!o.quiet) {
        static const char *names[] = {[RP_INTEGRATOR_WHITTED] = "whitted", [RP_INTEGRATOR_PATH] = "path",
                                      [RP_INTEGRATOR_EYELIGHT] = "eyelight",
                                      [RP_INTEGRATOR_DIRECT] = "direct", [RP_INTEGRATOR_AO] = "ao"};
        if (o.sd.render)
            printf("image    %s: %dx%d, stream engine, %s integrator, %d spp\n", o.output, l.w, l.h,
                   names[o.rd.integrator], o.rd.spp > 0 ? o.rd.spp : 1);
        else
            printf("image    %s: %dx%d, stream engine, %s shading\n", o.output, l.w, l.h,
                   o.sd.shading == STREAM_SHADE_SHADOW ? "shadow" : "eyelight");
        if (o.stats) print_grid(l.g), print_stats(&st);
    }
    status = CLI_EXIT_OK;
done:
    free(px);
    unload(&l);
    return status;
}

/* Mrays/s of one thread tracing the eye rays one at a time, through the grid or the BVH. */
static double time_rays(rp_scene *scene, const grid *g, rp_rayhit *rays, size_t n, rp_rayhit *out) {
    double t0 = cli_now_ms();
    for (size_t i = 0; i < n; i++) {
        out[i] = rays[i];
        if (g)
            grid_intersect1(g, &out[i], NULL);
        else
            rp_intersect1(scene, &out[i]);
    }
    double ms = cli_now_ms() - t0;
    return ms > 0.0 ? (double)n / (ms * 1e3) : 0.0;
}

/* Mrays/s of one thread tracing occlusion rays one at a time, through the grid or the BVH. */
static double time_shadow(rp_scene *scene, const grid *g, const rp_rayhit *rays, size_t n, rp_ray *out) {
    double t0 = cli_now_ms();
    for (size_t i = 0; i < n; i++) {
        out[i] = rays[i].ray;
        if (g)
            grid_occluded1(g, &out[i], NULL);
        else
            rp_occluded1(scene, &out[i]);
    }
    double ms = cli_now_ms() - t0;
    return ms > 0.0 ? (double)n / (ms * 1e3) : 0.0;
}

/* The secondary rays of the eye rays' hits (the BVH's), packed at the front of out: shadow rays
 * to a point (segments ending just short of it) or mirror reflections about the
 * geometric normal, both leaving the hit point on the side the eye ray came from (offset along
 * the normal by 1e-4 of the scene's size plus 2^-18 of the point's magnitude). Returns their
 * count. */
static size_t secondary_rays(const rp_rayhit *eye, size_t n, const float light[3], float size, bool shadow,
                             rp_rayhit *out) {
    size_t m = 0;
    for (size_t i = 0; i < n; i++) {
        const rp_ray *r = &eye[i].ray;
        const rp_hit *h = &eye[i].hit;
        if (h->geom_id == RP_INVALID_ID) continue;
        float d[3] = {r->dir_x, r->dir_y, r->dir_z}, nn[3] = {h->Ng_x, h->Ng_y, h->Ng_z};
        float p[3] = {r->org_x + r->tfar * d[0], r->org_y + r->tfar * d[1], r->org_z + r->tfar * d[2]};
        float len = sqrtf(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]);
        if (!(len > 0.0f)) continue;
        float dn = (d[0] * nn[0] + d[1] * nn[1] + d[2] * nn[2]) / len;
        float side = dn > 0.0f ? -1.0f : 1.0f, q[3], w[3], tfar = INFINITY;
        for (int k = 0; k < 3; k++) {
            nn[k] /= len;
            q[k] = p[k] + side * nn[k] * (1e-4f * size + fabsf(p[k]) * 0x1p-18f);
        }
        if (shadow) {
            for (int k = 0; k < 3; k++) w[k] = light[k] - q[k];
            tfar = 0.999f;
        } else {
            for (int k = 0; k < 3; k++) w[k] = d[k] - 2.0f * dn * nn[k];
        }
        rp_rayhit *o = &out[m++];
        memset(o, 0, sizeof *o);
        o->ray = (rp_ray){.org_x = q[0], .org_y = q[1], .org_z = q[2], .dir_x = w[0], .dir_y = w[1], .dir_z = w[2],
                          .tfar = tfar, .mask = 0xFFFFFFFFu};
        o->hit.geom_id = o->hit.prim_id = o->hit.inst_id = RP_INVALID_ID;
    }
    return m;
}

/* The grid against the BVH on the eye hits' shadow and reflection rays, one thread, single rays:
 * prints a line per kind and returns how many answers differ. */
static size_t bench_secondary(rp_scene *scene, const grid *g, const loaded *l, const rp_rayhit *eye, size_t n,
                              rp_rayhit *rays, rp_rayhit *a, rp_rayhit *b) {
    const rp_scene_data *d = &l->data;
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < d->vertex_count; i++)
        for (int k = 0; k < 3; k++) lo[k] = fminf(lo[k], d->positions[3 * i + k]), hi[k] = fmaxf(hi[k], d->positions[3 * i + k]);
    float size = fmaxf(hi[0] - lo[0], fmaxf(hi[1] - lo[1], hi[2] - lo[2]));
    if (!(size > 0.0f && size < INFINITY)) size = 1.0f;
    /* the first point light, else halfway from the scene's middle to the eye (inside a room, in
     * front of an object) */
    float light[3];
    for (int k = 0; k < 3; k++) light[k] = 0.25f * (lo[k] + hi[k]) + 0.5f * l->cam.pinhole.eye[k];
    for (size_t i = 0; i < d->light_count; i++)
        if (d->lights[i].type == RP_LIGHT_DATA_POINT) {
            memcpy(light, d->lights[i].position, sizeof light);
            break;
        }
    size_t differ_all = 0;
    for (int kind = 0; kind < 2; kind++) {
        size_t m = secondary_rays(eye, n, light, size, kind == 0, rays), differ = 0, hit = 0;
        double mg, mb;
        if (kind == 0) {
            rp_ray *ra = (rp_ray *)a, *rb = (rp_ray *)b; /* an rp_ray fits in an rp_rayhit */
            mg = time_shadow(scene, g, rays, m, ra), mb = time_shadow(scene, NULL, rays, m, rb);
            for (size_t i = 0; i < m; i++) {
                bool oa = ra[i].tfar == -INFINITY, ob = rb[i].tfar == -INFINITY;
                differ += oa != ob, hit += ob;
            }
        } else {
            mg = time_rays(scene, g, rays, m, a), mb = time_rays(scene, NULL, rays, m, b);
            for (size_t i = 0; i < m; i++) {
                differ += a[i].hit.geom_id != b[i].hit.geom_id || a[i].hit.prim_id != b[i].hit.prim_id ||
                          memcmp(&a[i].ray.tfar, &b[i].ray.tfar, sizeof(float)) != 0;
                hit += b[i].hit.geom_id != RP_INVALID_ID;
            }
        }
        printf("%-8s one thread, single rays: grid %.2f Mrays/s, BVH (%s) %.2f Mrays/s, grid/BVH time %.2fx; "
               "%zu rays (%zu %s), %zu differ\n",
               kind == 0 ? "shadow" : "reflect", mg, kind == 0 ? "rp_occluded1" : "rp_intersect1", mb,
               mg > 0.0 ? mb / mg : 0.0, m, hit, kind == 0 ? "occluded" : "hit", differ);
        differ_all += differ;
    }
    return differ_all;
}

int cli_stream_bench(int argc, char **argv) {
    stream_opts o = {.max_depth = -1, .reflect_depth = -1, .refract_depth = -1};
    int rc = parse("bench", argc, argv, &o, true);
    if (rc) return rc < 0 ? CLI_EXIT_OK : rc;
    if (o.purcell && !o.gd.min_dim && !(o.gd.density > 0.0f)) o.gd.min_dim = 64;
    /* the paper's bunny fills its view (s = 0.82: 82% of the eye rays hit); the scene's framing
     * camera narrowed to 11 degrees hits 82% of them too */
    if (o.purcell && !o.has_fov && !o.has_eye && !o.has_look) o.fov = 11.0f, o.has_fov = true;
    loaded l;
    int status = CLI_EXIT_FAILURE;
    rp_rayhit *hits = NULL, *a = NULL, *b = NULL, *sec = NULL;
    float *px = NULL;
    if (!load("bench", &o, 1024, 1024, &l)) goto done;
    o.sd.width = l.w, o.sd.height = l.h, o.sd.camera = &l.cam;
    size_t n = (size_t)l.w * (size_t)l.h;
    px = malloc(n * 3 * sizeof(float));
    hits = malloc(n * sizeof(rp_rayhit));
    a = malloc(n * sizeof(rp_rayhit));
    b = malloc(n * sizeof(rp_rayhit));
    sec = malloc(n * sizeof(rp_rayhit));
    if (!px || !hits || !a || !b || !sec) {
        fprintf(stderr, "raypack bench: out of memory for %zu rays\n", n);
        goto done;
    }
    char err[512] = "";
    stream_stats st;
    if (!stream_render(l.rs, l.g, &o.sd, px, hits, &st, err, sizeof err)) {
        fprintf(stderr, "raypack bench: %s\n", err);
        goto done;
    }
    /* the other scheduler, for comparison */
    stream_desc other = o.sd;
    other.wavefront = !o.sd.wavefront;
    stream_stats st_other;
    if (!stream_render(l.rs, l.g, &other, px, NULL, &st_other, err, sizeof err)) {
        fprintf(stderr, "raypack bench: %s\n", err);
        goto done;
    }
    /* the eye rays again, one at a time through the grid and the BVH: same hits, and the ratio */
    for (size_t i = 0; i < n; i++) {
        hits[i].ray.tfar = INFINITY;
        hits[i].hit = (rp_hit){.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID};
    }
    rp_scene *scene = rp_render_scene_core(l.rs);
    double mg = time_rays(scene, l.g, hits, n, a), mb = time_rays(scene, NULL, hits, n, b);
    size_t differ = 0;
    for (size_t i = 0; i < n; i++)
        differ += a[i].hit.geom_id != b[i].hit.geom_id || a[i].hit.prim_id != b[i].hit.prim_id ||
                  memcmp(&a[i].ray.tfar, &b[i].ray.tfar, sizeof(float)) != 0;
    printf("scene    %s: %zu triangles, %dx%d eye rays\n", o.scene, l.data.triangle_count, l.w, l.h);
    print_grid(l.g);
    print_stats(&st);
    printf("%s passes total %llu = traversal %llu + intersection %llu + other %llu, SIMD efficiency %.3f; "
           "%.1f ms (%s %.1f ms)\n",
           other.wavefront ? "wavefront" : "multipass", (unsigned long long)st_other.passes,
           (unsigned long long)st_other.traversal_passes, (unsigned long long)st_other.intersection_passes,
           (unsigned long long)st_other.other_passes, st_other.simd_efficiency, st_other.ms,
           o.sd.wavefront ? "wavefront" : "multipass", st.ms);
    printf("primary  one thread, single rays: grid %.2f Mrays/s, BVH (rp_intersect1) %.2f Mrays/s, "
           "grid/BVH time %.2fx; %zu of %zu hits differ\n",
           mg, mb, mg > 0.0 ? mb / mg : 0.0, differ, n);
    memcpy(hits, b, n * sizeof *b); /* the BVH's eye hits, where the secondary rays start */
    differ += bench_secondary(scene, l.g, &l, hits, n, sec, a, b);
    if (o.purcell) {
        const stream_paper_row *p = &stream_paper_table2[stream_paper_table2_count - 1];
        double r = st.rays ? (double)st.rays : 1.0;
        printf("\nPurcell et al. 2002, bunny ray cast (69,451 triangles, 1024x1024, grid 98x64x163) beside this run\n");
        printf("%-22s %10s %10s\n", "", "paper", "raypack");
        printf("%-22s %10.2f %10.2f\n", "fig. 6 v (voxels/ray)", 93.93, (double)st.voxels / r);
        printf("%-22s %10.2f %10.2f\n", "fig. 6 t (tests/ray)", 13.88, (double)st.tests / r);
        printf("%-22s %10.2f %10.2f\n", "fig. 6 s (shades/ray)", 0.82, (double)st.shades / r);
        printf("%-22s %10d %10llu\n", "passes total", p->passes, (unsigned long long)st.passes);
        printf("%-22s %10d %10llu\n", "passes traversal", p->traversal, (unsigned long long)st.traversal_passes);
        printf("%-22s %10d %10llu\n", "passes intersection", p->intersection, (unsigned long long)st.intersection_passes);
        printf("%-22s %10d %10llu\n", "passes other", p->other, (unsigned long long)st.other_passes);
        printf("%-22s %10d %10u\n", "max traversals/ray", p->max_traversals, st.max_voxels);
        printf("%-22s %10d %10u\n", "max intersections/ray", p->max_intersections, st.max_tests);
        printf("%-22s %10.3f %10.3f\n", "SIMD efficiency", p->simd_efficiency, st.simd_efficiency);
        printf("(the paper's other scenes, Soda Hall and the forest, are not among the shared scenes:\n");
        for (size_t k = 0; k + 1 < stream_paper_table2_count; k++) {
            p = &stream_paper_table2[k];
            printf(" %s: %d passes = %d + %d + %d, max %d / %d, SIMD %.3f\n", p->scene, p->passes, p->traversal,
                   p->intersection, p->other, p->max_traversals, p->max_intersections, p->simd_efficiency);
        }
        printf(" our view is the scene's framing camera at %.1f degrees, not the paper's exact one)\n",
               (double)l.cam.pinhole.fov_deg);
    }
    status = differ == 0 ? CLI_EXIT_OK : CLI_EXIT_FAILURE;
    if (differ) fprintf(stderr, "raypack bench: the grid's hits differ from the BVH's\n");
done:
    free(px), free(hits), free(a), free(b), free(sec);
    unload(&l);
    return status;
}
