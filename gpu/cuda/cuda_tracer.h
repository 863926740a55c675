/* Rays traced on the GPU for the CPU's renderer (gpu/cuda): a committed scene's BVH uploaded once,
 * then batches of rp_rayhit traced by the CUDA BVH kernels with rp_intersect1's and rp_occluded1's
 * answers, bit for bit. The stream tracer takes it as its tracer (stream_desc.trace = rp_cuda_trace),
 * so `raypack render --engine cuda` runs the renderer's integrators (Whitted, path, direct, AO) with
 * every ray on the GPU and the shading on the CPU, a wavefront of one stream per depth and kind.
 *
 * With emulate, the kernels' own traversal code runs on the CPU over the GPU layout
 * (rp_cuda_bvh_trace_emulated): the same answers where no GPU is, for checking the backend in CI.
 * The GPU traces the triangles; a scene's spheres, cones and user primitives are traced on the CPU
 * after it (a structure of their own, the same geom_ids), the nearer hit kept. Instances are
 * refused (one level: the CLI flattens animations). */
#ifndef RP_CUDA_TRACER_H
#define RP_CUDA_TRACER_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "cuda_bvh.h"
#include "raypack.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rp_cuda_tracer rp_cuda_tracer;

/* What a tracer did so far. */
typedef struct rp_cuda_tracer_stats {
    uint64_t rays, batches;
    double kernel_ms;        /* in the kernels (CUDA events; 0 when emulated) */
    double total_ms;         /* in rp_cuda_trace: conversion, copies both ways and kernels */
} rp_cuda_tracer_stats;

/* Converts scene's BVH to the GPU layout and, unless emulate, uploads it to device 0. NULL with a
 * message in err: no device, a scene the GPU cannot trace, out of memory. */
rp_cuda_tracer *rp_cuda_tracer_new(const rp_scene *scene, rp_cuda_kernel kernel, bool emulate, char *err,
                                   size_t err_size);
void rp_cuda_tracer_free(rp_cuda_tracer *t);
/* The device's name (or "CPU (emulated kernels)") and the BVH's bytes on it. */
const char *rp_cuda_tracer_device(const rp_cuda_tracer *t);
size_t rp_cuda_tracer_bytes(const rp_cuda_tracer *t);
rp_cuda_tracer_stats rp_cuda_tracer_get_stats(const rp_cuda_tracer *t);

/* stream_desc.trace: user is the rp_cuda_tracer. Traces rays[0..n) as rp_intersect1 each (closest
 * hit: ray.tfar and hit set on a hit) or, with occlusion, as rp_occluded1 (ray.tfar = -inf when
 * blocked). Rays with a mask other than all ones are refused (the GPU layout keeps geometry masks,
 * the kernels test against all ones). */
bool rp_cuda_trace(void *tracer, rp_rayhit *rays, size_t n, bool occlusion, char *err, size_t err_size);

#ifdef __cplusplus
}
#endif
#endif
