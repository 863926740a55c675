// rp-test: timeout=600
/* BART animation: the splines against values worked out by hand (at keys and between them), an AFF
 * scene moved to a time, broken animation data (file:line errors), and BART frames rendered through
 * the instanced path (built at the start, moved by rp_render_scene_set_time: instance transforms,
 * tpa refits) against the same frame flattened and built from scratch.
 *
 * Tolerance: the instanced path traces rays mapped into rest space by the inverse of the block's
 * transform, the flat one triangles mapped to the world by the transform, so hits inside moved
 * blocks differ by float rounding: a pixel may hit the neighbour of a triangle across their shared
 * edge, and distances differ in the last bits. Pixels must hit the same triangle at the same
 * distance within 1e-5 (relative), or a different one at the same distance within 1e-4 (an edge
 * that rounding decides), such pixels at most 0.5% of the image. Still geometry (under the
 * identity) and the tpa sub-scenes (rest space = world) must give identical hits. */
#include <math.h>
#include <stdint.h>
#include <sys/stat.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"

static char tmp_dir[512];

static const char *tmp_path(const char *name, char *buf, size_t size) {
    snprintf(buf, size, "%s/%s", tmp_dir, name);
    return buf;
}

static void write_text(const char *name, const char *text) {
    char path[1024];
    FILE *f = fopen(tmp_path(name, path, sizeof path), "wb");
    if (!f) return;
    fputs(text, f);
    fclose(f);
}

static bool near(double a, double b, double eps) { return fabs(a - b) <= eps; }

/* ---- splines ---------------------------------------------------------------------------------- */

static void check_position(const rp_animation_data *a, rp_anim_track tr, float t, float want, const char *what) {
    float v[4];
    rp_anim_track_eval(a, tr, RP_ANIM_TRANSL, t, v);
    CHECKF(near(v[0], want, 1e-5), "%s at t %g: %.7g, want %.7g", what, (double)t, (double)v[0], (double)want);
}

/* Rotation about z by `deg` degrees as a quaternion (either sign). */
static void check_rotation_z(const rp_animation_data *a, rp_anim_track tr, float t, double deg, const char *what) {
    float q[4];
    rp_anim_track_eval(a, tr, RP_ANIM_ROT, t, q);
    double h = deg * 3.14159265358979323846 / 360.0, s = q[3] < 0.0f ? -1.0 : 1.0;
    CHECKF(near(q[0], 0, 1e-6) && near(q[1], 0, 1e-6) && near(s * q[2], sin(h), 1e-5) && near(s * q[3], cos(h), 1e-5),
           "%s at t %g: (%g %g %g %g), want %g degrees about z", what, (double)t, (double)q[0], (double)q[1],
           (double)q[2], (double)q[3], deg);
}

