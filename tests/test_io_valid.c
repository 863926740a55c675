// rp-test: labels=io timeout=300
/* Valid but unusual scene files: what the formats' specs and other tools' common practice allow
 * (tinyobjloader, Blender's and 3ds Max's exporters), loaded as they mean. Each case is also
 * loaded in chunks of a few bytes on 1 and 3 threads (the parallel parsers), which must give the
 * serial result and the same warnings. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/stat.h>

#include "io/io_internal.h"
#include "raypack_io.h"
#include "rp_test.h"
#include "scene_same.h"

static char tmp_dir[512];

static const char *tmp_path(const char *name, char *buf, size_t size) {
    snprintf(buf, size, "%s/%s", tmp_dir, name);
    return buf;
}

static void write_bytes(const char *name, const void *data, size_t n) {
    char path[1024];
    tmp_path(name, path, sizeof path);
    /* a name with a folder: make the folder */
    char *slash = strrchr(path, '/');
    if (slash && slash > path + strlen(tmp_dir)) {
        *slash = '\0';
        mkdir(path, 0755);
        *slash = '/';
    }
    FILE *f = fopen(path, "wb");
    if (!f) {
        fprintf(stderr, "cannot write %s\n", path);
        exit(1);
    }
    fwrite(data, 1, n, f);
    fclose(f);
}

static void write_text(const char *name, const char *text) { write_bytes(name, text, strlen(text)); }

/* Warnings of one load, one a line. */
typedef struct warnings {
    char text[4096];
    int count;
} warnings;

static void collect(void *user, const char *message) {
    warnings *w = user;
    size_t n = strlen(w->text);
    snprintf(w->text + n, sizeof w->text - n, "%s\n", message);
    w->count++;
}

/* Loads name serially (warnings into w), then in chunks of 1 to 13 bytes on 1 and 3 threads:
 * those must give the same scene and the same warnings. */
