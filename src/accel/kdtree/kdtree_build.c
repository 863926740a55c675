/* kd-tree build by the SAH with the O(N log N) event sweep of Wald and Havran 2006 (sec. 4.3):
 * the start / end / planar events of all triangles' boxes are sorted once, each node sweeps its
 * sorted events for the cheapest plane, then splits the list in two without sorting again: the
 * events of triangles wholly on one side keep their order, the straddling triangles are clipped to
 * each child (sec. 4.1, "split clipping") and only their new events are sorted and merged in. The
 * cost has the empty-space bonus (a side with no triangles costs 0.8 of its SAH). Serial. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "accel/accel.h"
#include "accel/kdtree/kdtree.h"

#define KD_KT 1.0   /* cost of a traversal step */
#define KD_KI 0.5   /* cost of a triangle test: 4 are tested at once, about 2 steps' time */
#define KD_EMPTY_BONUS 0.8

enum { EV_END = 0, EV_PLANAR = 1, EV_START = 2 };
enum { SIDE_BOTH = 0, SIDE_LEFT = 1, SIDE_RIGHT = 2 };

/* An event: key = axis << 34 | position (as an order-preserving integer) << 2 | type, so sorting
 * keys sorts by axis, position and type (ends before planar before starts, the sweep's order). */
typedef struct kd_event {
    uint64_t key;
    uint32_t tri, pad;
} kd_event;

static inline uint32_t flip(float f) {
    f += 0.0f; /* -0 to +0: equal positions, one key */
    uint32_t u;
    memcpy(&u, &f, 4);
    return (u & 0x80000000u) ? ~u : u | 0x80000000u;
}
static inline float unflip(uint32_t u) {
    u = (u & 0x80000000u) ? u & 0x7FFFFFFFu : ~u;
    float f;
    memcpy(&f, &u, 4);
    return f;
}
static inline kd_event ev_make(int axis, float pos, int type, uint32_t tri) {
    return (kd_event){(uint64_t)axis << 34 | (uint64_t)flip(pos) << 2 | (uint64_t)type, tri, 0};
}
static inline int ev_axis(kd_event e) { return (int)(e.key >> 34); }
static inline int ev_type(kd_event e) { return (int)(e.key & 3u); }
static inline float ev_pos(kd_event e) { return unflip((uint32_t)(e.key >> 2)); }

typedef struct kd_builder {
    const sys_allocator *a;
    const accel_tri_input *in;
    float *verts;          /* 9 per triangle */
    uint8_t *side;         /* per triangle, scratch of the node being split */
    float eps;             /* how far clipped boxes are widened: rounding never drops a sliver */
    double root_area;
    kd_node *nodes;
    uint32_t node_count, node_cap;
    tri4 *blocks;
    uint32_t block_count, block_cap;
    uint32_t *ids;         /* a leaf's triangles */
    uint32_t ids_cap;
    uint64_t leaves, refs;
    uint32_t depth;
    double cost;
    bool oom;
} kd_builder;

static void *grow(const sys_allocator *a, void *p, size_t used, size_t old_cap, size_t new_cap) {
    void *q = sys_alloc(a, new_cap);
    if (!q) return NULL;
    if (used) memcpy(q, p, used);
    sys_free(a, p, old_cap);
    return q;
}

static int ev_cmp(const void *a, const void *b) {
    uint64_t x = ((const kd_event *)a)->key, y = ((const kd_event *)b)->key;
    return x < y ? -1 : x > y;
}

/* Sorts events by key: LSD radix sort, 12 bits a pass over the 36 key bits, for long lists (the
 * root's); qsort for the straddlers of a node, where the passes' 4096 buckets would cost more than
 * the events. tmp holds n events. */
static void ev_sort(kd_event *e, kd_event *tmp, size_t n) {
    if (n < 32768) {
        qsort(e, n, sizeof *e, ev_cmp);
        return;
    }
    static const int shift[3] = {0, 12, 24};
    kd_event *src = e, *dst = tmp;
    for (int pass = 0; pass < 3; pass++) {
        size_t count[4097] = {0};
        int s = shift[pass];
        for (size_t i = 0; i < n; i++) count[((src[i].key >> s) & 4095u) + 1]++;
        for (int b = 0; b < 4096; b++) count[b + 1] += count[b];
        for (size_t i = 0; i < n; i++) dst[count[(src[i].key >> s) & 4095u]++] = src[i];
        kd_event *t = src;
        src = dst, dst = t;
    }
    if (src != e) memcpy(e, src, n * sizeof *e);
}

