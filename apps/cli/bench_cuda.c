/* `raypack bench SCENE --engine cuda`: the CUDA BVH kernels (gpu/cuda/cuda_bvh.h) on the bench's
 * own ray sets (primary, shadow, reflection, diffuse, the path tracer's bounces). The scene's BVH,
 * built on the CPU, is converted to the GPU layout; each set goes to the device once and every
 * kernel traces it; its hits are checked against raypack's single-ray hits (bench_compare, and bit
 * for bit: the kernels share the CPU's arithmetic) before the kernel's time is taken (CUDA events
 * around the kernel alone, median / min / max of --repeats after --warmup launches). */
#if defined(RP_HAVE_CUDA) /* apps/cli/CMakeLists.txt: when gpu/cuda is built */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench.h"
#include "cli.h"
#include "cuda_bvh.h"
#include "raypack_io.h"

typedef struct cuda_result {
    size_t rays, differ, bits_differ;
    bench_stat ms[RP_CUDA_KERNEL_COUNT];
} cuda_result;

/* The GPU's hits as the bench keeps them; counts the valid slots whose t, prim or hit/miss is
 * not the reference's bit for bit. */
static size_t to_bench_hits(const bench_rays *set, const rp_cuda_bvh_hit *h, const bench_hits *ref,
                            bench_hits *out) {
    size_t bits = 0;
    for (size_t i = 0; i < set->slots; i++) {
        /* an occlusion query leaves tfar where nothing blocks the ray, as rp_occluded1 does */
        out->t[i] = set->occlusion ? h[i].t : (h[i].geom == RP_INVALID_ID ? INFINITY : h[i].t);
        out->prim[i] = set->occlusion ? RP_INVALID_ID : h[i].prim;
        if (set->valid[i])
            bits += memcmp(&out->t[i], &ref->t[i], sizeof(float)) != 0 || out->prim[i] != ref->prim[i];
    }
    return bits;
}

static bool write_json(const bench_ctx *ctx, const char *device, const rp_cuda_bvh_src *src, double convert_ms,
                       const cuda_result *res) {
    rp_atomic_file *af;
    FILE *f = bench_json_begin(ctx, &af);
    if (!f) return false;
    fprintf(f, ", \"engine\": \"cuda\", \"device\": ");
    bench_json_string(f, device);
    fprintf(f, ", \"triangles\": %zu, \"width\": %d, \"height\": %d, \"repeats\": %d,\n"
               " \"layout\": {\"nodes\": %u, \"triangles\": %u, \"depth\": %u, \"convert_ms\": %.3f},\n \"rays\": {",
            ctx->mesh.triangle_count, ctx->opts.width, ctx->opts.height, ctx->opts.repeats, src->node_count,
            src->tri_count, src->depth, convert_ms);
    for (int k = 0; k < BENCH_KIND_COUNT; k++) {
        const cuda_result *r = &res[k];
        fprintf(f, "%s\n  \"%s\": {\"count\": %zu, \"mismatches\": %zu, \"bit_mismatches\": %zu, \"kernels\": {",
                k ? "," : "", bench_kind_name((bench_kind)k), r->rays, r->differ, r->bits_differ);
        for (int m = 0; m < RP_CUDA_KERNEL_COUNT; m++)
            fprintf(f, "%s\"%s\": {\"mrays\": %.1f, \"median_ms\": %.4f, \"min_ms\": %.4f, \"max_ms\": %.4f}",
                    m ? ", " : "", rp_cuda_kernel_name((rp_cuda_kernel)m),
                    r->ms[m].median > 0.0 ? (double)r->rays / (r->ms[m].median * 1e3) : 0.0, r->ms[m].median,
                    r->ms[m].min, r->ms[m].max);
        fprintf(f, "}}");
    }
    fprintf(f, "\n }\n}\n");
    return bench_json_end(af);
}