static bool load(const char *name, rp_scene_data *s, warnings *w) {
    char path[1024], err[1024] = "";
    tmp_path(name, path, sizeof path);
    memset(w, 0, sizeof *w);
    io_load_opts serial = {.threads = 1, .warning = collect, .warning_user = w};
    bool ok = io_load_file_opts(path, &serial, s, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    if (!ok) return false;
    for (int threads = 1; threads <= 3; threads += 2)
        for (size_t chunk = 1; chunk <= 13; chunk += 4) {
            warnings w2;
            memset(&w2, 0, sizeof w2);
            io_load_opts par = {.threads = threads, .chunk_bytes = chunk, .warning = collect, .warning_user = &w2};
            rp_scene_data p;
            char err2[1024] = "";
            bool ok2 = io_load_file_opts(path, &par, &p, err2, sizeof err2);
            CHECKF(ok2, "%s in chunks of %zu: %s", name, chunk, err2);
            if (!ok2) continue;
            char why[256] = "";
            CHECKF(same_scene(s, &p, why, sizeof why), "%s in chunks of %zu on %d threads: %s", name, chunk, threads, why);
            CHECKF(strcmp(w->text, w2.text) == 0, "%s in chunks of %zu: warnings\n%s differ from the serial\n%s", name,
                   chunk, w2.text, w->text);
            rp_scene_data_free(&p);
        }
    return true;
}

static const rp_material_data *tri_material(const rp_scene_data *s, size_t tri) {
    return &s->materials[s->tri_materials[tri]];
}

/* ---- OBJ: usemtl ------------------------------------------------------------------------------ */

/* A usemtl naming a material that no library defines: the default material, and a warning naming
 * the file and line (tinyobjloader warns too); the scene still loads. */
static void test_usemtl_unknown(void) {
    write_text("um.mtl", "newmtl red\nKd 0.8 0.1 0.1\n");
    write_text("um.obj",
               "mtllib um.mtl\n"
               "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
               "usemtl red\n"
               "f 1 2 3\n"
               "usemtl nosuch\n"
               "f 1 3 4\n"
               "usemtl red\n"
               "f 1 2 4\n"
               "usemtl Red\n"
               "f 2 3 4\n");
    rp_scene_data s;
    warnings w;
    if (!load("um.obj", &s, &w)) return;
    CHECK(s.triangle_count == 4);
    CHECK(strcmp(tri_material(&s, 0)->name, "red") == 0 && strcmp(tri_material(&s, 2)->name, "red") == 0);
    CHECK(strcmp(tri_material(&s, 1)->name, "default") == 0 && strcmp(tri_material(&s, 3)->name, "default") == 0);
    CHECKF(w.count == 2, "%d warnings:\n%s", w.count, w.text);
    CHECKF(strstr(w.text, "um.obj:8: warning: usemtl 'nosuch'") != NULL, "%s", w.text);
    CHECKF(strstr(w.text, "um.obj:12: warning: usemtl 'Red'") != NULL, "%s", w.text); /* names are case sensitive */
    rp_scene_data_free(&s);

    /* Many of them: RP_LOAD_MAX_WARNINGS, then one line with the count of the rest. */
    char text[8192] = "v 0 0 0\nv 1 0 0\nv 1 1 0\n";
    for (int i = 0; i < RP_LOAD_MAX_WARNINGS + 5; i++)
        snprintf(text + strlen(text), sizeof text - strlen(text), "usemtl m%d\nf 1 2 3\n", i);
    write_text("um_many.obj", text);
    if (!load("um_many.obj", &s, &w)) return;
    CHECKF(w.count == RP_LOAD_MAX_WARNINGS + 1, "%d warnings", w.count);
    CHECKF(strstr(w.text, "warning: 5 more warnings not shown") != NULL, "%s", w.text);
    rp_scene_data_free(&s);

    /* Without a callback the load is silent and the same. */
    char path[1024], err[256];
    CHECK(rp_scene_data_load(tmp_path("um.obj", path, sizeof path), &s, err, sizeof err));
    rp_scene_data_free(&s);
}

/* ---- OBJ: names of materials and libraries ---------------------------------------------------- */

static void test_obj_names(void) {
    /* A comment after a name (tinyobjloader reads one word and so drops it; here the whole name is
     * looked for first, then without the comment, on either side), a name with blanks, a
     * library whose name has a blank (Blender writes the file's name as it is), a library in a
     * subfolder written with Windows' backslash, and a UTF-8 byte order mark before the first line
     * of the OBJ and of the MTL file. */
    write_text("nm.mtl", "\xEF\xBB\xBFnewmtl red   # walls\nKd 0.8 0.1 0.1\nnewmtl green paint\nKd 0.1 0.8 0.1\n"
                         "newmtl Material #25\nKd 0.25 0 0\nnewmtl Material #26\nKd 0.26 0 0\n");
    write_text("my lib.mtl", "newmtl blue\nKd 0.1 0.1 0.8\n");
    write_text("sub/nm2.mtl", "newmtl grey\nKd 0.5 0.5 0.5\n");
    write_text("nm.obj",
               "\xEF\xBB\xBFmtllib nm.mtl\n"
               "mtllib my lib.mtl\n"
               "mtllib sub\\nm2.mtl   # a comment\n"
               "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
               "usemtl red # the walls\n"
               "f 1 2 3\n"
               "usemtl green paint\n"
               "f 1 3 4\n"
               "usemtl blue\t\n"
               "f 1 2 4\n"
               "usemtl grey\n"
               "f 2 3 4\n"
               "usemtl Material #26\n" /* 3ds Max's names hold " #": the whole name first */
               "f 1 2 3\n"
               "usemtl Material #25 # a comment\n"
               "f 1 2 3\n");
    rp_scene_data s;
    warnings w;
    if (!load("nm.obj", &s, &w)) return;
    CHECKF(w.count == 0, "%s", w.text);
    CHECK(s.triangle_count == 6 && s.material_count == 6);
    if (s.triangle_count == 6) {
        CHECKF(strcmp(tri_material(&s, 0)->name, "red   # walls") == 0, "'%s'", tri_material(&s, 0)->name);
        CHECKF(tri_material(&s, 4)->kd[0] == 0.26f, "Material #26: kd %g", (double)tri_material(&s, 4)->kd[0]);
        CHECKF(tri_material(&s, 5)->kd[0] == 0.25f, "Material #25: kd %g", (double)tri_material(&s, 5)->kd[0]);
        CHECKF(strcmp(tri_material(&s, 1)->name, "green paint") == 0, "'%s'", tri_material(&s, 1)->name);
        CHECKF(strcmp(tri_material(&s, 2)->name, "blue") == 0, "'%s'", tri_material(&s, 2)->name);
        CHECKF(strcmp(tri_material(&s, 3)->name, "grey") == 0, "'%s'", tri_material(&s, 3)->name);
    }
    rp_scene_data_free(&s);

    /* Several libraries on one line still work, and one missing is an error naming it. */
    write_text("nm3.obj", "mtllib nm.mtl my_missing.mtl\nv 0 0 0\n");
    char path[1024], err[1024] = "";
    bool ok = rp_scene_data_load(tmp_path("nm3.obj", path, sizeof path), &s, err, sizeof err);
    CHECKF(!ok && strstr(err, "nm3.obj:1: error: cannot open material library 'my_missing.mtl'"), "%s", err);
    if (ok) rp_scene_data_free(&s);
}

/* ---- OBJ: statements over several lines ------------------------------------------------------- */

/* The OBJ spec's line continuation: a backslash ending a line joins the next one to it (Blender's
 * importer does the same); a comment is not continued. An error names the statement's first line. */
static void test_obj_continued(void) {
    write_text("cont.obj",
               "# a comment ending in a backslash \\\n"
               "v 0 0 0\n"
               "v 1 0 \\\n"
               "  0\n"
               "v 1 1 0\r\n"
               "v 0 1 0 \\\r\n"
               "   0.5 0.5 0.5\r\n"
               "f 1 2 \\\n"
               "  3 \\\n"
               "  4\n"
               "l 1 2 \\\n"
               "  3\n"
               "vt 0.5 \\\n"
               "  0.25\n"
               "f 1/1 2/1 3/1\n");
    rp_scene_data s;
    warnings w;
    if (!load("cont.obj", &s, &w)) return;
    CHECKF(s.vertex_count == 4 && s.triangle_count == 3, "%zu vertices %zu triangles", s.vertex_count, s.triangle_count);
    if (s.vertex_count == 4) CHECK(s.positions[3] == 1.0f && s.positions[4] == 0.0f && s.positions[5] == 0.0f);
    if (s.triangle_count == 3) {
        static const uint32_t want[9] = {0, 1, 2, 0, 2, 3, 0, 1, 2};
        CHECK(memcmp(s.indices, want, sizeof want) == 0);
    }
    if (s.triangle_count == 3 && s.texcoord_indices) {
        const float *uv = s.texcoords + 2 * s.texcoord_indices[6];
        CHECK(uv[0] == 0.5f && uv[1] == 0.25f);
    }
    rp_scene_data_free(&s);

    /* a line of a backslash alone continues into the next statement */
    write_text("cont_lone.obj", "v 0 0 0\n  \\\nv 1 0 0\nv 1 1 0\nf 1 2 3\n");
    if (load("cont_lone.obj", &s, &w)) {
        CHECKF(s.vertex_count == 3 && s.triangle_count == 1, "%zu vertices", s.vertex_count);
        rp_scene_data_free(&s);
    }

    write_text("cont_bad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 \\\n 3 x\nv 0 0 0\n");
    char path[1024];
    tmp_path("cont_bad.obj", path, sizeof path);
    for (size_t chunk = 0; chunk <= 9; chunk += 3) {
        char err[1024] = "";
        io_load_opts o = {.threads = chunk ? 3 : 1, .chunk_bytes = chunk};
        bool ok = io_load_file_opts(path, &o, &s, err, sizeof err);
        CHECKF(!ok && strstr(err, "cont_bad.obj:4: error: bad face vertex 'x'"), "chunks of %zu: %s", chunk, err);
        if (ok) rp_scene_data_free(&s);
    }
}

/* ---- MTL: values -------------------------------------------------------------------------------- */

/* MTL keywords in any case (some exporters write "KD", "Map_Kd", "NEWMTL"; Blender's importer
 * lowers them): the same materials as the usual spelling, quietly. */
static void test_mtl_case(void) {
    write_text("mc.ppm", "P3\n1 1\n255\n10 20 30\n");
    const char *lower = "newmtl a\nKd 0.5 0.25 0.125\nKs 0.1 0.2 0.3\nNs 20\nNi 1.4\nd 0.5\nillum 4\nmap_Kd mc.ppm\n"
                        "newmtl b\nKe 1 2 3\nTr 0.25\nTf 1 0.5 1\nmap_d -clamp on mc.ppm\nmap_Ks mc.ppm\n";
    const char *upper = "NEWMTL a\nKD 0.5 0.25 0.125\nks 0.1 0.2 0.3\nNS 20\nni 1.4\nD 0.5\nILLUM 4\nMap_Kd mc.ppm\n"
                        "NewMtl b\nKE 1 2 3\nTR 0.25\ntf 1 0.5 1\nMAP_D -clamp on mc.ppm\nmap_ks mc.ppm\n";
    const char *obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\nusemtl b\nf 1/1 2/1 3/1\n";
    char text[1024];
    write_text("mc_lower.mtl", lower);
    write_text("mc_upper.mtl", upper);
    snprintf(text, sizeof text, "mtllib mc_lower.mtl\n%s", obj);
    write_text("mc_lower.obj", text);
    snprintf(text, sizeof text, "mtllib mc_upper.mtl\n%s", obj);
    write_text("mc_upper.obj", text);
    rp_scene_data a, b;
    warnings wa, wb;
    if (!load("mc_lower.obj", &a, &wa)) return;
    if (load("mc_upper.obj", &b, &wb)) {
        char why[256] = "";
        CHECKF(same_scene(&a, &b, why, sizeof why), "MTL keywords in upper case: %s", why);
        CHECKF(wb.count == 0, "%s", wb.text);
        CHECK(a.triangle_count == 2 && tri_material(&a, 0)->kd[1] == 0.25f && tri_material(&a, 1)->map_alpha != 0);
        rp_scene_data_free(&b);
    }
    rp_scene_data_free(&a);
}

static void test_mtl_values(void) {
    write_text("mv.mtl",
               "newmtl d_tr\nKd 1 1 1\nd 1\nTr 1\n"      /* 3ds Max: both, d counts: opaque */
               "newmtl tr_d\nKd 1 1 1\nTr 1\nd 1\n"      /* the other order */
               "newmtl tr\nKd 1 1 1\nTr 0.25\n"          /* Tr alone: 1 - d */
               "newmtl halo\nKd 1 1 1\nd -halo 0.5\n"    /* the spec's halo form */
               "newmtl xyz\nKd xyz 0.95047 1 1.08883\n"  /* CIE XYZ of D65 white: sRGB white */
               "newmtl spec\nKd 0.5 0.5 0.5\nKs spectral steel.rfl 0.8\n");
    write_text("mv.obj",
               "mtllib mv.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\n"
               "usemtl d_tr\nf 1 2 3\nusemtl tr_d\nf 1 2 3\nusemtl tr\nf 1 2 3\n"
               "usemtl halo\nf 1 2 3\nusemtl xyz\nf 1 2 3\nusemtl spec\nf 1 2 3\n");
    rp_scene_data s;
    warnings w;
    if (!load("mv.obj", &s, &w)) return;
    CHECK(s.triangle_count == 6);
    if (s.triangle_count == 6) {
        CHECKF(tri_material(&s, 0)->kt[0] == 0.0f, "d 1, Tr 1: kt %g", (double)tri_material(&s, 0)->kt[0]);
        CHECKF(tri_material(&s, 1)->kt[0] == 0.0f, "Tr 1, d 1: kt %g", (double)tri_material(&s, 1)->kt[0]);
        CHECKF(tri_material(&s, 2)->kt[0] == 0.25f, "Tr 0.25: kt %g", (double)tri_material(&s, 2)->kt[0]);
        CHECKF(tri_material(&s, 3)->kt[0] == 0.5f, "d -halo 0.5: kt %g", (double)tri_material(&s, 3)->kt[0]);
        const float *kd = tri_material(&s, 4)->kd;
        CHECKF(fabsf(kd[0] - 1.0f) < 1e-3f && fabsf(kd[1] - 1.0f) < 1e-3f && fabsf(kd[2] - 1.0f) < 1e-3f,
               "Kd xyz of D65: %g %g %g", (double)kd[0], (double)kd[1], (double)kd[2]);
        const rp_material_data *sp = tri_material(&s, 5);
        CHECK(sp->kd[0] == 0.5f && sp->ks[0] == 0.0f);
    }
    CHECKF(w.count == 1 && strstr(w.text, "mv.mtl:19: warning: Ks spectral"), "%s", w.text);
    rp_scene_data_free(&s);
}

/* Texture map options: skipped before the file name; -s and -o (u and v) are the material's uv
 * transform, quietly; -clamp on and -mm are applied (a texture entry of its own: clamped, its
 * texels remapped), quietly; turbulence is not applied and says so; defaults and the rest are
 * quiet. A comment after the file name is not part of it. */
static void test_mtl_map_options(void) {
    write_text("mo.ppm", "P3\n1 1\n255\n10 20 30\n");
    write_text("mo.mtl",
               "newmtl quiet\nmap_Kd -s 1 1 1 -o 0 0 0 -clamp off -bm 1 -blendu off -blendv on -cc on -mm 0 1 -imfchan r "
               "-texres 512 -type sphere mo.ppm   # the diffuse map\n"
               "newmtl loud\nmap_Kd -s 2 2 1 -o 0.5 0 -clamp on -mm 0.1 0.9 -t 0.5 0 0 mo.ppm\n");
    write_text("mo.obj", "mtllib mo.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl quiet\nf 1 2 3\nusemtl loud\nf 1 2 3\n");
    rp_scene_data s;
    warnings w;
    if (!load("mo.obj", &s, &w)) return;
    CHECK(s.texture_count == 2 && s.triangle_count == 2);
    if (s.triangle_count == 2 && s.texture_count == 2) {
        CHECK(tri_material(&s, 0)->map_kd == 0 && tri_material(&s, 1)->map_kd == 1);
        const rp_texture_data *q = &s.textures[0], *l = &s.textures[1];
        CHECK(q->wrap_u == RP_TEXTURE_REPEAT && q->wrap_v == RP_TEXTURE_REPEAT && q->rgb[0] == 10 && q->rgb[2] == 30);
        /* 0.1 + 0.9 c: 10 -> 34.5, 30 -> 52.5 (rounded either way) */
        CHECKF(l->wrap_u == RP_TEXTURE_CLAMP && l->wrap_v == RP_TEXTURE_CLAMP && abs(l->rgb[0] - 34) <= 1 && abs(l->rgb[2] - 52) <= 1,
               "-clamp on -mm 0.1 0.9: wrap %d %d, texel %d %d %d", (int)l->wrap_u, (int)l->wrap_v, l->rgb[0], l->rgb[1], l->rgb[2]);
    }
    CHECKF(w.count == 1, "%d warnings:\n%s", w.count, w.text);
    CHECKF(strstr(w.text, "mo.mtl:4: warning: map_Kd option '-t 0.5 0 0' is not applied") != NULL &&
               strstr(w.text, "option '-s") == NULL && strstr(w.text, "option '-o") == NULL,
           "%s", w.text);
    if (s.triangle_count == 2) {
        const rp_material_data *quiet = tri_material(&s, 0), *loud = tri_material(&s, 1);
        const float want[6] = {2, 0, 0.5f, 0, 2, 0}; /* u' = 2 u + 0.5, v' = 2 v */
        CHECK(!quiet->uv_transform);
        CHECKF(loud->uv_transform && memcmp(loud->uv_matrix, want, sizeof want) == 0, "-s 2 2 1 -o 0.5 0: %g %g %g %g %g %g",
               (double)loud->uv_matrix[0], (double)loud->uv_matrix[1], (double)loud->uv_matrix[2], (double)loud->uv_matrix[3],
               (double)loud->uv_matrix[4], (double)loud->uv_matrix[5]);
    }
    rp_scene_data_free(&s);
}

/* A texture named by the exporter's absolute path (Windows or Unix) that is not there is found by
 * its file name beside the MTL file (Blender's importer does so), with a warning; a path that is
 * there is used as it is, quietly. */
static void test_mtl_texture_paths(void) {
    write_text("tp.ppm", "P3\n1 1\n255\n1 2 3\n");
    write_text("maps/tp2.ppm", "P3\n1 1\n255\n4 5 6\n");
    write_text("tp.mtl", "newmtl win\nmap_Kd C:\\Users\\me\\Textures\\tp.ppm\n"
                         "newmtl unix\nmap_Kd /home/me/textures/tp.ppm\n"
                         "newmtl here\nmap_Kd maps\\tp2.ppm\n");
    write_text("tp.obj", "mtllib tp.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl win\nf 1 2 3\nusemtl unix\nf 1 2 3\nusemtl here\nf 1 2 3\n");
    rp_scene_data s;
    warnings w;
    if (!load("tp.obj", &s, &w)) return;
    CHECKF(s.texture_count == 2, "%zu textures", s.texture_count);
    if (s.triangle_count == 3 && s.texture_count == 2) {
        CHECK(tri_material(&s, 0)->map_kd == tri_material(&s, 1)->map_kd);
        const rp_texture_data *t = &s.textures[tri_material(&s, 0)->map_kd];
        CHECK(t->rgb[0] == 1 && t->rgb[2] == 3);
        t = &s.textures[tri_material(&s, 2)->map_kd];
        CHECK(t->rgb[0] == 4 && t->rgb[2] == 6);
    }
    CHECKF(w.count == 2 && strstr(w.text, "tp.mtl:2: warning: texture 'C:/Users/me/Textures/tp.ppm' not found there; using 'tp.ppm'") &&
               strstr(w.text, "tp.mtl:4: warning: texture '/home/me/textures/tp.ppm'"),
           "%s", w.text);
    rp_scene_data_free(&s);
}

/* ---- PLY --------------------------------------------------------------------------------------- */

/* A `tristrips` element (Stanford's scans, VCG): strips of vertex_indices, -1 restarting one, the
 * odd triangles turned back; stitching triangles (a repeated corner) left out. Binary too. */
static void test_ply_strips(void) {
    static const char head[] = "element vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
                               "element tristrips 1\nproperty list int int vertex_indices\nend_header\n";
    char text[1024];
    snprintf(text, sizeof text, "ply\nformat ascii 1.0\n%s0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 2 0\n1 2 0\n"
             "9 0 1 2 3 -1 2 3 4 5\n", head);
    write_text("strips.ply", text);
    /* the same strips as little-endian binary, stitched (3 3 2 2: four degenerate triangles, which
     * keep the parity) instead of restarted */
    uint8_t bin[1024];
    int n = snprintf((char *)bin, sizeof bin, "ply\nformat binary_little_endian 1.0\n%s", head);
    size_t at = (size_t)n;
    static const float pos[6][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 2, 0}, {1, 2, 0}};
    memcpy(bin + at, pos, sizeof pos);
    at += sizeof pos;
    static const int32_t strip[11] = {10, 0, 1, 2, 3, 3, 2, 2, 3, 4, 5}; /* count, then the indices */
    memcpy(bin + at, strip, sizeof strip);
    at += sizeof strip;
    write_bytes("strips_bin.ply", bin, at);
    static const uint32_t want[12] = {0, 1, 2, 2, 1, 3, 2, 3, 4, 4, 3, 5};
    static const char *const names[] = {"strips.ply", "strips_bin.ply"};
    for (int i = 0; i < 2; i++) {
        rp_scene_data s;
        warnings w;
        if (!load(names[i], &s, &w)) continue;
        CHECKF(s.triangle_count == 4 && s.sphere_count == 0, "%s: %zu triangles, %zu spheres", names[i], s.triangle_count,
               s.sphere_count);
        if (s.triangle_count == 4)
            CHECKF(memcmp(s.indices, want, sizeof want) == 0, "%s: %u %u %u  %u %u %u  %u %u %u  %u %u %u", names[i],
                   s.indices[0], s.indices[1], s.indices[2], s.indices[3], s.indices[4], s.indices[5], s.indices[6],
                   s.indices[7], s.indices[8], s.indices[9], s.indices[10], s.indices[11]);
        rp_scene_data_free(&s);
    }
}

