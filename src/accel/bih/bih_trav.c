/* Single rays through the BIH (Waechter, Keller 2006, sec. 2.1): at a node the ray's interval is
 * cut by the two clip planes, the near child (by the direction's sign) is walked first and the far
 * one pushed with its interval; pending nodes that start beyond the closest hit are skipped. The
 * children's intervals may overlap, so the stack is not sorted: every entry is checked. Packets go
 * ray by ray (alt_no_packets). */
#include "accel/bih/bih.h"
#include "accel/tri_leaf.h"

typedef struct bih_entry {
    uint32_t node;
    float t0, t1;
} bih_entry;

static bool bih_trav(const rp_accel *acc, const accel_built *s, const alt_ray *r, alt_hit *h, bool any) {
    (void)acc;
    float t0, t1;
    if (!alt_ray_box(r, s->bounds, h->t, &t0, &t1)) return false;
    const bih_node *nodes = s->nodes;
    bih_entry stack[BIH_MAX_DEPTH + 2];
    uint32_t sp = 0, node = 0;
    for (;;) {
        const bih_node *nd = &nodes[node];
        while (nd->meta != BIH_LEAF) {
            uint32_t axis = nd->meta & 3u, child = nd->meta >> 2;
            float o = r->org[axis], rd = r->rdir[axis];
            float tl = (nd->clip[0] - o) * rd, tr = (nd->clip[1] - o) * rd;
            /* positive direction: in the left child while t <= tl, in the right from tr on */
            bool pos = rd > 0.0f;
            float tn = pos ? tl : tr, tf = pos ? tr : tl;
            uint32_t near = pos ? child : child + 1, far = pos ? child + 1 : child;
            float n1 = alt_up(tn), f0 = alt_dn(tf);
            bool vn = t0 <= n1, vf = f0 <= t1;
            if (vn && vf) {
                stack[sp++] = (bih_entry){far, f0 > t0 ? f0 : t0, t1};
                node = near;
                t1 = n1 < t1 ? n1 : t1;
            } else if (vn) {
                node = near;
                t1 = n1 < t1 ? n1 : t1;
            } else if (vf) {
                node = far;
                t0 = f0 > t0 ? f0 : t0;
            } else {
                goto pop;
            }
            nd = &nodes[node];
        }
        {
            uint32_t first, count;
            memcpy(&first, &nd->clip[0], 4), memcpy(&count, &nd->clip[1], 4);
            if (alt_leaf(s->blocks, r, first, count, h, any)) return true;
        }
    pop:
        for (;;) {
            if (sp == 0) return false;
            bih_entry e = stack[--sp];
            if (e.t0 <= h->t * ALT_CULL_SLACK) {
                node = e.node, t0 = e.t0, t1 = e.t1;
                break;
            }
        }
    }
}

ALT_KERNELS(bih, bih_trav, alt_no_packets)
