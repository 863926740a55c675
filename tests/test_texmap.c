/* Texture mapping that scene files ask for beyond a plain lookup: MTL bump maps (bump, map_bump
 * -bm: a height map made a tangent-space normal map at load time), MTL -s / -o and glTF's
 * KHR_texture_transform (the material's uv transform). Scenes are written to RP_TEST_TMP: a unit
 * quad in z = 0 facing +z with uv = (x, y), textures as PNGs. */
#include "rp_test.h"
#include "raypack_io.h"
#include "raypack_render.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char dir[512];
static rp_device *dev;

static const char *at(const char *name) {
    static char buf[4][800];
    static int k;
    k = (k + 1) % 4;
    snprintf(buf[k], sizeof buf[k], "%s/%s", dir, name);
    return buf[k];
}

static void write_text(const char *name, const char *text) {
    FILE *f = fopen(at(name), "w");
    CHECKF(f != NULL, "cannot write %s", name);
    if (!f) return;
    fputs(text, f);
    fclose(f);
}

/* A w x h PNG; texel(x, y, rgb) fills it, rows top first, values 0 or 1 (exact bytes 0 and 255). */
static void write_png(const char *name, int w, int h, void (*texel)(int x, int y, float rgb[3])) {
    float *px = malloc((size_t)w * (size_t)h * 3 * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) texel(x, y, px + 3 * ((size_t)y * (size_t)w + (size_t)x));
    char err[256];
    CHECKF(rp_image_write(at(name), w, h, 3, px, err, sizeof err), "%s", err);
    free(px);
}

/* 16 x 16 heights: stripes 4 texels wide along u, black and white */
static void stripes(int x, int y, float c[3]) {
    (void)y;
    c[0] = c[1] = c[2] = (float)((x / 4) & 1);
}
static void grey(int x, int y, float c[3]) {
    (void)x, (void)y;
    c[0] = c[1] = c[2] = 0.5f;
}
/* 8 x 8, quadrants of 4 x 4 texels: red top left, green top right, blue bottom left, white bottom right */
static void quadrants(int x, int y, float c[3]) {
    static const float q[4][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}};
    memcpy(c, q[(y >= 4) * 2 + (x >= 4)], 3 * sizeof(float));
}

/* The quad with material m of `mtl`, its uv running from (lo, lo) to (hi, hi). */
static void write_quad_obj_uv(const char *name, const char *mtl, int lo, int hi) {
    char text[512];
    snprintf(text, sizeof text,
             "mtllib %s\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt %d %d\nvt %d %d\nvt %d %d\nvt %d %d\nvn 0 0 1\n"
             "usemtl m\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n", mtl, lo, lo, hi, lo, hi, hi, lo, hi);
    write_text(name, text);
}

static void write_quad_obj(const char *name, const char *mtl) { write_quad_obj_uv(name, mtl, 0, 1); }

static void collect(void *user, const char *message) {
    char *text = user;
    size_t n = strlen(text);
    snprintf(text + n, 4096 - n, "%s\n", message);
}

