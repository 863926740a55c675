// rp-test: labels=render timeout=300
/* Alpha cutouts in the stream engine (src/stream: its intersection kernel rejects a hit on a
 * cut-out point and keeps looking): a checker wall behind 60 random quads, masked (an RGBA PNG of
 * random holes, a grey PNG of rings, 2 to 4 repeats across a quad) and BLEND (a ramp) and a few
 * opaque, lit by a point light. The stream's eye rays' hits equal alpha_intersect1's (the tile
 * renderer's queries) bit for bit, and its eye light, Whitted (shadow rays through the holes),
 * path (bounces and shadows, BLEND included) and AO images equal rp_render's value for value, with
 * both schedulers; the statistics count the cut-out hits passed over and still add up. */
#include <math.h>
#include <stdint.h>

#include "../src/render/render.h"
#include "accel/grid/grid.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"
#include "rp_test_png.h"
#include "rp_test_tmp.h"
#include "stream/stream.h"

static uint64_t rng_state = 31;
static float rng_f(void) {
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (float)(rng_state >> 40) * (1.0f / 16777216.0f);
}

enum { TEX = 32 };

static void write_files(void) {
    static uint8_t holes[TEX * TEX * 4], rings[TEX * TEX], ramp[TEX * TEX * 4], checker[TEX * TEX * 3];
    for (int y = 0; y < TEX; y++)
        for (int x = 0; x < TEX; x++) {
            int i = y * TEX + x;
            holes[4 * i] = 220, holes[4 * i + 1] = 60, holes[4 * i + 2] = 40;
            holes[4 * i + 3] = rng_f() < 0.4f ? 0 : 255;
            float dx = (float)x - 15.5f, dy = (float)y - 15.5f;
            rings[i] = ((int)sqrtf(dx * dx + dy * dy) / 3) % 2 ? 255 : 20;
            ramp[4 * i] = 40, ramp[4 * i + 1] = 80, ramp[4 * i + 2] = 230;
            ramp[4 * i + 3] = (uint8_t)(x * 255 / (TEX - 1));
            bool dark = (x / 4 + y / 4) % 2 != 0;
            checker[3 * i] = dark ? 30 : 200, checker[3 * i + 1] = dark ? 120 : 200, checker[3 * i + 2] = dark ? 30 : 200;
        }
    char path[1024];
    CHECK(stbi_write_png(tmp_path("holes.png", path, sizeof path), TEX, TEX, 4, holes, TEX * 4) != 0);
    CHECK(stbi_write_png(tmp_path("rings.png", path, sizeof path), TEX, TEX, 1, rings, TEX) != 0);
    CHECK(stbi_write_png(tmp_path("ramp.png", path, sizeof path), TEX, TEX, 4, ramp, TEX * 4) != 0);
    CHECK(stbi_write_png(tmp_path("checker.png", path, sizeof path), TEX, TEX, 3, checker, TEX * 3) != 0);
    write_text("scene.mtl", "newmtl wall\nKd 1 1 1\nmap_Kd checker.png\n"
                            "newmtl opaque\nKd 0.8 0.8 0.2\n"
                            "newmtl holes\nKd 1 1 1\nmap_Kd holes.png\nmap_d holes.png\n"
                            "newmtl rings\nKd 0.9 0.3 0.9\nKs 0.3 0.3 0.3\nNs 40\nillum 3\nmap_d rings.png\n"
                            "newmtl blend\nKd 1 1 1\nmap_Kd ramp.png\nmap_d ramp.png\n");
    static char obj[65536];
    int n = snprintf(obj, sizeof obj,
                     "mtllib scene.mtl\nv -3 -3 0\nv 3 -3 0\nv 3 3 0\nv -3 3 0\nvt 0 0\nvt 3 0\nvt 3 3\nvt 0 3\n"
                     "usemtl wall\nf 1/1 2/2 3/3 4/4\n");
    static const char *mats[5] = {"opaque", "holes", "holes", "rings", "blend"};
    for (int q = 0; q < 60; q++) {
        float c[3] = {rng_f() * 4 - 2, rng_f() * 4 - 2, 0.2f + rng_f() * 2.5f}, a = rng_f() * 6.2831853f,
              tilt = rng_f() - 0.5f, s = 0.3f + rng_f() * 0.5f, rep = 1 + (float)(int)(rng_f() * 3);
        float u[3] = {cosf(a) * s, sinf(a) * s, tilt * s}, v[3] = {-sinf(a) * s, cosf(a) * s, 0.3f * s};
        static const float ab[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
        for (int k = 0; k < 4; k++)
            n += snprintf(obj + n, sizeof obj - (size_t)n, "v %.9g %.9g %.9g\nvt %g %g\n",
                          c[0] + ab[k][0] * u[0] + ab[k][1] * v[0], c[1] + ab[k][0] * u[1] + ab[k][1] * v[1],
                          c[2] + ab[k][0] * u[2] + ab[k][1] * v[2], rep * (ab[k][0] + 1) / 2, rep * (ab[k][1] + 1) / 2);
        int b = 5 + 4 * q;
        n += snprintf(obj + n, sizeof obj - (size_t)n, "usemtl %s\nf %d/%d %d/%d %d/%d %d/%d\n",
                      mats[(int)(rng_f() * 5) % 5], b, b, b + 1, b + 1, b + 2, b + 2, b + 3, b + 3);
    }
    write_text("scene.obj", obj);
}

static bool same_f(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

enum { W = 72, H = 64 };

int main(void) {
    tmp_init("/tmp/rp_test_stream_alpha");
    write_files();
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    rp_scene_data d;
    char path[1024], err[512] = "";
    bool ok = rp_scene_data_load(tmp_path("scene.obj", path, sizeof path), &d, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return RP_TEST_END();
    for (size_t i = 0; i < d.material_count; i++)
        if (strcmp(d.materials[i].name, "blend") == 0) d.materials[i].alpha_mode = RP_ALPHA_BLEND;
    rp_light_data *l = calloc(1, sizeof *l);
    *l = (rp_light_data){.type = RP_LIGHT_DATA_POINT, .position = {-3, 2, 7}, .color = {40, 40, 40}};
    free(d.lights);
    d.lights = l, d.light_count = 1;
    rp_render_scene *rs = rp_render_scene_new(dev, &d, &(rp_render_scene_desc){.flatten_animation = true}, err, sizeof err);
    CHECKF(rs != NULL, "%s", err);
    grid *g = rs ? grid_build_scene(rp_render_scene_core(rs), NULL, err, sizeof err) : NULL;
    CHECKF(g != NULL, "%s", err);
    size_t n = (size_t)W * H;
    float *px = malloc(n * 3 * sizeof(float)), *ref = malloc(n * 3 * sizeof(float));
    rp_rayhit *hits = malloc(n * sizeof *hits);
    if (g && px && ref && hits) {
        CHECK(rs->cutouts);
        rp_camera cam = {.type = RP_CAMERA_PINHOLE, .pinhole = {.eye = {0.5f, -1, 8}, .look = {0, 0, 0}, .up = {0, 1, 0}, .fov_deg = 45}};
        /* eye rays: the stream's hits against the renderer's query, ray by ray */
        stream_desc sd = {.width = W, .height = H, .camera = &cam};
        stream_stats st;
        CHECKF(stream_render(rs, g, &sd, px, hits, &st, err, sizeof err), "%s", err);
        size_t bad = 0, cut_first = 0;
        for (size_t i = 0; i < n; i++) {
            rp_rayhit rh = {.ray = hits[i].ray};
            rh.ray.tfar = INFINITY;
            rh.hit.geom_id = rh.hit.prim_id = rh.hit.inst_id = RP_INVALID_ID;
            rp_rayhit core = rh;
            rp_intersect1(rp_render_scene_core(rs), &core);
            alpha_intersect1(rs, &rh);
            cut_first += core.hit.prim_id != rh.hit.prim_id;
            /* (u and v of a miss are what the query left: alpha.c's, of the last cut-out hit) */
            bad += !(same_f(rh.ray.tfar, hits[i].ray.tfar) && rh.hit.geom_id == hits[i].hit.geom_id &&
                     rh.hit.prim_id == hits[i].hit.prim_id &&
                     (rh.hit.geom_id == RP_INVALID_ID || (same_f(rh.hit.u, hits[i].hit.u) && same_f(rh.hit.v, hits[i].hit.v))));
        }
        CHECKF(bad == 0 && cut_first > n / 10, "eye rays: %zu of %zu differ from alpha_intersect1 (%zu first hit a cut-out point)",
               bad, n, cut_first);
        CHECKF(st.cutouts > 0 && st.cutouts <= st.tests, "eye rays: %llu cut-out hits passed over, %llu tests",
               (unsigned long long)st.cutouts, (unsigned long long)st.tests);

        static const rp_integrator_type integrators[4] = {RP_INTEGRATOR_EYELIGHT, RP_INTEGRATOR_WHITTED, RP_INTEGRATOR_PATH,
                                                          RP_INTEGRATOR_AO};
        static const char *names[4] = {"eyelight", "whitted", "path", "ao"};
        for (int k = 0; k < 4; k++) {
            rp_render_desc rd = {.width = W, .height = H, .integrator = integrators[k], .spp = k == 2 ? 4 : 1,
                                 .camera = &cam};
            CHECK(rp_render(rs, &rd, ref, NULL));
            for (int wave = 0; wave < 2; wave++) {
                stream_desc s2 = {.width = W, .height = H, .camera = &cam, .render = &rd, .wavefront = wave == 1};
                CHECKF(stream_render(rs, g, &s2, px, NULL, &st, err, sizeof err), "%s", err);
                size_t diff = 0, lit = 0;
                for (size_t i = 0; i < n * 3; i++) diff += !same_f(px[i], ref[i]), lit += ref[i] > 0.0f;
                CHECKF(diff == 0 && lit > n, "%s (%s): %zu of %zu values differ from rp_render's", names[k],
                       wave ? "wavefront" : "multipass", diff, n * 3);
                uint64_t tests = 0;
                for (int j = 0; j < RP_RAY_KIND_COUNT; j++) {
                    tests += st.kind[j].tests;
                    CHECK(st.kind[j].hits <= st.kind[j].rays);
                }
                CHECK(tests == st.tests && st.cutouts > 0 && st.cutouts <= st.tests);
                CHECK(st.passes == st.traversal_passes + st.intersection_passes + st.other_passes);
            }
            char name[64];
            snprintf(name, sizeof name, "stream_%s.png", names[k]);
            rp_image_write(tmp_path(name, path, sizeof path), W, H, 3, px, NULL, 0);
        }
    }
    free(px), free(ref), free(hits);
    grid_free(g);
    rp_render_scene_release(rs);
    rp_scene_data_free(&d);
    rp_device_release(dev);
    return RP_TEST_END();
}
