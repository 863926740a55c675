// rp-test: labels=render timeout=300
/* Alpha cutouts (src/render/alpha.c) against brute force on random rays. The scene: random quads
 * of four materials (opaque; map_d of an RGBA mask with random holes; map_d of a grey mask of
 * rings, no alpha channel; BLEND with a ramp), a dense stack of parallel masked quads, quads
 * duplicated with another material (exactly coplanar: equal distances, the core's (geom, prim)
 * tie-break decides), strips of quads sharing edges, and 70 fully cut quads stacked in front of an
 * opaque one (the 64-layer limit). Every query alpha.c wraps (alpha_intersect1 / occluded1, the
 * arrays with both hints, the n x n packets of every size with every traversal, with and without
 * each frustum, some lanes invalid) must give, ray for ray, the brute-force answer: every triangle
 * intersected with the kernels' own arithmetic (tri_intersect_ref), the hits taken by distance
 * (ties by prim), the first of each distance tested with the mask at its uv (the renderer's own
 * bilinear lookup, material_texture_alpha, on the material data's alpha, cutoff and texture), the
 * nearest uncut one kept, and nothing past 64 cut-out surfaces. */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>

#include "../src/render/render.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "rp_test.h"
#include "rp_test_png.h"
#include "rp_test_tmp.h"
#include "traverse/traverse.h"

/* ---- random numbers (splitmix64) ---- */

typedef struct rng {
    uint64_t s;
} rng;

static uint32_t rng_u32(rng *g) {
    uint64_t z = (g->s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return (uint32_t)((z ^ (z >> 31)) >> 32);
}
static float rng_float(rng *g) { return (float)(rng_u32(g) >> 8) * (1.0f / 16777216.0f); }
static float rng_range(rng *g, float lo, float hi) { return lo + (hi - lo) * rng_float(g); }

static void normalize3(float v[3]) {
    float l = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int a = 0; a < 3; a++) v[a] /= l;
}

static void random_dir(rng *g, float d[3]) {
    do {
        for (int a = 0; a < 3; a++) d[a] = rng_range(g, -1, 1);
    } while (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 1e-2f);
    normalize3(d);
}

/* ---- the scene files ---- */

enum { TEX = 32 };
enum { MAT_OPAQUE, MAT_HOLES, MAT_RINGS, MAT_BLEND, MAT_CUTALL, MATS };
static const char *mat_names[MATS] = {"opaque", "holes", "rings", "blend", "cutall"};

/* Masks: random holes in the alpha plane of an RGBA PNG (a third of the texels, some half
 * transparent), rings in a grey PNG (its grey value is the mask), a ramp for BLEND. */
static void write_masks(void) {
    static uint8_t rgba[TEX * TEX * 4], grey[TEX * TEX], ramp[TEX * TEX * 4];
    rng g = {7};
    for (int y = 0; y < TEX; y++)
        for (int x = 0; x < TEX; x++) {
            int i = y * TEX + x;
            uint32_t r = rng_u32(&g) % 6;
            rgba[4 * i] = 200, rgba[4 * i + 1] = 180, rgba[4 * i + 2] = 40;
            rgba[4 * i + 3] = r < 2 ? 0 : (r == 2 ? 100 : 255);
            float dx = (float)x - 15.5f, dy = (float)y - 15.5f;
            grey[i] = ((int)sqrtf(dx * dx + dy * dy) / 3) % 2 ? 255 : 30;
            ramp[4 * i] = ramp[4 * i + 1] = ramp[4 * i + 2] = 255;
            ramp[4 * i + 3] = (uint8_t)(x * 255 / (TEX - 1));
        }
    char path[1024];
    CHECK(stbi_write_png(tmp_path("holes.png", path, sizeof path), TEX, TEX, 4, rgba, TEX * 4) != 0);
    CHECK(stbi_write_png(tmp_path("rings.png", path, sizeof path), TEX, TEX, 1, grey, TEX) != 0);
    CHECK(stbi_write_png(tmp_path("ramp.png", path, sizeof path), TEX, TEX, 4, ramp, TEX * 4) != 0);
    /* cutall: MASK with alpha factor 0 (set after loading), its texture no matter */
    write_text("scene.mtl", "newmtl opaque\nKd 0.7 0.7 0.7\n"
                            "newmtl holes\nKd 1 1 1\nmap_d holes.png\n"
                            "newmtl rings\nKd 1 1 1\nmap_d rings.png\n"
                            "newmtl blend\nKd 1 1 1\nmap_d ramp.png\n"
                            "newmtl cutall\nKd 1 1 1\nmap_d holes.png\n");
}

