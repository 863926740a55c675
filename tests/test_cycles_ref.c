// rp-test: timeout=300
/* raypack's path tracer against an independent production renderer: Blender 3.4's Cycles rendered
 * cornell_original (64x64, 32768 samples per pixel, box filter, no clamping, no denoising, front-side
 * emission; tools/cycles/render_ref.py, docs/rendering.md "Agreement with Cycles") into
 * tests/data/cycles/cornell_original_64.pfm. raypack renders the same camera through the library and
 * must agree: the whole image's mean per channel within 1%, and each 8x8 block's mean per channel
 * within 3.5% + 0.001 (about six times the blocks' measured rms noise at 1024 samples). Negative
 * controls: the same comparison must fail for the light's Ke x 1.05, for the light's emission on
 * its back side (its triangles wound the other way), and for a vertical fov one degree wider. */
#include "../src/render/render.h"
#include "rp_test.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { W = 64, H = 64, BLOCK = 8 };

/* The camera the reference was rendered with: raypack's framed default for cornell_original
 * (`raypack info` prints it), given explicitly to both renderers. */
static const rp_pinhole_camera ref_cam = {
    .eye = {-0.01f, 0.995f, 4.5314f}, .look = {-0.01f, 0.995f, -0.025f}, .up = {0, 1, 0}, .fov_deg = 45.0f};

#define MEAN_TOL 0.01
/* Measured (docs/rendering.md "Agreement with Cycles"): at 1024 samples raypack's whole-image mean
 * is 0.0-0.4% off the reference depending on the sampler, its 8x8 blocks 0.6% rms, 2.1% at worst;
 * at 16384 samples 0.05% and 0.2% rms, as far as two raypack samplers are from each other. */
#define BLOCK_REL 0.035
#define BLOCK_ABS 0.001

typedef struct agreement {
    double mean_rel[3]; /* raypack / Cycles - 1, whole image */
    double worst_block; /* the largest |a - b| / (BLOCK_REL b + BLOCK_ABS) over blocks and channels */
    int worst_x, worst_y, worst_c;
} agreement;

static agreement compare(const float *a, const float *b) {
    agreement g = {{0, 0, 0}, 0.0, 0, 0, 0};
    double sa[3] = {0, 0, 0}, sb[3] = {0, 0, 0};
    for (int i = 0; i < W * H; i++)
        for (int c = 0; c < 3; c++) sa[c] += a[3 * i + c], sb[c] += b[3 * i + c];
    for (int c = 0; c < 3; c++) g.mean_rel[c] = sa[c] / sb[c] - 1.0;
    for (int by = 0; by < H; by += BLOCK)
        for (int bx = 0; bx < W; bx += BLOCK) {
            double ba[3] = {0, 0, 0}, bb[3] = {0, 0, 0};
            for (int y = by; y < by + BLOCK; y++)
                for (int x = bx; x < bx + BLOCK; x++)
                    for (int c = 0; c < 3; c++) {
                        ba[c] += a[3 * (y * W + x) + c] / (BLOCK * BLOCK);
                        bb[c] += b[3 * (y * W + x) + c] / (BLOCK * BLOCK);
                    }
            for (int c = 0; c < 3; c++) {
                double r = fabs(ba[c] - bb[c]) / (BLOCK_REL * bb[c] + BLOCK_ABS);
                if (r > g.worst_block) g.worst_block = r, g.worst_x = bx, g.worst_y = by, g.worst_c = c;
            }
        }
    return g;
}

static bool agrees(const agreement *g) {
    for (int c = 0; c < 3; c++)
        if (!(fabs(g->mean_rel[c]) <= MEAN_TOL)) return false;
    return g->worst_block <= 1.0;
}

static void print_agreement(const char *what, const agreement *g) {
    printf("%-28s mean raypack/Cycles-1 %+.4f %+.4f %+.4f; worst 8x8 block at (%d,%d) %c: %.2f of its tolerance\n",
           what, g->mean_rel[0], g->mean_rel[1], g->mean_rel[2], g->worst_x, g->worst_y, "RGB"[g->worst_c],
           g->worst_block);
}

static float *render_path(rp_device *dev, const rp_scene_data *d, float fov, int spp) {
    char err[512];
    rp_render_scene *s = rp_render_scene_new(dev, d, NULL, err, sizeof err);
    CHECKF(s != NULL, "cornell_original: %s", err);
    if (!s) return NULL;
    rp_camera cam = {.type = RP_CAMERA_PINHOLE, .pinhole = ref_cam};
    cam.pinhole.fov_deg = fov;
    rp_render_desc rd = {.width = W, .height = H, .spp = spp, .integrator = RP_INTEGRATOR_PATH, .camera = &cam,
                         .max_depth = 32};
    float *px = malloc((size_t)W * H * 3 * sizeof(float));
    if (px && !rp_render(s, &rd, px, NULL)) {
        free(px);
        px = NULL;
    }
    CHECK(px != NULL);
    rp_render_scene_release(s);
    return px;
}

