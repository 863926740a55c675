/* The `raypack` command on hostile input (issue 23): outputs that would overwrite an input or each
 * other, writes that fail part-way, FIFOs, folders, include bombs, degenerate cameras, sizes past the
 * limits. Each case must end within its time with the right exit status and message, never hang,
 * never damage a file. */
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdbool.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#define CLI_RUN_TIMEOUT "20" /* a hang fails instead of blocking CTest */
#include "cli_run.h"
#include "rp_test.h"

static char tmp[1024];

static bool write_text(const char *path, const char *text) {
    FILE *f = fopen(path, "wb");
    if (!f) return false;
    bool ok = fputs(text, f) >= 0;
    return fclose(f) == 0 && ok;
}

static bool file_is(const char *path, const char *text) {
    static char buf[1 << 16];
    FILE *f = fopen(path, "rb");
    if (!f) return false;
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = '\0';
    return n == strlen(text) && memcmp(buf, text, n) == 0;
}

static const char TRI_OBJ[] = "v -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n";

/* Outputs equal to an input or to each other: usage errors before any work, nothing touched. */
static void test_same_paths(void) {
    char scene[1200], other[1200], args[8192];
    snprintf(scene, sizeof scene, "%s/tri.obj", tmp);
    CHECK(write_text(scene, TRI_OBJ));
    snprintf(args, sizeof args, "render '%s' --stats-json '%s' -o '%s/x.png' --quiet", scene, scene, tmp);
    EXPECT(args, 2, "--stats-json");
    EXPECT(args, 2, "is the input SCENE");
    CHECK(file_is(scene, TRI_OBJ));
    /* another spelling of the same path, and a hard link: compared as files, not strings */
    snprintf(args, sizeof args, "render '%s' -o '%s/./sub/../tri.obj' --quiet", scene, tmp);
    char sub[1200];
    snprintf(sub, sizeof sub, "%s/sub", tmp);
    mkdir(sub, 0777);
    EXPECT(args, 2, "-o");
    CHECK(file_is(scene, TRI_OBJ));
    snprintf(other, sizeof other, "%s/hard.ppm", tmp);
    unlink(other);
    CHECK(link(scene, other) == 0);
    snprintf(args, sizeof args, "render '%s' -o '%s' --quiet", scene, other);
    EXPECT(args, 2, "is the input SCENE");
    CHECK(file_is(scene, TRI_OBJ));
    /* two outputs naming one file, existing or not */
    snprintf(args, sizeof args, "render -o '%s/same.png' --stats-json '%s/sub/../same.png' --quiet", tmp, tmp);
    EXPECT(args, 2, "are the same file");
    snprintf(args, sizeof args, "bench '%s' --json '%s'", scene, scene);
    EXPECT(args, 2, "--json");
    CHECK(file_is(scene, TRI_OBJ));
}

/* A file-size limit hit while writing: exit 1 naming the cause, the previous image intact. */
static void test_failed_write_keeps_old(void) {
    char img[1200], json[1200], args[8192];
    snprintf(img, sizeof img, "%s/keep.png", tmp);
    snprintf(json, sizeof json, "%s/keep.json", tmp);
    CHECK(write_text(img, "previous image\n"));
    CHECK(write_text(json, "{\"previous\": 1}\n"));
    snprintf(args, sizeof args, "render --width 256 --height 256 -o '%s' --quiet", img);
    EXPECT_P("ulimit -f 4;", args, 1, "File too large");
    CHECKF(file_is(img, "previous image\n"), "a failed render write damaged %s", img);
    /* the 8x8 image (207 bytes) fits in ulimit's 512-byte block, the stats JSON (a few KiB) does not */
    snprintf(args, sizeof args, "render --width 8 --height 8 -o '%s/tiny.ppm' --stats-json '%s' --quiet", tmp, json);
    EXPECT_P("ulimit -f 1;", args, 1, "File too large");
    CHECKF(file_is(json, "{\"previous\": 1}\n"), "a failed --stats-json write damaged %s", json);
    EXPECT(args, 0, "");
    CHECK(!file_is(json, "{\"previous\": 1}\n"));
}

/* A FIFO as the scene: read once as a stream (an open check before the load had blocked forever);
 * a folder or a missing file: exit 1 with errno's text. */
