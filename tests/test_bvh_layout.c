// rp-test: labels=core timeout=120
/* The compact layouts of the triangle BVH (accel/bvh/bvh.h): the quantized binary BVH's decoded
 * boxes hold the exact ones, at most three steps of their parent's grid wider (boxes far from the
 * origin, tiny, flat and point-like ones, a small object on a large ground, and one scene of a
 * single box), with the same topology (pairs of one-block leaves stored as one leaf and
 * split again by bvh2q_to_bvh2); the compact wide BVH holds, node for node, the
 * children and boxes of the full-width one, each node as narrow as its children allow. */
#include <math.h>
#include <stdint.h>

#include "accel/bvh/bvh.h"
#include "rp_test.h"

static uint64_t rng_state = 7;
static float rng_f(void) {
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (float)((uint32_t)(rng_state >> 33) >> 7) * (1.0f / 16777216.0f);
}

/* n boxes of one of several shapes around `centre`, spread over `extent`. */
static void make_boxes(bvh_prim *p, uint32_t n, float centre, float extent, int shape) {
    for (uint32_t i = 0; i < n; i++) {
        box3 b;
        float c[3], s[3];
        for (int a = 0; a < 3; a++) {
            c[a] = centre + (rng_f() - 0.5f) * extent;
            s[a] = shape == 0 ? rng_f() * extent * 1e-3f : shape == 1 ? rng_f() * extent * 1e-6f : 0.0f;
        }
        if (shape == 3) s[0] = extent * 0.01f, s[1] = 0.0f, s[2] = extent * 0.01f; /* flat */
        if (shape == 4) { /* a small object on a large ground: box 0 the ground, the others 10^-4 of it */
            for (int a = 0; a < 3; a++) {
                c[a] = i == 0 ? centre : centre + (rng_f() - 0.5f) * extent * 1e-4f;
                s[a] = i == 0 ? (a == 1 ? 0.0f : extent) : rng_f() * extent * 1e-7f;
            }
        }
        b.lo = v3(c[0] - s[0], c[1] - s[1], c[2] - s[2]);
        b.hi = v3(c[0] + s[0], c[1] + s[1], c[2] + s[2]);
        p[i] = bvh_prim_of(b);
    }
}

/* Leaves as bvhw_from_bvh2 wants them (their primitive range, at most 15 items). */
static bool leaf_fn(void *user, const bvh_node *leaf, uint32_t *first, uint32_t *items) {
    (void)user;
    *first = leaf->index;
    *items = (leaf->count + 3) / 4;
    return true;
}

/* The float tree's leaves renumbered to blocks of 4 in leaf order, as scene.c leaves them (so
 * sibling leaves of one block each lie in adjacent blocks and become pairs). */
static uint32_t number_blocks(bvh_node *nodes, uint32_t i, uint32_t next) {
    bvh_node *n = &nodes[i];
    if (n->count) {
        n->count = (n->count + 3) / 4, n->index = next;
        return next + n->count;
    }
    next = number_blocks(nodes, n->index, next);
    return number_blocks(nodes, n->index + 1, next);
}

/* Walks float node i of t and node j of the quantized tree together: the decoded boxes hold the
 * exact ones, leaves keep their blocks and a pair is an inner node of two one-block leaves in
 * adjacent blocks. Counts the bad planes, the moved leaves and the pairs. */
static void walk_quant(const bvh2 *t, uint32_t i, const bvh2q *q, uint32_t j, const float org[3], const float scale[3],
                       const float step[3], uint32_t *bad, uint32_t *loose, uint32_t *moved, uint32_t *pairs) {
    const bvh_node *n = &t->nodes[i];
    bvh_node d = bvh2q_decode(&q->nodes[j], org, scale);
    for (int k = 0; k < 3; k++) {
        *bad += !(d.lo[k] <= n->lo[k]) || !(d.hi[k] >= n->hi[k]);
        /* at most three steps of a grid over its parent's decoded box (1/64000 of it) wider on each
         * side: one for the rounding outward, one of margin, and a few of the float's ulps where the
         * grid is finer than they are (a grid over the whole scene made the small boxes of a scene
         * with a large ground as wide as 1/65535 of the ground) */
        float tol_lo = 3.0f * step[k] + fabsf(n->lo[k]) * 0x1p-21f, tol_hi = 3.0f * step[k] + fabsf(n->hi[k]) * 0x1p-21f;
        *loose += !(n->lo[k] - d.lo[k] <= tol_lo && d.hi[k] - n->hi[k] <= tol_hi);
    }
    if (q->nodes[j].ic & BVH2Q_PAIR) {
        const bvh_node *l = &t->nodes[n->index], *r = l + 1;
        (*pairs)++;
        *moved += n->count != 0 || l->count != 1 || r->count != 1 || l->index != d.index || r->index != d.index + 1 ||
                  d.count != 2;
        return;
    }
    if (n->count || d.count) {
        *moved += d.index != n->index || d.count != n->count;
        return;
    }
    float corg[3], cscale[3], cstep[3];
    bvh2q_child_grid(&d, corg, cscale);
    for (int k = 0; k < 3; k++) cstep[k] = (d.hi[k] - d.lo[k]) * (1.0f / 64000.0f);
    walk_quant(t, n->index, q, d.index, corg, cscale, cstep, bad, loose, moved, pairs);
    walk_quant(t, n->index + 1, q, d.index + 1, corg, cscale, cstep, bad, loose, moved, pairs);
}