/* Sutherland-Hodgman clip of triangle t to box b (lo xyz, hi xyz); returns its bounding box
 * (empty when nothing is left). */
static box3 clip_tri(const float *v, const float b[6]) {
    float poly[2][16][3];
    int n = 3, cur = 0;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) poly[0][i][k] = v[3 * i + k];
    for (int plane = 0; plane < 6 && n > 0; plane++) {
        int k = plane % 3;
        bool upper = plane >= 3;
        float c = b[plane];
        int m = 0;
        float (*in)[3] = poly[cur], (*out)[3] = poly[cur ^ 1];
        for (int i = 0; i < n; i++) {
            const float *p = in[i], *q = in[(i + 1) % n];
            bool pin = upper ? p[k] <= c : p[k] >= c, qin = upper ? q[k] <= c : q[k] >= c;
            if (pin && m < 16) memcpy(out[m++], p, sizeof(float) * 3);
            if (pin != qin && m < 16) {
                float s = (c - p[k]) / (q[k] - p[k]);
                for (int a = 0; a < 3; a++) out[m][a] = p[a] + (q[a] - p[a]) * s;
                out[m][k] = c;
                m++;
            }
        }
        n = m, cur ^= 1;
    }
    box3 r = box3_empty();
    for (int i = 0; i < n; i++) r = box3_extend(r, v3(poly[cur][i][0], poly[cur][i][1], poly[cur][i][2]));
    return r;
}

static double area(const float v[6]) {
    double dx = (double)v[3] - v[0], dy = (double)v[4] - v[1], dz = (double)v[5] - v[2];
    return dx * dy + dy * dz + dz * dx;
}

/* Box of triangle t inside voxel v: the clipped triangle's box, widened by eps (rounding in the
 * clip never loses a part of the triangle), within the triangle's own box. */
static box3 tri_in_voxel(const kd_builder *bd, uint32_t t, const float v[6]) {
    float w[6];
    for (int k = 0; k < 3; k++) w[k] = v[k] - bd->eps, w[3 + k] = v[3 + k] + bd->eps;
    const float *p = &bd->verts[9 * (size_t)t];
    box3 c = clip_tri(p, w);
    if (box3_is_empty(c)) return c;
    box3 tb = {v3_min(v3(p[0], p[1], p[2]), v3_min(v3(p[3], p[4], p[5]), v3(p[6], p[7], p[8]))),
               v3_max(v3(p[0], p[1], p[2]), v3_max(v3(p[3], p[4], p[5]), v3(p[6], p[7], p[8])))};
    c.lo = v3_sub(c.lo, v3(bd->eps, bd->eps, bd->eps));
    c.hi = v3_add(c.hi, v3(bd->eps, bd->eps, bd->eps));
    c.lo = v3_max(c.lo, tb.lo), c.hi = v3_min(c.hi, tb.hi);
    if (c.lo.x > c.hi.x || c.lo.y > c.hi.y || c.lo.z > c.hi.z) return box3_empty();
    return c;
}

static void push_box_events(kd_event *out, size_t *n, box3 b, uint32_t t) {
    float lo[3] = {b.lo.x, b.lo.y, b.lo.z}, hi[3] = {b.hi.x, b.hi.y, b.hi.z};
    for (int k = 0; k < 3; k++) {
        if (lo[k] == hi[k]) {
            out[(*n)++] = ev_make(k, lo[k], EV_PLANAR, t);
        } else {
            out[(*n)++] = ev_make(k, lo[k], EV_START, t);
            out[(*n)++] = ev_make(k, hi[k], EV_END, t);
        }
    }
}

static uint32_t node_alloc(kd_builder *bd, uint32_t count) {
    if (bd->node_count + count > bd->node_cap) {
        uint32_t cap = bd->node_cap ? bd->node_cap * 2 : 1024;
        while (cap < bd->node_count + count) cap *= 2;
        kd_node *n = grow(bd->a, bd->nodes, bd->node_count * sizeof *n, bd->node_cap * sizeof *n, cap * sizeof *n);
        if (!n) {
            bd->oom = true;
            return 0;
        }
        bd->nodes = n, bd->node_cap = cap;
    }
    uint32_t i = bd->node_count;
    bd->node_count += count;
    return i;
}

