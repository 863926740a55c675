/* Radiance HDR (RGBE) images: read through stb_image (environment maps), written by hand (flat
 * scanlines, which every reader accepts). */
#include "io_internal.h"
#include "raypack_io.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#pragma GCC diagnostic ignored "-Wswitch-enum"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#pragma GCC diagnostic ignored "-Wdouble-promotion"
#pragma GCC diagnostic ignored "-Wunused-function"
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#define STBI_ONLY_HDR
/* stb's allocations are the loaders' (io_alloc.c), so a test can refuse them too */
#define STBI_MALLOC(size) io_malloc(size)
#define STBI_REALLOC(p, size) io_realloc(p, size)
#define STBI_FREE(p) free(p)
#include <stb/stb_image.h>
#pragma GCC diagnostic pop
/* stb declares static functions this file does not use; GCC reports them at the end of the file. */
#pragma GCC diagnostic ignored "-Wunused-function"

float *rp_image_read_hdr(const char *path, int *width, int *height, char *err, size_t err_size) {
    if (!path) path = "(null)";
    int w = 0, h = 0, comp = 0;
    errno = 0; /* an errno left by an earlier call is not this one's reason */
    unsigned long failures = io_alloc_failures();
    float *px = stbi_loadf(path, &w, &h, &comp, 3);
    if (!px) {
        const char *why = io_alloc_failures() != failures ? "out of memory" : stbi_failure_reason();
        if (err && err_size) snprintf(err, err_size, "%s: error: cannot read a Radiance HDR image: %s", path,
                                      errno ? strerror(errno) : why);
        return NULL;
    }
    /* stb's buffer comes from its own malloc; hand the caller one that free() releases. */
    size_t n = (size_t)w * (size_t)h * 3;
    float *out = io_malloc(n * sizeof(float));
    if (out) memcpy(out, px, n * sizeof(float));
    stbi_image_free(px);
    if (!out) {
        if (err && err_size) snprintf(err, err_size, "%s: error: out of memory", path);
        return NULL;
    }
    *width = w;
    *height = h;
    return out;
}

static void rgbe(const float *c, uint8_t out[4]) {
    float m = fmaxf(c[0], fmaxf(c[1], c[2]));
    if (!(m > 1e-32f)) {
        memset(out, 0, 4);
        return;
    }
    int e;
    float f = frexpf(m, &e) * 256.0f / m;
    for (int k = 0; k < 3; k++) out[k] = (uint8_t)fminf(255.0f, fmaxf(0.0f, c[k] * f));
    out[3] = (uint8_t)(e + 128);
}

bool io_image_write_hdr(const char *path, int width, int height, int channels, const float *pixels, char *err,
                        size_t err_size) {
    size_t n = (size_t)width * (size_t)height;
    uint8_t *buf = malloc(n * 4);
    if (!buf) {
        if (err && err_size) snprintf(err, err_size, "%s: error: out of memory", path);
        return false;
    }
    for (size_t i = 0; i < n; i++) {
        float c[3];
        for (int k = 0; k < 3; k++) c[k] = pixels[i * (size_t)channels + (size_t)(channels == 1 ? 0 : k)];
        for (int k = 0; k < 3; k++) if (!isfinite(c[k])) c[k] = 0.0f;
        rgbe(c, buf + 4 * i);
    }
    /* through an atomic output: a failed write keeps the old file (rp_atomic_open) */
    rp_atomic_file *af = rp_atomic_open(path, err, err_size);
    bool ok = af != NULL;
    if (ok) {
        FILE *f = rp_atomic_stream(af);
        bool wrote = fprintf(f, "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n", height, width) > 0;
        wrote = wrote && fwrite(buf, 4, n, f) == n;
        if (!wrote) rp_atomic_fail(af, errno);
        ok = rp_atomic_commit(af, err, err_size);
    }
    free(buf);
    return ok;
}