static void test_not_regular_scenes(void) {
    char fifo[1200], scene[1200], prefix[4096], args[8192];
    snprintf(scene, sizeof scene, "%s/tri.obj", tmp);
    CHECK(write_text(scene, TRI_OBJ));
    snprintf(fifo, sizeof fifo, "%s/fifo.obj", tmp);
    unlink(fifo);
    CHECK(mkfifo(fifo, 0600) == 0);
    snprintf(prefix, sizeof prefix, "(timeout 20 cat '%s' > '%s' &);", scene, fifo);
    /* several times: a probe that opened the FIFO and closed it unread (the gzip check did) lost the
     * writer's bytes only when the writer was quicker than the probe, about one run in seven */
    for (int i = 0; i < 8; i++) {
        snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/fifo.ppm'", fifo, tmp);
        EXPECT_P(prefix, args, 0, "1 triangles");
        snprintf(args, sizeof args, "info '%s'", fifo);
        EXPECT_P(prefix, args, 0, "1 triangles");
    }
    unlink(fifo);
    snprintf(args, sizeof args, "render '%s' -o '%s/x.png'", tmp, tmp);
    EXPECT(args, 1, strerror(EISDIR));
    snprintf(args, sizeof args, "render '%s/missing.obj' -o '%s/x.png'", tmp, tmp);
    EXPECT(args, 1, strerror(ENOENT));
}

/* Cameras raypack cannot form, sizes past the limits, scenes with nothing (valid) to hit. */
static void test_cameras_and_sizes(void) {
    char args[8192], path[1200];
    EXPECT("render --eye 1,1,1 --look 1,1,1 --quiet", 2, "--eye and --look: the eye is the look-at point");
    EXPECT("render --up 0,0,0 --quiet", 2, "--up 0,0,0 is not a direction");
    EXPECT("render --eye 0,0,0 --look 0,0,-1 --up 0,0,2 --quiet", 2, "parallel to the view direction");
    EXPECT("render --eye 0,nan,0 --quiet", 2, "--eye expects three numbers");
    EXPECT("render --look inf,0,0 --quiet", 2, "--look expects three numbers");
    /* checked before loading: the scene does not even exist */
    EXPECT("render /nonexistent/x.obj --width 16384 --height 16384", 2, "too many pixels");
    EXPECT("render /nonexistent/x.obj --width 16385", 2, "--width expects an integer in [1, 16384]");
    EXPECT("render --help", 0, "at most 67108864");
    /* what --help allows is accepted: 16384 x 4096 = 67108864 passes the size check (and fails
     * only later, on the missing scene) */
    EXPECT("render /nonexistent/x.obj --width 16384 --height 4096", 1, "cannot open scene");
    /* from the scene file: file:line */
    snprintf(path, sizeof path, "%s/same.nff", tmp);
    CHECK(write_text(path, "v\nfrom 1 2 3\nat 1 2 3\nup 0 1 0\nangle 45\nhither 1\nresolution 8 8\n"
                           "p 3\n0 0 0\n1 0 0\n0 1 0\n"));
    snprintf(args, sizeof args, "render '%s' -o '%s/same.png' --quiet", path, tmp);
    EXPECT(args, 1, "same.nff:3: error: viewpoint: 'from' and 'at' are the same point");
    CHECK(write_text(path, "v\nfrom 0 0 5\nat 0 0 0\nup 0 0 -3\nangle 45\nhither 1\nresolution 8 8\n"
                           "p 3\n0 0 0\n1 0 0\n0 1 0\n"));
    EXPECT(args, 1, "same.nff:4: error: viewpoint: 'up' is parallel");
    /* a flag that makes the scene's camera degenerate: --look onto the scene's eye */
    CHECK(write_text(path, "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 8 8\n"
                           "p 3\n0 0 0\n1 0 0\n0 1 0\n"));
    snprintf(args, sizeof args, "render '%s' --look 0,0,5 -o '%s/same.png' --quiet", path, tmp);
    EXPECT(args, 2, "--look with the scene's camera: the eye is the look-at point");
    snprintf(args, sizeof args, "render '%s' --up 0,0,1 -o '%s/same.png' --quiet", path, tmp);
    EXPECT(args, 2, "--up with the scene's camera: the up vector is parallel");
    /* ... and so do the other commands that make rays from a camera: the stream engine and bench
     * rendered or timed NaN rays (or one line of them), exit 0; with the scene's camera they exit 1 */
    snprintf(args, sizeof args, "render '%s' --engine stream --up 0,0,1 -o '%s/same.png' --quiet", path, tmp);
    EXPECT(args, 1, "--up with the scene's camera: the up vector is parallel");
    EXPECT("render x.obj --engine stream --eye 1,1,1 --look 1,1,1 --quiet", 2, "--eye and --look: the eye is the look-at point");
    snprintf(args, sizeof args, "bench '%s' --look 0,0,5 --width 8 --height 8 --repeats 1", path);
    EXPECT(args, 1, "--look with the scene's camera: the eye is the look-at point");
    EXPECT("bench --eye 0,0,0 --look 0,0,-1 --up 0,0,2", 2, "parallel to the view direction");
    snprintf(args, sizeof args, "bench --render '%s' --look 0,0,5 --width 8 --height 8 --frames 1", path);
    EXPECT(args, 1, "--look with the scene's camera: the eye is the look-at point");
    EXPECT("bench --render x.obj --eye 1,1,1 --look 1,1,1", 2, "--eye and --look: the eye is the look-at point");
    /* a transform (scale 1e30) that overflows to inf drops its primitives, with a warning; nothing else left:
     * the nothing-to-hit warning as well */
    snprintf(path, sizeof path, "%s/overflow.aff", tmp);
    CHECK(write_text(path, "xs 1e30 1e30 1e30 0 1 0 0 0 0 0 {\np 3\n1e10 0 0\n0 1e10 0\n0 0 1e10\n}\n"));
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/overflow.png' --quiet", path, tmp);
    EXPECT(args, 0, "warning: 1 primitives with NaN/Inf coordinates");
    EXPECT(args, 0, "warning: the scene has nothing to hit");
    snprintf(path, sizeof path, "%s/tri.obj", tmp);
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/fine.png' --quiet", path, tmp);
    int rc = run_prefixed("", args);
    CHECKF(rc == 0 && !strstr(output, "warning"), "a valid scene warned (exit %d):\n%s", rc, output);
}

