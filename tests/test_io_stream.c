// rp-test: labels=io timeout=900
/* The streamed NFF loader (a gzip'd file inflated block by block on a thread while the blocks
 * before are parsed, io_stream.c) gives the whole-buffer loader's result: a synthetic .nff.gz using
 * every command (a light's colour on the next line, CRLF, a polygon on a line longer than a block,
 * transform and keyframed blocks, a `k` block given twice, a mesh, `tpa`, an include) loaded with
 * blocks of 1 to 97 bytes, so that blocks end on every line, on 1 and 3 threads, bit for bit;
 * errors in the last lines with the same message and line; the same text in three gzip members; a
 * truncated and a corrupt gzip file (the same message, naming the file); OBJ likewise (its statements
 * are single lines); and the shared teapot, Sponza and rings. */
#include <sys/stat.h>
#include <zlib.h>

#include "io/io_internal.h"
#include "raypack_io.h"
#include "rp_test.h"
#include "scene_same.h"

static char tmp_dir[512];

static const char *tmp_path(const char *name, char *buf, size_t size) {
    snprintf(buf, size, "%s/%s", tmp_dir, name);
    return buf;
}

/* Writes text as a gzip file of `members` members (cut at arbitrary bytes, mid-line). */
static void write_gz(const char *path, const char *text, int members) {
    size_t n = strlen(text), at = 0;
    for (int m = 0; m < members; m++) {
        size_t to = m + 1 == members ? n : n * (size_t)(2 * m + 1) / (size_t)(2 * members) + 1;
        gzFile gz = gzopen(path, m == 0 ? "wb" : "ab");
        CHECK(gz != NULL);
        if (!gz) return;
        if (to > at) CHECK(gzwrite(gz, text + at, (unsigned)(to - at)) == (int)(to - at));
        gzclose(gz);
        at = to;
    }
}

static void write_file(const char *path, const void *data, size_t size) {
    FILE *fp = fopen(path, "wb");
    CHECK(fp != NULL);
    if (!fp) return;
    CHECK(fwrite(data, 1, size, fp) == size);
    fclose(fp);
}

/* Loads path whole (one thread, no stream) and streamed with blocks of 1..97 bytes on 1 and 3
 * threads (on 3, chunks of a few bytes inside each window as well); every streamed load must give
 * the whole load's scene, or its error message. The whole load's error must contain want_error. */
static void check_streamed(const char *path, const char *want_error) {
    rp_scene_data whole;
    char werr[1024] = "";
    io_load_opts w = {.threads = 1, .stream = -1};
    bool wok = io_load_file_opts(path, &w, &whole, werr, sizeof werr);
    if (want_error)
        CHECKF(!wok && strstr(werr, want_error) != NULL, "%s: whole load: want '%s', got '%s'", path, want_error,
               wok ? "(loaded)" : werr);
    else
        CHECKF(wok, "%s: whole load failed: %s", path, werr);
    int bad = 0;
    for (size_t block = 1; block <= 97 && bad < 3; block += block < 16 ? 1 : 9) {
        for (int threads = 1; threads <= 3; threads += 2) {
            size_t blocks = 0;
            io_load_opts o = {.threads = threads, .stream = 1, .stream_block = block, .blocks = &blocks,
                              .chunk_bytes = threads > 1 ? block + 3 : 0};
            rp_scene_data s;
            char serr[1024] = "";
            bool sok = io_load_file_opts(path, &o, &s, serr, sizeof serr);
            char why[128] = "";
            bool same = sok == wok && (wok ? same_scene(&whole, &s, why, sizeof why) && same_animation(&whole, &s, why, sizeof why)
                                           : strcmp(werr, serr) == 0);
            if (!same || (sok && blocks < 2)) {
                bad++;
                CHECKF(same, "%s, blocks of %zu bytes on %d threads: %s (whole: %s; streamed: %s)", path, block, threads,
                       why, wok ? "loaded" : werr, sok ? "loaded" : serr);
                CHECKF(!sok || blocks >= 2, "%s, blocks of %zu bytes: %zu blocks (not streamed?)", path, block, blocks);
            }
            if (sok) rp_scene_data_free(&s);
        }
    }
    CHECKF(bad == 0, "%s: streamed loads differ from the whole load", path);
    if (wok) rp_scene_data_free(&whole);
}

