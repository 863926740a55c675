// rp-test: labels=render timeout=300
/* Alpha cutouts (src/render/alpha.c): an OBJ quad tilted 35 degrees in front of a checker wall,
 * whose MTL map_d is an RGBA PNG with a 4x4 checker of holes, lit by a point light beside the eye.
 * Every integrator (Whitted in packets and ray by ray, eye light, the AOVs, direct, path, instant
 * radiosity, AO) must show the wall exactly where the camera ray passes through a hole, and the
 * quad's shadow on the wall must have holes where the light's ray passes through one: each pixel
 * is classified by intersecting its ray with the quad and the wall here. A glTF with alphaMode MASK
 * and alphaCutoff 0.3 (a texture alpha of 0.2 cut, of 0.4 kept); BLEND (deterministic for any
 * thread count); map_d of a grey PNG without alpha (its grey value is the mask); a MASK
 * material that cuts nothing renders byte for byte as the opaque one; and the default camera's
 * framing and rp_render_scene_intersect1 (the viewer's orbit pick) see through a cut-out quad. */
#include <math.h>
#include <stdint.h>
#include <sys/stat.h>

#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"
#include "rp_test_png.h"
#include "rp_test_tmp.h"


enum { TEX = 64, CELL = 16 };

/* Whether cell (i, j) of the 4x4 pattern (i along s, j along t, (0, 0) at s = t = 0) is solid. */
static bool cell_solid(int i, int j) { return (i + j) % 2 == 0; }

/* A TEX x TEX PNG of the hole pattern: comp 4 (white, alpha `solid` / `hole`) or comp 1 (grey
 * `solid` / `hole`, no alpha channel). Row 0 is the top (t = 1). */
static void write_mask_png(const char *name, int comp, uint8_t solid, uint8_t hole) {
    static uint8_t px[TEX * TEX * 4];
    for (int y = 0; y < TEX; y++)
        for (int x = 0; x < TEX; x++) {
            uint8_t a = cell_solid(x / CELL, 3 - y / CELL) ? solid : hole;
            uint8_t *p = px + (size_t)(y * TEX + x) * (size_t)comp;
            if (comp == 1) p[0] = a;
            else p[0] = p[1] = p[2] = 255, p[3] = a;
        }
    char path[1024];
    CHECK(stbi_write_png(tmp_path(name, path, sizeof path), TEX, TEX, comp, px, TEX * comp) != 0);
}

/* The wall's checker (green and teal: green above red everywhere). */
static void write_checker_png(const char *name) {
    static uint8_t px[TEX * TEX * 3];
    for (int y = 0; y < TEX; y++)
        for (int x = 0; x < TEX; x++) {
            bool dark = ((x / 8) + (y / 8)) % 2 != 0;
            uint8_t *p = px + 3 * (size_t)(y * TEX + x);
            p[0] = dark ? 20 : 40, p[1] = dark ? 110 : 210, p[2] = dark ? 120 : 40;
        }
    char path[1024];
    CHECK(stbi_write_png(tmp_path(name, path, sizeof path), TEX, TEX, 3, px, TEX * 3) != 0);
}

/* ---- the scene's geometry, for classifying pixels ---- */

