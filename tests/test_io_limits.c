// rp-test: labels=io timeout=120
/* Loaders against files built to exhaust them (issue 23): include bombs (on disk and in a tar.gz),
 * PLY counts the data cannot hold and records of no properties, gzip files whose size trailer lies
 * or that inflate past the cap, folders and unreadable files. Each must fail fast with file:line
 * and the reason; the environment's limits raise the caps. */
#include <errno.h>
#include <stdint.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
#include <zlib.h>

#include "raypack_io.h"
#include "rp_test.h"

static char dir[900];

static const char *at(const char *name) {
    static char buf[4][1200];
    static int k;
    k = (k + 1) & 3;
    snprintf(buf[k], sizeof buf[k], "%s/%s", dir, name);
    return buf[k];
}

static void write_bytes(const char *name, const void *data, size_t n) {
    FILE *f = fopen(at(name), "wb");
    if (!f) {
        fprintf(stderr, "cannot write %s\n", at(name));
        exit(1);
    }
    fwrite(data, 1, n, f);
    fclose(f);
}

static void write_text(const char *name, const char *text) { write_bytes(name, text, strlen(text)); }

/* Process CPU time: a hang guard that a loaded machine (other jobs on the same cores) does not trip. */
static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Loads path, which must fail within a few seconds with "<...file>:<line>: error: ...needle...". */
static void expect_fail(const char *path, const char *file, unsigned line, const char *needle) {
    rp_scene_data s;
    char err[1024] = "";
    double t0 = now_s();
    bool ok = rp_scene_data_load(path, &s, err, sizeof err);
    double dt = now_s() - t0;
    CHECKF(!ok, "%s loaded (expected '%s')", path, needle);
    if (ok) {
        rp_scene_data_free(&s);
        return;
    }
    char want[256];
    snprintf(want, sizeof want, "%s:%u: error: ", file, line);
    CHECKF(strstr(err, want) != NULL, "message '%s' lacks '%s'", err, want);
    CHECKF(strstr(err, needle) != NULL, "message '%s' lacks '%s'", err, needle);
    /* a hang guard, not a benchmark: under ASan the 4096 includes of the bomb take about 3 s alone
     * (2 of them in the system: ASan's mappings), and CI runs two tests at once */
    double limit = rp_test_sanitized() ? 30.0 : 5.0;
    CHECKF(dt < limit, "%s took %.1f s of CPU time to fail", path, dt);
}

static bool loads(const char *path) {
    rp_scene_data s;
    char err[1024] = "";
    bool ok = rp_scene_data_load(path, &s, err, sizeof err);
    if (!ok) fprintf(stderr, "%s\n", err);
    else rp_scene_data_free(&s);
    return ok;
}

/* bomb0.aff includes bomb1.aff twice, ..., bomb30.aff holds one sphere: 2^31 parses uncapped. */
static void write_bomb(const char *prefix) {
    char name[64], text[256];
    for (int i = 0; i < 31; i++) {
        snprintf(name, sizeof name, "%s%d.aff", prefix, i);
        snprintf(text, sizeof text, "i 0 %s%d.aff\ni 0 %s%d.aff\n", prefix, i + 1, prefix, i + 1);
        write_text(name, text);
    }
    snprintf(name, sizeof name, "%s31.aff", prefix);
    write_text(name, "s 0 0 0 1\n");
}

