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

/* A one-component JPEG of w x h pixels built by hand: one quantisation table (16-bit entries of q,
 * or 8-bit), a DC table whose only code, the bit 0, means "category dc_cat", an AC table whose only
 * code means "end of block" (ac_table false: none, and a scan with Se = 0 that still names table 0
 * for its AC coefficients), then either no
 * entropy-coded data at all (stb_image feeds itself zeros: a DC difference of -(2^dc_cat - 1) per
 * block) or, with data, a difference of +(2^dc_cat - 1) per block. progressive: one first DC scan
 * with successive approximation Al = 13. Returns its size. */
static size_t hand_jpeg(uint8_t *out, int w, int h, bool dqt16, int q, int dc_cat, bool data, bool ac_table,
                        bool progressive) {
    size_t n = 0;
#define PUT(...)                                                                     \
    do {                                                                             \
        const uint8_t bytes_[] = {__VA_ARGS__};                                      \
        memcpy(out + n, bytes_, sizeof bytes_);                                      \
        n += sizeof bytes_;                                                          \
    } while (0)
    PUT(0xff, 0xd8);
    PUT(0xff, 0xdb, 0, dqt16 ? 131 : 67, dqt16 ? 0x10 : 0x00);
    for (int i = 0; i < 64; i++) {
        if (dqt16) PUT((uint8_t)(q >> 8));
        PUT((uint8_t)q);
    }
    PUT(0xff, progressive ? 0xc2 : 0xc0, 0, 11, 8, (uint8_t)(h >> 8), (uint8_t)h, (uint8_t)(w >> 8), (uint8_t)w, 1, 1,
        0x11, 0);
    PUT(0xff, 0xc4, 0, 20, 0x00, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, (uint8_t)dc_cat);
    if (ac_table && !progressive) PUT(0xff, 0xc4, 0, 20, 0x10, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00);
    if (progressive)
        PUT(0xff, 0xda, 0, 8, 1, 1, 0x00, 0, 0, 13);
    else
        PUT(0xff, 0xda, 0, 8, 1, 1, 0x00, 0, ac_table ? 63 : 0, 0); /* Se = 0 without AC table */
    if (data) { /* per block: the DC code 0, dc_cat one bits, the end-of-block code 0 */
        int blocks = ((w + 7) / 8) * ((h + 7) / 8), bits = 0;
        uint32_t acc = 0;
        for (int b = 0; b < blocks; b++)
            for (int i = 0; i < dc_cat + 2; i++) {
                acc = acc << 1 | (i >= 1 && i <= dc_cat);
                if (++bits == 8) {
                    out[n++] = (uint8_t)acc;
                    if (acc == 0xff) out[n++] = 0; /* byte stuffing */
                    acc = 0, bits = 0;
                }
            }
        if (bits) out[n++] = (uint8_t)(acc << (8 - bits) | (0xffu >> bits));
    }
    PUT(0xff, 0xd9);
#undef PUT
    return n;
}

/* Loads an OBJ whose material maps the texture t.jpg, written from jpg; returns the error, or ""
 * when it loaded. */
static const char *load_textured(const uint8_t *jpg, size_t size) {
    static char err[1024];
    char path[512];
    FILE *f = fopen(tmp_path(path, sizeof path, "t.jpg"), "wb");
    if (f) {
        fwrite(jpg, 1, size, f);
        fclose(f);
    }
    f = fopen(tmp_path(path, sizeof path, "tex.mtl"), "w");
    if (f) {
        fputs("newmtl a\nmap_Kd t.jpg\n", f);
        fclose(f);
    }
    f = fopen(tmp_path(path, sizeof path, "tex.obj"), "w");
    if (f) {
        fputs("mtllib tex.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n", f);
        fclose(f);
    }
    rp_scene_data s;
    err[0] = '\0';
    if (rp_scene_data_load(path, &s, err, sizeof err)) {
        rp_scene_data_free(&s);
        err[0] = '\0';
    }
    return err;
}

/* JPEGs that made stb_image (2.27) compute out of range (issue 23, texture fuzzer): stb sums the DC
 * differences of every block since the last restart and multiplies the sum by the quantiser in int
 * (stb_image.h:2197; dc << Al in progressive scans), so corrupt data overflows it. They are refused
 * with file:line before stb decodes them; the same files with small differences still load. */
