/* Image files: PNG (stb_image_write), PPM and PFM written by hand, PFM read back. */
#include "io_internal.h"
#include "raypack_io.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wswitch-enum"
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STBI_WRITE_NO_STDIO
#include <stb/stb_image_write.h>
#pragma GCC diagnostic pop
/* stb declares static functions this file does not use; GCC reports them at the end of the file. */
#pragma GCC diagnostic ignored "-Wunused-function"

typedef enum image_format { IMAGE_PNG, IMAGE_PPM, IMAGE_PFM, IMAGE_HDR, IMAGE_EXR, IMAGE_UNKNOWN } image_format;

static void set_err(char *err, size_t err_size, const char *path, const char *fmt, ...) {
    if (!err || err_size == 0) return;
    int n = snprintf(err, err_size, "%s: error: ", path);
    if (n < 0 || (size_t)n >= err_size) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err + n, err_size - (size_t)n, fmt, ap);
    va_end(ap);
}

static image_format format_of(const char *path) {
    const char *dot = strrchr(path, '.');
    if (!dot) return IMAGE_UNKNOWN;
    if (strcasecmp(dot, ".png") == 0) return IMAGE_PNG;
    if (strcasecmp(dot, ".ppm") == 0) return IMAGE_PPM;
    if (strcasecmp(dot, ".pfm") == 0) return IMAGE_PFM;
    if (strcasecmp(dot, ".hdr") == 0) return IMAGE_HDR;
    if (strcasecmp(dot, ".exr") == 0) return IMAGE_EXR;
    return IMAGE_UNKNOWN;
}

static uint8_t encode_srgb8(float v) {
    if (!(v > 0.0f)) return 0; /* negative and NaN */
    if (v >= 1.0f) return 255;
    float s = v <= 0.0031308f ? 12.92f * v : 1.055f * powf(v, 1.0f / 2.4f) - 0.055f;
    return (uint8_t)(s * 255.0f + 0.5f);
}

static bool little_endian(void) {
    const uint16_t one = 1;
    uint8_t b;
    memcpy(&b, &one, 1);
    return b == 1;
}

static void swap4(void *p) {
    uint8_t *b = p, t = b[0];
    b[0] = b[3];
    b[3] = t;
    t = b[1];
    b[1] = b[2];
    b[2] = t;
}

typedef struct mem_buffer {
    uint8_t *data;
    size_t size, cap;
    bool failed;
} mem_buffer;

static void mem_write(void *ctx, void *data, int size) {
    mem_buffer *m = ctx;
    if (m->failed || size <= 0) return;
    if (m->size + (size_t)size > m->cap) {
        size_t cap = m->cap ? m->cap * 2 : 65536;
        while (cap < m->size + (size_t)size) cap *= 2;
        uint8_t *p = realloc(m->data, cap);
        if (!p) {
            m->failed = true;
            return;
        }
        m->data = p;
        m->cap = cap;
    }
    memcpy(m->data + m->size, data, (size_t)size);
    m->size += (size_t)size;
}

/* Header then data, through an atomic output (rp_atomic_open): a failed write keeps the old file. */
static bool write_file(const char *path, const void *header, size_t header_size, const void *data,
                       size_t size, char *err, size_t err_size) {
    rp_atomic_file *af = rp_atomic_open(path, err, err_size);
    if (!af) return false;
    FILE *f = rp_atomic_stream(af);
    errno = 0;
    bool ok = (header_size == 0 || fwrite(header, 1, header_size, f) == header_size) &&
              (size == 0 || fwrite(data, 1, size, f) == size);
    if (!ok) rp_atomic_fail(af, errno);
    return rp_atomic_commit(af, err, err_size);
}

bool rp_image_write(const char *path, int width, int height, int channels, const float *pixels, char *err,
                    size_t err_size) {
    if (!path) path = "(null)";
    if (width <= 0 || height <= 0 || (channels != 1 && channels != 3) || !pixels) {
        set_err(err, err_size, path, "bad image (%dx%d, %d channels)", width, height, channels);
        return false;
    }
    image_format fmt = format_of(path);
    size_t n = (size_t)width * (size_t)height;
    switch (fmt) {
    case IMAGE_PFM: {
        char header[64];
        int hn = snprintf(header, sizeof header, "%s\n%d %d\n-1.0\n", channels == 3 ? "PF" : "Pf", width, height);
        size_t row = (size_t)width * (size_t)channels;
        float *buf = malloc(n * (size_t)channels * sizeof(float));
        if (!buf) {
            set_err(err, err_size, path, "out of memory");
            return false;
        }
        bool swap = !little_endian();
        for (int y = 0; y < height; y++) {
            /* PFM rows go bottom-up. */
            memcpy(buf + (size_t)(height - 1 - y) * row, pixels + (size_t)y * row, row * sizeof(float));
        }
        if (swap)
            for (size_t i = 0; i < n * (size_t)channels; i++) swap4(&buf[i]);
        bool ok = write_file(path, header, (size_t)hn, buf, n * (size_t)channels * sizeof(float), err, err_size);
        free(buf);
        return ok;
    }
    case IMAGE_PPM:
    case IMAGE_PNG: {
        /* 8-bit RGB (grey for one channel), sRGB-encoded. */
        int comp = fmt == IMAGE_PNG ? channels : 3;
        uint8_t *buf = malloc(n * (size_t)comp);
        if (!buf) {
            set_err(err, err_size, path, "out of memory");
            return false;
        }
        for (size_t i = 0; i < n; i++) {
            for (int k = 0; k < comp; k++)
                buf[i * (size_t)comp + (size_t)k] = encode_srgb8(pixels[i * (size_t)channels + (size_t)(channels == 1 ? 0 : k)]);
        }
        bool ok;
        if (fmt == IMAGE_PPM) {
            char header[64];
            int hn = snprintf(header, sizeof header, "P6\n%d %d\n255\n", width, height);
            ok = write_file(path, header, (size_t)hn, buf, n * 3, err, err_size);
        } else {
            mem_buffer m = {0};
            int r = stbi_write_png_to_func(mem_write, &m, width, height, comp, buf, width * comp);
            if (!r || m.failed) {
                set_err(err, err_size, path, "PNG encoding failed (out of memory)");
                ok = false;
            } else {
                ok = write_file(path, NULL, 0, m.data, m.size, err, err_size);
            }
            free(m.data);
        }
        free(buf);
        return ok;
    }
    case IMAGE_HDR:
        return io_image_write_hdr(path, width, height, channels, pixels, err, err_size);
    case IMAGE_EXR:
        return io_image_write_exr(path, width, height, channels, pixels, err, err_size);
    case IMAGE_UNKNOWN:
        break;
    }
    set_err(err, err_size, path, "unknown image format (expected .png, .ppm, .pfm, .hdr or .exr)");
    return false;
}

