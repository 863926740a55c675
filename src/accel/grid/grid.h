/* Uniform grid over triangles (Cleary and Wyvill 1988; Purcell et al. 2002, sec. 4.1): voxel ->
 * triangle lists in compact CSR arrays, traversed by 3D-DDA (Amanatides and Woo 1987) with
 * mailboxing. Hits are the BVH's: the same watertight test (tri_intersect_ref, the arithmetic of
 * the BVH kernels) on the same vertices, the same (geom, prim) tie-break, so grid_intersect1 gives
 * rp_intersect1's hit bit for bit.
 *
 * The traversal is split into setup / cell / step so the stream tracer (src/stream) runs it one
 * voxel per pass with the per-ray state in its own arrays, through the same code as the single-ray
 * loop. Spheres and user primitives (NFF cones) are listed in the voxels their boxes overlap, after
 * the triangles (item index tri_count + k), and tested by the core's own callbacks, as the BVH's
 * leaves test them; instances are not (a flat scene only). */
#ifndef RP_GRID_H
#define RP_GRID_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "raypack.h"
#include "sys/sys.h"
#include "traverse/traverse.h"

typedef struct grid_desc {
    /* Cleary-Wyvill: about density * triangles voxels, as near to cubes as the box allows; 0: 4 */
    float density;
    /* the paper's rule instead (sec. 5): cubic voxels, this many along the box's shortest side
     * (64 for the bunny gives 98 x 64 x 163); 0: use density */
    int min_dim;
    int max_voxels; /* cap on the voxel count (memory); 0: 1 << 24 */
    /* list a triangle only in the voxels it overlaps by the full separating-axis test (Akenine-
     * Moller 2001: the box's axes, the triangle's normal and the nine edge x axis directions),
     * not the voxels of its box that its plane crosses: fewer references for long thin and
     * slanted triangles */
    bool sat;
} grid_desc;

grid_desc grid_desc_defaults(const grid_desc *desc);

/* One triangle as the grid stores it: vertices, ids and the geometry mask. */
typedef struct grid_tri {
    float v[9]; /* v0, v1, v2 */
    uint32_t geom, prim, mask;
    uint32_t pad;
} grid_tri;

typedef struct grid {
    sys_allocator alloc;
    float lo[3], hi[3];     /* the grid's box (the triangles' box, slightly enlarged) */
    float cell[3], inv_cell[3];
    int res[3];
    uint32_t voxel_count;
    uint32_t *offsets;      /* voxel_count + 1: voxel c holds items[offsets[c] .. offsets[c + 1]) */
    uint32_t *items;        /* triangle indices */
    size_t item_count;
    grid_tri *tris;
    uint32_t tri_count;
    size_t tri_capacity;    /* allocated (live lanes; non-finite triangles are dropped) */
    uint32_t nonempty;      /* voxels with at least one triangle */
    /* spheres and user primitives: items tri_count + k, tested through the scene's accel */
    const rp_accel *acc;
    prim_ref *prims;
    float *prim_box;        /* 6 per primitive: lo xyz, hi xyz */
    uint32_t prim_count;
    double build_ms;
} grid;

/* Builds a grid over the triangles of tri4 blocks (tri4_lanes) whose geometry's mask is not 0
 * (geom_masks: per geom_id), copying their vertices. NULL when out of memory. A grid of no
 * triangles is valid (every ray misses). */
grid *grid_build_tri4(const sys_allocator *alloc, const tri4 *blocks, size_t block_count, const uint32_t *geom_masks,
                      const grid_desc *desc);
/* Builds a grid over count triangles (copied; non-finite ones are dropped, so g->tris[i] is
 * tris[i] when all are finite). NULL when out of memory. */
grid *grid_build_tris(const sys_allocator *alloc, const grid_tri *tris, uint32_t count, const grid_desc *desc);
/* Builds a grid of a committed scene's triangles, spheres and user primitives. NULL with a message in
 * err when the scene is not committed, holds instances, or memory runs out. Owned by the caller (grid_free);
 * valid while the scene is not edited. */
grid *grid_build_scene(rp_scene *scene, const grid_desc *desc, char *err, size_t err_size);
void grid_free(grid *g);
/* Bytes the grid holds. */
size_t grid_bytes(const grid *g);

/* Work of one query, added to by grid_intersect1 / grid_occluded1 when not NULL. */
typedef struct grid_work {
    uint64_t voxels;        /* voxels visited (stepped into) */
    uint64_t tests;         /* ray-triangle tests (mailboxed repeats not counted) */
} grid_work;

/* rp_intersect1 / rp_occluded1 over the grid (triangles only). */
void grid_intersect1(const grid *g, rp_rayhit *rh, grid_work *work);
void grid_occluded1(const grid *g, rp_ray *ray, grid_work *work);

/* ---- the traversal in steps (for the stream tracer) ----------------------------------------- */

/* A ray's traversal state: the current voxel and what is needed to step from it. */
typedef struct grid_walk {
    float org[3], dir[3], rcp[3];
    float t_end;            /* end of the segment inside the grid */
    int cell[3], step[3];
} grid_walk;

/* Traversal setup: clips [tnear, tfar] to the grid's box and finds the first voxel; false when the
 * ray misses the box. */
bool grid_walk_setup(const grid *g, const rp_ray *ray, grid_walk *w);
/* Voxel index of the walk's current cell. */
static inline uint32_t grid_walk_voxel(const grid *g, const grid_walk *w) {
    return ((uint32_t)w->cell[2] * (uint32_t)g->res[1] + (uint32_t)w->cell[1]) * (uint32_t)g->res[0] +
           (uint32_t)w->cell[0];
}
/* Distance at which the ray leaves the current voxel. */
float grid_walk_exit(const grid *g, const grid_walk *w);
/* Steps into the next voxel along the ray; false when the ray leaves the grid or its segment
 * (ending at tfar, the closest hit so far). */
bool grid_walk_step(const grid *g, grid_walk *w, float tfar);

/* A closest hit so far. */
typedef struct grid_hit {
    float t, u, v;
    uint32_t tri;           /* item: index into g->tris, or tri_count + primitive; UINT32_MAX: none */
    float ng[3];            /* a primitive's normal, as its callback wrote it */
} grid_hit;

/* Tests item i (a triangle, or a primitive through the core's callback); on a hit in [tnear, h->t] that is nearer, or as near with a lower (geom, prim),
 * takes it. Returns true on any hit in [tnear, h->t] (for any-hit queries). */
bool grid_test(const grid *g, uint32_t i, const rp_ray *ray, grid_hit *h);
/* Writes a closest hit into rh as rp_intersect1 does. */
void grid_hit_write(const grid *g, const grid_hit *h, rp_rayhit *rh);

/* Direct-mapped mailbox of recently tested triangles (Amanatides and Woo): a triangle spanning
 * several voxels is tested once per ray, mostly. A miss in it only costs a repeated test. */
#define GRID_MAILBOX 8
static inline bool grid_mailbox_seen(uint32_t *mb, uint32_t tri) {
    uint32_t *slot = &mb[tri % GRID_MAILBOX];
    if (*slot == tri) return true;
    *slot = tri;
    return false;
}

#endif