static bool load(const char *name, rp_scene_data *d, char *warnings) {
    char err[1024];
    rp_scene_load_desc ld;
    rp_scene_load_desc_defaults(&ld);
    ld.warning = collect;
    ld.warning_user = warnings;
    warnings[0] = '\0';
    bool ok = rp_scene_data_load_ex(at(name), &ld, d, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    return ok;
}

/* The quad seen head on, filling the middle of a 64 x 64 image: pixel (x, y) sees uv about
 * ((x + 0.5) / 64 - 0.5) * 1.2 + 0.5 (v from the bottom). */
#define IMG 64
static float *render(const char *name, rp_integrator_type integ, int spp, bool light, const char *want_warning) {
    rp_scene_data d;
    char warnings[4096];
    if (!load(name, &d, warnings)) return NULL;
    if (want_warning) CHECKF(strstr(warnings, want_warning) != NULL, "%s: no warning '%s' in: %s", name, want_warning, warnings);
    else CHECKF(warnings[0] == '\0', "%s warns: %s", name, warnings);
    if (light) { /* a light grazing the quad from -x */
        d.lights = calloc(1, sizeof *d.lights);
        d.light_count = 1;
        d.lights[0] = (rp_light_data){.type = RP_LIGHT_DATA_POINT, .position = {-4.0f, 0.5f, 0.6f}, .color = {1, 1, 1}};
        if (integ != RP_INTEGRATOR_WHITTED) d.lights[0].color[0] = d.lights[0].color[1] = d.lights[0].color[2] = 20.0f;
    }
    char err[512];
    rp_render_scene *s = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    CHECKF(s != NULL, "%s", err);
    float *px = malloc(IMG * IMG * 3 * sizeof(float));
    rp_camera cam = {.type = RP_CAMERA_PINHOLE};
    float half = 0.6f;
    cam.pinhole = (rp_pinhole_camera){.eye = {0.5f, 0.5f, 3.0f}, .look = {0.5f, 0.5f, 0.0f}, .up = {0, 1, 0},
                                      .fov_deg = (float)(2.0 * atan(half / 3.0) * 57.29577951308232)};
    rp_render_desc rd = {.width = IMG, .height = IMG, .spp = spp, .integrator = integ, .camera = &cam,
                         .aov = RP_AOV_ALBEDO, .ambient = light ? -1.0f : 1.0f};
    bool ok = s && rp_render(s, &rd, px, NULL);
    CHECKF(ok, "%s: render failed", name);
    rp_render_scene_release(s);
    rp_scene_data_free(&d);
    if (!ok) {
        free(px);
        return NULL;
    }
    char png[600];
    snprintf(png, sizeof png, "%s.%d.png", at(name), (int)integ);
    rp_image_write(png, IMG, IMG, 3, px, err, sizeof err); /* to look at */
    return px;
}

/* The largest luminance step between neighbouring pixels along a row, in the quad's middle. */
static float max_step(const float *px) {
    float m = 0.0f;
    for (int y = 12; y < IMG - 12; y++)
        for (int x = 12; x < IMG - 13; x++) {
            const float *a = px + 3 * (y * IMG + x), *b = a + 3;
            float d = fabsf((a[0] + a[1] + a[2]) - (b[0] + b[1] + b[2])) / 3.0f;
            if (d > m) m = d;
        }
    return m;
}

/* The pixel that sees uv (u, v) of the quad. */
static const float *pixel_at(const float *px, float u, float v) {
    int x = (int)floorf(((u - 0.5f) / 1.2f + 0.5f) * IMG), y = (int)floorf((0.5f - (v - 0.5f) / 1.2f) * IMG);
    return px + 3 * (y * IMG + x);
}

static bool same_colour(const float *a, const float *b) {
    return fabsf(a[0] - b[0]) < 1e-4f && fabsf(a[1] - b[1]) < 1e-4f && fabsf(a[2] - b[2]) < 1e-4f;
}

static void test_bump(void) {
    write_png("stripes.png", 16, 16, stripes);
    write_png("grey.png", 16, 16, grey);
    write_text("plain.mtl", "newmtl m\nKd 0.8 0.8 0.8\n");
    write_text("bump.mtl", "newmtl m\nKd 0.8 0.8 0.8\nbump stripes.png\n");
    write_text("bumpbm.mtl", "newmtl m\nKd 0.8 0.8 0.8\nmap_bump -bm 0.25 stripes.png\n");
    write_text("flat.mtl", "newmtl m\nKd 0.8 0.8 0.8\nmap_Bump -bm 2 grey.png\n");
    write_quad_obj("plain.obj", "plain.mtl");
    write_quad_obj("bump.obj", "bump.mtl");
    write_quad_obj("bumpbm.obj", "bumpbm.mtl");
    write_quad_obj("flat.obj", "flat.mtl");

    /* the height map became a normal map: white stripe edges tilt the normal along -u and +u */
    rp_scene_data d;
    char warnings[4096];
    if (load("bump.obj", &d, warnings)) {
        int32_t n = d.materials[0].map_normal - 1;
        CHECKF(n >= 0 && (size_t)n < d.texture_count, "bump: no normal map (%d)", n);
        if (n >= 0 && (size_t)n < d.texture_count) {
            const rp_texture_data *t = &d.textures[n];
            CHECK(t->width == 16 && t->height == 16);
            /* texel 3 rises to 4 (0 -> 1 over two texels: dh/du 0.5, slope 2 x 0.5 = 1): n = (-1, 0, 1) / sqrt 2 */
            const uint8_t *p3 = t->rgb + 3 * 3, *p4 = t->rgb + 3 * 4, *p1 = t->rgb + 3 * 1;
            int want_x = (int)lrintf((-1.0f / sqrtf(2.0f) * 0.5f + 0.5f) * 255.0f);
            CHECKF(p3[0] == want_x && p4[0] == want_x && p3[1] == 128, "bump edge texel %d %d %d, want x %d", p3[0], p3[1], p3[2], want_x);
            CHECKF(p1[0] == 128 && p1[1] == 128 && p1[2] == 255, "flat texel %d %d %d", p1[0], p1[1], p1[2]);
            const uint8_t *p7 = t->rgb + 3 * 7; /* white falls to black: tilted the other way */
            CHECK(p7[0] > 200);
        }
        rp_scene_data_free(&d);
    }
    if (load("flat.obj", &d, warnings)) {
        CHECKF(d.materials[0].map_normal == 0, "a flat height map gives no normal map");
        rp_scene_data_free(&d);
    }

    /* Whitted and path tracing, light grazing from -x: the stripes' edges shade, the plain quad is smooth */
    rp_integrator_type kinds[2] = {RP_INTEGRATOR_WHITTED, RP_INTEGRATOR_PATH};
    for (int k = 0; k < 2; k++) {
        int spp = kinds[k] == RP_INTEGRATOR_WHITTED ? 1 : 4;
        float *plain = render("plain.obj", kinds[k], spp, true, NULL);
        float *bump = render("bump.obj", kinds[k], spp, true, NULL);
        float *weak = render("bumpbm.obj", kinds[k], spp, true, NULL);
        float *flat = render("flat.obj", kinds[k], spp, true, NULL);
        if (plain && bump && weak && flat) {
            float sp = max_step(plain), sb = max_step(bump), sw = max_step(weak);
            CHECKF(sb > 0.03f && sb > 20.0f * sp, "integrator %d: bump steps %g, plain %g", (int)kinds[k], sb, sp);
            CHECKF(sw > 2.0f * sp && sw < sb, "integrator %d: -bm 0.25 steps %g (bump %g, plain %g)", (int)kinds[k], sw, sb, sp);
            CHECKF(memcmp(flat, plain, IMG * IMG * 3 * sizeof(float)) == 0, "integrator %d: a flat bump map changes the image", (int)kinds[k]);
        }
        free(plain), free(bump), free(weak), free(flat);
    }

    /* norm wins over bump (warned); a bump map coloured like a normal map is read as one (Blender) */
    write_png("n.png", 4, 4, grey); /* grey: a normal of (0, 0, -1)... only its index matters here */
    write_text("both.mtl", "newmtl m\nKd 0.8 0.8 0.8\nbump stripes.png\nnorm n.png\n");
    write_quad_obj("both.obj", "both.mtl");
    if (load("both.obj", &d, warnings)) {
        CHECKF(strstr(warnings, "both.mtl:3: warning: material 'm' has both norm and a bump map") != NULL, "%s", warnings);
        CHECK(d.materials[0].map_normal > 0 && strcmp(d.textures[d.materials[0].map_normal - 1].path, "n.png") == 0);
        rp_scene_data_free(&d);
    }
}

static void bluish(int x, int y, float c[3]) {
    c[0] = 0.2f + 0.05f * (float)x, c[1] = 0.2f + 0.05f * (float)y, c[2] = 1.0f;
}

static void test_bump_normal_map(void) {
    write_png("blender_normal.png", 4, 4, bluish);
    write_text("blender.mtl", "newmtl m\nKd 0.8 0.8 0.8\nmap_Bump -bm 1.000000 blender_normal.png\n");
    write_quad_obj("blender.obj", "blender.mtl");
    rp_scene_data d;
    char warnings[4096];
    if (load("blender.obj", &d, warnings)) {
        CHECKF(strstr(warnings, "blender.mtl:3: warning: material 'm': the bump map is coloured like a tangent-space normal map") != NULL,
               "%s", warnings);
        CHECK(d.materials[0].map_normal > 0 && strcmp(d.textures[d.materials[0].map_normal - 1].path, "blender_normal.png") == 0);
        rp_scene_data_free(&d);
    }
}

/* -s 2 2 repeats the texture twice across the quad, -o 0.5 0 shifts it by half: the albedo of the
 * transformed quad at uv is the plain one's at the transformed uv (block interiors, away from the
 * bilinear blends at the quadrants' edges). */
static void test_mtl_transform(void) {
    write_png("quad.png", 8, 8, quadrants);
    write_text("tex.mtl", "newmtl m\nKd 1 1 1\nmap_Kd quad.png\n");
    write_text("tex_s.mtl", "newmtl m\nKd 1 1 1\nmap_Kd -s 2 2 1 quad.png\n");
    write_text("tex_o.mtl", "newmtl m\nKd 1 1 1\nmap_Kd -o 0.5 0 quad.png\n");
    write_text("tex_mixed.mtl", "newmtl m\nKd 1 1 1\nmap_Pr -s 3 3 quad.png\nmap_Kd -s 2 2 quad.png\n");
    write_quad_obj("tex.obj", "tex.mtl");
    write_quad_obj("tex_s.obj", "tex_s.mtl");
    write_quad_obj("tex_o.obj", "tex_o.mtl");
    write_quad_obj("tex_mixed.obj", "tex_mixed.mtl");
    rp_scene_data d;
    char warnings[4096];
    if (load("tex_s.obj", &d, warnings)) {
        const rp_material_data *m = &d.materials[0];
        CHECK(m->uv_transform && m->uv_matrix[0] == 2.0f && m->uv_matrix[4] == 2.0f && m->uv_matrix[2] == 0.0f);
        rp_scene_data_free(&d);
    }
    float *plain = render("tex.obj", RP_INTEGRATOR_AOV, 1, false, NULL);
    float *scaled = render("tex_s.obj", RP_INTEGRATOR_AOV, 1, false, NULL);
    float *shifted = render("tex_o.obj", RP_INTEGRATOR_AOV, 1, false, NULL);
    /* the map_Pr's -s 3 3 loses to map_Kd's */
    float *mixed = render("tex_mixed.obj", RP_INTEGRATOR_AOV, 1, false, "tex_mixed.mtl:3: warning: material 'm': this texture's -s/-o differ from those of line 4");
    if (plain && scaled && shifted && mixed) {
        static const float pts[] = {0.1f, 0.15f, 0.2f, 0.3f, 0.35f, 0.6f, 0.65f, 0.8f, 0.85f, 0.9f};
        int n = (int)(sizeof pts / sizeof pts[0]), bad_s = 0, bad_o = 0, bad_m = 0, differ = 0;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                float u = pts[i], v = pts[j];
                float su = 2 * u - floorf(2 * u), sv = 2 * v - floorf(2 * v), ou = u + 0.5f - floorf(u + 0.5f);
                /* away from the quadrant edges (0, 0.5, 1) of the looked-up uv */
                bool inner_s = fabsf(su - 0.5f) > 0.07f && su > 0.07f && su < 0.93f && fabsf(sv - 0.5f) > 0.07f && sv > 0.07f && sv < 0.93f;
                bool inner_o = fabsf(ou - 0.5f) > 0.07f && ou > 0.07f && ou < 0.93f && fabsf(v - 0.5f) > 0.07f;
                if (inner_s) bad_s += !same_colour(pixel_at(scaled, u, v), pixel_at(plain, su, sv));
                if (inner_s) bad_m += !same_colour(pixel_at(mixed, u, v), pixel_at(plain, su, sv));
                if (inner_o) bad_o += !same_colour(pixel_at(shifted, u, v), pixel_at(plain, ou, v));
                differ += !same_colour(pixel_at(scaled, u, v), pixel_at(plain, u, v));
            }
        CHECKF(bad_s == 0 && bad_m == 0 && bad_o == 0, "-s 2 2: %d, mixed: %d, -o 0.5 0: %d pixels not the plain render's", bad_s, bad_m, bad_o);
        CHECKF(differ > 10, "-s 2 2 looks like the plain texture (%d pixels differ)", differ);
        /* the plain texture's quadrants where the quad's are: red top left, white bottom right */
        const float *tl = pixel_at(plain, 0.2f, 0.8f), *br = pixel_at(plain, 0.8f, 0.2f);
        CHECKF(tl[0] > 0.99f && tl[1] < 0.01f && br[1] > 0.99f && br[2] > 0.99f, "plain texture upside down?");
    }
    free(plain), free(scaled), free(shifted), free(mixed);
}