/* Environment maps that lie (found by the texture fuzzer): an RLE scanline with a run of length 0
 * had stb_image loop forever, a header of 30000 x 30000 pixels made it allocate 10 GB. */
static void test_bad_env_maps(void) {
    char scene[1200], env[1200], args[8192];
    snprintf(scene, sizeof scene, "%s/tri.obj", tmp);
    CHECK(write_text(scene, TRI_OBJ));
    snprintf(env, sizeof env, "%s/zero_run.hdr", tmp);
    FILE *f = fopen(env, "wb");
    if (f) { /* one 8-pixel RLE scanline: red's run, then a count of 0 */
        static const unsigned char rle[] = {2, 2, 0, 8, 0x88, 100, 0};
        fputs("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 8\n", f);
        fwrite(rle, 1, sizeof rle, f);
        fclose(f);
    }
    snprintf(args, sizeof args, "render '%s' --env '%s' --width 8 --height 8 -o '%s/env.png' --quiet", scene, env, tmp);
    EXPECT(args, 1, "zero_run.hdr: error: corrupt Radiance HDR image");
    snprintf(env, sizeof env, "%s/huge.hdr", tmp);
    CHECK(write_text(env, "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 30000 +X 30000\n"));
    snprintf(args, sizeof args, "render '%s' --env '%s' --width 8 --height 8 -o '%s/env.png' --quiet", scene, env, tmp);
    EXPECT(args, 1, "30000x30000 is more than 67108864 pixels");
}

/* Devices named as files (robust6): `mtllib /dev/zero` hung the load (an endless read, 4 GiB before
 * the size limit for an include), now refused at the line that names it, quickly. */
static void test_devices(void) {
    char scene[1200], args[8192];
    snprintf(scene, sizeof scene, "%s/dev.obj", tmp);
    CHECK(write_text(scene, "mtllib /dev/zero\nv -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n"));
    snprintf(args, sizeof args, "info '%s'", scene);
    EXPECT(args, 1, "dev.obj:1: error: cannot open material library '/dev/zero' (/dev/zero): a device or socket, not a file");
    snprintf(scene, sizeof scene, "%s/dev.aff", tmp);
    CHECK(write_text(scene, "i 0 /dev/zero\n"));
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/dev.png' --quiet", scene, tmp);
    EXPECT(args, 1, "dev.aff:1: error: cannot open include '/dev/zero' (/dev/zero): a device or socket, not a file");
    snprintf(args, sizeof args, "%s/dev.png", tmp);
    CHECK(access(args, F_OK) != 0);
}

/* Colours that render negative radiance (robust6): a negative MTL Kd or NFF fill colour gave
 * Whitted images with pixels below 0, a negative --env-scale path-traced ones; refused. */
