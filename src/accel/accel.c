/* What the kd-tree and BIH builders share: their blocks of triangles. */
#include <math.h>
#include <string.h>

#include "accel/accel.h"

void accel_built_free(const sys_allocator *a, accel_built *b) {
    sys_free(a, b->nodes, b->node_bytes);
    if (b->blocks) sys_free(a, b->blocks, ((size_t)b->block_count + 1) * sizeof(tri4));
    memset(b, 0, sizeof *b);
}

tri4 *accel_blocks_alloc(const sys_allocator *a, uint32_t count) {
    tri4 *t = sys_alloc(a, ((size_t)count + 1) * sizeof(tri4));
    if (!t) return NULL;
    /* the padding block, as the BVH's: NaN vertices (no edge function exactly 0, never a hit) */
    tri4 *pad = &t[count];
    memset(pad, 0, sizeof *pad);
    for (int q = 0; q < 9; q++)
        for (int j = 0; j < 4; j++) pad->v[q][j] = NAN;
    return t;
}

void accel_fill_block(const accel_tri_input *in, const uint32_t *ids, uint32_t n, tri4 *dst) {
    for (uint32_t lane = 0; lane < n; lane++) {
        prim_ref r = in->refs[ids[lane]];
        float v[9];
        uint32_t mask;
        in->fetch(in->user, r, v, &mask);
        for (int q = 0; q < 9; q++) dst->v[q][lane] = v[q];
        dst->geom[lane] = r.geom, dst->prim[lane] = r.prim;
    }
    tri4_pad(dst, n); /* lane 0 again */
}
