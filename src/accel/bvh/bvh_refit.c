/* Refit of a binary BVH whose leaves point at tri4 blocks (the scene's triangle BVH after
 * packing): the topology stays, every box is recomputed bottom-up from the blocks' (already
 * updated) vertices, and the SAH cost of the refitted tree is measured, so the caller can rebuild
 * when the motion has made the tree too poor (Wald, Boulos, Shirley 2007; Lauterbach et al. 2006). */
#include <math.h>
#include <string.h>

#include "accel/bvh/bvh.h"
#include "traverse/traverse.h"

static box3 blocks_box(const tri4 *t, uint32_t first, uint32_t count) {
    box3 b = box3_empty();
    for (uint32_t i = first; i < first + count; i++)
        for (int lane = 0; lane < 4; lane++)
            for (int k = 0; k < 3; k++)
                b = box3_extend(b, v3(t[i].v[3 * k][lane], t[i].v[3 * k + 1][lane], t[i].v[3 * k + 2][lane]));
    return b;
}

double bvh2_refit_blocks(bvh2 *bvh, const tri4 *blocks, double trav_cost) {
    if (!bvh->nodes || bvh->node_count == 0) return 0.0;
    /* post-order walk from the root (node indices need not grow with depth) */
    uint32_t stack[2 * BVHW_MAX_DEPTH + 8];
    uint8_t seen[2 * BVHW_MAX_DEPTH + 8];
    uint32_t sp = 0;
    stack[sp] = 0, seen[sp] = 0, sp++;
    while (sp) {
        uint32_t i = stack[sp - 1];
        bvh_node *n = &bvh->nodes[i];
        box3 b;
        if (n->count) {
            b = blocks_box(blocks, n->index, n->count);
        } else if (!seen[sp - 1]) {
            seen[sp - 1] = 1;
            stack[sp] = n->index, seen[sp] = 0, sp++;
            stack[sp] = n->index + 1, seen[sp] = 0, sp++;
            continue;
        } else {
            const bvh_node *l = &bvh->nodes[n->index], *r = &bvh->nodes[n->index + 1];
            b = box3_union((box3){v3(l->lo[0], l->lo[1], l->lo[2]), v3(l->hi[0], l->hi[1], l->hi[2])},
                           (box3){v3(r->lo[0], r->lo[1], r->lo[2]), v3(r->hi[0], r->hi[1], r->hi[2])});
        }
        n->lo[0] = b.lo.x, n->lo[1] = b.lo.y, n->lo[2] = b.lo.z;
        n->hi[0] = b.hi.x, n->hi[1] = b.hi.y, n->hi[2] = b.hi.z;
        sp--;
    }
    return bvh2_blocks_cost(bvh, trav_cost);
}

double bvh2_blocks_cost(const bvh2 *bvh, double trav_cost) {
    const bvh_node *root = &bvh->nodes[0];
    double ra = box3_half_area((box3){v3(root->lo[0], root->lo[1], root->lo[2]), v3(root->hi[0], root->hi[1], root->hi[2])});
    if (!(ra > 0.0)) return 0.0;
    double cost = 0.0;
    uint32_t stack[BVHW_MAX_DEPTH + 8], sp = 0;
    stack[sp++] = 0;
    while (sp) {
        const bvh_node *n = &bvh->nodes[stack[--sp]];
        double a = box3_half_area((box3){v3(n->lo[0], n->lo[1], n->lo[2]), v3(n->hi[0], n->hi[1], n->hi[2])}) / ra;
        if (n->count) {
            cost += a * n->count;
        } else {
            cost += a * trav_cost;
            stack[sp++] = n->index, stack[sp++] = n->index + 1;
        }
    }
    return cost;
}

void bvh2_pad_boxes(bvh2 *bvh) {
    if (!bvh->nodes || bvh->node_count == 0) return;
    float abs_pad = box_pad_abs(bvh->nodes[0].lo, bvh->nodes[0].hi);
    if (abs_pad == 0.0f) return;
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        bvh_node *n = &bvh->nodes[i];
        for (int k = 0; k < 3; k++) {
            if (!(n->lo[k] <= n->hi[k])) continue; /* an unused node's empty box */
            n->lo[k] = box_pad_lo(n->lo[k], abs_pad);
            n->hi[k] = box_pad_hi(n->hi[k], abs_pad);
        }
    }
}
