/* The CUDA BVH kernels (cuda_bvh.cu) and the CUDA grid kernel (cuda_grid.cu) against the CPU, and
 * their speed. For each mesh file (cuda_mesh.h, written by gpu_mesh_dump):
 *  - ray sets made on the CPU: primary rays (DESIGN.md's camera), shadow rays to the light (any
 *    hit) and cosine-distributed diffuse bounce rays from the primary hits; each traced by
 *    rp_intersect1 / rp_occluded1 and by every GPU kernel, hit for hit (t, u, v, geom, prim, Ng bit
 *    for bit; occluded or not); primary rays also through the GPU grid;
 *  - the frame pipeline on the GPU (eye rays, hits, a diffuse bounce each, its hit) as a megakernel
 *    and as a wavefront: both give the same rays and hits, bit for bit, and the rays they made give
 *    rp_intersect1's hits on the CPU.
 * Then Mrays/s of each kernel on each set (kernel time by CUDA events, best of --repeats; copies
 * excluded) and of the pipeline's passes.
 * Where no CUDA device is found, the kernels' traversal code runs on the CPU over the same GPU
 * layout (rp_cuda_bvh_trace_emulated) and is checked the same way on the three sets, so CI tests
 * the converter and the traversal logic; the rest is skipped.
 *   test_cuda_bvh [--size WxH] [--repeats N] MESH...
 * Links the core alone (see cuda_mesh.h). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "accel/grid/grid.h"
#include "cuda_bvh.h"
#include "cuda_grid.h"
#include "cuda_mesh.h"
#include "raypack.h"
#include "rp_test.h"

static bool same_f(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void normalize(float v[3]) {
    float l = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int a = 0; a < 3; a++) v[a] /= l;
}

static void cross(const float a[3], const float b[3], float o[3]) {
    o[0] = a[1] * b[2] - a[2] * b[1], o[1] = a[2] * b[0] - a[0] * b[2], o[2] = a[0] * b[1] - a[1] * b[0];
}

/* A hashed uniform in [0, 1) from (index, dimension). */
static float rnd(uint32_t i, uint32_t dim) {
    uint64_t z = ((uint64_t)i << 32 | dim) + 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return (float)(z >> 40) * (1.0f / 16777216.0f);
}

typedef struct ray_set {
    const char *name;
    bool occlusion;
    size_t n;
    rp_cuda_bvh_ray *rays;
    rp_rayhit *ref; /* the CPU's answers */
} ray_set;

typedef struct cpu_job {
    rp_scene *scene;
    ray_set *set;
} cpu_job;

#define CHUNK 4096u

static void cpu_task(void *user, uint32_t index, uint32_t thread) {
    (void)thread;
    cpu_job *j = user;
    ray_set *s = j->set;
    size_t end = (size_t)(index + 1) * CHUNK < s->n ? (size_t)(index + 1) * CHUNK : s->n;
    for (size_t i = (size_t)index * CHUNK; i < end; i++) {
        const rp_cuda_bvh_ray *r = &s->rays[i];
        rp_rayhit *rh = &s->ref[i];
        memset(rh, 0, sizeof *rh);
        rh->ray = (rp_ray){.org_x = r->org[0], .org_y = r->org[1], .org_z = r->org[2], .tnear = r->tnear,
                           .dir_x = r->dir[0], .dir_y = r->dir[1], .dir_z = r->dir[2], .tfar = r->tfar,
                           .mask = 0xFFFFFFFFu};
        rh->hit.geom_id = rh->hit.prim_id = rh->hit.inst_id = RP_INVALID_ID;
        if (s->occlusion)
            rp_occluded1(j->scene, &rh->ray);
        else
            rp_intersect1(j->scene, rh);
    }
}

/* The CPU's answers for a set, on every thread of the device. */
static void cpu_trace(rp_device *dev, rp_scene *scene, ray_set *s) {
    s->ref = malloc((s->n ? s->n : 1) * sizeof *s->ref);
    cpu_job j = {scene, s};
    rp_device_parallel_for(dev, (uint32_t)((s->n + CHUNK - 1) / CHUNK), cpu_task, &j);
}