static void test_jpeg_dc_range(void) {
    static uint8_t jpg[8192];
    const char *err;
    /* two blocks of -32767 from the zeros stb reads past the end, times 65535 (tests/fuzz/crashes/
     * texture/stb_jpeg_dc_overflow_dqt16) */
    err = load_textured(jpg, hand_jpeg(jpg, 16, 8, true, 65535, 15, false, true, false));
    CHECKF(strstr(err, "tex.mtl:2: error: cannot decode texture 't.jpg': corrupt JPEG (a DC coefficient out of range)"),
           "%s", err);
    /* 258 blocks of +32767 coded in the data, times an 8-bit quantiser of 255 */
    err = load_textured(jpg, hand_jpeg(jpg, 2064, 8, false, 255, 15, true, true, false));
    CHECKF(strstr(err, "a DC coefficient out of range"), "%s", err);
    /* the same with differences of +1 (a grey ramp of 258 blocks): loads */
    err = load_textured(jpg, hand_jpeg(jpg, 2064, 8, false, 1, 1, true, true, false));
    CHECKF(err[0] == '\0', "%s", err);
    /* a progressive first DC scan: 9 blocks of -32767, shifted left by 13 (stbi__jpeg_decode_block_prog_dc) */
    err = load_textured(jpg, hand_jpeg(jpg, 160, 8, false, 1, 15, false, true, true));
    CHECKF(strstr(err, "a DC coefficient out of range"), "%s", err);
    err = load_textured(jpg, hand_jpeg(jpg, 16, 8, false, 1, 1, true, true, true)); /* 2 << 13 fits */
    CHECKF(err[0] == '\0', "%s", err);
    /* the texture fuzzer's file whose entropy-coded data a marker cuts inside a code: stb's count
     * of bits went to -8 and its next refill shifted by 32 (stb_image.h:2065) */
    const char *src = getenv("RP_SOURCE_DIR");
    char repro[1024];
    snprintf(repro, sizeof repro, "%s/tests/fuzz/crashes/texture/stb_jpeg_code_cut_by_marker", src ? src : ".");
    FILE *f = fopen(repro, "rb");
    size_t got = f ? fread(jpg, 1, sizeof jpg, f) : 0;
    if (f) fclose(f);
    CHECKF(got > 100, "cannot read %s", repro);
    err = load_textured(jpg, got);
    CHECKF(strstr(err, "tex.mtl:2: error: cannot decode texture 't.jpg': corrupt JPEG (entropy-coded data cut inside a code by a marker)"),
           "%s", err);
    /* the same in a progressive AC scan (stbi__jpeg_decode_block_prog_ac's fast path takes bits it
     * does not have): the first 1176 bytes of Node.js's doc/thin-white-stripe.jpg (MIT), a
     * progressive JPEG, and an EOI (tests/fuzz/crashes/texture/stb_jpeg_progressive_ac_cut_by_marker);
     * the cut at every other place of that file is refused by stb itself or loads */
    snprintf(repro, sizeof repro, "%s/tests/fuzz/crashes/texture/stb_jpeg_progressive_ac_cut_by_marker",
             src ? src : ".");
    f = fopen(repro, "rb");
    got = f ? fread(jpg, 1, sizeof jpg, f) : 0;
    if (f) fclose(f);
    CHECKF(got > 1000, "cannot read %s", repro);
    err = load_textured(jpg, got);
    CHECKF(strstr(err, "tex.mtl:2: error: cannot decode texture 't.jpg': corrupt JPEG (entropy-coded data cut inside a code by a marker)"),
           "%s", err);
    /* a baseline scan with Se = 0 and no AC table: stb reads AC coefficients whatever Se says, from a
     * table it never wrote (tests/fuzz/crashes/texture/stb_jpeg_baseline_scan_without_ac_table) */
    err = load_textured(jpg, hand_jpeg(jpg, 16, 8, false, 1, 1, true, false, false));
    CHECKF(strstr(err, "tex.mtl:2: error: cannot decode texture 't.jpg': corrupt JPEG (a Huffman table"), "%s", err);
}