/* A leaf of the triangles that have events in e (one start or planar event on axis 0 each). */
static void make_leaf(kd_builder *bd, uint32_t node, const kd_event *e, size_t n, const float v[6], uint32_t depth) {
    uint32_t count = 0;
    for (size_t i = 0; i < n && ev_axis(e[i]) == 0; i++) {
        if (ev_type(e[i]) == EV_END) continue;
        if (count == bd->ids_cap) {
            uint32_t cap = bd->ids_cap ? bd->ids_cap * 2 : 256;
            uint32_t *ids = grow(bd->a, bd->ids, count * sizeof *ids, bd->ids_cap * sizeof *ids, cap * sizeof *ids);
            if (!ids) {
                bd->oom = true;
                return;
            }
            bd->ids = ids, bd->ids_cap = cap;
        }
        bd->ids[count++] = e[i].tri;
    }
    uint32_t blocks = (count + 3) / 4;
    if (bd->block_count + blocks > bd->block_cap) {
        uint32_t cap = bd->block_cap ? bd->block_cap * 2 : 1024;
        while (cap < bd->block_count + blocks) cap *= 2;
        tri4 *b = grow(bd->a, bd->blocks, bd->block_count * sizeof *b, bd->block_cap * sizeof *b, cap * sizeof *b);
        if (!b) {
            bd->oom = true;
            return;
        }
        bd->blocks = b, bd->block_cap = cap;
    }
    for (uint32_t k = 0; k < blocks; k++) {
        uint32_t m = count - 4 * k < 4 ? count - 4 * k : 4;
        accel_fill_block(bd->in, bd->ids + 4 * k, m, &bd->blocks[bd->block_count + k]);
    }
    bd->nodes[node] = (kd_node){bd->block_count, blocks << 2 | KD_LEAF};
    bd->block_count += blocks;
    bd->leaves++;
    bd->refs += count;
    if (depth > bd->depth) bd->depth = depth;
    bd->cost += bd->root_area > 0.0 ? area(v) / bd->root_area * KD_KI * count : 0.0;
}

/* Merges two sorted event lists into out. */
static void merge(const kd_event *a, size_t na, const kd_event *b, size_t nb, kd_event *out) {
    size_t i = 0, j = 0, k = 0;
    while (i < na && j < nb) out[k++] = a[i].key <= b[j].key ? a[i++] : b[j++];
    while (i < na) out[k++] = a[i++];
    while (j < nb) out[k++] = b[j++];
}

/* Builds the subtree of `node` over voxel v from the sorted events e (n of them, owned: freed
 * here) of its `tris` triangles. */
