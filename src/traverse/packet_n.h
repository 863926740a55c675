/* Large ray packets (Overbeck, Ramamoorthi, Mark 2008): the per-ISA kernel table of packet_n.inc. */
#ifndef RP_PACKET_N_H
#define RP_PACKET_N_H

#include "raypack.h"
#include "traverse/frustum.h"
#include "traverse/traverse.h"

/* The three algorithms of sec. 3 and the per-packet choice, as indices of rp_counters_n.traversal. */
typedef enum pkt_alg { PKT_AUTO = 0, PKT_MASKED = 1, PKT_RANGED = 2, PKT_PARTITION = 3 } pkt_alg;

typedef struct rp_kernels_n {
    const char *name;
    int width; /* rays per SIMD ray */
    /* n x n rays through the binary BVH (acc->nodes2) with algorithm alg (PKT_AUTO: chosen from the
     * packet's coherence), culling with the frustum q->kind asks for; then the non-triangle
     * primitives ray by ray. Counts into c when c != NULL. */
    void (*intersect_n)(const rp_accel *acc, const frustum_req *q, pkt_alg alg, rp_rayhit_n *p, rp_counters_n *c);
    void (*occluded_n)(const rp_accel *acc, const frustum_req *q, pkt_alg alg, rp_rayhit_n *p, rp_counters_n *c);
} rp_kernels_n;

/* Frusta are tested only where they can spare this many ray tests (see packet_n.inc). */
#define FRUSTUM_MIN_RAYS 32
/* Auto traversal (beyond the paper, whose authors chose per scene): a packet of up to 16x16 rays
 * goes to Ranged when its direction spread (slope extent across the dominant axis) times
 * sqrt(triangles / 4) is at most this, i.e. when its footprint crosses at most about this many
 * 4-triangle cells over the scene's extent; any other packet goes to Partition (sec. 5.2 and Table 1:
 * Ranged wins while the rays stay together, Partition degrades gracefully as they part). Fitted
 * on bunny, conference and rings (test_packets_n_bench, RP_BENCH_COMPARE=1). */
#define AUTO_RANGED_CELLS 120.0f

extern const rp_kernels_n rp_kernels_n_scalar, rp_kernels_n_sse, rp_kernels_n_avx2, rp_kernels_n_avx512;

#endif
