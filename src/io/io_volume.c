/* Volumes: the sparse brick grid of rp_volume_data (see raypack_io.h) and the .vdb entry of the
 * loaders. The brick table is dense over the widened active box, so finding a voxel's brick is
 * arithmetic; only bricks holding an active voxel are stored (the cloud at 1/16 resolution keeps
 * about a third of its box's bricks). */
#include <math.h>
#include <stdio.h>

#include "io/io_internal.h"
#include "io/io_volume.h"

#define B RP_VOLUME_BRICK
#define B3 (B * B * B)
/* Bricks a table may have: 2^27 slots (512 MiB of table) is far beyond any grid that fits in memory
 * voxel by voxel, and keeps every index in 32 bits. */
#define IO_VOLUME_MAX_BRICKS (1u << 27)

bool io_volume_begin(rp_volume_data *v, const int32_t lo[3], const int32_t hi[3], const float index_to_world[12]) {
    uint64_t total = 1;
    for (int a = 0; a < 3; a++) {
        if (lo[a] > hi[a] || lo[a] < INT32_MIN / 2 || hi[a] > INT32_MAX / 2) return false;
        v->active_min[a] = lo[a];
        v->active_max[a] = hi[a];
        v->origin[a] = lo[a] - 1;
        uint64_t extent = (uint64_t)((int64_t)hi[a] + 1 - ((int64_t)lo[a] - 1) + 1); /* voxels, widened */
        v->dims[a] = (uint32_t)((extent + B - 1) / B);
        total *= v->dims[a];
        if (total > IO_VOLUME_MAX_BRICKS) return false;
    }
    memcpy(v->index_to_world, index_to_world, sizeof v->index_to_world);
    v->brick_slot = io_malloc((size_t)total * sizeof *v->brick_slot);
    if (!v->brick_slot) return false;
    memset(v->brick_slot, 0xFF, (size_t)total * sizeof *v->brick_slot); /* RP_VOLUME_EMPTY */
    v->brick_count = 0;
    return true;
}

bool io_volume_set(rp_volume_data *v, int32_t i, int32_t j, int32_t k, float value) {
    int64_t x = (int64_t)i - v->origin[0], y = (int64_t)j - v->origin[1], z = (int64_t)k - v->origin[2];
    if (x < 0 || y < 0 || z < 0) return true; /* outside the box OpenVDB gave: cannot happen, ignored */
    uint64_t bx = (uint64_t)x / B, by = (uint64_t)y / B, bz = (uint64_t)z / B;
    if (bx >= v->dims[0] || by >= v->dims[1] || bz >= v->dims[2]) return true;
    size_t cell = (size_t)((bz * v->dims[1] + by) * v->dims[0] + bx);
    uint32_t slot = v->brick_slot[cell];
    if (slot == RP_VOLUME_EMPTY) {
        slot = v->brick_count;
        /* capacity: 64 bricks, doubled whenever the count reaches a power of two past that */
        if (slot == 0 || (slot >= 64 && (slot & (slot - 1)) == 0)) {
            size_t grown = slot ? 2 * (size_t)slot : 64;
            float *d = io_realloc(v->density, grown * B3 * sizeof(float));
            if (!d) return false;
            v->density = d;
        }
        memset(v->density + (size_t)slot * B3, 0, B3 * sizeof(float));
        v->brick_slot[cell] = slot;
        v->brick_count++;
    }
    size_t in = (size_t)(((uint64_t)z % B * B + (uint64_t)y % B) * B + (uint64_t)x % B);
    v->density[(size_t)slot * B3 + in] = isfinite(value) && value > 0.0f ? value : 0.0f; /* no negative extinction */
    v->active_voxels++;
    return true;
}

bool io_volume_finish(rp_volume_data *v) {
    v->brick_max = io_malloc((v->brick_count ? v->brick_count : 1) * sizeof *v->brick_max);
    if (!v->brick_max) return false;
    v->max_density = 0.0f;
    for (uint32_t s = 0; s < v->brick_count; s++) {
        float m = 0.0f;
        const float *d = v->density + (size_t)s * B3;
        for (int q = 0; q < B3; q++)
            if (d[q] > m) m = d[q]; /* NaN never wins */
        v->brick_max[s] = m;
        if (m > v->max_density) v->max_density = m;
    }
    return true;
}

void io_volume_free(rp_volume_data *v) {
    if (!v) return;
    free(v->brick_slot);
    free(v->density);
    free(v->brick_max);
    free(v);
}

bool rp_scene_data_add_medium_box(rp_scene_data *scene, const float lo[3], const float hi[3]) {
    enum { N = 16 };
    if (!scene) return false;
    for (int a = 0; a < 3; a++)
        if (!(isfinite(lo[a]) && isfinite(hi[a]) && hi[a] > lo[a])) return false;
    rp_volume_data *v = io_calloc(1, sizeof *v);
    if (!v) return false;
    /* voxel centres 0 .. N - 1 on the box's faces */
    const float xfm[12] = {(hi[0] - lo[0]) / (N - 1), 0, 0, lo[0], 0, (hi[1] - lo[1]) / (N - 1), 0, lo[1],
                           0, 0, (hi[2] - lo[2]) / (N - 1), lo[2]};
    const int32_t vlo[3] = {0, 0, 0}, vhi[3] = {N - 1, N - 1, N - 1};
    bool ok = io_volume_begin(v, vlo, vhi, xfm);
    for (int32_t k = 0; ok && k < N; k++)
        for (int32_t j = 0; ok && j < N; j++)
            for (int32_t i = 0; ok && i < N; i++) ok = io_volume_set(v, i, j, k, 1.0f);
    ok = ok && io_volume_finish(v);
    if (!ok) {
        io_volume_free(v);
        return false;
    }
    snprintf(v->grid_name, sizeof v->grid_name, "box");
    io_volume_free(scene->volume);
    scene->volume = v;
    return true;
}

#ifndef RP_IO_HAVE_OPENVDB
bool io_vdb_read(const char *path, const char *grid, rp_volume_data *v, char *why, size_t why_size) {
    (void)path, (void)grid, (void)v;
    snprintf(why, why_size, "this raypack was built without OpenVDB (apt install libopenvdb-dev, then rebuild)");
    return false;
}
#endif

bool vdb_load(io_ctx *ctx, const char *path, const char *shown) {
    if (ctx->vfs.archive)
        return io_error(ctx, shown, 0, "a .vdb file is read from the disk only, not from an archive or memory");
    rp_volume_data *v = io_calloc(1, sizeof *v);
    if (!v) return io_error(ctx, shown, 0, "out of memory");
    char why[512] = "";
    if (!io_vdb_read(path, ctx->volume_grid, v, why, sizeof why)) {
        io_volume_free(v);
        return io_error(ctx, shown, 0, "%s", why[0] ? why : "cannot read the OpenVDB file");
    }
    if (v->active_voxels == 0) {
        io_error(ctx, shown, 0, "grid '%s' has no active voxels", v->grid_name);
        io_volume_free(v);
        return false;
    }
    ctx->volume = v;
    return true;
}