typedef struct vec {
    double x, y, z;
} vec;
static vec vadd(vec a, vec b) { return (vec){a.x + b.x, a.y + b.y, a.z + b.z}; }
static vec vsub(vec a, vec b) { return (vec){a.x - b.x, a.y - b.y, a.z - b.z}; }
static vec vscale(vec a, double s) { return (vec){a.x * s, a.y * s, a.z * s}; }
static double vdot(vec a, vec b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

/* The quad: centre C, unit axes U (s) and V (t), half size 1: P(s, t) = C + (2s - 1) U + (2t - 1) V. */
typedef struct quad {
    vec c, u, v, n;
} quad;

static quad make_quad(double tilt_deg, double z) {
    double a = tilt_deg * 3.14159265358979 / 180.0;
    quad q = {.c = {0, 0, z}, .u = {cos(a), 0, -sin(a)}, .v = {0, 1, 0}};
    q.n = (vec){sin(a), 0, cos(a)}; /* u x v */
    return q;
}

static vec quad_corner(const quad *q, double s, double t) {
    return vadd(q->c, vadd(vscale(q->u, 2 * s - 1), vscale(q->v, 2 * t - 1)));
}

enum { MISSED = 0, SOLID = 1, HOLE = 2, UNSURE = 3 };

/* Where the segment o + d x, x in (0, xmax), crosses the quad: MISSED, SOLID, HOLE, or UNSURE near
 * an edge of the quad or of a cell (bilinear filtering blends there). */
static int quad_cross(const quad *q, vec o, vec d, double xmax, double *x_out) {
    double nd = vdot(q->n, d);
    if (fabs(nd) < 1e-9) return MISSED;
    double x = vdot(q->n, vsub(q->c, o)) / nd;
    if (!(x > 1e-6 && x < xmax)) return MISSED;
    vec p = vsub(vadd(o, vscale(d, x)), q->c);
    double s = (vdot(p, q->u) + 1) / 2, t = (vdot(p, q->v) + 1) / 2;
    const double m = 0.04;
    if (s < -m || s > 1 + m || t < -m || t > 1 + m) return MISSED;
    if (s < m || s > 1 - m || t < m || t > 1 - m) return UNSURE;
    double fs = s * 4 - floor(s * 4), ft = t * 4 - floor(t * 4);
    if (fs < 4 * m || fs > 1 - 4 * m || ft < 4 * m || ft > 1 - 4 * m) return UNSURE;
    if (x_out) *x_out = x;
    return cell_solid((int)(s * 4), (int)(t * 4)) ? SOLID : HOLE;
}

/* ---- the OBJ scene ---- */

static const double tilt = -35.0, quad_z = 1.5;
static const vec light = {-4.0, 2.0, 5.0};
static const float eye[3] = {0, 0, 6};

static void write_obj(const char *name, const char *mtl) {
    quad q = make_quad(tilt, quad_z);
    char text[2048];
    int n = snprintf(text, sizeof text,
                     "mtllib %s\n"
                     "v -3 -3 0\nv 3 -3 0\nv 3 3 0\nv -3 3 0\n"
                     "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                     "usemtl wall\nf 1/1 2/2 3/3 4/4\n",
                     mtl);
    const double st[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    for (int k = 0; k < 4; k++) {
        vec p = quad_corner(&q, st[k][0], st[k][1]);
        n += snprintf(text + n, sizeof text - (size_t)n, "v %.9g %.9g %.9g\n", p.x, p.y, p.z);
    }
    snprintf(text + n, sizeof text - (size_t)n, "usemtl leaf\nf 5/1 6/2 7/3 8/4\n");
    write_text(name, text);
}

static const char mtl_text_fmt[] =
    "newmtl wall\nKd 1 1 1\nmap_Kd checker.png\n"
    "newmtl leaf\nKd 0.8 0.1 0.1\n%s\n";

static void write_mtl(const char *name, const char *map_d_line) {
    char text[512];
    snprintf(text, sizeof text, mtl_text_fmt, map_d_line);
    write_text(name, text);
}

enum { W = 96, H = 96 };

static rp_camera scene_camera(void) {
    return (rp_camera){.type = RP_CAMERA_PINHOLE,
                       .pinhole = {.eye = {eye[0], eye[1], eye[2]}, .look = {0, 0, 0}, .up = {0, 1, 0}, .fov_deg = 50}};
}

/* Per pixel: what its centre's ray sees (SOLID: the quad; HOLE or MISSED: the wall; UNSURE) and,
 * for the wall, whether the light reaches the point (MISSED or HOLE), is blocked (SOLID) or UNSURE. */
typedef struct pixel_class {
    int seen, shadow;
} pixel_class;

/* The pixel centres' primary rays. */
static const rp_ray *pixel_rays(void) {
    static rp_ray rays[W * H];
    rp_camera cam = scene_camera();
    rp_render_primary_rays(&cam, W, H, rays);
    return rays;
}

static void classify(const quad *q, pixel_class *out) {
    const rp_ray *rays = pixel_rays();
    for (int i = 0; i < W * H; i++) {
        vec o = {rays[i].org_x, rays[i].org_y, rays[i].org_z}, d = {rays[i].dir_x, rays[i].dir_y, rays[i].dir_z};
        out[i].seen = quad_cross(q, o, d, 1e30, NULL);
        out[i].shadow = UNSURE;
        if (out[i].seen == SOLID || out[i].seen == UNSURE) continue;
        vec w = vadd(o, vscale(d, -o.z / d.z)); /* the wall, z = 0 */
        if (fabs(w.x) > 2.9 || fabs(w.y) > 2.9) {
            out[i].seen = UNSURE;
            continue;
        }
        out[i].shadow = quad_cross(q, w, vsub(light, w), 1.0, NULL);
    }
}

static float *render(rp_render_scene *rs, rp_render_desc d) {
    rp_camera cam = scene_camera();
    d.width = W, d.height = H, d.camera = &cam;
    float *px = calloc((size_t)W * H * 3, sizeof *px);
    if (px && !rp_render(rs, &d, px, NULL)) {
        free(px);
        return NULL;
    }
    return px;
}

/* Means of a channel over the pixels of each class, divided pixel by pixel by ref's (NULL: 1). */
typedef struct class_means {
    double solid, hole_lit, hole_dark, wall_lit, wall_dark; /* seen quad; wall through a hole (lit / shadowed); wall beside */
    double shadow_hole; /* wall lit through a hole of the quad */
    int n_solid, n_hole_lit, n_hole_dark, n_wall_lit, n_wall_dark, n_shadow_hole;
} class_means;

static class_means means(const float *px, const float *ref, int channels, int c, const pixel_class *pc) {
    class_means m = {0};
    for (int i = 0; i < W * H; i++) {
        size_t k = (size_t)i * (size_t)channels + (size_t)c;
        double v = px[k];
        if (pc[i].seen == SOLID) m.solid += v, m.n_solid++;
        if (pc[i].seen == UNSURE || pc[i].seen == SOLID || pc[i].shadow == UNSURE) continue;
        if (ref) {
            if (!(ref[k] > 1e-4f)) continue;
            v /= ref[k];
        }
        bool lit = pc[i].shadow != SOLID;
        if (pc[i].seen == HOLE && lit) m.hole_lit += v, m.n_hole_lit++;
        if (pc[i].seen == HOLE && !lit) m.hole_dark += v, m.n_hole_dark++;
        if (pc[i].seen == MISSED && lit) m.wall_lit += v, m.n_wall_lit++;
        if (pc[i].seen == MISSED && !lit) m.wall_dark += v, m.n_wall_dark++;
        if (pc[i].shadow == HOLE) m.shadow_hole += v, m.n_shadow_hole++;
    }
    m.solid /= m.n_solid > 0 ? m.n_solid : 1;
    m.hole_lit /= m.n_hole_lit > 0 ? m.n_hole_lit : 1;
    m.hole_dark /= m.n_hole_dark > 0 ? m.n_hole_dark : 1;
    m.wall_lit /= m.n_wall_lit > 0 ? m.n_wall_lit : 1;
    m.wall_dark /= m.n_wall_dark > 0 ? m.n_wall_dark : 1;
    m.shadow_hole /= m.n_shadow_hole > 0 ? m.n_shadow_hole : 1;
    return m;
}

/* Pixel by pixel: the quad where a solid cell is seen, the wall where a hole or nothing is (red
 * above green on the quad, green above red on the wall); returns the pixels that disagree. */
static int wrong_pixels(const float *px, const pixel_class *pc, bool lit_only, const char *what) {
    int wrong = 0;
    for (int i = 0; i < W * H; i++) {
        const float *p = px + 3 * (size_t)i;
        if (pc[i].seen == UNSURE) continue;
        if (lit_only && (pc[i].seen == SOLID ? false : pc[i].shadow != MISSED && pc[i].shadow != HOLE)) continue;
        bool quad_seen = p[0] > 1.5f * p[1], wall_seen = p[1] > 1.2f * p[0];
        bool ok = pc[i].seen == SOLID ? quad_seen : wall_seen;
        if (!ok && wrong++ < 3)
            fprintf(stderr, "%s: pixel (%d, %d) class %d/%d: %g %g %g\n", what, i % W, i / W, pc[i].seen, pc[i].shadow,
                    (double)p[0], (double)p[1], (double)p[2]);
    }
    return wrong;
}

static bool load_obj_scene(const char *obj, rp_scene_data *s, float intensity) {
    char path[1024], err[512] = "";
    bool ok = rp_scene_data_load(tmp_path(obj, path, sizeof path), s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return false;
    /* a point light beside the eye (OBJ has none) */
    rp_light_data *l = calloc(1, sizeof *l);
    if (!l) return false;
    *l = (rp_light_data){.type = RP_LIGHT_DATA_POINT, .position = {(float)light.x, (float)light.y, (float)light.z},
                         .color = {intensity, intensity, intensity}};
    free(s->lights);
    s->lights = l;
    s->light_count = 1;
    return true;
}

static void write_png(const char *name, const float *px) {
    char path[1024];
    rp_image_write(tmp_path(name, path, sizeof path), W, H, 3, px, NULL, 0);
}

static void test_obj_integrators(rp_device *dev) {
    write_mask_png("holes.png", 4, 255, 0);
    write_checker_png("checker.png");
    write_mtl("alpha.mtl", "map_d holes.png");
    write_obj("alpha.obj", "alpha.mtl");
    rp_scene_data s;
    if (!load_obj_scene("alpha.obj", &s, 1.0f)) return;
    const rp_material_data *leaf = &s.materials[s.tri_materials[2]];
    CHECKF(leaf->alpha_mode == RP_ALPHA_MASK && leaf->map_alpha > 0 && leaf->alpha == 1.0f && leaf->alpha_cutoff == 0.5f,
           "map_d: mode %d map %d alpha %g cutoff %g", (int)leaf->alpha_mode, (int)leaf->map_alpha, (double)leaf->alpha,
           (double)leaf->alpha_cutoff);
    if (leaf->map_alpha > 0) {
        const rp_texture_data *t = &s.textures[leaf->map_alpha - 1];
        CHECK(t->alpha != NULL && t->width == TEX && t->alpha[0] == 0 && t->alpha[(TEX - 1) * TEX] == 255);
        CHECK(t->rgb[0] == 255 && t->rgb[1] == 255);
    }
    const rp_material_data *wall = &s.materials[s.tri_materials[0]];
    CHECK(wall->alpha_mode == RP_ALPHA_OPAQUE && wall->map_alpha == 0 && s.textures[wall->map_kd].alpha == NULL);

    char err[512] = "";
    rp_render_scene *rs = rp_render_scene_new(dev, &s, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s", err);
    if (!rs) {
        rp_scene_data_free(&s);
        return;
    }
    quad q = make_quad(tilt, quad_z);
    static pixel_class pc[W * H];
    classify(&q, pc);
    int n_solid = 0, n_hole = 0, n_shadow_hole = 0, n_shadow = 0;
    for (int i = 0; i < W * H; i++) {
        n_solid += pc[i].seen == SOLID;
        n_hole += pc[i].seen == HOLE;
        n_shadow_hole += pc[i].seen == MISSED && pc[i].shadow == HOLE;
        n_shadow += pc[i].seen == MISSED && pc[i].shadow == SOLID;
    }
    CHECKF(n_solid > 150 && n_hole > 150 && n_shadow_hole > 40 && n_shadow > 40,
           "the view: %d solid, %d hole, %d wall lit through a hole, %d wall in the shadow", n_solid, n_hole, n_shadow_hole,
           n_shadow);

    /* albedo: exact, pixel by pixel */
    float *px = render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_ALBEDO});
    CHECK(px != NULL);
    if (px) {
        int wrong = wrong_pixels(px, pc, false, "albedo");
        CHECKF(wrong == 0, "albedo: %d pixels wrong", wrong);
        write_png("albedo.png", px);
        free(px);
    }
    /* depth: the quad's or the wall's distance */
    px = render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_DEPTH});
    if (px) {
        const rp_ray *rays = pixel_rays();
        int wrong = 0;
        for (int i = 0; i < W * H; i++) {
            if (pc[i].seen == UNSURE) continue;
            vec o = {rays[i].org_x, rays[i].org_y, rays[i].org_z}, d = {rays[i].dir_x, rays[i].dir_y, rays[i].dir_z};
            double want = -o.z / d.z;
            if (pc[i].seen == SOLID) quad_cross(&q, o, d, 1e30, &want);
            wrong += fabs(px[i] - want) > 1e-3 * want;
        }
        CHECKF(wrong == 0, "depth: %d pixels wrong", wrong);
        free(px);
    }
    /* eye light: |cos| of the quad's normal (tilted 35 degrees) or the wall's */
    for (int packet = 16; packet >= -1; packet -= 17) {
        px = render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_EYELIGHT, .packet = packet});
        if (!px) continue;
        const rp_ray *rays = pixel_rays();
        int wrong = 0;
        for (int i = 0; i < W * H; i++) {
            if (pc[i].seen == UNSURE) continue;
            vec d = {rays[i].dir_x, rays[i].dir_y, rays[i].dir_z};
            double want = pc[i].seen == SOLID ? fabs(vdot(q.n, d)) : fabs(d.z);
            wrong += fabs(px[3 * i] - want) > 1e-3;
        }
        CHECKF(wrong == 0, "eye light (packet %d): %d pixels wrong", packet, wrong);
        free(px);
    }
    /* Whitted (packets and ray by ray), direct, path, instant radiosity: the colours, and the
     * shadow's holes */
    const struct {
        rp_render_desc d;
        const char *name;
    } runs[] = {
        {{.integrator = RP_INTEGRATOR_WHITTED}, "whitted"},
        {{.integrator = RP_INTEGRATOR_WHITTED, .packet = -1}, "whitted-single"},
        {{.integrator = RP_INTEGRATOR_DIRECT, .spp = 4}, "direct"},
        {{.integrator = RP_INTEGRATOR_PATH, .spp = 8}, "path"},
        {{.integrator = RP_INTEGRATOR_IR, .spp = 2}, "ir"},
    };
    for (size_t r = 0; r < sizeof runs / sizeof runs[0]; r++) {
        /* the image and its reference: the same scene with the quad cut out everywhere (alpha 0),
         * the wall lit wherever the quad does not hide it from the camera */
        float *img[2] = {NULL, NULL};
        bool pbr = runs[r].d.integrator != RP_INTEGRATOR_WHITTED;
        for (int k = 0; k < 2; k++) {
            rp_scene_data s2;
            if (!load_obj_scene("alpha.obj", &s2, pbr ? 40.0f : 1.0f)) continue; /* pbr: the inverse square law */
            if (k == 1) s2.materials[s2.tri_materials[2]].alpha = 0.0f;
            rp_render_scene *use = rp_render_scene_new(dev, &s2, NULL, err, sizeof err);
            CHECKF(use != NULL, "%s", err);
            if (use) img[k] = render(use, runs[r].d);
            CHECK(img[k] != NULL);
            rp_render_scene_release(use);
            rp_scene_data_free(&s2);
        }
        if (img[0] && img[1]) {
            int wrong = wrong_pixels(img[0], pc, true, runs[r].name);
            CHECKF(wrong <= (runs[r].d.integrator == RP_INTEGRATOR_PATH || runs[r].d.integrator == RP_INTEGRATOR_IR ? 8 : 0),
                   "%s: %d pixels wrong", runs[r].name, wrong);
            class_means g = means(img[0], img[1], 3, 1, pc); /* green (the wall's) over the reference's */
            CHECKF(g.n_wall_lit > 50 && g.n_wall_dark > 50 && g.n_shadow_hole > 50 && g.wall_dark < 0.3 &&
                       g.shadow_hole > 0.8 && g.hole_lit > 0.8 && g.wall_lit > 0.8,
                   "%s over the wall without the quad: lit %g (%d), in the shadow %g (%d), lit through the shadow's "
                   "holes %g (%d), seen through a hole %g (%d)",
                   runs[r].name, g.wall_lit, g.n_wall_lit, g.wall_dark, g.n_wall_dark, g.shadow_hole, g.n_shadow_hole,
                   g.hole_lit, g.n_hole_lit);
            char name[64];
            snprintf(name, sizeof name, "%s.png", runs[r].name);
            write_png(name, img[0]);
        }
        free(img[0]);
        free(img[1]);
    }
    /* ambient occlusion: the quad's front sees nothing (1); the wall behind it sees the quad's
     * solid cells, where the hole lets the camera see it */
    px = render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_AO, .spp = 8, .ao_distance = 3.0f});
    if (px) {
        class_means a = means(px, NULL, 3, 0, pc);
        CHECKF(a.solid > 0.99 && a.n_hole_lit + a.n_hole_dark > 100 &&
                   (a.hole_lit * a.n_hole_lit + a.hole_dark * a.n_hole_dark) / (a.n_hole_lit + a.n_hole_dark) < 0.9,
               "ao: quad %g, wall through the holes %g / %g", a.solid, a.hole_lit, a.hole_dark);
        write_png("ao.png", px);
        free(px);
    }
    rp_render_scene_release(rs);
    rp_scene_data_free(&s);
}

