// rp-test: labels=cli timeout=300
/* `raypack render --engine stream` and `raypack bench --stream [--purcell]`: the stream engine's
 * image (PFM) equals `--integrator eyelight`'s value for value; the bench checks the grid's hits
 * against the BVH's and prints the statistics and the paper's table; Whitted (cornell_box, spd_teapot,
 * bart_museum5), path tracing and AO (cornell_original) on the stream write the packet renderer's
 * PFM and PNG byte for byte, with statistics per ray kind; bad input exits 2 (usage) or
 * 1 (a scene that cannot be loaded) with a message. The binary is build/<preset>/raypack, or $RP_CLI. */
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "raypack_io.h"
#include "cli_run.h"
#include "rp_test.h"

static char tmp[1024];

/* The two files hold the same bytes. */
static bool same_file(const char *a, const char *b) {
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    bool same = fa && fb;
    while (same) {
        int ca = fgetc(fa), cb = fgetc(fb);
        same = ca == cb;
        if (ca == EOF || cb == EOF) break;
    }
    if (fa) fclose(fa);
    if (fb) fclose(fb);
    return same;
}

/* `render --engine stream FLAGS` and `render FLAGS` (the packet renderer) write the same PFM and
 * PNG bytes; the stream's statistics name the ray kinds it traced. */
static void check_same(const char *scene, const char *flags, const char *kind_line) {
    char args[4096], a[1200], b[1200];
    static const char *exts[] = {"pfm", "png"};
    for (int e = 0; e < 2; e++) {
        snprintf(a, sizeof a, "%s/stream.%s", tmp, exts[e]);
        snprintf(b, sizeof b, "%s/packet.%s", tmp, exts[e]);
        snprintf(args, sizeof args, "render '%s' --engine stream %s --stats -o '%s'", scene, flags, a);
        EXPECT(args, 0, kind_line);
        CHECKF(strstr(output, "passes   total") != NULL, "%s %s: no statistics", scene, flags);
        snprintf(args, sizeof args, "render '%s' %s -q -o '%s'", scene, flags, b);
        EXPECT(args, 0, "");
        CHECKF(same_file(a, b), "%s %s: the stream's %s differs from the packet renderer's", scene, flags, exts[e]);
    }
}

static float *read_pfm(const char *path, int *w, int *h) {
    int c = 0;
    char err[256];
    float *px = rp_image_read_pfm(path, w, h, &c, err, sizeof err);
    CHECKF(px != NULL && c == 3, "%s: %s", path, px ? "channels" : err);
    return px;
}

