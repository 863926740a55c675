/* `raypack view`: an SDL2 window on rp_render. While the camera is still, frames of one sample each
 * accumulate (samples [k, k+1) through rp_render_desc.sample_start, which sum to what one k-spp
 * render gives); when it moves, the accumulation restarts, at a lower resolution when a full frame
 * would miss the --fps budget. The window's pixels are converted exactly as the PNG writer converts
 * them, so a screenshot of a still camera equals `raypack render --spp N` of the printed camera. */
#include "viewer.h"

#include <SDL.h>
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include "cli.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wswitch-enum"
#pragma GCC diagnostic ignored "-Wunused-function"
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb/stb_image_write.h>
#pragma GCC diagnostic pop

static const char *const CMD = "view";

static void view_usage(FILE *out) {
    fprintf(out,
            "usage: raypack view [SCENE] [render options] [view options]\n"
            "\n"
            "Opens a window on SCENE (the built-in room without one), rendered as `raypack render`\n"
            "renders it: the render options (--width, --height, --integrator, --max-depth, --aov,\n"
            "--threads, --isa, --traversal, --packet, --frustum, --eye, --look, --up, --fov) mean the\n"
            "same, and --spp N stops the accumulation at N samples [1024].\n"
            "\n"
            "view options:\n"
            "  --fps F              frame budget while the camera moves: frames that would take longer\n"
            "                       than 1/F s render at a lower resolution, 1..1000 [20]; while it is\n"
            "                       still, the window shows the accumulating image F times a second\n"
            "                       (the frames between add their samples unseen; F12 and the last\n"
            "                       frame show all of them)\n"
            "  --every-frame        show every frame, also while the camera is still\n"
            "  --frames N           render N frames, then (with --screenshot) save the window, and quit\n"
            "  --screenshot FILE    where --frames and F12 save the window (.png or .ppm, 8-bit sRGB)\n"
            "                       [raypack-view-N.png for F12]\n"
            "  --events FILE        scripted input: SDL events pushed at given frames (see --script)\n"
            "  --script TEXT        the same inline: items 'FRAME ACTION [ARGS]' separated by ';':\n"
            "                       down KEY, up KEY, key KEY (both), press|release left|middle|right X Y,\n"
            "                       move X Y, wheel N, resize W H, quit; keys by SDL name (w, F12,\n"
            "                       Escape, -)\n"
            "  --no-overlay         no text over the image\n"
            "  --log                print a line per frame (size, samples, motion, each phase's time)\n"
            "  --max-scale S        lowest resolution during motion is 1/S of the window's, 1..32 [16]\n"
            "  --compare            after each full-size frame, render it again with rp_render alone (not\n"
            "                       shown, into a sum of its own as render --time does) and report the\n"
            "                       window's cost against that in CPU time\n"
            "\n"
            "keys: W/S A/D Q/E fly (Shift: 4x faster), right mouse button: look, left button: orbit\n"
            "  about the point under the cursor, wheel: fly speed, - and =: field of view, P: print the\n"
            "  camera as flags, F12: screenshot, I: integrator, T: traversal, K: packet size (then\n"
            "  single rays), F: frusta on/off, , and .: max depth, O: overlay, R: the scene's camera,\n"
            "  H: this list, Escape: quit. With --frames or a script, motion per frame is fixed\n"
            "  (speed / fps) so that runs repeat exactly. The window can be resized: the image takes\n"
            "  its new size pixel for pixel and the accumulation restarts.\n");
}

typedef struct view_options {
    int frames, max_scale;
    float fps;
    const char *screenshot, *events, *script;
    bool overlay, log, compare, every_frame;
} view_options;

/* Splits argv into the viewer's own flags and the render flags (left in rargv for cli_render_parse). */
static int parse_view_options(int argc, char **argv, view_options *o, char **rargv, int *rargc, bool *help) {
    *rargc = 0;
    rargv[(*rargc)++] = argv[0];
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = NULL;
#define VALUE()                                                                  \
    do {                                                                         \
        if (!(v = cli_flag_value(CMD, argc, argv, &i))) return CLI_EXIT_USAGE;   \
    } while (0)
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            *help = true;
            return CLI_EXIT_OK;
        } else if (strcmp(a, "--fps") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 1.0, 1000.0, false, &o->fps)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--frames") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 100000000, &o->frames)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--max-scale") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 32, &o->max_scale)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--screenshot") == 0) {
            VALUE();
            const char *dot = strrchr(v, '.');
            if (!dot || (strcasecmp(dot, ".png") != 0 && strcasecmp(dot, ".ppm") != 0)) {
                fprintf(stderr, "raypack view: --screenshot expects a file ending in .png or .ppm, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
            o->screenshot = v;
        } else if (strcmp(a, "--events") == 0) {
            VALUE();
            o->events = v;
        } else if (strcmp(a, "--script") == 0) {
            VALUE();
            o->script = v;
        } else if (strcmp(a, "--no-overlay") == 0) {
            o->overlay = false;
        } else if (strcmp(a, "--compare") == 0) {
            o->compare = true;
        } else if (strcmp(a, "--log") == 0) {
            o->log = true;
        } else if (strcmp(a, "--every-frame") == 0) {
            o->every_frame = true;
        } else if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0 || strcmp(a, "--stats") == 0 ||
                   strcmp(a, "--stats-json") == 0 || strcmp(a, "--quiet") == 0 || strcmp(a, "-q") == 0) {
            fprintf(stderr, "raypack view: %s is an option of raypack render (the viewer saves with --screenshot)\n",
                    a);
            return CLI_EXIT_USAGE;
        } else {
            rargv[(*rargc)++] = argv[i];
        }
#undef VALUE
    }
    rargv[*rargc] = NULL;
    return CLI_EXIT_OK;
}

/* Reads a whole small text file; NULL after printing why. */
static char *read_text(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "raypack view: cannot open %s: %s\n", path, strerror(errno));
        return NULL;
    }
    size_t cap = 4096, n = 0;
    char *buf = malloc(cap);
    while (buf) {
        if (n + 1 >= cap) {
            if (cap >= ((size_t)16 << 20)) {
                fprintf(stderr, "raypack view: %s: larger than 16 MiB\n", path);
                free(buf);
                buf = NULL;
                break;
            }
            char *p = realloc(buf, cap *= 2);
            if (!p) {
                free(buf);
                buf = NULL;
                break;
            }
            buf = p;
        }
        size_t got = fread(buf + n, 1, cap - 1 - n, f);
        n += got;
        if (got == 0) break;
    }
    if (buf) buf[n] = '\0';
    else fprintf(stderr, "raypack view: cannot read %s\n", path);
    fclose(f);
    return buf;
}

/* ---- settings the keys switch ---- */

/* The integrator's name, NULL past the last one: -Wswitch-enum points here when one is added. */
static const char *integrator_name(int t) {
    switch ((rp_integrator_type)t) {
    case RP_INTEGRATOR_WHITTED: return "whitted";
    case RP_INTEGRATOR_EYELIGHT: return "eyelight";
    case RP_INTEGRATOR_AOV: return "aov";
    case RP_INTEGRATOR_DIRECT: return "direct";
    case RP_INTEGRATOR_PATH: return "path";
    case RP_INTEGRATOR_IR: return "ir";
    case RP_INTEGRATOR_AO: return "ao";
    }
    return NULL;
}

static const char *aov_name(rp_aov a) {
    switch (a) {
    case RP_AOV_DEPTH: return "depth";
    case RP_AOV_NORMAL: return "normal";
    case RP_AOV_PRIMID: return "primid";
    case RP_AOV_ALBEDO: return "albedo";
    }
    return "?";
}

/* The traversal's name, NULL past the last one. */
static const char *traversal_name(int t) {
    switch ((rp_traversal)t) {
    case RP_TRAVERSAL_AUTO: return "auto";
    case RP_TRAVERSAL_MASKED: return "masked";
    case RP_TRAVERSAL_RANGED: return "ranged";
    case RP_TRAVERSAL_PARTITION: return "partition";
    case RP_TRAVERSAL_SINGLE: return "single";
    case RP_TRAVERSAL_SIMD: return "simd";
    case RP_TRAVERSAL_SPAN: return "span";
    case RP_TRAVERSAL_MLRT: return "mlrt";
    }
    return NULL;
}

