/* The `raypack` command: exit status and message for every class of bad input (2 for usage errors,
 * 1 for load and write failures), --help everywhere, and small renders, AOVs and --stats-json that
 * work. The binary is found beside the tests folder of the build (build/<preset>/raypack), or at
 * $RP_CLI when set. */
#include <limits.h>
#include <math.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "raypack_io.h"
#include "cli_run.h"
#include "rp_test.h"

static char tmp[1024];

int main(void) {
    if (!find_exe()) {
        fprintf(stderr, "raypack binary not found at %s\n", exe);
        CHECK(!"raypack binary built");
        return RP_TEST_END();
    }
    const char *dir = getenv("RP_TEST_TMP");
    snprintf(tmp, 900, "%s", dir ? dir : "/tmp/raypack_test_cli");
    mkdir(tmp, 0777);
    char args[8192], buf[512];
    const char *cornell = rp_test_scene("cornell_box/cornell_box.obj", buf, sizeof buf);

    /* Help and dispatch. */
    EXPECT("--help", 0, "render");
    EXPECT("render --help", 0, "--width");
    EXPECT("info --help", 0, "usage: raypack info");
    EXPECT("bench --help", 0, "usage");
    EXPECT("", 2, "usage: raypack");
    EXPECT("frobnicate", 2, "unknown command 'frobnicate'");

    /* Usage errors: exit 2, naming what was expected. */
    EXPECT("render --width -5", 2, "--width expects an integer in [1, 16384], got '-5'");
    EXPECT("render --width abc", 2, "--width expects an integer");
    EXPECT("render --width", 2, "--width expects a value");
    EXPECT("render --height 0", 2, "--height expects an integer");
    EXPECT("render --fov 0", 2, "--fov expects a number in (0, 180)");
    EXPECT("render --fov 180", 2, "--fov expects a number");
    EXPECT("render --threads 100000", 2, "--threads expects an integer in [0, 1024]");
    EXPECT("render --spp 0", 2, "--spp expects an integer");
    EXPECT("render --max-depth 1.5", 2, "--max-depth expects an integer");
    EXPECT("render --eye 1,2", 2, "--eye expects three numbers");
    EXPECT("render --integrator radiosity", 2, "--integrator expects whitted, eyelight, direct, path, ir or ao");
    EXPECT("render --tonemap reinhard", 2, "--tonemap expects srgb or aces");
    EXPECT("render --integrator path --env /nonexistent/env.hdr", 1, "env.hdr: error: cannot read a Radiance HDR image");
    EXPECT("render --ir-filter 4", 2, "--ir-filter expects an odd side");
    EXPECT("render --aov colour", 2, "--aov expects depth, normal, primid or albedo");
    EXPECT("render --traversal fast", 2, "--traversal expects auto, masked, ranged, partition, span, single, simd or mlrt");
    EXPECT("render --packet 12", 2, "--packet expects 4, 8, 16 or 32");
    EXPECT("render --packet 64", 2, "--packet expects 4, 8, 16 or 32");
    EXPECT("render --frustum yes", 2, "--frustum expects on or off");
    EXPECT("render --isa avx1024", 2, "--isa expects auto, scalar, sse, avx2 or avx512, got 'avx1024'");
    EXPECT("bench --isa 16", 2, "--isa expects auto, scalar, sse, avx2 or avx512");
    EXPECT("render --frobnicate", 2, "unknown option '--frobnicate'");
    EXPECT("render a.obj b.obj", 2, "expected one SCENE");
    EXPECT("render -o out.jpg", 2, "-o expects a file ending in .png, .pfm, .ppm, .hdr or .exr");
    EXPECT("info --threads -1", 2, "--threads expects an integer");
    EXPECT("info --bogus", 2, "unknown option '--bogus'");

    /* Load and write failures: exit 1. */
    EXPECT("render /nonexistent/scene.obj", 1, "cannot open scene /nonexistent/scene.obj");
    EXPECT("info /nonexistent/scene.obj", 1, "cannot open scene");
    EXPECT("render -o /nonexistent-dir/x.png", 1, "cannot write /nonexistent-dir/x.png");
    snprintf(args, sizeof args, "%s/dir.png", tmp);
    mkdir(args, 0777);
    snprintf(args, sizeof args, "render -o '%s/dir.png'", tmp);
    EXPECT(args, 1, "is a directory");
    /* A broken scene: the loader's "file:line: error: message" comes through. */
    char broken[1100];
    snprintf(broken, sizeof broken, "%s/broken.obj", tmp);
    FILE *f = fopen(broken, "w");
    if (f) {
        fputs("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", f);
        fclose(f);
    }
    snprintf(args, sizeof args, "render '%s' -o '%s/broken.png' --quiet", broken, tmp);
    EXPECT(args, 1, "broken.obj:4: error:");

    /* Things that work. */
    snprintf(args, sizeof args, "render --width 40 --height 30 -o '%s/room.ppm' --quiet", tmp);
    EXPECT(args, 0, "");
    char path[1100];
    snprintf(path, sizeof path, "%s/room.ppm", tmp);
    f = fopen(path, "rb");
    CHECK(f != NULL);
    if (f) {
        char head[16] = "";
        CHECK(fread(head, 1, 12, f) == 12 && memcmp(head, "P6\n40 30\n255", 12) == 0);
        fclose(f);
    }
    snprintf(args, sizeof args, "render --width 40 -o '%s/room.png' --stats --stats-json '%s/stats.json'", tmp, tmp);
    EXPECT(args, 0, "Mrays/s");
    EXPECT(args, 0, "frustum box culls/tests");
    EXPECT(args, 0, "box tests by BVH depth");
    EXPECT(args, 0, "16x16 packets, auto traversal, frusta on");
    EXPECT(args, 0, "packets: span ");
    snprintf(path, sizeof path, "%s/stats.json", tmp);
    f = fopen(path, "r");
    CHECK(f != NULL);
    if (f) {
        static char json[65536];
        size_t n = fread(json, 1, sizeof json - 1, f);
        json[n] = '\0';
        CHECKF(strstr(json, "\"mrays_per_s\"") && strstr(json, "\"shadow\"") && strstr(json, "\"height\": 30"),
               "%s", json);
        CHECKF(strstr(json, "\"work\"") && strstr(json, "\"box_tests_depth\": [") &&
                   strstr(json, "\"frustum_tri_culls\"") && strstr(json, "\"traversal\": \"auto\"") &&
                   strstr(json, "\"simd\": "),
               "%s", json);
        fclose(f);
    }
    /* every traversal, packet size and frustum setting writes the same image */
    snprintf(args, sizeof args, "render --width 40 --height 30 -o '%s/ref.pfm' --quiet", tmp);
    EXPECT(args, 0, "");
    static const char *modes[] = {"--traversal single --packet 4", "--traversal partition --packet 32 --frustum off",
                                  "--traversal ranged --packet 8", "--traversal simd", "--traversal masked"};
    snprintf(path, sizeof path, "%s/ref.pfm", tmp);
    int rw = 0, rh = 0, rc = 0;
    char rerr[512] = "";
    float *ref = rp_image_read_pfm(path, &rw, &rh, &rc, rerr, sizeof rerr);
    CHECKF(ref != NULL, "%s", rerr);
    for (size_t i = 0; ref && i < sizeof modes / sizeof modes[0]; i++) {
        snprintf(args, sizeof args, "render --width 40 --height 30 %s -o '%s/mode.pfm' --quiet", modes[i], tmp);
        EXPECT(args, 0, "");
        snprintf(path, sizeof path, "%s/mode.pfm", tmp);
        int mw = 0, mh = 0, mc = 0;
        float *px = rp_image_read_pfm(path, &mw, &mh, &mc, rerr, sizeof rerr);
        CHECKF(px && mw == rw && mh == rh && mc == rc && memcmp(px, ref, sizeof(float) * (size_t)(rw * rh * rc)) == 0,
               "%s: image differs from the default's", modes[i]);
        free(px);
    }
    free(ref);
    snprintf(args, sizeof args, "render --width 40 --height 30 --aov depth -o '%s/depth.pfm' --quiet", tmp);
    EXPECT(args, 0, "");
    snprintf(path, sizeof path, "%s/depth.pfm", tmp);
    int w = 0, h = 0, c = 0;
    char err[512] = "";
    float *px = rp_image_read_pfm(path, &w, &h, &c, err, sizeof err);
    CHECKF(px && w == 40 && h == 30 && c == 1, "%s", err);
    free(px);
    for (int i = 0; i < 3; i++) {
        static const char *aovs[] = {"normal", "primid", "albedo"};
        snprintf(args, sizeof args, "render --width 24 --height 16 --aov %s -o '%s/aov.png' --quiet", aovs[i], tmp);
        EXPECT(args, 0, "");
    }
    /* Every kernel set gives the same image: the built-in room (mirror, glass, Whitted packets)
     * with the scalar kernels and with the widest this CPU has. */
    snprintf(args, sizeof args, "render --width 64 --height 48 --isa scalar -o '%s/isa_scalar.pfm'", tmp);
    EXPECT(args, 0, "scalar kernels");
    snprintf(args, sizeof args, "render --width 64 --height 48 -o '%s/isa_auto.pfm' --quiet", tmp);
    EXPECT(args, 0, "");
    {
        char pa[1100], pb[1100];
        snprintf(pa, sizeof pa, "%s/isa_scalar.pfm", tmp);
        snprintf(pb, sizeof pb, "%s/isa_auto.pfm", tmp);
        int wa = 0, ha = 0, ca = 0, wb = 0, hb = 0, cb = 0;
        float *ia = rp_image_read_pfm(pa, &wa, &ha, &ca, err, sizeof err);
        float *ib = rp_image_read_pfm(pb, &wb, &hb, &cb, err, sizeof err);
        CHECKF(ia && ib && wa == 64 && ha == 48 && wb == wa && hb == ha && cb == ca, "%s", err);
        if (ia && ib && wb == wa && hb == ha && cb == ca)
            CHECKF(memcmp(ia, ib, (size_t)wa * (size_t)ha * (size_t)ca * sizeof(float)) == 0,
                   "--isa scalar and --isa auto render different images");
        free(ia);
        free(ib);
    }
    if (cornell) {
        snprintf(args, sizeof args, "info '%s'", cornell);
        EXPECT(args, 0, "36 triangles");
        EXPECT(args, 0, "SAH cost");
        snprintf(args, sizeof args,
                 "render '%s' --width 32 --height 32 --integrator eyelight --eye 278,273,-800 --look 278,273,0 "
                 "--fov 39 --threads 2 -o '%s/cornell.png'",
                 cornell, tmp);
        EXPECT(args, 0, "primary 1024");
    }
    char original[600];
    if (rp_test_scene("cornell_original/CornellBox-Original.obj", original, sizeof original)) {
        /* the physically based integrators end to end: a float image and its denoiser AOVs, and
         * progressive frames by time */
        snprintf(args, sizeof args, "render '%s' --width 24 --height 24 --integrator path --spp 2 --aovs "
                 "--threads 2 -o '%s/pt.pfm'", original, tmp);
        EXPECT(args, 0, "bounce");
        const char *suffix[3] = {"pt.pfm", "pt.albedo.pfm", "pt.normal.pfm"};
        for (int k = 0; k < 3; k++) {
            char p[1200], why[256];
            snprintf(p, sizeof p, "%s/%s", tmp, suffix[k]);
            int pw = 0, ph = 0, pc = 0;
            float *img = rp_image_read_pfm(p, &pw, &ph, &pc, why, sizeof why);
            CHECKF(img && pw == 24 && ph == 24 && pc == 3, "%s: %s", p, img ? "wrong size" : why);
            free(img);
        }
        snprintf(args, sizeof args, "render '%s' --width 16 --height 16 --integrator ir --time 0.3 --threads 2 "
                 "-o '%s/ir.png'", original, tmp);
        EXPECT(args, 0, "frames");
        snprintf(args, sizeof args, "bench --render '%s' --frames 1 --width 16 --height 16 --threads 2", original);
        EXPECT(args, 0, "ir ");
        EXPECT("bench --render", 2, "expected at least one SCENE");
        snprintf(args, sizeof args, "bench --render '%s' --integrators eyelight --kernels --frames 2 --width 32 "
                 "--height 32 --threads 1 --eye 0,1,3 --look 0,1,0 --fov 50", original);
        EXPECT(args, 0, "kernel/frame");
        snprintf(args, sizeof args, "render --integrator path --width 16 --height 16 -o '%s/room.png'", tmp);
        EXPECT(args, 0, "scene");
    }
    /* --volume FILE.vdb in a scene of surfaces, placed by --volume-fit: the cloud in the Cornell box
     * shows; fitted into a box behind the camera it does not; and the errors. */
    char vbuf[512];
    const char *cloud = rp_test_scene("volume_wdas_cloud/wdas_cloud_sixteenth.vdb", vbuf, sizeof vbuf);
    if (cornell && cloud) {
        const char *common = "--integrator whitted --albedo 0.2 --width 48 --height 48 --eye 278,273,-800 "
                             "--look 278,273,0 --fov 40 --quiet";
        static const char *const fits[3] = {"", "--volume-fit 150,150,150,400,400,400",
                                            "--volume-fit 150,150,-3000,400,400,-2800"};
        float *img[3] = {NULL, NULL, NULL};
        bool vdb = true;
        for (int i = 0; i < 3 && vdb; i++) {
            snprintf(args, sizeof args, "render '%s' %s%s%s %s %s -o '%s/vol%d.pfm'", cornell, i ? "--volume '" : "",
                     i ? cloud : "", i ? "'" : "", fits[i], common, tmp, i);
            int vrc = run(args);
            if (vrc != 0 && i == 1 && strstr(output, "without OpenVDB")) {
                vdb = false; /* built without OpenVDB: the error says so */
                break;
            }
            CHECKF(vrc == 0, "%s: exit %d\n%s", args, vrc, output);
            snprintf(path, sizeof path, "%s/vol%d.pfm", tmp, i);
            int vw = 0, vh = 0, vc = 0;
            img[i] = rp_image_read_pfm(path, &vw, &vh, &vc, err, sizeof err);
            CHECKF(img[i] && vw == 48 && vh == 48 && vc == 3, "%s", err);
        }
        if (vdb && img[1]) { /* the stream engine reads the same flags and composites the cloud alike */
            snprintf(args, sizeof args, "render '%s' --engine stream --volume '%s' %s %s -o '%s/vol_stream.pfm'", cornell,
                     cloud, fits[1], common, tmp);
            int src = run(args);
            CHECKF(src == 0, "%s: exit %d\n%s", args, src, output);
            snprintf(path, sizeof path, "%s/vol_stream.pfm", tmp);
            int vw = 0, vh = 0, vc = 0;
            float *st = rp_image_read_pfm(path, &vw, &vh, &vc, err, sizeof err);
            CHECKF(st && vw == 48 && vh == 48 && vc == 3 && memcmp(st, img[1], 48 * 48 * 3 * sizeof(float)) == 0,
                   "--engine stream --volume: not the packet renderer's image (%s)", err);
            free(st);
            snprintf(args, sizeof args, "render '%s' --engine stream --shading shadow --volume '%s' -o '%s/x.png'",
                     cornell, cloud, tmp);
            EXPECT(args, 1, "does not show a participating medium");
        }
        if (img[0] && img[1] && img[2]) {
            /* the cloud is a dark (albedo 0.2) patch over a third of the view's width, wispy: about
             * 66 pixels; behind the camera only the headlight, which follows the scene's box (the
             * volume's included), moves a little */
            size_t n = 48 * 48 * 3, changed = 0;
            double behind = 0.0;
            for (size_t k = 0; k < n; k++) {
                changed += fabsf(img[0][k] - img[1][k]) > 0.3f;
                behind = fmax(behind, fabs(img[0][k] - img[2][k]));
            }
            CHECKF(changed >= 90 && changed < n / 4, "--volume: the cloud in the box changed %zu of %zu values", changed, n);
            CHECKF(behind < 1e-3, "--volume-fit behind the camera changed the image by %g", behind);
        }
        for (int i = 0; i < 3; i++) free(img[i]);
        snprintf(args, sizeof args, "render '%s' --volume '%s'", cornell, cornell);
        EXPECT(args, 1, "the file holds no volume (a .vdb is wanted)");
        snprintf(args, sizeof args, "render '%s' --volume-fit 0,0,0,1,1,1", cornell);
        EXPECT(args, 1, "--volume-fit: the scene has no volume to fit");
        snprintf(args, sizeof args, "render '%s' --volume '%s' --medium-box 0,0,0,1,1,1", cornell, cloud);
        EXPECT(args, 1, "a scene holds one volume, give one of them");
        EXPECT("render --volume /nonexistent/cloud.vdb", 1, "/nonexistent/cloud.vdb");
        EXPECT("render --volume-fit 1,1,1,0,0,0", 2, "--volume-fit: the second corner must be above the first");
    }
    {
        /* Secondary rays start off a surface by the float spacing of its point, its ray and its
         * primitive, not the scene's: sphere B (radius 0.1) lies 0.1 under sphere A, below a point
         * light, on a ground 2 or 2e5 across. B's lit-side pixel is in A's shadow (ambient only) on
         * both grounds; with the scene's offset (2e-5 of 1e5: 2 units) its shadow ray started beyond
         * A on the large ground and the pixel was lit (0.65 against 0.08). */
        float centre[3] = {0}, stream_centre[2] = {0};
        for (int g = 0; g < 3; g++) {
            /* g 2: the small ground's scene moved 1e4 along each axis (below) */
            double half = g == 1 ? 100000.0 : 1.0, o = g == 2 ? 10000.0 : 0.0;
            snprintf(path, sizeof path, "%s/two_spheres.nff", tmp);
            FILE *nf = fopen(path, "w");
            CHECK(nf != NULL);
            if (!nf) break;
            fprintf(nf, "v\nfrom %.9g %.9g %.9g\nat %.9g %.9g %.9g\nup 0 1 0\nangle 10\nhither 0.001\nresolution 32 32\n"
                        "l %.9g %.9g %.9g\nf 1 1 1 1 0 0 0 0\ns %.9g %.9g %.9g 0.1\ns %.9g %.9g %.9g 0.1\n"
                        "p 4\n%.9g %.9g %.9g\n%.9g %.9g %.9g\n%.9g %.9g %.9g\n%.9g %.9g %.9g\n",
                    o + 1, o + 0.28, o, o, o + 0.28, o, o, o + 5, o, o, o + 0.5, o, o, o + 0.2, o, o - half, o, o - half,
                    o - half, o, o + half, o + half, o, o + half, o + half, o, o - half);
            fclose(nf);
            snprintf(args, sizeof args, "render '%s' -o '%s/two.pfm' --quiet", path, tmp);
            EXPECT(args, 0, "");
            snprintf(path, sizeof path, "%s/two.pfm", tmp);
            int tw = 0, th = 0, tc = 0;
            char err2[512] = "";
            float *two = rp_image_read_pfm(path, &tw, &th, &tc, err2, sizeof err2);
            CHECKF(two && tw == 32 && th == 32 && tc == 3, "%s", err2);
            if (two) centre[g] = two[(16 * 32 + 16) * 3];
            free(two);
            if (g == 2) continue;
            /* the stream tracer's shadow shading too (it took the scene's offset: 0.52, lit) */
            snprintf(path, sizeof path, "%s/two_spheres.nff", tmp);
            snprintf(args, sizeof args, "render '%s' --engine stream --shading shadow -o '%s/two.pfm' --quiet", path, tmp);
            EXPECT(args, 0, "");
            snprintf(path, sizeof path, "%s/two.pfm", tmp);
            two = rp_image_read_pfm(path, &tw, &th, &tc, err2, sizeof err2);
            CHECKF(two && tw == 32 && th == 32 && tc == 3, "%s", err2);
            if (two) stream_centre[g] = two[(16 * 32 + 16) * 3];
            free(two);
        }
        CHECKF(stream_centre[0] > 0.0f && stream_centre[0] < 0.2f && stream_centre[1] == stream_centre[0],
               "--engine stream --shading shadow: sphere B's shadowed pixel: %g on the small ground, %g on the large one",
               (double)stream_centre[0], (double)stream_centre[1]);
        CHECKF(centre[0] > 0.0f && centre[0] < 0.2f && centre[1] == centre[0],
               "sphere B's shadowed pixel: %g on the small ground, %g on the large one", (double)centre[0],
               (double)centre[1]);
        /* Far from the origin the offset is the float spacing's (2e-6 of the coordinates), not 2e-5
         * of them: moved 1e4, the rays started 0.2 off B, beyond A, and the pixel was lit (0.65). */
        CHECKF(fabsf(centre[2] - centre[0]) < 0.01f, "sphere B's shadowed pixel: %g, moved 1e4 from the origin %g",
               (double)centre[0], (double)centre[2]);
    }
    {
        /* A ground quad 2e5 across, its diagonal 0.19 under the camera: the packets' cone test made
         * the edge plane of that diagonal in float, off by several percent (the line passes close to
         * the apex, the vertices are 1e5 away), and dropped a row of the ground's hits along it. The
         * n x n packets (frusta and cones on) must give the single rays' image. */
        snprintf(path, sizeof path, "%s/ground.nff", tmp);
        FILE *gf = fopen(path, "w");
        CHECK(gf != NULL);
        if (gf) {
            fprintf(gf, "v\nfrom 0.106761 0.161643 -0.0830294\nat 0.0227777 0.0876894 -0.0184207\nup 0 1 0\n"
                        "angle 53.6853\nhither 0.001\nresolution 96 64\nl 0 5 0\nf 1 1 1 1 0 0 0 0\np 4\n"
                        "-100000 0.033 -100000\n-100000 0.033 100000\n100000 0.033 100000\n100000 0.033 -100000\n");
            fclose(gf);
            float *img[2] = {NULL, NULL};
            int gw[2] = {0}, gh[2] = {0}, gc[2] = {0};
            for (int k = 0; k < 2; k++) {
                snprintf(args, sizeof args, "render '%s' --integrator eyelight %s -o '%s/ground.pfm' --quiet", path,
                         k ? "--traversal single" : "", tmp);
                EXPECT(args, 0, "");
                char gpath[1200], gerr[512] = "";
                snprintf(gpath, sizeof gpath, "%s/ground.pfm", tmp);
                img[k] = rp_image_read_pfm(gpath, &gw[k], &gh[k], &gc[k], gerr, sizeof gerr);
                CHECKF(img[k] != NULL, "%s", gerr);
            }
            size_t differ = 0;
            if (img[0] && img[1] && gw[0] == gw[1] && gh[0] == gh[1] && gc[0] == gc[1])
                for (size_t i = 0; i < (size_t)gw[0] * (size_t)gh[0] * (size_t)gc[0]; i++) differ += img[0][i] != img[1][i];
            else
                differ = 1;
            CHECKF(differ == 0, "a ground 2e5 across: packets and single rays differ in %zu values", differ);
            free(img[0]);
            free(img[1]);
        }
    }
    {
        /* A telephoto view: a quad 2 across and a sphere of radius 1 seen from 36, 361 and 3612
         * units away, lit by a point light at the eye, so every pixel is lit. The hit point was
         * org + t dir, off the surface by the float spacing of the far eye, more than the ray
         * offset: at 361 units 98 of the quad's 1024 pixels and 41 of the sphere's were in their own
         * shadow (ambient only, 0.08 against 0.9). */
        for (int k = 0; k < 6; k++) {
            double dd = k % 3 == 0 ? 30.0 : k % 3 == 1 ? 300.0 : 3000.0;
            double ex = 0.6 * dd, ey = 0.3 * dd, ez = dd;
            double fov = 2.0 * atan(0.5 / sqrt(ex * ex + ey * ey + ez * ez)) * 180.0 / 3.14159265358979;
            snprintf(path, sizeof path, "%s/tele.nff", tmp);
            FILE *tf = fopen(path, "w");
            CHECK(tf != NULL);
            if (!tf) break;
            fprintf(tf, "v\nfrom %g %g %g\nat 0 0 0\nup 0 1 0\nangle %.9g\nhither 0.001\nresolution 32 32\nb 0 0 0\n"
                        "l %g %g %g\nf 1 1 1 1 0 0 0 0\n%s",
                    ex, ey, ez, fov, ex, ey, ez, k < 3 ? "p 4\n-1 -1 0\n1 -1 0\n1 1 0\n-1 1 0\n" : "s 0 0 0 1\n");
            fclose(tf);
            snprintf(args, sizeof args, "render '%s' -o '%s/tele.pfm' --quiet", path, tmp);
            EXPECT(args, 0, "");
            char tpath[1200], terr[512] = "";
            snprintf(tpath, sizeof tpath, "%s/tele.pfm", tmp);
            int tw = 0, th = 0, tc = 0;
            float *img = rp_image_read_pfm(tpath, &tw, &th, &tc, terr, sizeof terr);
            CHECKF(img && tw == 32 && th == 32 && tc == 3, "%s", terr);
            if (!img) continue;
            int dark = 0;
            for (int i = 0; i < 32 * 32; i++) dark += img[3 * i] < 0.5f;
            CHECKF(dark == 0, "the %s seen from %g units away: %d of 1024 pixels in their own shadow",
                   k < 3 ? "quad" : "sphere", dd * sqrt(1.45), dark);
            free(img);
        }
    }
    return RP_TEST_END();
}
