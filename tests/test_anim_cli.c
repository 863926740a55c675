// rp-test: timeout=300
/* `raypack animate` on a few frames of BART's museum (frames written, the per-frame and fps lines),
 * `raypack render --anim-time`, --lights, --reflect-depth / --refract-depth, and their errors. */
#include <math.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli_run.h"
#include "rp_test.h"

static bool exists(const char *path) {
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0;
}

int main(void) {
    if (!find_exe()) {
        CHECK(!"raypack binary built");
        return RP_TEST_END();
    }
    const char *dir = getenv("RP_TEST_TMP");
    char tmp[900], args[4096], path[1200], buf[512];
    snprintf(tmp, sizeof tmp, "%s", dir ? dir : "/tmp/raypack_test_anim_cli");
    mkdir(tmp, 0777);
    const char *museum = rp_test_scene("bart_museum5.tar.gz", buf, sizeof buf);
    if (!museum) {
        CHECK(!"bart_museum5 found");
        return RP_TEST_END();
    }
    char frames[1000];
    snprintf(frames, sizeof frames, "%s/frames", tmp);
    mkdir(frames, 0777);
    /* 3 frames over [-1, 5]: times -1, 2, 5 */
    snprintf(args, sizeof args, "animate '%s' --frames 3 --width 32 --height 24 --threads 2 -o '%s/%%03d.png'", museum, frames);
    EXPECT(args, 0, "frames/s with updates (BART)");
    CHECKF(strstr(output, "frame     1 t   2.0000") != NULL, "no line for frame 1 at t 2:\n%s", output);
    CHECKF(strstr(output, "refit") && strstr(output, "written  3 images"), "%s", output);
    for (int i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s/%03d.png", frames, i);
        CHECKF(exists(path), "%s not written", path);
    }
    snprintf(path, sizeof path, "%s/003.png", frames);
    CHECK(!exists(path));
    /* --fps 0.5 over 6 time units: frames at -1, 1, 3, 5; --first/--last pick two; no -o writes nothing */
    snprintf(args, sizeof args, "animate '%s' --fps 0.5 --first 1 --last 2 --width 16 --height 12 --quiet --anim-flat", museum);
    EXPECT(args, 0, "summary  2 frames");
    CHECKF(strstr(output, "(no images written)") != NULL, "%s", output);
    /* a frame of render at a time: the same pixels as animate's frame at that time */
    snprintf(args, sizeof args, "render '%s' --anim-time 2 --width 32 --height 24 --threads 2 -q -o '%s/r2.png'", museum, tmp);
    EXPECT(args, 0, "");
    snprintf(args, sizeof args, "cmp -s '%s/r2.png' '%s/001.png'", tmp, frames);
    CHECKF(system(args) == 0, "render --anim-time 2 differs from animate's frame at t 2");
    /* Overbeck's fig. 1 flags parse and run */
    snprintf(args, sizeof args, "render '%s' --anim-time 0.5 --lights 1 --reflect-depth 1 --refract-depth 4 --width 16 "
             "--height 12 -o '%s/fig1.png'", museum, tmp);
    EXPECT(args, 0, "1 lights");
    /* errors */
    snprintf(args, sizeof args, "animate '%s' --frames 2 --fps 3", museum);
    EXPECT(args, 2, "exclude each other");
    snprintf(args, sizeof args, "animate '%s' -o '%s/x.png'", museum, tmp);
    EXPECT(args, 2, "one integer conversion");
    snprintf(args, sizeof args, "animate '%s' -o '%s/%%d%%s.png'", museum, tmp);
    EXPECT(args, 2, "one integer conversion");
    snprintf(args, sizeof args, "animate '%s' -o '%s/nowhere/%%d.png'", museum, tmp);
    EXPECT(args, 1, "does not exist");
    snprintf(args, sizeof args, "animate '%s' --frames 4 --first 9", museum);
    EXPECT(args, 2, "past the last frame");
    snprintf(args, sizeof args, "render '%s' --lights 2 -o '%s/l.png'", museum, tmp);
    EXPECT(args, 2, "the scene has 2 lights");
    snprintf(args, sizeof args, "render '%s' --lights 0,x -o '%s/l.png'", museum, tmp);
    EXPECT(args, 2, "--lights expects");
    char buf2[512];
    const char *teapot = rp_test_scene("spd_teapot.nff.gz", buf2, sizeof buf2);
    if (teapot) {
        snprintf(args, sizeof args, "render '%s' --anim-time 1 -o '%s/t.png'", teapot, tmp);
        EXPECT(args, 2, "not animated");
        snprintf(args, sizeof args, "animate '%s'", teapot);
        EXPECT(args, 2, "not animated");
    }
    /* the viewer: space plays the animation (scene time with the clock: --fps 2, 0.5 a frame) and the
     * camera follows the path; paused at frame 5, t = -1 + 5 x 0.5 = 1.5, the path's key there: the
     * eye at (0, 3, 4.9) */
    if (system("command -v xvfb-run > /dev/null 2>&1") == 0 && run("view --help") == 0) {
        /* under ASan, X11's and SDL's own leaks are suppressed as in test_view */
        const char *src = getenv("RP_SOURCE_DIR");
        char lsan[1200];
        snprintf(lsan, sizeof lsan, "suppressions=%s/apps/viewer/lsan.supp:print_suppressions=0", src ? src : ".");
        setenv("LSAN_OPTIONS", lsan, 1);
        snprintf(args, sizeof args, "view '%s' --width 32 --height 24 --threads 2 --fps 2 --frames 6 --no-overlay "
                 "--script '0 key space; 5 key space'", museum);
        EXPECT_P("xvfb-run -a -s '-screen 0 1280x1024x24'", args, 0, "animation: paused at t 1.500");
        const char *last = NULL;
        for (const char *c = strstr(output, "camera: --eye "); c; c = strstr(c + 1, "camera: --eye ")) last = c;
        float e[3] = {0, 0, 0};
        CHECKF(last && sscanf(last, "camera: --eye %f,%f,%f", &e[0], &e[1], &e[2]) == 3 && fabsf(e[0]) < 1e-4f &&
               fabsf(e[1] - 3.0f) < 1e-4f && fabsf(e[2] - 4.9f) < 1e-4f, "viewer's camera at t 1.5:\n%s", output);
    } else {
        printf("no xvfb-run or no viewer: the viewer's animation is not checked\n");
    }
    EXPECT("animate", 2, "expected an animated SCENE");
    EXPECT("animate --help", 0, "--frames N");
    return RP_TEST_END();
}
