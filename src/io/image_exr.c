/* OpenEXR output through the OpenEXR 3 C API (openexr.h, Debian libopenexr-dev): RGB (or Y) float
 * channels, ZIP compressed scanlines, linear radiance as is. Without the library (RP_IO_HAVE_EXR
 * unset) writing an .exr fails with a message saying so. */
#include "io_internal.h"
#include "raypack_io.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef RP_IO_HAVE_EXR
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#include <openexr.h>
#pragma GCC diagnostic pop

bool io_image_write_exr(const char *path, int width, int height, int channels, const float *pixels, char *err,
                        size_t err_size) {
    /* OpenEXR writes the atomic output's temporary file by name; commit renames it into place, so a
     * failed write keeps the old file (rp_atomic_open) */
    rp_atomic_file *af = rp_atomic_open(path, err, err_size);
    if (!af) return false;
    exr_context_t ctx = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_result_t r = exr_start_write(&ctx, rp_atomic_temp_path(af), EXR_WRITE_FILE_DIRECTLY, &init);
    int part = 0;
    /* channels are stored in name order: B, G, R */
    static const char *const names[3] = {"B", "G", "R"};
    const int source[3] = {2, 1, 0};
    int nch = channels == 3 ? 3 : 1;
    if (r == EXR_ERR_SUCCESS) r = exr_add_part(ctx, "rgb", EXR_STORAGE_SCANLINE, &part);
    if (r == EXR_ERR_SUCCESS) r = exr_initialize_required_attr_simple(ctx, part, width, height, EXR_COMPRESSION_ZIP);
    for (int c = 0; r == EXR_ERR_SUCCESS && c < nch; c++)
        r = exr_add_channel(ctx, part, nch == 3 ? names[c] : "Y", EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LINEAR, 1, 1);
    if (r == EXR_ERR_SUCCESS) r = exr_write_header(ctx);
    int32_t lines = 1;
    if (r == EXR_ERR_SUCCESS) r = exr_get_scanlines_per_chunk(ctx, part, &lines);
    for (int y = 0; r == EXR_ERR_SUCCESS && y < height; y += lines) {
        exr_chunk_info_t cinfo;
        exr_encode_pipeline_t enc;
        memset(&enc, 0, sizeof enc);
        r = exr_write_scanline_chunk_info(ctx, part, y, &cinfo);
        if (r == EXR_ERR_SUCCESS) r = exr_encoding_initialize(ctx, part, &cinfo, &enc);
        if (r != EXR_ERR_SUCCESS) break;
        for (int c = 0; c < enc.channel_count; c++) {
            int k = nch == 3 ? source[c] : 0;
            enc.channels[c].encode_from_ptr = (const uint8_t *)(pixels + (size_t)y * (size_t)width * (size_t)channels + k);
            enc.channels[c].user_pixel_stride = channels * (int32_t)sizeof(float);
            enc.channels[c].user_line_stride = width * channels * (int32_t)sizeof(float);
            enc.channels[c].user_bytes_per_element = 4;
            enc.channels[c].user_data_type = EXR_PIXEL_FLOAT;
        }
        r = exr_encoding_choose_default_routines(ctx, part, &enc);
        if (r == EXR_ERR_SUCCESS) r = exr_encoding_run(ctx, part, &enc);
        exr_encoding_destroy(ctx, &enc);
    }
    exr_result_t fr = exr_finish(&ctx);
    if (r == EXR_ERR_SUCCESS) r = fr;
    if (r != EXR_ERR_SUCCESS) {
        rp_atomic_abort(af);
        if (err && err_size) snprintf(err, err_size, "%s: error: OpenEXR: %s", path, exr_get_default_error_message(r));
        return false;
    }
    return rp_atomic_commit(af, err, err_size);
}
#else
bool io_image_write_exr(const char *path, int width, int height, int channels, const float *pixels, char *err,
                        size_t err_size) {
    (void)width;
    (void)height;
    (void)channels;
    (void)pixels;
    if (err && err_size)
        snprintf(err, err_size, "%s: error: raypack was built without OpenEXR (apt install libopenexr-dev)", path);
    return false;
}
#endif
