/* Rendered images: the Cornell box and the built-in room (160x120, Whitted) equal the checked-in
 * references in tests/data/render/ exactly (8-bit sRGB PNG, any pixel difference fails and writes a
 * diff image); and an image is bit-identical (float framebuffer) with 1, 2 and 3 threads.
 * RP_UPDATE_REFERENCES=1 rewrites the references from the current renderer. */
#include <math.h>
#include <stdint.h>
#include <sys/stat.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wswitch-enum"
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#include <stb/stb_image.h>
#pragma GCC diagnostic pop
#pragma GCC diagnostic ignored "-Wunused-function"

enum { W = 160, H = 120 };

static const char *tmp_path(char *buf, size_t size, const char *name) {
    const char *dir = getenv("RP_TEST_TMP");
    if (!dir) dir = ".";
    mkdir(dir, 0777);
    snprintf(buf, size, "%s/%s", dir, name);
    return buf;
}

/* Renders data with `threads` threads; returns a malloc'ed W*H*3 float image or NULL. */
static float *render(const rp_scene_data *data, int threads, int spp, rp_integrator_type integrator) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = threads});
    CHECK(dev != NULL);
    if (!dev) return NULL;
    char err[256] = "";
    rp_render_scene *rs = rp_render_scene_new(dev, data, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s", err);
    float *px = NULL;
    if (rs) {
        px = malloc(sizeof(float) * W * H * 3);
        rp_render_desc desc = {.width = W, .height = H, .spp = spp, .integrator = integrator};
        rp_render_stats st;
        CHECK(rp_render(rs, &desc, px, &st));
        CHECK(st.rays[RP_RAY_PRIMARY] == (uint64_t)W * H * (uint64_t)spp);
        rp_render_scene_release(rs);
    }
    rp_device_release(dev);
    return px;
}

/* Compares an image with the reference PNG through the 8-bit encoding the writer uses. */
static void compare_reference(const float *px, const char *name) {
    char file[128], out[512], ref[512], diff[512] = "", err[512] = "";
    snprintf(file, sizeof file, "%s.png", name);
    tmp_path(out, sizeof out, file);
    const char *src = getenv("RP_SOURCE_DIR");
    snprintf(ref, sizeof ref, "%s/tests/data/render/%s.png", src ? src : "..", name);
    CHECKF(rp_image_write(out, W, H, 3, px, err, sizeof err), "%s", err);
    if (getenv("RP_UPDATE_REFERENCES")) {
        CHECKF(rp_image_write(ref, W, H, 3, px, err, sizeof err), "%s", err);
        fprintf(stderr, "wrote reference %s\n", ref);
    }
    int w, h, c, rw, rh, rc;
    uint8_t *a = stbi_load(out, &w, &h, &c, 3);
    uint8_t *b = stbi_load(ref, &rw, &rh, &rc, 3);
    CHECKF(b != NULL, "reference %s missing (RP_UPDATE_REFERENCES=1 writes it)", ref);
    if (a && b) {
        CHECKF(w == rw && h == rh, "%s: size %dx%d, reference %dx%d", name, w, h, rw, rh);
        if (w == rw && h == rh) {
            int bad = 0, maxd = 0;
            float *dimg = malloc(sizeof(float) * (size_t)(w * h * 3));
            for (int i = 0; i < w * h * 3; i++) {
                int d = abs((int)a[i] - (int)b[i]);
                if (d > maxd) maxd = d;
                bad += d != 0;
                dimg[i] = d ? 1.0f : 0.0f;
            }
            if (bad) {
                snprintf(file, sizeof file, "%s_diff.png", name);
                tmp_path(diff, sizeof diff, file);
                rp_image_write(diff, w, h, 3, dimg, err, sizeof err);
            }
            CHECKF(bad == 0, "%s: %d channel values differ from %s (max %d); render %s, diff image %s", name, bad,
                   ref, maxd, out, diff);
            free(dimg);
        }
    }
    stbi_image_free(a);
    stbi_image_free(b);
}

static void test_scene(const char *name, const rp_scene_data *data) {
    float *px = render(data, 0, 1, RP_INTEGRATOR_WHITTED);
    if (px) compare_reference(px, name);
    free(px);

    /* Thread counts: 1, 2, 3 give the same floats, with jittered samples and with eye light. */
    for (int mode = 0; mode < 2; mode++) {
        rp_integrator_type integ = mode ? RP_INTEGRATOR_EYELIGHT : RP_INTEGRATOR_WHITTED;
        int spp = mode ? 1 : 2;
        float *ref = render(data, 1, spp, integ);
        for (int t = 2; t <= 3 && ref; t++) {
            float *o = render(data, t, spp, integ);
            CHECKF(o && memcmp(o, ref, sizeof(float) * W * H * 3) == 0, "%s: %d threads differ from 1 (mode %d)",
                   name, t, mode);
            free(o);
        }
        free(ref);
    }
}

