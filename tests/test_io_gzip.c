// rp-test: labels=io timeout=120
/* Reading .gz scene files (io_vfs.c): the whole-buffer inflate (libdeflate, when built with it)
 * and zlib's streaming one must give the same scene on every kind of gzip file: one member, several
 * members (the last trailer then states only its own size), a trailer whose size lies, and a
 * truncated file, which must fail with the file's name; and tar.gz archives likewise. */
#include <math.h>
#include <stdint.h>
#include <sys/stat.h>
#include <zlib.h>

#include "raypack_io.h"
#include "rp_test.h"

static char tmp_dir[512];

static const char *tmp_path(const char *name, char *buf, size_t size) {
    snprintf(buf, size, "%s/%s", tmp_dir, name);
    return buf;
}

/* An OBJ of n triangles, triangle i at x = i. */
static size_t make_obj(char *buf, size_t size, int first, int n) {
    size_t len = 0;
    for (int i = first; i < first + n; i++)
        len += (size_t)snprintf(buf + len, size - len, "v %d 0 0\nv %d.5 1 0\nv %d 0 1\nf -3 -2 -1\n", i, i, i);
    return len;
}

static size_t gz_member(const char *text, size_t n, unsigned char *out, size_t cap) {
    z_stream z;
    memset(&z, 0, sizeof z);
    deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY); /* +16: gzip wrapper */
    z.next_in = (unsigned char *)(uintptr_t)text;
    z.avail_in = (unsigned)n;
    z.next_out = out;
    z.avail_out = (unsigned)cap;
    deflate(&z, Z_FINISH);
    size_t got = z.total_out;
    deflateEnd(&z);
    return got;
}

static void write_file(const char *name, const void *data, size_t n) {
    char path[1024];
    FILE *f = fopen(tmp_path(name, path, sizeof path), "wb");
    if (!f) exit(1);
    fwrite(data, 1, n, f);
    fclose(f);
}

/* Loads name and checks it holds triangles 0..n-1 in order. */
static void expect_scene(const char *name, int n) {
    char path[1024], err[1024] = "";
    rp_scene_data s;
    bool ok = rp_scene_data_load(tmp_path(name, path, sizeof path), &s, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    if (!ok) return;
    CHECKF(s.triangle_count == (size_t)n, "%s: %zu triangles, want %d", name, s.triangle_count, n);
    bool in_order = s.triangle_count == (size_t)n;
    for (size_t t = 0; in_order && t < s.triangle_count; t++)
        in_order = s.positions[3 * (size_t)s.indices[3 * t]] == (float)t;
    CHECKF(in_order, "%s: triangles out of order", name);
    rp_scene_data_free(&s);
}

/* A one-file ustar archive holding `text` as scene.obj; returns its size (a multiple of 512). */
static size_t make_tar(const char *text, size_t n, unsigned char *out) {
    memset(out, 0, 512);
    snprintf((char *)out, 100, "scene.obj");
    snprintf((char *)out + 100, 8, "0000644");
    snprintf((char *)out + 108, 8, "0000000");
    snprintf((char *)out + 116, 8, "0000000");
    snprintf((char *)out + 124, 12, "%011o", (unsigned)n);
    snprintf((char *)out + 136, 12, "%011o", 0u);
    out[156] = '0';
    memcpy(out + 257, "ustar\0" "00", 8);
    memset(out + 148, ' ', 8);
    unsigned sum = 0;
    for (int i = 0; i < 512; i++) sum += out[i];
    snprintf((char *)out + 148, 8, "%06o", sum);
    size_t body = (n + 511) / 512 * 512;
    memset(out + 512, 0, body + 1024); /* data, then two zero blocks */
    memcpy(out + 512, text, n);
    return 512 + body + 1024;
}

int main(void) {
    const char *t = getenv("RP_TEST_TMP");
    snprintf(tmp_dir, sizeof tmp_dir, "%s", t ? t : "/tmp/rp_test_io_gzip");
    mkdir(tmp_dir, 0755);
    enum { CAP = 1 << 20 };
    char *text = malloc(CAP);
    unsigned char *gz = malloc(2 * CAP);
    size_t a = make_obj(text, CAP, 0, 3000);
    size_t na = gz_member(text, a, gz, CAP);
    write_file("one.obj.gz", gz, na);
    expect_scene("one.obj.gz", 3000);

    /* two members: the second continues the first's triangles */
    size_t b = make_obj(text, CAP, 3000, 500);
    size_t nb = gz_member(text, b, gz + na, CAP);
    write_file("two.obj.gz", gz, na + nb);
    expect_scene("two.obj.gz", 3500);

    /* a trailer that states too small a size (mod 2^32 wrap, or a lying writer) */
    unsigned char *lie = malloc(na);
    memcpy(lie, gz, na);
    lie[na - 4] = 7, lie[na - 3] = 0, lie[na - 2] = 0, lie[na - 1] = 0;
    write_file("lie.obj.gz", lie, na); /* the CRC still matches, only ISIZE is wrong */
    char path[1024], err[1024] = "";
    rp_scene_data s;
    bool ok = rp_scene_data_load(tmp_path("lie.obj.gz", path, sizeof path), &s, err, sizeof err);
    /* zlib checks ISIZE too: either the scene loads whole or the file is refused by name */
    if (ok) {
        CHECK(s.triangle_count == 3000);
        rp_scene_data_free(&s);
    } else {
        CHECKF(strstr(err, "lie.obj.gz") != NULL, "message '%s'", err);
    }

    /* truncated: the first half of the member */
    write_file("cut.obj.gz", gz, na / 2);
    ok = rp_scene_data_load(tmp_path("cut.obj.gz", path, sizeof path), &s, err, sizeof err);
    CHECK(!ok);
    if (ok) rp_scene_data_free(&s);
    else CHECKF(strstr(err, "cut.obj.gz") != NULL, "message '%s'", err);
    /* trailing garbage after a complete member */
    memcpy(gz + na, "garbage!", 8);
    write_file("tail.obj.gz", gz, na + 8);
    ok = rp_scene_data_load(tmp_path("tail.obj.gz", path, sizeof path), &s, err, sizeof err);
    if (ok) {
        CHECK(s.triangle_count == 3000);
        rp_scene_data_free(&s);
    } else {
        CHECKF(strstr(err, "tail.obj.gz") != NULL, "message '%s'", err);
    }
    /* tar.gz archives: one member (inflated whole) and two (the streaming fallback) */
    unsigned char *tar = malloc(CAP + 4096);
    size_t tn = make_tar(text, make_obj(text, CAP, 0, 2000), tar);
    size_t ga = gz_member((const char *)tar, tn, gz, CAP);
    write_file("one.tar.gz", gz, ga);
    expect_scene("one.tar.gz", 2000);
    size_t half = tn / 1024 * 512;
    ga = gz_member((const char *)tar, half, gz, CAP);
    ga += gz_member((const char *)tar + half, tn - half, gz + ga, CAP);
    write_file("two.tar.gz", gz, ga);
    expect_scene("two.tar.gz", 2000);
    write_file("cut.tar.gz", gz, ga / 3);
    ok = rp_scene_data_load(tmp_path("cut.tar.gz", path, sizeof path), &s, err, sizeof err);
    CHECK(!ok);
    if (ok) rp_scene_data_free(&s);
    else CHECKF(strstr(err, "cut.tar.gz") != NULL, "message '%s'", err);
    free(tar);
    free(lie);
    free(text);
    free(gz);
    return RP_TEST_END();
}