static void test_negative_colours(void) {
    char scene[1200], mtl[1200], args[8192];
    snprintf(mtl, sizeof mtl, "%s/neg.mtl", tmp);
    CHECK(write_text(mtl, "newmtl m\nKd -1 0.5 0.5\n"));
    snprintf(scene, sizeof scene, "%s/neg.obj", tmp);
    CHECK(write_text(scene, "mtllib neg.mtl\nusemtl m\nv -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n"));
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/neg.pfm' --quiet", scene, tmp);
    EXPECT(args, 1, "neg.mtl:2: error: Kd: negative colour component -1 (expected >= 0)");
    snprintf(scene, sizeof scene, "%s/neg.nff", tmp);
    CHECK(write_text(scene, "l 0 0 3\nf -1 0.5 0.5 1 0 0 0 1\np 3\n-1 -1 0\n1 -1 0\n0 1 0\n"));
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/neg.pfm' --quiet", scene, tmp);
    EXPECT(args, 1, "neg.nff:2: error: f: negative colour or coefficient -1 (expected >= 0)");
    CHECK(write_text(scene, "l 0 0 3 1 -2 1\np 3\n-1 -1 0\n1 -1 0\n0 1 0\n"));
    EXPECT(args, 1, "neg.nff:1: error: l colour: negative colour or coefficient -2 (expected >= 0)");
    snprintf(args, sizeof args, "%s/neg.pfm", tmp);
    CHECK(access(args, F_OK) != 0);
    EXPECT("render --env-scale -1,1,1 --integrator path --quiet", 2, "--env-scale expects three numbers >= 0, got '-1,1,1'");
}

/* The loaders' warnings reach stderr: an OBJ usemtl naming a material no library defines renders
 * (exit 0) with the default material and a warning naming the file and line, in render, info
 * and bench alike. */
static void test_load_warnings(void) {
    char scene[1200], mtl[1200], args[8192];
    snprintf(mtl, sizeof mtl, "%s/warn.mtl", tmp);
    CHECK(write_text(mtl, "newmtl red\nKd 0.8 0.1 0.1\n"));
    snprintf(scene, sizeof scene, "%s/warn.obj", tmp);
    CHECK(write_text(scene, "mtllib warn.mtl\nv -1 -1 0\nv 1 -1 0\nv 0 1 0\nusemtl red\nf 1 2 3\nusemtl rde\nf 1 3 2\n"));
    static const char *const want = "warn.obj:7: warning: usemtl 'rde': no material library read so far defines it";
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/warn.png' --quiet", scene, tmp);
    EXPECT(args, 0, want);
    snprintf(args, sizeof args, "info '%s'", scene);
    EXPECT(args, 0, want);
    snprintf(args, sizeof args, "bench '%s' --width 8 --height 8 --repeats 1 --warmup 0 --threads 1", scene);
    EXPECT(args, 0, want);
}

/* An environment map cut short (robust6): a 91-byte HDR header claiming 8000 x 8000 flat pixels
 * rendered, 1.5 GB later, with a black sky; refused. */
static void test_env_cut_short(void) {
    char scene[1200], env[1200], args[8192];
    snprintf(scene, sizeof scene, "%s/tri.obj", tmp);
    CHECK(write_text(scene, TRI_OBJ));
    snprintf(env, sizeof env, "%s/cut.hdr", tmp);
    CHECK(write_text(env, "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 8000 +X 8000\n\x80\x80\x80\x81"));
    snprintf(args, sizeof args, "render '%s' --env '%s' --integrator path --width 8 --height 8 -o '%s/cut.png' --quiet",
             scene, env, tmp);
    EXPECT(args, 1, "cut.hdr: error: corrupt Radiance HDR image");
    snprintf(args, sizeof args, "%s/cut.png", tmp);
    CHECK(access(args, F_OK) != 0);
}

/* Radiance near FLT_MAX (robust6): a texel of RGBE exponent 255 (1.7e38) overflowed to Inf, NaN in
 * instant radiosity's image and a black one when path tracing with --env-scale 10; refused. */