/* A MASK material that cuts nothing (cutoff 0) takes the fix-up paths and must change nothing: the
 * same bytes as the opaque material, every integrator; BLEND at alpha 0.5 lets about half the rays
 * through, the same ones on 1 and 3 threads. */
static void test_same_bytes(void) {
    rp_scene_data s;
    if (!load_obj_scene("alpha.obj", &s, 30.0f)) return;
    rp_material_data *leaf = &s.materials[s.tri_materials[2]];
    const rp_render_desc runs[] = {
        {.integrator = RP_INTEGRATOR_WHITTED},
        {.integrator = RP_INTEGRATOR_WHITTED, .packet = -1},
        {.integrator = RP_INTEGRATOR_EYELIGHT},
        {.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_NORMAL},
        {.integrator = RP_INTEGRATOR_DIRECT, .spp = 2},
        {.integrator = RP_INTEGRATOR_PATH, .spp = 2},
        {.integrator = RP_INTEGRATOR_IR, .spp = 1},
        {.integrator = RP_INTEGRATOR_AO, .spp = 2},
    };
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    char err[512] = "";
    for (size_t r = 0; r < sizeof runs / sizeof runs[0]; r++) {
        float *img[2] = {NULL, NULL};
        for (int k = 0; k < 2; k++) {
            leaf->alpha_mode = k == 0 ? RP_ALPHA_OPAQUE : RP_ALPHA_MASK;
            leaf->alpha_cutoff = 0.0f;
            rp_render_scene *rs = rp_render_scene_new(dev, &s, NULL, err, sizeof err);
            CHECKF(rs != NULL, "%s", err);
            if (rs) img[k] = render(rs, runs[r]);
            rp_render_scene_release(rs);
        }
        CHECKF(img[0] && img[1] && memcmp(img[0], img[1], (size_t)W * H * 3 * sizeof(float)) == 0,
               "integrator %d: a MASK that cuts nothing changed the image", (int)runs[r].integrator);
        free(img[0]);
        free(img[1]);
    }
    /* BLEND, alpha 0.5, no texture */
    leaf->alpha_mode = RP_ALPHA_BLEND;
    leaf->alpha = 0.5f;
    leaf->map_alpha = 0;
    quad q = make_quad(tilt, quad_z);
    static pixel_class pc[W * H];
    classify(&q, pc);
    float *img[2] = {NULL, NULL};
    for (int k = 0; k < 2; k++) {
        rp_device *d = rp_device_new(&(rp_device_desc){.threads = k == 0 ? 1 : 3});
        rp_render_scene *rs = rp_render_scene_new(d, &s, NULL, err, sizeof err);
        CHECKF(rs != NULL, "%s", err);
        if (rs) img[k] = render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_PATH, .spp = 2});
        rp_render_scene_release(rs);
        rp_device_release(d);
    }
    CHECKF(img[0] && img[1] && memcmp(img[0], img[1], (size_t)W * H * 3 * sizeof(float)) == 0,
           "BLEND: 1 and 3 threads differ");
    rp_render_scene *rs = rp_render_scene_new(dev, &s, NULL, err, sizeof err);
    float *alb = rs ? render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_ALBEDO}) : NULL;
    if (alb) {
        int quad_px = 0, through = 0;
        for (int i = 0; i < W * H; i++) {
            if (pc[i].seen != SOLID && pc[i].seen != HOLE) continue;
            quad_px++;
            through += alb[3 * i + 1] > alb[3 * i];
        }
        CHECKF(quad_px > 300 && through > quad_px * 3 / 10 && through < quad_px * 7 / 10,
               "BLEND 0.5: %d of %d pixels see through", through, quad_px);
        write_png("blend.png", alb);
    }
    free(alb);
    rp_render_scene_release(rs);
    free(img[0]);
    free(img[1]);
    rp_device_release(dev);
    rp_scene_data_free(&s);
}