/* The next integrator (the AOVs one by one, but depth, which has one channel). */
static void next_integrator(rp_render_desc *d) {
    if (d->integrator == RP_INTEGRATOR_AOV && d->aov < RP_AOV_ALBEDO) {
        d->aov = (rp_aov)(d->aov + 1);
        return;
    }
    int t = (int)d->integrator + 1;
    if (!integrator_name(t)) t = 0;
    d->integrator = (rp_integrator_type)t;
    if (d->integrator == RP_INTEGRATOR_AOV) d->aov = RP_AOV_NORMAL;
}

/* Whether frames of further samples change the image (AOVs trace the pixel centre only). */
static bool accumulates(const rp_render_desc *d) { return d->integrator != RP_INTEGRATOR_AOV; }

/* ---- the viewer ---- */

typedef struct viewer {
    view_options opt;
    cli_render_setup setup;
    rp_scene_data data;
    bool loaded;
    rp_device *dev;
    rp_render_scene *scene;
    int w, h;                   /* the window's and the full resolution's size */
    rp_render_desc desc;        /* settings; size, camera and samples set per frame */
    view_camera cam, home;
    float *frame, *sum;         /* w * h * 3: the last rp_render output, the accumulated samples */
    uint32_t *disp;             /* w * h xRGB8888: what the window shows, when its surface is not that */
    uint32_t *lines;            /* a row of w pixels per device thread, for reduced frames */
    uint32_t *out;              /* where this frame's pixels go: the window's surface itself or disp */
    int out_pitch;              /* in pixels */
    bool direct;                /* out is the window's surface */
    int samples;                /* accumulated at full resolution */
    int shown_samples;          /* of the frame in the window's pixels */
    double shown_ms;            /* when the last frame that the window shows was rendered */
    int spp_max;
    int depth;                  /* max depth, 0..64 (rp_render_desc's 0 is its default, 5) */
    int scale;                  /* divisor of the last frame's resolution */
    double full_ms;             /* estimate of a full-resolution frame's rp_render time */
    double overhead_ms;         /* conversion and presentation, smoothed */
    bool deterministic;         /* fixed motion per frame (scripted or --frames runs) */
    SDL_Window *win;
    bool held[8];               /* w a s d q e, shift */
    int look_drag, orbit_drag;  /* buttons held */
    float pivot[3];
    bool overlay, quit, camera_moved, reset, redraw;
    bool pending;               /* the surface holds a frame not shown yet */
    int screenshots;
    /* what the overlay and the summary report */
    double fps, mrays, last_frame_ms;
    uint64_t total_rays;
    double total_render_ms, total_frame_ms;
    /* the frame's phases after the first frame, in ms (view_phase) */
    double phase_ms[6];           /* wall time per phase */
    float *phase_log;             /* per frame after the first: the phases and the frame, for medians */
    int phase_frames, phase_cap;
    double cpu_render, cpu_convert, cpu_all; /* process CPU time: the render phase, converting, all */
    double bytes;                 /* touched by the conversion, in total */
    const char *srgb;             /* how the conversion runs (view_srgb_select) */
    float *scratch;               /* --compare: where rp_render alone renders */
    double cmp_view_cpu, cmp_ref_cpu; /* --compare: process CPU of the viewer's frames, of rp_render alone */
    int cmp_frames;
    int cmp_samples;              /* --compare: the samples scratch holds summed (as sum holds them) */
    int frames_done;
    bool playing;               /* space: an animated scene's time runs (frame 0 until then) */
    double anim_t;
    /* rp_render runs on a thread of its own, made once: a thread a frame would fault its stack's
     * pages in again every frame, after glibc's madvise of the last one's (a TLB shootdown) */
    bool render_started, render_quit;
    pthread_t render_th;
    pthread_mutex_t render_lock;
    pthread_cond_t render_cv;  /* a call was posted, or the posted one is done */
    struct render_call *render_job; /* the posted call; NULL once done */
} viewer;

enum { HELD_W, HELD_A, HELD_S, HELD_D, HELD_Q, HELD_E, HELD_SHIFT };

static void print_settings(const viewer *v) {
    const rp_render_desc *d = &v->desc;
    printf("settings: integrator %s", integrator_name((int)d->integrator));
    if (d->integrator == RP_INTEGRATOR_AOV) printf(" %s", aov_name(d->aov));
    printf(", max depth %d, packet %d, traversal %s, frusta %s\n", v->depth, d->packet,
           traversal_name((int)d->traversal), d->no_frustum ? "off" : "on");
    fflush(stdout);
}

static bool flush(viewer *v);
static bool catch_up(viewer *v);

/* Writes the window's pixels (read back from its surface, after showing what is pending) to path. */
static bool save_screenshot(viewer *v, const char *path) {
    if (!catch_up(v) || !flush(v)) return false;
    SDL_Surface *s = SDL_GetWindowSurface(v->win);
    if (!s) {
        fprintf(stderr, "raypack view: cannot read the window: %s\n", SDL_GetError());
        return false;
    }
    uint8_t *rgb = malloc((size_t)s->w * (size_t)s->h * 3);
    if (!rgb) {
        fprintf(stderr, "raypack view: out of memory for a screenshot\n");
        return false;
    }
    bool ok = true;
    if (SDL_MUSTLOCK(s)) SDL_LockSurface(s);
    if (SDL_ConvertPixels(s->w, s->h, s->format->format, s->pixels, s->pitch, SDL_PIXELFORMAT_RGB24, rgb, s->w * 3) !=
        0) {
        fprintf(stderr, "raypack view: cannot read the window: %s\n", SDL_GetError());
        ok = false;
    }
    if (SDL_MUSTLOCK(s)) SDL_UnlockSurface(s);
    if (ok) {
        const char *dot = strrchr(path, '.');
        if (dot && strcasecmp(dot, ".ppm") == 0) {
            FILE *f = fopen(path, "wb");
            ok = f && fprintf(f, "P6\n%d %d\n255\n", s->w, s->h) > 0 &&
                 fwrite(rgb, 1, (size_t)s->w * (size_t)s->h * 3, f) == (size_t)s->w * (size_t)s->h * 3;
            if (f && fclose(f) != 0) ok = false;
        } else {
            ok = stbi_write_png(path, s->w, s->h, 3, rgb, s->w * 3) != 0;
        }
        if (!ok) fprintf(stderr, "raypack view: cannot write %s: %s\n", path, strerror(errno));
        else printf("screenshot: %s (%dx%d, %d samples)\n", path, s->w, s->h, v->shown_samples);
        fflush(stdout);
    }
    free(rgb);
    return ok;
}

/* The point under pixel (x, y) for orbiting, through one ray of the public API that passes cut-out
 * points as the image does (a leaf's holes are not a pivot); the look-at point when the ray hits
 * nothing. */
static void pick_pivot(viewer *v, int x, int y) {
    float dir[3];
    view_camera_ray(&v->cam, v->w, v->h, (float)x + 0.5f, (float)y + 0.5f, dir);
    rp_rayhit rh;
    memset(&rh, 0, sizeof rh);
    rh.ray.org_x = v->cam.eye[0];
    rh.ray.org_y = v->cam.eye[1];
    rh.ray.org_z = v->cam.eye[2];
    rh.ray.dir_x = dir[0];
    rh.ray.dir_y = dir[1];
    rh.ray.dir_z = dir[2];
    rh.ray.tfar = INFINITY;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.hit.geom_id = RP_INVALID_ID;
    rh.hit.prim_id = RP_INVALID_ID;
    rh.hit.inst_id = RP_INVALID_ID;
    rp_render_scene_intersect1(v->scene, &rh);
    if (rh.hit.geom_id != RP_INVALID_ID) {
        for (int k = 0; k < 3; k++) v->pivot[k] = v->cam.eye[k] + dir[k] * rh.ray.tfar;
    } else {
        memcpy(v->pivot, v->cam.look, sizeof v->pivot);
    }
}