static void test_include_bomb(void) {
    write_bomb("bomb");
    /* which file reports depends on the depth-first order: the last include line that runs out */
    expect_fail(at("bomb0.aff"), "bomb29.aff", 2, "more than 4096 included files");
    expect_fail(at("bomb0.aff"), "bomb29.aff", 2, "RP_MAX_INCLUDES raises the limit");

    /* the same bomb as an archive (807 bytes of .tar.gz in the issue) */
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "cd '%s' && mkdir -p tarbomb && cp bomb*.aff tarbomb/ && tar czf bomb.tar.gz tarbomb", dir);
    if (system(cmd) == 0) expect_fail(at("bomb.tar.gz"), "bomb.tar.gz/tarbomb/bomb29.aff", 2, "more than 4096 included files");

    /* the caps come from the environment: 3 includes pass under 3, not under 2 */
    write_text("three.aff", "i 0 one.aff\ni 0 one.aff\ni 0 one.aff\n");
    write_text("one.aff", "s 0 0 0 1\n");
    setenv("RP_MAX_INCLUDES", "3", 1);
    CHECK(loads(at("three.aff")));
    setenv("RP_MAX_INCLUDES", "2", 1);
    expect_fail(at("three.aff"), "three.aff", 3, "more than 2 included files");
    unsetenv("RP_MAX_INCLUDES");
    /* included bytes: one.aff is 10 bytes; 25 bytes take two of three */
    setenv("RP_MAX_INCLUDE_BYTES", "25", 1);
    expect_fail(at("three.aff"), "three.aff", 3, "exceed 25 bytes");
    setenv("RP_MAX_INCLUDE_BYTES", "30", 1);
    CHECK(loads(at("three.aff")));
    unsetenv("RP_MAX_INCLUDE_BYTES");
}

static const char PLY_ASCII_HEAD[] = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                     "property float y\nproperty float z\n";