/* GPU hits against the CPU's; returns how many differ. */
static size_t compare(const ray_set *s, const rp_cuda_bvh_hit *h) {
    size_t bad = 0;
    for (size_t i = 0; i < s->n; i++) {
        const rp_rayhit *r = &s->ref[i];
        bool same;
        if (s->occlusion) {
            same = (r->ray.tfar == -INFINITY) == (h[i].t == -INFINITY);
        } else {
            same = h[i].geom == r->hit.geom_id && h[i].prim == r->hit.prim_id && same_f(h[i].t, r->ray.tfar);
            if (same && h[i].geom != RP_INVALID_ID)
                same = same_f(h[i].u, r->hit.u) && same_f(h[i].v, r->hit.v) && same_f(h[i].ng[0], r->hit.Ng_x) &&
                       same_f(h[i].ng[1], r->hit.Ng_y) && same_f(h[i].ng[2], r->hit.Ng_z);
        }
        if (!same && bad < 3)
            fprintf(stderr, "  %s ray %zu: GPU geom %u prim %u t %.9g, CPU geom %u prim %u t %.9g\n", s->name, i,
                    h[i].geom, h[i].prim, (double)h[i].t, r->hit.geom_id, r->hit.prim_id, (double)r->ray.tfar);
        bad += !same;
    }
    return bad;
}

/* Primary rays of DESIGN.md's camera, in 8x4 tiles (one GPU warp each). */
static void make_primary(const cuda_mesh *m, int w, int h, ray_set *s) {
    float f[3], r[3], u[3];
    for (int a = 0; a < 3; a++) f[a] = m->look[a] - m->eye[a];
    normalize(f);
    cross(f, m->up, r);
    normalize(r);
    cross(r, f, u);
    float th = tanf(m->fov_deg * 0.5f * 3.14159265358979f / 180.0f), aspect = (float)w / (float)h;
    s->name = "primary", s->occlusion = false, s->n = 0;
    s->rays = malloc((size_t)w * (size_t)h * sizeof *s->rays);
    for (int ty = 0; ty < h; ty += 4)
        for (int tx = 0; tx < w; tx += 8)
            for (int y = ty; y < ty + 4 && y < h; y++)
                for (int x = tx; x < tx + 8 && x < w; x++) {
                    float sx = (2.0f * ((float)x + 0.5f) / (float)w - 1.0f) * th * aspect;
                    float sy = (1.0f - 2.0f * ((float)y + 0.5f) / (float)h) * th;
                    rp_cuda_bvh_ray *ray = &s->rays[s->n++];
                    for (int a = 0; a < 3; a++) ray->org[a] = m->eye[a], ray->dir[a] = f[a] + sx * r[a] + sy * u[a];
                    normalize(ray->dir);
                    ray->tnear = 0.0f, ray->tfar = INFINITY;
                }
}

