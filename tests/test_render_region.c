/* rp_render_desc.region (the MPI renderer's tiles): a region renders exactly the pixels the whole
 * frame has there, whatever its corner, size, the tile size and the packet size, and leaves every
 * pixel outside it untouched (path, direct, AO and instant radiosity too, whose filter reads a margin
 * around the region); a region outside the image is refused. Random regions and cameras on
 * the Cornell box, BART's kitchen and the built-in room. */
#include <math.h>
#include <stdint.h>

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"

enum { W = 97, H = 61 };

static uint32_t rng = 12345u;
static uint32_t next(void) {
    rng ^= rng << 13;
    rng ^= rng >> 17;
    rng ^= rng << 5;
    return rng;
}
static int range(int lo, int hi) { return lo + (int)(next() % (uint32_t)(hi - lo + 1)); }

static void check_scene(const char *name, const rp_scene_data *data, int trials) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    char err[256] = "";
    rp_render_scene *rs = dev ? rp_render_scene_new(dev, data, NULL, err, sizeof err) : NULL;
    CHECKF(rs != NULL, "%s: %s", name, err);
    if (!rs) {
        if (dev) rp_device_release(dev);
        return;
    }
    float *whole = malloc(sizeof(float) * W * H * 3), *part = malloc(sizeof(float) * W * H * 3);
    rp_camera base = rp_render_scene_default_camera(rs);
    for (int t = 0; t < trials; t++) {
        rp_camera cam = base;
        for (int k = 0; k < 3; k++)
            cam.pinhole.look[k] += (float)(range(-100, 100)) * 0.002f * (1.0f + fabsf(base.pinhole.look[k]));
        static const int packets[] = {4, 8, 16, 32};
        rp_integrator_type integ = t % 3 == 2 ? RP_INTEGRATOR_EYELIGHT : RP_INTEGRATOR_WHITTED;
        rp_render_desc d = {.width = W, .height = H, .camera = &cam, .integrator = integ, .spp = t % 4 == 1 ? 2 : 1};
        CHECK(rp_render(rs, &d, whole, NULL));
        int x0 = range(0, W - 1), y0 = range(0, H - 1);
        int x1 = range(x0 + 1, W), y1 = range(y0 + 1, H);
        rp_render_desc r = d;
        r.region[0] = x0;
        r.region[1] = y0;
        r.region[2] = x1;
        r.region[3] = y1;
        r.tile_size = range(1, 40);
        r.packet = packets[next() % 4];
        if (t % 5 == 3) r.packet = -1; /* the reference tracer */
        for (int i = 0; i < W * H * 3; i++) part[i] = -7.0f;
        CHECK(rp_render(rs, &r, part, NULL));
        int wrong = 0, touched = 0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                for (int k = 0; k < 3; k++) {
                    size_t i = ((size_t)y * W + (size_t)x) * 3 + (size_t)k;
                    bool inside = x >= x0 && x < x1 && y >= y0 && y < y1;
                    if (inside && memcmp(&part[i], &whole[i], sizeof(float)) != 0) wrong++;
                    if (!inside && part[i] != -7.0f) touched++;
                }
        CHECKF(wrong == 0 && touched == 0,
               "%s trial %d: region (%d,%d)-(%d,%d), tile %d, packet %d: %d pixels differ, %d outside written", name,
               t, x0, y0, x1, y1, r.tile_size, r.packet, wrong, touched);
    }
    /* The physically based integrators (the MPI renderer's other tiles): instant radiosity renders
     * the region's margin for its discontinuity buffer, whose filter must then match the frame's. */
    static const rp_integrator_type pbr[] = {RP_INTEGRATOR_PATH, RP_INTEGRATOR_IR, RP_INTEGRATOR_DIRECT,
                                             RP_INTEGRATOR_AO};
    for (int t = 0; t < trials; t++) {
        rp_render_desc d = {.width = W, .height = H, .integrator = pbr[t % 4], .spp = t % 3 == 1 ? 2 : 1,
                            .ir = {.vpls = 4, .interleave = t % 2 ? 3 : 0, .filter = t % 5 == 4 ? 5 : 0}};
        CHECK(rp_render(rs, &d, whole, NULL));
        int x0 = range(0, W - 1), y0 = range(0, H - 1);
        rp_render_desc r = d;
        r.region[0] = x0;
        r.region[1] = y0;
        r.region[2] = range(x0 + 1, W);
        r.region[3] = range(y0 + 1, H);
        r.tile_size = range(1, 40);
        for (int i = 0; i < W * H * 3; i++) part[i] = -7.0f;
        CHECK(rp_render(rs, &r, part, NULL));
        int wrong = 0, touched = 0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                for (int k = 0; k < 3; k++) {
                    size_t i = ((size_t)y * W + (size_t)x) * 3 + (size_t)k;
                    bool inside = x >= r.region[0] && x < r.region[2] && y >= r.region[1] && y < r.region[3];
                    if (inside && memcmp(&part[i], &whole[i], sizeof(float)) != 0) wrong++;
                    if (!inside && part[i] != -7.0f) touched++;
                }
        CHECKF(wrong == 0 && touched == 0,
               "%s pbr trial %d (integrator %d): region (%d,%d)-(%d,%d), tile %d: %d pixels differ, %d outside written",
               name, t, (int)d.integrator, r.region[0], r.region[1], r.region[2], r.region[3], r.tile_size, wrong,
               touched);
    }
    /* Regions that are not inside the image. */
    static const int bad[][4] = {{0, 0, W + 1, H}, {-1, 0, 5, 5}, {5, 5, 5, 9}, {6, 5, 5, 9}, {0, 0, 0, 1}};
    for (size_t b = 0; b < sizeof bad / sizeof bad[0]; b++) {
        rp_render_desc r = {.width = W, .height = H, .region = {bad[b][0], bad[b][1], bad[b][2], bad[b][3]}};
        CHECKF(!rp_render(rs, &r, part, NULL), "%s: region %d accepted", name, (int)b);
    }
    free(whole);
    free(part);
    rp_render_scene_release(rs);
    rp_device_release(dev);
}

int main(void) {
    int trials = rp_test_sanitized() ? 6 : 20;
    char buf[512], err[512];
    rp_scene_data room;
    CHECK(rp_default_scene(&room));
    check_scene("room", &room, trials);
    rp_default_scene_free(&room);
    static const char *const scenes[] = {"cornell_box/cornell_box.obj", "bart_kitchen.tar.gz"};
    for (size_t s = 0; s < sizeof scenes / sizeof scenes[0]; s++) {
        const char *path = rp_test_scene(scenes[s], buf, sizeof buf);
        CHECK(path != NULL);
        if (!path) continue;
        rp_scene_data data;
        CHECKF(rp_scene_data_load(path, &data, err, sizeof err), "%s", err);
        check_scene(scenes[s], &data, trials);
        rp_scene_data_free(&data);
    }
    return RP_TEST_END();
}