static void print_keys(void) {
    printf("keys: W/S A/D Q/E fly (Shift 4x), right drag look, left drag orbit, wheel speed, - = fov,\n"
           "      P camera, F12 screenshot, I integrator, T traversal, K packet, F frusta, , . depth,\n"
           "      O overlay, R reset camera, Space play/pause an animation, Escape quit\n");
    fflush(stdout);
}

static void on_key(viewer *v, const SDL_KeyboardEvent *k, bool down) {
    SDL_Keycode key = k->keysym.sym;
    int held = -1;
    switch (key) {
    case SDLK_w: held = HELD_W; break;
    case SDLK_a: held = HELD_A; break;
    case SDLK_s: held = HELD_S; break;
    case SDLK_d: held = HELD_D; break;
    case SDLK_q: held = HELD_Q; break;
    case SDLK_e: held = HELD_E; break;
    case SDLK_LSHIFT:
    case SDLK_RSHIFT: held = HELD_SHIFT; break;
    default: break;
    }
    if (held >= 0) {
        v->held[held] = down;
        return;
    }
    if (!down || k->repeat) return;
    rp_render_desc *d = &v->desc;
    bool settings = true;
    switch (key) {
    case SDLK_p: view_camera_print(&v->cam, stdout); settings = false; break;
    case SDLK_F12: {
        char name[64];
        const char *path = v->opt.screenshot;
        if (!path) {
            snprintf(name, sizeof name, "raypack-view-%d.png", v->screenshots++);
            path = name;
        }
        save_screenshot(v, path);
        settings = false;
        break;
    }
    case SDLK_i: next_integrator(d); break;
    case SDLK_t: {
        int t = (int)d->traversal + 1;
        d->traversal = (rp_traversal)(traversal_name(t) ? t : 0);
        break;
    }
    case SDLK_k: {
        /* 4, 8, 16, 32, then one ray at a time (the reference tracer) */
        d->packet = d->packet < 0 ? 4 : (d->packet == 32 ? -1 : 2 * d->packet);
        break;
    }
    case SDLK_f: d->no_frustum = !d->no_frustum; break;
    case SDLK_COMMA: v->depth = v->depth > 0 ? v->depth - 1 : 0; break;
    case SDLK_PERIOD: v->depth = v->depth < 64 ? v->depth + 1 : 64; break;
    case SDLK_MINUS:
    case SDLK_KP_MINUS:
        v->cam.fov_deg = fminf(160.0f, v->cam.fov_deg + 5.0f);
        v->camera_moved = true;
        settings = false;
        break;
    case SDLK_EQUALS:
    case SDLK_PLUS:
    case SDLK_KP_PLUS:
        v->cam.fov_deg = fmaxf(5.0f, v->cam.fov_deg - 5.0f);
        v->camera_moved = true;
        settings = false;
        break;
    case SDLK_o: v->overlay = !v->overlay; settings = false; v->reset = true; break;
    case SDLK_r: v->cam = v->home; v->camera_moved = true; settings = false; break;
    case SDLK_h: print_keys(); settings = false; break;
    case SDLK_SPACE:
        if (v->data.animation) {
            v->playing = !v->playing;
            if (v->playing) v->anim_t = v->data.animation->time; /* the start, or where it paused */
            printf("animation: %s at t %.3f\n", v->playing ? "playing" : "paused", v->anim_t);
        } else {
            printf("animation: this scene is not animated\n");
        }
        fflush(stdout);
        settings = false;
        break;
    case SDLK_ESCAPE: v->quit = true; settings = false; break;
    default: settings = false; break;
    }
    if (settings) {
        v->reset = true;
        print_settings(v);
    }
}

static void handle_event(viewer *v, const SDL_Event *e) {
    switch (e->type) {
    case SDL_QUIT: v->quit = true; break;
    case SDL_KEYDOWN:
    case SDL_KEYUP: on_key(v, &e->key, e->type == SDL_KEYDOWN); break;
    case SDL_MOUSEBUTTONDOWN:
        if (e->button.button == SDL_BUTTON_RIGHT) v->look_drag = 1;
        if (e->button.button == SDL_BUTTON_LEFT) {
            v->orbit_drag = 1;
            pick_pivot(v, e->button.x, e->button.y);
            printf("orbit: pivot %.9g,%.9g,%.9g\n", (double)v->pivot[0], (double)v->pivot[1], (double)v->pivot[2]);
            fflush(stdout);
        }
        break;
    case SDL_MOUSEBUTTONUP:
        if (e->button.button == SDL_BUTTON_RIGHT) v->look_drag = 0;
        if (e->button.button == SDL_BUTTON_LEFT) v->orbit_drag = 0;
        break;
    case SDL_MOUSEMOTION: {
        /* a window's width of motion turns by about 180 degrees */
        float k = 3.14159265f / (float)v->w;
        float yaw = -(float)e->motion.xrel * k, pitch = -(float)e->motion.yrel * k;
        if (e->motion.xrel == 0 && e->motion.yrel == 0) break;
        if (v->look_drag) {
            view_camera_turn(&v->cam, yaw, pitch);
            v->camera_moved = true;
        } else if (v->orbit_drag) {
            view_camera_orbit(&v->cam, v->pivot, yaw, pitch);
            v->camera_moved = true;
        }
        break;
    }
    case SDL_MOUSEWHEEL: {
        int steps = e->wheel.direction == SDL_MOUSEWHEEL_FLIPPED ? -e->wheel.y : e->wheel.y;
        v->cam.speed *= powf(1.25f, (float)steps);
        printf("speed: %.9g\n", (double)v->cam.speed);
        fflush(stdout);
        break;
    }
    case SDL_USEREVENT:
        if (e->user.code == VIEW_EVENT_RESIZE)
            SDL_SetWindowSize(v->win, (int)(intptr_t)e->user.data1, (int)(intptr_t)e->user.data2);
        break;
    case SDL_WINDOWEVENT:
        if (e->window.event == SDL_WINDOWEVENT_EXPOSED) v->redraw = true;
        /* keys released elsewhere never come back as key-up events (scripted keys are not affected) */
        if (e->window.event == SDL_WINDOWEVENT_FOCUS_LOST && !v->deterministic) {
            memset(v->held, 0, sizeof v->held);
            v->look_drag = v->orbit_drag = 0;
        }
        break;
    default: break;
    }
}

/* Flies by the held keys for dt seconds. */
static void fly(viewer *v, double dt) {
    float step = v->cam.speed * (float)dt * (v->held[HELD_SHIFT] ? 4.0f : 1.0f);
    float r = (float)(v->held[HELD_D] - v->held[HELD_A]), u = (float)(v->held[HELD_E] - v->held[HELD_Q]),
          f = (float)(v->held[HELD_W] - v->held[HELD_S]);
    if (r == 0.0f && u == 0.0f && f == 0.0f) return;
    view_camera_move(&v->cam, r * step, u * step, f * step);
    v->camera_moved = true;
}

/* ---- from the render buffer to the window's pixels, in bands of rows on the device's threads ---- */

/* The process's CPU time: on a loaded machine they count the work, where
 * the wall clock counts the waits for a core too. */
static double cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* Lets the process's other threads block before its CPU clock is read: the clock adds a thread
 * that runs on another core only up to its last scheduler tick (some milliseconds stale), and a
 * worker spins a while after a render before it sleeps. Without this, --compare charged the CPU
 * the reference's worker spent in its last tick to the viewer's next frame: the window seemed to
 * cost 13-20% on cornell_box when rendering alone cost the same as rp_render (issue 22). */
static void settle_threads(void) {
    struct timespec ts = {0, 2000000}; /* 2 ms: the pool's spin is about 0.1 ms */
    nanosleep(&ts, NULL);
}

/* A frame's way into the window's pixels. The tile renderer calls present_tile on its threads as
 * tiles finish, while the tile is in cache; a tile that finishes while the window still sends the
 * last frame (flush, on the main thread) waits in a list, which the main thread converts once the
 * window is done with its pixels. */
