// rp-test: timeout=600
/* Every ISA's kernels give the same image (rp_device_desc.isa; `raypack render --isa`: "every
 * choice gives the same image"): shared scenes x random cameras x every integrator, on a device of
 * each SIMD width the CPU has (scalar, SSE, AVX2, AVX-512), compared bit for bit with the scalar
 * kernels' image; Whitted also in every packet traversal, packet size and without frusta. Session
 * 32's sweep of the CLI (702 renders, /work/sweep outside the repository) in a CI-sized form. The
 * cameras are random: RP_TEST_SEED sets the seed (default a fixed one, printed). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"
#include "sys/sys.h"

#define W 40
#define H 30

static uint64_t rng;
static float rnd(void) { /* splitmix64, the top 24 bits */
    uint64_t z = (rng += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    z ^= z >> 31;
    return (float)(z >> 40) * (1.0f / 16777216.0f);
}

typedef struct frame_kind {
    const char *name;
    rp_render_desc d;
} frame_kind;

/* Renders d with camera cam on rs; NULL when rp_render refuses (counted as a failure by the caller). */
static float *render(rp_render_scene *rs, rp_render_desc d, const rp_camera *cam) {
    d.width = W, d.height = H, d.camera = cam;
    size_t n = (size_t)W * H * (size_t)rp_render_channels(&d);
    float *px = malloc(n * sizeof *px);
    if (px && !rp_render(rs, &d, px, NULL)) {
        free(px);
        return NULL;
    }
    return px;
}

