// rp-test: labels=cli timeout=300
/* `raypack render --engine stream` and `raypack bench --stream [--purcell]`: the stream engine's
 * image (PFM) equals `--integrator eyelight`'s value for value; the bench checks the grid's hits
 * against the BVH's and prints the statistics and the paper's table; bad input exits 2 (usage) or
 * 1 (a scene that cannot be loaded) with a message. The binary is build/<preset>/raypack, or $RP_CLI. */
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "raypack_io.h"
#include "cli_run.h"
#include "rp_test.h"

static char tmp[1024];

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

    /* bench: hits checked against the BVH, the statistics and the paper's table */
    snprintf(args, sizeof args, "bench '%s' --stream --purcell --width 64 --height 64", bunny);
    EXPECT(args, 0, "0 of 4096 hits differ");
    CHECK(strstr(output, "passes total") && strstr(output, "SIMD efficiency") && strstr(output, "1085") &&
          strstr(output, "grid/BVH time") && strstr(output, "64 along") == NULL);
    snprintf(args, sizeof args, "bench '%s' --stream --density 2 --oracle 0 --width 32", cornell);
    EXPECT(args, 0, "0 of 1024 hits differ");
    return RP_TEST_END();
}