typedef struct present_job {
    viewer *v;
    int fw, fh, scale;     /* the frame's size and its divisor */
    bool accumulate;       /* show sum / samples */
    bool add;              /* the frame is added into sum here (else rp_render adds it: accumulate) */
    int samples;           /* after this frame */
    pthread_mutex_t lock;  /* guards free, waiting and count */
    pthread_cond_t freed;
    atomic_bool free;      /* the window's pixels may be written (set under lock) */
    int (*waiting)[4];     /* tiles to convert once they are */
    int count, cap;
    double *busy_ms;       /* per device thread (8 apart): time in present_tile */
} present_job;

/* Converts the frame's pixels [x0, x1) x [y0, y1) into the window's: the accumulated mean (with
 * add and j->add, the frame is added into the sum first), or a reduced frame's pixels widened to
 * scale x scale blocks; `line` holds a row of the window. */
static void present_rect(const present_job *j, int x0, int y0, int x1, int y1, bool add, uint32_t *line) {
    viewer *v = j->v;
    int n = x1 - x0;
    if (j->accumulate) {
        /* as the tile renderer sums samples, then scales by 1/spp (by 1: the sum itself) */
        float inv = j->samples == 1 ? 1.0f : 1.0f / (float)j->samples;
        size_t at = (size_t)y0 * (size_t)v->w + (size_t)x0;
        view_srgb_rect(v->sum + at * 3, add && j->add ? v->frame + at * 3 : NULL, (size_t)v->w * 3, inv,
                       v->out + (size_t)y0 * (size_t)v->out_pitch + (size_t)x0, (size_t)v->out_pitch, n, y1 - y0);
        return;
    }
    int s = j->scale;
    if (s == 1) {
        view_srgb_rect(v->frame + ((size_t)y0 * (size_t)j->fw + (size_t)x0) * 3, NULL, (size_t)j->fw * 3, 1.0f,
                       v->out + (size_t)y0 * (size_t)v->out_pitch + (size_t)x0, (size_t)v->out_pitch, n, y1 - y0);
        return;
    }
    for (int y = y0; y < y1; y++) {
        float *row = v->frame + ((size_t)y * (size_t)j->fw + (size_t)x0) * 3;
        view_srgb_pixels(row, NULL, 1.0f, line, n);
        int ox0 = x0 * s, ox1 = x1 * s < v->w ? x1 * s : v->w, oy0 = y * s, oy1 = (y + 1) * s < v->h ? (y + 1) * s : v->h;
        uint32_t *out = v->out + (size_t)oy0 * (size_t)v->out_pitch;
        for (int x = ox0; x < ox1; x++) out[x] = line[x / s - x0];
        for (int oy = oy0 + 1; oy < oy1; oy++)
            memcpy(v->out + (size_t)oy * (size_t)v->out_pitch + ox0, out + ox0, (size_t)(ox1 - ox0) * sizeof *out);
    }
}

/* rp_render_desc.tile_done. */
static void present_tile(void *user, int x0, int y0, int x1, int y1, uint32_t thread) {
    present_job *j = user;
    double t0 = cli_now_ms();
    uint32_t *line = j->v->lines + (size_t)thread * (size_t)j->v->w;
    if (atomic_load_explicit(&j->free, memory_order_acquire)) { /* the usual case: no lock */
        present_rect(j, x0, y0, x1, y1, true, line);
        j->busy_ms[8 * thread] += cli_now_ms() - t0;
        return;
    }
    pthread_mutex_lock(&j->lock);
    bool now = atomic_load_explicit(&j->free, memory_order_relaxed);
    if (!now && j->count == j->cap) { /* grow the list; out of memory: wait for the window */
        int cap = j->cap ? 2 * j->cap : 256;
        int (*w)[4] = realloc(j->waiting, (size_t)cap * sizeof *w);
        if (w) {
            j->waiting = w;
            j->cap = cap;
        } else {
            while (!atomic_load_explicit(&j->free, memory_order_relaxed)) pthread_cond_wait(&j->freed, &j->lock);
            now = true;
        }
    }
    if (!now) {
        int *t = j->waiting[j->count++];
        t[0] = x0, t[1] = y0, t[2] = x1, t[3] = y1;
    }
    pthread_mutex_unlock(&j->lock);
    if (now) {
        present_rect(j, x0, y0, x1, y1, true, line);
    } else if (j->accumulate && j->add) {
        /* add the frame now, while it is in cache; the pixels come later, from the sum (each row's
         * codes go to the same scratch line: pitch 0) */
        size_t at = (size_t)y0 * (size_t)j->v->w + (size_t)x0;
        view_srgb_rect(j->v->sum + at * 3, j->v->frame + at * 3, (size_t)j->v->w * 3, 1.0f, line, 0, x1 - x0, y1 - y0);
    }
    j->busy_ms[8 * thread] += cli_now_ms() - t0;
}

/* The window is done with its pixels: tiles from now on convert themselves, and the main thread
 * converts those that waited. */
static void present_release(present_job *j) {
    pthread_mutex_lock(&j->lock);
    atomic_store_explicit(&j->free, true, memory_order_release);
    int n = j->count;
    pthread_cond_broadcast(&j->freed);
    pthread_mutex_unlock(&j->lock);
    /* the list no longer grows: present_tile appends only while free is false */
    uint32_t *line = j->v->lines + (size_t)rp_device_thread_count(j->v->dev) * (size_t)j->v->w;
    for (int i = 0; i < n; i++) {
        const int *t = j->waiting[i];
        present_rect(j, t[0], t[1], t[2], t[3], false, line);
    }
}

/* Darkens a box and writes the overlay's lines into it. */
static void draw_overlay(viewer *v, const char *const *lines, int n) {
    int sc = v->w >= 800 ? 2 : 1, pad = 3 * sc, lh = (VIEW_FONT_H + 3) * sc, bw = 0;
    for (int i = 0; i < n; i++) {
        int lw = view_font_width(lines[i], sc);
        if (lw > bw) bw = lw;
    }
    int x1 = bw + 2 * pad < v->w ? bw + 2 * pad : v->w, y1 = n * lh + 2 * pad - 2 * sc;
    if (y1 > v->h) y1 = v->h;
    for (int y = 0; y < y1; y++)
        for (int x = 0; x < x1; x++) {
            uint32_t *p = &v->out[(size_t)y * (size_t)v->out_pitch + (size_t)x];
            *p = ((*p >> 2) & 0x3F3F3Fu) | 0xFF000000u;
        }
    for (int i = 0; i < n; i++)
        view_font_draw(v->out, v->w, v->h, v->out_pitch, pad, pad + i * lh, sc, 0xFFFFE080u, lines[i]);
}

static void overlay_text(viewer *v, int fw, int fh) {
    char l0[128], l1[128], l2[128];
    const rp_render_desc *d = &v->desc;
    snprintf(l0, sizeof l0, "%.1f fps  %.1f Mrays/s  %d spp", v->fps, v->mrays, v->samples);
    char integ[32];
    snprintf(integ, sizeof integ, "%s%s%s", integrator_name((int)d->integrator),
             d->integrator == RP_INTEGRATOR_AOV ? " " : "",
             d->integrator == RP_INTEGRATOR_AOV ? aov_name(d->aov) : "");
    char packet[32];
    if (d->packet < 0) snprintf(packet, sizeof packet, "single rays");
    else snprintf(packet, sizeof packet, "%dx%d", d->packet, d->packet);
    snprintf(l1, sizeof l1, "%s depth %d  %s %s  frusta %s", integ, v->depth,
             traversal_name((int)d->traversal), packet, d->no_frustum ? "off" : "on");
    snprintf(l2, sizeof l2, "%dx%d (1/%d)  %d threads", fw, fh, v->scale, rp_device_thread_count(v->dev));
    const char *lines[3] = {l0, l1, l2};
    draw_overlay(v, lines, 3);
}

/* One rp_render call, run on a thread of its own. */
typedef struct render_call {
    rp_render_scene *scene;
    rp_render_desc desc;
    rp_camera cam;
    float *pixels;
    rp_render_stats stats;
    bool ok;
} render_call;

