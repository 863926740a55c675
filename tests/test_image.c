/* Image files: PFM round trips exactly (1 and 3 channels, +inf included), PPM and PNG carry the
 * sRGB-encoded 8-bit values, and bad paths or extensions fail with "path: error: ...". */
#include <math.h>
#include <stdint.h>
#include <sys/stat.h>

#include "io/io_internal.h"
#include "raypack_io.h"
#include "rp_test.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wswitch-enum"
#pragma GCC diagnostic ignored "-Wunused-function"
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#include <stb/stb_image.h>
#pragma GCC diagnostic pop
#pragma GCC diagnostic ignored "-Wunused-function"

static const char *tmp_path(char *buf, size_t size, const char *name) {
    const char *dir = getenv("RP_TEST_TMP");
    if (!dir) dir = ".";
    mkdir(dir, 0777);
    snprintf(buf, size, "%s/%s", dir, name);
    return buf;
}

static void test_pfm_roundtrip(int channels) {
    enum { W = 7, H = 5 };
    float px[W * H * 3];
    for (int i = 0; i < W * H * channels; i++) px[i] = (float)i * 0.37f - 3.0f;
    px[4] = INFINITY;
    px[5] = 1e-30f;
    char path[512], err[512] = "";
    tmp_path(path, sizeof path, channels == 1 ? "img1.pfm" : "img3.pfm");
    CHECKF(rp_image_write(path, W, H, channels, px, err, sizeof err), "%s", err);
    int w = 0, h = 0, c = 0;
    float *back = rp_image_read_pfm(path, &w, &h, &c, err, sizeof err);
    CHECKF(back != NULL, "%s", err);
    if (!back) return;
    CHECK(w == W && h == H && c == channels);
    CHECK(memcmp(back, px, sizeof(float) * (size_t)(W * H * channels)) == 0);
    free(back);

    /* The file itself: header, then the bottom row first, little endian. */
    FILE *f = fopen(path, "rb");
    CHECK(f != NULL);
    if (!f) return;
    char head[32] = "";
    size_t n = fread(head, 1, channels == 1 ? 13 : 13, f);
    CHECK(n == 13);
    CHECK(memcmp(head, channels == 1 ? "Pf\n7 5\n-1.0\n" : "PF\n7 5\n-1.0\n", 12) == 0);
    fseek(f, 12, SEEK_SET);
    uint8_t b[4];
    CHECK(fread(b, 1, 4, f) == 4);
    float first;
    uint32_t bits = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
    memcpy(&first, &bits, 4);
    CHECK(first == px[(H - 1) * W * channels]);
    fclose(f);
}

static void test_8bit(void) {
    enum { W = 4, H = 2 };
    /* linear values and their sRGB 8-bit encodings */
    const float lin[W * H] = {0.0f, 1.0f, 0.5f, 0.2158605f, -1.0f, 7.0f, NAN, 0.0031308f};
    const uint8_t enc[W * H] = {0, 255, 188, 128, 0, 255, 0, 10};
    float px[W * H * 3];
    for (int i = 0; i < W * H; i++)
        for (int k = 0; k < 3; k++) px[3 * i + k] = k == 1 ? lin[i] : 0.0f;
    char path[512], err[512] = "";
    tmp_path(path, sizeof path, "img.ppm");
    CHECKF(rp_image_write(path, W, H, 3, px, err, sizeof err), "%s", err);
    FILE *f = fopen(path, "rb");
    CHECK(f != NULL);
    if (f) {
        char head[16];
        CHECK(fread(head, 1, 11, f) == 11 && memcmp(head, "P6\n4 2\n255\n", 11) == 0);
        uint8_t data[W * H * 3];
        CHECK(fread(data, 1, sizeof data, f) == sizeof data);
        for (int i = 0; i < W * H; i++) CHECKF(data[3 * i + 1] == enc[i], "pixel %d: %d != %d", i, data[3 * i + 1], enc[i]);
        fclose(f);
    }
    tmp_path(path, sizeof path, "img.png");
    CHECKF(rp_image_write(path, W, H, 3, px, err, sizeof err), "%s", err);
    int w, h, c;
    uint8_t *png = stbi_load(path, &w, &h, &c, 3);
    CHECK(png != NULL);
    if (png) {
        CHECK(w == W && h == H && c == 3);
        for (int i = 0; i < W * H; i++) CHECKF(png[3 * i + 1] == enc[i], "png pixel %d: %d != %d", i, png[3 * i + 1], enc[i]);
        stbi_image_free(png);
    }
    /* One channel goes to a grey PNG. */
    tmp_path(path, sizeof path, "grey.png");
    CHECKF(rp_image_write(path, W, H, 1, lin, err, sizeof err), "%s", err);
    png = stbi_load(path, &w, &h, &c, 1);
    CHECK(png != NULL && c == 1);
    if (png) {
        for (int i = 0; i < W * H; i++) CHECK(png[i] == enc[i]);
        stbi_image_free(png);
    }
}