/* An HDR header line that starts with a NUL byte ends the header for stb_image (it compares the
 * line as a C string), so the RLE check must read the pixels from there too: it did not, and stb
 * looped forever on the truncated RLE scanline behind it (issue 23, texture fuzzer; reproducer in
 * tests/fuzz/crashes/texture/stb_hdr_nul_header_line_hang). Refused, not hung. */
static void test_hdr_nul_header_line(void) {
    static const char hdr[] = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\0\0\n-Y 1 +X 8\n\x02\x02\x00\x08\x88\x64";
    char path[512], err[512] = "";
    FILE *f = fopen(tmp_path(path, sizeof path, "nul.hdr"), "wb");
    if (f) {
        fwrite(hdr, 1, sizeof hdr - 1, f);
        fclose(f);
    }
    int w, h;
    float *px = rp_image_read_hdr(path, &w, &h, err, sizeof err);
    CHECK(px == NULL);
    free(px);
    CHECKF(strstr(err, "nul.hdr: error: corrupt Radiance HDR image (an RLE scanline with a run of length 0, or cut short)"),
           "%s", err);
}

/* HDR pixels cut short: stb_image fills what an RLE file lacks with zeros and leaves a flat file's
 * missing pixels unwritten, with no error, so `render --env` lit the scene with a black (or garbage)
 * sky; a 91-byte header claiming 8000 x 8000 flat pixels took 1.5 GB and rendered (robust6).
 * Refused: flat scanlines (width under 8), an RLE-sized image whose first scanline is flat, an RLE
 * dump cut short. The complete files load. */
static void test_hdr_cut_short(void) {
    static const struct {
        const char *name;
        const char *data;
        size_t size;
        bool ok;
    } cases[] = {
#define HDR_HEAD "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n"
#define HDR_CASE(name, text, ok) {name, HDR_HEAD text, sizeof HDR_HEAD text - 1, ok}
        HDR_CASE("flat_ok.hdr", "-Y 1 +X 2\n\x80\x80\x80\x81\x80\x80\x80\x81", true),
        HDR_CASE("flat_short.hdr", "-Y 2 +X 2\n\x80\x80\x80\x81\x80\x80\x80\x81", false),
        HDR_CASE("flat_wide.hdr", "-Y 8000 +X 8000\n\x80\x80\x80\x81", false),
        HDR_CASE("negative.hdr", "-Y 4 +X -5\n\x80\x80\x80\x81", false), /* was "-5x4 is more than N pixels" */
        /* one 8-pixel RLE scanline: R, G, B as runs of 8, E as a dump of 8 bytes, 2 of them missing */
        HDR_CASE("rle_ok.hdr",
                 "-Y 1 +X 8\n\x02\x02\x00\x08\x88\x80\x88\x80\x88\x80\x08\x81\x81\x81\x81\x81\x81\x81\x81",
                 true),
        HDR_CASE("rle_short.hdr",
                 "-Y 1 +X 8\n\x02\x02\x00\x08\x88\x80\x88\x80\x88\x80\x08\x81\x81\x81\x81\x81\x81",
                 false),
#undef HDR_CASE
#undef HDR_HEAD
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char path[512], err[512] = "";
        FILE *f = fopen(tmp_path(path, sizeof path, cases[i].name), "wb");
        if (f) {
            fwrite(cases[i].data, 1, cases[i].size, f);
            fclose(f);
        }
        int w = 0, h = 0;
        float *px = rp_image_read_hdr(path, &w, &h, err, sizeof err);
        if (cases[i].ok) {
            CHECKF(px && w * h >= 2 && px[0] > 0.5f && px[3 * w * h - 1] > 0.5f, "%s: %s", cases[i].name, err);
        } else {
            CHECKF(!px && strstr(err, "corrupt Radiance HDR image") && strstr(err, cases[i].name), "%s loaded (%dx%d): %s",
                   cases[i].name, w, h, err);
        }
        free(px);
    }
}

int main(void) {
    test_declared_sizes();
    test_pfm_roundtrip(1);
    test_pfm_roundtrip(3);
    test_8bit();
    test_errors();
    test_jpeg_dc_range();
    test_hdr_nul_header_line();
    test_hdr_cut_short();
    return RP_TEST_END();
}
