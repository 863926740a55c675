/* rp_render_desc.tile_done (the viewer converts tiles with it while they are in cache): for every
 * integrator kind, on an image that is not a whole number of tiles, with and without a region, the
 * callback covers each rendered pixel exactly once, from a device thread index, and the pixels it
 * sees are already the final ones (instant radiosity's after its filter); the image equals a
 * render without the callback. rp_render_desc.accumulate: frames of samples [0, 1), [1, 3), [3, 7)
 * added into one sum, divided by 7 as rp_render divides, equal one 7-sample render bit for bit, for
 * every integrator but instant radiosity, which refuses it. */
#include <stdatomic.h>
#include <stdbool.h>

#include "raypack.h"
#include "raypack_render.h"
#include "rp_test.h"

enum { W = 70, H = 45 };

typedef struct seen {
    const float *pixels;
    float copy[W * H * 3];
    atomic_int covered[W * H];
    atomic_int bad_thread, bad_rect;
    int threads;
} seen;

static void on_tile(void *user, int x0, int y0, int x1, int y1, uint32_t thread) {
    seen *s = user;
    if ((int)thread >= s->threads) atomic_fetch_add(&s->bad_thread, 1);
    if (!(0 <= x0 && x0 < x1 && x1 <= W && 0 <= y0 && y0 < y1 && y1 <= H)) {
        atomic_fetch_add(&s->bad_rect, 1);
        return;
    }
    for (int y = y0; y < y1; y++)
        for (int x = x0; x < x1; x++) {
            atomic_fetch_add(&s->covered[y * W + x], 1);
            memcpy(&s->copy[3 * (y * W + x)], &s->pixels[3 * (y * W + x)], 3 * sizeof(float));
        }
}

int main(void) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    rp_scene_data data;
    CHECK(dev && rp_default_scene(&data));
    char err[512];
    rp_render_scene *scene = dev ? rp_render_scene_new(dev, &data, NULL, err, sizeof err) : NULL;
    CHECKF(scene != NULL, "%s", err);
    if (!scene) return RP_TEST_END();
    static const rp_integrator_type kinds[] = {RP_INTEGRATOR_WHITTED, RP_INTEGRATOR_EYELIGHT, RP_INTEGRATOR_AOV,
                                               RP_INTEGRATOR_PATH, RP_INTEGRATOR_IR};
    static seen s;
    static float plain[W * H * 3], with[W * H * 3];
    for (size_t k = 0; k < sizeof kinds / sizeof kinds[0]; k++)
        for (int use_region = 0; use_region < 2; use_region++) {
            if (use_region && kinds[k] == RP_INTEGRATOR_IR) continue; /* regions refuse it */
            rp_render_desc d = {.width = W, .height = H, .spp = 2, .integrator = kinds[k], .aov = RP_AOV_NORMAL,
                                .sample_start = 3, .ir = {.interleave = 3, .vpls = 16, .filter = 3}};
            if (use_region) {
                d.region[0] = 5, d.region[1] = 7, d.region[2] = 61, d.region[3] = 40;
            }
            memset(plain, 0, sizeof plain);
            memset(with, 0, sizeof with);
            CHECK(rp_render(scene, &d, plain, NULL));
            memset(&s, 0, sizeof s);
            s.pixels = with;
            s.threads = rp_device_thread_count(dev);
            d.tile_done = on_tile;
            d.tile_user = &s;
            CHECK(rp_render(scene, &d, with, NULL));
            int once = 0, wrong = 0;
            for (int y = 0; y < H; y++)
                for (int x = 0; x < W; x++) {
                    bool inside = !use_region || (x >= 5 && x < 61 && y >= 7 && y < 40);
                    int c = atomic_load(&s.covered[y * W + x]);
                    once += c == (inside ? 1 : 0);
                    if (inside && memcmp(&s.copy[3 * (y * W + x)], &with[3 * (y * W + x)], 3 * sizeof(float)) != 0)
                        wrong++;
                }
            CHECKF(once == W * H, "integrator %d region %d: %d of %d pixels covered as they should", (int)kinds[k],
                   use_region, once, W * H);
            CHECKF(wrong == 0, "integrator %d region %d: %d pixels changed after their tile was reported", (int)kinds[k],
                   use_region, wrong);
            CHECK(atomic_load(&s.bad_thread) == 0 && atomic_load(&s.bad_rect) == 0);
            CHECKF(memcmp(plain, with, sizeof plain) == 0, "integrator %d: the callback changed the image", (int)kinds[k]);
        }
    /* progressive sums */
    static const rp_integrator_type sums[] = {RP_INTEGRATOR_WHITTED, RP_INTEGRATOR_EYELIGHT, RP_INTEGRATOR_DIRECT,
                                              RP_INTEGRATOR_PATH, RP_INTEGRATOR_AO};
    static float sum[W * H * 3];
    for (size_t k = 0; k < sizeof sums / sizeof sums[0]; k++) {
        rp_render_desc d = {.width = W, .height = H, .spp = 7, .integrator = sums[k], .max_depth = 3};
        CHECK(rp_render(scene, &d, plain, NULL));
        static const int from[4] = {0, 1, 3, 7};
        bool ok = true;
        for (int f = 0; f < 3; f++) {
            d.sample_start = from[f];
            d.spp = from[f + 1] - from[f];
            d.accumulate = f > 0;
            ok = ok && rp_render(scene, &d, sum, NULL);
        }
        CHECK(ok);
        int wrong = 0;
        for (int i = 0; i < W * H * 3; i++) {
            float mean = sum[i] * (1.0f / 7.0f);
            wrong += memcmp(&mean, &plain[i], sizeof mean) != 0;
        }
        CHECKF(wrong == 0, "integrator %d: %d channels of the accumulated frames differ from one 7-sample render",
               (int)sums[k], wrong);
    }
    rp_render_desc ir = {.width = W, .height = H, .integrator = RP_INTEGRATOR_IR, .accumulate = true};
    CHECK(!rp_render(scene, &ir, sum, NULL));
    rp_render_scene_release(scene);
    rp_default_scene_free(&data);
    rp_device_release(dev);
    return RP_TEST_END();
}