/* From each primary hit: a shadow ray to the light, or a cosine-distributed diffuse ray. */
static void make_next(const ray_set *p, const cuda_mesh *m, bool shadow, ray_set *s) {
    s->name = shadow ? "shadow" : "diffuse", s->occlusion = shadow, s->n = 0;
    s->rays = malloc((p->n ? p->n : 1) * sizeof *s->rays);
    for (size_t i = 0; i < p->n; i++) {
        const rp_rayhit *h = &p->ref[i];
        if (h->hit.geom_id == RP_INVALID_ID) continue;
        float n[3] = {h->hit.Ng_x, h->hit.Ng_y, h->hit.Ng_z}, hp[3];
        float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(len > 0.0f)) continue;
        const rp_cuda_bvh_ray *pr = &p->rays[i];
        float side = n[0] * pr->dir[0] + n[1] * pr->dir[1] + n[2] * pr->dir[2] > 0.0f ? -1.0f : 1.0f;
        float scale = 1e-4f;
        for (int a = 0; a < 3; a++) {
            n[a] *= side / len;
            hp[a] = pr->org[a] + h->ray.tfar * pr->dir[a];
            scale = fmaxf(scale, fabsf(hp[a]) * 1e-4f);
        }
        rp_cuda_bvh_ray *r = &s->rays[s->n++];
        for (int a = 0; a < 3; a++) r->org[a] = hp[a] + n[a] * scale;
        r->tnear = 0.0f;
        if (shadow) {
            float d = 0.0f;
            for (int a = 0; a < 3; a++) r->dir[a] = m->light[a] - r->org[a], d += r->dir[a] * r->dir[a];
            d = sqrtf(d);
            for (int a = 0; a < 3; a++) r->dir[a] /= d;
            r->tfar = d * 0.999f;
        } else {
            float u1 = rnd((uint32_t)i, 0), u2 = rnd((uint32_t)i, 1);
            float rad = sqrtf(u1), phi = 6.28318530717959f * u2;
            float lx = rad * cosf(phi), ly = rad * sinf(phi), lz = sqrtf(fmaxf(0.0f, 1.0f - u1));
            float sg = copysignf(1.0f, n[2]), a = -1.0f / (sg + n[2]), b = n[0] * n[1] * a;
            float t1[3] = {1.0f + sg * n[0] * n[0] * a, sg * b, -sg * n[0]}, t2[3] = {b, sg + n[1] * n[1] * a, -n[1]};
            for (int k = 0; k < 3; k++) r->dir[k] = lx * t1[k] + ly * t2[k] + lz * n[k];
            normalize(r->dir);
            r->tfar = INFINITY;
        }
    }
}

static double best_of(const float *ms, int n) {
    double b = INFINITY;
    for (int i = 0; i < n; i++) b = ms[i] < b ? ms[i] : b;
    return b;
}

/* The GPU grid on the primary set, against the CPU's hits. */
static void grid_check(rp_scene *scene, const ray_set *p, const char *name, int repeats) {
    char err[512] = "";
    grid *g = grid_build_scene(scene, NULL, err, sizeof err);
    CHECKF(g != NULL, "%s: grid: %s", name, err);
    if (!g) return;
    rp_cuda_grid *cg = rp_cuda_grid_from_grid(g, err, sizeof err);
    CHECKF(cg != NULL, "%s: %s", name, err);
    rp_cuda_ray *rays = calloc(p->n ? p->n : 1, sizeof *rays);
    float best = INFINITY;
    bool ok = cg != NULL;
    for (int k = 0; ok && k < repeats; k++) {
        for (size_t i = 0; i < p->n; i++) {
            memcpy(rays[i].org, p->rays[i].org, 12), memcpy(rays[i].dir, p->rays[i].dir, 12);
            rays[i].tnear = p->rays[i].tnear, rays[i].tfar = p->rays[i].tfar;
            rays[i].mask = 0xFFFFFFFFu, rays[i].geom = rays[i].prim = RP_INVALID_ID;
        }
        float ms = 0.0f;
        ok = rp_cuda_grid_intersect(cg, rays, p->n, &ms, err, sizeof err);
        best = ms < best ? ms : best;
    }
    CHECKF(ok, "%s: grid: %s", name, err);
    size_t bad = 0;
    for (size_t i = 0; ok && i < p->n; i++) {
        const rp_cuda_ray *c = &rays[i];
        const rp_rayhit *r = &p->ref[i];
        bool same = c->geom == r->hit.geom_id && c->prim == r->hit.prim_id && same_f(c->tfar, r->ray.tfar);
        if (same && c->geom != RP_INVALID_ID)
            same = same_f(c->u, r->hit.u) && same_f(c->v, r->hit.v) && same_f(c->ng[0], r->hit.Ng_x);
        bad += !same;
    }
    CHECKF(bad == 0, "%s: %zu of %zu GPU grid hits differ from rp_intersect1", name, bad, p->n);
    printf("  grid %dx%dx%d: primary %zu rays, %zu differ, %.1f Mrays/s (kernel %.3f ms, rays and hits copied by the call)\n",
           g->res[0], g->res[1], g->res[2], p->n, bad, (double)p->n / ((double)best * 1e3), (double)best);
    free(rays);
    rp_cuda_grid_free(cg);
    grid_free(g);
}