static void test_splines(void) {
    /* x only; the spline runs from key 1 to key 2 (keys 0 and 3 shape its tangents) */
    rp_anim_key keys[] = {
        /* 0..3: uniform, TCB 0 */
        {-1, {0, 0, 0, 0}, 0, 0, 0}, {0, {0, 0, 0, 0}, 0, 0, 0}, {1, {1, 0, 0, 0}, 0, 0, 0}, {2, {1, 0, 0, 0}, 0, 0, 0},
        /* 4..7: tension 1 at both ends of the interval: zero tangents */
        {-1, {0, 0, 0, 0}, 1, 0, 0}, {0, {0, 0, 0, 0}, 1, 0, 0}, {1, {1, 0, 0, 0}, 1, 0, 0}, {2, {1, 0, 0, 0}, 1, 0, 0},
        /* 8..11: non-uniform times, P = 0, 0, 2, 4 at -1, 0, 2, 3, bias 1 at key 9, continuity 0.5 at key 10 */
        {-1, {0, 0, 0, 0}, 0, 0, 0}, {0, {0, 0, 0, 0}, 0, 0, 1}, {2, {2, 0, 0, 0}, 0, 0.5f, 0}, {3, {4, 0, 0, 0}, 0, 0, 0},
        /* 12..15: rotation about z, 0, 0, 90, 90 degrees */
        {-1, {0, 0, 1, 0}, 0, 0, 0}, {0, {0, 0, 1, 0}, 0, 0, 0}, {1, {0, 0, 1, 90}, 0, 0, 0}, {2, {0, 0, 1, 90}, 0, 0, 0},
        /* 16..19: 0, 0, 270, 270: 270 is -90 (a quaternion at an obtuse angle: BART flips it) */
        {-1, {0, 0, 1, 0}, 0, 0, 0}, {0, {0, 0, 1, 0}, 0, 0, 0}, {1, {0, 0, 2, 270}, 0, 0, 0}, {2, {0, 0, 1, 270}, 0, 0, 0},
        /* 20..24: five keys, two intervals: 0 at -1 and 0, 1 at 1, 3 at 2 and 3 */
        {-1, {0, 0, 0, 0}, 0, 0, 0}, {0, {0, 0, 0, 0}, 0, 0, 0}, {1, {1, 0, 0, 0}, 0, 0, 0}, {2, {3, 0, 0, 0}, 0, 0, 0},
        {3, {3, 0, 0, 0}, 0, 0, 0},
    };
    rp_animation_data a = {.keys = keys, .key_count = sizeof keys / sizeof keys[0]};
    rp_anim_track uni = {0, 4}, tense = {4, 4}, skew = {8, 4}, rot = {12, 4}, flip = {16, 4}, two = {20, 5};
    /* TCB 0, uniform: tangents 0.5 at both keys, x(u) = 0.5u + 1.5u^2 - u^3 */
    check_position(&a, uni, 0.0f, 0.0f, "uniform, key 1");
    check_position(&a, uni, 1.0f, 1.0f, "uniform, key 2");
    check_position(&a, uni, 0.5f, 0.5f, "uniform, middle");
    check_position(&a, uni, 0.25f, 0.203125f, "uniform, u 0.25");
    check_position(&a, uni, -7.0f, 0.0f, "uniform, clamped before");
    check_position(&a, uni, 9.0f, 1.0f, "uniform, clamped after");
    /* tension 1: smoothstep 3u^2 - 2u^3 */
    check_position(&a, tense, 0.25f, 0.15625f, "tension 1, u 0.25");
    /* skew: adj0 = 2*2/3, Tout = adj0 (bias 1: all of P1-P0 = 0) = 0; adj1 = 2*2/3,
     * Tin = 0.5 adj1 (0.5 (P2-P1) + 1.5 (P3-P2)) = (2/3)(1 + 3) = 8/3; DP = 2:
     * x(u) = (6 - 8/3) u^2 + (-4 + 8/3) u^3 = (10/3) u^2 - (4/3) u^3; at t 1 (u 0.5): 5/6 - 1/6 = 2/3 */
    check_position(&a, skew, 1.0f, 2.0f / 3.0f, "non-uniform TCB, middle");
    check_position(&a, skew, 2.0f, 2.0f, "non-uniform TCB, key 2");
    /* two intervals: at t 0.5 (interval 0): Tout = 0.5, Tin at key 2 = 0.5 (1 + 2) = 1.5, DP 1:
     * x = 0.5u + (3 - 1 - 1.5) u^2 + (-2 + 0.5 + 1.5) u^3 = 0.5u + 0.5u^2 -> 0.375;
     * at t 1.5 (interval 1): Tout = 1.5, Tin = 0.5 (0 + 2) = 1, DP 2: x = 1 + 1.5u + (6 - 3 - 1) u^2
     * + (-4 + 1.5 + 1) u^3 = 1 + 0.75 + 0.5 - 0.1875 = 2.0625 */
    check_position(&a, two, 0.5f, 0.375f, "two intervals, first");
    check_position(&a, two, 1.0f, 1.0f, "two intervals, key 2");
    check_position(&a, two, 1.5f, 2.0625f, "two intervals, second");
    /* rotation about one axis: squad's angle is the same Hermite curve, 90 (0.5u + 1.5u^2 - u^3) */
    check_rotation_z(&a, rot, 0.0f, 0.0, "rotation, key 1");
    check_rotation_z(&a, rot, 1.0f, 90.0, "rotation, key 2");
    check_rotation_z(&a, rot, 0.5f, 45.0, "rotation, middle");
    check_rotation_z(&a, rot, 0.25f, 18.28125, "rotation, u 0.25");
    /* 270 degrees reached the short way round, through -45 (the axis (0,0,2) normalized) */
    check_rotation_z(&a, flip, 0.5f, -45.0, "rotation past 180, middle");
    check_rotation_z(&a, flip, 1.0f, -90.0, "rotation past 180, key 2");
    /* absent channels */
    float v[4];
    rp_anim_track_eval(&a, (rp_anim_track){0, 0}, RP_ANIM_SCALE, 0.5f, v);
    CHECK(v[0] == 1.0f && v[1] == 1.0f && v[2] == 1.0f);
    rp_anim_track_eval(&a, (rp_anim_track){0, 0}, RP_ANIM_ROT, 0.5f, v);
    CHECK(v[0] == 0.0f && v[3] == 1.0f);
}