/* The same topology and leaves, node for node. */
static uint32_t tree_diff(const bvh2 *a, uint32_t i, const bvh2 *b, uint32_t j) {
    const bvh_node *x = &a->nodes[i], *y = &b->nodes[j];
    if (x->count || y->count) return x->count != y->count || x->index != y->index;
    return tree_diff(a, x->index, b, y->index) + tree_diff(a, x->index + 1, b, y->index + 1);
}

static uint32_t total_pairs; /* over every tree: the pairs are made and checked somewhere */

static void check_quant(const sys_allocator *a, const bvh2 *b) {
    bvh2 t = *b;
    bvh_node *nodes = malloc((size_t)b->node_count * sizeof *nodes);
    memcpy(nodes, b->nodes, (size_t)b->node_count * sizeof *nodes);
    t.nodes = nodes;
    if (nodes[0].count || nodes[0].index) number_blocks(nodes, 0, 0);
    bvh2q q;
    CHECK(bvh2q_from_bvh2(a, &t, &q));
    if (!q.nodes) {
        free(nodes);
        return;
    }
    uint32_t bad = 0, loose = 0, moved = 0, pairs = 0;
    if (nodes[0].count || nodes[0].index) walk_quant(&t, 0, &q, 0, q.org, q.scale, q.scale, &bad, &loose, &moved, &pairs);
    CHECKF(bad == 0, "%u planes of decoded boxes cut into the exact boxes", bad);
    CHECKF(loose == 0, "%u planes of decoded boxes more than three grid steps outside the exact boxes", loose);
    CHECK(moved == 0);
    total_pairs += pairs;
    CHECKF(q.node_count == 2 * t.leaf_count - 1 - 2 * pairs, "%u nodes for %u leaves and %u pairs", q.node_count,
           t.leaf_count, pairs);
    bvh2 back;
    CHECK(bvh2q_to_bvh2(a, &q, true, &back));
    CHECK(back.node_count == 2 * t.leaf_count - 1 && back.depth == t.depth && back.leaf_count == t.leaf_count);
    CHECK(tree_diff(&t, 0, &back, 0) == 0);
    bvh2_free(a, &back);
    CHECK(bvh2q_to_bvh2(a, &q, false, &back));
    CHECK(back.node_count == q.node_count && back.leaf_count == t.leaf_count - pairs);
    bvh2_free(a, &back);
    bvh2q_free(a, &q);
    free(nodes);
}

static uint32_t kids_of(const float *b, int w, const uint32_t **child) {
    *child = (const uint32_t *)(b + 6 * w);
    uint32_t k = 0;
    for (int i = 0; i < w; i++)
        if ((*child)[i] != BVHW_EMPTY) k = (uint32_t)i + 1;
    return k;
}