/* A glTF of the quad with texture `image`, its uv running from lo to hi as the OBJ's would (glTF's
 * t is 1 - v: the texture lands as in the OBJ); transform: the members of a KHR_texture_transform,
 * sampler: those of the texture's sampler (on line 5 of the file), NULL for none. Its buffer is
 * name.bin. */
static void write_gltf_quad(const char *name, const char *image, float lo, float hi, const char *transform,
                            const char *sampler) {
    /* positions (4 vec3), uvs (4 vec2), indices (6 u16) */
    const float pos[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}, uv[8] = {lo, 1 - lo, hi, 1 - lo, hi, 1 - hi, lo, 1 - hi};
    const uint16_t idx[6] = {0, 1, 2, 0, 2, 3};
    char bin[256];
    snprintf(bin, sizeof bin, "%s.bin", name);
    FILE *f = fopen(at(bin), "wb");
    if (f) {
        fwrite(pos, sizeof pos, 1, f);
        fwrite(uv, sizeof uv, 1, f);
        fwrite(idx, sizeof idx, 1, f);
        fclose(f);
    }
    char text[4096], ext[512] = "", smp[512] = "";
    if (transform) snprintf(ext, sizeof ext, ",\"extensions\":{\"KHR_texture_transform\":{%s}}", transform);
    if (sampler) snprintf(smp, sizeof smp, ",\"sampler\":0}],\n\"samplers\":[{%s", sampler);
    snprintf(text, sizeof text,
             "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_texture_transform\"],\n"
             "\"materials\":[{\"name\":\"m\",\"pbrMetallicRoughness\":{\"metallicFactor\":0,\"baseColorTexture\":{\"index\":0%s}}}],\n"
             "\"images\":[{\"uri\":\"%s\"}],\n"
             "\"textures\":[{\"source\":0%s}],\n"
             "\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],\n"
             "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"indices\":2,\"material\":0}]}],\n"
             "\"buffers\":[{\"uri\":\"%s\",\"byteLength\":92}],\n"
             "\"bufferViews\":[{\"buffer\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":32},{\"buffer\":0,\"byteOffset\":80,\"byteLength\":12}],\n"
             "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,1,0]},\n"
             "  {\"bufferView\":1,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},\n"
             "  {\"bufferView\":2,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]}\n",
             ext, image, sampler ? smp : "", bin);
    write_text(name, text);
}