static void build_node(kd_builder *bd, uint32_t node, kd_event *e, size_t n, uint32_t tris, const float v[6],
                       uint32_t depth, uint32_t max_depth) {
    size_t ebytes = (n + 1) * sizeof *e; /* every event list holds one spare event */
    double av = area(v);
    double best = INFINITY;
    int best_axis = -1, best_left = 0;
    float best_pos = 0.0f;
    if (tris > 0 && depth < max_depth && av > 0.0) {
        size_t i = 0;
        for (int k = 0; k < 3; k++) {
            uint32_t nl = 0, nr = tris;
            /* a child's half area is linear in the plane: ab + (a + b) * its length along k */
            double ea = (double)v[3 + (k + 1) % 3] - v[(k + 1) % 3], eb = (double)v[3 + (k + 2) % 3] - v[(k + 2) % 3];
            double cap = ea * eb, per = ea + eb;
            while (i < n && ev_axis(e[i]) == k) {
                uint64_t at = e[i].key >> 2;
                uint32_t pe = 0, pp = 0, ps = 0;
                while (i < n && e[i].key >> 2 == at && ev_type(e[i]) == EV_END) pe++, i++;
                while (i < n && e[i].key >> 2 == at && ev_type(e[i]) == EV_PLANAR) pp++, i++;
                while (i < n && e[i].key >> 2 == at && ev_type(e[i]) == EV_START) ps++, i++;
                float p = unflip((uint32_t)at);
                nr -= pp + pe;
                if (p > v[k] && p < v[3 + k]) {
                    double pl = (cap + per * ((double)p - v[k])) / av, pr = (cap + per * ((double)v[3 + k] - p)) / av;
                    /* planar triangles to the left, then to the right */
                    for (int side = 0; side < 2; side++) {
                        uint32_t l = side == 0 ? nl + pp : nl, r = side == 0 ? nr : nr + pp;
                        double c = KD_KT + KD_KI * (pl * l + pr * r);
                        if (l == 0 || r == 0) c *= KD_EMPTY_BONUS;
                        if (c < best) best = c, best_axis = k, best_pos = p, best_left = side == 0;
                    }
                }
                nl += ps + pp;
            }
        }
    }
    if (best_axis < 0 || best >= KD_KI * tris) {
        make_leaf(bd, node, e, n, v, depth);
        sys_free(bd->a, e, ebytes);
        return;
    }
    /* classify: straddling unless its events say one side */
    for (size_t i = 0; i < n && ev_axis(e[i]) == 0; i++)
        if (ev_type(e[i]) != EV_END) bd->side[e[i].tri] = SIDE_BOTH;
    uint32_t both = tris;
    for (size_t i = 0; i < n; i++) {
        if (ev_axis(e[i]) != best_axis) continue;
        int type = ev_type(e[i]);
        float p = ev_pos(e[i]);
        uint8_t s = SIDE_BOTH;
        if (type == EV_END && p <= best_pos) s = SIDE_LEFT;
        else if (type == EV_START && p >= best_pos) s = SIDE_RIGHT;
        else if (type == EV_PLANAR) s = p < best_pos ? SIDE_LEFT : p > best_pos ? SIDE_RIGHT : best_left ? SIDE_LEFT : SIDE_RIGHT;
        if (s != SIDE_BOTH && bd->side[e[i].tri] == SIDE_BOTH) bd->side[e[i].tri] = s, both--;
    }
    float vl[6], vr[6];
    memcpy(vl, v, sizeof vl), memcpy(vr, v, sizeof vr);
    vl[3 + best_axis] = best_pos, vr[best_axis] = best_pos;
    /* one-sided events keep their order; the straddlers' new events are sorted and merged in */
    size_t nbl = (size_t)both * 6, nlo = 0, nro = 0, nb_l = 0, nb_r = 0;
    kd_event *lo = sys_alloc(bd->a, (n + 1) * sizeof *lo), *ro = sys_alloc(bd->a, (n + 1) * sizeof *ro);
    kd_event *bl = sys_alloc(bd->a, (nbl + 1) * sizeof *bl), *br = sys_alloc(bd->a, (nbl + 1) * sizeof *br);
    kd_event *tmp = sys_alloc(bd->a, (nbl + 1) * sizeof *tmp);
    if (!lo || !ro || !bl || !br || !tmp) {
        bd->oom = true;
        sys_free(bd->a, lo, (n + 1) * sizeof *lo), sys_free(bd->a, ro, (n + 1) * sizeof *ro);
        sys_free(bd->a, bl, (nbl + 1) * sizeof *bl), sys_free(bd->a, br, (nbl + 1) * sizeof *br);
        sys_free(bd->a, tmp, (nbl + 1) * sizeof *tmp);
        sys_free(bd->a, e, ebytes);
        return;
    }
    uint32_t tl = 0, tr = 0;
    for (size_t i = 0; i < n; i++) {
        uint8_t s = bd->side[e[i].tri];
        if (s == SIDE_LEFT) lo[nlo++] = e[i];
        else if (s == SIDE_RIGHT) ro[nro++] = e[i];
    }
    for (size_t i = 0; i < n && ev_axis(e[i]) == 0; i++) {
        if (ev_type(e[i]) == EV_END) continue;
        uint32_t t = e[i].tri;
        uint8_t s = bd->side[t];
        if (s == SIDE_LEFT) tl++;
        else if (s == SIDE_RIGHT) tr++;
        else {
            box3 cl = tri_in_voxel(bd, t, vl), cr = tri_in_voxel(bd, t, vr);
            if (!box3_is_empty(cl)) push_box_events(bl, &nb_l, cl, t), tl++;
            if (!box3_is_empty(cr)) push_box_events(br, &nb_r, cr, t), tr++;
        }
    }
    sys_free(bd->a, e, ebytes);
    ev_sort(bl, tmp, nb_l);
    ev_sort(br, tmp, nb_r);
    sys_free(bd->a, tmp, (nbl + 1) * sizeof *tmp);
    size_t nl_all = nlo + nb_l, nr_all = nro + nb_r;
    kd_event *el = sys_alloc(bd->a, (nl_all + 1) * sizeof *el), *er = sys_alloc(bd->a, (nr_all + 1) * sizeof *er);
    uint32_t child = node_alloc(bd, 2);
    if (!el || !er || bd->oom) {
        bd->oom = true;
        sys_free(bd->a, el, (nl_all + 1) * sizeof *el), sys_free(bd->a, er, (nr_all + 1) * sizeof *er);
    } else {
        merge(lo, nlo, bl, nb_l, el);
        merge(ro, nro, br, nb_r, er);
    }
    sys_free(bd->a, lo, (n + 1) * sizeof *lo), sys_free(bd->a, ro, (n + 1) * sizeof *ro);
    sys_free(bd->a, bl, (nbl + 1) * sizeof *bl), sys_free(bd->a, br, (nbl + 1) * sizeof *br);
    if (bd->oom) return;
    float split = best_pos;
    uint32_t bits;
    memcpy(&bits, &split, 4);
    bd->nodes[node] = (kd_node){bits, child << 2 | (uint32_t)best_axis};
    bd->cost += bd->root_area > 0.0 ? av / bd->root_area * KD_KT : 0.0;
    build_node(bd, child, el, nl_all, tl, vl, depth + 1, max_depth);
    if (bd->oom) {
        sys_free(bd->a, er, (nr_all + 1) * sizeof *er);
        return;
    }
    build_node(bd, child + 1, er, nr_all, tr, vr, depth + 1, max_depth);
}

