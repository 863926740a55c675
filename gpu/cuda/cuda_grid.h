/* CUDA backend of the uniform grid (gpu/cuda): the grid's arrays on a CUDA device and the same
 * 3D-DDA closest-hit traversal (accel/grid/grid.c) as a megakernel, one thread per ray, with the
 * same watertight arithmetic (built with --fmad=false), so hits equal the CPU's bit for bit.
 * Plain C / C++ header (stdint only): the C side fills it from a grid, the .cu reads it. */
#ifndef RP_CUDA_GRID_H
#define RP_CUDA_GRID_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A grid as plain arrays (host memory), the fields of accel/grid/grid.h's grid. */
typedef struct rp_cuda_grid_src {
    float lo[3], hi[3], cell[3], inv_cell[3];
    int res[3];
    uint32_t voxel_count, tri_count;
    size_t item_count;
    const uint32_t *offsets, *items;
    const float *tris;       /* 16 floats per triangle: v0, v1, v2, then geom, prim, mask as bits */
} rp_cuda_grid_src;

/* One ray and its closest hit, as rp_rayhit's fields (48 + 32 bytes). */
typedef struct rp_cuda_ray {
    float org[3], tnear, dir[3], tfar;  /* tfar: the hit distance on return */
    uint32_t mask, geom, prim, pad;     /* geom, prim: 0xFFFFFFFF when nothing was hit */
    float u, v, ng[3], pad2[3];
} rp_cuda_ray;

typedef struct rp_cuda_grid rp_cuda_grid;

/* Number of CUDA devices, 0 when there are none or no driver. */
int rp_cuda_device_count(void);
/* Copies a grid to device 0; NULL with a message in err on failure. */
rp_cuda_grid *rp_cuda_grid_upload(const rp_cuda_grid_src *src, char *err, size_t err_size);
/* Traces n rays (closest hit) on the device; kernel_ms gets the kernel's time (events). */
int rp_cuda_grid_intersect(rp_cuda_grid *g, rp_cuda_ray *rays, size_t n, float *kernel_ms, char *err,
                           size_t err_size);
void rp_cuda_grid_free(rp_cuda_grid *g);
/* Copies a grid built on the CPU (accel/grid/grid.h) to device 0: rp_cuda_grid_upload of its arrays.
 * C side (cuda_bvh_scene.c). */
struct grid;
rp_cuda_grid *rp_cuda_grid_from_grid(const struct grid *g, char *err, size_t err_size);

#ifdef __cplusplus
}
#endif
#endif