int main(void) {
    bool small = rp_test_sanitized() != 0;
    char path[512], ref_path[1024], err[512];
    const char *src = getenv("RP_SOURCE_DIR");
    snprintf(ref_path, sizeof ref_path, "%s/tests/data/cycles/cornell_original_64.pfm", src ? src : "..");
    int rw = 0, rh = 0, rc = 0;
    float *ref = rp_image_read_pfm(ref_path, &rw, &rh, &rc, err, sizeof err);
    CHECKF(ref != NULL, "%s", err);
    CHECKF(!ref || (rw == W && rh == H && rc == 3), "reference is %dx%d x %d, want %dx%d x 3", rw, rh, rc, W, H);
    const char *scene = rp_test_scene("cornell_original/CornellBox-Original.obj", path, sizeof path);
    CHECK(scene != NULL);
    if (!ref || rw != W || rh != H || rc != 3 || !scene) {
        free(ref);
        return RP_TEST_END();
    }
    rp_scene_data d;
    CHECKF(rp_scene_data_load(path, &d, err, sizeof err), "%s", err);
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});

    /* the light is the one material with emission: Ke (17, 12, 4) */
    size_t light = d.material_count;
    for (size_t i = 0; i < d.material_count; i++)
        if (d.materials[i].ke[0] > 0.0f) light = i;
    CHECK(light < d.material_count);

    /* The check itself. Sanitized builds (ten times slower) take fewer samples and only the whole
     * image's mean, at a wider tolerance. */
    int spp = small ? 64 : 1024;
    float *px = render_path(dev, &d, ref_cam.fov_deg, spp);
    if (px) {
        agreement g = compare(px, ref);
        print_agreement("raypack path tracer", &g);
        for (int c = 0; c < 3; c++)
            CHECKF(fabs(g.mean_rel[c]) <= (small ? 3 * MEAN_TOL : MEAN_TOL),
                   "channel %c: the image's mean is %+.2f%% off Cycles'", "RGB"[c], 100 * g.mean_rel[c]);
        if (!small)
            CHECKF(g.worst_block <= 1.0, "8x8 block at (%d,%d) channel %c off Cycles' by %.2f times its tolerance",
                   g.worst_x, g.worst_y, "RGB"[g.worst_c], g.worst_block);
    }
    free(px);

    /* Negative controls: the comparison tells these apart from the reference (fewer samples; each
     * is many tolerances away). */
    if (!small && light < d.material_count) {
        int cspp = 256;
        float ke[3];
        memcpy(ke, d.materials[light].ke, sizeof ke);
        for (int c = 0; c < 3; c++) d.materials[light].ke[c] = ke[c] * 1.05f;
        float *p1 = render_path(dev, &d, ref_cam.fov_deg, cspp);
        memcpy(d.materials[light].ke, ke, sizeof ke);
        if (p1) {
            agreement g = compare(p1, ref);
            print_agreement("control: Ke x 1.05", &g);
            CHECKF(!agrees(&g), "the comparison misses the light's Ke x 1.05");
        }
        free(p1);

        /* emission from the other side: the light's triangles wound the other way (it lights the
         * ceiling above it, and the room only through the 1 cm gap) */
        for (size_t t = 0; t < d.triangle_count; t++)
            if (d.tri_materials[t] == light) {
                uint32_t v = d.indices[3 * t + 1];
                d.indices[3 * t + 1] = d.indices[3 * t + 2], d.indices[3 * t + 2] = v;
            }
        float *p2 = render_path(dev, &d, ref_cam.fov_deg, cspp);
        for (size_t t = 0; t < d.triangle_count; t++)
            if (d.tri_materials[t] == light) {
                uint32_t v = d.indices[3 * t + 1];
                d.indices[3 * t + 1] = d.indices[3 * t + 2], d.indices[3 * t + 2] = v;
            }
        if (p2) {
            agreement g = compare(p2, ref);
            print_agreement("control: light wound back", &g);
            CHECKF(!agrees(&g), "the comparison misses emission from the light's back side");
        }
        free(p2);

        float *p3 = render_path(dev, &d, ref_cam.fov_deg + 1.0f, cspp);
        if (p3) {
            agreement g = compare(p3, ref);
            print_agreement("control: fov 46", &g);
            CHECKF(!agrees(&g), "the comparison misses a vertical fov one degree wider");
        }
        free(p3);
    }

    rp_device_release(dev);
    rp_scene_data_free(&d);
    free(ref);
    return RP_TEST_END();
}