/* Cones (user geometry with the renderer's exact intersector) and spheres: the depth AOV of the
 * centre pixel equals the analytic distance. Camera at z = 5 looking down -z; 3x3 pixels, so the
 * centre pixel's ray is the optical axis. */
static void test_analytic(void) {
    rp_material_data mat = {.kd = {0.5f, 0.5f, 0.5f}, .ior = 1.0f, .illum = -1, .map_kd = -1};
    rp_cone_data cyl = {.base = {0, -1, 0}, .base_radius = 0.5f, .apex = {0, 1, 0}, .apex_radius = 0.5f};
    rp_cone_data cone = {.base = {0, -1, 0}, .base_radius = 1.0f, .apex = {0, 1, 0}, .apex_radius = 0.0f};
    rp_cone_data tilted = {.base = {0, 0, -2}, .base_radius = 0.25f, .apex = {0, 0, 2}, .apex_radius = 0.25f};
    rp_sphere_data sph = {.center = {0, 0, 1}, .radius = 2.0f};
    struct { const rp_cone_data *cone; const rp_sphere_data *sphere; double t; } cases[] = {
        {&cyl, NULL, 4.5}, {&cone, NULL, 4.5}, {&tilted, NULL, INFINITY}, {NULL, &sph, 2.0}};
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        rp_scene_data d;
        memset(&d, 0, sizeof d);
        d.material_count = 1;
        d.materials = &mat;
        d.cone_count = cases[i].cone ? 1 : 0;
        d.cones = (rp_cone_data *)cases[i].cone;
        d.sphere_count = cases[i].sphere ? 1 : 0;
        d.spheres = (rp_sphere_data *)cases[i].sphere;
        char err[256] = "";
        rp_render_scene *rs = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
        CHECKF(rs != NULL, "%s", err);
        if (!rs) continue;
        rp_camera cam = {.type = RP_CAMERA_PINHOLE, .pinhole = {.eye = {0, 0, 5}, .up = {0, 1, 0}, .fov_deg = 40}};
        rp_render_desc desc = {.width = 3, .height = 3, .integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_DEPTH,
                               .camera = &cam};
        float depth[9];
        CHECK(rp_render(rs, &desc, depth, NULL));
        double t = depth[4];
        CHECKF(isinf(cases[i].t) ? t == INFINITY : fabs(t - cases[i].t) < 1e-5, "case %zu: t %g, expected %g", i, t,
               cases[i].t);
        /* Whitted with a headlight also runs over these primitives. */
        float rgb[27];
        desc.integrator = RP_INTEGRATOR_WHITTED;
        CHECK(rp_render(rs, &desc, rgb, NULL));
        CHECK(isinf(cases[i].t) || rgb[12] > 0.1f);
        rp_render_scene_release(rs);
    }
    rp_device_release(dev);
}

/* Progressive frames (rp_render_desc.sample_start): frames of samples [k, k+1) summed for
 * k = 0..n-1 and scaled by 1/n give exactly the floats of one n-spp frame, for the packet and the
 * single-ray Whitted tracers and eye light; sample 0 is the pixel centre, so a 1-spp frame is too. */
static void test_progressive(const char *name, const rp_scene_data *data) {
    enum { N = 4 };
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    char err[256] = "";
    rp_render_scene *rs = dev ? rp_render_scene_new(dev, data, NULL, err, sizeof err) : NULL;
    CHECKF(rs != NULL, "%s", err);
    float *ref = malloc(sizeof(float) * W * H * 3), *frame = malloc(sizeof(float) * W * H * 3);
    float *sum = calloc(W * H * 3, sizeof(float));
    struct { rp_integrator_type integ; int packet; } modes[] = {
        {RP_INTEGRATOR_WHITTED, 0}, {RP_INTEGRATOR_WHITTED, -1}, {RP_INTEGRATOR_EYELIGHT, 0}};
    for (size_t m = 0; rs && m < sizeof modes / sizeof modes[0]; m++) {
        rp_render_desc d = {.width = W, .height = H, .integrator = modes[m].integ, .packet = modes[m].packet};
        memset(sum, 0, sizeof(float) * W * H * 3);
        for (int k = 0; k < N; k++) {
            d.spp = 1;
            d.sample_start = k;
            CHECK(rp_render(rs, &d, frame, NULL));
            if (k == 1) CHECKF(memcmp(frame, sum, sizeof(float) * W * H * 3) != 0, "%s: sample 1 is sample 0", name);
            for (int i = 0; i < W * H * 3; i++) sum[i] += frame[i];
            d.spp = k + 1;
            d.sample_start = 0;
            CHECK(rp_render(rs, &d, ref, NULL));
            bool same = true;
            for (int i = 0; i < W * H * 3 && same; i++)
                same = (k == 0 ? sum[i] : sum[i] * (1.0f / (float)(k + 1))) == ref[i];
            CHECKF(same, "%s mode %zu: %d accumulated 1-spp frames differ from one %d-spp frame", name, m, k + 1,
                   k + 1);
        }
    }
    free(ref);
    free(frame);
    free(sum);
    rp_render_scene_release(rs);
    rp_device_release(dev);
}