static void *render_main(void *p) {
    render_call *c = p;
    c->ok = rp_render(c->scene, &c->desc, c->pixels, &c->stats);
    return NULL;
}

/* The render thread: runs each posted call, until told to quit. */
static void *render_loop(void *p) {
    viewer *v = p;
    pthread_mutex_lock(&v->render_lock);
    for (;;) {
        while (!v->render_job && !v->render_quit) pthread_cond_wait(&v->render_cv, &v->render_lock);
        if (!v->render_job) break; /* quit, nothing posted */
        render_call *c = v->render_job;
        pthread_mutex_unlock(&v->render_lock);
        render_main(c);
        pthread_mutex_lock(&v->render_lock);
        v->render_job = NULL;
        pthread_cond_broadcast(&v->render_cv);
    }
    pthread_mutex_unlock(&v->render_lock);
    return NULL;
}

/* Posts a call to the render thread (started on first use). False when there is no such thread:
 * the caller runs the call itself. */
static bool render_post(viewer *v, render_call *c) {
    if (!v->render_started) {
        if (pthread_mutex_init(&v->render_lock, NULL) != 0) return false;
        if (pthread_cond_init(&v->render_cv, NULL) != 0) {
            pthread_mutex_destroy(&v->render_lock);
            return false;
        }
        v->render_job = NULL;
        v->render_quit = false;
        if (pthread_create(&v->render_th, NULL, render_loop, v) != 0) {
            pthread_cond_destroy(&v->render_cv);
            pthread_mutex_destroy(&v->render_lock);
            return false;
        }
        v->render_started = true;
    }
    pthread_mutex_lock(&v->render_lock);
    v->render_job = c;
    pthread_cond_broadcast(&v->render_cv);
    pthread_mutex_unlock(&v->render_lock);
    return true;
}

/* Waits for the posted call. */
static void render_wait(viewer *v) {
    pthread_mutex_lock(&v->render_lock);
    while (v->render_job) pthread_cond_wait(&v->render_cv, &v->render_lock);
    pthread_mutex_unlock(&v->render_lock);
}

static void render_stop(viewer *v) {
    if (!v->render_started) return;
    pthread_mutex_lock(&v->render_lock);
    v->render_quit = true;
    pthread_cond_broadcast(&v->render_cv);
    pthread_mutex_unlock(&v->render_lock);
    pthread_join(v->render_th, NULL);
    pthread_cond_destroy(&v->render_cv);
    pthread_mutex_destroy(&v->render_lock);
    v->render_started = false;
}

static bool show(viewer *v);

/* Shows the frame waiting in the window's surface, if any. */
static bool flush(viewer *v) {
    if (!v->pending) return true;
    v->pending = false;
    return show(v);
}

/* Where this frame's pixels go: straight into the window's surface when it is 32-bit xRGB (X11's
 * usual visual), which saves a copy, else into disp for show to convert. */
static bool target(viewer *v) {
    SDL_Surface *s = SDL_GetWindowSurface(v->win);
    if (!s) {
        fprintf(stderr, "raypack view: no window surface: %s\n", SDL_GetError());
        return false;
    }
    uint32_t f = s->format->format;
    v->direct = !SDL_MUSTLOCK(s) && (f == SDL_PIXELFORMAT_RGB888 || f == SDL_PIXELFORMAT_ARGB8888) && s->w == v->w &&
                s->h == v->h && s->pitch % 4 == 0;
    v->out = v->direct ? s->pixels : v->disp;
    v->out_pitch = v->direct ? s->pitch / 4 : v->w;
    return true;
}

/* Shows this frame's pixels (converted into the window's format unless they are there already). */
static bool show(viewer *v) {
    SDL_Surface *s = SDL_GetWindowSurface(v->win);
    if (!s) {
        fprintf(stderr, "raypack view: no window surface: %s\n", SDL_GetError());
        return false;
    }
    int rc = 0;
    if (!v->direct) {
        if (SDL_MUSTLOCK(s)) SDL_LockSurface(s);
        rc = SDL_ConvertPixels(v->w, v->h, SDL_PIXELFORMAT_ARGB8888, v->disp, v->w * 4, s->format->format, s->pixels,
                               s->pitch);
        if (SDL_MUSTLOCK(s)) SDL_UnlockSurface(s);
    }
    if (rc != 0 || SDL_UpdateWindowSurface(v->win) != 0) {
        fprintf(stderr, "raypack view: cannot draw into the window: %s\n", SDL_GetError());
        return false;
    }
    return true;
}

/* The window shows fewer samples than the sum holds (still frames since the last shown one were not
 * shown, see step): converts the whole sum into the window's pixels now, for F12 and at the end. */
static bool catch_up(viewer *v) {
    if (v->shown_samples == v->samples || v->samples == 0 || v->scale != 1) return true;
    if (!flush(v) || !target(v)) return false;
    present_job j = {.v = v, .fw = v->w, .fh = v->h, .scale = 1, .accumulate = true, .samples = v->samples};
    present_rect(&j, 0, 0, v->w, v->h, false, v->lines + (size_t)rp_device_thread_count(v->dev) * (size_t)v->w);
    if (v->overlay) overlay_text(v, v->w, v->h);
    v->shown_samples = v->samples;
    v->pending = true;
    return true;
}

/* The resolution divisor for a frame during motion: the smallest whose estimated time fits. */
static int motion_scale(const viewer *v) {
    /* a fifth of the frame kept in reserve: a frame's cost varies with what comes into view */
    double budget = 0.8 * 1000.0 / (double)v->opt.fps - v->overhead_ms;
    if (budget < 0.1) budget = 0.1;
    if (v->full_ms <= budget) return 1;
    int s = (int)ceil(sqrt(v->full_ms / budget));
    return s < 1 ? 1 : (s > v->opt.max_scale ? v->opt.max_scale : s);
}

/* Where a frame's time goes: events (input and motion); render (rp_render on a thread of its own,
 * less tiles: the device threads' time converting finished tiles, shared out); meanwhile, on the
 * main thread, show (the last frame to the display server) and late (tiles that finished during
 * show); then overlay. Show and late overlap the rendering. */
enum { PHASE_EVENTS, PHASE_RENDER, PHASE_TILES, PHASE_SHOW, PHASE_LATE, PHASE_OVERLAY, PHASE_COUNT };
static const char *const phase_name[PHASE_COUNT] = {"events", "render", "tiles", "show (overlapped)",
                                                    "late tiles (overlapped)", "overlay"};


/* Follows the window's size (a user or the script resized it): the film takes the window's size
 * pixel for pixel, and the accumulation restarts. False when out of memory. */
static bool follow_window_size(viewer *v) {
    SDL_Surface *s = SDL_GetWindowSurface(v->win);
    if (!s) {
        fprintf(stderr, "raypack view: no window surface: %s\n", SDL_GetError());
        return false;
    }
    if (s->w == v->w && s->h == v->h) return true;
    int w = s->w, h = s->h;
    size_t n = (size_t)w * (size_t)h;
    if (w < 1 || h < 1 || (double)w * (double)h > 8192.0 * 8192.0) {
        fprintf(stderr, "raypack view: cannot follow the window to %dx%d\n", w, h);
        return false;
    }
    float *frame = realloc(v->frame, n * 3 * sizeof(float)), *sum = frame ? realloc(v->sum, n * 3 * sizeof(float)) : NULL;
    if (frame) v->frame = frame;
    if (sum) v->sum = sum;
    uint32_t *disp = sum ? realloc(v->disp, n * sizeof(uint32_t)) : NULL;
    if (disp) v->disp = disp;
    uint32_t *lines = disp ? realloc(v->lines, ((size_t)rp_device_thread_count(v->dev) + 1) * (size_t)w * sizeof(uint32_t))
                           : NULL;
    if (lines) v->lines = lines;
    if (!lines) {
        fprintf(stderr, "raypack view: out of memory for a %dx%d window\n", w, h);
        return false;
    }
    free(v->scratch); /* --compare's, made again at the new size */
    v->scratch = NULL;
    v->cmp_samples = -1;
    v->full_ms *= (double)n / ((double)v->w * (double)v->h);
    v->w = w;
    v->h = h;
    v->samples = 0;
    v->pending = false; /* the last frame had the old size */
    v->redraw = true;
    printf("window: %dx%d\n", w, h);
    fflush(stdout);
    return true;
}