/* glTF KHR_texture_transform: the quad with glTF's uv (x, 1 - y) so that the plain texture lands
 * as in the OBJ; scale 2 repeats it, offset 0.5 shifts it, rotation pi/2 with offset (0, 1) turns
 * it a quarter clockwise (the extension's own example: the top left corner shows the image's bottom
 * left). */
static void write_gltf(const char *name, const char *transform) { write_gltf_quad(name, "quad.png", 0, 1, transform, NULL); }

static void test_gltf_transform(void) {
    rp_scene_data probe;
    char err[256];
    write_gltf("plain.gltf", NULL);
    if (!rp_scene_data_load(at("plain.gltf"), &probe, err, sizeof err) && strstr(err, "without assimp")) {
        printf("built without assimp: glTF skipped\n");
        return;
    }
    rp_scene_data_free(&probe);
    float *obj = render("tex.obj", RP_INTEGRATOR_AOV, 1, false, NULL);
    float *plain = render("plain.gltf", RP_INTEGRATOR_AOV, 1, false, NULL);
    write_gltf("scaled.gltf", "\"scale\":[2,2]");
    float *scaled = render("scaled.gltf", RP_INTEGRATOR_AOV, 1, false, NULL);
    write_gltf("shifted.gltf", "\"offset\":[0.5,0]");
    float *shifted = render("shifted.gltf", RP_INTEGRATOR_AOV, 1, false, NULL);
    write_gltf("turned.gltf", "\"offset\":[0,1],\"rotation\":1.57079632679");
    float *turned = render("turned.gltf", RP_INTEGRATOR_AOV, 1, false, NULL);
    float *ref_s = render("tex_s.obj", RP_INTEGRATOR_AOV, 1, false, NULL);
    float *ref_o = render("tex_o.obj", RP_INTEGRATOR_AOV, 1, false, NULL);
    if (obj && plain && scaled && shifted && turned && ref_s && ref_o) {
        static const float pts[] = {0.15f, 0.35f, 0.65f, 0.85f};
        int bad_p = 0, bad_s = 0, bad_o = 0;
        for (int i = 0; i < 4; i++)
            for (int j = 0; j < 4; j++) {
                float u = pts[i], v = pts[j];
                bad_p += !same_colour(pixel_at(plain, u, v), pixel_at(obj, u, v));
                bad_s += !same_colour(pixel_at(scaled, u, v), pixel_at(ref_s, u, v));
                bad_o += !same_colour(pixel_at(shifted, u, v), pixel_at(ref_o, u, v));
            }
        CHECKF(bad_p == 0 && bad_s == 0 && bad_o == 0, "glTF against the OBJ: plain %d, scale 2: %d, offset 0.5: %d pixels differ",
               bad_p, bad_s, bad_o);
        /* a quarter turn clockwise: top left blue (the image's bottom left), top right red, bottom right green, bottom left white */
        const float *tl = pixel_at(turned, 0.2f, 0.8f), *tr = pixel_at(turned, 0.8f, 0.8f), *br = pixel_at(turned, 0.8f, 0.2f),
                    *bl = pixel_at(turned, 0.2f, 0.2f);
        CHECKF(tl[2] > 0.99f && tl[0] < 0.01f && tr[0] > 0.99f && tr[1] < 0.01f && br[1] > 0.99f && br[0] < 0.01f && bl[0] > 0.99f && bl[1] > 0.99f,
               "rotation: tl %g %g %g, tr %g %g %g, br %g %g %g, bl %g %g %g", tl[0], tl[1], tl[2], tr[0], tr[1], tr[2], br[0], br[1], br[2],
               bl[0], bl[1], bl[2]);
    }
    free(obj), free(plain), free(scaled), free(shifted), free(turned), free(ref_s), free(ref_o);
}

