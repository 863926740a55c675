/* The path tracer's bounce rays as ray sets of `raypack bench` (bounce1, bounce2): one path-traced
 * frame (spp 1, the bench's camera and size, the scene's own materials) records the rays that leave
 * its primary hits and the hits after them (rp_render_desc.bounce_rays), the incoherent rays a path
 * tracer traces, and each goes into its pixel's slot. */
#include "bench.h"
#include "cli.h"

#include <raypack_render.h>
#include <stdlib.h>
#include <string.h>

/* Block layout of bench.h: the slot of pixel (x, y). */
static size_t pixel_slot(int width, int x, int y) {
    size_t blocks_x = (size_t)((width + BENCH_BLOCK - 1) / BENCH_BLOCK);
    size_t block = (size_t)(y / BENCH_BLOCK) * blocks_x + (size_t)(x / BENCH_BLOCK);
    uint32_t lx = (uint32_t)(x % BENCH_BLOCK), ly = (uint32_t)(y % BENCH_BLOCK), s = 0;
    for (uint32_t b = 0; (1u << b) < BENCH_BLOCK; b++) s |= ((lx >> b) & 1u) << (2 * b) | ((ly >> b) & 1u) << (2 * b + 1);
    return block * BENCH_CHUNK + s;
}

bool bench_make_path_sets(bench_ctx *ctx) {
    int w = ctx->opts.width, h = ctx->opts.height;
    /* The generated sphere field has no file: its triangles with the loaders' grey diffuse. */
    rp_scene_data own;
    rp_material_data grey = {.kd = {0.8f, 0.8f, 0.8f}, .ior = 1.0f, .illum = -1, .map_kd = -1};
    const rp_scene_data *data = ctx->data;
    uint32_t *mats = NULL;
    if (!data) {
        mats = calloc(ctx->mesh.triangle_count, sizeof *mats);
        if (!mats) {
            fprintf(stderr, "raypack bench: path-traced rays: out of memory\n");
            return false;
        }
        own = (rp_scene_data){.vertex_count = ctx->mesh.vertex_count, .positions = ctx->mesh.positions,
                              .triangle_count = ctx->mesh.triangle_count, .indices = ctx->mesh.indices,
                              .tri_materials = mats, .material_count = 1, .materials = &grey};
        data = &own;
    }
    char err[512] = "";
    rp_render_scene *rs = rp_render_scene_new(ctx->device, data, NULL, err, sizeof err);
    rp_ray *rays = malloc(2 * (size_t)w * (size_t)h * sizeof *rays);
    float *px = malloc((size_t)w * (size_t)h * 3 * sizeof *px);
    bool ok = rs && rays && px;
    if (!ok) fprintf(stderr, "raypack bench: path-traced rays: %s\n", !rs && err[0] ? err : "out of memory");
    if (ok) {
        const bench_camera *c = &ctx->camera;
        rp_camera cam = {.type = RP_CAMERA_PINHOLE};
        memcpy(cam.pinhole.eye, c->eye, sizeof c->eye);
        memcpy(cam.pinhole.look, c->look, sizeof c->look);
        memcpy(cam.pinhole.up, c->up, sizeof c->up);
        cam.pinhole.fov_deg = c->fov_deg;
        rp_render_desc d = {.width = w, .height = h, .integrator = RP_INTEGRATOR_PATH, .max_depth = 2,
                            .camera = &cam, .bounce_rays = rays};
        ok = rp_render(rs, &d, px, NULL);
        if (!ok) fprintf(stderr, "raypack bench: path-traced rays: rendering failed (out of memory?)\n");
    }
    for (int k = 0; ok && k < 2; k++) {
        bench_rays *set = &ctx->sets[BENCH_BOUNCE1 + k];
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                const rp_ray *r = &rays[(size_t)k * (size_t)w * (size_t)h + (size_t)y * (size_t)w + (size_t)x];
                if (!(r->tfar >= 0.0f)) continue;
                size_t slot = pixel_slot(w, x, y);
                set->rays[slot] = (bench_ray){.org = {r->org_x, r->org_y, r->org_z}, .tnear = r->tnear,
                                              .dir = {r->dir_x, r->dir_y, r->dir_z}, .tfar = r->tfar};
                set->valid[slot] = -1;
                set->count++;
            }
    }
    if (rs) rp_render_scene_release(rs);
    free(rays);
    free(px);
    free(mats);
    return ok;
}