static bool kd_build(const sys_allocator *a, sys_pool *pool, accel_tri_input *in, accel_built *out) {
    (void)pool;
    memset(out, 0, sizeof *out);
    kd_builder bd = {.a = a, .in = in};
    uint32_t n = in->count;
    box3 b = in->bounds;
    float v[6] = {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z};
    float mag = 0.0f;
    for (int k = 0; k < 6; k++) mag = fmaxf(mag, fabsf(v[k]));
    bd.eps = 2e-6f * mag;
    bd.root_area = area(v);
    size_t vb = (size_t)n * 9 * sizeof(float), ne = (size_t)n * 6;
    bd.verts = sys_alloc(a, vb + 1);
    bd.side = sys_alloc(a, (size_t)n + 1);
    kd_event *e = sys_alloc(a, (ne + 1) * sizeof *e), *tmp = sys_alloc(a, (ne + 1) * sizeof *tmp);
    bool ok = bd.verts && bd.side && e && tmp;
    size_t m = 0;
    if (ok) {
        for (uint32_t i = 0; i < n; i++) {
            uint32_t mask;
            in->fetch(in->user, in->refs[i], &bd.verts[9 * (size_t)i], &mask);
            const bvh_prim *p = &in->boxes[i];
            push_box_events(e, &m, (box3){v3(p->lo[0], p->lo[1], p->lo[2]), v3(p->hi[0], p->hi[1], p->hi[2])}, i);
        }
        ev_sort(e, tmp, m);
    }
    sys_free(a, tmp, (ne + 1) * sizeof *tmp);
    uint32_t max_depth = (uint32_t)(8.0 + 1.3 * log2((double)(n > 1 ? n : 1)));
    if (max_depth > KD_MAX_DEPTH) max_depth = KD_MAX_DEPTH;
    if (ok) ok = node_alloc(&bd, 1) == 0 && !bd.oom;
    if (ok) {
        /* build_node frees its list as m + 1 events (planar events made m < ne) */
        kd_event *root = sys_alloc(a, (m + 1) * sizeof *root);
        if (!root) ok = false;
        else {
            memcpy(root, e, m * sizeof *root);
            build_node(&bd, 0, root, m, n, v, 1, max_depth);
            ok = !bd.oom;
        }
    }
    sys_free(a, e, (ne + 1) * sizeof *e);
    sys_free(a, bd.verts, vb + 1);
    sys_free(a, bd.side, (size_t)n + 1);
    sys_free(a, bd.ids, bd.ids_cap * sizeof(uint32_t));
    tri4 *blocks = ok ? accel_blocks_alloc(a, bd.block_count) : NULL;
    if (blocks && bd.block_count) memcpy(blocks, bd.blocks, (size_t)bd.block_count * sizeof(tri4));
    sys_free(a, bd.blocks, bd.block_cap * sizeof(tri4));
    if (!ok || !blocks) {
        sys_free(a, bd.nodes, bd.node_cap * sizeof(kd_node));
        return false;
    }
    out->nodes = bd.nodes;
    out->node_bytes = bd.node_cap * sizeof(kd_node);
    out->blocks = blocks;
    out->block_count = bd.block_count;
    out->root_depth = bd.depth;
    out->nodes_total = bd.node_count;
    out->inner_nodes = bd.node_count - bd.leaves;
    out->leaves = bd.leaves;
    out->tri_refs = bd.refs;
    out->sah_cost = bd.cost;
    /* the traversal starts from the root box moved outward by the BVH's margin (bvh2_pad_boxes):
     * an axis-parallel ray in one of its faces would leave it at t = 0 */
    float abs_pad = box_pad_abs(v, v + 3);
    for (int k = 0; k < 3 && abs_pad > 0.0f; k++) v[k] = box_pad_lo(v[k], abs_pad), v[3 + k] = box_pad_hi(v[3 + k], abs_pad);
    memcpy(out->bounds, v, sizeof v);
    return true;
}

RP_HIDDEN const accel_ops accel_kdtree = {"kdtree", kd_build, &kdtree_kernels, NULL};