/* The albedo of the loaded OBJ scene s must show the quad's holes exactly where the plain mask
 * cuts them (label names the case); s is freed. */
static void check_albedo_holes(rp_device *dev, rp_scene_data *s, const char *label) {
    char err[512] = "";
    rp_render_scene *rs = rp_render_scene_new(dev, s, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s", err);
    float *px = rs ? render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_ALBEDO}) : NULL;
    if (px) {
        static pixel_class pc[W * H];
        quad q = make_quad(tilt, quad_z);
        classify(&q, pc);
        int wrong = wrong_pixels(px, pc, false, label);
        CHECKF(wrong == 0, "%s: %d pixels wrong", label, wrong);
    }
    free(px);
    rp_render_scene_release(rs);
    rp_scene_data_free(s);
}

/* map_d of a grey PNG without an alpha channel: its grey value is the mask. */
static void test_grey_mask(rp_device *dev) {
    write_mask_png("holes_grey.png", 1, 255, 0);
    write_mtl("grey.mtl", "map_d holes_grey.png");
    write_obj("grey.obj", "grey.mtl");
    rp_scene_data s;
    if (!load_obj_scene("grey.obj", &s, 1.0f)) return;
    const rp_material_data *leaf = &s.materials[s.tri_materials[2]];
    CHECK(leaf->map_alpha > 0 && s.textures[leaf->map_alpha - 1].alpha == NULL);
    check_albedo_holes(dev, &s, "grey map_d");
}

