// rp-test: labels=io timeout=300
/* Scene loaders: small handwritten files for each feature and each class of broken file (written at
 * run time into RP_TEST_TMP), plus the shared scenes that are quick enough under ASan. The large
 * shared scenes are in test_io_scenes.c. */
#include <math.h>
#include <stdint.h>
#include <sys/stat.h>
#include <zlib.h>

#include "raypack_io.h"
#include "rp_test.h"
#include "rp_test_tmp.h"


static bool load(const char *name, rp_scene_data *s, char *err, size_t err_size) {
    char path[1024];
    return rp_scene_data_load(tmp_path(name, path, sizeof path), s, err, err_size);
}

/* Loads a file that must fail and checks the message is "<...name>:<line>: error: ...". */
static void expect_error(const char *name, const char *err_file, unsigned line, const char *needle) {
    rp_scene_data s;
    char err[1024] = "";
    bool ok = load(name, &s, err, sizeof err);
    CHECKF(!ok, "%s loaded but should fail", name);
    if (ok) {
        rp_scene_data_free(&s);
        return;
    }
    CHECKF(s.triangle_count == 0 && s.positions == NULL, "%s: out not empty after failure", name);
    char want[256];
    snprintf(want, sizeof want, "%s:%u: error: ", err_file, line);
    const char *at = strstr(err, want);
    CHECKF(at != NULL && (at == err || at[-1] == '/'), "%s: message '%s' lacks '%s'", name, err, want);
    if (needle) CHECKF(strstr(err, needle) != NULL, "%s: message '%s' lacks '%s'", name, err, needle);
}

static bool near(float a, float b) { return fabsf(a - b) <= 1e-5f * (1.0f + fabsf(a) + fabsf(b)); }

/* ---- numbers ---------------------------------------------------------------------------------- */