/* MTL map_Ks multiplies Ks as map_Kd does Kd: a highlight-only quad (Kd 0, Ks 1, a broad Ns 1) lit
 * from the eye shows the quadrants' colours, in Whitted and path tracing, where the untextured one
 * is white. */
static void test_map_ks(void) {
    write_text("ks.mtl", "newmtl m\nKd 0 0 0\nKs 1 1 1\nNs 1\nmap_Ks quad.png\n");
    write_text("ks_plain.mtl", "newmtl m\nKd 0 0 0\nKs 1 1 1\nNs 1\n");
    write_quad_obj("ks.obj", "ks.mtl");
    write_quad_obj("ks_plain.obj", "ks_plain.mtl");
    rp_integrator_type kinds[2] = {RP_INTEGRATOR_WHITTED, RP_INTEGRATOR_PATH};
    for (int k = 0; k < 2; k++) {
        float *tex = render("ks.obj", kinds[k], 4, true, NULL), *plain = render("ks_plain.obj", kinds[k], 4, true, NULL);
        if (tex && plain) {
            static const float uv[4][2] = {{0.2f, 0.8f}, {0.8f, 0.8f}, {0.2f, 0.2f}, {0.8f, 0.2f}};
            static const float want[4][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}};
            for (int q = 0; q < 4; q++) {
                const float *a = pixel_at(tex, uv[q][0], uv[q][1]), *b = pixel_at(plain, uv[q][0], uv[q][1]);
                bool ok = b[0] > 0.01f;
                for (int c = 0; c < 3; c++) ok &= fabsf(a[c] - want[q][c] * b[c]) <= 0.02f * b[c] + 1e-6f;
                CHECKF(ok, "integrator %d, quadrant %d: %g %g %g, untextured %g %g %g", (int)kinds[k], q, a[0], a[1], a[2], b[0], b[1], b[2]);
            }
        }
        free(tex), free(plain);
    }
}

/* ---- samplers: wrap modes and filters (glTF samplers, MTL -clamp), MTL -mm ---- */

enum { WRAP_REPEAT, WRAP_CLAMP, WRAP_MIRROR };

/* 4 x 4, every texel its own colour: red along x, green along y, blue a pattern */
static void ramp(int x, int y, float c[3]) {
    c[0] = (float)x / 3.0f, c[1] = (float)y / 3.0f, c[2] = (float)((x * 3 + y * 5) % 4) / 3.0f;
}

static float srgb_decode(uint8_t b) {
    float c = (float)b / 255.0f;
    return c <= 0.04045f ? c / 12.92f : powf((c + 0.055f) / 1.055f, 2.4f);
}

