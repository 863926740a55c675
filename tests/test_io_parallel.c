// rp-test: labels=io timeout=900
/* The chunked parallel parsers give the serial result: every shared scene loaded on one thread,
 * on four threads with the chunks a load picks, and with chunks of a few kB (boundaries in every
 * command), compared array by array and bit for bit; synthetic OBJ, NFF and PLY files loaded with
 * chunks of 1 to 97 bytes, so that a boundary falls on every byte (a line cut by a chunk, negative
 * indices, CRLF, comments, material state, errors in the last chunk), results and error messages
 * equal to the serial ones; ASCII PLY likewise (blank lines, CRLF, extra properties, a record over
 * two lines, errors in the last chunk on the serial line). Under ASan only the scenes under 20 MB of
 * text. */
#include <math.h>
#include <stdint.h>

#include "io/io_internal.h"
#include "raypack_io.h"
#include "rp_test.h"
#include "scene_same.h"

/* ---- the shared scenes ------------------------------------------------------------------------ */

static const char *const scenes[] = {
    "cornell_box/cornell_box.obj", "cornell_original/CornellBox-Original.obj", "spd_teapot.nff.gz",
    "stanford_bunny_bun_zipper.ply.gz", "dabrovic_sponza.obj.gz", "bart_kitchen.tar.gz", "bart_museum5.tar.gz",
    "spd_rings_s5.nff.gz", "conference_geom.obj.gz", "spd_tree_s12.nff.gz", "pointcloud/open3d_sinc_grid.ply",
};

