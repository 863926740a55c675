/* Rays through the BIH (Waechter, Keller 2006, sec. 2.1), ordered front to back with early exit.
 *
 * Single rays: at a node the ray's interval is cut by the two clip planes, the near child (by the
 * direction's sign) is walked first and the far one pushed with its interval; pending nodes that
 * start beyond the closest hit are skipped. The children's intervals may overlap, so the stack is
 * not sorted: every entry is checked. A clip node (bih.h) cuts the interval by its child's slab,
 * both ends widened, and goes on into its one child.
 *
 * Packets (4/8/16-ray SIMD packets and n x n packets, one code for both): the rays walk the tree
 * together, 4 lanes at a time (vf4), each with its own interval, as Wald et al. 2001 walk the
 * kd-tree. At a node each lane's interval is cut by the two clip planes exactly as its single-ray
 * walk cuts it (the same widened distances, tri_leaf.h), giving the lane's interval in each child;
 * the packet enters the child that is near for most of its rays first (the majority sign of the
 * node's axis, fixed per packet) and pushes the other with the node's box and the range of 4-lane
 * chunks that need it. Rays whose sign differs from the majority are handled correctly, only not
 * in their own front-to-back order: their near child may come second, which costs early exit, not
 * hits (closest hits break ties by (geom, prim), so the order of the leaves never changes the
 * answer). A pending child's intervals are not stored: when it is popped each lane's interval is
 * recomputed from the child's box (the root box cut by its ancestors' clip planes, as alt_ray_box
 * with the widened exit), and lanes whose closest hit lies before the box (or occluded lanes) drop
 * out; a child no lane still needs is skipped. A subtree that only one or two rays still enter is
 * handed to the single-ray walk with their intervals. Leaves test each active ray against their
 * blocks with the single-ray leaf (alt_leaf), so each ray gets its single-ray hit bit for bit. */
#include "accel/bih/bih.h"
#include "accel/tri_leaf.h"

typedef struct bih_entry {
    uint32_t node;
    float t0, t1;
} bih_entry;