/* The fast float parser must round like strtof: compare on tricky literals through a loaded OBJ. */
static void test_float_parsing(void) {
    static const char *lits[] = {"0",        "-0",       "1",          "-1.5",         ".5",
                                 "5.",       "1e3",      "1E-3",       "+2.25",        "3.4028234e38",
                                 "1.17549435e-38", "1.4e-45", "0.1",   "0.3",          "123456789",
                                 "16777217", "33554435", "1.00000005960464477550", "7.038531e-26",
                                 "8.589973e9", "0.000000000000000000000000001", "123456789012345678901234567890",
                                 "6.15385e-18", "-0.0000001", "4.3527734e-4", "2.5e+10"};
    size_t n = sizeof lits / sizeof lits[0];
    char text[8192] = "";
    size_t len = 0;
    for (size_t i = 0; i < n; i++) len += (size_t)snprintf(text + len, sizeof text - len, "v %s 0 0\n", lits[i]);
    snprintf(text + len, sizeof text - len, "f 1 2 3\n");
    write_text("floats.obj", text);
    rp_scene_data s;
    char err[512];
    bool ok = load("floats.obj", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    CHECK(s.vertex_count == n);
    for (size_t i = 0; i < n && i < s.vertex_count; i++) {
        float want = strtof(lits[i], NULL);
        CHECKF(memcmp(&s.positions[3 * i], &want, sizeof want) == 0, "%s parsed as %.9g, strtof says %.9g", lits[i],
               (double)s.positions[3 * i], (double)want);
    }
    rp_scene_data_free(&s);
}

/* ---- OBJ -------------------------------------------------------------------------------------- */

static void test_obj(void) {
    /* P3 texture for map_Kd: 2x1, max 15. */
    write_text("tex_p3.ppm", "P3\n# comment\n2 1\n15\n15 0 0  0 15 0\n");
    write_text("mats.mtl",
               "# materials\n"
               "newmtl red\n"
               "Kd 0.8 0.1 0.1\nKs 0.5 0.5 0.5\nNs 32\nNi 1.5\nd 0.75\nillum 7\nTf 0.2 0.3 0.4\nKe 1 2 3\n"
               "map_Kd -s 1 1 1 tex_p3.ppm\n"
               "newmtl plain\nKd 0.5\n");
    write_text("groups.obj",
               "# negative indices, objects and groups, missing normals\n"
               "mtllib mats.mtl\n"
               "o first\n"
               "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
               "g quad\n"
               "f -4 -3 -2 -1\n"
               "o second\n"
               "g a b\n"
               "usemtl red\n"
               "v 0 0 1\nv 1 0 1\nv 0 1 1\n"
               "vn 0 0 1\n"
               "vt 0.5 0.25\n"
               "s 1\n"
               "f 5/1/1 6/1/1 7/1/-1\n"
               "usemtl plain\n"
               "f -3//1 -2//1 -1//1\n"
               "usemtl undefined_name\n"
               "f 1 2 3\n");
    rp_scene_data s;
    char err[512];
    bool ok = load("groups.obj", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    CHECK(s.triangle_count == 5);
    CHECK(s.vertex_count == 7);
    CHECK(s.indices[0] == 0 && s.indices[1] == 1 && s.indices[2] == 2);
    CHECK(s.indices[3] == 0 && s.indices[4] == 2 && s.indices[5] == 3);
    CHECK(s.indices[6] == 4 && s.indices[7] == 5 && s.indices[8] == 6);
    CHECK(s.normal_indices != NULL && s.texcoord_indices != NULL);
    if (s.normal_indices) {
        CHECK(s.normal_indices[6] == 0 && s.normal_indices[8] == 0);
        /* the quad had no normals: it got its face normal (0,0,1) */
        const float *n = s.normals + 3 * s.normal_indices[0];
        CHECK(near(n[0], 0) && near(n[1], 0) && near(n[2], 1));
    }
    if (s.texcoord_indices) {
        CHECK(s.texcoords[2 * s.texcoord_indices[6]] == 0.5f && s.texcoords[2 * s.texcoord_indices[6] + 1] == 0.25f);
        CHECK(s.texcoords[2 * s.texcoord_indices[0]] == 0.0f);
    }
    /* materials: red, plain, then the default grey for faces without (or with an unknown) usemtl */
    CHECK(s.material_count == 3);
    const rp_material_data *red = &s.materials[s.tri_materials[2]];
    CHECK(strcmp(red->name, "red") == 0);
    CHECK(red->kd[0] == 0.8f && red->ks[1] == 0.5f && red->ns == 32.0f && red->ior == 1.5f && red->illum == 7);
    CHECK(red->kr[0] == 0.5f);                       /* illum 7 reflects with Ks */
    CHECK(red->kt[0] == 0.2f && red->kt[2] == 0.4f); /* illum 7 transmits with Tf */
    CHECK(red->ke[2] == 3.0f);
    CHECK(red->map_kd == 0 && s.texture_count == 1);
    if (s.texture_count == 1) {
        CHECK(s.textures[0].width == 2 && s.textures[0].height == 1);
        CHECK(s.textures[0].rgb[0] == 255 && s.textures[0].rgb[1] == 0 && s.textures[0].rgb[4] == 255);
        CHECK(strcmp(s.textures[0].path, "tex_p3.ppm") == 0);
    }
    CHECK(strcmp(s.materials[s.tri_materials[3]].name, "plain") == 0);
    CHECK(s.materials[s.tri_materials[3]].kd[2] == 0.5f); /* "Kd 0.5" is grey */
    const rp_material_data *def = &s.materials[s.tri_materials[0]];
    CHECK(strcmp(def->name, "default") == 0 && def->kd[0] == def->kd[1] && def->kd[0] > 0.0f && def->map_kd == -1);
    CHECK(s.tri_materials[4] == s.tri_materials[0]);
    CHECK(!s.camera.valid);
    rp_scene_data_free(&s);

    /* The same file gzip'd loads the same. */
    char path[1024];
    gzFile gz = gzopen(tmp_path("cube.obj.gz", path, sizeof path), "wb");
    const char *cube = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n";
    gzwrite(gz, cube, (unsigned)strlen(cube));
    gzclose(gz);
    ok = load("cube.obj.gz", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (ok) {
        CHECK(s.triangle_count == 1 && s.file_bytes == strlen(cube));
        rp_scene_data_free(&s);
    }
}

/* ---- PLY -------------------------------------------------------------------------------------- */

/* Appends v to buf in the byte order asked. */
static size_t put(uint8_t *buf, size_t at, const void *v, size_t n, bool big) {
    for (size_t i = 0; i < n; i++) buf[at + i] = ((const uint8_t *)v)[big ? n - 1 - i : i];
    return at + n;
}

static void write_binary_ply(const char *name, bool big) {
    char header[1024];
    int hl = snprintf(header, sizeof header,
                      "ply\nformat %s 1.0\ncomment extra properties of every type\n"
                      "element vertex 5\nproperty double x\nproperty float y\nproperty float z\n"
                      "property uchar red\nproperty list uchar short junk\nproperty int16 confidence\n"
                      "element face 2\nproperty list uchar uint vertex_indices\nproperty float quality\n"
                      "property list ushort int8 more\n"
                      "element edge 1\nproperty int v1\nproperty int v2\n"
                      "end_header\n",
                      big ? "binary_big_endian" : "binary_little_endian");
    uint8_t buf[2048];
    size_t at = 0;
    memcpy(buf, header, (size_t)hl);
    at = (size_t)hl;
    static const float pos[5][3] = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {0, 1, 0}, {1, 1, 1}};
    for (int i = 0; i < 5; i++) {
        double x = pos[i][0];
        at = put(buf, at, &x, 8, big);
        at = put(buf, at, &pos[i][1], 4, big);
        at = put(buf, at, &pos[i][2], 4, big);
        uint8_t red = 200, cnt = (uint8_t)(i % 3);
        at = put(buf, at, &red, 1, big);
        at = put(buf, at, &cnt, 1, big);
        for (int k = 0; k < cnt; k++) {
            int16_t j = (int16_t)-k;
            at = put(buf, at, &j, 2, big);
        }
        int16_t conf = 7;
        at = put(buf, at, &conf, 2, big);
    }
    static const uint32_t quad[4] = {0, 1, 2, 3}, tri[3] = {3, 2, 4};
    uint8_t n4 = 4, n3 = 3;
    float q = 0.5f;
    uint16_t more = 2;
    int8_t m[2] = {1, 2};
    at = put(buf, at, &n4, 1, big);
    for (int i = 0; i < 4; i++) at = put(buf, at, &quad[i], 4, big);
    at = put(buf, at, &q, 4, big);
    at = put(buf, at, &more, 2, big);
    at = put(buf, at, &m[0], 1, big);
    at = put(buf, at, &m[1], 1, big);
    at = put(buf, at, &n3, 1, big);
    for (int i = 0; i < 3; i++) at = put(buf, at, &tri[i], 4, big);
    at = put(buf, at, &q, 4, big);
    more = 0;
    at = put(buf, at, &more, 2, big);
    int32_t e[2] = {0, 1};
    at = put(buf, at, &e[0], 4, big);
    at = put(buf, at, &e[1], 4, big);
    write_bytes(name, buf, at);
}

static void check_ply_mesh(const char *name) {
    rp_scene_data s;
    char err[512];
    bool ok = load(name, &s, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    if (!ok) return;
    CHECKF(s.vertex_count == 5 && s.triangle_count == 3, "%s: %zu vertices %zu triangles", name, s.vertex_count,
           s.triangle_count);
    if (s.vertex_count == 5) {
        CHECK(s.positions[3] == 2.0f && s.positions[7] == 1.0f && s.positions[14] == 1.0f);
    }
    if (s.triangle_count == 3) {
        static const uint32_t want[9] = {0, 1, 2, 0, 2, 3, 3, 2, 4};
        CHECKF(memcmp(s.indices, want, sizeof want) == 0, "%s: indices differ", name);
    }
    CHECK(s.material_count == 1 && s.normals == NULL && s.texcoords == NULL);
    rp_scene_data_free(&s);
}

static void test_ply(void) {
    write_text("mesh_ascii.ply",
               "ply\nformat ascii 1.0\ncomment extra properties of every type\n"
               "element vertex 5\nproperty double x\nproperty float y\nproperty float z\n"
               "property uchar red\nproperty list uchar short junk\nproperty int16 confidence\n"
               "element face 2\nproperty list uchar uint vertex_indices\nproperty float quality\n"
               "property list ushort int8 more\n"
               "element edge 1\nproperty int v1\nproperty int v2\n"
               "end_header\n"
               "0 0 0 200 0 7\n2 0 0 200 1 0 7\n2 1 0 200 2 0 -1 7\n0 1 0 200 0 7\n1 1 1 200 1 0 7\n"
               "4 0 1 2 3 0.5 2 1 2\n3 3 2 4 0.5 0\n0 1\n");
    check_ply_mesh("mesh_ascii.ply");
    write_binary_ply("mesh_le.ply", false);
    check_ply_mesh("mesh_le.ply");
    write_binary_ply("mesh_be.ply", true);
    check_ply_mesh("mesh_be.ply");

    /* Normals and texture coordinates come per vertex. */
    write_text("mesh_nuv.ply",
               "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
               "property float nx\nproperty float ny\nproperty float nz\nproperty float u\nproperty float v\n"
               "element face 1\nproperty list uchar int vertex_index\nend_header\n"
               "0 0 0 0 0 1 0 0\n1 0 0 0 0 1 1 0\n0 1 0 0 0 1 0 1\n3 0 1 2\n");
    rp_scene_data s;
    char err[512];
    bool ok = load("mesh_nuv.ply", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (ok) {
        CHECK(s.normal_count == 3 && s.texcoord_count == 3 && s.normal_indices && s.texcoord_indices);
        if (s.texcoord_indices) CHECK(s.texcoords[2 * s.texcoord_indices[1]] == 1.0f);
        rp_scene_data_free(&s);
    }
}

/* ---- NFF / AFF -------------------------------------------------------------------------------- */

/* Signed area of a polygon in the z = 0 plane. */
static double shoelace(const double (*p)[2], int n) {
    double a = 0;
    for (int i = 0; i < n; i++) a += p[i][0] * p[(i + 1) % n][1] - p[(i + 1) % n][0] * p[i][1];
    return a / 2;
}

static void test_nff_concave(void) {
    /* A 144-vertex gear like SPD's: 36 teeth, 4 vertices per tooth, deeply concave. */
    enum { N = 144 };
    double pts[N][2];
    char *text = malloc(64 * N + 1024);
    size_t len = (size_t)sprintf(text, "v\nfrom 0 0 10\nat 0 0 0\nup 0 1 0\nangle 30\nhither 1\nresolution 200 400\n"
                                       "f 1 0 0 1 0 0 0 0\np %d\n", N);
    for (int i = 0; i < N; i++) {
        double a = 2 * 3.14159265358979323846 * i / N;
        double r = (i % 4 < 2) ? 1.0 : 0.6;
        pts[i][0] = r * cos(a);
        pts[i][1] = r * sin(a);
        len += (size_t)sprintf(text + len, "%.9g %.9g 0\n", pts[i][0], pts[i][1]);
    }
    /* the same gear mirrored (clockwise) at z = 1 */
    len += (size_t)sprintf(text + len, "p %d\n", N);
    for (int i = N - 1; i >= 0; i--) len += (size_t)sprintf(text + len, "%.9g %.9g 1\n", pts[i][0], pts[i][1]);
    write_text("gear.nff", text);
    free(text);
    rp_scene_data s;
    char err[512];
    bool ok = load("gear.nff", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    CHECK(s.triangle_count == 2 * (N - 2));
    double want = shoelace(pts, N);
    for (int g = 0; g < 2; g++) {
        double sum = 0, abs_sum = 0;
        bool same_side = true;
        for (size_t t = (size_t)g * (N - 2); t < (size_t)(g + 1) * (N - 2) && t < s.triangle_count; t++) {
            const float *a = s.positions + 3 * s.indices[3 * t], *b = s.positions + 3 * s.indices[3 * t + 1],
                        *c = s.positions + 3 * s.indices[3 * t + 2];
            double area = ((double)(b[0] - a[0]) * (c[1] - a[1]) - (double)(b[1] - a[1]) * (c[0] - a[0])) / 2;
            sum += area;
            abs_sum += fabs(area);
            if (g == 0 ? area < -1e-9 : area > 1e-9) same_side = false;
        }
        /* Same orientation everywhere and total |area| = polygon area: no overlap, no hole. */
        CHECKF(fabs(fabs(sum) - want) < 1e-4 && fabs(abs_sum - want) < 1e-4, "gear %d: area %g (|%g|), want %g", g, sum,
               abs_sum, want);
        CHECK(same_side);
    }
    /* angle 30 spans the narrower side (width 200): vertical fov = 2 atan(tan(15 deg) * 400/200) */
    CHECK(s.camera.valid && s.camera.width == 200 && s.camera.height == 400);
    double fov = 2 * atan(tan(15 * 3.14159265358979323846 / 180) * 2) * 180 / 3.14159265358979323846;
    CHECKF(fabs(s.camera.fov_deg - fov) < 1e-3, "fov %g want %g", (double)s.camera.fov_deg, fov);
    CHECK(s.material_count == 1 && s.materials[0].kd[0] == 1.0f && s.materials[0].illum == -1);
    rp_scene_data_free(&s);
}

static void test_aff(void) {
    mkdir(tmp_path("aff", (char[1024]){0}, 1024), 0755);
    mkdir(tmp_path("TextureFiles", (char[1024]){0}, 1024), 0755);
    /* 2x2 binary PPM */
    static const uint8_t p6[] = {'P', '6', '\n', '2', ' ', '2', '\n', '2', '5', '5', '\n', 255, 0, 0, 0, 255, 0,
                                 0, 0, 255, 9, 9, 9};
    write_bytes("TextureFiles/checker.ppm", p6, sizeof p6);
    write_text("aff/part.aff",
               "% included part: a triangle mesh with normals and texture coordinates\n"
               "m\n vertices 3\n 0 0 0\n 1 0 0\n 0 1 0\n"
               " normals 1\n 0 0 1\n"
               " texturecoords 3 checker.ppm\n 0 0\n 1 0\n 0 1\n"
               " triangles 1\n 0 1 2  0 0 0  0 1 2\n");
    write_text("aff/scene.aff",
               "b 0.1 0.2 0.3\n"
               "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 0.1\nresolution 64 48\n"
               "l 1 2 3\nl 4 5 6 0.5 0.5 0.5   # coloured\n"
               "am 0.1 0.1 0.1\n"
               "fm 0.1 0.1 0.1  0.5 0.6 0.7  0.2 0.2 0.2  20 0.5 1.3\n"
               "xs 2 2 2  0 0 1 90  10 0 0\n{\n"
               "  i 0 part.aff\n"
               "  s 1 0 0 0.5\n"
               "}\n"
               "x mover\n{\n  c 0 0 0 1  0 1 0 0.5\n  pp 3\n 0 0 0 0 0 1\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n}\n"
               "tt checker.ppm\n 0 0 0 0 0\n 1 0 0 1 0\n 0 1 0 0 1\n"
               "tpa 2\n 0\n 0 0 0 0 0 1\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n 1\n 5 0 0 0 0 1\n 6 0 0 0 0 1\n 5 1 0 0 0 1\n"
               "a 0 10 100\n"
               "k mover\n{\n  transl 4\n  -1 0 0 7  0 0 0\n  0 0 0 8  0 0 0\n  1 0 0 9  0 0 0\n  2 0 0 9  0 0 0\n}\n");
    rp_scene_data s;
    char err[512];
    bool ok = load("aff/scene.aff", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return;
    CHECK(s.triangle_count == 4 && s.sphere_count == 1 && s.cone_count == 1 && s.light_count == 2);
    CHECK(s.has_background && s.background[2] == 0.3f);
    CHECK(s.camera.valid && s.camera.fov_deg == 40.0f && s.camera.width == 64 && s.camera.eye[2] == 5.0f);
    CHECK(s.lights[0].color[0] == 1.0f && s.lights[1].color[0] == 0.5f && s.lights[1].position[2] == 6.0f);
    CHECK(s.texture_count == 1);
    if (s.texture_count == 1) CHECK(s.textures[0].width == 2 && s.textures[0].rgb[4] == 255 && s.textures[0].rgb[11] == 9);
    if (s.triangle_count == 4) {
        /* mesh under xs: scale 2, rotate 90 degrees about z, move by (10,0,0): (1,0,0) -> (10,2,0) */
        const float *p = s.positions + 3 * s.indices[1];
        CHECKF(near(p[0], 10) && near(p[1], 2) && near(p[2], 0), "xs vertex (%g %g %g)", (double)p[0], (double)p[1],
               (double)p[2]);
        const rp_material_data *m = &s.materials[s.tri_materials[0]];
        CHECK(m->map_kd == 0 && m->kd[1] == 0.6f && m->ks[0] == 0.2f && m->kr[0] == 0.2f && m->kt[0] == 0.5f &&
              m->ns == 20.0f && m->ior == 1.3f && m->ka[0] == 0.1f);
        CHECK(m->ke[0] == 0.0f && m->map_ke == 0); /* ambient beside diffuse: no emission */
        CHECK(s.normal_indices && s.texcoord_indices);
        /* pp inside `x mover`: at the animation's start (a 0 ...) the spline is at key 1, (0,0,8)
         * (BART: key 0 only shapes the tangent) */
        p = s.positions + 3 * s.indices[3 * 1 + 1];
        CHECKF(near(p[0], 1) && near(p[2], 8), "keyframed vertex (%g %g %g)", (double)p[0], (double)p[1], (double)p[2]);
        /* tpa: first keyframe */
        p = s.positions + 3 * s.indices[3 * 3 + 1];
        CHECK(p[0] == 1.0f);
        CHECK(s.materials[s.tri_materials[2]].map_kd == 0);
    }
    if (s.sphere_count == 1) CHECK(near(s.spheres[0].center[0], 10) && near(s.spheres[0].center[1], 2) && near(s.spheres[0].radius, 1));
    if (s.cone_count == 1) CHECK(near(s.cones[0].base[2], 8) && near(s.cones[0].apex[1], 1) && s.cones[0].apex_radius == 0.5f);
    rp_scene_data_free(&s);
}

/* BART's ambient-only surfaces (the kitchen's garden: `fm` with ambient and nothing else) emit
 * `am` x ambient, textured as the surface is, wherever `am` stands in the file; without `am` they
 * stay dark, as in BART's own shading. */
static void test_aff_ambient(void) {
    write_text("aff/amb.aff", "fm 0.4 0.5 0.6  0 0 0  0 0 0  0 0 0\n"
                              "tt checker.ppm\n 0 0 0 0 0\n 1 0 0 1 0\n 0 1 0 0 1\n"
                              "p 3\n 0 0 1\n 1 0 1\n 0 1 1\n"
                              "am 2 2 2\n");
    write_text("aff/amb_none.aff", "fm 0.4 0.5 0.6  0 0 0  0 0 0  0 0 0\np 3\n 0 0 1\n 1 0 1\n 0 1 1\n");
    rp_scene_data s;
    char err[512];
    bool ok = load("aff/amb.aff", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (ok && s.triangle_count == 2) {
        const rp_material_data *t = &s.materials[s.tri_materials[0]], *p = &s.materials[s.tri_materials[1]];
        CHECKF(near(t->ke[0], 0.8f) && near(t->ke[1], 1.0f) && near(t->ke[2], 1.2f) && t->map_ke == t->map_kd + 1 &&
                   t->map_kd >= 0,
               "textured ambient surface: ke %g %g %g map_ke %d map_kd %d", (double)t->ke[0], (double)t->ke[1],
               (double)t->ke[2], t->map_ke, t->map_kd);
        CHECK(near(p->ke[2], 1.2f) && p->map_ke == 0 && p->ka[1] == 0.5f);
    } else {
        CHECKF(false, "amb.aff: %zu triangles", ok ? s.triangle_count : 0);
    }
    if (ok) rp_scene_data_free(&s);
    ok = load("aff/amb_none.aff", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (ok) {
        CHECK(s.triangle_count == 1 && s.materials[s.tri_materials[0]].ke[0] == 0.0f);
        rp_scene_data_free(&s);
    }
}

/* ---- broken files ----------------------------------------------------------------------------- */

static void test_errors(void) {
    write_text("e_range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
    expect_error("e_range.obj", "e_range.obj", 4, "out of range");
    write_text("e_neg.obj", "v 0 0 0\nv 1 0 0\n\nv 0 1 0\nf -1 -2 -4\n");
    expect_error("e_neg.obj", "e_neg.obj", 5, "out of range");
    write_text("e_zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
    expect_error("e_zero.obj", "e_zero.obj", 4, "index 0");
    write_text("e_nan.obj", "# nan\nv 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
    expect_error("e_nan.obj", "e_nan.obj", 3, "nan");
    write_text("e_inf.obj", "v 0 0 0\nv 1e39 0 0\n");
    expect_error("e_inf.obj", "e_inf.obj", 2, NULL);
    write_text("e_nomtl.obj", "# comment\nmtllib missing.mtl\nv 0 0 0\n");
    expect_error("e_nomtl.obj", "e_nomtl.obj", 2, "missing.mtl");
    /* a scene's folder given for its file, and a file without a suffix: each said as such (the
     * message showed "unknown scene format '.'" for both) */
    {
        char dir[1024];
        mkdir(tmp_path("e_scene_dir", dir, sizeof dir), 0755);
        expect_error("e_scene_dir", "e_scene_dir", 0, "is a directory");
        write_text("e_nosuffix", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        expect_error("e_nosuffix", "e_nosuffix", 0, "no file name suffix");
        write_text("e_suffix.rpq", "v 0 0 0\n");
        expect_error("e_suffix.rpq", "e_suffix.rpq", 0, "unknown scene format '.rpq'");
    }
    write_text("e_notex.mtl", "newmtl a\nKd 1 1 1\n\nmap_Kd missing_texture.png\n");
    write_text("e_notex.obj", "mtllib e_notex.mtl\nv 0 0 0\n");
    expect_error("e_notex.obj", "e_notex.mtl", 4, "missing_texture.png");
    write_text("e_badtex.ppm", "P6\n4 4\n255\nshort");
    write_text("e_badtex.mtl", "newmtl a\nmap_Kd e_badtex.ppm\n");
    write_text("e_badtex.obj", "mtllib e_badtex.mtl\n");
    expect_error("e_badtex.obj", "e_badtex.mtl", 2, "truncated");
    /* a numeric texture option without its number, and a bump strength whose normals would be NaN */
    write_text("e_optnum.mtl", "newmtl a\nbump -bm nan e_optnum.ppm\n");
    write_text("e_optnum.obj", "mtllib e_optnum.mtl\n");
    expect_error("e_optnum.obj", "e_optnum.mtl", 2, "-bm: expected a finite number, got 'nan'");
    write_text("e_opts.mtl", "newmtl a\nKd 1 1 1\nmap_Kd -s x 1 e_opts.ppm\n");
    write_text("e_opts.obj", "mtllib e_opts.mtl\n");
    expect_error("e_opts.obj", "e_opts.mtl", 3, "-s: expected a finite number, got 'x'");
    write_text("e_bumpbig.ppm", "P6\n2 2\n255\n\001\002\003\004\005\006\007\010\011\012\013\014");
    write_text("e_bumpbig.mtl", "newmtl a\n\nbump -bm 3e38 e_bumpbig.ppm\n");
    write_text("e_bumpbig.obj", "mtllib e_bumpbig.mtl\n");
    expect_error("e_bumpbig.obj", "e_bumpbig.mtl", 3, "too large");
    write_text("e_face.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n");
    expect_error("e_face.obj", "e_face.obj", 3, NULL);
    static const uint8_t junk[] = {0x7f, 'E', 'L', 'F', 2, 1, 1, 0, 0, 0, 0, 0, 0xff, 0xfe, '\n', 0x00, 0x13};
    write_bytes("e_junk.obj", junk, sizeof junk);
    expect_error("e_junk.obj", "e_junk.obj", 1, NULL);
    write_bytes("e_junk.nff", junk, sizeof junk);
    expect_error("e_junk.nff", "e_junk.nff", 1, NULL);
    write_bytes("e_junk.ply", junk, sizeof junk);
    expect_error("e_junk.ply", "e_junk.ply", 1, NULL);
    expect_error("does_not_exist.obj", "does_not_exist.obj", 0, "cannot open");

    /* truncated gzip: the first half of a compressed file */
    char path[1024];
    gzFile gz = gzopen(tmp_path("full.obj.gz", path, sizeof path), "wb");
    for (int i = 0; i < 2000; i++) gzprintf(gz, "v %d %d %d\n", i, i * 7 % 13, i * 3 % 11);
    gzclose(gz);
    FILE *f = fopen(path, "rb");
    uint8_t buf[65536];
    size_t n = f ? fread(buf, 1, sizeof buf, f) : 0;
    if (f) fclose(f);
    write_bytes("e_trunc.obj.gz", buf, n / 2);
    expect_error("e_trunc.obj.gz", "e_trunc.obj.gz", 0, NULL);

    /* PLY */
    const char *ply_head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                           "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    char text[2048];
    snprintf(text, sizeof text, "%s0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", ply_head);
    write_text("e_range.ply", text);
    expect_error("e_range.ply", "e_range.ply", 13, "out of range");
    snprintf(text, sizeof text, "%s0 0 0\n1 0 0\n0 1 0\n", ply_head);
    write_text("e_count.ply", text); /* face missing: element count larger than the data */
    /* refused at the element's header line, before reading (or allocating for) the records */
    expect_error("e_count.ply", "e_count.ply", 7, "more than the 0 bytes the file has left");
    snprintf(text, sizeof text, "%s0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n", ply_head);
    write_text("e_extra.ply", text); /* element count smaller than the data */
    expect_error("e_extra.ply", "e_extra.ply", 14, "after the last element");
    snprintf(text, sizeof text, "%s0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", ply_head);
    write_text("e_nan.ply", text);
    expect_error("e_nan.ply", "e_nan.ply", 11, NULL);
    write_text("e_head.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty flot x\nend_header\n");
    expect_error("e_head.ply", "e_head.ply", 4, "flot");
    write_binary_ply("full_le.ply", false);
    f = fopen(tmp_path("full_le.ply", path, sizeof path), "rb");
    n = f ? fread(buf, 1, sizeof buf, f) : 0;
    if (f) fclose(f);
    write_bytes("e_trunc.ply", buf, n - 9);
    expect_error("e_trunc.ply", "e_trunc.ply", 19, "truncated"); /* binary data: the line after end_header */

    /* NFF / AFF */
    write_text("e_trunc.nff", "f 1 1 1 1 0 0 0 0\np 4\n0 0 0\n1 0 0\n1 1 0\n");
    expect_error("e_trunc.nff", "e_trunc.nff", 6, "end of file");
    write_text("e_nan.nff", "s 0 0 0 1\ns 0 0\nnan 1\n");
    expect_error("e_nan.nff", "e_nan.nff", 3, "nan");
    write_text("e_cmd.nff", "s 0 0 0 1\n\nbogus 1 2 3\n");
    expect_error("e_cmd.nff", "e_cmd.nff", 3, "bogus");
    write_text("e_inc.aff", "l 0 0 0\n% comment\ni 0 not_there.aff\n");
    expect_error("e_inc.aff", "e_inc.aff", 3, "not_there.aff");
    write_text("e_inc2.aff", "s 0 0 0 1\n\n\ni 0 e_inc.aff\n");
    expect_error("e_inc2.aff", "e_inc.aff", 3, "not_there.aff"); /* the error is where the include is */
    write_text("e_loop.aff", "i 0 e_loop.aff\n");
    expect_error("e_loop.aff", "e_loop.aff", 1, "too deep");
    write_text("e_tex.aff", "fm 0 0 0 1 1 1 0 0 0 1 0 1\n\ntt nowhere.ppm\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n");
    expect_error("e_tex.aff", "e_tex.aff", 3, "nowhere.ppm");
    write_text("e_block.aff", "xs 1 1 1 0 0 1 0 0 0 0\n{\ns 0 0 0 1\n");
    expect_error("e_block.aff", "e_block.aff", 4, "line 1");
    write_text("e_close.aff", "s 0 0 0 1\n}\n");
    expect_error("e_close.aff", "e_close.aff", 2, NULL);
    write_text("e_mesh.aff", "m\nvertices 3\n0 0 0\n1 0 0\n0 1 0\ntriangles 1\n0 1 3\n");
    expect_error("e_mesh.aff", "e_mesh.aff", 7, "out of range");
    write_text("e_poly.nff", "p 2\n0 0 0\n1 0 0\n");
    expect_error("e_poly.nff", "e_poly.nff", 1, NULL);
    write_text("e_view.nff", "v\nfrom 0 0 0\nat 0 0 1\nangle 45\n\ns 0 0 0 1\n");
    expect_error("e_view.nff", "e_view.nff", 6, "viewpoint");
    write_text("e_ext.xyz", "hello\n");
    expect_error("e_ext.xyz", "e_ext.xyz", 0, "format");
}

/* Every prefix of valid files, and files with bytes overwritten, must load or fail cleanly. */
static void test_truncations(void) {
    static const char *names[] = {"groups.obj", "mesh_ascii.ply", "mesh_le.ply", "mesh_be.ply", "aff/scene.aff"};
    int failures_ok = 0;
    for (size_t k = 0; k < sizeof names / sizeof names[0]; k++) {
        char path[1024];
        FILE *f = fopen(tmp_path(names[k], path, sizeof path), "rb");
        if (!f) continue;
        static uint8_t data[8192];
        size_t n = fread(data, 1, sizeof data, f);
        fclose(f);
        char name[256], ext[16];
        const char *dot = strrchr(names[k], '.');
        snprintf(ext, sizeof ext, "%s", dot);
        /* beside the files they include (part.aff, mats.mtl) */
        snprintf(name, sizeof name, "%scut%s", strncmp(names[k], "aff/", 4) == 0 ? "aff/" : "", ext);
        for (size_t len = 0; len < n; len += 1 + len / 64) {
            write_bytes(name, data, len);
            rp_scene_data s;
            char err[512];
            if (rp_scene_data_load(tmp_path(name, path, sizeof path), &s, err, sizeof err)) {
                rp_scene_data_free(&s);
            } else {
                failures_ok += strstr(err, ": error: ") != NULL;
            }
        }
        uint32_t rng = 12345;
        for (int trial = 0; trial < 200; trial++) {
            static uint8_t mod[8192];
            memcpy(mod, data, n);
            for (int j = 0; j < 3; j++) {
                rng = rng * 1664525u + 1013904223u;
                mod[(rng >> 8) % n] = (uint8_t)(rng >> 24);
            }
            write_bytes(name, mod, n);
            rp_scene_data s;
            char err[512];
            if (rp_scene_data_load(tmp_path(name, path, sizeof path), &s, err, sizeof err)) rp_scene_data_free(&s);
        }
    }
    CHECK(failures_ok > 50);
}

/* ---- shared scenes ---------------------------------------------------------------------------- */

static void check_scene(const char *name, size_t tris, long spheres, long cones, long lights, long materials,
                        int camera) {
    char path[1024];
    if (!rp_test_scene(name, path, sizeof path)) {
        CHECKF(0, "missing scene %s", name);
        return;
    }
    rp_scene_data s;
    char err[1024];
    bool ok = rp_scene_data_load(path, &s, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    if (!ok) return;
    CHECKF(s.triangle_count == tris, "%s: %zu triangles, want %zu", name, s.triangle_count, tris);
    if (spheres >= 0) CHECKF(s.sphere_count == (size_t)spheres, "%s: %zu spheres", name, s.sphere_count);
    if (cones >= 0) CHECKF(s.cone_count == (size_t)cones, "%s: %zu cones", name, s.cone_count);
    if (lights >= 0) CHECKF(s.light_count == (size_t)lights, "%s: %zu lights", name, s.light_count);
    if (materials >= 0) CHECKF(s.material_count == (size_t)materials, "%s: %zu materials", name, s.material_count);
    if (camera >= 0) CHECKF(s.camera.valid == (camera != 0), "%s: camera %d", name, s.camera.valid);
    /* every index is in range */
    bool in_range = true;
    for (size_t i = 0; i < 3 * s.triangle_count; i++) {
        in_range &= s.indices[i] < s.vertex_count;
        if (s.normal_indices) in_range &= s.normal_indices[i] < s.normal_count;
        if (s.texcoord_indices) in_range &= s.texcoord_indices[i] < s.texcoord_count;
    }
    for (size_t i = 0; i < s.triangle_count; i++) in_range &= s.tri_materials[i] < s.material_count;
    for (size_t i = 0; i < s.material_count; i++) in_range &= s.materials[i].map_kd < (int32_t)s.texture_count;
    CHECKF(in_range, "%s: index out of range", name);
    printf("%-36s %8zu tris %7.1f MB %8.1f ms\n", name, s.triangle_count, (double)s.file_bytes / 1e6, s.parse_ms);
    rp_scene_data_free(&s);
}

/* Point clouds: vertices alone become spheres of the default material, half the neighbours'
 * spacing in radius unless the caller gives one; non-finite vertices none; a mesh none. */
static void test_points(void) {
    char text[8192], err[512];
    int at = snprintf(text, sizeof text, "ply\nformat ascii 1.0\nelement vertex 25\nproperty double x\n"
                                         "property double y\nproperty double z\nend_header\n");
    for (int i = 0; i < 25; i++) at += snprintf(text + at, sizeof text - (size_t)at, "%g %g 1\n", 0.5 * (i % 5), 0.5 * (i / 5));
    write_text("points.ply", text);
    rp_scene_data s;
    bool ok = load("points.ply", &s, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (ok) {
        CHECKF(s.triangle_count == 0 && s.sphere_count == 25 && s.material_count == 1, "%zu spheres", s.sphere_count);
        if (s.sphere_count == 25)
            CHECKF(s.spheres[7].radius == 0.25f && s.spheres[7].center[0] == 1.0f && s.spheres[7].center[1] == 0.5f &&
                       s.spheres[7].center[2] == 1.0f && s.spheres[7].material == 0,
                   "sphere 7: radius %g at %g %g %g", (double)s.spheres[7].radius, (double)s.spheres[7].center[0],
                   (double)s.spheres[7].center[1], (double)s.spheres[7].center[2]);
        rp_scene_data_free(&s);
    }
    char path[1024];
    ok = rp_scene_data_load_ex(tmp_path("points.ply", path, sizeof path), &(rp_scene_load_desc){.point_radius = 2.0f}, &s,
                               err, sizeof err);
    CHECKF(ok && s.sphere_count == 25 && s.spheres[24].radius == 2.0f, "point_radius 2: %s", err);
    if (ok) rp_scene_data_free(&s);
    /* an OBJ of v lines; a single point; a mesh */
    write_text("points.obj", "v 0 0 0\nv 3 0 0\nv 0 4 0\n");
    ok = load("points.obj", &s, err, sizeof err);
    CHECKF(ok && s.sphere_count == 3 && s.spheres[0].radius == 1.5f, "points.obj: %zu spheres, %s", s.sphere_count, err);
    if (ok) rp_scene_data_free(&s);
    write_text("point.obj", "v 2 0 0\n");
    ok = load("point.obj", &s, err, sizeof err);
    CHECKF(ok && s.sphere_count == 1 && s.spheres[0].radius > 0.0f, "point.obj: %s", err);
    if (ok) rp_scene_data_free(&s);
    write_text("tri_points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nf 1 2 3\n");
    ok = load("tri_points.obj", &s, err, sizeof err);
    CHECKF(ok && s.triangle_count == 1 && s.sphere_count == 0, "a mesh with a loose vertex: %s", err);
    if (ok) rp_scene_data_free(&s);
}

int main(void) {
    tmp_init("/tmp/rp_test_io");

    test_float_parsing();
    test_obj();
    test_ply();
    test_points();
    test_nff_concave();
    test_aff();
    test_aff_ambient();
    test_errors();
    test_truncations();

    check_scene("cornell_box/cornell_box.obj", 36, 0, 0, 0, 5, 0);
    check_scene("spd_teapot.nff.gz", 2328, 0, 0, 2, 3, 1);
    check_scene("stanford_bunny_bun_zipper.ply.gz", 69451, 0, 0, 0, 1, 0);
    check_scene("bart_museum5.tar.gz", 11308, 0, 8, 2, -1, 1);
    if (!rp_test_sanitized()) check_scene("dabrovic_sponza.obj.gz", 66454, 0, 0, 0, 1, 0);
    check_scene("pointcloud/open3d_sinc_grid.ply", 0, 160801, 0, 0, 1, 0);
    return RP_TEST_END();
}