/* The pipeline as megakernel and wavefront: equal outputs, the rays' hits equal the CPU's. */
static void frame_check(rp_device *dev, rp_scene *scene, const rp_cuda_bvh *gb, const cuda_mesh *m, int w, int h,
                        const char *name, int repeats) {
    size_t px = (size_t)w * (size_t)h;
    rp_cuda_frame fr[2];
    for (int k = 0; k < 2; k++) {
        memset(&fr[k], 0, sizeof fr[k]);
        fr[k].primary_rays = malloc(px * sizeof(rp_cuda_bvh_ray)), fr[k].bounce_rays = malloc(px * sizeof(rp_cuda_bvh_ray));
        fr[k].primary_hits = malloc(px * sizeof(rp_cuda_bvh_hit)), fr[k].bounce_hits = malloc(px * sizeof(rp_cuda_bvh_hit));
    }
    rp_cuda_view v = {.fov_deg = m->fov_deg, .width = w, .height = h, .seed = 1};
    memcpy(v.eye, m->eye, 12), memcpy(v.look, m->look, 12), memcpy(v.up, m->up, 12);
    char err[512] = "";
    float tot[2][16], prim[16], bounce[16];
    bool ok = true;
    int reps = repeats < 16 ? repeats : 16;
    for (int k = 0; ok && k < 2; k++)
        for (int i = 0; ok && i < reps; i++) {
            ok = rp_cuda_bvh_frame(gb, &v, k == 1, &fr[k], err, sizeof err);
            tot[k][i] = fr[k].total_ms;
            if (k == 1) prim[i] = fr[k].primary_ms, bounce[i] = fr[k].bounce_ms;
        }
    CHECKF(ok, "%s: frame: %s", name, err);
    if (ok) {
        bool same = memcmp(fr[0].primary_rays, fr[1].primary_rays, px * sizeof(rp_cuda_bvh_ray)) == 0 &&
                    memcmp(fr[0].primary_hits, fr[1].primary_hits, px * sizeof(rp_cuda_bvh_hit)) == 0 &&
                    memcmp(fr[0].bounce_rays, fr[1].bounce_rays, px * sizeof(rp_cuda_bvh_ray)) == 0 &&
                    memcmp(fr[0].bounce_hits, fr[1].bounce_hits, px * sizeof(rp_cuda_bvh_hit)) == 0 &&
                    fr[0].bounce_count == fr[1].bounce_count;
        CHECKF(same, "%s: the megakernel and the wavefront differ", name);
        /* the GPU's own rays through the CPU */
        ray_set ps = {.name = "frame primary", .n = px, .rays = fr[1].primary_rays};
        cpu_trace(dev, scene, &ps);
        size_t bad_p = compare(&ps, fr[1].primary_hits);
        ray_set bs = {.name = "frame bounce", .n = 0, .rays = malloc(px * sizeof(rp_cuda_bvh_ray))};
        rp_cuda_bvh_hit *bh = malloc(px * sizeof *bh);
        for (size_t i = 0; i < px; i++)
            if (fr[1].bounce_rays[i].tfar >= 0.0f) bs.rays[bs.n] = fr[1].bounce_rays[i], bh[bs.n++] = fr[1].bounce_hits[i];
        cpu_trace(dev, scene, &bs);
        size_t bad_b = compare(&bs, bh);
        CHECKF(bad_p == 0 && bad_b == 0 && bs.n == fr[1].bounce_count,
               "%s: frame: %zu primary and %zu bounce hits differ from the CPU's (%zu bounces, GPU counted %u)", name,
               bad_p, bad_b, bs.n, fr[1].bounce_count);
        double mk = best_of(tot[0], reps), wf = best_of(tot[1], reps), bp = best_of(prim, reps),
               bb = best_of(bounce, reps);
        printf("  frame %dx%d, %u bounces: megakernel %.3f ms (%.1f Mrays/s), wavefront %.3f ms (%.1f Mrays/s): "
               "its primary pass %.1f Mrays/s, its bounce pass %.1f Mrays/s; %zu + %zu hits differ from the CPU\n",
               w, h, fr[1].bounce_count, mk, (double)(px + fr[0].bounce_count) / (mk * 1e3), wf,
               (double)(px + fr[1].bounce_count) / (wf * 1e3), (double)px / (bp * 1e3),
               (double)fr[1].bounce_count / (bb * 1e3), bad_p, bad_b);
        free(ps.ref), free(bs.ref), free(bs.rays), free(bh);
    }
    for (int k = 0; k < 2; k++)
        free(fr[k].primary_rays), free(fr[k].bounce_rays), free(fr[k].primary_hits), free(fr[k].bounce_hits);
}

