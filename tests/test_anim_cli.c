// rp-test: timeout=300
/* `raypack animate` on a few frames of BART's museum (frames written, the per-frame and fps lines),
 * `raypack render --anim-time`, --lights, --reflect-depth / --refract-depth, and their errors. */
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
    const char *teapot = rp_test_scene("spd_teapot.nff.gz", buf, sizeof buf);
    if (teapot) {
        snprintf(args, sizeof args, "render '%s' --anim-time 1 -o '%s/t.png'", teapot, tmp);
        EXPECT(args, 2, "not animated");
        snprintf(args, sizeof args, "animate '%s'", teapot);
        EXPECT(args, 2, "not animated");
    }
    EXPECT("animate", 2, "expected an animated SCENE");
    EXPECT("animate --help", 0, "--frames N");
    return RP_TEST_END();
}
