/* Large ray packets (Overbeck, Ramamoorthi, Mark 2008): the per-ISA kernel table of packet_n.inc. */
#ifndef RP_PACKET_N_H
#define RP_PACKET_N_H

#include "raypack.h"
#include "traverse/frustum.h"
#include "traverse/traverse.h"

/* The three algorithms of sec. 3, Span (Ranged narrowed from both ends, packet_n.inc) and the
 * per-packet choice, as indices of rp_counters_n.traversal. */
typedef enum pkt_alg { PKT_AUTO = 0, PKT_MASKED = 1, PKT_RANGED = 2, PKT_PARTITION = 3, PKT_SPAN = 4 } pkt_alg;

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
/* Auto traversal (beyond the paper, whose authors chose per scene): a packet goes to Span when its
 * direction spread (slope extent across the dominant axis) times sqrt(triangles / 4) is at most
 * this, i.e. when its footprint crosses at most about this many 4-triangle cells over the scene's
 * extent; any other packet (and one whose rays face apart) goes to Partition, which degrades
 * gracefully as the rays part (sec. 5.2 and Table 1). Span beat Partition at 16x16 and 32x32 on
 * the coherent rays of every scene `raypack bench --grid` was run on. */
#define AUTO_SPAN_CELLS 120.0f

extern const rp_kernels_n rp_kernels_n_scalar, rp_kernels_n_sse, rp_kernels_n_avx2, rp_kernels_n_avx512;

#endif