int main(void) {
    if (!find_exe()) {
        fprintf(stderr, "raypack binary not found at %s\n", exe);
        CHECK(!"raypack binary built");
        return RP_TEST_END();
    }
    const char *dir = getenv("RP_TEST_TMP");
    snprintf(tmp, 900, "%s", dir ? dir : "/tmp/raypack_test_stream_cli");
    mkdir(tmp, 0777);
    char args[4096], b1[512], b2[512];
    const char *cornell = rp_test_scene("cornell_box/cornell_box.obj", b1, sizeof b1);
    const char *bunny = rp_test_scene("stanford_bunny_bun_zipper.ply.gz", b2, sizeof b2);
    CHECK(cornell && bunny);
    if (!cornell || !bunny) return RP_TEST_END();

    EXPECT("render --engine stream --help", 0, "--min-dim");
    EXPECT("bench --stream --help", 0, "--purcell");
    EXPECT("render --engine stream", 2, "needs a SCENE");
    EXPECT("render x.obj --engine warp", 2, "--engine expects stream");
    snprintf(args, sizeof args, "render '%s' --engine stream --shading whitted", cornell);
    EXPECT(args, 2, "shades eyelight or shadow");
    snprintf(args, sizeof args, "render '%s' --engine stream --density 0", cornell);
    EXPECT(args, 2, "--density expects");
    snprintf(args, sizeof args, "render '%s/none.obj' --engine stream", tmp);
    EXPECT(args, 1, "none.obj");

    /* the image of the eyelight integrator, value for value, from a camera of our own */
    const char *cam = "--eye 278,273,-500 --look 278,273,0 --fov 50 --width 61 --height 47";
    snprintf(args, sizeof args, "render '%s' --engine stream --stats %s -o '%s/stream.pfm'", cornell, cam, tmp);
    EXPECT(args, 0, "passes   total");
    snprintf(args, sizeof args, "render '%s' --integrator eyelight %s -o '%s/packet.pfm' -q", cornell, cam, tmp);
    EXPECT(args, 0, "");
    int w1 = 0, h1 = 0, w2 = 0, h2 = 0;
    snprintf(args, sizeof args, "%s/stream.pfm", tmp);
    float *a = read_pfm(args, &w1, &h1);
    snprintf(args, sizeof args, "%s/packet.pfm", tmp);
    float *b = read_pfm(args, &w2, &h2);
    CHECK(a && b && w1 == 61 && h1 == 47 && w2 == w1 && h2 == h1);
    if (a && b && w1 == w2 && h1 == h2) {
        size_t diff = 0, lit = 0;
        for (size_t i = 0; i < (size_t)w1 * (size_t)h1 * 3; i++) diff += memcmp(&a[i], &b[i], 4) != 0, lit += a[i] > 0.0f;
        CHECKF(diff == 0 && lit > 1000, "%zu values differ, %zu lit", diff, lit);
    }
    free(a), free(b);
    snprintf(args, sizeof args, "render '%s' --engine stream --shading shadow --width 40 -o '%s/shadow.png'", cornell, tmp);
    EXPECT(args, 0, "shadow shading");

    /* the renderer's integrators on the stream: the packet renderer's files byte for byte */
    char b3[512], b4[512], b5[512];
    const char *original = rp_test_scene("cornell_original/CornellBox-Original.obj", b3, sizeof b3);
    const char *teapot = rp_test_scene("spd_teapot.nff.gz", b4, sizeof b4);
    const char *museum = rp_test_scene("bart_museum5.tar.gz", b5, sizeof b5);
    CHECK(original && teapot && museum);
    if (original && teapot && museum) {
        check_same(cornell, "--integrator whitted --width 40 --height 30", "\nshadow ");
        check_same(teapot, "--integrator whitted --width 48 --height 36 --spp 2", "\nreflection ");
        check_same(museum, "--integrator whitted --width 48 --height 36 --anim-flat", "\nreflection ");
        check_same(original, "--integrator path --width 24 --height 24 --spp 3 --max-depth 4", "\nbounce ");
        check_same(original, "--integrator ao --width 24 --height 24 --spp 2", "\nshadow ");
    }
    snprintf(args, sizeof args, "render '%s' --engine stream --integrator ir", cornell);
    EXPECT(args, 2, "whitted, path, direct or ao");
    snprintf(args, sizeof args, "render '%s' --engine stream --integrator path --spp 0", cornell);
    EXPECT(args, 2, "--spp");
    snprintf(args, sizeof args, "render '%s' --engine stream --integrator path --sampler halton", cornell);
    EXPECT(args, 2, "--sampler expects pcg or sobol");

    /* bench: hits checked against the BVH, the statistics and the paper's table */
    snprintf(args, sizeof args, "bench '%s' --stream --purcell --width 64 --height 64", bunny);
    EXPECT(args, 0, "0 of 4096 hits differ");
    CHECK(strstr(output, "passes total") && strstr(output, "SIMD efficiency") && strstr(output, "1085") &&
          strstr(output, "grid/BVH time") && strstr(output, "64 along") == NULL);
    /* the eye hits' shadow and reflection rays through both, checked too */
    CHECK(strstr(output, "\nshadow   one thread") && strstr(output, "\nreflect  one thread") &&
          strstr(output, "occluded), 0 differ") && strstr(output, "hit), 0 differ"));
    snprintf(args, sizeof args, "bench '%s' --stream --density 2 --oracle 0 --width 32", cornell);
    EXPECT(args, 0, "0 of 1024 hits differ");
    CHECK(strstr(output, "occluded), 0 differ") && strstr(output, "hit), 0 differ"));
    return RP_TEST_END();
}