static const char nff_good[] =
    "# a streamed NFF file\n"
    "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 64 48\n"
    "b 0.1 0.2 0.3\nam 0.1 0.1 0.1\n"
    "l 1 2 3\n"
    "l 4 5 6\n0.5 0.25 0.125\n"                  /* the colour on the next line */
    "d 2\na 0 2 3\n"
    "p 3\n0 0 0\n1 0 0\n0 1 0\n"                 /* the default material */
    "f 1 0 0 0.5 0.5 10 0 1.5\n"
    "pp 3\n0 0 1 0 0 1\n1 0 1 0 0 1\n0 1 1 0 0 1\n"
    "p 4 # a quad\n0 0 2\n1 0 2\n1 1 2\n0 1 2\n"
    "f 0 1 0 0.5 0.5 10 0 0\r\n"                 /* CRLF */
    "p 3\r\n-1.5e-3 2 3\r\n4 5 6\r\n7 8 9.25\r\n"
    "p 13 0 0 3 1 0 3 2 0.5 3 2.5 1 3 3 2 3 2.5 3 3 2 3.5 3 1 4 3 0.5 3.5 3 -0.5 3 3 -1 2 3 -0.75 1 3 -0.25 "
    "0.5 3\n"                                    /* a polygon on a line longer than most blocks */
    "  p 3\n 0 0 4\n\t1 0 4\n 0 1 4\n"           /* indented */
    "s 0 0 0 1\n"
    "c 0 0 0 1 0 1 0 0.5\n"
    "p 6\n0 0 5\n2 0 5\n2 2 5\n1 1 5\n0 2 5\n-1 1 5\n" /* concave */
    "xs 1 1 1 0 0 1 30 0 0 1 {\n"
    "p 3\n0 0 0\n1 0 0\n0 1 0\n"
    "f 0 0 1 1 0 1 0 0\n"
    "x spin {\n"
    "s 1 1 1 0.5\n"
    "p 3\n0 0 1\n1 0 1\n0 1 1\n"
    "l 0 3 0\n"
    "}\n"
    "}\n"
    "k spin {\n"
    "transl 4\n0 0 0 0 0 0 0\n1 1 0 0 0 0 0\n2 2 0 0 0 0 0\n3 3 0 0 0 0 0\n"
    "}\n"
    "k spin {\n"                                 /* again: replaces the keys above */
    "transl 4\n0 0 0 0 0 0 0\n1 0 1 0 0 0 0\n2 0 2 0 0 0 0\n3 0 3 0 0 0 0\n"
    "rot 4\n0 0 1 0 0 0 0 0\n1 0 1 0 90 0 0 0\n2 0 1 0 180 0 0 0\n3 0 1 0 270 0 0 0\n"
    "visibility 2\n0 1\n1.5 0\n"
    "}\n"
    "m vertices 4\n0 0 6\n1 0 6\n1 1 6\n0 1 6\n"
    "normals 1\n0 0 1\n"
    "triangles 2\n0 1 2 0 0 0\n0 2 3 0 0 0\n"
    "tpa 2\n0  0 0 7 0 0 1  1 0 7 0 0 1  0 1 7 0 0 1\n1  0 0 8 0 0 1  1 0 8 0 0 1  0 1 8 0 0 1\n"
    "i 1 inc.nff\n"                              /* an include (read whole) */
    "i 3 nosuch.nff\n"                           /* more detail than `d 2`: skipped */
    "% percent comment\n"
    "f 0.3 0.3 0.3 1 0 1 0 0\n"
    "p 3\n1e1 2e-1 3\n4 5 6\n7 8 9\n"
    "pp 3\n0 0 1 0 0 1 1 0 1 0 0 1 0 1 1 0 0 1\n"
    "p 3\n0.1 0.2 0.3\n0.4 0.5 0.6\n0.7 0.8 0.9";  /* no newline at the end */

static void check_good(void) {
    char path[1024], inc[1024];
    static const char included[] = "s 5 5 5 1\np 3\n0 0 9\n1 0 9\n0 1 9\n";
    write_file(tmp_path("inc.nff", inc, sizeof inc), included, sizeof included - 1);
    write_gz(tmp_path("good.nff.gz", path, sizeof path), nff_good, 1);
    check_streamed(path, NULL);
    /* three gzip members, each ending mid-line: the same scene as one member */
    char multi[1024];
    write_gz(tmp_path("multi.nff.gz", multi, sizeof multi), nff_good, 3);
    check_streamed(multi, NULL);
    rp_scene_data a, b;
    char err[1024];
    io_load_opts whole = {.threads = 1, .stream = -1}, streamed = {.threads = 2, .stream = 1, .stream_block = 40};
    bool ok = io_load_file_opts(path, &whole, &a, err, sizeof err);
    CHECKF(ok, "%s", err);
    bool ok2 = io_load_file_opts(multi, &streamed, &b, err, sizeof err);
    CHECKF(ok2, "%s", err);
    char why[128] = "";
    if (ok && ok2) CHECKF(same_scene(&a, &b, why, sizeof why), "one member against three: %s", why);
    if (ok) {
        CHECK(a.triangle_count > 20 && a.light_count == 3 && a.sphere_count == 3 && a.animation != NULL);
        rp_scene_data_free(&a);
    }
    if (ok2) rp_scene_data_free(&b);
}