static void test_ply_counts(void) {
    char text[2048];
    /* records of no properties: 10^12 of them took minutes; now refused at the element line */
    snprintf(text, sizeof text, "%selement junk 1000000000000\nend_header\n0 0 0\n1 0 0\n0 1 0\n", PLY_ASCII_HEAD);
    write_text("noprops.ply", text);
    expect_fail(at("noprops.ply"), "noprops.ply", 7, "no properties");
    /* a vertex count the data cannot hold, binary: 12 bytes a vertex, 36 bytes there */
    const char bin_head[] = "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\n"
                            "property float y\nproperty float z\nend_header\n";
    char bin[512];
    memcpy(bin, bin_head, sizeof bin_head - 1);
    memset(bin + sizeof bin_head - 1, 0, 36);
    write_bytes("bigcount.ply", bin, sizeof bin_head - 1 + 36);
    expect_fail(at("bigcount.ply"), "bigcount.ply", 3, "records of at least 12 bytes");
    /* faces: the list's count byte makes each record at least 1 byte */
    const char face_head[] = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                             "property float y\nproperty float z\nelement face 100\n"
                             "property list uchar int vertex_indices\nend_header\n";
    memcpy(bin, face_head, sizeof face_head - 1);
    memset(bin + sizeof face_head - 1, 0, 36 + 50);
    write_bytes("faces.ply", bin, sizeof face_head - 1 + 36 + 50);
    expect_fail(at("faces.ply"), "faces.ply", 7, "element 'face' declares 100 records");
    /* a count that fits exactly still loads */
    snprintf(text, sizeof text, "%selement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                "0 0 0\n1 0 0\n0 1 0\n3 0 1 2", PLY_ASCII_HEAD);
    write_text("exact.ply", text);
    CHECK(loads(at("exact.ply")));
}

static void test_gzip(void) {
    /* an 18-byte gzip (empty deflate) whose trailer claims 4 GiB - 1 */
    const unsigned char tiny[18] = {0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3, 3, 0, 0, 0, 0, 0, 0xff, 0xff};
    unsigned char liar[20];
    memcpy(liar, tiny, 18);
    liar[18] = 0xff;
    liar[19] = 0xff;
    write_bytes("liar.obj.gz", liar, 20);
    expect_fail(at("liar.obj.gz"), "liar.obj.gz", 0, "gzip");
    /* a gzip bomb against a lowered cap: 4 MiB of blanks */
    gzFile gz = gzopen(at("bomb.obj.gz"), "wb9");
    CHECK(gz != NULL);
    if (gz) {
        static char blanks[1 << 16];
        memset(blanks, ' ', sizeof blanks);
        for (int i = 0; i < 64; i++) gzwrite(gz, blanks, sizeof blanks);
        gzclose(gz);
    }
    setenv("RP_MAX_FILE_BYTES", "1M", 1);
    expect_fail(at("bomb.obj.gz"), "bomb.obj.gz", 0, "more than 1048576 bytes");
    unsetenv("RP_MAX_FILE_BYTES");
    /* a truncated gzip says so */
    FILE *f = fopen(at("bomb.obj.gz"), "rb");
    unsigned char head[200];
    size_t n = f ? fread(head, 1, sizeof head, f) : 0;
    if (f) fclose(f);
    write_bytes("cut.obj.gz", head, n);
    expect_fail(at("cut.obj.gz"), "cut.obj.gz", 0, "gzip");
}

static void test_not_files(void) {
    mkdir(at("folder.obj"), 0777);
    expect_fail(at("folder.obj"), "folder.obj", 0, strerror(EISDIR));
    expect_fail(at("missing.obj"), "missing.obj", 0, strerror(ENOENT));
    mkdir(at("folder.aff"), 0777);
    write_text("incdir.aff", "s 0 0 0 1\ni 0 folder.aff\n");
    expect_fail(at("incdir.aff"), "incdir.aff", 2, strerror(EISDIR));
    write_text("noperm.obj", "v 0 0 0\n");
    chmod(at("noperm.obj"), 0);
    if (access(at("noperm.obj"), R_OK) != 0) /* root reads anyway */
        expect_fail(at("noperm.obj"), "noperm.obj", 0, strerror(EACCES));
    chmod(at("noperm.obj"), 0644);
}

/* Textures whose headers lie: checked before stb_image allocates what they claim. */
static void test_textures(void) {
    write_text("tex.obj", "mtllib tex.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                          "f 1/1 2/2 3/3\n");
    write_text("tex.mtl", "newmtl a\nmap_Kd t.png\n");
    /* a PNG whose first chunk claims 2 GiB: stb_image grew its buffer to 1.6 GB for such a file */
    static const unsigned char png[] = {0x89, 'P', 'N', 'G', 0x0d, 0x0a, 0x1a, 0x0a, 0, 0, 0, 13, 'I', 'H', 'D', 'R',
                                        0, 0, 0, 3, 0, 0, 0, 2, 8, 2, 0, 0, 0, 0x12, 0x16, 0xf1, 0x4d,
                                        0x7f, 0xff, 0xff, 0xff, 'I', 'D', 'A', 'T', 0, 0, 0, 0};
    write_bytes("t.png", png, sizeof png);
    expect_fail(at("tex.obj"), "tex.mtl", 2, "a chunk longer than the file");
    /* a PNG claiming 10000 x 10000 pixels (300 MB of RGB, under stb_image's own 1 GiB limit) with
     * nothing behind it */
    unsigned char big[sizeof png];
    memcpy(big, png, sizeof png);
    big[16] = 0, big[17] = 0, big[18] = 0x27, big[19] = 0x10; /* width 10000 */
    big[20] = 0, big[21] = 0, big[22] = 0x27, big[23] = 0x10; /* height 10000 */
    big[33] = big[34] = big[35] = big[36] = 0;
    memcpy(big + 37, "tEXt", 4); /* an empty text chunk instead of the IDAT */
    write_bytes("t.png", big, sizeof big);
    expect_fail(at("tex.obj"), "tex.mtl", 2, "RP_MAX_TEXTURE_PIXELS");
    /* a JPEG whose Huffman table counts 16 x 255 codes (stb_image wrote past its 257 entries) */
    unsigned char jpg[64] = {0xff, 0xd8, 0xff, 0xc4, 0x00, 0x13, 0x00};
    for (int i = 0; i < 16; i++) jpg[7 + i] = 0xff;
    jpg[23] = 0xff, jpg[24] = 0xd9;
    write_bytes("t.png", jpg, 25);
    expect_fail(at("tex.obj"), "tex.mtl", 2, "Huffman table");
}

int main(void) {
    const char *t = getenv("RP_TEST_TMP");
    snprintf(dir, sizeof dir, "%s", t ? t : "/tmp/raypack_test_io_limits");
    mkdir(dir, 0777);
    test_include_bomb();
    test_ply_counts();
    test_gzip();
    test_not_files();
    test_textures();
    return RP_TEST_END();
}