/* One ray from `node` with interval [t0, t1]: true at an any-hit (any). */
static bool bih_walk(const accel_built *s, const alt_ray *r, alt_hit *h, bool any, uint32_t node, float t0, float t1) {
    const bih_node *nodes = s->nodes;
    bih_entry stack[BIH_MAX_DEPTH + 2];
    uint32_t sp = 0;
    for (;;) {
        const bih_node *nd = &nodes[node];
        while (nd->meta != BIH_LEAF) {
            uint32_t axis = nd->meta & 3u, child = nd->meta >> BIH_TAG_BITS;
            float o = r->org[axis], rd = r->rdir[axis];
            if (nd->meta & BIH_CLIP) { /* the child's slab, both ends widened */
                float ta = (nd->clip[0] - o) * rd, tb = (nd->clip[1] - o) * rd;
                float tn = alt_dn(ta < tb ? ta : tb), tf = alt_up(ta < tb ? tb : ta);
                t0 = tn > t0 ? tn : t0, t1 = tf < t1 ? tf : t1;
                if (!(t0 <= t1)) goto pop;
                nd = &nodes[child];
                continue;
            }
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

static bool bih_trav(const rp_accel *acc, const accel_built *s, const alt_ray *r, alt_hit *h, bool any) {
    (void)acc;
    float t0, t1;
    if (!alt_ray_box(r, s->bounds, h->t, &t0, &t1)) return false;
    return bih_walk(s, r, h, any, 0, t0, t1);
}

/* ---- packets ------------------------------------------------------------------------------- */

/* Widened distances of tri_leaf.h, 4 lanes at a time: alt_up(t) is the larger of t * ALT_UP and
 * t * ALT_DN, alt_dn(t) the smaller (bit for bit, NaN too), without a compare and a blend. */
static inline vf4 up4(vf4 t) { return vf4_max(t * vf4_splat(ALT_UP), t * vf4_splat(ALT_DN)); }
static inline vf4 dn4(vf4 t) { return vf4_min(t * vf4_splat(ALT_UP), t * vf4_splat(ALT_DN)); }
/* A closest hit so far moved away from the ray's start by the culling slack: boxes entered beyond
 * it are skipped (the single-ray walk's e.t0 <= h->t * ALT_CULL_SLACK, also for t <= 0). */
static inline vf4 cull4(vf4 t) {
    return vf4_max(t * vf4_splat(ALT_CULL_SLACK), t * vf4_splat(1.0f / ALT_CULL_SLACK));
}

/* Set bits of a 4-lane mask (the baseline ISA these kernels are built for has no popcnt: GCC
 * calls libgcc's, 5% of the packets' time on spd_teapot). */
static inline uint32_t pop4(uint32_t m) { return (0x4332322132212110ull >> (4 * m)) & 0xFu; }

/* Subtrees that at most this many of a packet's rays enter go to the single-ray walk. */
#define BIH_SINGLE_SWITCH 2

/* The most rays a packet walk holds: a 16x16 block (larger n x n packets go as their 16x16
 * blocks, which keeps the walk's buffers, about 40 KB, on the stack). */
#define BIH_PK_MAX 256
#define BIH_PK_CHUNKS (BIH_PK_MAX / 4)

/* A packet's rays in 4-lane chunks (SoA), and per ray its single-ray form for the leaves. */
typedef struct bih_pk {
    uint32_t chunks;
    const alt_ray *r;   /* per ray; only live rays are read */
    alt_hit *h;         /* per ray: the closest hit so far */
    vf4 *o[3], *rd[3];  /* origins, reciprocal directions */
    vf4 *tnear;
    vf4 *ht;            /* closest hit distance so far; -inf for dead and occluded rays */
    int pos[3];         /* the majority sign of each axis' direction: the packet's near child */
    int uni[3];         /* every live ray has that sign */
    bool any;
    uint32_t left;      /* live rays not yet occluded (any) */
    uint32_t occ[BIH_PK_MAX / 32]; /* occluded rays (any) */
} bih_pk;

/* A child pending on the packet's stack: its box and the chunks of rays that need it. */
typedef struct bih_pentry {
    uint32_t node, c0, c1;
    float box[6];
} bih_pentry;

/* Each ray's interval in box b (alt_ray_box's arithmetic, 4 lanes at a time) for the chunks
 * [c0, c1), capped by the closest hit so far; narrows [c0, c1) to the chunks with an active ray.
 * Returns the number of active rays. */
static uint32_t pk_box(const bih_pk *p, const float b[6], vf4 *t0, vf4 *t1, uint32_t *c0, uint32_t *c1) {
    uint32_t first = UINT32_MAX, last = 0, active = 0;
    for (uint32_t c = *c0; c < *c1; c++) {
        vf4 lo = p->tnear[c], hi = cull4(p->ht[c]);
        for (int k = 0; k < 3; k++) {
            vf4 ta = (vf4_splat(b[k]) - p->o[k][c]) * p->rd[k][c];
            vf4 tb = (vf4_splat(b[3 + k]) - p->o[k][c]) * p->rd[k][c];
            /* minps / maxps: alt_ray_box's ternaries, NaN included */
            vf4 tn = vf4_min(ta, tb), tf = up4(vf4_max(tb, ta));
            lo = vf4_max(tn, lo);
            hi = vf4_min(tf, hi);
        }
        uint32_t m = vi4_movemask(lo <= hi);
        t0[c] = vf4_select(lo <= hi, lo, vf4_splat(INFINITY));
        t1[c] = vf4_select(lo <= hi, hi, vf4_splat(-INFINITY));
        if (m) {
            first = first == UINT32_MAX ? c : first, last = c;
            active += pop4(m);
        }
    }
    *c0 = first == UINT32_MAX ? 0 : first, *c1 = first == UINT32_MAX ? 0 : last + 1;
    return active;
}

/* The few active rays of chunks [c0, c1) through the single-ray walk from `node`. */
static void pk_single(bih_pk *p, const accel_built *s, uint32_t node, const vf4 *t0, const vf4 *t1, uint32_t c0,
                      uint32_t c1) {
    for (uint32_t c = c0; c < c1; c++) {
        uint32_t m = vi4_movemask(t0[c] <= t1[c]);
        for (; m; m &= m - 1) {
            uint32_t j = simd_ctz(m), i = 4 * c + j;
            bool hit = bih_walk(s, &p->r[i], &p->h[i], p->any, node, t0[c][j], t1[c][j]);
            if (p->any && hit) p->ht[c][j] = -INFINITY, p->left--, p->occ[i / 32] |= 1u << (i % 32);
            else p->ht[c][j] = p->h[i].t;
        }
    }
}

/* The packet walk: every live ray ends with its single-ray closest hit (or, with any, ht = -inf
 * where occluded). */
static void pk_walk(bih_pk *p, const accel_built *s) {
    RP_ALIGN(16) vf4 buf[3][2][BIH_PK_CHUNKS];
    vf4 *t0 = buf[0][0], *t1 = buf[0][1]; /* the current node's intervals */
    int cur = 0;
    bih_pentry stack[BIH_MAX_DEPTH + 2];
    uint32_t sp = 0, c0 = 0, c1 = p->chunks;
    uint32_t active = pk_box(p, s->bounds, t0, t1, &c0, &c1);
    if (!active) return;
    const bih_node *nodes = s->nodes;
    uint32_t node = 0;
    float box[6];
    memcpy(box, s->bounds, sizeof box);
    for (;;) {
        if (active <= BIH_SINGLE_SWITCH) {
            pk_single(p, s, node, t0, t1, c0, c1);
            goto pop;
        }
        const bih_node *nd = &nodes[node];
        if (nd->meta != BIH_LEAF && (nd->meta & BIH_CLIP)) { /* the child's slab, as the single-ray walk */
            uint32_t axis = nd->meta & 3u;
            vf4 ca = vf4_splat(nd->clip[0]), cb = vf4_splat(nd->clip[1]);
            uint32_t f = UINT32_MAX, l = 0, na = 0;
            for (uint32_t c = c0; c < c1; c++) {
                vf4 o = p->o[axis][c], rd = p->rd[axis][c];
                vf4 ta = (ca - o) * rd, tb = (cb - o) * rd;
                vf4 x0 = vf4_max(t0[c], dn4(vf4_min(ta, tb))), x1 = vf4_min(t1[c], up4(vf4_max(tb, ta)));
                vi4 in = x0 <= x1;
                t0[c] = vf4_select(in, x0, vf4_splat(INFINITY)), t1[c] = vf4_select(in, x1, vf4_splat(-INFINITY));
                uint32_t bits = vi4_movemask(in);
                if (bits) f = f == UINT32_MAX ? c : f, l = c, na += pop4(bits);
            }
            if (!na) goto pop;
            c0 = f, c1 = l + 1, active = na, node = nd->meta >> BIH_TAG_BITS;
            if (nd->clip[0] > box[axis]) box[axis] = nd->clip[0];
            if (nd->clip[1] < box[3 + axis]) box[3 + axis] = nd->clip[1];
            continue;
        }
        if (nd->meta != BIH_LEAF) {
            uint32_t axis = nd->meta & 3u, child = nd->meta >> BIH_TAG_BITS;
            bool ppos = p->pos[axis] != 0;
            /* the packet's first child: near for the majority, the left one for positive rays */
            uint32_t first = ppos ? child : child + 1, second = ppos ? child + 1 : child;
            int a = (cur + 1) % 3, b = (cur + 2) % 3; /* the first child's intervals into a */
            vf4 *a0 = buf[a][0], *a1 = buf[a][1], *b0 = buf[b][0], *b1 = buf[b][1];
            vf4 cl = vf4_splat(nd->clip[0]), cr = vf4_splat(nd->clip[1]);
            uint32_t fa = UINT32_MAX, la = 0, fb = UINT32_MAX, lb = 0, na = 0, nb = 0;
            /* Per lane: the near child's interval [x0, min(x1, n1)], the far one's [max(x0, f0), x1]
             * (the single-ray walk's, value for value; empty where it skips the child, NaN too) */
#define BIH_COUNT(c)                                                                              \
    do {                                                                                          \
        uint32_t bits_a = vi4_movemask(a0[c] <= a1[c]), bits_b = vi4_movemask(b0[c] <= b1[c]);    \
        if (bits_a) fa = fa == UINT32_MAX ? c : fa, la = c, na += pop4(bits_a);                   \
        if (bits_b) fb = fb == UINT32_MAX ? c : fb, lb = c, nb += pop4(bits_b);                   \
    } while (0)
            if (p->uni[axis]) { /* every live ray's near child is the packet's first */
                vf4 cn = ppos ? cl : cr, cf = ppos ? cr : cl;
                for (uint32_t c = c0; c < c1; c++) {
                    vf4 o = p->o[axis][c], rd = p->rd[axis][c], x0 = t0[c], x1 = t1[c];
                    vf4 n1 = up4((cn - o) * rd), f0 = dn4((cf - o) * rd);
                    a0[c] = x0, a1[c] = vf4_min(x1, n1);
                    b0[c] = vf4_max(x0, f0), b1[c] = x1;
                    BIH_COUNT(c);
                }
            } else {
                for (uint32_t c = c0; c < c1; c++) {
                    vf4 o = p->o[axis][c], rd = p->rd[axis][c], x0 = t0[c], x1 = t1[c];
                    vf4 tl = (cl - o) * rd, tr = (cr - o) * rd;
                    vi4 pos = rd > vf4_splat(0.0f);
                    vf4 n1 = up4(vf4_select(pos, tl, tr)), f0 = dn4(vf4_select(pos, tr, tl));
                    vf4 nhi = vf4_min(x1, n1), flo = vf4_max(x0, f0);
                    vi4 same = ppos ? pos : ~pos; /* lanes whose near child is the packet's first */
                    a0[c] = vf4_select(same, x0, flo), a1[c] = vf4_select(same, nhi, x1);
                    b0[c] = vf4_select(same, flo, x0), b1[c] = vf4_select(same, x1, nhi);
                    BIH_COUNT(c);
                }
            }
#undef BIH_COUNT
            /* the children's boxes: the left one ends at clip 0, the right one starts at clip 1 */
            float bfirst[6], bsecond[6];
            memcpy(bfirst, box, sizeof box), memcpy(bsecond, box, sizeof box);
            float *bl = ppos ? bfirst : bsecond, *br = ppos ? bsecond : bfirst;
            if (nd->clip[0] < bl[3 + axis]) bl[3 + axis] = nd->clip[0];
            if (nd->clip[1] > br[axis]) br[axis] = nd->clip[1];
            if (na && nb) {
                bih_pentry *e = &stack[sp++];
                e->node = second, e->c0 = fb, e->c1 = lb + 1;
                memcpy(e->box, bsecond, sizeof bsecond);
            }
            if (na) {
                cur = a, t0 = a0, t1 = a1, c0 = fa, c1 = la + 1, active = na, node = first;
                memcpy(box, bfirst, sizeof box);
                continue;
            }
            if (nb) {
                cur = b, t0 = b0, t1 = b1, c0 = fb, c1 = lb + 1, active = nb, node = second;
                memcpy(box, bsecond, sizeof box);
                continue;
            }
            goto pop;
        }
        {
            uint32_t first, count;
            memcpy(&first, &nd->clip[0], 4), memcpy(&count, &nd->clip[1], 4);
            for (uint32_t c = c0; c < c1; c++) {
                for (uint32_t m = vi4_movemask(t0[c] <= t1[c]); m; m &= m - 1) {
                    uint32_t j = simd_ctz(m), i = 4 * c + j;
                    if (alt_leaf(s->blocks, &p->r[i], first, count, &p->h[i], p->any))
                        p->ht[c][j] = -INFINITY, p->left--, p->occ[i / 32] |= 1u << (i % 32);
                    else p->ht[c][j] = p->h[i].t;
                }
            }
        }
    pop:
        for (;;) {
            if (sp == 0 || (p->any && p->left == 0)) return;
            bih_pentry *e = &stack[--sp];
            c0 = e->c0, c1 = e->c1;
            active = pk_box(p, e->box, t0, t1, &c0, &c1);
            if (active) {
                node = e->node;
                memcpy(box, e->box, sizeof box);
                break;
            }
        }
    }
}

/* Fills the packet's chunks from its rays (dead lanes: never active) and the majority signs. */
static void pk_setup(bih_pk *p, vf4 (*soa)[BIH_PK_CHUNKS], const alt_ray *r, alt_hit *h, const uint32_t *live,
                     uint32_t count, bool any) {
    p->chunks = (count + 3) / 4;
    p->r = r, p->h = h, p->any = any, p->left = 0;
    memset(p->occ, 0, sizeof p->occ);
    for (int k = 0; k < 3; k++) p->o[k] = soa[k], p->rd[k] = soa[3 + k];
    p->tnear = soa[6], p->ht = soa[7];
    int votes[3] = {0, 0, 0}, npos[3] = {0, 0, 0};
    for (uint32_t i = 0; i < 4 * p->chunks; i++) {
        uint32_t c = i / 4, j = i % 4;
        if (i < count && (live[i / 32] >> (i % 32) & 1u)) {
            for (int k = 0; k < 3; k++) {
                p->o[k][c][j] = r[i].org[k], p->rd[k][c][j] = r[i].rdir[k];
                votes[k] += r[i].rdir[k] > 0.0f ? 1 : -1;
                npos[k] += r[i].rdir[k] > 0.0f;
            }
            p->tnear[c][j] = r[i].tnear, p->ht[c][j] = h[i].t;
            p->left++;
        } else {
            for (int k = 0; k < 3; k++) p->o[k][c][j] = 0.0f, p->rd[k][c][j] = 1.0f;
            p->tnear[c][j] = INFINITY, p->ht[c][j] = -INFINITY;
        }
    }
    for (int k = 0; k < 3; k++)
        p->pos[k] = votes[k] >= 0, p->uni[k] = npos[k] == 0 || npos[k] == (int)p->left;
}

/* The SIMD packets (ALT_KERNELS' PTRAV): all of them walk the tree together; occluded lanes are
 * returned in *occluded. A packet of one or two live rays goes ray by ray. */
static bool bih_packet(const accel_built *s, const alt_ray *r, alt_hit *h, uint32_t live, int k, bool any,
                       uint32_t *occluded) {
    if (simd_popcount(live) <= 2) return false;
    RP_ALIGN(16) vf4 soa[8][BIH_PK_CHUNKS];
    bih_pk p;
    pk_setup(&p, soa, r, h, &live, (uint32_t)k, any);
    pk_walk(&p, s);
    *occluded = p.occ[0] & live;
    return true;
}

/* Rays [base, base + m) of an n x n packet as one packet walk, then spheres and user primitives
 * ray by ray through the device's BVH kernels, as the SIMD packets do. */
static void trace_block(const rp_accel *acc, rp_rayhit_n *pk, uint32_t base, uint32_t m, bool any) {
    const accel_built *s = acc->alt;
    alt_ray r[BIH_PK_MAX];
    alt_hit h[BIH_PK_MAX];
    uint32_t live[BIH_PK_MAX / 32] = {0}, nlive = 0;
    for (uint32_t i = 0; i < m; i++) {
        uint32_t q = base + i;
        if ((pk->valid && !pk->valid[q]) || !(pk->tnear[q] <= pk->tfar[q])) continue;
        rp_ray one = {.org_x = pk->org_x[q], .org_y = pk->org_y[q], .org_z = pk->org_z[q], .tnear = pk->tnear[q],
                      .dir_x = pk->dir_x[q], .dir_y = pk->dir_y[q], .dir_z = pk->dir_z[q], .tfar = pk->tfar[q],
                      .mask = pk->mask ? pk->mask[q] : 0xFFFFFFFFu};
        alt_ray_setup(&r[i], &one, acc);
        h[i] = (alt_hit){.t = one.tfar, .geom = RP_INVALID_ID, .prim = RP_INVALID_ID};
        live[i / 32] |= 1u << (i % 32), nlive++;
    }
    if (!nlive) return;
    uint32_t occ[BIH_PK_MAX / 32] = {0};
    if (s && s->block_count) {
        RP_ALIGN(16) vf4 soa[8][BIH_PK_CHUNKS];
        bih_pk p;
        pk_setup(&p, soa, r, h, live, m, any);
        pk_walk(&p, s);
        memcpy(occ, p.occ, sizeof occ);
    }
    for (uint32_t i = 0; i < m; i++) {
        if (!(live[i / 32] >> (i % 32) & 1u)) continue;
        uint32_t q = base + i;
        rp_rayhit one;
        one.ray = (rp_ray){.org_x = pk->org_x[q], .org_y = pk->org_y[q], .org_z = pk->org_z[q], .tnear = pk->tnear[q],
                           .dir_x = pk->dir_x[q], .dir_y = pk->dir_y[q], .dir_z = pk->dir_z[q], .tfar = pk->tfar[q],
                           .mask = pk->mask ? pk->mask[q] : 0xFFFFFFFFu};
        if (any) {
            if (occ[i / 32] >> (i % 32) & 1u) {
                pk->tfar[q] = -INFINITY;
            } else if (acc->pnodes) {
                acc->base->occluded1(acc, &one.ray);
                pk->tfar[q] = one.ray.tfar;
            }
            continue;
        }
        one.hit.geom_id = RP_INVALID_ID;
        if (s && s->block_count && h[i].geom != RP_INVALID_ID) alt_write_hit(s, &h[i], &one);
        if (acc->pnodes) acc->base->intersect1(acc, &one);
        if (one.hit.geom_id == RP_INVALID_ID) continue;
        pk->tfar[q] = one.ray.tfar;
        pk->Ng_x[q] = one.hit.Ng_x, pk->Ng_y[q] = one.hit.Ng_y, pk->Ng_z[q] = one.hit.Ng_z;
        pk->u[q] = one.hit.u, pk->v[q] = one.hit.v;
        pk->prim_id[q] = one.hit.prim_id, pk->geom_id[q] = one.hit.geom_id;
        pk->inst_id[q] = one.hit.inst_id;
    }
}

/* n x n packets (rp_intersect_n / rp_occluded_n, any traversal but single and SIMD): each 16x16
 * block of the packet (rp_packet_n_index keeps it a square of the image) walks the tree as one
 * when its rays share their direction signs; a block of mixed signs (diffuse bounces) goes as 16
 * packets of 16 rays, as a whole it had been 2.5-4x slower than its rays one by one (bunny,
 * teapot; `bench --accel-grid`). */
static void bih_trace_n(const rp_accel *acc, rp_rayhit_n *pk, bool any) {
    uint32_t count = pk->n * pk->n;
    for (uint32_t base = 0; base < count; base += BIH_PK_MAX) {
        uint32_t m = count - base < BIH_PK_MAX ? count - base : BIH_PK_MAX;
        uint32_t pos[3] = {0, 0, 0}, live = 0;
        for (uint32_t q = base; q < base + m; q++) {
            if (pk->valid && !pk->valid[q]) continue;
            pos[0] += pk->dir_x[q] > 0.0f, pos[1] += pk->dir_y[q] > 0.0f, pos[2] += pk->dir_z[q] > 0.0f;
            live++;
        }
        bool mixed = false;
        for (int k = 0; k < 3; k++) mixed |= pos[k] != 0 && pos[k] != live;
        uint32_t step = mixed ? 16 : m;
        for (uint32_t b = base; b < base + m; b += step) trace_block(acc, pk, b, step < base + m - b ? step : base + m - b, any);
    }
}

ALT_KERNELS(bih, bih_trav, bih_packet, bih_trace_n)