/* Without a GPU: the kernels' traversal on the CPU, over the GPU layout. */
static void emulated_check(const rp_cuda_bvh_src *src, ray_set *sets, int count, const char *name) {
    for (int s = 0; s < count; s++) {
        ray_set *set = &sets[s];
        rp_cuda_bvh_hit *hits = malloc((set->n ? set->n : 1) * sizeof *hits);
        double t0 = now_s();
        rp_cuda_bvh_trace_emulated(src, set->rays, set->n, set->occlusion, hits);
        double t = now_s() - t0;
        size_t bad = compare(set, hits);
        CHECKF(bad == 0, "%s: %s rays, the kernels' traversal on the CPU: %zu of %zu hits differ", name, set->name,
               bad, set->n);
        printf("  %-8s %8zu rays, the kernels' traversal run on the CPU: %zu differ (%.2f Mrays/s, 1 thread)\n",
               set->name, set->n, bad, (double)set->n / t * 1e-6);
        free(hits);
    }
}

static void run_mesh(rp_device *dev, const char *path, int w, int h, int repeats, bool gpu) {
    cuda_mesh m;
    char err[512] = "";
    if (!cuda_mesh_read(path, &m, err, sizeof err)) {
        CHECKF(0, "%s", err);
        return;
    }
    const char *name = strrchr(path, '/') ? strrchr(path, '/') + 1 : path;
    rp_scene *scene = rp_scene_new(dev, NULL);
    rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, m.positions, 0, 0, m.vertex_count);
    rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, m.indices, 0, 0, m.triangle_count);
    rp_geometry_commit(g);
    rp_scene_attach(scene, g);
    rp_geometry_release(g);
    double t0 = now_s();
    CHECKF(rp_scene_commit(scene) == RP_ERROR_NONE, "%s: commit", name);
    double build_s = now_s() - t0;
    rp_cuda_bvh_src src;
    bool ok = rp_cuda_bvh_src_from_scene(scene, &src, err, sizeof err);
    CHECKF(ok, "%s: %s", name, err);
    rp_cuda_bvh *gb = ok && gpu ? rp_cuda_bvh_upload(&src, err, sizeof err) : NULL;
    CHECKF(gb != NULL || !gpu, "%s: %s", name, err);
    if (ok && (gb || !gpu)) {
        printf("%s: %llu triangles, CPU BVH build %.0f ms (%d threads), GPU layout %u nodes, %u triangles, depth %u, "
               "%.1f MiB\n",
               name, (unsigned long long)m.triangle_count, build_s * 1e3, rp_device_thread_count(dev), src.node_count,
               src.tri_count, src.depth, (double)(src.node_count * 64ull + src.tri_count * 48ull) / 1048576.0);
        ray_set sets[3];
        make_primary(&m, w, h, &sets[0]);
        cpu_trace(dev, scene, &sets[0]);
        make_next(&sets[0], &m, true, &sets[1]);
        make_next(&sets[0], &m, false, &sets[2]);
        for (int s = 1; s < 3; s++) cpu_trace(dev, scene, &sets[s]);
        if (!gb) emulated_check(&src, sets, 3, name);
        for (int s = 0; gb && s < 3; s++) {
            ray_set *set = &sets[s];
            rp_cuda_batch *q = rp_cuda_batch_new(set->rays, set->n, err, sizeof err);
            CHECKF(q != NULL, "%s: %s", name, err);
            rp_cuda_bvh_hit *hits = malloc((set->n ? set->n : 1) * sizeof *hits);
            for (int k = 0; q && k < RP_CUDA_KERNEL_COUNT; k++) {
                float ms[64];
                int reps = repeats < 64 ? repeats : 64;
                bool tok = rp_cuda_bvh_trace(gb, q, (rp_cuda_kernel)k, set->occlusion, NULL, err, sizeof err); /* warm */
                for (int i = 0; tok && i < reps; i++)
                    tok = rp_cuda_bvh_trace(gb, q, (rp_cuda_kernel)k, set->occlusion, &ms[i], err, sizeof err);
                tok = tok && rp_cuda_batch_hits(q, hits, err, sizeof err);
                CHECKF(tok, "%s: %s", name, err);
                if (!tok) continue;
                size_t bad = compare(set, hits);
                CHECKF(bad == 0, "%s: %s rays, kernel %s: %zu of %zu hits differ from the CPU's", name, set->name,
                       rp_cuda_kernel_name((rp_cuda_kernel)k), bad, set->n);
                double b = best_of(ms, reps);
                printf("  %-8s %8zu rays, kernel %-10s: %zu differ, %8.1f Mrays/s (best of %d: %.3f ms)\n", set->name,
                       set->n, rp_cuda_kernel_name((rp_cuda_kernel)k), bad, (double)set->n / (b * 1e3), reps, b);
            }
            free(hits);
            rp_cuda_batch_free(q);
        }
        if (gb) {
            grid_check(scene, &sets[0], name, repeats < 5 ? repeats : 5);
            frame_check(dev, scene, gb, &m, w, h, name, repeats);
        }
        for (int s = 0; s < 3; s++) free(sets[s].rays), free(sets[s].ref);
    }
    rp_cuda_bvh_free(gb);
    rp_cuda_bvh_src_free(&src);
    rp_scene_release(scene);
    cuda_mesh_free(&m);
}

