/* Large ray packets (Overbeck, Ramamoorthi, Mark 2008): the per-ISA kernel table of packet_n.inc. */
#ifndef RP_PACKET_N_H
#define RP_PACKET_N_H

#include "raypack.h"
#include "traverse/frustum.h"
#include "traverse/traverse.h"

/* The three algorithms of sec. 3, Span (Ranged narrowed from both ends, packet_n.inc), the
 * per-packet choice, auto's way out for incoherent packets (one SIMD ray at a time through the
 * wide BVH, done by the caller) and multi-level ray tracing, as indices of rp_counters_n.traversal. */
typedef enum pkt_alg {
    PKT_AUTO = 0,
    PKT_MASKED = 1,
    PKT_RANGED = 2,
    PKT_PARTITION = 3,
    PKT_SPAN = 4,
    PKT_SIMD = 5,
    PKT_MLRT = 6 /* entry points found by the packet's frusta, then Span from them (packet_n.inc) */
} pkt_alg;

/* Auto's classes of packets (kn_prepare); a coherent packet always goes to Span, the others
 * have two ways each, which rp_auto_tally learns to choose from. */
typedef enum auto_class {
    AUTO_PARTING = 0,    /* the spread is too wide for Span: Partition (way 0) or Span (1) */
    AUTO_INCOHERENT = 1, /* ... and for a packet, and most SIMD rays are incoherent too: a packet (0)
                            or SIMD rays (1) */
    AUTO_COHERENT = 2
} auto_class;

/* Auto's learned choice for the two classes of packets its measure cannot settle
 * (rp_auto_tally): until each way of a class has TALLY_WARM packets the ways take turns; then each
 * packet goes the way whose packets took less time per live ray, every TALLY_EXPLORE-th the other
 * way. A way's figures are halved when they reach 2 * TALLY_WINDOW packets, so they follow the
 * recent packets; a packet counts for at most TALLY_CAP times its way's mean, so a thread
 * preempted during one does not skew the choice for long (tally_add, api_n.c). */
#define TALLY_WARM 4
#define TALLY_EXPLORE 16
#define TALLY_WINDOW 64
#define TALLY_CAP 16

/* The way the next packet of class c (not AUTO_COHERENT) takes: the tally's choice or, without
 * one, Partition for parting packets and SIMD rays for incoherent ones. */
static inline int auto_way(const rp_auto_tally *t, auto_class c) {
    if (!t) return c == AUTO_INCOHERENT;
    const uint64_t *n = t->packets[c], *rays = t->rays[c], *ticks = t->ticks[c];
    if (n[0] < TALLY_WARM || n[1] < TALLY_WARM) return n[1] <= n[0];
    bool faster = (double)ticks[1] * (double)rays[0] < (double)ticks[0] * (double)rays[1];
    return faster != (t->seen[c] % TALLY_EXPLORE == TALLY_EXPLORE - 1);
}

/* What a kernel did with a packet. */
typedef struct kn_result {
    uint32_t live;  /* live rays */
    auto_class cls; /* AUTO_COHERENT when not traced by auto */
    int way;        /* the way its class took; for AUTO_INCOHERENT's SIMD rays (1) the packet is
                       left untouched, for the caller to trace one SIMD ray at a time */
    uint64_t start; /* sys_ticks() when the way was chosen (any class but AUTO_COHERENT, with
                       q->tally) */
} kn_result;

typedef struct rp_kernels_n {
    const char *name;
    int width; /* rays per SIMD ray */
    /* n x n rays through the binary BVH (acc->nodes2) with algorithm alg (PKT_AUTO: chosen from the
     * packet's coherence), culling with the frustum q->kind asks for; then the non-triangle
     * primitives ray by ray. Counts into c when c != NULL. */
    kn_result (*intersect_n)(const rp_accel *acc, const frustum_req *q, pkt_alg alg, rp_rayhit_n *p, rp_counters_n *c);
    kn_result (*occluded_n)(const rp_accel *acc, const frustum_req *q, pkt_alg alg, rp_rayhit_n *p, rp_counters_n *c);
} rp_kernels_n;

