/* Float image writers of the renderer's outputs: Radiance .hdr read back by rp_image_read_hdr
 * (stb_image) within RGBE's precision, OpenEXR read back by OpenEXR's own decoder exactly, PFM
 * exactly, the channel order and the row order (top row first) included. */
#include "raypack_io.h"
#include "rp_test.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef RP_TEST_HAVE_EXR
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#include <openexr.h>
#pragma GCC diagnostic pop

/* Reads channel `name` of an EXR into out (w * h floats, top row first); false on failure. */
static bool exr_channel(const char *path, const char *name, int w, int h, float *out) {
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    if (exr_start_read(&ctx, path, &init) != EXR_ERR_SUCCESS) return false;
    int32_t lines = 1;
    exr_get_scanlines_per_chunk(ctx, 0, &lines);
    bool ok = true;
    for (int y = 0; ok && y < h; y += lines) {
        exr_chunk_info_t ci;
        exr_decode_pipeline_t dec;
        memset(&dec, 0, sizeof dec);
        ok = exr_read_scanline_chunk_info(ctx, 0, y, &ci) == EXR_ERR_SUCCESS &&
             exr_decoding_initialize(ctx, 0, &ci, &dec) == EXR_ERR_SUCCESS;
        if (!ok) break;
        bool found = false;
        for (int c = 0; c < dec.channel_count; c++) {
            if (strcmp(dec.channels[c].channel_name, name) == 0) {
                dec.channels[c].decode_to_ptr = (uint8_t *)(out + (size_t)y * (size_t)w);
                dec.channels[c].user_pixel_stride = 4;
                dec.channels[c].user_line_stride = 4 * w;
                dec.channels[c].user_bytes_per_element = 4;
                dec.channels[c].user_data_type = EXR_PIXEL_FLOAT;
                found = true;
            } else {
                dec.channels[c].decode_to_ptr = NULL;
            }
        }
        ok = found && exr_decoding_choose_default_routines(ctx, 0, &dec) == EXR_ERR_SUCCESS &&
             exr_decoding_run(ctx, 0, &dec) == EXR_ERR_SUCCESS;
        exr_decoding_destroy(ctx, &dec);
    }
    exr_finish(&ctx);
    return ok;
}
#endif

int main(void) {
    const char *dir = getenv("RP_TEST_TMP");
    if (!dir) dir = ".";
    char cmd[600];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
    CHECK(system(cmd) == 0);
    enum { W = 37, H = 21 };
    float *px = malloc(W * H * 3 * sizeof(float));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++)
                px[(y * W + x) * 3 + c] = (float)(0.01 + x * 0.37 + y * 1.9 + c * 5.0) * (c == 1 ? 0.001f : 1.0f);
    char path[600], err[600];
    /* HDR */
    snprintf(path, sizeof path, "%s/t.hdr", dir);
    CHECKF(rp_image_write(path, W, H, 3, px, err, sizeof err), "%s", err);
    int w = 0, h = 0;
    float *back = rp_image_read_hdr(path, &w, &h, err, sizeof err);
    CHECKF(back && w == W && h == H, "%s", back ? "size" : err);
    double worst = 0.0;
    for (int i = 0; back && i < W * H * 3; i++) {
        int p = i / 3;
        float m = fmaxf(px[p * 3], fmaxf(px[p * 3 + 1], px[p * 3 + 2]));
        worst = fmax(worst, fabs(back[i] - px[i]) / m); /* RGBE's mantissas are relative to the largest channel */
    }
    CHECKF(worst < 1.0 / 128, "HDR round trip: error %.4g of the pixel's largest channel", worst);
    free(back);
    /* PFM */
    snprintf(path, sizeof path, "%s/t.pfm", dir);
    CHECKF(rp_image_write(path, W, H, 3, px, err, sizeof err), "%s", err);
    int ch = 0;
    back = rp_image_read_pfm(path, &w, &h, &ch, err, sizeof err);
    CHECKF(back && w == W && h == H && ch == 3 && memcmp(back, px, W * H * 3 * sizeof(float)) == 0, "PFM round trip");
    free(back);
    /* EXR */
    snprintf(path, sizeof path, "%s/t.exr", dir);
    bool wrote = rp_image_write(path, W, H, 3, px, err, sizeof err);
#ifdef RP_TEST_HAVE_EXR
    CHECKF(wrote, "%s", err);
    static const char *const names[3] = {"R", "G", "B"};
    float *chan = malloc(W * H * sizeof(float));
    for (int c = 0; wrote && c < 3; c++) {
        CHECKF(exr_channel(path, names[c], W, H, chan), "cannot decode channel %s", names[c]);
        int bad = 0;
        for (int i = 0; i < W * H; i++) bad += chan[i] != px[i * 3 + c];
        CHECKF(bad == 0, "EXR channel %s: %d pixels differ", names[c], bad);
    }
    free(chan);
#else
    CHECKF(!wrote && strstr(err, "without OpenEXR"), "an EXR without OpenEXR: %s", err);
#endif
    free(px);
    return RP_TEST_END();
}