/* map_d with the material's texture transform (MTL -o): the inverted hole pattern moved by one cell
 * (u + 0.25) cuts the same holes as the plain one (the cut-out test reads the uv shading reads). */
static void test_mask_transform(rp_device *dev) {
    write_mask_png("holes_inv.png", 4, 0, 255);
    write_mtl("moved.mtl", "map_d -o 0.25 0 holes_inv.png");
    write_obj("moved.obj", "moved.mtl");
    rp_scene_data s;
    if (!load_obj_scene("moved.obj", &s, 1.0f)) return;
    check_albedo_holes(dev, &s, "map_d -o 0.25 0 of the inverted mask");
}

/* ---- the default camera's framing and the renderer's public closest hit ---- */

/* A fully cut-out 4x4 quad facing +z (z = 0) and an opaque 3x3 wall of 72 triangles facing +x
 * (x = 0) through its middle. Seen from +z, the quad would be all front faces; cut out, the view
 * from +z shows the wall edge on: the default camera must look from +x. And a ray through the quad
 * onto the wall: rp_render_scene_intersect1 passes the quad, rp_intersect1 stops on it. */
static void test_default_camera(rp_device *dev) {
    write_mask_png("clear.png", 4, 0, 0);
    write_text("frame.mtl", "newmtl leaf\nKd 0.2 0.8 0.2\nmap_d clear.png\nnewmtl wall\nKd 0.8 0.8 0.8\n");
    char text[16384];
    int n = snprintf(text, sizeof text,
                     "mtllib frame.mtl\nv -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                     "usemtl leaf\nf 1/1 2/2 3/3 4/4\nusemtl wall\n");
    for (int j = 0; j <= 6; j++) /* (y, z) on a 7x7 lattice, row j at y = -1.5 + 0.5 j */
        for (int i = 0; i <= 6; i++)
            n += snprintf(text + n, sizeof text - (size_t)n, "v 0 %g %g\n", -1.5 + 0.5 * j, 1.5 - 0.5 * i);
    for (int j = 0; j < 6; j++) /* z falling along i, y rising along j: the normal is +x */
        for (int i = 0; i < 6; i++) {
            int a = 5 + j * 7 + i;
            n += snprintf(text + n, sizeof text - (size_t)n, "f %d %d %d %d\n", a, a + 1, a + 8, a + 7);
        }
    write_text("frame.obj", text);
    char err[512] = "";
    rp_scene_data s;
    if (!load_obj_scene("frame.obj", &s, 1.0f)) return;
    rp_render_scene *rs = rp_render_scene_new(dev, &s, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s", err);
    if (rs) {
        rp_camera cam = rp_render_scene_default_camera(rs);
        const float *e = cam.pinhole.eye;
        CHECKF(e[0] > 3.0f && fabsf(e[1]) < 1e-3f && fabsf(e[2]) < 1e-3f,
               "default camera at %g %g %g: the cut-out quad framed the view (the wall faces +x)", e[0], e[1], e[2]);
        rp_rayhit rh = {.ray = {.org_x = 2, .org_y = 0.2f, .org_z = 1, .dir_x = -1, .dir_z = -1, .tfar = INFINITY,
                                .mask = 0xFFFFFFFFu},
                        .hit = {.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID}};
        rp_rayhit core = rh;
        rp_intersect1(rp_render_scene_core(rs), &core);
        rp_render_scene_intersect1(rs, &rh);
        CHECKF(core.ray.tfar == 1.0f, "the core's hit on the quad at t %g", core.ray.tfar);
        CHECKF(rh.hit.geom_id != RP_INVALID_ID && rh.ray.tfar == 2.0f && rh.hit.Ng_x != 0.0f,
               "rp_render_scene_intersect1: t %g (the wall behind the cut-out quad is at 2)", rh.ray.tfar);
        rp_render_scene_release(rs);
    }
    rp_scene_data_free(&s);
}

/* ---- glTF: alphaMode MASK, alphaCutoff 0.3, over an opaque wall ---- */

/* The quad (z = 1.5, facing +z) and the wall (z = 0): 8 positions, 8 uvs, 12 indices. */
static void write_gltf_bin(const char *name) {
    float pos[24], uv[16];
    uint16_t idx[12] = {0, 1, 2, 0, 2, 3, 0, 1, 2, 0, 2, 3};
    const float st[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    for (int k = 0; k < 4; k++) {
        pos[3 * k] = 2 * st[k][0] - 1, pos[3 * k + 1] = 2 * st[k][1] - 1, pos[3 * k + 2] = 1.5f;
        pos[12 + 3 * k] = 6 * st[k][0] - 3, pos[12 + 3 * k + 1] = 6 * st[k][1] - 3, pos[12 + 3 * k + 2] = 0;
        /* glTF's uv origin is the image's top left: v = 1 - t */
        uv[2 * k] = uv[8 + 2 * k] = st[k][0];
        uv[2 * k + 1] = uv[8 + 2 * k + 1] = 1 - st[k][1];
    }
    unsigned char buf[96 + 64 + 24];
    memcpy(buf, pos, 96);
    memcpy(buf + 96, uv, 64);
    memcpy(buf + 160, idx, 24);
    write_bytes(name, buf, sizeof buf);
}

static const char gltf_text[] =
    "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],\n"
    "\"meshes\":[{\"primitives\":[\n"
    "  {\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"indices\":2,\"material\":0},\n"
    "  {\"attributes\":{\"POSITION\":3,\"TEXCOORD_0\":4},\"indices\":5,\"material\":1}]}],\n"
    "\"materials\":[{\"name\":\"leaf\",\"alphaMode\":\"MASK\",\"alphaCutoff\":0.3,\"doubleSided\":true,\n"
    "    \"pbrMetallicRoughness\":{\"baseColorFactor\":[0.8,0.1,0.1,1],\"baseColorTexture\":{\"index\":0},\"metallicFactor\":0}},\n"
    "  {\"name\":\"wall\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[0.1,0.8,0.1,1],\"metallicFactor\":0}}],\n"
    "\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"mask_gltf.png\"}],\n"
    "\"buffers\":[{\"uri\":\"alpha.bin\",\"byteLength\":184}],\n"
    "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":96,\"byteLength\":32},\n"
    "  {\"buffer\":0,\"byteOffset\":160,\"byteLength\":12},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":48},\n"
    "  {\"buffer\":0,\"byteOffset\":128,\"byteLength\":32},{\"buffer\":0,\"byteOffset\":172,\"byteLength\":12}],\n"
    "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"min\":[-1,-1,1.5],\"max\":[1,1,1.5]},\n"
    "  {\"bufferView\":1,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},\n"
    "  {\"bufferView\":2,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"},\n"
    "  {\"bufferView\":3,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"min\":[-3,-3,0],\"max\":[3,3,0]},\n"
    "  {\"bufferView\":4,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},\n"
    "  {\"bufferView\":5,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]}\n";

static void test_gltf_mask(rp_device *dev) {
    write_mask_png("mask_gltf.png", 4, 102, 51); /* alpha 0.4 (kept at cutoff 0.3) and 0.2 (cut) */
    write_gltf_bin("alpha.bin");
    write_text("alpha.gltf", gltf_text);
    char path[1024], err[512] = "";
    rp_scene_data s;
    bool ok = rp_scene_data_load(tmp_path("alpha.gltf", path, sizeof path), &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    const rp_material_data *leaf = NULL;
    for (size_t i = 0; i < s.material_count; i++)
        if (strcmp(s.materials[i].name, "leaf") == 0) leaf = &s.materials[i];
    CHECK(leaf != NULL);
    if (leaf) {
        CHECKF(leaf->alpha_mode == RP_ALPHA_MASK && fabsf(leaf->alpha_cutoff - 0.3f) < 1e-6f && leaf->alpha == 1.0f &&
                   leaf->map_kd >= 0 && leaf->map_alpha == leaf->map_kd + 1,
               "glTF leaf: mode %d cutoff %g alpha %g map_kd %d map_alpha %d", (int)leaf->alpha_mode,
               (double)leaf->alpha_cutoff, (double)leaf->alpha, (int)leaf->map_kd, (int)leaf->map_alpha);
    }
    rp_render_scene *rs = rp_render_scene_new(dev, &s, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s", err);
    float *px = rs ? render(rs, (rp_render_desc){.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_ALBEDO}) : NULL;
    if (px) {
        static pixel_class pc[W * H];
        quad q = make_quad(0.0, 1.5);
        classify(&q, pc);
        int n_solid = 0, n_hole = 0;
        for (int i = 0; i < W * H; i++) n_solid += pc[i].seen == SOLID, n_hole += pc[i].seen == HOLE;
        int wrong = wrong_pixels(px, pc, false, "glTF MASK");
        CHECKF(wrong == 0 && n_solid > 100 && n_hole > 100, "glTF MASK: %d pixels wrong (%d solid, %d hole)", wrong,
               n_solid, n_hole);
        write_png("gltf_albedo.png", px);
    }
    free(px);
    rp_render_scene_release(rs);
    rp_scene_data_free(&s);
}

int main(void) {
    tmp_init("/tmp/rp_test_alpha");
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    test_obj_integrators(dev);
    test_same_bytes();
    test_grey_mask(dev);
    test_mask_transform(dev);
    test_gltf_mask(dev);
    test_default_camera(dev);
    rp_device_release(dev);
    return RP_TEST_END();
}