/* Texel index i wrapped into [0, n), as OpenGL's wrap modes define it for texel indices. */
static int ref_wrap(int i, int n, int mode) {
    if (mode == WRAP_CLAMP) return i < 0 ? 0 : i >= n ? n - 1 : i;
    if (mode == WRAP_MIRROR) {
        int m = ((i % (2 * n)) + 2 * n) % (2 * n);
        return m < n ? m : 2 * n - 1 - m;
    }
    return ((i % n) + n) % n;
}

/* The reference lookup (linear RGB) of 8-bit sRGB texels at (u, v), v up: texel coordinates
 * s = u w, t = (1 - v) h (rows run down), NEAREST the texel they fall in, else the bilinear blend
 * of the four around s - 1/2, t - 1/2; texel indices wrapped by ref_wrap. */
static void ref_lookup(const uint8_t *rgb, int w, int h, int wrap_u, int wrap_v, bool nearest, double u, double v,
                       float out[3]) {
    double s = u * w, t = (1.0 - v) * h;
    int i0, j0;
    double a = 0.0, b = 0.0;
    if (nearest) {
        i0 = (int)floor(s), j0 = (int)floor(t);
    } else {
        i0 = (int)floor(s - 0.5), j0 = (int)floor(t - 0.5);
        a = s - 0.5 - i0, b = t - 0.5 - j0;
    }
    for (int c = 0; c < 3; c++) {
        double sum = 0.0;
        for (int k = 0; k < 4; k++) {
            int i = ref_wrap(i0 + (k & 1), w, wrap_u), j = ref_wrap(j0 + (k >> 1), h, wrap_v);
            double wt = ((k & 1) ? a : 1.0 - a) * ((k >> 1) ? b : 1.0 - b);
            if (wt != 0.0) sum += wt * srgb_decode(rgb[3 * (j * w + i) + c]);
        }
        out[c] = (float)sum;
    }
}

/* Pixels of a 64 x 64 albedo render of the quad (uv from -1 to 2) that are not the reference
 * lookup's at the uv they see (within 1e-4; 1e-5 NEAREST, which reads texels as they are), away
 * from the quad's edges and, NEAREST, texel edges (where the renderer's uv and this one's round to
 * either side); *checked: how many were compared. */
static int wide_mismatches(const float *px, const uint8_t *rgb, int w, int h, int wrap_u, int wrap_v, bool nearest,
                           int *checked) {
    int bad = 0;
    *checked = 0;
    for (int y = 0; y < IMG; y++)
        for (int x = 0; x < IMG; x++) {
            double qx = ((x + 0.5) / IMG - 0.5) * 1.2 + 0.5, qy = 0.5 - ((y + 0.5) / IMG - 0.5) * 1.2;
            if (qx < 0.002 || qx > 0.998 || qy < 0.002 || qy > 0.998) continue;
            double u = -1.0 + 3.0 * qx, v = -1.0 + 3.0 * qy, s = u * w, t = (1.0 - v) * h;
            if (nearest && (fabs(s - floor(s + 0.5)) < 0.02 || fabs(t - floor(t + 0.5)) < 0.02)) continue;
            float want[3];
            ref_lookup(rgb, w, h, wrap_u, wrap_v, nearest, u, v, want);
            const float *got = px + 3 * (y * IMG + x);
            float tol = nearest ? 1e-5f : 1e-4f;
            bool ok = fabsf(got[0] - want[0]) <= tol && fabsf(got[1] - want[1]) <= tol && fabsf(got[2] - want[2]) <= tol;
            if (!ok && bad < 3)
                printf("  pixel %d %d (uv %.4f %.4f): %g %g %g, want %g %g %g\n", x, y, u, v, got[0], got[1], got[2], want[0],
                       want[1], want[2]);
            bad += !ok;
            ++*checked;
        }
    return bad;
}

/* The quad with uv from -1 to 2 over a 4 x 4 texture shows it as each sampler says: glTF's repeat
 * (no sampler), CLAMP_TO_EDGE, MIRRORED_REPEAT, the two axes apart, magFilter NEAREST; MTL's
 * -clamp on is glTF's CLAMP_TO_EDGE; -mm 0.5 0.5 maps every stored value c to 0.5 + 0.5 c (half the
 * contrast), and alpha cut-outs read their texture under its sampler. */