/* One frame: input, motion, maybe a render, the window. False on a fatal error. */
static bool step(viewer *v, view_script *script, int frame, double dt) {
    double t0 = cli_now_ms(), u0 = cpu_ms();
    view_script_push(script, frame);
    SDL_Event e;
    while (SDL_PollEvent(&e)) handle_event(v, &e);
    fly(v, dt);
    if (v->playing) { /* scene time runs with the wall clock, from the end back to the start */
        const rp_animation_data *a = v->data.animation;
        v->anim_t += dt;
        if (v->anim_t > a->end) v->anim_t = a->start;
        if (!rp_render_scene_set_time(v->scene, &v->data, (float)v->anim_t, NULL)) return false;
        if (a->camera[RP_ANIM_TRANSL].count || a->camera[RP_ANIM_ROT].count) { /* the camera's path */
            memcpy(v->cam.eye, v->data.camera.eye, sizeof v->cam.eye);
            memcpy(v->cam.look, v->data.camera.look, sizeof v->cam.look);
            memcpy(v->cam.up, v->data.camera.up, sizeof v->cam.up);
        }
        v->camera_moved = true;
    }
    if (!follow_window_size(v)) return false;
    double events_ms = cli_now_ms() - t0, u1 = cpu_ms(), u2 = u1;
    bool moved = v->camera_moved;
    v->camera_moved = false;
    if (moved || v->reset) v->samples = 0;
    v->reset = false;
    int cap = accumulates(&v->desc) ? v->spp_max : 1;
    int scale = moved ? motion_scale(v) : 1;
    bool render = moved || v->samples < cap;
    int fw = (v->w + scale - 1) / scale, fh = (v->h + scale - 1) / scale;
    present_job job = {.v = v, .fw = fw, .fh = fh, .scale = scale};
    bool ir = v->desc.integrator == RP_INTEGRATOR_IR;
    /* While the camera is still, the window shows the accumulating image once per frame budget
     * (1/fps), as a display would, not every sample: a frame is shown when the one after it would
     * end past the budget since the last shown one, and the first and the last (the cap, --frames)
     * always are. The others only add their samples into the sum (rp_render's accumulate), so the
     * window costs no conversion there. Instant radiosity adds its samples in the tile callback:
     * every frame shown. */
    bool show_frame = true;
    if (render && scale == 1 && !ir && !v->opt.every_frame && v->samples > 0) {
        bool last = v->samples + 1 >= cap || (v->opt.frames > 0 && frame + 1 >= v->opt.frames);
        show_frame = last || cli_now_ms() + 2.0 * v->full_ms - v->shown_ms > 1000.0 / (double)v->opt.fps;
    }
    uint64_t rays = 0;
    double render_ms = 0.0, tiles_ms = 0.0, late_ms = 0.0, show_ms = 0.0, overlay_ms = 0.0, bytes = 0.0;
    double busy_sum = 0.0; /* thread time in present_tile */
    if (render) {
        if (scale == 1) {
            job.accumulate = true;
            job.samples = v->samples + 1;
        }
        if (!target(v)) return false;
        /* a surface in another format is converted from disp when shown: show the last frame first */
        if (!v->direct && !flush(v)) return false;
        atomic_init(&job.free, !v->pending);
        int nthreads = rp_device_thread_count(v->dev);
        double busy[8 * 16] = {0};
        job.busy_ms = nthreads <= 16 ? busy : calloc(8 * (size_t)nthreads, sizeof(double));
        if (!job.busy_ms) {
            fprintf(stderr, "raypack view: out of memory\n");
            return false;
        }
        pthread_mutex_init(&job.lock, NULL);
        pthread_cond_init(&job.freed, NULL);
        rp_camera cam = view_camera_get(&v->cam);
        /* still frames render into the sum, which rp_render continues (accumulate) from the second
         * sample on; instant radiosity, whose pixels come from a filter over the whole frame,
         * renders each sample apart and its tiles are added here */
        job.add = job.accumulate && ir && job.samples > 1;
        render_call rc = {.scene = v->scene, .desc = v->desc, .cam = cam,
                          .pixels = job.accumulate && !job.add ? v->sum : v->frame};
        rc.desc.accumulate = job.accumulate && !ir && job.samples > 1;
        rc.desc.width = fw;
        rc.desc.height = fh;
        rc.desc.camera = &rc.cam;
        rc.desc.max_depth = v->depth == 0 ? -1 : v->depth;
        rc.desc.spp = 1;
        rc.desc.sample_start = scale == 1 ? v->samples : 0;
        rc.desc.tile_done = show_frame ? present_tile : NULL;
        rc.desc.tile_user = &job;
        /* the window shows the last frame while this one renders: its round trip to the display
         * server overlaps the rendering instead of adding to it */
        bool threaded = render_post(v, &rc);
        double s0 = cli_now_ms();
        bool shown = flush(v);
        show_ms = cli_now_ms() - s0;
        double c0 = cli_now_ms();
        present_release(&job);
        late_ms = cli_now_ms() - c0;
        if (threaded) render_wait(v);
        else render_main(&rc);
        u2 = cpu_ms();
        double c1 = cli_now_ms();
        for (int k = 0; k < nthreads; k++) busy_sum += job.busy_ms[8 * k];
        tiles_ms = busy_sum / nthreads; /* the frame's wall time it took: the threads share it out */
        if (job.busy_ms != busy) free(job.busy_ms);
        free(job.waiting);
        pthread_mutex_destroy(&job.lock);
        pthread_cond_destroy(&job.freed);
        if (!shown) return false;
        if (!rc.ok) {
            fprintf(stderr, "raypack view: rendering failed (out of memory?)\n");
            return false;
        }
        render_ms = rc.stats.render_ms;
        rays = 0;
        for (int k = 0; k < RP_RAY_KIND_COUNT; k++) rays += rc.stats.rays[k];
        v->mrays = render_ms > 0.0 ? (double)rays / (render_ms * 1e3) : 0.0;
        v->full_ms = render_ms * ((double)v->w * (double)v->h) / ((double)fw * (double)fh);
        v->scale = scale;
        if (scale == 1) v->samples++;
        /* what the encoding reads (the sum, and the frame it adds) and writes (the sum, the pixels) */
        double px = (double)v->w * (double)v->h, fpx = (double)fw * (double)fh;
        bytes = !show_frame ? 0.0 : job.add ? 40.0 * px : job.accumulate ? 16.0 * px : 12.0 * fpx + 4.0 * px;
        if (show_frame) {
            if (v->overlay) overlay_text(v, fw, fh);
            v->pending = true;
            v->shown_samples = v->samples;
            v->shown_ms = c1;
        }
        overlay_ms = cli_now_ms() - c1;
    } else if (v->pending || v->redraw) {
        /* nothing new: show what is pending, or send the surface again */
        if (!v->pending) v->pending = true;
        if (!flush(v)) return false;
    }
    v->redraw = false;
    double t1 = cli_now_ms();
    double frame_ms = t1 - t0;
    if (render && show_frame && v->frames_done > 0) { /* the first frame also maps the window */
        double over = frame_ms - render_ms;
        v->overhead_ms = v->frames_done > 1 ? 0.8 * v->overhead_ms + 0.2 * over : over;
    }
    if (v->frames_done > 0) { /* the first frame also maps the window: the summary leaves it out */
        v->total_frame_ms += frame_ms;
        v->total_render_ms += render_ms - tiles_ms;
        v->total_rays += rays;
        double phase[PHASE_COUNT] = {events_ms, render_ms - tiles_ms, tiles_ms, show_ms, late_ms, overlay_ms};
        for (int k = 0; k < PHASE_COUNT; k++) v->phase_ms[k] += phase[k];
        if (v->phase_frames == v->phase_cap && v->phase_cap < (1 << 20)) {
            int grow = v->phase_cap ? 2 * v->phase_cap : 256;
            float *p = realloc(v->phase_log, (size_t)grow * (PHASE_COUNT + 1) * sizeof *p);
            if (p) {
                v->phase_log = p;
                v->phase_cap = grow;
            }
        }
        if (v->phase_frames < v->phase_cap) {
            float *p = v->phase_log + (size_t)v->phase_frames++ * (PHASE_COUNT + 1);
            for (int k = 0; k < PHASE_COUNT; k++) p[k] = (float)phase[k];
            p[PHASE_COUNT] = (float)frame_ms;
        }
        v->cpu_render += u2 - u1;
        v->cpu_convert += busy_sum + late_ms;
        v->cpu_all += cpu_ms() - u0;
        v->bytes += bytes;
    }
    v->last_frame_ms = frame_ms;
    double frame_cpu = cpu_ms() - u0; /* the process's CPU time in this frame, --compare's render left out */
    if (v->opt.compare && render && scale == 1 && v->frames_done > 0) {
        /* the same frame (settings, camera, samples) by rp_render alone, right after the viewer's:
         * the machine's load drifts alike for both. As `raypack render --time` renders its frames,
         * it continues a sum of its own (scratch) from the second sample on, so the reference pays
         * the accumulation too; instant radiosity's samples are rendered apart (the viewer adds them
         * itself, as the command does). */
        float *px = v->scratch ? v->scratch : (v->scratch = malloc((size_t)v->w * (size_t)v->h * 3 * sizeof(float)));
        bool cont = v->desc.integrator != RP_INTEGRATOR_IR && v->samples > 1;
        if (px && cont && v->cmp_samples != v->samples - 1) /* the first compared frame: start from the sum (untimed) */
            memcpy(px, v->sum, (size_t)v->w * (size_t)v->h * 3 * sizeof(float));
        settle_threads();
        double c0 = cpu_ms();
        rp_render_desc d = v->desc;
        rp_camera cam = view_camera_get(&v->cam);
        d.width = v->w;
        d.height = v->h;
        d.camera = &cam;
        d.max_depth = v->depth == 0 ? -1 : v->depth;
        d.spp = 1;
        d.sample_start = v->samples - 1;
        d.accumulate = cont;
        v->cmp_samples = -1;
        if (px && rp_render(v->scene, &d, px, NULL)) {
            v->cmp_samples = v->samples;
            settle_threads(); /* and the next frame starts from settled clocks */
            v->cmp_ref_cpu += cpu_ms() - c0;
            v->cmp_view_cpu += c0 - u0;
            v->cmp_frames++;
        }
    }
    if (v->opt.log)
        printf("frame %d: %dx%d scale %d samples %d moved %d render %.2f ms (tiles %.2f) show %.2f ms late %.2f ms "
               "events %.2f ms overlay %.2f ms frame %.2f ms cpu %.2f ms shown %d\n",
               frame, fw, fh, scale, v->samples, moved ? 1 : 0, render_ms, tiles_ms, show_ms, late_ms, events_ms,
               overlay_ms, frame_ms, frame_cpu, render && show_frame ? 1 : 0);
    v->frames_done++;
    return true;
}

