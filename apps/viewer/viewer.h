/* `raypack view`: the interactive SDL2 viewer. It renders through the public rp_render API with the
 * flags of `raypack render` (cli_render_parse), so the window shows the pixels `raypack render`
 * writes for the same camera, settings and sample count. One concern per file:
 *   view.c         options, the window, the frame loop (progressive refinement, resolution)
 *   view_camera.c  fly / look / orbit camera
 *   view_script.c  scripted input events (--events, --script) for tests and demos
 *   view_font.c    the overlay's 5x7 bitmap font
 *   view_srgb.c    linear float to 8-bit sRGB, exactly as the PNG writer does it, by table */
#ifndef RP_VIEWER_H
#define RP_VIEWER_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <raypack.h>
#include <raypack_render.h>

/* The subcommand (argv[0] is "view"). */
int cli_view(int argc, char **argv);

/* ---- camera ---- */

/* The viewer's camera: a pinhole camera as rp_render takes it, moved in world space; up is the
 * scene's up and stays fixed, so the horizon stays level. */
typedef struct view_camera {
    float eye[3], look[3], up[3];
    float fov_deg;
    float speed; /* fly speed, world units per second */
} view_camera;

/* Fly: moves eye and look together by (right, up, forward) * dist in the camera's frame. */
void view_camera_move(view_camera *c, float right, float up, float forward);
/* Mouse look: turns the view direction by yaw (about up) and pitch (about the right axis), radians. */
void view_camera_turn(view_camera *c, float yaw, float pitch);
/* Orbit: turns the eye about pivot by yaw and pitch, keeping where it looks relative to the pivot. */
void view_camera_orbit(view_camera *c, const float pivot[3], float yaw, float pitch);
/* The camera as rp_render takes it. */
rp_camera view_camera_get(const view_camera *c);
/* The primary ray direction through pixel coordinates (x, y) of a w x h image (DESIGN.md's camera). */
void view_camera_ray(const view_camera *c, int w, int h, float x, float y, float dir[3]);
/* Prints the camera as the flags `raypack render` takes, exactly (floats round-trip). */
void view_camera_print(const view_camera *c, FILE *f);

/* ---- scripted input ---- */

typedef struct view_script view_script;
/* SDL_USEREVENT codes the script pushes: resize (data1, data2: the new width and height). */
enum { VIEW_EVENT_RESIZE = 1 };
/* Parses a script: items separated by ';' or new lines, each "FRAME ACTION [ARGS]" (see
 * view_script.c); `origin` names the source in errors. Returns NULL after printing why. */
view_script *view_script_parse(const char *text, const char *origin);
/* Pushes the script's events for frame `frame` onto SDL's queue. */
void view_script_push(view_script *s, int frame);
/* The last frame the script acts on, or -1 when it is empty. */
int view_script_last_frame(const view_script *s);
void view_script_free(view_script *s);

/* ---- overlay font ---- */

enum { VIEW_FONT_W = 5, VIEW_FONT_H = 7 };
/* Draws text into a 32-bit xRGB image (pitch in pixels) at (x, y), each font pixel a scale x scale
 * block, in colour rgb; clipped to the image. Lower case draws as upper case. */
void view_font_draw(uint32_t *pixels, int w, int h, int pitch, int x, int y, int scale, uint32_t rgb,
                    const char *text);
/* Width in pixels of text drawn at scale (one column of space between glyphs). */
int view_font_width(const char *text, int scale);

/* ---- sRGB ---- */

/* The table's buckets: floats in [2^-13, 1] by their exponent and as many top mantissa bits as that
 * octave needs for the code to rise by at most one within a bucket (fewer where the codes are
 * sparse); every float below 2^-13 encodes to 0 (the code becomes 1 near 1.5e-4). 384 words with
 * glibc's powf (1.5 KiB, 24 cache lines; cut evenly by 8 mantissa bits it took 3329, 13 KiB), so it
 * stays in the first level cache while tiles are rendered and converted in turn. */
#define VIEW_SRGB_LO 0x39000000u /* 2^-13 */
enum {
    VIEW_SRGB_E0 = (int)(VIEW_SRGB_LO >> 23), /* the exponent field of octave 0; octave 13 is 1.0 */
    VIEW_SRGB_OCTAVES = 14,
    VIEW_SRGB_MAX = 4096 /* words the table may take */
};
/* Per bucket: bits 24-31 the code at its start, bits 0-23 the mantissa's low bits (below the
 * bucket's) where the next code begins (1 << 23: none). Per octave: the shift that leaves the
 * bucket's bits of the mantissa, and its first bucket (view_srgb_init). */
extern uint32_t view_srgb_table[VIEW_SRGB_MAX];
extern uint32_t view_srgb_shift[16], view_srgb_first[16];
extern bool view_srgb_exact; /* false: the table could not be built, use the formula */

/* Builds the table (once; not thread-safe, call before the first view_srgb8). */
void view_srgb_init(void);
/* The same by the formula: rp_image_write's encode_srgb8, operation for operation. */
uint8_t view_srgb8_formula(float v);
/* The table's size in words. */
int view_srgb_table_words(void);

/* Chooses how view_srgb_pixels runs: isa is an rp_device_desc.isa code (0 the widest the CPU has,
 * 1 or 4 scalar, 8 AVX2, 16 AVX-512), capped by the CPU. Returns its name. Call after view_srgb_init. */
const char *view_srgb_select(int isa);
/* n pixels of 3 floats: sum += add (when add is not NULL), then out = 0xFF000000 | the codes of
 * sum * inv as xRGB8888, exactly view_srgb8 per channel (inv 1: sum itself). */
void view_srgb_pixels(float *sum, const float *add, float inv, uint32_t *out, int n);
/* The same over `rows` rows of n pixels: sum and add advance by stride floats a row, out by pitch
 * words (one call a tile: the constants are set up once). */
void view_srgb_rect(float *sum, const float *add, size_t stride, float inv, uint32_t *out, size_t pitch, int n,
                    int rows);

/* The 8-bit sRGB code of a linear value, equal to what rp_image_write stores in a PNG. Branch-free
 * but for the table's check: clamping to [0, 1] maps negatives and NaN to 0 as the formula does. */
static inline uint32_t view_srgb8(float v) {
    if (!view_srgb_exact) return view_srgb8_formula(v);
    const float lo = 0x1p-13f;
    v = v > lo ? v : lo; /* NaN too; 2^-13 encodes to 0 */
    v = v < 1.0f ? v : 1.0f;
    uint32_t b;
    memcpy(&b, &v, sizeof b);
    uint32_t e = (b >> 23) - (uint32_t)VIEW_SRGB_E0, m = b & 0x7FFFFFu, sh = view_srgb_shift[e];
    uint32_t t = view_srgb_table[view_srgb_first[e] + (m >> sh)];
    return (t >> 24) + ((m & ((1u << sh) - 1u)) >= (t & 0xFFFFFFu));
}

#endif