/* Elements in any order (the PLY spec's): faces and strips before the vertices, an element of
 * another name between; the triangles the usual order gives. */
static void test_ply_order(void) {
    write_text("order.ply",
               "ply\nformat ascii 1.0\n"
               "element face 1\nproperty list uchar int vertex_indices\n"
               "element junk 2\nproperty float a\n"
               "element tristrips 1\nproperty list int int vertex_indices\n"
               "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
               "end_header\n"
               "4 0 1 2 3\n"
               "7\n8\n"
               "4 0 1 3 2\n"
               "0 0 0\n1 0 0\n1 1 0\n0 1 0\n");
    rp_scene_data s;
    warnings w;
    if (!load("order.ply", &s, &w)) return;
    CHECKF(s.triangle_count == 4 && s.vertex_count == 4, "%zu triangles", s.triangle_count);
    if (s.triangle_count == 4) {
        static const uint32_t want[12] = {0, 1, 2, 0, 2, 3, 0, 1, 3, 3, 1, 2};
        CHECK(memcmp(s.indices, want, sizeof want) == 0);
    }
    rp_scene_data_free(&s);
}

/* MeshLab's textured PLY: `comment TextureFile NAME` (a name with a blank) and texture coordinates
 * per face corner (`property list uchar float texcoord`) or per vertex (`s t`); the texture is the
 * faces' diffuse map. A TextureFile that is not there is a warning, the mesh untextured. */