static void viewer_free(viewer *v) {
    render_stop(v);
    free(v->frame);
    free(v->sum);
    free(v->disp);
    free(v->lines);
    free(v->phase_log);
    free(v->scratch);
    if (v->win) SDL_DestroyWindow(v->win);
    rp_render_scene_release(v->scene);
    if (v->dev) rp_device_release(v->dev);
    if (v->loaded) cli_render_unload(&v->setup, &v->data);
}

static bool viewer_init(viewer *v) {
    if (!cli_render_load(CMD, &v->setup, &v->data)) return false;
    v->loaded = true;
    if (cli_render_scene_flags(CMD, &v->setup, &v->data) != CLI_EXIT_OK) return false; /* --lights, --anim-time */
    if (v->setup.desc.integrator == RP_INTEGRATOR_AOV && v->setup.desc.aov == RP_AOV_DEPTH) {
        fprintf(stderr, "raypack view: --aov depth has one channel; the viewer shows normal, primid or albedo\n");
        return false;
    }
    v->dev = cli_device_new(CMD, v->setup.threads, v->setup.isa);
    if (!v->dev) return false;
    v->srgb = view_srgb_select(rp_device_isa(v->dev)); /* the kernels' width (auto: sys_cpu_simd_auto) */
    char err[512] = "";
    v->scene = rp_render_scene_new(v->dev, &v->data, &v->setup.scene_desc, err, sizeof err);
    if (!v->scene) {
        fprintf(stderr, "raypack view: %s\n", err);
        return false;
    }
    cli_render_size(&v->setup, &v->data, &v->w, &v->h);
    if ((double)v->w * (double)v->h > 8192.0 * 8192.0) {
        fprintf(stderr, "raypack view: a %dx%d window is too large\n", v->w, v->h);
        return false;
    }
    v->desc = v->setup.desc;
    v->depth = rp_render_desc_defaults(&v->desc).max_depth;
    rp_camera cam = cli_render_camera(&v->setup, v->scene);
    if (!cli_scene_in_reach(CMD, v->setup.scene, v->scene, &cam)) return false;
    memcpy(v->cam.eye, cam.pinhole.eye, sizeof v->cam.eye);
    memcpy(v->cam.look, cam.pinhole.look, sizeof v->cam.look);
    memcpy(v->cam.up, cam.pinhole.up, sizeof v->cam.up);
    v->cam.fov_deg = cam.pinhole.fov_deg;
    /* a quarter of the scene's diagonal per second */
    rp_bounds b;
    rp_scene_get_bounds(rp_render_scene_core(v->scene), &b);
    float dx = b.upper_x - b.lower_x, dy = b.upper_y - b.lower_y, dz = b.upper_z - b.lower_z;
    float diag = sqrtf(dx * dx + dy * dy + dz * dz);
    v->cam.speed = isfinite(diag) && diag > 0.0f ? 0.25f * diag : 1.0f;
    v->home = v->cam;
    size_t n = (size_t)v->w * (size_t)v->h;
    v->frame = malloc(n * 3 * sizeof(float));
    v->sum = malloc(n * 3 * sizeof(float));
    v->disp = calloc(n, sizeof(uint32_t));
    /* a row per device thread and one for the main thread */
    v->lines = malloc(((size_t)rp_device_thread_count(v->dev) + 1) * (size_t)v->w * sizeof(uint32_t));
    if (!v->frame || !v->sum || !v->disp || !v->lines) {
        fprintf(stderr, "raypack view: out of memory for a %dx%d window\n", v->w, v->h);
        return false;
    }
    char title[300];
    snprintf(title, sizeof title, "raypack view - %s", v->setup.scene ? v->setup.scene : "built-in room");
    v->win = SDL_CreateWindow(title, SDL_WINDOWPOS_UNDEFINED, SDL_WINDOWPOS_UNDEFINED, v->w, v->h, SDL_WINDOW_RESIZABLE);
    if (!v->win) {
        fprintf(stderr, "raypack view: cannot open a %dx%d window: %s\n", v->w, v->h, SDL_GetError());
        return false;
    }
    SDL_Surface *s = SDL_GetWindowSurface(v->win);
    if (!s || s->w != v->w || s->h != v->h) {
        fprintf(stderr, "raypack view: the window is %dx%d, not %dx%d: %s\n", s ? s->w : 0, s ? s->h : 0, v->w, v->h,
                s ? "the screen is too small (xvfb-run -s '-screen 0 WxHx24')" : SDL_GetError());
        return false;
    }
    return true;
}