int main(void) {
    const char *seed_env = getenv("RP_TEST_SEED");
    uint64_t seed = seed_env ? strtoull(seed_env, NULL, 0) : 0x15a32ull;
    rng = seed;
    printf("test_isa_images: seed %#llx (RP_TEST_SEED)\n", (unsigned long long)seed);
    const bool small = rp_test_sanitized();
    static const char *scenes[] = {"cornell_box/cornell_box.obj", "spd_teapot.nff.gz", "bart_museum5.tar.gz",
                                   "gltf_cube/Cube.gltf", "stanford_bunny_bun_zipper.ply.gz", "dabrovic_sponza.obj.gz"};
    const int n_scenes = small ? 3 : (int)(sizeof scenes / sizeof scenes[0]);
    const int cameras = small ? 1 : 2;

    /* the frames: every integrator, then Whitted's packet settings */
    frame_kind kinds[32];
    int nk = 0;
    kinds[nk++] = (frame_kind){"whitted", {.integrator = RP_INTEGRATOR_WHITTED}};
    kinds[nk++] = (frame_kind){"eyelight", {.integrator = RP_INTEGRATOR_EYELIGHT}};
    /* jittered samples: the baseline copy of the packets' loops (scalar and SSE devices) against
     * the AVX2 copy (render.h, RENDER_X86_AVX2) */
    kinds[nk++] = (frame_kind){"eyelight 3 spp from sample 2",
                               {.integrator = RP_INTEGRATOR_EYELIGHT, .spp = 3, .sample_start = 2}};
    kinds[nk++] = (frame_kind){"whitted 2 spp", {.integrator = RP_INTEGRATOR_WHITTED, .spp = 2}};
    kinds[nk++] = (frame_kind){"direct", {.integrator = RP_INTEGRATOR_DIRECT, .spp = 2}};
    kinds[nk++] = (frame_kind){"path", {.integrator = RP_INTEGRATOR_PATH, .spp = 2}};
    kinds[nk++] = (frame_kind){"ao", {.integrator = RP_INTEGRATOR_AO, .spp = 2}};
    kinds[nk++] = (frame_kind){"ir", {.integrator = RP_INTEGRATOR_IR}};
    kinds[nk++] = (frame_kind){"aov normal", {.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_NORMAL}};
    kinds[nk++] = (frame_kind){"aov depth", {.integrator = RP_INTEGRATOR_AOV, .aov = RP_AOV_DEPTH}};
    kinds[nk++] = (frame_kind){"whitted one ray at a time", {.integrator = RP_INTEGRATOR_WHITTED, .packet = -1}};
    static const rp_traversal travs[] = {RP_TRAVERSAL_MASKED, RP_TRAVERSAL_RANGED, RP_TRAVERSAL_PARTITION,
                                         RP_TRAVERSAL_SINGLE, RP_TRAVERSAL_SIMD,   RP_TRAVERSAL_SPAN,
                                         RP_TRAVERSAL_MLRT};
    static const char *trav_names[] = {"masked", "ranged", "partition", "single", "simd", "span", "mlrt"};
    static const int packets[] = {4, 8, 32};
    for (int t = 0; t < 7 && !small; t++)
        for (int p = 0; p < 3; p++) {
            static char names[21][48];
            snprintf(names[t * 3 + p], sizeof names[0], "whitted %s %dx%d%s", trav_names[t], packets[p], packets[p],
                     p == 1 ? " no frusta" : "");
            kinds[nk++] = (frame_kind){names[t * 3 + p], {.integrator = RP_INTEGRATOR_WHITTED, .packet = packets[p],
                                                          .traversal = travs[t], .no_frustum = p == 1}};
        }

    static const int isas[] = {1, 4, 8, 16};
    int frames = 0, compared = 0;
    for (int si = 0; si < n_scenes; si++) {
        char path[1024];
        if (!rp_test_scene(scenes[si], path, sizeof path)) {
            CHECKF(0, "shared scene %s missing", scenes[si]);
            continue;
        }
        rp_scene_data data;
        char err[512] = "";
        if (!rp_scene_data_load(path, &data, err, sizeof err)) {
            CHECKF(0, "%s: %s", scenes[si], err);
            continue;
        }
        /* the cameras: from the scene's bounds, the eye anywhere in them or a tenth beyond */
        rp_camera cams[2];
        float *ref[2][32] = {{NULL}};
        for (int ii = 0; ii < 4; ii++) {
            if (isas[ii] > sys_cpu_simd_width()) continue;
            rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2, .isa = isas[ii]});
            rp_render_scene *rs = dev ? rp_render_scene_new(dev, &data, NULL, err, sizeof err) : NULL;
            CHECKF(rs != NULL, "%s, isa %d: %s", scenes[si], isas[ii], err);
            if (!rs) {
                rp_device_release(dev);
                continue;
            }
            if (ii == 0) {
                rp_bounds b;
                rp_scene_get_bounds(rp_render_scene_core(rs), &b);
                const float lo[3] = {b.lower_x, b.lower_y, b.lower_z}, hi[3] = {b.upper_x, b.upper_y, b.upper_z};
                for (int c = 0; c < cameras; c++) {
                    rp_pinhole_camera *p = &cams[c].pinhole;
                    cams[c].type = RP_CAMERA_PINHOLE;
                    for (int k = 0; k < 3; k++) {
                        p->eye[k] = lo[k] + (hi[k] - lo[k]) * (-0.1f + 1.2f * rnd());
                        p->look[k] = lo[k] + (hi[k] - lo[k]) * (0.2f + 0.6f * rnd());
                        p->up[k] = k == 1 ? 1.0f : 0.0f;
                    }
                    p->fov_deg = 20.0f + 70.0f * rnd();
                }
            }
            for (int c = 0; c < cameras; c++)
                for (int k = 0; k < nk; k++) {
                    float *px = render(rs, kinds[k].d, &cams[c]);
                    frames++;
                    CHECKF(px != NULL, "%s camera %d %s isa %d: rp_render failed", scenes[si], c, kinds[k].name, isas[ii]);
                    if (!px) continue;
                    if (!ref[c][k]) {
                        ref[c][k] = px;
                        continue;
                    }
                    size_t n = (size_t)W * H * (size_t)rp_render_channels(&kinds[k].d), diff = 0, first = n;
                    for (size_t i = 0; i < n; i++)
                        if (memcmp(&px[i], &ref[c][k][i], sizeof(float)) != 0) {
                            if (first == n) first = i;
                            diff++;
                        }
                    compared++;
                    const rp_pinhole_camera *p = &cams[c].pinhole;
                    CHECKF(diff == 0,
                           "%s, %s, isa %d against scalar: %zu of %zu values differ (first at %zu: %.9g against %.9g); "
                           "camera eye %.9g,%.9g,%.9g look %.9g,%.9g,%.9g fov %.9g",
                           scenes[si], kinds[k].name, isas[ii], diff, n, first, first < n ? (double)px[first] : 0.0,
                           first < n ? (double)ref[c][k][first] : 0.0, (double)p->eye[0], (double)p->eye[1],
                           (double)p->eye[2], (double)p->look[0], (double)p->look[1], (double)p->look[2],
                           (double)p->fov_deg);
                    free(px);
                }
            rp_render_scene_release(rs);
            rp_device_release(dev);
        }
        for (int c = 0; c < 2; c++)
            for (int k = 0; k < nk; k++) free(ref[c][k]);
        rp_scene_data_free(&data);
    }
    printf("test_isa_images: %d frames, %d compared with the scalar kernels' (widest here: %d)\n", frames, compared,
           sys_cpu_simd_width());
    CHECK(compared > 0);
    return RP_TEST_END();
}