/* Reads one whitespace-delimited token of the PFM header. */
static bool read_token(FILE *f, char *buf, size_t size) {
    int c;
    do {
        c = fgetc(f);
    } while (c == ' ' || c == '\t' || c == '\n' || c == '\r');
    size_t n = 0;
    while (c != EOF && c != ' ' && c != '\t' && c != '\n' && c != '\r') {
        if (n + 1 >= size) return false;
        buf[n++] = (char)c;
        c = fgetc(f);
    }
    buf[n] = '\0';
    return n > 0; /* the single whitespace after the token has been consumed */
}

float *rp_image_read_pfm(const char *path, int *width, int *height, int *channels, char *err, size_t err_size) {
    if (!path) path = "(null)";
    FILE *f = fopen(path, "rb");
    if (!f) {
        set_err(err, err_size, path, "cannot open: %s", strerror(errno));
        return NULL;
    }
    char magic[8], ws[32], hs[32], ss[64];
    if (!read_token(f, magic, sizeof magic) || (strcmp(magic, "PF") != 0 && strcmp(magic, "Pf") != 0)) {
        set_err(err, err_size, path, "not a PFM file (expected PF or Pf)");
        fclose(f);
        return NULL;
    }
    int ch = magic[1] == 'F' ? 3 : 1;
    char *end;
    if (!read_token(f, ws, sizeof ws) || !read_token(f, hs, sizeof hs) || !read_token(f, ss, sizeof ss)) {
        set_err(err, err_size, path, "truncated PFM header");
        fclose(f);
        return NULL;
    }
    long w = strtol(ws, &end, 10);
    bool bad = *end != '\0';
    long h = strtol(hs, &end, 10);
    bad = bad || *end != '\0';
    double scale = strtod(ss, &end);
    bad = bad || *end != '\0' || scale == 0.0 || !isfinite(scale);
    if (bad || w <= 0 || h <= 0 || w > (1L << 16) || h > (1L << 16)) {
        set_err(err, err_size, path, "bad PFM header (size %s x %s, scale %s)", ws, hs, ss);
        fclose(f);
        return NULL;
    }
    size_t row = (size_t)w * (size_t)ch, n = row * (size_t)h;
    /* the declared size against the bytes there are, before allocating for it (65536^2 pixels is
     * 51 GB, and a 20-byte file may claim it) */
    long here = ftell(f), end_at = -1; /* (a stream that cannot seek is read as it comes) */
    if (here >= 0 && fseek(f, 0, SEEK_END) == 0) {
        end_at = ftell(f);
        if (fseek(f, here, SEEK_SET) != 0) end_at = -1, here = 0;
    }
    if (end_at >= here && here >= 0 && (uint64_t)(end_at - here) < (uint64_t)n * sizeof(float)) {
        set_err(err, err_size, path, "truncated PFM data (%ld x %ld x %d floats declared, %ld bytes there)", w, h, ch,
                end_at > here ? end_at - here : 0L);
        fclose(f);
        return NULL;
    }
    float *pix = io_malloc(n * sizeof(float));
    float *tmp = io_malloc(row * sizeof(float));
    if (!pix || !tmp) {
        free(pix);
        free(tmp);
        set_err(err, err_size, path, "out of memory");
        fclose(f);
        return NULL;
    }
    bool swap = (scale < 0.0) != little_endian();
    for (long y = 0; y < h; y++) {
        if (fread(tmp, sizeof(float), row, f) != row) {
            set_err(err, err_size, path, "truncated PFM data (row %ld of %ld)", y, h);
            free(pix);
            free(tmp);
            fclose(f);
            return NULL;
        }
        if (swap)
            for (size_t i = 0; i < row; i++) swap4(&tmp[i]);
        memcpy(pix + (size_t)(h - 1 - y) * row, tmp, row * sizeof(float));
    }
    free(tmp);
    fclose(f);
    if (width) *width = (int)w;
    if (height) *height = (int)h;
    if (channels) *channels = ch;
    return pix;
}
