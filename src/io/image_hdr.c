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

/* RP_MAX_TEXTURE_PIXELS, as the loaders read it (io_scene.c's env_limit, kept small here). */
static uint64_t max_pixels(void) {
    const char *v = getenv("RP_MAX_TEXTURE_PIXELS");
    if (!v || !*v) return IO_DEFAULT_MAX_TEXTURE_PIXELS;
    char *end;
    unsigned long long n = strtoull(v, &end, 10);
    uint64_t scale = *end == 'k' || *end == 'K' ? 1ull << 10 : *end == 'M' ? 1ull << 20 : *end == 'G' ? 1ull << 30 : 1;
    if (scale != 1) end++;
    if (end == v || *end != '\0' || n == 0 || n > UINT64_MAX / scale) return IO_DEFAULT_MAX_TEXTURE_PIXELS;
    return (uint64_t)n * scale;
}

/* The file whole (a stream too), at most limit bytes; NULL with *why (errno's text, "out of
 * memory" or "more than N bytes"). */
static unsigned char *read_all(const char *path, size_t limit, size_t *size, char *why, size_t why_size) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(why, why_size, "%s", strerror(errno));
        return NULL;
    }
    size_t cap = 1 << 16, n = 0;
    unsigned char *d = io_malloc(cap);
    while (d) {
        if (n == cap) {
            if (cap > limit) {
                snprintf(why, why_size, "more than %zu bytes for at most %llu pixels; RP_MAX_TEXTURE_PIXELS raises the limit",
                         limit, (unsigned long long)max_pixels());
                free(d);
                fclose(f);
                return NULL;
            }
            unsigned char *g = io_realloc(d, cap * 2);
            if (!g) {
                free(d);
                d = NULL;
                break;
            }
            d = g, cap *= 2;
        }
        size_t got = fread(d + n, 1, cap - n, f);
        n += got;
        if (got == 0) break;
    }
    if (!d) snprintf(why, why_size, "out of memory");
    else if (ferror(f)) {
        snprintf(why, why_size, "%s", strerror(errno ? errno : EIO));
        free(d);
        d = NULL;
    }
    fclose(f);
    *size = n;
    return d;
}

/* stb_image 2.27 (Debian's) decodes an RLE scanline with a loop that never ends on a count of 0,
 * which is also what it reads past the end of the file: an 88-byte file hung the reader (found by
 * the texture fuzzer). And a file cut short anywhere else is no error to stb: it fills the pixels
 * the file lacks with zeros (RLE) or leaves them unwritten (flat), so a 91-byte header claiming
 * 8000 x 8000 pixels rendered as a black environment. False when the RLE scanlines hold a count
 * of 0 or the pixels, flat or RLE, stop before the last one; true for everything else, which stb
 * decodes in bounds or refuses itself (a bad header, a scanline of another width). Follows
 * stbi__hdr_load's parsing step by step. */
static bool hdr_complete(const unsigned char *d, size_t n) {
    size_t pos = 0;
    char line[1024];
    int lines = 0;
    for (;;) { /* the magic line, header lines up to an empty one, then the resolution line */
        size_t len = 0;
        while (pos < n && d[pos] != '\n') {
            if (len + 1 < sizeof line) line[len++] = (char)d[pos];
            pos++;
        }
        if (pos >= n) return true; /* stb finds no pixels and says so */
        pos++;
        line[len] = '\0';
        if (lines == 0 && strcmp(line, "#?RADIANCE") != 0 && strcmp(line, "#?RGBE") != 0) return true;
        if (lines > 0 && line[0] == '\0') break; /* stb's test: a line starting with NUL ends it too */
        lines++;
    }
    size_t len = 0;
    while (pos < n && d[pos] != '\n') {
        if (len + 1 < sizeof line) line[len++] = (char)d[pos];
        pos++;
    }
    pos++;
    line[len] = '\0';
    if (strncmp(line, "-Y ", 3) != 0) return true;
    char *t = line + 3;
    long height = strtol(t, &t, 10);
    while (*t == ' ') t++;
    if (strncmp(t, "+X ", 3) != 0) return true;
    long width = strtol(t + 3, NULL, 10);
    if (width <= 0 || height <= 0 || width > INT32_MAX || height > INT32_MAX) return true; /* stb refuses it */
    /* flat pixels, 4 bytes each, to the end of the image (stb restarts at the first pixel when a
     * scanline of an RLE file turns out flat) */
    uint64_t flat = (uint64_t)width * (uint64_t)height * 4;
    if (width < 8 || width >= 32768) return pos <= n && n - pos >= flat;
    for (long y = 0; y < height; y++) {
        if (pos + 4 > n) return false;
        if (d[pos] != 2 || d[pos + 1] != 2 || (d[pos + 2] & 0x80)) return n - pos >= flat;
        if (((long)d[pos + 2] << 8 | d[pos + 3]) != width) return true;
        pos += 4;
        for (int k = 0; k < 4; k++)
            for (long x = 0; x < width;) {
                if (pos >= n) return false; /* stb reads a count of 0 here, forever */
                long count = d[pos++];
                if (count > 128) {
                    count -= 128;
                    pos++; /* the run's value */
                } else if (count == 0) {
                    return false;
                } else {
                    pos += (size_t)count;
                }
                if (count > width - x) return true;
                if (pos > n) return false; /* the run's value or the dump cut short */
                x += count;
            }
    }
    return true;
}

float *rp_image_read_hdr(const char *path, int *width, int *height, char *err, size_t err_size) {
    if (!path) path = "(null)";
    int w = 0, h = 0, comp = 0;
    char why[256];
    size_t size = 0;
    /* a flat scanline takes 4 bytes a pixel and RLE less, so no valid file within the pixel limit
     * is larger than this (and a FIFO is read once) */
    unsigned char *data = read_all(path, (size_t)(4 * max_pixels() + (1u << 20)), &size, why, sizeof why);
    if (!data) {
        if (err && err_size) snprintf(err, err_size, "%s: error: cannot read a Radiance HDR image: %s", path, why);
        return NULL;
    }
    /* the declared size first: stb allocates it whole before reading a pixel (a 40-byte header may
     * claim 30000 x 30000 pixels, 10 GB); then that the file holds them all */
    if (size <= INT32_MAX && stbi_info_from_memory(data, (int)size, &w, &h, &comp) &&
        (w <= 0 || h <= 0 || (uint64_t)w * (uint64_t)h > max_pixels())) {
        free(data);
        if (err && err_size) {
            if (w <= 0 || h <= 0) snprintf(err, err_size, "%s: error: corrupt Radiance HDR image (%dx%d pixels)", path, w, h);
            else
                snprintf(err, err_size, "%s: error: %dx%d is more than %llu pixels; RP_MAX_TEXTURE_PIXELS raises the limit",
                         path, w, h, (unsigned long long)max_pixels());
        }
        return NULL;
    }
    if (!hdr_complete(data, size) || size > INT32_MAX) {
        free(data);
        if (err && err_size)
            snprintf(err, err_size, "%s: error: corrupt Radiance HDR image (an RLE scanline with a run of length 0, or cut short)",
                     path);
        return NULL;
    }
    unsigned long failures = io_alloc_failures();
    float *px = stbi_loadf_from_memory(data, (int)size, &w, &h, &comp, 3);
    free(data);
    if (!px) {
        const char *reason = io_alloc_failures() != failures ? "out of memory" : stbi_failure_reason();
        if (err && err_size) snprintf(err, err_size, "%s: error: cannot read a Radiance HDR image: %s", path, reason);
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