int bench_vs_cuda(bench_ctx *ctx) {
    char device[256], err[512] = "";
    int rc = 1;
    rp_cuda_bvh_src src;
    memset(&src, 0, sizeof src);
    rp_cuda_bvh *gpu = NULL;
    cuda_result *res = calloc(BENCH_KIND_COUNT, sizeof *res);
    double *samples = calloc((size_t)ctx->opts.repeats, sizeof(double));
    bench_hits hits = {NULL, NULL};
    rp_cuda_bvh_hit *gh = NULL;
    if (!res || !samples) goto done;
    double build_ms = 0.0;
    rp_scene_stats stats;
    if (!ctx->scene && !(ctx->scene = bench_build_raypack(ctx, &build_ms, &stats))) goto done;
    double t0 = bench_now_ms();
    if (!rp_cuda_bvh_src_from_scene(ctx->scene, &src, err, sizeof err)) {
        fprintf(stderr, "raypack bench: %s\n", err);
        goto done;
    }
    /* the layout is made first, so that a machine without a GPU still checks the way there */
    if (!rp_cuda_device_info(device, sizeof device)) {
        fprintf(stderr, "raypack bench: --engine cuda: no CUDA device found (the GPU layout was made: %u nodes, "
                        "%u triangles)\n", src.node_count, src.tri_count);
        goto done;
    }
    if (!(gpu = rp_cuda_bvh_upload(&src, err, sizeof err))) {
        fprintf(stderr, "raypack bench: %s\n", err);
        goto done;
    }
    double convert_ms = bench_now_ms() - t0;
    if (!bench_make_ray_sets(ctx) || !bench_hits_alloc(&hits, ctx->sets[0].slots)) goto done;
    gh = malloc(ctx->sets[0].slots * sizeof *gh);
    if (!gh) goto done;
    bench_print_header(ctx);
    printf("cuda      %s; BVH built on the CPU in %.1f ms, GPU layout %u nodes, %u triangles, depth %u, %.1f MiB "
           "(converted and copied in %.1f ms)\n",
           device, build_ms, src.node_count, src.tri_count, src.depth, (double)rp_cuda_bvh_bytes(gpu) / 1048576.0,
           convert_ms);
    if (src.skipped)
        printf("cuda      %zu non-triangle primitives are not traced on the GPU\n", src.skipped);
    printf("\n%-10s %9s  %-11s %10s %10s %10s  %s\n", "rays", "count", "kernel", "Mrays/s", "min ms", "max ms",
           "hits against raypack single");
    bool failed = false;
    for (int k = 0; k < BENCH_KIND_COUNT && !failed; k++) {
        const bench_rays *set = &ctx->sets[k];
        cuda_result *r = &res[k];
        r->rays = set->count;
        /* every slot goes up; slots without a ray get an empty interval, which the kernels miss */
        rp_cuda_bvh_ray *rays = malloc(set->slots * sizeof *rays);
        if (!rays) goto done;
        for (size_t i = 0; i < set->slots; i++) {
            memcpy(&rays[i], &set->rays[i], sizeof rays[i]);
            if (!set->valid[i]) rays[i].tnear = 1.0f, rays[i].tfar = 0.0f;
        }
        rp_cuda_batch *q = rp_cuda_batch_new(rays, set->slots, err, sizeof err);
        free(rays);
        if (!q) {
            fprintf(stderr, "raypack bench: %s\n", err);
            goto done;
        }
        for (int m = 0; m < RP_CUDA_KERNEL_COUNT && !failed; m++) {
            rp_cuda_kernel kern = (rp_cuda_kernel)m;
            bool ok = rp_cuda_bvh_trace(gpu, q, kern, set->occlusion, NULL, err, sizeof err) &&
                      rp_cuda_batch_hits(q, gh, err, sizeof err);
            for (int w = 1; ok && w < ctx->opts.warmup; w++)
                ok = rp_cuda_bvh_trace(gpu, q, kern, set->occlusion, NULL, err, sizeof err);
            for (int i = 0; ok && i < ctx->opts.repeats; i++) {
                float ms = 0.0f;
                ok = rp_cuda_bvh_trace(gpu, q, kern, set->occlusion, &ms, err, sizeof err);
                samples[i] = ms;
            }
            if (!ok) {
                fprintf(stderr, "raypack bench: %s\n", err);
                rp_cuda_batch_free(q);
                goto done;
            }
            size_t bits = to_bench_hits(set, gh, &ctx->ref[k], &hits);
            bench_diff d = bench_compare(&ctx->mesh, set, &ctx->ref[k], &hits);
            r->differ = d.total > r->differ ? d.total : r->differ;
            r->bits_differ = bits > r->bits_differ ? bits : r->bits_differ;
            if (d.total || bits) {
                fprintf(stderr, "raypack bench: %s rays: cuda %s disagrees with raypack single on %zu rays (%zu not "
                                "bit for bit)\n",
                        bench_kind_name((bench_kind)k), rp_cuda_kernel_name(kern), d.total, bits);
                bench_print_mismatches(&ctx->mesh, set, &ctx->ref[k], &hits, "single", rp_cuda_kernel_name(kern), 3);
                failed = true;
            }
            r->ms[m] = bench_stats(samples, ctx->opts.repeats);
            printf("%-10s %9zu  %-11s %10.1f %10.4f %10.4f  %s\n", bench_kind_name((bench_kind)k), set->count,
                   rp_cuda_kernel_name(kern), (double)set->count / (r->ms[m].median * 1e3), r->ms[m].min,
                   r->ms[m].max, d.total || bits ? "DIFFER" : "equal, bit for bit");
        }
        rp_cuda_batch_free(q);
    }
    rc = failed ? 1 : 0;
    if (!failed && ctx->opts.json_path && !write_json(ctx, device, &src, convert_ms, res)) rc = 1;
done:
    free(gh);
    bench_hits_free(&hits);
    free(samples);
    free(res);
    rp_cuda_bvh_free(gpu);
    rp_cuda_bvh_src_free(&src);
    return rc;
}
#endif