/* Walks the full-width and the compact tree side by side. */
static void check_compact(const sys_allocator *a, const bvh2 *b, int width) {
    bvhw full, comp;
    CHECK(bvhw_from_bvh2(a, NULL, b, width, leaf_fn, NULL, &full));
    CHECK(bvhw_from_bvh2(a, NULL, b, width, leaf_fn, NULL, &comp));
    CHECK(bvhw_compact(a, &comp) && comp.compact);
    /* smaller, but for trees of a few nodes (the root rounded up to 64 bytes, the tail's pad) */
    CHECKF(full.node_count > 16 ? comp.bytes < full.bytes : comp.bytes <= full.bytes + 64 + BVHW_TAIL_PAD,
           "compact %zu bytes, full %zu", comp.bytes, full.bytes);
    uint32_t stack_f[4096], stack_c[4096], sp = 0, bad = 0, visited = 0;
    stack_f[sp] = 0, stack_c[sp] = 0, sp++;
    while (sp && sp < 4096 - 16) {
        sp--;
        uint32_t rf = stack_f[sp], rc = stack_c[sp];
        const float *bf = (const float *)((const char *)full.nodes + (size_t)rf * bvhw_node_bytes(width));
        const int wc = width >> (rc & BVHW_KIND_MASK);
        const float *bc = (const float *)bvhw_node_at(comp.nodes, rc);
        const uint32_t *cf, *cc;
        uint32_t kf = kids_of(bf, width, &cf), kc = kids_of(bc, wc, &cc);
        visited++;
        /* as narrow as the children allow (the root stays full width), and the same children */
        bad += kc != kf || (rc != 0 && wc > 2 && (uint32_t)(wc / 2) >= kf) || (rc == 0 && wc != width);
        for (uint32_t i = 0; i < kf && i < kc; i++) {
            for (int p = 0; p < 6; p++) bad += memcmp(&bf[p * width + (int)i], &bc[p * wc + (int)i], 4) != 0;
            if (cf[i] & BVHW_LEAF) {
                bad += cc[i] != cf[i];
            } else {
                bad += (cc[i] & BVHW_LEAF) != 0;
                stack_f[sp] = cf[i], stack_c[sp] = cc[i], sp++;
            }
        }
    }
    CHECKF(bad == 0 && visited == full.node_count, "%u differences, %u of %u nodes visited", bad, visited,
           full.node_count);
    bvhw_free(a, &full);
    bvhw_free(a, &comp);
}

/* The margin bvh2_pad_boxes adds keeps a small object's boxes small on a large ground (shape 4
 * around the origin: the object spans 10^-4 of the ground): every box of the object's (all but
 * the root's and the ground's leaf) grows by under 10^-3 of the object's span per side. The
 * absolute part of the margin had been 2^-20 of the scene (20 times the object's triangles'
 * boxes here), which slowed every structure by 100-1000x on such scenes. */
static void check_pad_small(const bvh2 *b, float extent) {
    bvh2 t = *b;
    t.nodes = malloc((size_t)b->node_count * sizeof *t.nodes);
    memcpy(t.nodes, b->nodes, (size_t)b->node_count * sizeof *t.nodes);
    bvh2_pad_boxes(&t);
    const float span = extent * 1e-4f, most = span * 1e-3f;
    uint32_t grown = 0, checked = 0;
    for (uint32_t i = 1; i < b->node_count; i++) {
        const bvh_node *n = &b->nodes[i], *p = &t.nodes[i];
        if (!(n->lo[0] <= n->hi[0]) || n->hi[0] - n->lo[0] > span) continue; /* unused, or holds the ground */
        checked++;
        for (int k = 0; k < 3; k++) grown += !(n->lo[k] - p->lo[k] < most && p->hi[k] - n->hi[k] < most);
    }
    CHECKF(checked > 0 && grown == 0, "%u planes of %u small boxes moved out by more than %g", grown, checked,
           (double)most);
    free(t.nodes);
}

int main(void) {
    const sys_allocator a = {sys_default_alloc, NULL};
    const float centres[3] = {0.0f, 1.0e4f, -3.0e6f};
    const uint32_t sizes[4] = {1, 7, 1000, 20000};
    for (int c = 0; c < 3; c++)
        for (int shape = 0; shape < 5; shape++)
            for (int si = 0; si < 4; si++) {
                uint32_t n = sizes[si];
                bvh_prim *p = malloc((size_t)n * sizeof *p);
                make_boxes(p, n, centres[c], c == 2 ? 10.0f : 100.0f, shape);
                bvh2 b;
                bvh_build_desc d = {.bins = 16, .max_leaf_size = 8, .block_size = 4, .trav_cost = 0.5f};
                CHECK(bvh_build(&a, NULL, p, n, &d, &b));
                check_quant(&a, &b);
                if (shape == 4 && c == 0 && n > 1) check_pad_small(&b, 100.0f);
                for (int w = 4; w <= 16; w *= 2) check_compact(&a, &b, w);
                bvh2_free(&a, &b);
                free(p);
            }
    CHECKF(total_pairs > 0, "no pairs of one-block leaves in any tree");
    return RP_TEST_END();
}