static void test_errors(void) {
    float px[3] = {0, 0, 0};
    char err[512] = "";
    CHECK(!rp_image_write("/nonexistent-dir/x.png", 1, 1, 3, px, err, sizeof err));
    CHECKF(strstr(err, "/nonexistent-dir/x.png: error: ") == err, "%s", err);
    err[0] = '\0';
    char path[512];
    tmp_path(path, sizeof path, "img.jpg");
    CHECK(!rp_image_write(path, 1, 1, 3, px, err, sizeof err));
    CHECKF(strstr(err, "unknown image format") != NULL, "%s", err);
    CHECK(!rp_image_write(path, 0, 1, 3, px, err, sizeof err));
    int w, h, c;
    CHECK(rp_image_read_pfm("/nonexistent-dir/x.pfm", &w, &h, &c, err, sizeof err) == NULL);
    /* A truncated PFM. */
    tmp_path(path, sizeof path, "short.pfm");
    FILE *f = fopen(path, "wb");
    if (f) {
        fputs("PF\n4 4\n-1.0\n", f);
        fwrite(px, sizeof(float), 3, f);
        fclose(f);
    }
    err[0] = '\0';
    CHECK(rp_image_read_pfm(path, &w, &h, &c, err, sizeof err) == NULL);
    CHECKF(strstr(err, "truncated") != NULL, "%s", err);
}

static size_t largest_request;
static bool note_size(void *user, size_t size) {
    (void)user;
    if (size > largest_request) largest_request = size;
    return true;
}

/* Headers that claim more than the file holds (issue 23): a PFM of 65536 x 65536 pixels in 20
 * bytes (51 GB), an HDR of 30000 x 30000 (10 GB, which stb would allocate whole and fill with zeros)
 * are refused before anything that size is asked for. */
static void test_declared_sizes(void) {
    char path[512], err[512] = "";
    int w, h, c;
    io_set_alloc_hook(note_size, NULL);
    tmp_path(path, sizeof path, "huge.pfm");
    FILE *f = fopen(path, "wb");
    if (f) {
        fputs("PF\n65536 65536\n-1.0\n12345678", f);
        fclose(f);
    }
    largest_request = 0;
    CHECK(rp_image_read_pfm(path, &w, &h, &c, err, sizeof err) == NULL);
    CHECKF(strstr(err, "truncated PFM data") != NULL, "%s", err);
    CHECKF(largest_request < (1u << 20), "a 20-byte PFM asked for %zu bytes", largest_request);
    tmp_path(path, sizeof path, "huge.hdr");
    f = fopen(path, "wb");
    if (f) {
        fputs("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 30000 +X 30000\n\x80\x80\x80\x81", f);
        fclose(f);
    }
    largest_request = 0;
    err[0] = '\0';
    CHECK(rp_image_read_hdr(path, &w, &h, err, sizeof err) == NULL);
    CHECKF(strstr(err, "RP_MAX_TEXTURE_PIXELS") != NULL, "%s", err);
    CHECKF(largest_request < (1u << 20), "a 60-byte HDR asked for %zu bytes", largest_request);
    io_set_alloc_hook(NULL, NULL);
}

int main(void) {
    test_declared_sizes();
    test_pfm_roundtrip(1);
    test_pfm_roundtrip(3);
    test_8bit();
    test_errors();
    return RP_TEST_END();
}