/* Errors in the last lines: the whole load's message (file:line) from the streamed one too. */
static void check_errors(void) {
    unsigned lines = 1;
    for (const char *c = nff_good; *c; c++) lines += *c == '\n';
    struct {
        const char *tail, *error;
        unsigned line; /* after nff_good's last line */
    } bad[] = {
        {"\np 3\n0 0 0\n1 0 0\n0 x 0\n", "p: expected a finite number, got 'x'", 4},
        {"\np 3\n0 0 0\n1 0 0\n", "unexpected end of file, expected p", 4},
        {"\np 3\r\n0 0 0\r\n1 0 0\r\n0 1 0\r\nfoo 1 2\r\n", "unknown command 'foo'", 5},
        {"\nxs 1 1 1 0 0 1 0 0 0 0 {\np 3\n0 0 0\n1 0 0\n0 1 0\n", "end of file inside the transform block opened at line", 6},
        {"\nl 1 2 3\n0.5 0.5\n", "unexpected end of file, expected l colour", 3},
        {"\np 99\n0 0 0\n1 0 0\n0 1 0\n", "unexpected end of file, expected polygon vertices", 1},
        {"\nm vertices 3\n0 0 0\n1 0 0\n0 1 0\ntriangles 1\n0 1 5\n", "mesh triangle 0: index out of range", 6},
        {"\nxs 1 1 1 0 0 1 0 0 0 0\n", "expected '{' after xs", 2},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        static char text[sizeof nff_good + 256];
        char path[1024], want[1400];
        snprintf(text, sizeof text, "%s%s", nff_good, bad[i].tail);
        tmp_path("bad.nff.gz", path, sizeof path);
        write_gz(path, text, 1);
        snprintf(want, sizeof want, "%s:%u: error: %s", path, lines + bad[i].line, bad[i].error);
        check_streamed(path, want);
    }
}

/* OBJ streamed likewise: every statement, CRLF, a face on a line longer than most blocks, a
 * material library; errors in the last lines. */
static const char obj_good[] =
    "# a streamed OBJ file\n"
    "mtllib a.mtl\n"
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0.5\n"
    "vn 0 0 1\nvn 0 0 -1\n"
    "f 1 2 3\n"
    "f 1/1 2/2 3/3 4/4\n"
    "usemtl red\n"
    "f 1//1 2//1 3//1\n"
    "f -4/-4/-2 -3/-3/-2 -2/-2/-2\n"
    "\n   \t\n"
    "g group\no object\ns 1\n"
    "v 2 0 0 1 0 0\r\nv 2 1 0\r\n"              /* a vertex colour (the ones before white) */
    "f -1 -2 1#comment\r\n"
    "usemtl nosuch\n"
    "f 1 2 -1\n"
    "usemtl blue\n"
    "v 0 2 0\nv 1 3 0 0.5 0.5 0.5\nv 2 2 0\nv 2 4 0 1 0.2 0.3 1\nv 0 4 0\n"
    "f -5 -4 -3 -2 -1\n"
    "f 1 2 3 4 5 6 7 8 9 10 11 1 2 3 4 5 6 7 8 9 10 11 1 2 3 4 5 6 7 8 9 10 11 1 2 3 4 5 6 7 8 9 10 11\n"
    "f 1/1/1 2/2 3/3/2\n"
    "usemtl red\n"
    "f 3 2 1";

static void check_obj(void) {
    char path[1024], mtl[1024];
    static const char lib[] = "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n";
    write_file(tmp_path("a.mtl", mtl, sizeof mtl), lib, sizeof lib - 1);
    write_gz(tmp_path("good.obj.gz", path, sizeof path), obj_good, 1);
    check_streamed(path, NULL);
    write_gz(tmp_path("multi.obj.gz", path, sizeof path), obj_good, 3);
    check_streamed(path, NULL);
    unsigned lines = 1;
    for (const char *c = obj_good; *c; c++) lines += *c == '\n';
    struct {
        const char *tail, *error;
        unsigned line;
    } bad[] = {
        {"\nf 1 2 99\n", "vertex index 99 out of range (11 defined so far)", 1},
        {"\nv 1 2 3\r\nvn 1 x 3\r\n", "vn: expected a finite number, got 'x'", 2},
        {"\nbogus 1", "unknown statement 'bogus'", 1},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        static char text[sizeof obj_good + 64];
        char want[1400];
        snprintf(text, sizeof text, "%s%s", obj_good, bad[i].tail);
        tmp_path("bad.obj.gz", path, sizeof path);
        write_gz(path, text, 1);
        snprintf(want, sizeof want, "%s:%u: error: %s", path, lines + bad[i].line, bad[i].error);
        check_streamed(path, want);
    }
}

