/* Bounding interval hierarchy (Waechter, Keller 2006, "Instant ray tracing: the bounding interval
 * hierarchy"): a binary tree of two clip planes per node on one axis, the left child's upper
 * bound and the right child's lower bound; children of a node side by side. */
#ifndef RP_BIH_H
#define RP_BIH_H

#include <stdint.h>

/* Inner: clip[0] = max of the left child along axis, clip[1] = min of the right one, meta = first
 * child << BIH_TAG_BITS | axis. Clip node (empty space cut off, one child): clip[0] and clip[1] the
 * lower and upper planes of its child along axis, meta = child << BIH_TAG_BITS | BIH_CLIP | axis.
 * Leaf: clip holds the first tri4 block and the block count (as bits), meta = BIH_LEAF. */
typedef struct bih_node {
    float clip[2];
    uint32_t meta;
} bih_node;

#define BIH_LEAF 3u
#define BIH_CLIP 4u
#define BIH_TAG_BITS 3
#define BIH_MAX_DEPTH 64
#define BIH_LEAF_SIZE 4 /* triangles: a leaf is one tri4 block */

#endif
