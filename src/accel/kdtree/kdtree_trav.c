/* Single rays through the kd-tree: ordered front to back (near child first, the far one pushed
 * with its interval), and pending cells that start beyond the closest hit are skipped (early
 * exit). A ray lying in a split plane walks both sides with its whole interval. Plane distances
 * are widened by the rounding bound of Ize 2013, so a cell the ray touches is never skipped.
 * Packets of rays whose directions share their signs walk the tree together (kd_packet, Wald et
 * al. 2001); others go ray by ray. */
#include "accel/kdtree/kdtree.h"
#include "accel/tri_leaf.h"

/* The ray lies in planes of this axis (a direction component the traversal takes as +-1e-18,
 * wt_rcp): on a split plane it meets the triangles of both sides that touch it. */
#define KD_IN_PLANE(r, axis) (fabsf((r)->dir[axis]) < 1e-18f)

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
            if (o == split && KD_IN_PLANE(r, axis)) {
                stack[sp++] = (kd_entry){far, t0, t1}; /* in the plane: both sides, the whole interval */
                node = near;
            } else if (ts < 0.0f) {
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
        /* the next pending cell that does not start beyond the hit (the stack is not sorted: a
         * ray in a plane pushed the far side with the interval the near side has) */
        for (;;) {
            if (sp == 0) return false;
            kd_entry e = stack[--sp];
            if (e.t0 <= h->t * ALT_CULL_SLACK) {
                node = e.node, t0 = e.t0, t1 = e.t1;
                break;
            }
        }
    }
}

/* A pending subtree of a packet: its rays and their intervals. */
typedef struct kd_pentry {
    uint32_t node, mask;
    float t0[16], t1[16];
} kd_pentry;

/* Ordered packet traversal (Wald, Slusallek, Benthin, Wagner 2001, sec. 4.2): with every direction
 * sign shared, the near child of a node is the same for all rays, so the packet descends as one:
 * the rays that need the near child go there, those that also (or only) need the far one wait on
 * the stack with their intervals. Each ray's intervals are its single-ray traversal's, so every
 * ray gets its single-ray hit. Leaves test the rays one by one against their blocks. */
static bool kd_packet(const accel_built *s, const alt_ray *r, alt_hit *h, uint32_t live, int k, bool any,
                      uint32_t *occluded) {
    uint32_t first = simd_ctz(live);
    for (int a = 0; a < 3; a++) {
        bool neg = r[first].rdir[a] < 0.0f;
        for (uint32_t m = live; m; m &= m - 1)
            if ((r[simd_ctz(m)].rdir[a] < 0.0f) != neg) return false;
    }
    (void)k;
    float t0[16], t1[16];
    uint32_t m = 0;
    for (uint32_t q = live; q; q &= q - 1) {
        uint32_t i = simd_ctz(q);
        if (alt_ray_box(&r[i], s->bounds, h[i].t, &t0[i], &t1[i])) m |= 1u << i;
    }
    const kd_node *nodes = s->nodes;
    kd_pentry stack[KD_MAX_DEPTH + 2];
    uint32_t sp = 0, node = 0, done = 0;
    while (m) {
        kd_node nd = nodes[node];
        while ((nd.b & 3u) != KD_LEAF) {
            uint32_t axis = nd.b & 3u, child = nd.b >> 2;
            float split;
            memcpy(&split, &nd.a, 4);
            /* by the shared sign: the near child is entered first (t <= ts), the far one after */
            bool pos = r[first].rdir[axis] > 0.0f;
            uint32_t near = pos ? child : child + 1, far = pos ? child + 1 : child;
            uint32_t mn = 0, mf = 0;
            float ts[16];
            float tf[16]; /* where the far child starts: ts, or -inf for a ray in the plane */
            for (uint32_t q = m; q; q &= q - 1) {
                uint32_t i = simd_ctz(q);
                ts[i] = (split - r[i].org[axis]) * r[i].rdir[axis];
                tf[i] = ts[i];
                if (r[i].org[axis] == split && KD_IN_PLANE(&r[i], axis)) ts[i] = INFINITY, tf[i] = -INFINITY;
                if (t0[i] <= alt_up(ts[i])) mn |= 1u << i;
                if (alt_dn(tf[i]) <= t1[i]) mf |= 1u << i;
            }
            if (mf && mn) {
                kd_pentry *e = &stack[sp++];
                e->node = far, e->mask = mf;
                for (uint32_t q = mf; q; q &= q - 1) {
                    uint32_t i = simd_ctz(q);
                    float d = alt_dn(tf[i]);
                    e->t0[i] = d > t0[i] ? d : t0[i], e->t1[i] = t1[i];
                }
            }
            if (mn) {
                for (uint32_t q = mn; q; q &= q - 1) {
                    uint32_t i = simd_ctz(q);
                    float u = alt_up(ts[i]);
                    t1[i] = u < t1[i] ? u : t1[i];
                }
                node = near, m = mn;
            } else if (mf) {
                for (uint32_t q = mf; q; q &= q - 1) {
                    uint32_t i = simd_ctz(q);
                    float d = alt_dn(tf[i]);
                    t0[i] = d > t0[i] ? d : t0[i];
                }
                node = far, m = mf;
            } else {
                m = 0;
                break;
            }
            nd = nodes[node];
        }
        if (m && (nd.b & 3u) == KD_LEAF) {
            for (uint32_t q = m; q; q &= q - 1) {
                uint32_t i = simd_ctz(q);
                if (alt_leaf(s->blocks, &r[i], nd.a, nd.b >> 2, &h[i], any)) done |= 1u << i;
            }
        }
        /* next pending subtree with a ray still in need of it */
        m = 0;
        while (sp && !m) {
            kd_pentry *e = &stack[--sp];
            for (uint32_t q = e->mask & ~done; q; q &= q - 1) {
                uint32_t i = simd_ctz(q);
                if (e->t0[i] <= h[i].t * ALT_CULL_SLACK) m |= 1u << i, t0[i] = e->t0[i], t1[i] = e->t1[i];
            }
            node = e->node;
        }
    }
    *occluded = done;
    return true;
}

ALT_KERNELS(kdtree, kd_trav, kd_packet, NULL)