static void check_scene(const char *name) {
    char path[1024], err[1024];
    if (!rp_test_scene(name, path, sizeof path)) {
        CHECKF(0, "missing scene %s", name);
        return;
    }
    rp_scene_data serial;
    io_load_opts one = {.threads = 1};
    bool ok = io_load_file_opts(path, &one, &serial, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    if (!ok) return;
    if (rp_test_sanitized() && serial.file_bytes > (20u << 20)) {
        rp_scene_data_free(&serial);
        return;
    }
    /* the chunks a load picks on 4 threads, and chunks of 4 kB (some 45000 on the tree) */
    size_t taken = 0;
    const io_load_opts runs[2] = {{.threads = 4}, {.threads = 3, .chunk_bytes = 4096, .chunks_taken = &taken}};
    for (int r = 0; r < 2; r++) {
        rp_scene_data par;
        ok = io_load_file_opts(path, &runs[r], &par, err, sizeof err);
        CHECKF(ok, "%s (threads %d, chunks %zu): %s", name, runs[r].threads, runs[r].chunk_bytes, err);
        if (!ok) continue;
        char why[128] = "";
        CHECKF(same_scene(&serial, &par, why, sizeof why), "%s (threads %d, chunks %zu): %s", name, runs[r].threads,
               runs[r].chunk_bytes, why);
        rp_scene_data_free(&par);
    }
    /* the chunked parsers did run: every text format but a few-kB file has chunks taken */
    bool text = strstr(name, ".nff") || (strstr(name, ".obj") && serial.file_bytes > 8192) ||
                strstr(name, "bun_zipper.ply");
    CHECKF(!text || taken > 0, "%s: no chunk was parsed in parallel", name);
    printf("%-42s %8zu triangles, %6zu chunks taken: serial = parallel\n", name, serial.triangle_count, taken);
    rp_scene_data_free(&serial);
}

/* ---- synthetic files, chunk boundaries on every byte --------------------------------------------- */

/* Loads text as `name` serially and with chunks of 1..97 bytes (on 1 and 3 threads); every load
 * must give the serial result, or the serial error message. Returns the serial message ("" when it
 * loaded). */
static void check_files(const io_entry *e, size_t files, const char *want_error, bool chunks_used) {
    const char *name = e[0].name;
    rp_scene_data serial;
    char serr[512] = "";
    io_load_opts one = {.threads = 1};
    bool sok = io_load_memory_opts(e, files, false, &one, &serial, serr, sizeof serr);
    if (want_error) {
        CHECKF(!sok && strstr(serr, want_error) != NULL, "%s: serial load: want an error with '%s', got '%s'", name,
               want_error, sok ? "(loaded)" : serr);
    } else {
        CHECKF(sok, "%s: serial load failed: %s", name, serr);
    }
    int bad = 0;
    size_t taken = 0, taken_all = 0;
    for (size_t chunk = 1; chunk <= 97 && bad < 3; chunk += chunk < 16 ? 1 : 9) {
        for (int threads = 1; threads <= 3; threads += 2) {
            io_load_opts o = {.threads = threads, .chunk_bytes = chunk, .chunks_taken = &taken};
            rp_scene_data par;
            char perr[512] = "";
            bool pok = io_load_memory_opts(e, files, false, &o, &par, perr, sizeof perr);
            char why[128] = "";
            bool same = pok == sok && (sok ? same_scene(&serial, &par, why, sizeof why) : strcmp(serr, perr) == 0);
            if (!same) {
                bad++;
                CHECKF(same, "%s, chunks of %zu bytes on %d threads: %s (serial: %s; chunked: %s)", name, chunk, threads,
                       why, sok ? "loaded" : serr, pok ? "loaded" : perr);
            }
            if (pok) rp_scene_data_free(&par);
            taken_all += taken;
        }
    }
    CHECKF(bad == 0, "%s: chunked loads differ", name);
    CHECKF(!chunks_used || taken_all > 0, "%s: no chunk was parsed in parallel", name);
    if (sok) rp_scene_data_free(&serial);
}

static void check_text(const char *name, const char *text, const char *want_error) {
    io_entry e = {.name = (char *)name, .data = (char *)text, .size = strlen(text)};
    check_files(&e, 1, want_error, true);
}

/* The same for a file the chunks leave whole to the serial reader (PLY with an error, or a record
 * over two lines). */
static void check_text_serial(const char *name, const char *text, const char *want_error) {
    io_entry e = {.name = (char *)name, .data = (char *)text, .size = strlen(text)};
    check_files(&e, 1, want_error, false);
}

/* A shared scene's files as memory entries (the OBJ and its MTL), chunked on every byte. */
static void check_shared_text(const char *obj, const char *mtl) {
    const char *names[2] = {obj, mtl};
    io_entry e[2];
    char *bufs[2] = {NULL, NULL};
    size_t n = 0;
    for (int i = 0; i < 2 && names[i]; i++) {
        char path[1024];
        if (!rp_test_scene(names[i], path, sizeof path)) {
            CHECKF(0, "missing scene %s", names[i]);
            return;
        }
        FILE *fp = fopen(path, "rb");
        fseek(fp, 0, SEEK_END);
        long size = ftell(fp);
        rewind(fp);
        bufs[i] = calloc((size_t)size + 1, 1);
        size_t got = fread(bufs[i], 1, (size_t)size, fp);
        fclose(fp);
        const char *slash = strrchr(names[i], '/');
        e[n++] = (io_entry){.name = (char *)(slash ? slash + 1 : names[i]), .data = bufs[i], .size = got};
    }
    check_files(e, n, NULL, true);
    free(bufs[0]);
    free(bufs[1]);
}

static const char obj_good[] =
    "# vertices, texture coordinates and normals in every form\n"
    "mtllib a.mtl\n"
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0.5\n"
    "vn 0 0 1\nvn 0 0 -1\n"
    "f 1 2 3\n"
    "f 1/1 2/2 3/3 4/4\n"                 /* a quad, with texture coordinates */
    "usemtl red\n"
    "f 1//1 2//1 3//1\n"
    "f -4/-4/-2 -3/-3/-2 -2/-2/-2\n"      /* negative indices */
    "\n   \t\n"
    "g group\no object\ns 1\n"
    "v 2 0 0\r\nv 2 1 0\r\n"             /* CRLF */
    "f -1 -2 1#comment\r\n"
    "usemtl nosuch\n"                      /* unknown: the default material */
    "f 1 2 -1\n"
    "usemtl blue\n"
    "v 0 2 0\nv 1 3 0\nv 2 2 0\nv 2 4 0\nv 0 4 0\n"
    "f -5 -4 -3 -2 -1\n"                  /* a pentagon, concave: ear clipping */
    "f 5 6 7 8 9 10 11\n"
    "f 1/1/1 2/2 3/3/2\n"                 /* mixed corners: the serial pass */
    "f 1 2 3 4 5 6 7 8 9 10 11 1 2 3 4 5 6 7 8 9 10 11 1 2 3 4 5 6 7 8 9 10 11 1 2 3 4 5 6 7 8 9 10 11 "
    "1 2 3 4 5 6 7 8 9 10 11 1 2 3 4 5 6 7 8 9 10 11 1 2 3\n" /* 69 corners */
    "mtllib b.mtl\n"                      /* a library in the middle */
    "usemtl green\n"
    "vt 0.25 0.75\n"
    "f 1/-1 2/-1 3/-1\n"
    "usemtl red\n"
    "f 3 2 1\n";

static void check_obj(void) {
    static const char mtl_a[] = "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n";
    static const char mtl_b[] = "newmtl green\nKd 0 1 0\n";
    io_entry e[3] = {{.name = "good.obj", .data = (char *)obj_good, .size = sizeof obj_good - 1},
                     {.name = "a.mtl", .data = (char *)mtl_a, .size = sizeof mtl_a - 1},
                     {.name = "b.mtl", .data = (char *)mtl_b, .size = sizeof mtl_b - 1}};
    check_files(e, 3, NULL, true);
    unsigned lines = 0;
    for (const char *c = obj_good; *c; c++) lines += *c == '\n';
    struct {
        const char *tail, *error;
        unsigned line; /* after obj_good */
    } bad[] = {
        {"f 1 2 99\n", "vertex index 99 out of range (11 defined so far)", 1},
        {"v 1 2 3\nf 1 2 -18\n", "vertex index -18 out of range (12 defined so far)", 2},
        {"f 1/9 2/1 3/1\n", "texture coordinate index 9 out of range", 1},
        {"f 1//3 2//1 3//1\n", "normal index 3 out of range", 1},
        {"f 0 1 2\n", "vertex index 0 is invalid", 1},
        {"v 1 2\n", "v: expected a finite number", 1},
        {"v 1 2 3\nvn 1 x 3\n", "vn: expected a finite number, got 'x'", 2},
        {"f 1 2\n", "face with 2 vertices", 1},
        {"bogus 1\n", "unknown statement 'bogus'", 1},
        {"f 1 2 3/\n", "bad texture coordinate index", 1},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        static char text[8192];
        char want[256];
        snprintf(text, sizeof text, "%s%s", obj_good, bad[i].tail);
        snprintf(want, sizeof want, "bad.obj:%u: error: %s", lines + bad[i].line, bad[i].error);
        e[0] = (io_entry){.name = "bad.obj", .data = text, .size = strlen(text)};
        check_files(e, 3, want, true);
    }
    check_shared_text("cornell_box/cornell_box.obj", "cornell_box/cornell_box.mtl");
    check_shared_text("cornell_original/CornellBox-Original.obj", "cornell_original/CornellBox-Original.mtl");
}

static const char nff_good[] =
    "# comment line\n"
    "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 64 48\n"
    "b 0.1 0.2 0.3\nl 1 2 3\n"
    "p 3\n0 0 0\n1 0 0\n0 1 0\n"                 /* the default material */
    "f 1 0 0 0.5 0.5 10 0 1.5\n"
    "pp 3\n0 0 1 0 0 1\n1 0 1 0 0 1\n0 1 1 0 0 1\n"
    "p 4 # a quad\n0 0 2\n1 0 2\n1 1 2\n0 1 2\n"
    "f 0 1 0 0.5 0.5 10 0 0\r\n"                 /* CRLF */
    "p 3\r\n-1.5e-3 2 3\r\n4 5 6\r\n7 8 9.25\r\n"
    "p 3 0 0 3 1 0 3 0 1 3\n"                    /* a polygon on one line */
    "  p 3\n 0 0 4\n\t1 0 4\n 0 1 4\n"           /* indented */
    "s 0 0 0 1\n"                                /* a sphere between polygon lists */
    "p 6\n0 0 5\n2 0 5\n2 2 5\n1 1 5\n0 2 5\n-1 1 5\n" /* concave */
    "xs 1 1 1 0 0 1 0 0 0 1 {\n"                 /* a transform block: parsed serially */
    "p 3\n0 0 0\n1 0 0\n0 1 0\n"
    "f 0 0 1 1 0 1 0 0\n"
    "}\n"
    "% percent comment\n"
    "f 0.3 0.3 0.3 1 0 1 0 0\n"
    "p 3\n1e1 2e-1 3\n4 5 6\n7 8 9\n"
    "pp 3\n0 0 1 0 0 1 1 0 1 0 0 1 0 1 1 0 0 1\n"
    "c 0 0 0 1 0 1 0 0.5\n"
    "p 3\n0.1 0.2 0.3\n0.4 0.5 0.6\n0.7 0.8 0.9\n";

static void check_nff(void) {
    check_text("good.nff", nff_good, NULL);
    /* errors: in the last chunk, on the right line, with the serial message */
    unsigned lines = 0;
    for (const char *c = nff_good; *c; c++) lines += *c == '\n';
    char text[4096], want[128];
    snprintf(text, sizeof text, "%sp 3\n0 0 0\n1 0 0\n0 x 0\n", nff_good);
    snprintf(want, sizeof want, "bad_float.nff:%u: error: p: expected a finite number, got 'x'", lines + 4);
    check_text("bad_float.nff", text, want);
    snprintf(text, sizeof text, "%sp 3\n0 0 0\n1 0 0\n", nff_good); /* truncated in the last polygon */
    snprintf(want, sizeof want, "truncated.nff:%u: error: unexpected end of file", lines + 4);
    check_text("truncated.nff", text, want);
    snprintf(text, sizeof text, "%sp 2\n0 0 0\n1 0 0\n", nff_good);
    snprintf(want, sizeof want, "two.nff:%u: error: p: polygon with 2 vertices", lines + 1);
    check_text("two.nff", text, want);
    snprintf(text, sizeof text, "p 3\n0 0 0\n1 0 0\n0 1 0\nfoo 1 2\n%s", nff_good);
    check_text("unknown.nff", text, "unknown.nff:5: error: unknown command 'foo'");
    /* a chunk start that is not a command: `f` as the texture name of a tt */
    check_text("fname.nff", "p 3\n0 0 0\n1 0 0\n0 1 0\ntt\nf 0 0 0\n1 0 0\n0 1 0\np 3\n0 0 0\n1 0 0\n0 1 0\n",
               "fname.nff:6: error: cannot open texture 'f'");
}

/* ASCII PLY: a header with comments, extra properties on both elements, a quad and a concave
 * pentagon (ear clipping in the fill), blank lines, CRLF, indented and tab-separated records. */
static const char ply_head[] =
    "ply\r\nformat ascii 1.0\ncomment made by hand\n"
    "element vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
    "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\n"
    "element face %u\nproperty uchar flags\nproperty list uchar int vertex_indices\n"
    "property list uchar float weights\nend_header\n";
static const char ply_body[] =
    "0 0 0 0 0 1 255\n1 0 0 0 0 1 0\n1 1 0 0 0 1 7\n"
    "0 1 0 0 0 1 9\r\n"
    "\n   \t\n"
    "  2 0 0 0 0 1 1\n\t3 1e0 0 0 0 1 2\n2.5 0.5 0 0 0 1 3\n"
    "-1.5e-3 0.25 0.125 0 0.6 0.8 4\n"
    "0 3 0 1 2 0\n"
    "1 4 0 1 2 3 2 0.5 0.5\r\n"
    "\n"
    "2 5 4 5 6 3 7 1 1.0\n"
    "0 3 7 6 5 0";

static void check_ply(void) {
    char text[4096], want[256];
    unsigned head_lines = 0;
    for (const char *c = ply_head; *c; c++) head_lines += *c == '\n';
    snprintf(text, sizeof text, ply_head, 4u);
    size_t n = strlen(text);
    snprintf(text + n, sizeof text - n, "%s", ply_body);
    check_text("good.ply", text, NULL);
    /* a line after the chunks' layout: a record over two lines (the serial reader's, and the same) */
    snprintf(text, sizeof text, ply_head, 4u);
    n = strlen(text);
    snprintf(text + n, sizeof text - n, "%s\n", ply_body);
    char *split = strstr(text + n, "2 5 4 5 6 3");
    split[5] = '\n';
    check_text_serial("split.ply", text, NULL);
    /* errors in the second half, on the serial reader's line */
    struct {
        const char *from, *to, *error;
        unsigned line; /* of the body */
    } bad[] = {
        {"0 3 7 6 5 0", "0 3 7 6 x 0", "expected an integer, got 'x'", 15},
        {"0 3 7 6 5 0", "0 3 7 6 8 0", "face 3: vertex index 8 out of range (8 vertices)", 15},
        {"0 3 7 6 5 0", "0 2 7 6", "face 3 has 2 vertices (at least 3 needed)", 15},
        {"2.5 0.5 0 0 0 1 3", "2.5 0.5 0 0 0 1 3 4", "expected an integer, got '0.8'", 10},
        {"0 3 7 6 5 0", "0 3 7 6 5 0\n1", "data after the last element", 16},
        {"0 3 7 6 5 0", "", "unexpected end of file", 15},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(text, sizeof text, ply_head, 4u);
        n = strlen(text);
        snprintf(text + n, sizeof text - n, "%s", ply_body);
        char *at = strstr(text + n, bad[i].from), tail[1024];
        snprintf(tail, sizeof tail, "%s", at + strlen(bad[i].from));
        snprintf(at, sizeof text - (size_t)(at - text), "%s%s", bad[i].to, tail);
        snprintf(want, sizeof want, "bad.ply:%u: error: %s", head_lines + bad[i].line, bad[i].error);
        check_text_serial("bad.ply", text, want);
    }
}

int main(void) {
    for (size_t i = 0; i < sizeof scenes / sizeof scenes[0]; i++) check_scene(scenes[i]);
    check_nff();
    check_obj();
    check_ply();
    return RP_TEST_END();
}