int main(int argc, char **argv) {
    int w = 512, h = 512, repeats = 5, first = 1;
    for (; first < argc && strncmp(argv[first], "--", 2) == 0; first += 2) {
        if (first + 1 >= argc) break;
        if (strcmp(argv[first], "--size") == 0 && sscanf(argv[first + 1], "%dx%d", &w, &h) == 2 && w > 0 && h > 0) continue;
        if (strcmp(argv[first], "--repeats") == 0 && sscanf(argv[first + 1], "%d", &repeats) == 1 && repeats > 0) continue;
        fprintf(stderr, "usage: test_cuda_bvh [--size WxH] [--repeats N] MESH...\n");
        return 2;
    }
    char info[256];
    bool gpu = rp_cuda_device_info(info, sizeof info);
    if (gpu)
        printf("device: %s\n", info);
    else
        printf("no CUDA device found: the kernels' traversal is checked on the CPU, the GPU runs are skipped "
               "(gpu/cuda/run_on_gpu.sh runs them on a GPU)\n");
    if (first >= argc) {
        fprintf(stderr, "test_cuda_bvh: no mesh files (gpu_mesh_dump writes them)\n");
        return 2;
    }
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 0});
    for (int i = first; i < argc; i++) run_mesh(dev, argv[i], w, h, repeats, gpu);
    rp_device_release(dev);
    return RP_TEST_END();
}