static void test_samplers(void) {
    write_png("ramp.png", 4, 4, ramp);
    write_text("ramp.mtl", "newmtl m\nKd 1 1 1\nmap_Kd ramp.png\n");
    write_text("ramp_clamp.mtl", "newmtl m\nKd 1 1 1\nmap_Kd -clamp on ramp.png\n");
    write_text("ramp_mm.mtl", "newmtl m\nKd 1 1 1\nmap_Kd -mm 0.5 0.5 ramp.png\n");
    write_quad_obj_uv("ramp.obj", "ramp.mtl", -1, 2);
    write_quad_obj_uv("ramp_clamp.obj", "ramp_clamp.mtl", -1, 2);
    write_quad_obj_uv("ramp_mm.obj", "ramp_mm.mtl", -1, 2);
    rp_scene_data d;
    char warnings[4096];
    uint8_t texels[48], mm[48];
    if (!load("ramp.obj", &d, warnings)) return;
    bool ok = d.texture_count == 1 && d.textures[0].width == 4 && d.textures[0].height == 4;
    CHECK(ok);
    if (ok) memcpy(texels, d.textures[0].rgb, sizeof texels);
    rp_scene_data_free(&d);
    if (!ok) return;
    /* -mm 0.5 0.5: the texel bytes, remapped, in a texture of its own */
    if (load("ramp_mm.obj", &d, warnings)) {
        int32_t k = d.materials[0].map_kd;
        ok = k >= 0 && (size_t)k < d.texture_count && d.textures[k].width == 4;
        CHECKF(ok && warnings[0] == '\0', "-mm: texture %d, warnings %s", k, warnings);
        int lo = 255, hi = 0, mlo = 255, mhi = 0, bad = 0;
        for (int i = 0; ok && i < 48; i++) {
            mm[i] = d.textures[k].rgb[i];
            bad += abs(mm[i] - (int)lrint(127.5 + 0.5 * texels[i])) > 1;
            lo = texels[i] < lo ? texels[i] : lo, hi = texels[i] > hi ? texels[i] : hi;
            mlo = mm[i] < mlo ? mm[i] : mlo, mhi = mm[i] > mhi ? mm[i] : mhi;
        }
        CHECKF(ok && bad == 0 && abs(2 * (mhi - mlo) - (hi - lo)) <= 2, "-mm 0.5 0.5: %d texels off; range %d-%d, was %d-%d", bad,
               mlo, mhi, lo, hi);
        rp_scene_data_free(&d);
        if (!ok) return;
    }

    struct {
        const char *file, *sampler;
        int wrap_u, wrap_v;
        bool nearest;
        const uint8_t *rgb;
    } cases[] = {
        {"wide.gltf", NULL, WRAP_REPEAT, WRAP_REPEAT, false, texels},
        {"wide_clamp.gltf", "\"wrapS\":33071,\"wrapT\":33071", WRAP_CLAMP, WRAP_CLAMP, false, texels},
        {"wide_mirror.gltf", "\"wrapS\":33648,\"wrapT\":33648,\"magFilter\":9729", WRAP_MIRROR, WRAP_MIRROR, false, texels},
        {"wide_clamp_mirror.gltf", "\"wrapS\":33071,\"wrapT\":33648", WRAP_CLAMP, WRAP_MIRROR, false, texels},
        {"wide_nearest.gltf", "\"magFilter\":9728,\"minFilter\":9728", WRAP_REPEAT, WRAP_REPEAT, true, texels},
        {"wide_mirror_clamp_nearest.gltf", "\"wrapS\":33648,\"wrapT\":33071,\"magFilter\":9728", WRAP_MIRROR, WRAP_CLAMP, true, texels},
        {"ramp.obj", NULL, WRAP_REPEAT, WRAP_REPEAT, false, texels},
        {"ramp_clamp.obj", NULL, WRAP_CLAMP, WRAP_CLAMP, false, texels},
        {"ramp_mm.obj", NULL, WRAP_REPEAT, WRAP_REPEAT, false, mm},
    };
    enum { NCASES = sizeof cases / sizeof cases[0] };
    float *img[NCASES];
    bool gltf = true;
    for (int c = 0; c < NCASES; c++) {
        img[c] = NULL;
        bool is_gltf = strstr(cases[c].file, ".gltf") != NULL;
        if (is_gltf) write_gltf_quad(cases[c].file, "ramp.png", -1, 2, NULL, cases[c].sampler);
        if (c == 0) { /* built without assimp: the glTF cases are skipped */
            char err[256];
            gltf = rp_scene_data_load(at(cases[c].file), &d, err, sizeof err);
            if (gltf) rp_scene_data_free(&d);
            else printf("built without assimp? %s: glTF skipped\n", err);
        }
        if (is_gltf && !gltf) continue;
        img[c] = render(cases[c].file, RP_INTEGRATOR_AOV, 1, false, NULL);
        if (!img[c]) continue;
        int checked, bad = wide_mismatches(img[c], cases[c].rgb, 4, 4, cases[c].wrap_u, cases[c].wrap_v, cases[c].nearest, &checked);
        CHECKF(bad == 0 && checked > 1500, "%s: %d of %d pixels are not the reference lookup's", cases[c].file, bad, checked);
        if (cases[c].nearest) { /* texel-exact blocks: every pixel of the quad is one texel's colour */
            int blends = 0;
            for (int y = 10; y < IMG - 10; y++)
                for (int x = 10; x < IMG - 10; x++) {
                    const float *p = img[c] + 3 * (y * IMG + x);
                    bool texel = false;
                    for (int i = 0; i < 16 && !texel; i++)
                        texel = fabsf(p[0] - srgb_decode(texels[3 * i])) <= 1e-5f && fabsf(p[1] - srgb_decode(texels[3 * i + 1])) <= 1e-5f &&
                                fabsf(p[2] - srgb_decode(texels[3 * i + 2])) <= 1e-5f;
                    blends += !texel;
                }
            CHECKF(blends == 0, "%s: %d pixels are not a texel's colour", cases[c].file, blends);
        }
    }
    /* MTL -clamp on is glTF's CLAMP_TO_EDGE */
    if (img[1] && img[7]) {
        int differ = 0;
        for (int i = 0; i < IMG * IMG; i++) differ += !same_colour(img[1] + 3 * i, img[7] + 3 * i);
        CHECKF(differ == 0, "-clamp on and CLAMP_TO_EDGE differ in %d pixels", differ);
    }
    for (int c = 0; c < NCASES; c++) free(img[c]);

    /* alpha cut-outs read the mask under its sampler: -clamp on a mask cut on its left half cuts the
     * quad's left half (u < 0.5), where repeating it would leave u in [-0.5, 0) standing */
    write_text("cut.mtl", "newmtl m\nKd 1 1 1\nmap_d -clamp on stripes.png\n");
    write_text("cut_repeat.mtl", "newmtl m\nKd 1 1 1\nmap_d stripes.png\n");
    write_quad_obj_uv("cut.obj", "cut.mtl", -1, 2);
    write_quad_obj_uv("cut_repeat.obj", "cut_repeat.mtl", -1, 2);
    float *cut = render("cut.obj", RP_INTEGRATOR_AOV, 1, false, NULL), *rep = render("cut_repeat.obj", RP_INTEGRATOR_AOV, 1, false, NULL);
    if (cut && rep) {
        /* stripes.png: 16 texels, black (cut) for x in [0, 4) and [8, 12): u in [0, 0.25) and [0.5, 0.75) */
        const float q_at = (-0.125f + 1.0f) / 3.0f; /* u = -0.125: clamped to texel 0 (cut); repeated, u 0.875 (white) */
        const float *c = pixel_at(cut, q_at, 0.5f), *r = pixel_at(rep, q_at, 0.5f);
        CHECKF(c[0] == 0.0f && r[0] > 0.9f, "map_d -clamp on at u -0.125: %g (want cut), repeated %g (want kept)", c[0], r[0]);
        const float q_in = (0.875f + 1.0f) / 3.0f; /* u = 0.875 inside the image: kept either way */
        CHECK(pixel_at(cut, q_in, 0.5f)[0] > 0.9f && pixel_at(rep, q_in, 0.5f)[0] > 0.9f);
    }
    free(cut), free(rep);
}