/* ---- an AFF scene at a time ------------------------------------------------------------------- */

static void test_aff_time(void) {
    write_text("anim.aff",
               "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 0.1\nresolution 32 24\n"
               "l 0 3 0\n"
               "xs 1 1 1  0 1 0 0  0 10 0\n{\n"             /* moves everything inside up by 10 */
               "  x mover\n  {\n"
               "    pp 3\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n 0 0 1 0 0 1\n"
               "    x spin\n    {\n      p 3\n 1 0 0\n 0 1 0\n 0 0 1\n      s 2 0 0 0.5\n    }\n"
               "  }\n}\n"
               "tpa 2\n 0\n 0 0 0 0 0 1\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n 2\n 4 0 0 0 1 0\n 5 0 0 0 1 0\n 4 1 0 0 1 0\n"
               "a 0 2 5\n"
               "k mover\n{\n  transl 4\n  -1 0 0 0  0 0 0\n  0 0 0 0  0 0 0\n  1 2 0 0  0 0 0\n  2 2 0 0  0 0 0\n"
               "  scale 4\n  -1 1 1 1  0 0 0\n  0 1 1 1  0 0 0\n  2 3 3 3  0 0 0\n  3 3 3 3  0 0 0\n}\n"
               "k spin\n{\n  rot 4\n  -1 0 0 1 0  0 0 0\n  0 0 0 1 0  0 0 0\n  2 0 0 1 90  0 0 0\n  3 0 0 1 90  0 0 0\n}\n"
               "k camera\n{\n  transl 4\n  -1 0 0 5  0 0 0\n  0 0 0 5  0 0 0\n  2 0 0 9  0 0 0\n  3 0 0 9  0 0 0\n"
               "  rot 4\n  -1 0 1 0 0  0 0 0\n  0 0 1 0 0  0 0 0\n  2 0 1 0 90  0 0 0\n  3 0 1 0 90  0 0 0\n}\n");
    rp_scene_data s;
    char err[512], path[1024];
    bool ok = rp_scene_data_load(tmp_path("anim.aff", path, sizeof path), &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    const rp_animation_data *a = s.animation;
    CHECK(a && a->node_count == 2 && a->tpa_count == 1 && a->start == 0.0f && a->end == 2.0f && a->frames == 5);
    CHECK(s.triangle_count == 3 && s.sphere_count == 1);
    if (!a || s.triangle_count != 3) {
        rp_scene_data_free(&s);
        return;
    }
    CHECK(near(rp_scene_data_frame_time(&s, 2), 1.0, 1e-6) && near(rp_scene_data_frame_time(&s, 4), 2.0, 1e-6));
    /* another count over the same range (animate --frames, render --mpi --frames), and the ends */
    CHECK(near(rp_anim_frame_time(a, 1, 3), 0.5 * ((double)a->start + a->end), 1e-6) &&
          rp_anim_frame_time(a, 0, 3) == a->start && near(rp_anim_frame_time(a, 2, 3), a->end, 1e-6) &&
          rp_anim_frame_time(a, 5, 1) == a->start && rp_anim_frame_time(NULL, 1, 3) == 0.0f);
    CHECK(a->tri_node[0] == 0 && a->tri_node[1] == 1 && a->tri_node[2] == -1 && a->tri_tpa[2] == 1);
    /* t 0 (the start, as loaded): everything at rest, 10 up */
    const float *p = s.positions + 3 * s.indices[0];
    CHECKF(near(p[1], 10, 1e-5), "start: (%g %g %g)", (double)p[0], (double)p[1], (double)p[2]);
    /* t 1: mover's translation is key 2's, x 2; its scale is at u 0.5 of [0, 2] (from 1 to 3):
     * adj0 = 2*2/3, Tout = 0.5 adj0 (2 + 0) = 4/3, adj1 = 2*2/3, Tin = 0.5 adj1 (0 + 2) = 4/3, DP 2:
     * s(u) = 1 + (4/3)u + (6 - 8/3 - 4/3)u^2 + (-4 + 8/3)u^3; at u 0.5: 1 + 2/3 + 1/2 - 1/6 = 2 */
    CHECK(rp_scene_data_set_time(&s, 1.0f));
    /* vertex (1,0,0) of the pp (rest (1,10,0)): world = parent(up 10) * T(2,0,0) S(2) * parent^-1:
     * (1,0,0) local -> (2*1 + 2, 0, 0) + (0, 10, 0) */
    for (int c = 0; c < 3; c++) {
        uint32_t vi = s.indices[c];
        const float *q = s.positions + 3 * vi;
        float want[3] = {0, 10, 0};
        if (near(a->rest_positions[3 * vi], 1, 1e-6)) want[0] = 4;
        else want[0] = 2;
        if (near(a->rest_positions[3 * vi + 1], 11, 1e-6)) want[1] = 12;
        if (near(a->rest_positions[3 * vi + 2], 1, 1e-6)) want[2] = 2;
        CHECKF(near(q[0], want[0], 1e-5) && near(q[1], want[1], 1e-5) && near(q[2], want[2], 1e-5),
               "mover at t 1: (%g %g %g), want (%g %g %g)", (double)q[0], (double)q[1], (double)q[2], (double)want[0],
               (double)want[1], (double)want[2]);
    }
    /* spin inside mover: rot at t 1 is 45 degrees about z (the uniform Hermite curve's middle):
     * local (1,0,0) -> (cos45, sin45, 0), then mover: x 2 * c + 2, y 2 * s + 10 */
    double c45 = sqrt(0.5);
    bool found = false;
    for (int c = 0; c < 3; c++) {
        uint32_t vi = s.indices[3 + c];
        if (!near(a->rest_positions[3 * vi], 1, 1e-6)) continue;
        const float *q = s.positions + 3 * vi;
        found = true;
        CHECKF(near(q[0], 2 * c45 + 2, 1e-4) && near(q[1], 2 * c45 + 10, 1e-4) && near(q[2], 0, 1e-5),
               "spin at t 1: (%g %g %g)", (double)q[0], (double)q[1], (double)q[2]);
    }
    CHECK(found);
    /* the sphere (in spin): centre (2,0,0) rotated 45 and scaled 2, radius 0.5 * 2 */
    CHECKF(near(s.spheres[0].center[0], 4 * c45 + 2, 1e-4) && near(s.spheres[0].radius, 1.0, 1e-5),
           "sphere at t 1: (%g %g %g) r %g", (double)s.spheres[0].center[0], (double)s.spheres[0].center[1],
           (double)s.spheres[0].center[2], (double)s.spheres[0].radius);
    /* tpa halfway between its keys at 0 and 2: corner 1 (1,0,0) -> (5,0,0) at (3,0,0); normal halfway */
    const rp_anim_tpa *tp = &a->tpas[0];
    const float *q = s.positions + 3 * (size_t)(tp->vertex + 1);
    CHECKF(near(q[0], 3, 1e-6) && near(q[1], 0, 1e-6), "tpa at t 1: (%g %g %g)", (double)q[0], (double)q[1], (double)q[2]);
    const float *n = s.normals + 3 * (size_t)(tp->normal + 1);
    CHECK(near(n[1], 0.5, 1e-6) && near(n[2], 0.5, 1e-6));
    /* camera at t 1: eye z 7 (Hermite middle of 5..9), looking down -z turned 45 degrees about y */
    CHECKF(s.camera.valid && near(s.camera.eye[2], 7, 1e-5), "camera eye (%g %g %g)", (double)s.camera.eye[0],
           (double)s.camera.eye[1], (double)s.camera.eye[2]);
    float d[3] = {s.camera.look[0] - s.camera.eye[0], s.camera.look[1] - s.camera.eye[1], s.camera.look[2] - s.camera.eye[2]};
    CHECKF(near(d[0], -c45, 1e-5) && near(d[1], 0, 1e-5) && near(d[2], -c45, 1e-5) && near(s.camera.up[1], 1, 1e-5),
           "camera direction (%g %g %g)", (double)d[0], (double)d[1], (double)d[2]);
    /* back to the start: the rest positions again */
    CHECK(rp_scene_data_set_time(&s, 0.0f));
    for (size_t i = 0; i < 3 * s.vertex_count; i++)
        if (!near(s.positions[i], a->rest_positions[i], 1e-5)) {
            CHECKF(false, "position %zu at t 0: %g, rest %g", i, (double)s.positions[i], (double)a->rest_positions[i]);
            break;
        }
    rp_scene_data_free(&s);
}

/* ---- broken animation data -------------------------------------------------------------------- */

static void expect_error(const char *name, const char *text, unsigned line, const char *needle) {
    write_text(name, text);
    rp_scene_data s;
    char err[1024] = "", path[1024], want[256];
    bool ok = rp_scene_data_load(tmp_path(name, path, sizeof path), &s, err, sizeof err);
    CHECKF(!ok, "%s loaded but should fail", name);
    if (ok) {
        rp_scene_data_free(&s);
        return;
    }
    snprintf(want, sizeof want, "%s:%u: error: ", name, line);
    CHECKF(strstr(err, want) && strstr(err, needle), "%s: got '%s', want '%s...%s'", name, err, want, needle);
}

static void test_errors(void) {
    expect_error("e_few.aff", "x a\n{\n}\nk a\n{\n  transl 3\n  0 0 0 0 0 0 0\n  1 0 0 0 0 0 0\n  2 0 0 0 0 0 0\n}\n", 6,
                 "at least 4");
    expect_error("e_back.aff",
                 "k a\n{\n  rot 4\n  0 0 1 0 0 0 0 0\n  1 0 1 0 5 0 0 0\n  0.5 0 1 0 9 0 0 0\n  2 0 1 0 0 0 0 0\n}\n", 6,
                 "before the previous");
    expect_error("e_axis.aff", "k a\n{\n  rot 4\n  0 0 1 0 0 0 0 0\n  1 0 0 0 5 0 0 0\n  2 0 1 0 9 0 0 0\n  3 0 1 0 0 0 0 0\n}\n",
                 5, "zero vector");
    expect_error("e_twice.aff",
                 "k a\n{\n  scale 4\n 0 1 1 1 0 0 0\n 1 1 1 1 0 0 0\n 2 1 1 1 0 0 0\n 3 1 1 1 0 0 0\n"
                 "  scale 4\n 0 1 1 1 0 0 0\n 1 1 1 1 0 0 0\n 2 1 1 1 0 0 0\n 3 1 1 1 0 0 0\n}\n",
                 8, "given twice");
    expect_error("e_type.aff", "k a\n{\n  wobble 4\n}\n", 3, "unknown keyframe type");
    expect_error("e_vis.aff", "k a\n{\n  visibility 2\n  0 1\n  1 2\n}\n", 5, "visibility flag");
    expect_error("e_short.aff", "k a\n{\n  transl 4\n  0 0 0 0 0 0 0\n  1 0 0 x 0 0 0\n", 5, "expected a finite number");
    expect_error("e_range.aff", "\n\na 5 1 10\n", 3, "ends");
    expect_error("e_frames.aff", "a 0 1 0\n", 1, "frames");
    expect_error("e_tpa.aff", "tpa 2\n 1\n 0 0 0 0 0 1\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n 0.5\n 0 0 0 0 0 1\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n",
                 9, "before the previous");
    expect_error("e_tpa_n.aff", "p 3\n 0 0 0\n 1 0 0\n 0 1 0\ntpa 0\n", 5, "keyframe count");
    /* a keyframed block inside a scale of 0: rp_scene_data_set_time could not undo its rest
     * transform (anim_inverse), so the loader refuses it */
    expect_error("e_singular.aff",
                 "xs 0 1 1  0 1 0 0  0 0 0\n{\n  x a\n  {\n    p 3\n 0 0 0\n 1 0 0\n 0 1 0\n  }\n}\n"
                 "k a\n{\n  transl 4\n  0 0 0 0 0 0 0\n  1 1 0 0 0 0 0\n  2 2 0 0 0 0 0\n  3 3 0 0 0 0 0\n}\n",
                 0, "singular transform around keyframed block 'a'");
    expect_error("e_tpa_eof.aff", "tpa 2\n 0\n 0 0 0 0 0 1\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n 1\n 0 0 0 0 0 1\n", 8, "end of file");
}

/* ---- BART frames: instanced and updated against flattened and rebuilt -------------------------- */

typedef struct frame_px {
    float *primid, *depth, *color;
} frame_px;

static bool render_frame(rp_render_scene *s, int w, int h, frame_px *out) {
    rp_camera cam = rp_render_scene_default_camera(s);
    rp_render_desc d = {.width = w, .height = h, .camera = &cam, .integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_PRIMID};
    out->primid = malloc((size_t)w * h * 3 * sizeof(float));
    out->depth = malloc((size_t)w * h * sizeof(float));
    out->color = malloc((size_t)w * h * 3 * sizeof(float));
    if (!out->primid || !out->depth || !out->color) return false;
    bool ok = rp_render(s, &d, out->primid, NULL);
    d.aov = RP_AOV_DEPTH;
    ok = ok && rp_render(s, &d, out->depth, NULL);
    d.integrator = RP_INTEGRATOR_WHITTED;
    ok = ok && rp_render(s, &d, out->color, NULL);
    return ok;
}

static void frame_free(frame_px *f) {
    free(f->primid), free(f->depth), free(f->color);
}

/* Compares two renders of one frame; exact: identical hits and colours required. */
static void compare_frames(const char *what, const frame_px *a, const frame_px *b, int w, int h, bool exact) {
    size_t n = (size_t)w * h, other = 0, bad = 0, color_diff = 0;
    for (size_t i = 0; i < n; i++) {
        bool same = memcmp(a->primid + 3 * i, b->primid + 3 * i, 3 * sizeof(float)) == 0;
        float da = a->depth[i], db = b->depth[i];
        bool both_miss = isinf(da) && isinf(db);
        double rel = both_miss ? 0.0 : fabs((double)da - db) / fmax(fabs((double)db), 1e-6);
        if (!(rel <= (same ? 1e-5 : 1e-4)) || (isinf(da) != isinf(db))) bad++;
        if (!same) other++;
        for (int c = 0; c < 3; c++)
            if (fabsf(a->color[3 * i + (size_t)c] - b->color[3 * i + (size_t)c]) > (exact ? 0.0f : 1e-3f)) {
                color_diff++;
                break;
            }
    }
    if (exact) {
        CHECKF(other == 0 && bad == 0 && color_diff == 0, "%s: %zu pixels hit another triangle, %zu at another distance, "
               "%zu of another colour (want all identical)", what, other, bad, color_diff);
    } else {
        CHECKF(bad == 0 && other * 200 <= n && color_diff * 100 <= n,
               "%s: %zu pixels beyond the distance tolerance, %zu on a neighbouring triangle (at most %zu), %zu of "
               "another colour", what, bad, other, n / 200, color_diff);
    }
}

static void test_bart(rp_device *dev, const char *name, const float *times, int nt, bool exact) {
    char path[1024], err[512];
    if (!rp_test_scene(name, path, sizeof path)) {
        CHECKF(false, "scene %s missing", name);
        return;
    }
    int w = rp_test_sanitized() ? 48 : 128, h = rp_test_sanitized() ? 36 : 96;
    rp_scene_data anim, flat;
    bool ok = rp_scene_data_load(path, &anim, err, sizeof err);
    CHECKF(ok && anim.animation, "%s: %s", name, err);
    if (!ok) return;
    rp_render_scene *inst = rp_render_scene_new(dev, &anim, NULL, err, sizeof err);
    /* the blocks' world-space vertices refitted under the identity: the flat frame's triangles */
    rp_scene_data refit_data;
    rp_render_scene *refit = NULL;
    bool refit_loaded = rp_scene_data_load(path, &refit_data, err, sizeof err);
    if (refit_loaded)
        refit = rp_render_scene_new(dev, &refit_data, &(rp_render_scene_desc){.refit_blocks = true}, err, sizeof err);
    CHECKF(refit != NULL, "%s: %s", name, err);
    rp_render_scene *flat_up = NULL;
    rp_scene_data flat_up_data;
    ok = rp_scene_data_load(path, &flat_up_data, err, sizeof err);
    if (ok) flat_up = rp_render_scene_new(dev, &flat_up_data, &(rp_render_scene_desc){.flatten_animation = true}, err, sizeof err);
    CHECKF(inst && flat_up, "%s: %s", name, err);
    for (int k = 0; inst && flat_up && k < nt; k++) {
        float t = times[k];
        rp_render_update_stats us;
        CHECK(rp_render_scene_set_time(inst, &anim, t, &us));
        CHECK(us.rebuilds >= 1 && us.instances >= 1); /* the top level at least */
        rp_render_update_stats fs, rs;
        CHECK(rp_render_scene_set_time(flat_up, &flat_up_data, t, &fs));
        CHECK(refit && rp_render_scene_set_time(refit, &refit_data, t, &rs) && rs.refits + rs.rebuilds >= 2);
        /* the reference: the frame flattened and built from scratch */
        ok = rp_scene_data_load(path, &flat, err, sizeof err);
        CHECKF(ok, "%s", err);
        if (!ok) break;
        CHECK(rp_scene_data_set_time(&flat, t));
        rp_render_scene *ref = rp_render_scene_new(dev, &flat, &(rp_render_scene_desc){.flatten_animation = true}, err, sizeof err);
        CHECKF(ref, "%s", err);
        frame_px fa = {0}, fb = {0}, fc = {0}, fd = {0};
        if (ref && refit && render_frame(inst, w, h, &fa) && render_frame(ref, w, h, &fb) &&
            render_frame(flat_up, w, h, &fc) && render_frame(refit, w, h, &fd)) {
            char what[256];
            snprintf(what, sizeof what, "%s t %g, instanced + updated vs flat rebuilt", name, (double)t);
            compare_frames(what, &fa, &fb, w, h, exact);
            snprintf(what, sizeof what, "%s t %g, flat refitted/rebuilt by the update vs flat built", name, (double)t);
            compare_frames(what, &fc, &fb, w, h, true);
            snprintf(what, sizeof what, "%s t %g, blocks refitted in world space vs flat built", name, (double)t);
            compare_frames(what, &fd, &fb, w, h, true);
        } else {
            CHECKF(false, "%s t %g: rendering failed", name, (double)t);
        }
        frame_free(&fa), frame_free(&fb), frame_free(&fc), frame_free(&fd);
        rp_render_scene_release(ref);
        rp_scene_data_free(&flat);
    }
    rp_render_scene_release(inst);
    rp_render_scene_release(refit);
    if (refit_loaded) rp_scene_data_free(&refit_data);
    rp_render_scene_release(flat_up);
    rp_scene_data_free(&anim);
    rp_scene_data_free(&flat_up_data);
}

/* Frames move (camera path, tpa), and going back to the start gives the first build's image. */
static void test_start_frame(rp_device *dev) {
    char path[1024], err[512];
    if (!rp_test_scene("bart_museum5.tar.gz", path, sizeof path)) return;
    rp_scene_data d;
    if (!rp_scene_data_load(path, &d, err, sizeof err)) return;
    rp_render_scene *s = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    frame_px a = {0}, b = {0}, c = {0};
    float t0 = d.animation->start;
    rp_render_update_stats us;
    bool ok = s && render_frame(s, 40, 30, &a) && rp_render_scene_set_time(s, &d, 3.0f, &us) &&
              render_frame(s, 40, 30, &c) && rp_render_scene_set_time(s, &d, t0, &us) && render_frame(s, 40, 30, &b);
    CHECK(ok);
    if (ok) {
        compare_frames("museum: start, t 3, start again", &a, &b, 40, 30, true);
        size_t moved = 0;
        for (size_t i = 0; i < 40 * 30; i++) moved += a.depth[i] != c.depth[i];
        CHECKF(moved > 600, "museum at t 3: only %zu of 1200 pixels differ from the start's", moved);
    }
    /* other data than the scene's is refused */
    CHECK(!rp_render_scene_set_time(s, NULL, 1.0f, NULL));
    frame_free(&a), frame_free(&b), frame_free(&c);
    rp_render_scene_release(s);
    rp_scene_data_free(&d);
}

/* Whitted's depths per ray kind on the built-in room (a mirror and a glass sphere). */
static void test_depths(rp_device *dev) {
    rp_scene_data d;
    if (!rp_default_scene(&d)) return;
    char err[256];
    rp_render_scene *s = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    CHECK(s != NULL);
    int w = 48, h = 36;
    float *a = malloc((size_t)w * h * 3 * sizeof(float)), *b = malloc((size_t)w * h * 3 * sizeof(float));
    rp_render_stats sa, sb;
    /* both kinds at 2 are max_depth 2 */
    bool ok = s && a && b && rp_render(s, &(rp_render_desc){.width = w, .height = h, .max_depth = 2}, a, &sa) &&
              rp_render(s, &(rp_render_desc){.width = w, .height = h, .reflect_depth = 2, .refract_depth = 2}, b, &sb);
    CHECK(ok && memcmp(a, b, (size_t)w * h * 3 * sizeof(float)) == 0);
    /* no reflections, refraction 5 deep; then the other way round */
    ok = ok && rp_render(s, &(rp_render_desc){.width = w, .height = h, .reflect_depth = -1, .refract_depth = 5}, a, &sa) &&
         rp_render(s, &(rp_render_desc){.width = w, .height = h, .reflect_depth = 5, .refract_depth = -1}, b, &sb);
    CHECK(ok && sa.rays[RP_RAY_REFLECTION] == 0 && sa.rays[RP_RAY_REFRACTION] > 0);
    CHECK(ok && sb.rays[RP_RAY_REFRACTION] == 0 && sb.rays[RP_RAY_REFLECTION] > 0);
    /* Overbeck's fig. 1: one bounce of reflection, four of refraction: fewer reflection rays than 5 deep */
    rp_render_stats sc;
    ok = ok && rp_render(s, &(rp_render_desc){.width = w, .height = h, .reflect_depth = 1, .refract_depth = 4}, a, &sc);
    CHECK(ok && sc.rays[RP_RAY_REFLECTION] > 0 && sc.rays[RP_RAY_REFLECTION] < sb.rays[RP_RAY_REFLECTION] &&
          sc.rays[RP_RAY_REFRACTION] > 0);
    free(a), free(b);
    rp_render_scene_release(s);
    rp_default_scene_free(&d);
}

int main(void) {
    const char *t = getenv("RP_TEST_TMP");
    snprintf(tmp_dir, sizeof tmp_dir, "%s", t ? t : "/tmp/rp_test_anim");
    mkdir(tmp_dir, 0755);
    test_splines();
    test_aff_time();
    test_errors();
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    CHECK(dev != NULL);
    if (dev) {
        /* kitchen: the toy car and its wheels move (instances); museum: tpa triangles (refits) and
         * the camera path, rest space = world: identical */
        static const float kitchen_t[] = {10.0f, 17.0f}, museum_t[] = {0.7f, 3.2f};
        test_bart(dev, "bart_kitchen.tar.gz", kitchen_t, rp_test_sanitized() ? 1 : 2, false);
        test_bart(dev, "bart_museum5.tar.gz", museum_t, 2, true);
        test_start_frame(dev);
        test_depths(dev);
        rp_device_release(dev);
    }
    return RP_TEST_END();
}
