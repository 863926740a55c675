/* The uniform grid as a core acceleration structure (RP_ACCEL_GRID): the voxel lists of grid.c
 * (resolution rule, margin, triangle / voxel overlap) repacked as tri4 blocks per voxel, so a
 * voxel's triangles are tested four at a time by the BVH's watertight leaf test (tri_leaf.h) and
 * every query returns the BVH's hits bit for bit. A triangle in several voxels is in a block of
 * each; a mailbox of the triangles tested (Amanatides, Woo 1987) skips a block whose triangles
 * were all tested already. Triangles are listed by the full triangle-box overlap test (grid_desc.sat).
 * Traversal is the 3D-DDA of Amanatides and Woo, front to back, ending when the closest hit lies
 * before the current voxel's exit; empty space is crossed by proximity clouds (Cohen, Sheffer
 * 1994): each empty voxel stores how far the empty cube around it reaches, and the walk jumps to
 * that cube's exit in one step. Coherent packets walk slice by slice (grid_packet). The builder
 * is here; the traversal is grid_trav.inc, compiled once per ISA as the BVH's kernels are. */
#include <math.h>
#include <string.h>

#include "accel/grid/grid.h"
#include "accel/grid/grid_layout.h"

/* The clear cubes of octant o (bit k set: the cube grows towards +axis k) from the occupancy in d
 * (0: occupied, else empty): d[v] becomes the side of the largest empty cube with v at its corner
 * that lies in octant o, at most 255 (voxels outside the grid count as empty). A cube of side n at
 * v is v and the cubes of side n - 1 at its 7 neighbours in the octant, so one pass that visits
 * those neighbours first gives it (the largest empty square's recurrence, in 3D). */
static void clear_cubes(uint8_t *d, const int32_t res[3], int o) {
    const int32_t nx = res[0], ny = res[1], nz = res[2];
    const int32_t sx = o & 1 ? 1 : -1, sy = o & 2 ? 1 : -1, sz = o & 4 ? 1 : -1;
    uint8_t m[4096]; /* per x: the least of the neighbours in the rows already done (res <= 4096) */
    for (int32_t zi = 0; zi < nz; zi++) {
        int32_t z = sz > 0 ? nz - 1 - zi : zi;
        for (int32_t yi = 0; yi < ny; yi++) {
            int32_t y = sy > 0 ? ny - 1 - yi : yi;
            uint8_t *row = d + ((size_t)z * (size_t)ny + (size_t)y) * (size_t)nx;
            bool in_y = y + sy >= 0 && y + sy < ny, in_z = z + sz >= 0 && z + sz < nz;
            const uint8_t *ry = in_y ? d + ((size_t)z * (size_t)ny + (size_t)(y + sy)) * (size_t)nx : NULL;
            const uint8_t *rz = in_z ? d + ((size_t)(z + sz) * (size_t)ny + (size_t)y) * (size_t)nx : NULL;
            const uint8_t *ryz = in_y && in_z ? d + ((size_t)(z + sz) * (size_t)ny + (size_t)(y + sy)) * (size_t)nx : NULL;
            for (int32_t x = 0; x < nx; x++) {
                uint8_t v = 254; /* outside the grid: empty */
                if (ry && ry[x] < v) v = ry[x];
                if (rz && rz[x] < v) v = rz[x];
                if (ryz && ryz[x] < v) v = ryz[x];
                m[x] = v;
            }
            /* along the row, in the octant's order: x + sx is done before x */
            for (int32_t xi = 0; xi < nx; xi++) {
                int32_t x = sx > 0 ? nx - 1 - xi : xi;
                if (!row[x]) continue;
                uint8_t v = m[x];
                if (x + sx >= 0 && x + sx < nx) {
                    if (m[x + sx] < v) v = m[x + sx];
                    if (row[x + sx] < v) v = row[x + sx];
                }
                row[x] = (uint8_t)(v + 1);
            }
        }
    }
}

/* voxels per triangle when rp_scene_desc.grid_density is 0 */
#define GRID_ACCEL_DENSITY 4.0f