/* Frusta are tested only where they can spare this many ray tests (see packet_n.inc). */
#define FRUSTUM_MIN_RAYS 32
/* Auto traversal (beyond the paper, whose authors chose per scene): a packet goes to Span when its
 * direction spread (slope extent across the dominant axis) times sqrt(triangles / 4) is at most
 * this, i.e. when its footprint crosses at most about this many 4-triangle cells over the scene's
 * extent; any other packet goes to Partition, which degrades gracefully as the rays part (sec. 5.2
 * and Table 1). Span beat Partition at 16x16 and 32x32 on the coherent rays of every scene
 * `raypack bench --grid` was run on. A packet whose rays face apart (most often one across the
 * corner of two flat mirrors) goes to Span as well: summed over the grid's six levels (1024x1024,
 * 16x16 auto with frusta, callgrind) that took 1.0% fewer instructions on kitchen, 0.3-0.6% fewer
 * on museum, conference and sponza, 0.1-0.4% more on bunny, tree and rings (curved mirrors, whose
 * packets part for good), and left auto within 1% of the best fixed algorithm on every shared
 * scene (kitchen had been 1.9% behind Span). 480 rather than 120: the grid's levels took 2-5% fewer
 * instructions on kitchen's, conference's and sponza's refraction and reflection packets and
 * within 1% of the same elsewhere; 960: 0.4% fewer on kitchen and conference, 1.5% more on tree
 * (its refraction packets 6% more); with Span for every packet that faces one way (no threshold),
 * tree's refraction packets took 8% more. */
#define AUTO_SPAN_CELLS 480.0f
/* A packet whose spread crosses more than this many cells, or whose rays face apart, and more than
 * AUTO_SIMD_SHARE of whose SIMD rays are incoherent on their own too (some lane more than
 * acos(AUTO_SIMD_COS), 26 degrees, from the first) is traced one SIMD ray at a time through the
 * wide BVH instead: its rays share too few nodes for a packet to pay. Rings' 2-bounce reflections
 * off curved mirrors (`raypack bench --grid`, 16x16 auto with frusta against SIMD rays): 0.82 ->
 * 1.18 timed in pairs. Without the per-SIMD-ray test, conference's reflection packets that
 * straddle two flat mirrors went that way too and lost 10-15% against Span; with it, a fifth as
 * many do. */
#define AUTO_SIMD_CELLS 1000.0f
#define AUTO_SIMD_COS 0.9f
/* ... as a fraction of SIMD rays W wide: half up to 8 wide, 3/4 at 16 (4x4 tiles, AVX-512),
 * where half took too many of the reflection packets that Span traces faster. `raypack bench
 * --grid`, auto over the best fixed algorithm on the 2-bounce reflections, 16x16 with frusta,
 * half -> 3/4, AVX-512: conference 0.90 -> 0.96, kitchen 0.96 -> 0.98, museum 0.95 -> 0.99, bunny
 * 0.95 -> 0.97; rings 1.33 -> 1.27 and tree 1.19 -> 1.14 (their curved mirrors' packets still go
 * ray by ray); 7/8: conference 0.98, rings 1.16. AVX2 (`--isa avx2`), half -> 3/4: conference
 * 0.97 -> 1.00, but rings 1.39 -> 1.19 (32x32: 1.40 -> 1.04), so 8-wide SIMD rays keep half. */
#define AUTO_SIMD_SHARE(W) ((W) >= 16 ? 0.75f : 0.5f)
/* These thresholds sort packets into three classes (auto_class); without a tally they also choose
 * the way: Span for coherent packets, Partition for parting ones, SIMD rays for incoherent ones.
 * With a tally (rp_auto_tally, which the renderer and the bench keep per thread and kind of
 * packet) the two ways of the parting and the incoherent class are timed as they are taken, and
 * each packet takes the way that has cost less per ray (api_n.c). The thresholds alone could not
 * tell apart the incoherent packets that SIMD rays trace faster (rings' curved mirrors) from those
 * Span traces faster (conference's flat ones, 3-8% behind Span); per-packet timing can. Both ways of
 * a class are compared on one tree for the parting class; the incoherent class's SIMD rays walk
 * the wide BVH, a second tree in the caches, whose cost to the packets after them the timing does
 * not see: timing the parting class against SIMD rays as well sent conference's parting packets
 * ray by ray and left auto at 0.92-0.96 of the best fixed algorithm on its reflections (`raypack
 * bench --grid`, 8x8 to 32x32, timed in pairs) against 0.96-0.99 without that choice, so it is
 * not offered. */
/* ... in scenes of at least this many cells only: in a tree of a few hundred nodes every ray
 * visits much the same nodes, however it points (`raypack bench --vs embree`, diffuse rays, 16x16
 * auto: cornell's 36 triangles 0.91x and spd_teapot's 2328 0.80x with SIMD rays, bart_museum5's
 * 11308 1.23x, the larger scenes 1.2-3.1x). */
#define AUTO_SIMD_MIN_CELLS 1024.0f

extern const rp_kernels_n rp_kernels_n_scalar, rp_kernels_n_sse, rp_kernels_n_avx2, rp_kernels_n_avx512;

#endif
