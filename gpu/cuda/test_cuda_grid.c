/* The CUDA grid kernel (gpu/cuda) gives rp_intersect1's hits bit for bit (geom, prim, t, u, v, Ng)
 * on the bunny and the conference: the eye rays of a view (the stream tracer's camera rays) and
 * random rays from inside the box. Exits 77 (CTest: skipped) with a message when no CUDA device is
 * found. With --bench it traces 1024x1024 eye rays and prints the kernel's Mrays/s (kernel time by
 * CUDA events, copies excluded) beside the CPU grid's and BVH's single-thread rates. */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "accel/grid/grid.h"
#include "cuda_grid.h"
#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"
#include "stream/stream.h"
#include "sys/sys.h"

static bool same_f(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }
static uint64_t rng = 7;
static float rnd(void) {
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return (float)(rng >> 40) * (1.0f / 16777216.0f);
}

static void run_scene(rp_device *dev, const char *file, const rp_camera *cam_in, int w, int h, bool bench) {
    char buf[512], err[512] = "";
    const char *path = rp_test_scene(file, buf, sizeof buf);
    CHECKF(path != NULL, "%s", file);
    if (!path) return;
    rp_scene_data d;
    if (!rp_scene_data_load(path, &d, err, sizeof err)) {
        CHECKF(0, "%s", err);
        return;
    }
    rp_render_scene *rs = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    grid *g = rs ? grid_build_scene(rp_render_scene_core(rs), NULL, err, sizeof err) : NULL;
    CHECKF(g != NULL, "%s: %s", file, err);
    if (g) {
        rp_scene *scene = rp_render_scene_core(rs);
        rp_cuda_grid *cg = rp_cuda_grid_from_grid(g, err, sizeof err);
        CHECKF(cg != NULL, "%s: %s", file, err);
        size_t n = (size_t)w * (size_t)h, nr = n / 4;
        rp_rayhit *ref = malloc((n + nr) * sizeof(rp_rayhit));
        rp_cuda_ray *rays = calloc(n + nr, sizeof(rp_cuda_ray));
        float *px = malloc(n * 3 * sizeof(float));
        rp_camera cam = cam_in ? *cam_in : rp_render_scene_default_camera(rs);
        stream_desc sd = {.width = w, .height = h, .camera = &cam};
        CHECK(stream_render(rs, g, &sd, px, ref, NULL, err, sizeof err));
        for (size_t i = n; i < n + nr; i++) { /* random rays from inside the box */
            rp_ray r = {.tfar = INFINITY, .mask = 0xFFFFFFFFu};
            float o[3], dd[3];
            for (int a = 0; a < 3; a++) o[a] = g->lo[a] + (g->hi[a] - g->lo[a]) * rnd(), dd[a] = 2.0f * rnd() - 1.0f;
            r.org_x = o[0], r.org_y = o[1], r.org_z = o[2], r.dir_x = dd[0], r.dir_y = dd[1], r.dir_z = dd[2];
            ref[i].ray = r;
        }
        for (size_t i = 0; i < n + nr; i++) {
            rp_cuda_ray *c = &rays[i];
            const rp_ray *r = &ref[i].ray;
            c->org[0] = r->org_x, c->org[1] = r->org_y, c->org[2] = r->org_z, c->tnear = r->tnear;
            c->dir[0] = r->dir_x, c->dir[1] = r->dir_y, c->dir[2] = r->dir_z, c->tfar = i < n ? INFINITY : r->tfar;
            c->mask = r->mask, c->geom = c->prim = 0xFFFFFFFFu;
            /* the reference: rp_intersect1 of the same ray */
            ref[i].ray.tfar = c->tfar;
            ref[i].hit = (rp_hit){.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID};
        }
        double t0 = sys_seconds();
        for (size_t i = 0; i < n; i++) rp_intersect1(scene, &ref[i]);
        double bvh_s = sys_seconds() - t0;
        for (size_t i = n; i < n + nr; i++) rp_intersect1(scene, &ref[i]);
        t0 = sys_seconds();
        for (size_t i = 0; i < n; i++) {
            rp_rayhit x = ref[i];
            x.ray.tfar = INFINITY;
            grid_intersect1(g, &x, NULL);
        }
        double grid_s = sys_seconds() - t0;
        float ms = 0.0f;
        bool ok = cg && rp_cuda_grid_intersect(cg, rays, n, &ms, err, sizeof err) &&
                  rp_cuda_grid_intersect(cg, rays + n, nr, NULL, err, sizeof err);
        CHECKF(ok, "%s: %s", file, err);
        size_t bad = 0;
        for (size_t i = 0; ok && i < n + nr; i++) {
            const rp_cuda_ray *c = &rays[i];
            const rp_rayhit *r = &ref[i];
            bool same = c->geom == r->hit.geom_id && c->prim == r->hit.prim_id && same_f(c->tfar, r->ray.tfar);
            if (same && c->geom != 0xFFFFFFFFu)
                same = same_f(c->u, r->hit.u) && same_f(c->v, r->hit.v) && same_f(c->ng[0], r->hit.Ng_x) &&
                       same_f(c->ng[1], r->hit.Ng_y) && same_f(c->ng[2], r->hit.Ng_z);
            bad += !same;
        }
        CHECKF(bad == 0, "%s: %zu of %zu GPU hits differ from rp_intersect1", file, bad, n + nr);
        printf("%s: %zu eye + %zu random rays, %zu differ", file, n, nr, bad);
        if (bench)
            printf("; eye rays: CUDA grid kernel %.1f Mrays/s (%.3f ms), CPU grid %.2f, CPU BVH %.2f Mrays/s (1 thread)",
                   ms > 0.0f ? (double)n / (ms * 1e3) : 0.0, (double)ms, (double)n / grid_s * 1e-6,
                   (double)n / bvh_s * 1e-6);
        printf("\n");
        free(ref), free(rays), free(px);
        rp_cuda_grid_free(cg);
    }
    grid_free(g);
    rp_render_scene_release(rs);
    rp_scene_data_free(&d);
}

int main(int argc, char **argv) {
    bool bench = argc > 1 && strcmp(argv[1], "--bench") == 0;
    int devices = rp_cuda_device_count();
    if (devices == 0) {
        printf("skipped: no CUDA device found (the kernel was compiled; run gpu/cuda/run_on_gpu.sh on a GPU)\n");
        return 77;
    }
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    int w = bench ? 1024 : 320, h = bench ? 1024 : 240;
    run_scene(dev, "stanford_bunny_bun_zipper.ply.gz", NULL, w, h, bench);
    rp_camera inside = {.type = RP_CAMERA_PINHOLE,
                        .pinhole = {.eye = {1500, 350, 500}, .look = {300, 200, 300}, .up = {0, 1, 0}, .fov_deg = 60}};
    run_scene(dev, "conference_geom.obj.gz", &inside, w, h, bench);
    rp_device_release(dev);
    return RP_TEST_END();
}