/* A truncated and a corrupt gzip file: both loads fail with the same message, naming the file. */
static void check_broken_gzip(void) {
    char path[1024], cut[1024];
    static char text[64 << 10];
    size_t n = 0;
    while (n + sizeof nff_good + 1 < sizeof text) { /* large enough for several deflate blocks */
        memcpy(text + n, nff_good, sizeof nff_good - 1);
        n += sizeof nff_good - 1;
        text[n++] = '\n';
    }
    text[n] = '\0';
    write_gz(tmp_path("whole.nff.gz", path, sizeof path), text, 1);
    FILE *fp = fopen(path, "rb");
    CHECK(fp != NULL);
    if (!fp) return;
    static unsigned char gz[64 << 10];
    size_t size = fread(gz, 1, sizeof gz, fp);
    fclose(fp);
    CHECK(size > 200 && size < sizeof gz);
    write_file(tmp_path("truncated.nff.gz", cut, sizeof cut), gz, size * 2 / 3);
    char want[1100];
    snprintf(want, sizeof want, "%s:0: error: cannot open: corrupt or truncated gzip data", cut);
    check_streamed(cut, want);
    write_file(cut, gz, size - 3); /* the trailer cut */
    check_streamed(cut, want);
    for (size_t i = size / 2; i < size / 2 + 16; i++) gz[i] ^= 0x55;
    write_file(cut, gz, size);
    check_streamed(cut, want);
    /* more text than RP_MAX_FILE_BYTES allows: refused as the whole read refuses it */
    setenv("RP_MAX_FILE_BYTES", "1k", 1);
    snprintf(want, sizeof want, "%s:0: error: cannot open: more than 1024 bytes (decompressed)", path);
    check_streamed(path, want);
    unsetenv("RP_MAX_FILE_BYTES");
}

/* A shared scene: whole against streamed with the default blocks and with 4 kB blocks. */
static void check_shared(const char *name, bool small_blocks) {
    char path[1024], err[1024];
    if (!rp_test_scene(name, path, sizeof path)) {
        CHECKF(0, "missing scene %s", name);
        return;
    }
    rp_scene_data whole;
    io_load_opts w = {.threads = 1, .stream = -1};
    bool ok = io_load_file_opts(path, &w, &whole, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    if (!ok) return;
    const io_load_opts runs[3] = {{.threads = 2}, {.threads = 1, .stream = 1}, {.threads = 2, .stream = 1, .stream_block = 4096}};
    for (int r = small_blocks ? 1 : 0; r < (small_blocks ? 3 : 1); r++) {
        size_t blocks = 0;
        io_load_opts o = runs[r];
        o.blocks = &blocks;
        rp_scene_data s;
        ok = io_load_file_opts(path, &o, &s, err, sizeof err);
        CHECKF(ok, "%s (block %zu): %s", name, o.stream_block, err);
        if (!ok) continue;
        char why[128] = "";
        CHECKF(same_scene(&whole, &s, why, sizeof why), "%s (threads %d, block %zu): %s", name, o.threads, o.stream_block, why);
        CHECKF(blocks >= (r == 0 ? 2u : 1u), "%s: %zu blocks (not streamed?)", name, blocks);
        printf("%-24s threads %d, blocks of %7zu bytes (0: chosen): %5zu blocks, %zu triangles: streamed = whole\n", name, o.threads,
               o.stream_block, blocks, s.triangle_count);
        rp_scene_data_free(&s);
    }
    rp_scene_data_free(&whole);
}

int main(void) {
    const char *t = getenv("RP_TEST_TMP");
    snprintf(tmp_dir, sizeof tmp_dir, "%s", t ? t : "/tmp/rp_test_io_stream");
    mkdir(tmp_dir, 0755);
    check_good();
    check_errors();
    check_obj();
    check_broken_gzip();
    check_shared("spd_teapot.nff.gz", true);
    check_shared("dabrovic_sponza.obj.gz", true);
    if (!rp_test_sanitized()) check_shared("spd_rings_s5.nff.gz", false); /* 36 MB of text: several default blocks */
    return RP_TEST_END();
}
