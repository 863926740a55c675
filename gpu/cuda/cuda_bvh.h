/* CUDA backend over raypack's BVH (gpu/cuda): the canonical binary BVH of a committed scene in a
 * GPU layout (Aila and Laine 2009: each inner node holds both children's boxes), closest-hit and
 * any-hit traversal kernels with the CPU's watertight test and (geom, prim) tie-break (built with
 * --fmad=false, so hits equal rp_intersect1's bit for bit), and a small pipeline that makes primary
 * and diffuse bounce rays on the device, once as a megakernel (one thread follows a pixel from its
 * eye ray to its bounce's hit) and once as a wavefront (Laine, Karras, Aila 2013: one kernel per
 * stage over ray streams, the bounce stream compacted between passes).
 *
 * Plain C / C++ header (stdint only). Triangles only: spheres and user geometry stay on the CPU
 * (rp_cuda_bvh_src_from_scene counts what it leaves out). Errors return 0 / NULL and write a
 * message into err. Every pointer argument is host memory. */
#ifndef RP_CUDA_BVH_H
#define RP_CUDA_BVH_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A child reference: an inner node's index, or a leaf: RP_CUDA_LEAF | first << RP_CUDA_COUNT_BITS |
 * count, triangles [first, first + count) of the triangle array. */
#define RP_CUDA_LEAF 0x80000000u
#define RP_CUDA_COUNT_BITS 6u
#define RP_CUDA_MAX_LEAF ((1u << RP_CUDA_COUNT_BITS) - 1u)
#define RP_CUDA_MAX_TRIS (1u << (31u - RP_CUDA_COUNT_BITS))
/* The traversal stack's entries: the converter refuses deeper trees. */
#define RP_CUDA_STACK 96u

/* The GPU layout, host side. Node i is 16 floats: (l.lo.x, l.hi.x, l.lo.y, l.hi.y),
 * (r.lo.x, r.hi.x, r.lo.y, r.hi.y), (l.lo.z, l.hi.z, r.lo.z, r.hi.z), (l ref, r ref, 0, 0) as bits;
 * node 0 is the root. Triangle j is 12 floats: v0 xyz, geom; v1 xyz, prim; v2 xyz, mask (ids and
 * mask as bits), in leaf order. */
typedef struct rp_cuda_bvh_src {
    float *nodes;
    uint32_t node_count;
    float *tris;
    uint32_t tri_count;
    uint32_t depth;          /* levels of the binary BVH */
    size_t skipped;          /* primitives the GPU does not trace (spheres, user geometry) */
} rp_cuda_bvh_src;

/* One ray (the layout of bench_ray) and one hit (geom RP_INVALID_ID / 0xFFFFFFFF: none; an
 * occlusion query writes t = -inf when occluded, else leaves t = tfar). */
typedef struct rp_cuda_bvh_ray {
    float org[3], tnear;
    float dir[3], tfar;
} rp_cuda_bvh_ray;

typedef struct rp_cuda_bvh_hit {
    float t, u, v;
    uint32_t geom, prim;
    float ng[3];
} rp_cuda_bvh_hit;

typedef enum rp_cuda_kernel {
    RP_CUDA_KERNEL_SIMPLE = 0,     /* one thread per ray */
    RP_CUDA_KERNEL_PERSISTENT = 1, /* persistent warps fetching 32 rays at a time (Aila and Laine) */
    RP_CUDA_KERNEL_SPECULATIVE = 2, /* one thread per ray, leaves postponed until the warp has one each */
    RP_CUDA_KERNEL_COUNT = 3
} rp_cuda_kernel;

typedef struct rp_cuda_bvh rp_cuda_bvh;
typedef struct rp_cuda_batch rp_cuda_batch;

/* The GPU layout of a committed scene's binary BVH (the default structure, RP_ACCEL_BVH): its
 * triangles in leaf order, without the tri4 blocks' padding lanes. C side (gpu/cuda/cuda_bvh_scene.c);
 * out owns its arrays until rp_cuda_bvh_src_free. */
