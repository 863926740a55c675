// rp-test: labels=bench timeout=300
/* `--accel` in raypack render, info and bench, and `raypack bench --accel-grid` on a tiny scene
 * (so it cannot rot): exit statuses, the table's check line, the JSON's keys, and renders that are
 * byte for byte the same file whatever the structure. Speed is not checked: tests do not time. */
#include <limits.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "raypack.h"
#include "cli_run.h"
#include "rp_test.h"


static char *slurp(const char *path, size_t *size) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *b = malloc((size_t)n + 1);
    *size = fread(b, 1, (size_t)n, f);
    b[*size] = '\0';
    fclose(f);
    return b;
}

int main(void) {
    if (!find_exe()) {
        CHECK(!"raypack binary built");
        return RP_TEST_END();
    }
    const char *dir = getenv("RP_TEST_TMP");
    char tmp[900], args[4096], buf[512];
    snprintf(tmp, sizeof tmp, "%s", dir ? dir : "/tmp/raypack_test_cli_accel");
    mkdir(tmp, 0777);
    const char *teapot = rp_test_scene("spd_teapot.nff.gz", buf, sizeof buf);
    if (!teapot) {
        CHECK(!"spd_teapot found");
        return RP_TEST_END();
    }
    EXPECT("info --accel octree", 2, "expects bvh, kdtree, bih or grid");
    EXPECT("render --accel grid --density 0", 2, "--density");
    EXPECT("info --accel grid --density -1", 2, "--density");
    EXPECT("bench --accel grid --density 1001", 2, "--density");
    EXPECT("render --accel", 2, "--accel");
    EXPECT("bench --accel-grid --grid", 2, "--accel-grid");
    snprintf(args, sizeof args, "info '%s' --accel kdtree", teapot);
    EXPECT(args, 0, "triangle references");
    snprintf(args, sizeof args, "info '%s' --accel bih", teapot);
    EXPECT(args, 0, "bih ");
    snprintf(args, sizeof args, "info '%s' --accel grid", teapot);
    EXPECT(args, 0, "voxels");
    /* --density sets the grid's resolution: 8 voxels per triangle make more of them than 1 */
    unsigned long long vox[2] = {0, 0};
    static const char *const dens[2] = {"1", "8"};
    for (int d = 0; d < 2; d++) {
        snprintf(args, sizeof args, "info '%s' --accel grid --density %s", teapot, dens[d]);
        EXPECT(args, 0, "voxels");
        const char *g = strstr(output, "grid  ");
        CHECKF(g && sscanf(g, "grid %llu voxels", &vox[d]) == 1, "info --density %s prints the voxels", dens[d]);
    }
    CHECKF(vox[0] > 0 && vox[1] > 4 * vox[0], "--density 8 gives more voxels (%llu) than --density 1 (%llu)", vox[1],
           vox[0]);
    /* the same image from every structure, byte for byte (Whitted: shadows and reflections too) */
    size_t sizes[RP_ACCEL_COUNT];
    char *png[RP_ACCEL_COUNT];
    static const char *names[RP_ACCEL_COUNT] = {"bvh", "kdtree", "bih", "grid"};
    for (int a = 0; a < RP_ACCEL_COUNT; a++) {
        char path[1024];
        snprintf(path, sizeof path, "%s/teapot_%s.png", tmp, names[a]);
        snprintf(args, sizeof args, "render '%s' --accel %s --width 96 --height 72 -o '%s'", teapot, names[a], path);
        EXPECT(args, 0, "");
        png[a] = slurp(path, &sizes[a]);
        CHECKF(png[a] && sizes[a] > 100, "%s renders", names[a]);
    }
    for (int a = 1; a < RP_ACCEL_COUNT; a++)
        CHECKF(png[0] && png[a] && sizes[a] == sizes[0] && memcmp(png[a], png[0], sizes[0]) == 0,
               "the %s image equals the bvh one", names[a]);
    for (int a = 0; a < RP_ACCEL_COUNT; a++) free(png[a]);
    /* builds on 2 threads (the BVH's and the BIH's builds go parallel from 4096 triangles: the
     * bunny), checked under ThreadSanitizer too */
    char buf2[512];
    const char *bunny = rp_test_scene("stanford_bunny_bun_zipper.ply.gz", buf2, sizeof buf2);
    CHECK(bunny != NULL);
    for (int a = 0; bunny && a < RP_ACCEL_COUNT; a++) {
        char path[1024];
        snprintf(path, sizeof path, "%s/bunny_%s.png", tmp, names[a]);
        snprintf(args, sizeof args, "render '%s' --accel %s --threads 2 --width 64 --height 48 -o '%s'", bunny,
                 names[a], path);
        EXPECT(args, 0, "");
        png[a] = slurp(path, &sizes[a]);
        CHECKF(png[a] && sizes[a] > 100, "%s renders the bunny", names[a]);
    }
    for (int a = 1; bunny && a < RP_ACCEL_COUNT; a++)
        CHECKF(png[0] && png[a] && sizes[a] == sizes[0] && memcmp(png[a], png[0], sizes[0]) == 0,
               "the bunny's %s image equals the bvh one", names[a]);
    for (int a = 0; bunny && a < RP_ACCEL_COUNT; a++) free(png[a]);
    /* the grid on a tiny image */
    char json[1024];
    snprintf(json, sizeof json, "%s/accel_grid.json", tmp);
    snprintf(args, sizeof args, "bench '%s' --accel-grid --width 64 --height 64 --repeats 1 --warmup 0 --json '%s'",
             teapot, json);
    EXPECT(args, 0, "every structure and mode finds the BVH's single-ray hits");
    CHECK(strstr(output, "16x16") && strstr(output, "kdtree") && strstr(output, "grid") && strstr(output, "diffuse"));
    /* plain bench on the grid checks its rays against the reference too */
    snprintf(args, sizeof args, "bench '%s' --accel grid --density 2 --width 32 --height 32 --repeats 1 --warmup 0",
             teapot);
    EXPECT(args, 0, "");
    /* build times alone: every structure, in turns, with the BVH's ratio */
    EXPECT("bench --builds --accel-grid", 2, "--builds is a run of its own");
    snprintf(args, sizeof args, "bench '%s' --builds --repeats 2", teapot);
    EXPECT(args, 0, "2 builds each in turns");
    for (int a = 0; a < RP_ACCEL_COUNT; a++) {
        char key[64];
        snprintf(key, sizeof key, "build     %-7s median ", names[a]);
        const char *l = strstr(output, key);
        double med = -1.0, lo = -1.0, ratio = -1.0;
        CHECKF(l && sscanf(l + strlen(key), "%lf ms, min %lf ms, %*f MiB, BVH / this %lfx", &med, &lo, &ratio) == 3 &&
                   med > 0.0 && lo > 0.0 && lo <= med && ratio > 0.0 && (a != 0 || ratio == 1.0),
               "--builds prints %s's build (%g, %g, %g)", names[a], med, lo, ratio);
    }
    size_t n;
    char *j = slurp(json, &n);
    CHECK(j != NULL);
    if (j) {
        for (int a = 0; a < RP_ACCEL_COUNT; a++) {
            char key[64];
            snprintf(key, sizeof key, "\"%s\": {\"build_ms\": ", names[a]);
            CHECKF(strstr(j, key) != NULL, "JSON has %s", key);
        }
        CHECK(strstr(j, "\"simd16\": {\"mrays_median\": ") && strstr(j, "\"tri_refs\": ") && strstr(j, "\"bytes\": "));
        free(j);
    }
    return RP_TEST_END();
}
