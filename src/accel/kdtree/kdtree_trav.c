/* Single rays through the kd-tree: ordered front to back (near child first, the far one pushed
 * with its interval), and the walk stops as soon as the nearest pending cell starts beyond the
 * closest hit (early exit). Plane distances are widened by the rounding bound of Ize 2013, so a
 * cell the ray touches is never skipped. Packets go ray by ray (tri_leaf.h's ALT_KERNELS). */
#include "accel/kdtree/kdtree.h"
#include "accel/tri_leaf.h"

typedef struct kd_entry {
    uint32_t node;
    float t0, t1;
} kd_entry;

static bool kd_trav(const rp_accel *acc, const accel_built *s, const alt_ray *r, alt_hit *h, bool any) {
    (void)acc;
    float t0, t1;
    if (!alt_ray_box(r, s->bounds, h->t, &t0, &t1)) return false;
    const kd_node *nodes = s->nodes;
    kd_entry stack[KD_MAX_DEPTH + 2];
    uint32_t sp = 0, node = 0;
    for (;;) {
        kd_node nd = nodes[node];
        while ((nd.b & 3u) != KD_LEAF) {
            uint32_t axis = nd.b & 3u, child = nd.b >> 2;
            float split;
            memcpy(&split, &nd.a, 4);
            float o = r->org[axis], rd = r->rdir[axis];
            float ts = (split - o) * rd;
            /* the near child holds the origin; on the plane, the side the ray leaves */
            bool left = o < split || (o == split && rd > 0.0f);
            uint32_t near = left ? child : child + 1, far = left ? child + 1 : child;
            if (ts < 0.0f) {
                node = near; /* heading away from the plane */
            } else {
                bool vn = t0 <= ts * ALT_UP, vf = ts * ALT_DN <= t1;
                if (vn && vf) {
                    stack[sp++] = (kd_entry){far, ts * ALT_DN > t0 ? ts * ALT_DN : t0, t1};
                    node = near;
                    t1 = ts * ALT_UP < t1 ? ts * ALT_UP : t1;
                } else if (vn) {
                    node = near;
                } else {
                    node = far;
                    t0 = ts * ALT_DN > t0 ? ts * ALT_DN : t0;
                }
            }
            nd = nodes[node];
        }
        if (alt_leaf(s->blocks, r, nd.a, nd.b >> 2, h, any)) return true;
        /* pending cells in front-to-back order: the first that starts beyond the hit ends it */
        for (;;) {
            if (sp == 0) return false;
            kd_entry e = stack[--sp];
            if (e.t0 <= h->t * ALT_CULL_SLACK) {
                node = e.node, t0 = e.t0, t1 = e.t1;
                break;
            }
            /* the stack is sorted (the last pushed is the nearest): nothing after it is nearer */
            if (!any) return false;
        }
    }
}

ALT_KERNELS(kdtree, kd_trav)
