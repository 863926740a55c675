/* The streaming ray tracer of Purcell, Buck, Mark and Hanrahan 2002 on the CPU: a stream of rays
 * with per-ray state (traversing, intersecting, shading, done) in structure-of-arrays form, run
 * through the paper's kernels (eye-ray generation, traversal setup, traversal step, intersection,
 * shading) over the uniform grid (accel/grid), one kernel per pass, by the multipass scheduler:
 * an oracle runs an intersection pass once 20% of the active rays need one (sec. 4.2), else a
 * traversal pass. A traversal pass steps every traversing ray by one voxel, an intersection pass
 * tests every intersecting ray against one triangle of its voxel, as the paper's fragment programs
 * do, so the pass counts and per-ray statistics are the paper's (table 2, fig. 6).
 *
 * The shading kernel either shades eye light / the paper's shadow caster, or runs one of the
 * renderer's integrators (Whitted, path, direct, AO) through the renderer's own shading functions:
 * each depth's shadow, reflection, refraction and bounce rays are streams of their own through the
 * same traversal and intersection passes, so the image is rp_render's bit for bit (the grid's hits
 * are the BVH's) and the statistics are kept per ray kind. Alpha cutouts: the intersection kernel
 * rejects a hit on a cut-out point (alpha.c's test) and the ray looks on, for every kind of ray.
 *
 * Each pass (traversal setup, traversal, intersection, and the integrators' shading kernels: eye-ray
 * generation, whitted_surface, path_vertex) runs over chunks of its stream on the device's threads,
 * and the chunks' outputs (the active list, new rays, counts) are merged in chunk order: every
 * number, image and hit is deterministic, and the same on any number of threads. */
#ifndef RP_STREAM_H
#define RP_STREAM_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "accel/grid/grid.h"
#include "raypack.h"
#include "raypack_render.h"

typedef enum stream_shading {
    STREAM_SHADE_EYELIGHT = 0, /* ray casting: |cos| between geometric normal and ray, the
                                * arithmetic of the renderer's eyelight integrator */
    STREAM_SHADE_SHADOW = 1    /* ray casting + the paper's shadow caster: kd (ambient + lit |cos|)
                                * for the first point light (or a headlight at the eye) */
} stream_shading;

typedef struct stream_desc {
    int width, height;          /* 0: 512 */
    const rp_camera *camera;    /* NULL: rp_render_scene_default_camera */
    stream_shading shading;
    float oracle;               /* intersect once this fraction of active rays needs it; 0: 0.2;
                                 * 1e-9 or less: the naive oracle (intersect if any ray needs to) */
    bool wavefront;             /* the wavefront scheduler instead: per-kernel queues compacted
                                 * between passes, both kernels every iteration (oracle unused) */
    /* When not NULL, the renderer's integrator instead of `shading`: Whitted, path, direct, AO or
     * eye light with the desc's settings (spp, depths, sampler, ambient...; its width, height and
     * camera are replaced by the ones above). The shade kernel calls the renderer's own shading
     * (whitted_surface / whitted_light, path_vertex) and emits shadow, reflection, refraction and
     * bounce rays as streams of their own, so the image equals rp_render's bit for bit. */
    const rp_render_desc *render;
    /* When not NULL, every stream is traced by this instead of the grid's passes (the CUDA backend,
     * gpu/cuda/cuda_tracer.h); stream_render's grid may then be NULL, and the grid's counters
     * (voxels, tests, passes of traversal and intersection) stay 0. It traces rays[0..n) as
     * rp_intersect1 (closest hit: ray.tfar and hit set on a hit) or, with occlusion, as rp_occluded1
     * (ray.tfar -inf when blocked) would, bit for bit; false with a message in err. */
    bool (*trace)(void *user, rp_rayhit *rays, size_t n, bool occlusion, char *err, size_t err_size);
    void *trace_user;
} stream_desc;

stream_desc stream_desc_defaults(const stream_desc *desc);

/* Statistics of the streams of one kind of ray (rp_ray_kind) over a frame. */
typedef struct stream_kind_stats {
    uint64_t rays, hits;         /* hits: closest hit found, or (shadow rays) occluded */
    uint64_t batches;            /* streams of this kind run through the scheduler */
    uint64_t traversal_passes, intersection_passes; /* of those streams */
    uint64_t voxels, tests;
    uint32_t max_voxels, max_tests;
} stream_kind_stats;

/* Statistics of one frame (all streams: eye rays, then shadow, reflection, refraction, bounce). */
typedef struct stream_stats {
    uint64_t rays, eye_rays, shadow_rays;
    uint64_t passes;             /* = traversal + intersection + other */
    uint64_t traversal_passes, intersection_passes, other_passes;
    uint64_t voxels, tests, shades; /* sums over rays: voxels visited, triangles tested, shading evaluations */
    uint32_t max_voxels, max_tests; /* the most of any ray */
    uint64_t work;               /* ray-passes that did work in traversal and intersection passes */
    uint64_t slots;              /* rays of the stream (wavefront: of the pass's queue) summed over those passes */
    double simd_efficiency;      /* work / slots: the mean fraction of a pass's rays doing work */
    uint64_t eye_hits, shadow_blocked;
    uint64_t cutouts;            /* hits on cut-out points of alpha-tested surfaces that the intersection
                                  * kernel passed over (counted in tests, not in hits) */
    stream_kind_stats kind[RP_RAY_KIND_COUNT]; /* sums over kinds equal the totals above */
    double ms;
    double trace_ms;             /* of ms, the time in stream_desc.trace (0 over the grid) */
} stream_stats;

/* Renders width x height x 3 floats (top row first) of the scene with the stream tracer over g
 * (built from rs's core scene). hits, if not NULL, receives each eye ray and its hit (pixel order)
 * as rp_intersect1 would return them. false (with err) on bad arguments or out of memory. */
bool stream_render(rp_render_scene *rs, const grid *g, const stream_desc *desc, float *pixels, rp_rayhit *hits,
                   stream_stats *stats, char *err, size_t err_size);

/* Paper's figures for comparison (Purcell et al. 2002, table 2 and fig. 6). */
typedef struct stream_paper_row {
    const char *scene;
    int passes, traversal, intersection, other, max_traversals, max_intersections;
    double simd_efficiency;
} stream_paper_row;
extern const stream_paper_row stream_paper_table2[];
extern const size_t stream_paper_table2_count;

#endif