/* An emission texture (MTL map_Ke) multiplies Ke: a quad facing the camera, Ke 2 x a 4x1 texture
 * (red, red, blue, blue), shows 2 x the texel's linear colour on each half, in Whitted and path
 * tracing alike; only its front emits under path tracing; it is not sampled as a light, while the
 * same quad without the texture is (two triangle lights). */
static void test_emission_texture(void) {
    char ppm[512], mtl[512], obj[512], obj2[512], err[512] = "";
    tmp_path(ppm, sizeof ppm, "emit.ppm");
    tmp_path(mtl, sizeof mtl, "emit.mtl");
    tmp_path(obj, sizeof obj, "emit.obj");
    tmp_path(obj2, sizeof obj2, "emit_plain.obj");
    FILE *fp = fopen(ppm, "wb");
    CHECK(fp != NULL);
    if (!fp) return;
    static const unsigned char tex[12] = {255, 0, 0, 255, 0, 0, 0, 0, 255, 0, 0, 255};
    fprintf(fp, "P6\n4 1\n255\n");
    fwrite(tex, 1, sizeof tex, fp);
    fclose(fp);
    fp = fopen(mtl, "w");
    if (fp) {
        fprintf(fp, "newmtl glow\nKd 0 0 0\nKe 2 2 2\nmap_Ke emit.ppm\nnewmtl plain\nKd 0 0 0\nKe 2 2 2\n");
        fclose(fp);
    }
    for (int k = 0; k < 2; k++) {
        fp = fopen(k ? obj2 : obj, "w");
        if (!fp) continue;
        fprintf(fp, "mtllib emit.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                    "usemtl %s\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
                k ? "plain" : "glow");
        fclose(fp);
    }
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    CHECK(dev != NULL);
    if (!dev) return;
    for (int k = 0; k < 2; k++) {
        rp_scene_data d;
        bool ok = rp_scene_data_load(k ? obj2 : obj, &d, err, sizeof err);
        CHECKF(ok, "%s", err);
        if (!ok) continue;
        CHECK(d.material_count >= 1 && (k ? d.materials[d.tri_materials[0]].map_ke == 0 : d.materials[d.tri_materials[0]].map_ke == 1));
        rp_render_scene *rs = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
        CHECKF(rs != NULL, "%s", err);
        if (rs) {
            size_t nl = 99;
            rp_render_scene_lights(rs, &nl);
            CHECKF(nl == (k ? 2u : 0u), "%s: %zu lights", k ? "plain emitter" : "textured emitter", nl);
            float *px = malloc(sizeof(float) * W * H * 3);
            for (int pass = 0; k == 0 && px && pass < 3; pass++) {
                /* whitted and path from the front, path from behind */
                rp_camera cam = {.type = RP_CAMERA_PINHOLE,
                                 .pinhole = {.eye = {0, 0, pass == 2 ? -3.0f : 3.0f}, .up = {0, 1, 0}, .fov_deg = 30}};
                rp_render_desc desc = {.width = W, .height = H, .spp = 2, .camera = &cam,
                                       .integrator = pass == 0 ? RP_INTEGRATOR_WHITTED : RP_INTEGRATOR_PATH};
                CHECK(rp_render(rs, &desc, px, NULL));
                /* a quarter of the width in from either side: u = 0.23 and 0.77 (mirrored from behind) */
                const float *l = px + 3 * ((size_t)(H / 2) * W + W / 4), *r = px + 3 * ((size_t)(H / 2) * W + 3 * W / 4);
                float want = pass == 2 ? 0.0f : 2.0f;
                const float *red = pass == 2 ? r : l, *blue = pass == 2 ? l : r;
                CHECKF(fabsf(red[0] - want) < 1e-4f && red[1] == 0.0f && fabsf(red[2]) < 1e-4f && fabsf(blue[0]) < 1e-4f &&
                           fabsf(blue[2] - want) < 1e-4f,
                       "pass %d: red side %g %g %g, blue side %g %g %g, want %g on each", pass, red[0], red[1], red[2],
                       blue[0], blue[1], blue[2], want);
            }
            free(px);
            rp_render_scene_release(rs);
        }
        rp_scene_data_free(&d);
    }
    rp_device_release(dev);
}

int main(void) {
    test_analytic();
    test_emission_texture();
    rp_scene_data room;
    CHECK(rp_default_scene(&room));
    test_scene("default_room", &room);
    test_progressive("default_room", &room);
    rp_default_scene_free(&room);

    char buf[512], err[512] = "";
    const char *path = rp_test_scene("cornell_box/cornell_box.obj", buf, sizeof buf);
    CHECK(path != NULL);
    if (path) {
        rp_scene_data d;
        bool ok = rp_scene_data_load(path, &d, err, sizeof err);
        CHECKF(ok, "%s", err);
        if (ok) {
            test_scene("cornell_box", &d);
            rp_scene_data_free(&d);
        }
    }
    return RP_TEST_END();
}