struct rp_scene;
bool rp_cuda_bvh_src_from_scene(const struct rp_scene *scene, rp_cuda_bvh_src *out, char *err, size_t err_size);
void rp_cuda_bvh_src_free(rp_cuda_bvh_src *src);

/* Name of a kernel ("simple", "persistent", "speculative"). */
const char *rp_cuda_kernel_name(rp_cuda_kernel k);
/* The device's name, multiprocessors and memory, as one line into out; 0 without a device. */
int rp_cuda_device_info(char *out, size_t out_size);
/* Copies a BVH to device 0. */
rp_cuda_bvh *rp_cuda_bvh_upload(const rp_cuda_bvh_src *src, char *err, size_t err_size);
void rp_cuda_bvh_free(rp_cuda_bvh *bvh);
/* Bytes the BVH takes on the device. */
size_t rp_cuda_bvh_bytes(const rp_cuda_bvh *bvh);

/* n rays on the device and room for their hits. */
rp_cuda_batch *rp_cuda_batch_new(const rp_cuda_bvh_ray *rays, size_t n, char *err, size_t err_size);
void rp_cuda_batch_free(rp_cuda_batch *batch);
/* Page-locked host memory (cudaMallocHost: copies to and from it run at the bus's speed); NULL when
 * there is none or no device. */
void *rp_cuda_host_alloc(size_t bytes);
void rp_cuda_host_free(void *p);
/* Replaces the batch's rays by n others, growing its device memory when n is more than it held. */
int rp_cuda_batch_set(rp_cuda_batch *batch, const rp_cuda_bvh_ray *rays, size_t n, char *err, size_t err_size);
/* Traces the batch (closest hit, or any hit with occlusion); *ms gets the kernel's time (CUDA
 * events), NULL allowed. */
int rp_cuda_bvh_trace(const rp_cuda_bvh *bvh, rp_cuda_batch *batch, rp_cuda_kernel kernel, bool occlusion,
                      float *ms, char *err, size_t err_size);
/* Copies the batch's hits (n of them) to out. */
int rp_cuda_batch_hits(const rp_cuda_batch *batch, rp_cuda_bvh_hit *out, char *err, size_t err_size);

/* The kernels' traversal run on the CPU, one ray after another, over the host layout: the same code
 * as the device's (host and device functions), for checking the layout and the traversal where no
 * GPU is. */
void rp_cuda_bvh_trace_emulated(const rp_cuda_bvh_src *src, const rp_cuda_bvh_ray *rays, size_t n, bool occlusion,
                                rp_cuda_bvh_hit *hits);

/* A pinhole view (DESIGN.md's camera contract) and the seed of the bounce directions. */
typedef struct rp_cuda_view {
    float eye[3], look[3], up[3];
    float fov_deg;
    int width, height;
    uint32_t seed;
} rp_cuda_view;

/* What a pipeline run gives, per pixel (index y * width + x), all host arrays of width * height:
 * the primary ray and hit, and the bounce ray (tfar < 0 where the primary ray missed: no bounce)
 * and its hit. Any of them may be NULL. */
typedef struct rp_cuda_frame {
    rp_cuda_bvh_ray *primary_rays, *bounce_rays;
    rp_cuda_bvh_hit *primary_hits, *bounce_hits;
    /* times (CUDA events): the whole frame; for the wavefront also its primary and bounce trace
     * passes alone */
    float total_ms, primary_ms, bounce_ms;
    uint32_t bounce_count;   /* bounce rays traced */
} rp_cuda_frame;

/* Renders the view's primary and diffuse bounce rays on the device, as a megakernel or as a
 * wavefront; both give the same rays and hits. */
int rp_cuda_bvh_frame(const rp_cuda_bvh *bvh, const rp_cuda_view *view, bool wavefront, rp_cuda_frame *out,
                      char *err, size_t err_size);

#ifdef __cplusplus
}
#endif
#endif