static void test_ply_texture(void) {
    write_text("ply tex.ppm", "P3\n2 1\n255\n255 0 0  0 0 255\n");
    write_text("wedge.ply",
               "ply\nformat ascii 1.0\ncomment TextureFile ply tex.ppm\n"
               "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
               "element face 2\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n"
               "0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
               "3 0 1 2 6 0 0 1 0 1 1\n"
               "4 0 1 2 3 8 0 0 0.5 0 0.5 0.5 0 0.5\n");
    write_text("vuv.ply",
               "ply\nformat ascii 1.0\ncomment TextureFile ply tex.ppm\n"
               "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float s\nproperty float t\n"
               "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
               "0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n3 0 1 2\n");
    write_text("notex.ply",
               "ply\nformat ascii 1.0\ncomment TextureFile absent.png\n"
               "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float s\nproperty float t\n"
               "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
               "0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n3 0 1 2\n");
    rp_scene_data s;
    warnings w;
    if (load("wedge.ply", &s, &w)) {
        CHECK(s.triangle_count == 3 && s.texture_count == 1 && s.material_count == 1 && s.texcoord_indices);
        if (s.triangle_count == 3 && s.texcoord_indices && s.material_count == 1) {
            CHECK(s.materials[0].map_kd == 0 && s.materials[0].kd[0] == 1.0f);
            /* the quad's corner 2 (vertex 2) has its own (0.5, 0.5), not the triangle's (1, 1) */
            for (size_t t = 1; t < 3; t++)
                for (int j = 0; j < 3; j++)
                    if (s.indices[3 * t + (size_t)j] == 2) {
                        const float *uv = s.texcoords + 2 * s.texcoord_indices[3 * t + (size_t)j];
                        CHECKF(uv[0] == 0.5f && uv[1] == 0.5f, "%g %g", (double)uv[0], (double)uv[1]);
                    }
            const float *uv = s.texcoords + 2 * s.texcoord_indices[2];
            CHECK(uv[0] == 1.0f && uv[1] == 1.0f);
        }
        rp_scene_data_free(&s);
    }
    if (load("vuv.ply", &s, &w)) {
        CHECK(s.texture_count == 1 && s.material_count == 1 && s.materials[0].map_kd == 0);
        rp_scene_data_free(&s);
    }
    if (load("notex.ply", &s, &w)) {
        CHECK(s.texture_count == 0 && s.material_count == 1 && s.materials[0].map_kd == -1);
        CHECKF(w.count == 1 && strstr(w.text, "notex.ply:3: warning: TextureFile 'absent.png' not found"), "%s", w.text);
        rp_scene_data_free(&s);
    }
}