/* Malformed samplers and options: an unknown glTF wrap mode or filter warns naming the file and
 * the line (read as REPEAT, LINEAR); -clamp with another word than on/off and -mm without a number
 * are errors at their line. */
static void test_sampler_errors(void) {
    rp_scene_data d;
    char warnings[4096], err[512];
    write_gltf_quad("bad_wrap.gltf", "ramp.png", -1, 2, NULL, "\"wrapS\":12345,\"magFilter\":1");
    if (rp_scene_data_load(at("bad_wrap.gltf"), &d, err, sizeof err)) {
        rp_scene_data_free(&d);
        if (load("bad_wrap.gltf", &d, warnings)) {
            CHECKF(strstr(warnings, "bad_wrap.gltf:5: warning: sampler 0: wrapS is not a glTF wrap mode") != NULL &&
                       strstr(warnings, "bad_wrap.gltf:5: warning: sampler 0: magFilter is not a glTF texture filter") != NULL,
                   "%s", warnings);
            CHECK(d.texture_count == 1 && d.textures[0].wrap_u == RP_TEXTURE_REPEAT && d.textures[0].filter == RP_TEXTURE_LINEAR);
            rp_scene_data_free(&d);
        }
    }
    static const char *const bad[][2] = {
        {"map_Kd -clamp maybe ramp.png", "bad.mtl:3: error: map_Kd option -clamp: expected on or off, got 'maybe'"},
        {"map_d -clamp ramp.png", "bad.mtl:3: error: map_d option -clamp: expected on or off, got 'ramp.png'"},
        {"map_Kd -mm ramp.png", "bad.mtl:3: error: map_Kd option -mm: expected a finite number, got 'ramp.png'"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char mtl[256];
        snprintf(mtl, sizeof mtl, "newmtl m\nKd 1 1 1\n%s\n", bad[i][0]);
        write_text("bad.mtl", mtl);
        write_quad_obj("bad.obj", "bad.mtl");
        bool loaded = rp_scene_data_load(at("bad.obj"), &d, err, sizeof err);
        if (loaded) rp_scene_data_free(&d);
        CHECKF(!loaded && strstr(err, bad[i][1]) != NULL, "'%s': %s", bad[i][0], loaded ? "loaded" : err);
    }
}

int main(void) {
    const char *tmp = getenv("RP_TEST_TMP");
    snprintf(dir, sizeof dir, "%s", tmp ? tmp : "/tmp/rp_test_texmap");
    char cmd[600];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
    CHECK(system(cmd) == 0);
    dev = rp_device_new(NULL);
    test_bump();
    test_bump_normal_map();
    test_mtl_transform();
    test_gltf_transform();
    test_map_ks();
    test_samplers();
    test_sampler_errors();
    rp_device_release(dev);
    return RP_TEST_END();
}