static int compare_float(const void *a, const void *b) {
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* Median and minimum of column k of n rows of `stride` floats. */
static void column_stats(const float *rows, int n, int stride, int k, double *median, double *min) {
    *median = *min = 0.0;
    float *c = n > 0 ? malloc((size_t)n * sizeof *c) : NULL;
    if (!c) return;
    for (int i = 0; i < n; i++) c[i] = rows[(size_t)i * (size_t)stride + (size_t)k];
    qsort(c, (size_t)n, sizeof *c, compare_float);
    *median = n % 2 ? c[n / 2] : 0.5 * ((double)c[n / 2 - 1] + (double)c[n / 2]);
    *min = c[0];
    free(c);
}

int cli_view(int argc, char **argv) {
    viewer v;
    memset(&v, 0, sizeof v);
    v.opt = (view_options){.fps = 20.0f, .max_scale = 16, .overlay = true};
    bool help = false;
    char **rargv = calloc((size_t)argc + 1, sizeof *rargv);
    if (!rargv) return CLI_EXIT_FAILURE;
    int rargc = 0;
    int rc = parse_view_options(argc, argv, &v.opt, rargv, &rargc, &help);
    if (rc == CLI_EXIT_OK && !help) rc = cli_render_parse(rargc, rargv, &v.setup, &help);
    free(rargv);
    if (rc != CLI_EXIT_OK) return rc;
    if (help) {
        view_usage(stdout);
        return CLI_EXIT_OK;
    }
    view_script *script = NULL;
    if (v.opt.events || v.opt.script) {
        char *text = v.opt.events ? read_text(v.opt.events) : NULL;
        if (v.opt.events && !text) return CLI_EXIT_FAILURE;
        size_t n = (text ? strlen(text) : 0) + (v.opt.script ? strlen(v.opt.script) : 0) + 2;
        char *all = malloc(n);
        if (all) snprintf(all, n, "%s\n%s", text ? text : "", v.opt.script ? v.opt.script : "");
        free(text);
        if (!all) return CLI_EXIT_FAILURE;
        script = view_script_parse(all, v.opt.events ? v.opt.events : "--script");
        free(all);
        if (!script) return CLI_EXIT_USAGE;
    }
    v.overlay = v.opt.overlay;
    v.spp_max = v.setup.spp > 0 ? v.setup.spp : 1024;
    v.deterministic = script != NULL || v.opt.frames > 0;
    view_srgb_init();

    int status = CLI_EXIT_FAILURE;
    /* The window's surface is X11's own shared-memory image, not a texture of an OpenGL renderer:
     * without a GPU that renderer is llvmpipe, whose threads would take the ray tracer's cores (and
     * its GL libraries keep allocations LeakSanitizer reports). SDL_FRAMEBUFFER_ACCELERATION in the
     * environment still decides. */
    SDL_SetHintWithPriority(SDL_HINT_FRAMEBUFFER_ACCELERATION, "0", SDL_HINT_DEFAULT);
    if (SDL_Init(SDL_INIT_VIDEO) != 0) {
        fprintf(stderr, "raypack view: cannot start SDL video: %s (no display? run it under xvfb-run)\n",
                SDL_GetError());
        view_script_free(script);
        return CLI_EXIT_FAILURE;
    }
    if (viewer_init(&v)) {
        printf("view: %s, %dx%d, %d threads, speed %.9g, sRGB by %s\n",
               v.setup.scene ? v.setup.scene : "built-in room", v.w, v.h, rp_device_thread_count(v.dev),
               (double)v.cam.speed, v.srgb);
        view_camera_print(&v.cam, stdout);
        print_settings(&v);
        status = CLI_EXIT_OK;
        double last = cli_now_ms(), start = last;
        for (int frame = 0; !v.quit && (v.opt.frames == 0 || frame < v.opt.frames); frame++) {
            double now = cli_now_ms();
            double dt = v.deterministic ? 1.0 / (double)v.opt.fps : fmin(0.25, (now - last) / 1e3);
            last = now;
            if (!step(&v, script, frame, dt)) {
                status = CLI_EXIT_FAILURE;
                break;
            }
            double wall = cli_now_ms() - now;
            v.fps = v.frames_done <= 1 ? 1000.0 / fmax(wall, 1e-3) : 0.9 * v.fps + 0.1 * 1000.0 / fmax(wall, 1e-3);
            /* idle when the image is final and nobody is watching the clock */
            int cap = accumulates(&v.desc) ? v.spp_max : 1;
            if (!v.deterministic && v.samples >= cap && !v.camera_moved) SDL_WaitEventTimeout(NULL, 50);
        }
        if (status == CLI_EXIT_OK && (!catch_up(&v) || !flush(&v))) status = CLI_EXIT_FAILURE;
        if (status == CLI_EXIT_OK && v.opt.frames > 0 && v.opt.screenshot && !save_screenshot(&v, v.opt.screenshot))
            status = CLI_EXIT_FAILURE;
        double wall = cli_now_ms() - start;
        view_camera_print(&v.cam, stdout);
        /* the window's cost: rays per ms of rp_render against rays per ms of whole frames (rp_render,
         * the conversion, the overlay, the window and the events), frames after the first */
        double in_render = v.total_render_ms > 0.0 ? (double)v.total_rays / (v.total_render_ms * 1e3) : 0.0;
        double in_frames = v.total_frame_ms > 0.0 ? (double)v.total_rays / (v.total_frame_ms * 1e3) : 0.0;
        printf("summary: %d frames, %d samples, %.1f ms, %.2f fps; after the first frame: %llu rays, %.2f Mrays/s in "
               "rp_render (%.1f ms), %.2f Mrays/s over whole frames (%.1f ms), window cost %.1f%%\n",
               v.frames_done, v.samples, wall, wall > 0.0 ? v.frames_done * 1e3 / wall : 0.0,
               (unsigned long long)v.total_rays, in_render, v.total_render_ms, in_frames, v.total_frame_ms,
               in_render > 0.0 ? 100.0 * (1.0 - in_frames / in_render) : 0.0);
        /* per phase: ms a frame and share of the frame time; show overlaps render */
        int nf = v.frames_done - 1;
        if (nf > 0 && v.total_frame_ms > 0.0) {
            printf("phases: ms a frame (share of frame time):");
            double rest = v.total_frame_ms;
            for (int k = 0; k < PHASE_COUNT; k++) {
                printf(" %s %.3f (%.1f%%)", phase_name[k], v.phase_ms[k] / nf, 100.0 * v.phase_ms[k] / v.total_frame_ms);
                if (k != PHASE_SHOW && k != PHASE_LATE) rest -= v.phase_ms[k];
            }
            printf(" other %.3f (%.1f%%); encoding touched %.1f MB a frame\n", rest / nf, 100.0 * rest / v.total_frame_ms,
                   v.bytes / nf / 1e6);
            /* on a shared machine a thread preempted inside a short phase inflates its mean: the
             * median and the minimum over frames tell more */
            printf("phases: median (min) ms:");
            for (int k = 0; k <= PHASE_COUNT; k++) {
                double med, lo;
                column_stats(v.phase_log, v.phase_frames, PHASE_COUNT + 1, k, &med, &lo);
                printf(" %s %.3f (%.3f)", k < PHASE_COUNT ? phase_name[k] : "frame", med, lo);
            }
            printf("\n");
            /* process CPU time (the display server's is not in it): the render phase holds the
             * conversion (the threads' time in it) and the main thread's showing */
            double pure = v.cpu_render - v.cpu_convert;
            printf("phases: CPU ms a frame: all %.3f, render phase %.3f, of which converting %.3f; the window's share "
                   "of the process's CPU time %.1f%%\n",
                   v.cpu_all / nf, v.cpu_render / nf, v.cpu_convert / nf,
                   v.cpu_all > 0.0 ? 100.0 * (1.0 - pure / v.cpu_all) : 0.0);
        }
        if (v.cmp_frames > 0)
            printf("compare: %d full-size frames: viewer %.3f ms CPU a frame, rp_render alone %.3f: the window costs "
                   "%.1f%% (the display server's CPU time not included)\n",
                   v.cmp_frames, v.cmp_view_cpu / v.cmp_frames, v.cmp_ref_cpu / v.cmp_frames,
                   100.0 * (v.cmp_view_cpu / v.cmp_ref_cpu - 1.0));
        fflush(stdout);
    }
    viewer_free(&v);
    view_script_free(script);
    SDL_Quit();
    return status;
}