/* ---- textures ----------------------------------------------------------------------------------- */

/* TGA (uncompressed and RLE, bottom-up and top-down) and BMP (24-bit, bottom-up, padded rows) as
 * map_Kd: the texels a PPM of the same image gives. The image is 3x2: red green blue / white black
 * grey. */
static void test_tga_bmp(void) {
    static const uint8_t rgb[2][3][3] = {{{255, 0, 0}, {0, 255, 0}, {0, 0, 255}}, {{255, 255, 255}, {0, 0, 0}, {128, 128, 128}}};
    uint8_t tga[18 + 18], rle[18 + 64], bmp[54 + 2 * 12];
    /* TGA type 2, 24 bits, origin at the bottom left: the bottom row first, BGR */
    memset(tga, 0, 18);
    tga[2] = 2, tga[12] = 3, tga[14] = 2, tga[16] = 24;
    size_t at = 18;
    for (int y = 1; y >= 0; y--)
        for (int x = 0; x < 3; x++)
            for (int c = 2; c >= 0; c--) tga[at++] = rgb[y][x][c];
    write_bytes("tx.tga", tga, at);
    /* TGA type 10 (RLE), 32 bits, origin at the top left (descriptor bit 5): one raw packet of the
     * top row, then the bottom row: raw white, a run of black, raw grey */
    memset(rle, 0, 18);
    rle[2] = 10, rle[12] = 3, rle[14] = 2, rle[16] = 32, rle[17] = 0x28;
    at = 18;
    rle[at++] = 2; /* raw, 3 pixels */
    for (int x = 0; x < 3; x++) {
        for (int c = 2; c >= 0; c--) rle[at++] = rgb[0][x][c];
        rle[at++] = 255;
    }
    rle[at++] = 0; /* raw, 1 pixel: white */
    rle[at++] = 255, rle[at++] = 255, rle[at++] = 255, rle[at++] = 255;
    rle[at++] = 0x80; /* run of 1: black */
    rle[at++] = 0, rle[at++] = 0, rle[at++] = 0, rle[at++] = 255;
    rle[at++] = 0; /* raw, 1 pixel: grey */
    rle[at++] = 128, rle[at++] = 128, rle[at++] = 128, rle[at++] = 255;
    write_bytes("tx_rle.tga", rle, at);
    /* BMP: BITMAPINFOHEADER, 24 bits, rows bottom-up, each padded to 12 bytes */
    memset(bmp, 0, sizeof bmp);
    bmp[0] = 'B', bmp[1] = 'M';
    uint32_t size = sizeof bmp, off = 54, hdr = 40, w = 3, h = 2, img = 24;
    memcpy(bmp + 2, &size, 4), memcpy(bmp + 10, &off, 4), memcpy(bmp + 14, &hdr, 4);
    memcpy(bmp + 18, &w, 4), memcpy(bmp + 22, &h, 4), memcpy(bmp + 34, &img, 4);
    bmp[26] = 1, bmp[28] = 24;
    at = 54;
    for (int y = 1; y >= 0; y--) {
        for (int x = 0; x < 3; x++)
            for (int c = 2; c >= 0; c--) bmp[at++] = rgb[y][x][c];
        at += 3; /* padding */
    }
    write_bytes("tx.bmp", bmp, at);
    static const char *const names[] = {"tx.tga", "tx_rle.tga", "tx.bmp"};
    for (int i = 0; i < 3; i++) {
        char mtl[256], obj[256], text[512];
        snprintf(mtl, sizeof mtl, "tx%d.mtl", i);
        snprintf(obj, sizeof obj, "tx%d.obj", i);
        snprintf(text, sizeof text, "newmtl t\nKd 1 1 1\nmap_Kd %s\n", names[i]);
        write_text(mtl, text);
        snprintf(text, sizeof text, "mtllib %s\nusemtl t\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nf 1/1 2/2 3/3\n", mtl);
        write_text(obj, text);
        rp_scene_data s;
        warnings wn;
        if (!load(obj, &s, &wn)) continue;
        CHECKF(s.texture_count == 1, "%s", names[i]);
        if (s.texture_count == 1) {
            const rp_texture_data *t = &s.textures[0];
            CHECKF(t->width == 3 && t->height == 2, "%s: %dx%d", names[i], t->width, t->height);
            if (t->width == 3 && t->height == 2)
                CHECKF(memcmp(t->rgb, rgb, sizeof rgb) == 0, "%s: texels %d %d %d  %d %d %d ...", names[i], t->rgb[0],
                       t->rgb[1], t->rgb[2], t->rgb[3], t->rgb[4], t->rgb[5]);
        }
        rp_scene_data_free(&s);
    }
}

