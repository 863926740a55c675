/* Texture images for materials: PPM (P3 and P6) decoded here, every other format by stb_image. All
 * end up 8-bit RGB, top row first. */
#include <stdio.h>

#include "io/io_internal.h"

/* stb_image is third-party code: compiled here once, static, without the project's warnings (the
 * unused-function one stays off to the end of the file, where GCC reports it). */
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#pragma GCC diagnostic ignored "-Wswitch-enum"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#pragma GCC diagnostic ignored "-Wdouble-promotion"
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#define STBI_NO_STDIO
#define STBI_NO_HDR
#define STBI_NO_LINEAR
#include <stb/stb_image.h>
#pragma GCC diagnostic pop

/* Reads one header field of a PPM (skipping whitespace and # comments). */
static const char *ppm_field(const char *p, const char *end, int64_t *v) {
    for (;;) {
        while (p < end && (io_is_space(*p) || *p == '\n')) p++;
        if (p < end && *p == '#') {
            while (p < end && *p != '\n') p++;
            continue;
        }
        break;
    }
    if (p >= end) return NULL;
    return io_parse_int(p, v);
}

/* Decodes a P3/P6 PPM into rgb; returns NULL with a message in why. */
static uint8_t *ppm_decode(const char *data, size_t size, int32_t *w, int32_t *h, const char **why) {
    const char *p = data + 2, *end = data + size;
    int64_t width, height, maxval;
    bool ascii = data[1] == '3';
    if (!(p = ppm_field(p, end, &width)) || !(p = ppm_field(p, end, &height)) ||
        !(p = ppm_field(p, end, &maxval))) {
        *why = "bad PPM header";
        return NULL;
    }
    if (width <= 0 || height <= 0 || width > 65536 || height > 65536 || maxval <= 0 || maxval > 65535) {
        *why = "PPM size or maximum value out of range";
        return NULL;
    }
    size_t n = (size_t)width * (size_t)height * 3;
    /* Check the data can be there before allocating for it: P6 stores n samples, P3 at least 2n bytes. */
    size_t left = p < end ? (size_t)(end - p) : 0;
    if ((ascii && left / 2 < n) || (!ascii && left < n * (maxval > 255 ? 2 : 1) + 1)) {
        *why = ascii ? "truncated or bad P3 pixel data" : "truncated P6 pixel data";
        return NULL;
    }
    uint8_t *rgb = malloc(n);
    if (!rgb) {
        *why = "out of memory";
        return NULL;
    }
    if (ascii) {
        for (size_t i = 0; i < n; i++) {
            int64_t v;
            if (!(p = ppm_field(p, end, &v)) || v < 0 || v > maxval) {
                free(rgb);
                *why = "truncated or bad P3 pixel data";
                return NULL;
            }
            rgb[i] = (uint8_t)((v * 255 + maxval / 2) / maxval);
        }
    } else {
        p++; /* the single whitespace byte after maxval */
        size_t bpc = maxval > 255 ? 2 : 1;
        if (p > end || (size_t)(end - p) < n * bpc) {
            free(rgb);
            *why = "truncated P6 pixel data";
            return NULL;
        }
        const uint8_t *s = (const uint8_t *)p;
        for (size_t i = 0; i < n; i++) {
            int64_t v = bpc == 2 ? (int64_t)s[2 * i] << 8 | s[2 * i + 1] : s[i];
            if (v > maxval) v = maxval;
            if (maxval != 255) v = (v * 255 + maxval / 2) / maxval;
            rgb[i] = (uint8_t)v;
        }
    }
    *w = (int32_t)width;
    *h = (int32_t)height;
    return rgb;
}

uint32_t tex_load(io_ctx *ctx, const char *path, const char *as_written, const char *file,
                  uint32_t line) {
    io_builder *b = &ctx->b;
    for (size_t i = 0; i < b->texture_n; i++)
        if (strcmp(b->texture_keys[i], path) == 0) return (uint32_t)i;

    io_buf buf;
    if (!vfs_read(ctx, path, &buf)) {
        char shown[IO_PATH_MAX + 256];
        vfs_display(&ctx->vfs, path, shown, sizeof shown);
        io_error(ctx, file, line, "cannot open texture '%s' (%s): %s", as_written, shown, ctx->why);
        return IO_NONE;
    }
    int32_t w = 0, h = 0;
    uint8_t *rgb = NULL;
    const char *why = "unsupported or corrupt image";
    if (buf.size >= 3 && buf.data[0] == 'P' && (buf.data[1] == '3' || buf.data[1] == '6')) {
        rgb = ppm_decode(buf.data, buf.size, &w, &h, &why);
    } else if (buf.size <= INT32_MAX) {
        int iw, ih, comp;
        stbi_uc *px = stbi_load_from_memory((const stbi_uc *)buf.data, (int)buf.size, &iw, &ih, &comp, 3);
        if (px) {
            size_t n = (size_t)iw * (size_t)ih * 3;
            rgb = malloc(n);
            if (rgb) memcpy(rgb, px, n); /* stb's buffer goes back to stb's allocator */
            stbi_image_free(px);
            w = iw;
            h = ih;
        } else {
            why = stbi_failure_reason();
        }
    }
    vfs_buf_free(&buf);
    if (!rgb) {
        io_error(ctx, file, line, "cannot decode texture '%s': %s", as_written, why);
        return IO_NONE;
    }
    char *key = strdup(path);
    if (!key || b->texture_n >= INT32_MAX ||
        !io_reserve((void **)&b->textures, &b->texture_cap, b->texture_n + 1, sizeof(rp_texture_data))) {
        free(key);
        free(rgb);
        io_error(ctx, file, line, "out of memory");
        return IO_NONE;
    }
    /* texture_keys grows with textures: same capacity. */
    char **keys = realloc(b->texture_keys, b->texture_cap * sizeof(char *));
    if (!keys) {
        free(key);
        free(rgb);
        io_error(ctx, file, line, "out of memory");
        return IO_NONE;
    }
    b->texture_keys = keys;
    rp_texture_data *t = &b->textures[b->texture_n];
    memset(t, 0, sizeof *t);
    snprintf(t->path, sizeof t->path, "%s", as_written);
    t->width = w;
    t->height = h;
    t->rgb = rgb;
    b->texture_keys[b->texture_n] = key;
    return (uint32_t)b->texture_n++;
}