static void test_env_overflow(void) {
    char scene[1200], env[1200], args[8192];
    snprintf(scene, sizeof scene, "%s/tri.obj", tmp);
    CHECK(write_text(scene, TRI_OBJ));
    snprintf(env, sizeof env, "%s/bright.hdr", tmp);
    CHECK(write_text(env, "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 2\n\x80\x80\x80\x81\xff\xff\xff\xff"));
    snprintf(args, sizeof args, "render '%s' --env '%s' --integrator ir --width 8 --height 8 -o '%s/bright.pfm' --quiet",
             scene, env, tmp);
    EXPECT(args, 1, "bright.hdr: error: pixel (1, 0)'s radiance, times the scale, is over 1e+30");
    /* the same map is fine, its bright pixel dimmed by the scale */
    snprintf(args, sizeof args,
             "render '%s' --env '%s' --env-scale 1e-10,1e-10,1e-10 --integrator ir --width 8 --height 8 -o '%s/bright.pfm' --quiet",
             scene, env, tmp);
    EXPECT(args, 0, "");
}

/* Scenes with large coordinates (robust6). The float tests multiply coordinates: a triangle 1e11
 * across rendered black (its unit normal overflowed), 4e12 across with NaN pixels (hits lost),
 * both with exit 0; one 2e30 across could not even be framed (the camera squared its extent in
 * float: "the scene's camera: not finite", a usage error naming no file). Now the camera frames it
 * (info prints a finite one) and render refuses a scene spanning more than 1e9, naming the file;
 * past 1e38 no float camera frames it. */
static void test_huge_scenes(void) {
    char scene[1200], args[8192];
    snprintf(scene, sizeof scene, "%s/wide.obj", tmp);
    CHECK(write_text(scene, "v 1e6 -1e6 0\nv -1e6 -1e6 0\nv 0 1e6 0\nf 1 2 3\n"));
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/wide.pfm' --quiet", scene, tmp);
    EXPECT(args, 0, "");
    snprintf(args, sizeof args, "render '%s' --eye 0,0,2e9 --width 8 --height 8 -o '%s/wide.pfm' --quiet", scene, tmp);
    EXPECT(args, 1, "wide.obj: error: the scene and the eye span 2e+09: past 1e+09");
    /* bench refuses it too: its modes disagreed there, and its check blamed the kernels */
    snprintf(args, sizeof args, "bench '%s' --eye 0,0,2e9 --look 0,0,0 --width 8 --height 8 --repeats 1 --warmup 0", scene);
    EXPECT(args, 1, "wide.obj: error: the scene and the eye span 2e+09: past 1e+09");
    CHECK(write_text(scene, "v 4e12 -4e12 0\nv -4e12 -4e12 0\nv 0 4e12 0\nf 1 2 3\n"));
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/wide.pfm' --quiet", scene, tmp);
    EXPECT(args, 1, "wide.obj: error: the scene and the eye span");
    CHECK(write_text(scene, "v 1e30 -1e30 0\nv -1e30 -1e30 0\nv 0 1e30 0\nf 1 2 3\n"));
    EXPECT(args, 1, "wide.obj: error: the scene and the eye span");
    snprintf(args, sizeof args, "info '%s'", scene);
    int rc = run(args);
    CHECKF(rc == 0 && !strstr(output, "nan") && !strstr(output, "inf,"), "exit %d:\n%s", rc, output);
    CHECK(write_text(scene, "v 3e38 0 0\nv -3e38 1 0\nv 0 1 0\nf 1 2 3\n"));
    snprintf(args, sizeof args, "render '%s' --width 8 --height 8 -o '%s/wide.pfm' --quiet", scene, tmp);
    EXPECT(args, 1, "wide.obj: error: the scene's camera: not finite");
    snprintf(args, sizeof args, "%s/wide.pfm", tmp);
    unlink(args);
    /* animate checks every frame: a block keyframed 1e13 away at t = 1 */
    snprintf(scene, sizeof scene, "%s/flyaway.aff", tmp);
    CHECK(write_text(scene, "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 8 8\na 0 2 3\n"
                            "x obj {\np 3\n-1 -1 0\n1 -1 0\n0 1 0\n}\nk obj {\ntransl 5\n-1 0 0 0 0 0 0\n0 0 0 0 0 0 0\n"
                            "1 0 0 -1e13 0 0 0\n2 0 0 0 0 0 0\n3 0 0 0 0 0 0\n}\n"));
    snprintf(args, sizeof args, "animate '%s' --width 8 --height 8 --quiet", scene);
    EXPECT(args, 1, "flyaway.aff: error: the scene and the eye span 1e+13");
}

/* bench --json into a missing folder or onto a folder (robust6): the benchmark ran whole (8 s on a
 * triangle, minutes on a real scene) before the write failed; now refused first, as render does. */