/* Vertex colours: OBJ's `v x y z r g b` (and `w r g b`), PLY's red/green/blue properties (uchar:
 * /255; float: as they are), sRGB-decoded; uncoloured vertices of a coloured file white; a file
 * without colours has none; a coloured point cloud's spheres take its colours. */
static bool near_color(const float *c, float r, float g, float b) {
    return fabsf(c[0] - r) < 1e-4f && fabsf(c[1] - g) < 1e-4f && fabsf(c[2] - b) < 1e-4f;
}

static void test_vertex_colors(void) {
    const float half = io_srgb_to_linear(0.5f); /* 0.2140 */
    CHECKF(fabsf(half - 0.21404f) < 1e-4f, "sRGB 0.5 decodes to %g", (double)half);
    write_text("colors.obj", "v 0 0 0\n"            /* white: before any colour */
                             "v 1 0 0 1 0 0\n"      /* red */
                             "v 0 1 0 1 0 0.5 1\n"  /* w, then r g b */
                             "v 1 1 0 1\n"          /* w alone: white */
                             "f 1 2 3\nf 2 4 3\n");
    rp_scene_data s;
    warnings w;
    if (load("colors.obj", &s, &w)) {
        CHECK(s.colors != NULL && s.vertex_count == 4);
        if (s.colors) {
            CHECK(near_color(s.colors, 1, 1, 1));
            CHECK(near_color(s.colors + 3, 1, 0, 0));
            CHECKF(near_color(s.colors + 6, 0, half, 1), "w r g b: %g %g %g", (double)s.colors[6], (double)s.colors[7],
                   (double)s.colors[8]);
            CHECK(near_color(s.colors + 9, 1, 1, 1));
        }
        rp_scene_data_free(&s);
    }
    write_text("plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0 1\nf 1 2 3\n");
    if (load("plain.obj", &s, &w)) {
        CHECK(s.colors == NULL);
        rp_scene_data_free(&s);
    }
    static const char ply_head[] = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                                   "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
                                   "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    char text[1024];
    snprintf(text, sizeof text, "ply\nformat ascii 1.0\n%s0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 128 255\n"
             "3 0 1 2\n", ply_head);
    write_text("colors.ply", text);
    uint8_t bin[1024];
    size_t at = (size_t)snprintf((char *)bin, sizeof bin, "ply\nformat binary_little_endian 1.0\n%s", ply_head);
    static const float pos[3][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    static const uint8_t rgba[3][4] = {{255, 0, 0, 255}, {0, 255, 0, 255}, {0, 0, 128, 255}};
    for (int v = 0; v < 3; v++) {
        memcpy(bin + at, pos[v], sizeof pos[v]);
        at += sizeof pos[v];
        memcpy(bin + at, rgba[v], 4);
        at += 4;
    }
    static const uint8_t face[13] = {3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0};
    memcpy(bin + at, face, sizeof face);
    at += sizeof face;
    write_bytes("colors_bin.ply", bin, at);
    const float c128 = io_srgb_to_linear(128.0f / 255.0f);
    static const char *const names[] = {"colors.ply", "colors_bin.ply"};
    for (int i = 0; i < 2; i++) {
        if (!load(names[i], &s, &w)) continue;
        CHECKF(s.colors && s.triangle_count == 1, "%s: no colours", names[i]);
        if (s.colors)
            CHECKF(near_color(s.colors, 1, 0, 0) && near_color(s.colors + 3, 0, 1, 0) &&
                       near_color(s.colors + 6, 0, 0, c128),
                   "%s: colours %g %g %g, %g %g %g, %g %g %g", names[i], (double)s.colors[0], (double)s.colors[1],
                   (double)s.colors[2], (double)s.colors[3], (double)s.colors[4], (double)s.colors[5],
                   (double)s.colors[6], (double)s.colors[7], (double)s.colors[8]);
        rp_scene_data_free(&s);
    }
    /* a coloured point cloud: float colours taken as they are (then decoded) */
    write_text("cloud.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                            "property float z\nproperty float red\nproperty float green\nproperty float blue\n"
                            "end_header\n0 0 0 1 0 0\n1 0 0 0 1 0\n0 1 0 0 0 0.5\n");
    if (load("cloud.ply", &s, &w)) {
        CHECKF(s.sphere_count == 3 && s.sphere_colors, "cloud: %zu spheres, colours %p", s.sphere_count,
               (void *)s.sphere_colors);
        if (s.sphere_colors)
            CHECK(near_color(s.sphere_colors, 1, 0, 0) && near_color(s.sphere_colors + 3, 0, 1, 0) &&
                  near_color(s.sphere_colors + 6, 0, 0, half));
        rp_scene_data_free(&s);
    }
}

int main(void) {
    const char *t = getenv("RP_TEST_TMP");
    snprintf(tmp_dir, sizeof tmp_dir, "%s", t ? t : "/tmp/rp_test_io_valid");
    mkdir(tmp_dir, 0755);

    test_usemtl_unknown();
    test_obj_names();
    test_obj_continued();
    test_mtl_values();
    test_mtl_case();
    test_mtl_map_options();
    test_mtl_texture_paths();
    test_ply_strips();
    test_ply_order();
    test_ply_texture();
    test_tga_bmp();
    test_vertex_colors();
    return RP_TEST_END();
}