/* The OBJ text, grown as quads are added. */
typedef struct obj_text {
    char *s;
    size_t n, cap;
    int verts, uvs;
} obj_text;

static void obj_printf(obj_text *o, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void obj_printf(obj_text *o, const char *fmt, ...) {
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        int k = vsnprintf(o->s + o->n, o->cap - o->n, fmt, ap);
        va_end(ap);
        if (k >= 0 && (size_t)k < o->cap - o->n) {
            o->n += (size_t)k;
            return;
        }
        o->cap = o->cap * 2 + 4096;
        o->s = realloc(o->s, o->cap);
        if (!o->s) exit(1);
    }
}

/* A quad c + a u + b v (a, b in [-1, 1]) of material mat, uv offset + scale * (a, b) (repeat
 * wrapping beyond [0, 1]); its two triangles share the diagonal. */
static void add_quad(obj_text *o, const float c[3], const float u[3], const float v[3], int mat, const float uv0[2],
                     float uv_scale) {
    static const float ab[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
    for (int k = 0; k < 4; k++) {
        float p[3];
        for (int a = 0; a < 3; a++) p[a] = c[a] + ab[k][0] * u[a] + ab[k][1] * v[a];
        obj_printf(o, "v %.9g %.9g %.9g\nvt %.9g %.9g\n", p[0], p[1], p[2], uv0[0] + uv_scale * (ab[k][0] + 1) * 0.5f,
                   uv0[1] + uv_scale * (ab[k][1] + 1) * 0.5f);
    }
    int b = o->verts;
    obj_printf(o, "usemtl %s\nf %d/%d %d/%d %d/%d\nf %d/%d %d/%d %d/%d\n", mat_names[mat], b + 1, b + 1, b + 2, b + 2,
               b + 3, b + 3, b + 1, b + 1, b + 3, b + 3, b + 4, b + 4);
    o->verts += 4, o->uvs += 4;
}

static int random_mat(rng *g) {
    uint32_t r = rng_u32(g) % 20;
    return r < 3 ? MAT_OPAQUE : r < 10 ? MAT_HOLES : r < 15 ? MAT_RINGS : MAT_BLEND;
}

/* The layer stack: 70 fully cut quads at z = 1..70 in front of an opaque one at z = 0, around
 * x = 10, y = 0, away from the rest. */
enum { STACK_LAYERS = 70 };
static const float stack_x = 10.0f;

static void write_scene(void) {
    obj_text o = {0};
    obj_printf(&o, "mtllib scene.mtl\n");
    rng g = {12345};
    /* random quads in [-1, 1]^3; every fifth one duplicated exactly with another material */
    for (int i = 0; i < 220; i++) {
        float c[3], u[3], v[3], n[3];
        for (int a = 0; a < 3; a++) c[a] = rng_range(&g, -1, 1);
        random_dir(&g, u);
        random_dir(&g, n);
        v[0] = u[1] * n[2] - u[2] * n[1], v[1] = u[2] * n[0] - u[0] * n[2], v[2] = u[0] * n[1] - u[1] * n[0];
        normalize3(v);
        float su = rng_range(&g, 0.1f, 0.5f), sv = rng_range(&g, 0.1f, 0.5f);
        for (int a = 0; a < 3; a++) u[a] *= su, v[a] *= sv;
        float uv0[2] = {rng_range(&g, -1, 1), rng_range(&g, -1, 1)}, scale = rng_range(&g, 0.5f, 3.0f);
        int mat = random_mat(&g);
        add_quad(&o, c, u, v, mat, uv0, scale);
        if (i % 5 == 0) add_quad(&o, c, u, v, (mat + 1 + (int)(rng_u32(&g) % 3)) % 4, uv0, scale);
    }
    /* a dense stack of 40 masked quads parallel to z = 0, few opaque */
    for (int i = 0; i < 40; i++) {
        float c[3] = {rng_range(&g, -0.2f, 0.2f), rng_range(&g, -0.2f, 0.2f), -1.0f + 0.05f * (float)i};
        float u[3] = {0.9f, 0, 0}, v[3] = {0, 0.9f, 0};
        float uv0[2] = {rng_float(&g), rng_float(&g)};
        int mat = i % 13 == 12 ? MAT_OPAQUE : 1 + (int)(rng_u32(&g) % 3);
        add_quad(&o, c, u, v, mat, uv0, rng_range(&g, 1, 4));
    }
    /* strips of quads sharing edges (shared vertices written twice, bit for bit the same) */
    for (int s = 0; s < 6; s++) {
        float c[3] = {rng_range(&g, -1, 1), rng_range(&g, -1, 1), rng_range(&g, -1, 1)}, u[3], v[3], n[3];
        random_dir(&g, u);
        random_dir(&g, n);
        v[0] = u[1] * n[2] - u[2] * n[1], v[1] = u[2] * n[0] - u[0] * n[2], v[2] = u[0] * n[1] - u[1] * n[0];
        normalize3(v);
        for (int a = 0; a < 3; a++) u[a] *= 0.125f, v[a] *= 0.25f;
        for (int k = 0; k < 6; k++) {
            float ck[3];
            for (int a = 0; a < 3; a++) ck[a] = c[a] + 2.0f * (float)k * u[a];
            float uv0[2] = {0.25f * (float)k, 0};
            add_quad(&o, ck, u, v, random_mat(&g), uv0, 0.25f);
        }
    }
    /* the layer stack */
    for (int i = 0; i <= STACK_LAYERS; i++) {
        float c[3] = {stack_x, 0, (float)i}, u[3] = {1, 0, 0}, v[3] = {0, 1, 0}, uv0[2] = {0, 0};
        add_quad(&o, c, u, v, i == 0 ? MAT_OPAQUE : MAT_CUTALL, uv0, 1);
    }
    write_bytes("scene.obj", o.s, o.n);
    free(o.s);
}

/* ---- the brute-force reference ---- */

typedef struct world {
    rp_scene_data sd;
    rp_render_scene *rs;
    uint32_t tri_geom;
} world;

/* The same arithmetic as alpha.c's BLEND test: a hash of the ray and of the hit's distance. */
static float blend_hash(const rp_ray *r, float t) {
    const float f[7] = {r->org_x, r->org_y, r->org_z, r->dir_x, r->dir_y, r->dir_z, t};
    uint32_t h = 0x9e3779b9u;
    for (int k = 0; k < 7; k++) {
        uint32_t b;
        memcpy(&b, &f[k], 4);
        h = render_hash(h ^ b);
    }
    return (float)(h >> 8) * (1.0f / 16777216.0f);
}

/* Whether the hit of r on triangle prim at t (barycentrics u, v) is on a cut-out point, from the
 * material data. */
static bool ref_cut(const world *w, const rp_ray *r, uint32_t prim, float t, float u, float v) {
    const rp_scene_data *d = &w->sd;
    const rp_material_data *m = &d->materials[d->tri_materials[prim]];
    if (m->alpha_mode == RP_ALPHA_OPAQUE) return false;
    float a = m->alpha;
    if (m->map_alpha > 0) {
        const uint32_t *ti = d->texcoord_indices + 3 * (size_t)prim;
        const float *t0 = d->texcoords + 2 * ti[0], *t1 = d->texcoords + 2 * ti[1], *t2 = d->texcoords + 2 * ti[2];
        float b0 = 1.0f - u - v;
        float uv[2] = {b0 * t0[0] + u * t1[0] + v * t2[0], b0 * t0[1] + u * t1[1] + v * t2[1]};
        a *= material_texture_alpha(w->rs, m->map_alpha - 1, uv);
    }
    if (m->alpha_mode == RP_ALPHA_MASK) return a < m->alpha_cutoff;
    return blend_hash(r, t) >= a;
}

typedef struct ref_hit {
    float t, u, v;
    uint32_t prim; /* RP_INVALID_ID: a miss (t the ray's tfar) */
    int layers;    /* cut-out surfaces passed */
    bool raw_cut;  /* the nearest hit was cut out (the core alone answers wrongly) */
} ref_hit;

typedef struct cand {
    float t, u, v;
    uint32_t prim;
} cand;

static int cand_cmp(const void *pa, const void *pb) {
    const cand *a = pa, *b = pb;
    if (a->t != b->t) return a->t < b->t ? -1 : 1;
    return a->prim < b->prim ? -1 : a->prim > b->prim;
}

/* The closest opaque hit: every triangle's hit over [tnear, tfar], by distance then prim; of
 * equal distances only the first (the core's answer) is tested; cut-out ones are passed, 64 at
 * most (the 65th makes a miss). */
static ref_hit reference(const world *w, const rp_ray *r, cand *scratch) {
    const rp_scene_data *d = &w->sd;
    const float o[3] = {r->org_x, r->org_y, r->org_z}, dir[3] = {r->dir_x, r->dir_y, r->dir_z};
    size_t n = 0;
    for (uint32_t i = 0; i < d->triangle_count; i++) {
        const uint32_t *ix = d->indices + 3 * (size_t)i;
        float t, u, v;
        if (tri_intersect_ref(o, dir, r->tnear, r->tfar, d->positions + 3 * ix[0], d->positions + 3 * ix[1],
                              d->positions + 3 * ix[2], &t, &u, &v))
            scratch[n++] = (cand){t, u, v, i};
    }
    qsort(scratch, n, sizeof *scratch, cand_cmp);
    ref_hit h = {.t = r->tfar, .prim = RP_INVALID_ID};
    for (size_t k = 0; k < n; k++) {
        if (k > 0 && scratch[k].t == scratch[k - 1].t) continue;
        const cand *c = &scratch[k];
        bool cut = ref_cut(w, r, c->prim, c->t, c->u, c->v);
        if (h.layers == 0 && k == 0) h.raw_cut = cut;
        if (!cut) {
            h.t = c->t, h.u = c->u, h.v = c->v, h.prim = c->prim;
            return h;
        }
        if (++h.layers > 64) break; /* the 65th cut-out surface: a miss */
    }
    return h;
}

/* ---- the rays ---- */

/* Random rays: from anywhere around the quads in any direction, aimed from outside at random points
 * of random triangles, at the midpoints of the quads' diagonals (both triangles' shared edge), along
 * the stack (near +-z), and down the layer stack from above 63 to 66 layers and from above all. */
static void make_rays(const world *w, rp_ray *rays, size_t n, uint64_t seed) {
    const rp_scene_data *d = &w->sd;
    rng g = {seed};
    size_t nt = d->triangle_count - 2 * (STACK_LAYERS + 1); /* not aimed at the layer stack */
    for (size_t i = 0; i < n; i++) {
        float o[3], dir[3];
        uint32_t kind = (uint32_t)(i % 8);
        if (kind < 3) {
            for (int a = 0; a < 3; a++) o[a] = rng_range(&g, -1.5f, 1.5f);
            random_dir(&g, dir);
        } else if (kind < 6) {
            uint32_t t = rng_u32(&g) % (uint32_t)nt;
            const uint32_t *ix = d->indices + 3 * (size_t)t;
            float b1 = rng_float(&g), b2 = rng_float(&g), p[3];
            if (kind == 5) /* the midpoint of the diagonal, v0-v2 of the quad's first triangle */
                ix = d->indices + 3 * (size_t)(t & ~1u), b1 = 0.0f, b2 = 0.5f;
            if (b1 + b2 > 1.0f) b1 = 1.0f - b1, b2 = 1.0f - b2;
            const float *v0 = d->positions + 3 * ix[0], *v1 = d->positions + 3 * ix[1], *v2 = d->positions + 3 * ix[2];
            for (int a = 0; a < 3; a++) p[a] = v0[a] + b1 * (v1[a] - v0[a]) + b2 * (v2[a] - v0[a]);
            random_dir(&g, dir);
            for (int a = 0; a < 3; a++) o[a] = p[a] - 3.0f * dir[a];
        } else if (kind == 6) {
            o[0] = rng_range(&g, -0.5f, 0.5f), o[1] = rng_range(&g, -0.5f, 0.5f), o[2] = rng_float(&g) < 0.5f ? -2.0f : 2.0f;
            dir[0] = rng_range(&g, -0.1f, 0.1f), dir[1] = rng_range(&g, -0.1f, 0.1f), dir[2] = o[2] < 0 ? 1.0f : -1.0f;
            normalize3(dir);
        } else {
            static const float above[5] = {63.5f, 64.5f, 65.5f, 66.5f, 80.0f};
            o[0] = stack_x + rng_range(&g, -0.9f, 0.9f), o[1] = rng_range(&g, -0.9f, 0.9f);
            o[2] = above[rng_u32(&g) % 5];
            dir[0] = dir[1] = 0.0f, dir[2] = -1.0f;
        }
        float tnear = rng_u32(&g) % 4 == 0 ? rng_range(&g, 0.0f, 1.0f) : 0.0f;
        float tfar = rng_u32(&g) % 4 == 0 ? rng_range(&g, 1.0f, 4.0f) : INFINITY;
        if (kind == 7) tfar = INFINITY;
        rays[i] = (rp_ray){.org_x = o[0], .org_y = o[1], .org_z = o[2], .tnear = tnear, .dir_x = dir[0], .dir_y = dir[1],
                           .dir_z = dir[2], .tfar = tfar, .mask = 0xFFFFFFFFu};
    }
}

/* Whether a closest-hit answer is the reference's (t, geom, prim, u, v; a miss keeps tfar). */
static bool same_hit(const world *w, const ref_hit *h, float t, uint32_t geom, uint32_t prim, float u, float v) {
    if (h->prim == RP_INVALID_ID) return geom == RP_INVALID_ID && memcmp(&t, &h->t, 4) == 0;
    return geom == w->tri_geom && prim == h->prim && t == h->t && u == h->u && v == h->v;
}

static bool same_occluded(const ref_hit *h, float tfar_before, float tfar_after) {
    if (h->prim != RP_INVALID_ID) return tfar_after == -INFINITY;
    return memcmp(&tfar_after, &tfar_before, 4) == 0;
}

static rp_rayhit rayhit_of(const rp_ray *r) {
    rp_rayhit rh = {.ray = *r};
    rh.hit.geom_id = rh.hit.prim_id = rh.hit.inst_id = RP_INVALID_ID;
    return rh;
}

static void shuffle(rng *g, uint32_t *order, size_t n) {
    for (size_t i = 0; i < n; i++) order[i] = (uint32_t)i;
    for (size_t i = n; i > 1; i--) {
        size_t j = rng_u32(g) % i;
        uint32_t t = order[i - 1];
        order[i - 1] = order[j], order[j] = t;
    }
}

enum { NRAYS = 4000 };

/* Single rays and the arrays (both hints, counts not a multiple of alpha.c's chunk), in random
 * orders. */
static void test_single_and_arrays(const world *w, cand *scratch) {
    static rp_ray rays[NRAYS];
    static ref_hit ref[NRAYS];
    static rp_rayhit rh[NRAYS];
    static rp_ray occ[NRAYS];
    static uint32_t order[NRAYS];
    make_rays(w, rays, NRAYS, 99);
    int hits = 0, fixed = 0, deep = 0, limit = 0, limit_hit = 0;
    for (size_t i = 0; i < NRAYS; i++) {
        ref[i] = reference(w, &rays[i], scratch);
        hits += ref[i].prim != RP_INVALID_ID;
        fixed += ref[i].raw_cut;
        deep += ref[i].layers >= 3;
        limit += ref[i].layers > 64;
        limit_hit += ref[i].layers == 64 && ref[i].prim != RP_INVALID_ID;
    }
    /* the test means something: hits, cut-out hits the core alone gets wrong, rays through many
     * layers, rays stopped by the limit and rays just within it */
    CHECKF(hits > NRAYS / 4 && fixed > NRAYS / 8 && deep > 100 && limit > 50 && limit_hit > 50,
           "hits %d, cut-out first hits %d, rays through 3+ layers %d, at the limit %d / %d", hits, fixed, deep, limit,
           limit_hit);

    /* the layer limit exactly: 64 cut-out quads above the opaque one are passed, 65 are not */
    for (int layers = 63; layers <= 66; layers++) {
        rp_ray r = {.org_x = stack_x + 0.3f, .org_y = -0.2f, .org_z = (float)layers + 0.5f, .dir_z = -1.0f,
                    .tfar = INFINITY, .mask = 0xFFFFFFFFu};
        rp_rayhit h = rayhit_of(&r);
        alpha_intersect1(w->rs, &h);
        bool seen = h.hit.geom_id != RP_INVALID_ID;
        CHECKF(seen == (layers <= 64) && (!seen || h.ray.tfar == (float)layers + 0.5f),
               "%d cut-out layers in front of an opaque quad: %s at %g", layers, seen ? "hit" : "miss", h.ray.tfar);
        rp_ray s = r;
        alpha_occluded1(w->rs, &s);
        CHECKF((s.tfar == -INFINITY) == (layers <= 64), "%d cut-out layers: occluded %d", layers, s.tfar == -INFINITY);
    }

    rng g = {2024};
    int bad1 = 0, bad_occ1 = 0;
    shuffle(&g, order, NRAYS);
    for (size_t k = 0; k < NRAYS; k++) {
        uint32_t i = order[k];
        rp_rayhit h = rayhit_of(&rays[i]);
        alpha_intersect1(w->rs, &h);
        if (!same_hit(w, &ref[i], h.ray.tfar, h.hit.geom_id, h.hit.prim_id, h.hit.u, h.hit.v)) {
            if (bad1++ < 5)
                fprintf(stderr, "ray %u: alpha_intersect1 t %.9g geom %u prim %u, reference t %.9g prim %u\n", i,
                        h.ray.tfar, h.hit.geom_id, h.hit.prim_id, ref[i].t, ref[i].prim);
        }
        rp_ray r = rays[i];
        alpha_occluded1(w->rs, &r);
        bad_occ1 += !same_occluded(&ref[i], rays[i].tfar, r.tfar);
    }
    CHECKF(bad1 == 0, "alpha_intersect1 differs from brute force on %d of %d rays", bad1, NRAYS);
    CHECKF(bad_occ1 == 0, "alpha_occluded1 differs from brute force on %d of %d rays", bad_occ1, NRAYS);

    static const uint32_t flags[2] = {RP_QUERY_INCOHERENT, RP_QUERY_COHERENT};
    static const size_t counts[3] = {NRAYS, 1, 517};
    for (int f = 0; f < 2; f++)
        for (int c = 0; c < 3; c++) {
            size_t n = counts[c];
            shuffle(&g, order, NRAYS);
            for (size_t k = 0; k < n; k++) rh[k] = rayhit_of(&rays[order[k]]), occ[k] = rays[order[k]];
            alpha_intersect_array(w->rs, rh, n, flags[f]);
            alpha_occluded_array(w->rs, occ, n, flags[f]);
            int bad = 0, bad_occ = 0;
            for (size_t k = 0; k < n; k++) {
                const ref_hit *h = &ref[order[k]];
                bad += !same_hit(w, h, rh[k].ray.tfar, rh[k].hit.geom_id, rh[k].hit.prim_id, rh[k].hit.u, rh[k].hit.v);
                bad_occ += !same_occluded(h, rays[order[k]].tfar, occ[k].tfar);
            }
            CHECKF(bad == 0, "alpha_intersect_array (flags %u, %zu rays) differs from brute force on %d", flags[f], n, bad);
            CHECKF(bad_occ == 0, "alpha_occluded_array (flags %u, %zu rays) differs from brute force on %d", flags[f], n,
                   bad_occ);
        }
}

/* ---- packets ---- */

static const rp_traversal modes[] = {RP_TRAVERSAL_AUTO,      RP_TRAVERSAL_MASKED, RP_TRAVERSAL_RANGED,
                                     RP_TRAVERSAL_PARTITION, RP_TRAVERSAL_SINGLE, RP_TRAVERSAL_SIMD,
                                     RP_TRAVERSAL_SPAN,      RP_TRAVERSAL_MLRT};

/* The rays of an n x n packet for a frustum kind: NONE and SECONDARY random rays (make_rays');
 * PRIMARY a pinhole camera's grid from a random eye at the quads; SHADOW segments from random points
 * to one point. */
static void packet_rays(const world *w, uint32_t n, rp_frustum_kind fk, rng *g, rp_ray *rays, float point[3]) {
    uint32_t nn = n * n;
    if (fk == RP_FRUSTUM_NONE || fk == RP_FRUSTUM_SECONDARY) {
        make_rays(w, rays, nn, rng_u32(g));
        static uint32_t order[RP_PACKET_N_MAX * RP_PACKET_N_MAX];
        static rp_ray tmp[RP_PACKET_N_MAX * RP_PACKET_N_MAX];
        shuffle(g, order, nn);
        for (uint32_t q = 0; q < nn; q++) tmp[q] = rays[order[q]];
        memcpy(rays, tmp, nn * sizeof *rays);
        return;
    }
    float e[3], f[3], r[3], u[3];
    random_dir(g, e);
    for (int a = 0; a < 3; a++) e[a] *= 2.5f, f[a] = rng_range(g, -0.3f, 0.3f) - e[a];
    normalize3(f);
    float up[3] = {0, 1, 0};
    r[0] = f[1] * up[2] - f[2] * up[1], r[1] = f[2] * up[0] - f[0] * up[2], r[2] = f[0] * up[1] - f[1] * up[0];
    normalize3(r);
    u[0] = r[1] * f[2] - r[2] * f[1], u[1] = r[2] * f[0] - r[0] * f[2], u[2] = r[0] * f[1] - r[1] * f[0];
    for (int a = 0; a < 3; a++) point[a] = rng_range(g, -0.5f, 0.5f) + 2.0f * u[a];
    for (uint32_t y = 0; y < n; y++)
        for (uint32_t x = 0; x < n; x++) {
            float sx = ((float)x + 0.5f) / (float)n * 2.0f - 1.0f, sy = ((float)y + 0.5f) / (float)n * 2.0f - 1.0f;
            rp_ray *ray = &rays[rp_packet_n_index(n, x, y)];
            float d[3];
            for (int a = 0; a < 3; a++) d[a] = f[a] + 0.4f * (sx * r[a] + sy * u[a]);
            if (fk == RP_FRUSTUM_PRIMARY) {
                normalize3(d);
                *ray = (rp_ray){.org_x = e[0], .org_y = e[1], .org_z = e[2], .dir_x = d[0], .dir_y = d[1], .dir_z = d[2],
                                .tfar = INFINITY, .mask = 0xFFFFFFFFu};
            } else { /* from points of the quads' region up to the point */
                float p[3];
                for (int a = 0; a < 3; a++) p[a] = e[a] * 0.1f + 1.2f * d[a] + rng_range(g, -0.3f, 0.3f);
                *ray = (rp_ray){.org_x = p[0], .org_y = p[1], .org_z = p[2], .tnear = 1e-4f, .dir_x = point[0] - p[0],
                                .dir_y = point[1] - p[1], .dir_z = point[2] - p[2], .tfar = 1.0f - 1e-4f,
                                .mask = 0xFFFFFFFFu};
            }
        }
}

static void packet_load(rp_rayhit_n *p, const rp_ray *rays, const int32_t *valid) {
    uint32_t nn = p->n * p->n;
    for (uint32_t q = 0; q < nn; q++) {
        p->org_x[q] = rays[q].org_x, p->org_y[q] = rays[q].org_y, p->org_z[q] = rays[q].org_z;
        p->dir_x[q] = rays[q].dir_x, p->dir_y[q] = rays[q].dir_y, p->dir_z[q] = rays[q].dir_z;
        p->tnear[q] = rays[q].tnear;
        /* an invalid lane keeps sentinels, never written */
        p->tfar[q] = valid[q] ? rays[q].tfar : 12345.0f;
        p->geom_id[q] = p->prim_id[q] = p->inst_id[q] = valid[q] ? RP_INVALID_ID : 777u;
    }
}

static void test_packets(rp_device *dev, const world *w, cand *scratch) {
    static const rp_frustum_kind kinds[4] = {RP_FRUSTUM_NONE, RP_FRUSTUM_PRIMARY, RP_FRUSTUM_SHADOW, RP_FRUSTUM_SECONDARY};
    static const char *kind_names[4] = {"none", "primary", "shadow", "secondary"};
    static rp_ray rays[RP_PACKET_N_MAX * RP_PACKET_N_MAX];
    static ref_hit ref[RP_PACKET_N_MAX * RP_PACKET_N_MAX];
    static int32_t valid[RP_PACKET_N_MAX * RP_PACKET_N_MAX];
    rng g = {4242};
    int fixed = 0;
    for (uint32_t n = 4; n <= RP_PACKET_N_MAX; n *= 2) {
        rp_rayhit_n p;
        CHECK(rp_rayhit_n_alloc(dev, n, &p));
        uint32_t nn = n * n;
        for (int k = 0; k < 4; k++)
            for (int rep = 0; rep < 2; rep++) {
                float point[3] = {0, 0, 0};
                packet_rays(w, n, kinds[k], &g, rays, point);
                for (uint32_t q = 0; q < nn; q++) {
                    ref[q] = reference(w, &rays[q], scratch);
                    fixed += ref[q].raw_cut;
                    valid[q] = rep == 0 || rng_u32(&g) % 8 != 0; /* rep 0: all live (valid NULL) */
                }
                p.valid = rep == 0 ? NULL : valid;
                for (size_t m = 0; m < sizeof modes / sizeof modes[0]; m++) {
                    rp_query_n_desc qd = {.traversal = modes[m], .frustum = kinds[k]};
                    memcpy(qd.point, point, sizeof point);
                    int bad = 0, bad_occ = 0, touched = 0;
                    packet_load(&p, rays, valid);
                    alpha_intersect_n(w->rs, &qd, &p);
                    for (uint32_t q = 0; q < nn; q++) {
                        if (rep && !valid[q]) {
                            touched += p.tfar[q] != 12345.0f || p.geom_id[q] != 777u || p.prim_id[q] != 777u;
                            continue;
                        }
                        if (!same_hit(w, &ref[q], p.tfar[q], p.geom_id[q], p.prim_id[q], p.u[q], p.v[q])) {
                            if (bad++ < 3)
                                fprintf(stderr, "n %u %s mode %d lane %u: t %.9g prim %u, reference t %.9g prim %u\n", n,
                                        kind_names[k], (int)modes[m], q, p.tfar[q], p.prim_id[q], ref[q].t,
                                        ref[q].prim);
                        }
                    }
                    packet_load(&p, rays, valid);
                    alpha_occluded_n(w->rs, &qd, &p);
                    for (uint32_t q = 0; q < nn; q++) {
                        if (rep && !valid[q]) {
                            touched += p.tfar[q] != 12345.0f;
                            continue;
                        }
                        bad_occ += !same_occluded(&ref[q], rays[q].tfar, p.tfar[q]);
                    }
                    CHECKF(bad == 0, "alpha_intersect_n %ux%u, frustum %s, traversal %d: %d of %u lanes differ", n, n,
                           kind_names[k], (int)modes[m], bad, nn);
                    CHECKF(bad_occ == 0, "alpha_occluded_n %ux%u, frustum %s, traversal %d: %d of %u lanes differ", n,
                           n, kind_names[k], (int)modes[m], bad_occ, nn);
                    CHECKF(touched == 0, "%ux%u %s: %d invalid lanes written", n, n, kind_names[k], touched);
                }
            }
        rp_rayhit_n_free(dev, &p);
    }
    CHECKF(fixed > 1000, "only %d packet rays first hit a cut-out point", fixed);
}

int main(void) {
    tmp_init("/tmp/rp_test_alpha_random");
    write_masks();
    write_scene();
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    world w = {0};
    char path[1024], err[512] = "";
    bool ok = rp_scene_data_load(tmp_path("scene.obj", path, sizeof path), &w.sd, err, sizeof err);
    CHECKF(ok, "%s", err);
    if (!ok) return RP_TEST_END();
    /* BLEND and the fully cut material, which MTL cannot say */
    CHECK(w.sd.material_count >= MATS);
    for (size_t i = 0; i < w.sd.material_count; i++) {
        rp_material_data *m = &w.sd.materials[i];
        if (strcmp(m->name, "blend") == 0) m->alpha_mode = RP_ALPHA_BLEND, m->alpha = 0.9f;
        if (strcmp(m->name, "cutall") == 0) m->alpha = 0.0f;
        if (strcmp(m->name, "holes") == 0) m->alpha_cutoff = 0.3f; /* the texels of alpha 100 (0.39) kept */
    }
    w.rs = rp_render_scene_new(dev, &w.sd, NULL, err, sizeof err);
    CHECKF(w.rs != NULL, "%s", err);
    if (w.rs) {
        CHECK(w.rs->cutouts);
        w.tri_geom = w.rs->geom_ids[RENDER_GEOM_TRIANGLES];
        cand *scratch = malloc(w.sd.triangle_count * sizeof *scratch);
        test_single_and_arrays(&w, scratch);
        test_packets(dev, &w, scratch);
        free(scratch);
        rp_render_scene_release(w.rs);
    }
    rp_scene_data_free(&w.sd);
    rp_device_release(dev);
    return RP_TEST_END();
}
