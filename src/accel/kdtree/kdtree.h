/* SAH kd-tree over triangles (Wald, Havran 2006, "On building fast kd-trees for ray tracing, and on
 * doing that in O(N log N)"): nodes of 8 bytes, the two children of an inner node side by side,
 * leaves pointing at tri4 blocks (a triangle straddling a plane is in the blocks of both sides). */
#ifndef RP_KDTREE_H
#define RP_KDTREE_H

#include <stdint.h>

/* Inner: a = the split position's bits, b = first child << 2 | axis (0..2).
 * Leaf: a = first tri4 block, b = block count << 2 | 3. */
typedef struct kd_node {
    uint32_t a, b;
} kd_node;

#define KD_LEAF 3u
#define KD_MAX_DEPTH 64 /* the builder's cap: 8 + 1.3 log2 N levels, at most this */

#endif