static void test_bench_json_folder(void) {
    char args[8192];
    snprintf(args, sizeof args, "bench --json '%s/missing/b.json' --repeats 1", tmp);
    EXPECT(args, 1, "raypack bench: cannot write");
    CHECKF(strstr(output, "missing does not exist") && !strstr(output, "Mrays"), "%s", output);
    snprintf(args, sizeof args, "bench --json '%s' --repeats 1", tmp);
    EXPECT(args, 1, "it is a directory");
    CHECKF(!strstr(output, "Mrays"), "%s", output);
}

/* Sum of a binary PPM's bytes after its header (P6, width, height, 255); -1 when unreadable. */
static long ppm_sum(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) return -1;
    int w, h, maxv;
    long sum = fscanf(f, "P6 %d %d %d", &w, &h, &maxv) == 3 && fgetc(f) != EOF ? 0 : -1;
    for (int c; sum >= 0 && (c = fgetc(f)) != EOF;) sum += c;
    fclose(f);
    return sum;
}

/* A keyframed scale of 0 (robust6): the block's instance transform has no inverse, which
 * rp_geometry_set_instance refuses. At the first frame the commit failed ("a geometry lacks a
 * buffer", naming no file); later it kept the previous frame's transform, so the block showed
 * whole where the flat build shows nothing. Now hidden at that frame, shown at the others. */
static void test_anim_zero_scale(void) {
    char scene[1200], args[8192], frame[1200];
    static const char cam[] = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 8 8\n";
    static const char block[] = "x obj {\np 3\n-1 -1 0\n1 -1 0\n0 1 0\n}\n";
    static const char *const keys[2] = {
        /* 1 at t = 0 and 2, 0 at t = 1 */
        "k obj {\nscale 5\n-1 1 1 1 0 0 0\n0 1 1 1 0 0 0\n1 0 0 0 0 0 0\n2 1 1 1 0 0 0\n3 1 1 1 0 0 0\n}\n",
        /* 0 from the start */
        "k obj {\nscale 4\n0 0 0 0 0 0 0\n1 0 0 0 0 0 0\n2 0 0 0 0 0 0\n3 0 0 0 0 0 0\n}\n"};
    for (int k = 0; k < 2; k++) {
        char text[1024];
        snprintf(text, sizeof text, "%sa 0 2 3\n%s%s", cam, block, keys[k]);
        snprintf(scene, sizeof scene, "%s/shrink.aff", tmp);
        CHECK(write_text(scene, text));
        for (int flat = 0; flat < 2; flat++) {
            snprintf(args, sizeof args, "animate '%s' -o '%s/shrink%%d.ppm' --integrator eyelight --width 16 --height 12 --quiet%s",
                     scene, tmp, flat ? " --anim-flat" : "");
            EXPECT(args, 0, "");
            for (int i = 0; i < 3; i++) {
                snprintf(frame, sizeof frame, "%s/shrink%d.ppm", tmp, i);
                long sum = ppm_sum(frame);
                bool shown = k == 0 && i != 1;
                CHECKF(shown ? sum > 0 : sum == 0, "%s frame %d (%s build): pixel sum %ld", k ? "scale 0" : "scale 1, 0, 1",
                       i, flat ? "flat" : "instanced", sum);
                unlink(frame);
            }
        }
    }
}

/* A frame pattern whose width makes every name kilobytes of blanks (robust6): a usage error. */
static void test_animate_pattern(void) {
    char args[8192];
    snprintf(args, sizeof args, "animate '%s/none.aff' -o '%s/f%%999999999d.png'", tmp, tmp);
    EXPECT(args, 2, "-o expects a pattern with one integer conversion (of width 99 at most)");
}

int main(void) {
    if (!find_exe()) {
        fprintf(stderr, "raypack binary not found at %s\n", exe);
        CHECK(!"raypack binary built");
        return RP_TEST_END();
    }
    const char *dir = getenv("RP_TEST_TMP");
    snprintf(tmp, 900, "%s", dir ? dir : "/tmp/raypack_test_cli_robust");
    mkdir(tmp, 0777);
    test_same_paths();
    test_failed_write_keeps_old();
    test_not_regular_scenes();
    test_cameras_and_sizes();
    test_bad_env_maps();
    test_devices();
    test_negative_colours();
    test_load_warnings();
    test_env_cut_short();
    test_env_overflow();
    test_huge_scenes();
    test_animate_pattern();
    test_anim_zero_scale();
    test_bench_json_folder();
    return RP_TEST_END();
}
