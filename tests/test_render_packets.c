/* Whitted in n x n packets (Overbeck et al. 2008) gives the image of the depth-first single-ray
 * tracer bit for bit (float framebuffer), for every traversal (auto, masked, ranged, partition,
 * span, single, simd), packet side 4..32 and frusta on and off, on the built-in room and shared scenes;
 * images whose size is no multiple of the packet side test the partial blocks at the edges. Also:
 * counting work does not change the image, and it counts each ray kind. */
#include <math.h>
#include <stdint.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"

static const rp_traversal TRAVERSALS[] = {RP_TRAVERSAL_AUTO,      RP_TRAVERSAL_MASKED, RP_TRAVERSAL_RANGED,
                                          RP_TRAVERSAL_PARTITION, RP_TRAVERSAL_SPAN,   RP_TRAVERSAL_SINGLE,
                                          RP_TRAVERSAL_SIMD, RP_TRAVERSAL_MLRT};
static const int PACKETS[] = {4, 8, 16, 32};

static void check_scene(rp_device *dev, const char *name, const rp_scene_data *data, int w, int h) {
    char err[256] = "";
    rp_render_scene *rs = rp_render_scene_new(dev, data, NULL, err, sizeof err);
    CHECKF(rs != NULL, "%s: %s", name, err);
    if (!rs) return;
    size_t count = (size_t)w * (size_t)h * 3;
    float *ref = malloc(sizeof(float) * count), *px = malloc(sizeof(float) * count);
    rp_render_desc desc = {.width = w, .height = h, .packet = -1};
    rp_render_stats ref_st, st;
    CHECK(rp_render(rs, &desc, ref, &ref_st));
    int bad_modes = 0;
    for (size_t t = 0; t < sizeof TRAVERSALS / sizeof TRAVERSALS[0]; t++)
        for (size_t p = 0; p < sizeof PACKETS / sizeof PACKETS[0]; p++)
            for (int fr = 0; fr < 2; fr++) {
                desc.packet = PACKETS[p];
                desc.traversal = TRAVERSALS[t];
                desc.no_frustum = fr == 1;
                desc.count_work = t == 0 && fr == 0;
                memset(px, 0, sizeof(float) * count);
                bool ok = rp_render(rs, &desc, px, &st);
                size_t diff = 0;
                for (size_t i = 0; i < count; i++) diff += memcmp(&px[i], &ref[i], sizeof(float)) != 0;
                bool same_rays = memcmp(st.rays, ref_st.rays, sizeof st.rays) == 0;
                CHECKF(ok && diff == 0 && same_rays,
                       "%s: traversal %d, packet %d, frustum %s: %zu of %zu values differ from the single-ray "
                       "tracer, rays %s",
                       name, (int)TRAVERSALS[t], PACKETS[p], fr ? "off" : "on", diff, count,
                       same_rays ? "equal" : "differ");
                bad_modes += !(ok && diff == 0);
                if (desc.count_work) {
                    /* every ray kind that was traced did traversal work, counted per kind */
                    for (int k = 0; k < RP_RAY_KIND_COUNT; k++)
                        CHECKF((st.rays[k] == 0) == (st.work[k].rays == 0) &&
                                   (st.rays[k] == 0 || st.work[k].box_tests > 0),
                               "%s: packet %d, kind %d: %llu rays, counters %llu rays %llu box tests", name,
                               PACKETS[p], k, (unsigned long long)st.rays[k], (unsigned long long)st.work[k].rays,
                               (unsigned long long)st.work[k].box_tests);
                } else {
                    for (int k = 0; k < RP_RAY_KIND_COUNT; k++) CHECK(st.work[k].rays == 0);
                }
            }
    printf("%s: %dx%d, %d modes differ; rays primary %llu shadow %llu reflection %llu refraction %llu\n", name, w,
           h, bad_modes, (unsigned long long)ref_st.rays[RP_RAY_PRIMARY], (unsigned long long)ref_st.rays[RP_RAY_SHADOW],
           (unsigned long long)ref_st.rays[RP_RAY_REFLECTION], (unsigned long long)ref_st.rays[RP_RAY_REFRACTION]);
    /* a packet size the tracer does not take is refused */
    desc.packet = 12;
    CHECK(!rp_render(rs, &desc, px, NULL));
    /* so is a camera with no frame, whose rays would be NaN (or one line): the image was NaN */
    desc.packet = 16;
    rp_camera cam = rp_render_scene_default_camera(rs);
    CHECK(rp_render(rs, &(rp_render_desc){.width = w, .height = h, .camera = &cam}, px, NULL));
    for (int k = 0; k < 3; k++) cam.pinhole.up[k] = cam.pinhole.look[k] - cam.pinhole.eye[k];
    CHECK(!rp_render(rs, &(rp_render_desc){.width = w, .height = h, .camera = &cam}, px, NULL));
    cam = rp_render_scene_default_camera(rs);
    memcpy(cam.pinhole.look, cam.pinhole.eye, sizeof cam.pinhole.eye);
    CHECK(!rp_render(rs, &(rp_render_desc){.width = w, .height = h, .camera = &cam, .integrator = RP_INTEGRATOR_PATH},
                     px, NULL));
    cam = rp_render_scene_default_camera(rs);
    cam.pinhole.eye[1] = NAN;
    CHECK(!rp_render(rs, &(rp_render_desc){.width = w, .height = h, .camera = &cam}, px, NULL));
    cam = rp_render_scene_default_camera(rs);
    cam.pinhole.fov_deg = 180.0f;
    CHECK(!rp_render(rs, &(rp_render_desc){.width = w, .height = h, .camera = &cam}, px, NULL));
    free(ref);
    free(px);
    rp_render_scene_release(rs);
}

static void check_file(rp_device *dev, const char *file, int w, int h) {
    char buf[512], err[512] = "";
    const char *path = rp_test_scene(file, buf, sizeof buf);
    CHECKF(path != NULL, "%s", file);
    if (!path) return;
    rp_scene_data d;
    bool ok = rp_scene_data_load(path, &d, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    check_scene(dev, file, &d, w, h);
    rp_scene_data_free(&d);
}

int main(void) {
    /* 2 threads: blocks of one image are traced concurrently, with per-thread counters merged */
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    CHECK(dev != NULL);
    if (!dev) return RP_TEST_END();
    bool small = rp_test_sanitized();
    rp_scene_data room;
    CHECK(rp_default_scene(&room));
    check_scene(dev, "default room", &room, small ? 37 : 75, small ? 29 : 53);
    rp_default_scene_free(&room);
    check_file(dev, "cornell_box/cornell_box.obj", small ? 33 : 66, small ? 33 : 66);
    check_file(dev, "spd_teapot.nff.gz", small ? 35 : 70, small ? 27 : 50);
    check_file(dev, "bart_museum5.tar.gz", small ? 35 : 70, small ? 27 : 50);
    rp_device_release(dev);
    return RP_TEST_END();
}