static bool grid_accel_build(const sys_allocator *a, sys_pool *pool, accel_tri_input *in, accel_built *out) {
    (void)pool;
    memset(out, 0, sizeof *out);
    grid_tri *tris = sys_alloc(a, (size_t)(in->count ? in->count : 1) * sizeof(grid_tri));
    if (!tris) return false;
    for (uint32_t i = 0; i < in->count; i++) {
        grid_tri *t = &tris[i];
        prim_ref r = in->refs[i];
        in->fetch(in->user, r, t->v, &t->mask);
        t->geom = r.geom, t->prim = r.prim, t->pad = 0;
    }
    grid_desc gd = {.density = in->grid_density > 0.0f ? in->grid_density : GRID_ACCEL_DENSITY, .sat = true};
    grid *g = grid_build_tris(a, tris, in->count, &gd);
    sys_free(a, tris, (size_t)(in->count ? in->count : 1) * sizeof(grid_tri));
    if (!g) return false;
    uint64_t blocks = 0;
    for (uint32_t v = 0; v < g->voxel_count; v++) blocks += (g->offsets[v + 1] - g->offsets[v] + 3) / 4;
    if (blocks >= UINT32_MAX / 4) {
        grid_free(g);
        return false;
    }
    const uint32_t occ_words = (g->voxel_count + 63) / 64;
    size_t bytes = LAYOUT_HEAD + (size_t)occ_words * sizeof(uint64_t) + ((size_t)g->voxel_count + 1) * sizeof(uint32_t) + (size_t)blocks * 4 * sizeof(uint32_t) +
                   8 * (size_t)g->voxel_count;
    grid_layout *lay = sys_alloc(a, bytes);
    tri4 *tb = lay ? accel_blocks_alloc(a, (uint32_t)blocks) : NULL;
    if (!tb) {
        sys_free(a, lay, bytes);
        grid_free(g);
        return false;
    }
    memset(lay, 0, LAYOUT_HEAD);
    for (int k = 0; k < 3; k++) lay->lo[k] = g->lo[k], lay->cell[k] = g->cell[k], lay->res[k] = g->res[k];
    for (int k = 0; k < 3; k++) lay->inv_cell[k] = 1.0f / g->cell[k];
    lay->voxel_count = g->voxel_count;
    lay->block_count = blocks;
    lay->occ_words = occ_words;
    uint64_t *occ = (uint64_t *)layout_occupied(lay);
    memset(occ, 0, (size_t)occ_words * sizeof(uint64_t));
    for (uint32_t v = 0; v < g->voxel_count; v++)
        if (g->offsets[v] != g->offsets[v + 1]) occ[v >> 6] |= (uint64_t)1 << (v & 63);
    uint32_t *first = (uint32_t *)layout_first(lay), *ids = first + g->voxel_count + 1;
    for (int o = 0; o < 8; o++) {
        uint8_t *clear = (uint8_t *)layout_clear(lay, o);
        for (uint32_t v = 0; v < g->voxel_count; v++) clear[v] = g->offsets[v] != g->offsets[v + 1] ? 0 : 1;
        clear_cubes(clear, lay->res, o);
    }
    uint32_t b = 0;
    for (uint32_t v = 0; v < g->voxel_count; v++) {
        first[v] = b;
        for (uint32_t k = g->offsets[v]; k < g->offsets[v + 1]; k += 4, b++) {
            uint32_t n = g->offsets[v + 1] - k < 4 ? g->offsets[v + 1] - k : 4;
            tri4 *dst = &tb[b];
            for (uint32_t lane = 0; lane < 4; lane++) {
                /* unused lanes: lane 0 again, as the BVH's blocks */
                uint32_t i = g->items[k + (lane < n ? lane : 0)];
                ids[4 * b + lane] = i;
                if (lane >= n) continue;
                const grid_tri *t = &g->tris[i];
                for (int q = 0; q < 9; q++) dst->v[q][lane] = t->v[q];
                dst->geom[lane] = t->geom, dst->prim[lane] = t->prim;
            }
            tri4_pad(dst, n);
        }
    }
    first[g->voxel_count] = b;
    out->nodes = lay;
    out->node_bytes = bytes;
    out->blocks = tb;
    out->block_count = (uint32_t)blocks;
    out->root_depth = 1;
    out->nodes_total = g->voxel_count;
    out->inner_nodes = 0;
    out->leaves = g->nonempty;
    out->tri_refs = g->item_count;
    out->sah_cost = 0.0;
    for (int k = 0; k < 3; k++) out->bounds[k] = g->lo[k], out->bounds[3 + k] = g->hi[k];
    grid_free(g);
    return true;
}


/* The traversal of the device's ISA (rp_kernels.isa of the BVH's kernels: 1, 4, 8, 16). */
static const rp_kernels *grid_kernels_for_isa(int isa) {
    switch (isa) {
    case 16: return &grid_accel_avx512_kernels;
    case 8: return &grid_accel_avx2_kernels;
    case 4: return &grid_accel_sse_kernels;
    default: return &grid_accel_scalar_kernels;
    }
}

RP_HIDDEN const accel_ops accel_grid = {"grid", grid_accel_build, &grid_accel_scalar_kernels, grid_kernels_for_isa};
