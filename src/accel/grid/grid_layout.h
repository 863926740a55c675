/* The uniform grid's layout as the core acceleration structure (RP_ACCEL_GRID) stores it: written
 * by grid_accel.c's builder (compiled once), read by the traversal of grid_trav.inc (compiled once
 * per instruction set, as src/traverse/kernels.inc). */
#ifndef RP_GRID_LAYOUT_H
#define RP_GRID_LAYOUT_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "accel/accel.h"

/* At the head of accel_built.nodes, followed by
 *   uint64_t occupied[occ_words]: bit v % 64 of word v / 64 set when voxel v holds triangles (one
 *   bit a voxel: 141 KiB for the conference's 1.1 M voxels, which stays in L2 where the clear
 *   bytes of an octant, 1.1 MiB, did not: perf had put a fifth of the single rays' and of the
 *   slice walk's samples on the clear byte's load),
 *   uint32_t first[voxel_count + 1]: voxel v's blocks are [first[v], first[v + 1]),
 *   uint32_t ids[4 * block_count]: the triangle of each lane (the mailbox's key),
 *   uint8_t clear[8][voxel_count]: per octant of ray directions, 0 when voxel v holds triangles,
 *   else the side (in voxels, at most 255) of the largest cube with v at its corner, growing
 *   into that octant, that holds none. (Stored in bricks of 4 x 4 x 4 voxels, a cache line each,
 *   the single rays had been slower against the BVH on all five scenes measured: docs/accel.md.) */
typedef struct grid_layout {
    float lo[3], cell[3], inv_cell[3];
    int32_t res[3];
    uint32_t voxel_count;
    uint32_t occ_words;
    uint64_t block_count;
} grid_layout;

#define LAYOUT_HEAD ((sizeof(grid_layout) + 63) / 64 * 64)

static inline const uint64_t *layout_occupied(const grid_layout *g) {
    return (const uint64_t *)((const char *)g + LAYOUT_HEAD);
}
static inline bool layout_has_tris(const uint64_t *occ, uint32_t voxel) { return occ[voxel >> 6] >> (voxel & 63) & 1u; }
static inline const uint32_t *layout_first(const grid_layout *g) {
    return (const uint32_t *)(layout_occupied(g) + g->occ_words);
}
static inline const uint32_t *layout_ids(const grid_layout *g) { return layout_first(g) + g->voxel_count + 1; }
/* One byte per voxel for a ray's octant (bit k: the ray goes towards +axis k), small enough to
 * stay in cache: empty space costs no load of first[]. */
static inline const uint8_t *layout_clear(const grid_layout *g, int octant) {
    return (const uint8_t *)(layout_ids(g) + 4 * g->block_count) + (size_t)octant * g->voxel_count;
}

/* The grid's queries, one table per instruction set (grid_trav.inc); the scene takes the one of
 * its device's ISA. */
extern const rp_kernels grid_accel_scalar_kernels, grid_accel_sse_kernels, grid_accel_avx2_kernels,
    grid_accel_avx512_kernels;

#endif
