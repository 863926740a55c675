// rp-test: labels=core timeout=900
/* Large packets never lose a hit, whatever the camera and the caller's layout (issue: a frustum
 * made from the slopes of an 8x8 packet rounded them to the ulp of a far-from-origin apex and
 * culled the triangle one ray hit). Random cameras on shared scenes, from inside and outside the
 * scene's bounds, grazing its faces, with fov from 1 to 170 degrees and image widths from 64 to
 * 8192 (so packets of very narrow and very wide spread); an n x n block of the image at a random
 * place, its rays sometimes shuffled inside the packet and some dead; shadow packets from its hits
 * toward a random light; reflection packets off the hit surfaces. Every traversal x packet size x
 * frustum setting, closest hit and any hit, ray by ray against rp_intersect1 / rp_occluded1.
 *
 * Every ISA's kernels (the best with all cameras, the others with a quarter). Then the BIH
 * (rp_scene_desc.accel) with half the cameras: its n x n packets (every traversal setting) and its
 * 4/8/16-ray SIMD packets (rp_intersect4..16, rp_occluded4..16, the packet's slots in order, dead
 * rays included), hit for hit against the BVH's single rays.
 * `test_packets_random --long [CAMERAS]` runs many more cameras (default 4000 per scene) with
 * seeds after the CI list; `--seed S` runs one. */
#include <math.h>

#include "raypack.h"
#include "raypack_io.h"
#include "rp_test.h"
#include "sys/sys.h"

#include "packets_n_gen.h"

/* splitmix64: a seed per (scene, camera), so any failure is replayed by its seed alone. */
static uint64_t rng_next(uint64_t *s) {
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}
static float rng_float(uint64_t *s) { return (float)(rng_next(s) >> 40) * (1.0f / 16777216.0f); }
static uint32_t rng_below(uint64_t *s, uint32_t n) { return (uint32_t)(rng_next(s) % n); }

typedef struct cam {
    float eye[3], f[3], r[3], u[3], th;
    int width, height;
} cam;

static void rand_dir(uint64_t *s, float d[3]) {
    float z = 2.0f * rng_float(s) - 1.0f, a = 6.2831853f * rng_float(s), q = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    d[0] = q * cosf(a), d[1] = q * sinf(a), d[2] = z;
}

/* A camera of one of four kinds: outside the bounds looking in, inside looking anywhere, grazing a
 * face of the bounds, or far away with a tiny fov. */
static void rand_camera(const world *w, uint64_t *s, cam *c) {
    float ext[3], mid[3], diag = 0.0f;
    for (int a = 0; a < 3; a++) {
        ext[a] = w->hi[a] - w->lo[a], mid[a] = 0.5f * (w->lo[a] + w->hi[a]);
        diag += ext[a] * ext[a];
    }
    diag = sqrtf(diag);
    float look[3], fov;
    uint32_t kind = rng_below(s, 4);
    for (int a = 0; a < 3; a++) look[a] = w->lo[a] + rng_float(s) * ext[a];
    if (kind == 0) { /* outside, looking at a point inside */
        float d[3];
        rand_dir(s, d);
        float dist = diag * (0.6f + 2.4f * rng_float(s));
        for (int a = 0; a < 3; a++) c->eye[a] = mid[a] + dist * d[a];
        fov = 5.0f + 115.0f * rng_float(s);
    } else if (kind == 1) { /* inside, any direction */
        float d[3];
        rand_dir(s, d);
        for (int a = 0; a < 3; a++) c->eye[a] = w->lo[a] + rng_float(s) * ext[a], look[a] = c->eye[a] + d[a];
        fov = 1.0f + 169.0f * rng_float(s);
    } else if (kind == 2) { /* grazing: just off a face of the bounds, looking along it */
        int ax = (int)rng_below(s, 3), side = (int)rng_below(s, 2);
        for (int a = 0; a < 3; a++) c->eye[a] = w->lo[a] + rng_float(s) * ext[a];
        float off = ext[ax] * (rng_float(s) - 0.5f) * 0.02f;
        c->eye[ax] = (side ? w->hi[ax] : w->lo[ax]) + off;
        for (int a = 0; a < 3; a++) look[a] = w->lo[a] + rng_float(s) * ext[a];
        look[ax] = c->eye[ax] + (rng_float(s) - 0.5f) * 0.02f * ext[ax];
        fov = 10.0f + 160.0f * rng_float(s);
    } else { /* far away, narrow */
        float d[3];
        rand_dir(s, d);
        float dist = diag * (2.0f + 8.0f * rng_float(s));
        for (int a = 0; a < 3; a++) c->eye[a] = mid[a] + dist * d[a];
        fov = 1.0f + 9.0f * rng_float(s);
    }
    float up[3];
    do {
        rand_dir(s, up);
        if (rng_below(s, 2)) up[0] = 0, up[1] = 1, up[2] = 0;
        for (int a = 0; a < 3; a++) c->f[a] = look[a] - c->eye[a];
        normalize(c->f);
        cross(c->f, up, c->r);
    } while (!(dot(c->r, c->r) > 1e-4f));
    normalize(c->r);
    cross(c->r, c->f, c->u);
    c->th = tanf(fov * 0.5f * 3.14159265f / 180.0f);
    static const int widths[] = {64, 256, 640, 1024, 2048, 8192};
    c->width = widths[rng_below(s, 6)];
    c->height = (int)((float)c->width * (0.5f + rng_float(s)));
    if (c->height < 32) c->height = 32;
}

/* DESIGN.md's primary ray of pixel (x, y) + jitter. */
static void cam_ray(const cam *c, int x, int y, float jx, float jy, rp_ray *r) {
    float sx = (2.0f * ((float)x + jx) / (float)c->width - 1.0f) * c->th * ((float)c->width / (float)c->height);
    float sy = (1.0f - 2.0f * ((float)y + jy) / (float)c->height) * c->th;
    float d[3];
    for (int a = 0; a < 3; a++) d[a] = c->f[a] + sx * c->r[a] + sy * c->u[a];
    normalize(d);
    *r = (rp_ray){.org_x = c->eye[0], .org_y = c->eye[1], .org_z = c->eye[2], .tnear = 0.0f, .dir_x = d[0],
                  .dir_y = d[1], .dir_z = d[2], .tfar = INFINITY, .mask = 0xFFFFFFFFu};
}

typedef struct stats {
    uint64_t rays, hits, bad, cameras;
} stats;

/* Traces rays[0 .. n*n) (slot q of the packet holds rays[q]) with every traversal and frustum
 * setting (few: auto, single and SIMD without frustum, for a structure whose packets ignore both);
 * counts the rays whose answer differs from the single-ray one. */
static void trace_all(rp_device *dev, rp_scene *scene, const test_ray *rays, uint32_t n, rp_frustum_kind fk,
                      const float point[3], const char *what, uint64_t seed, bool few, stats *st) {
    rp_rayhit_n p;
    if (!rp_rayhit_n_alloc(dev, n, &p)) {
        CHECK(!"packet allocates");
        return;
    }
    uint32_t count = n * n;
    int32_t *valid = malloc(sizeof(int32_t) * count);
    for (uint32_t q = 0; q < count; q++) valid[q] = rays[q].live ? -1 : 0;
    p.valid = valid;
    rp_auto_tally tally;
    memset(&tally, 0, sizeof tally);
    for (size_t m = 0; m < sizeof modes / sizeof modes[0]; m++)
        for (int fr = 0; fr < 2 - few; fr++)
            for (int occ = 0; occ < 2; occ++) {
                if (few && modes[m] != RP_TRAVERSAL_AUTO && modes[m] != RP_TRAVERSAL_SINGLE &&
                    modes[m] != RP_TRAVERSAL_SIMD)
                    continue;
                rp_query_n_desc d = {.traversal = modes[m], .frustum = fr ? fk : RP_FRUSTUM_NONE,
                                     .tally = modes[m] == RP_TRAVERSAL_AUTO && occ ? &tally : NULL};
                if (point) memcpy(d.point, point, sizeof d.point);
                for (uint32_t q = 0; q < count; q++) {
                    const rp_ray *r = &rays[q].ray;
                    p.org_x[q] = r->org_x, p.org_y[q] = r->org_y, p.org_z[q] = r->org_z;
                    p.dir_x[q] = r->dir_x, p.dir_y[q] = r->dir_y, p.dir_z[q] = r->dir_z;
                    p.tnear[q] = r->tnear, p.tfar[q] = rays[q].live ? r->tfar : 42.0f;
                    p.geom_id[q] = RP_INVALID_ID, p.prim_id[q] = 777u;
                }
                if (occ) rp_occluded_n(scene, &d, &p);
                else rp_intersect_n(scene, &d, &p);
                uint32_t bad = 0, first = UINT32_MAX;
                for (uint32_t q = 0; q < count; q++) {
                    const test_ray *t = &rays[q];
                    bool wrong;
                    if (!t->live) wrong = p.tfar[q] != 42.0f || p.geom_id[q] != RP_INVALID_ID;
                    else if (occ) wrong = (p.tfar[q] == -INFINITY) != t->occluded;
                    else wrong = p.geom_id[q] != t->ref.hit.geom_id ||
                                 (t->ref.hit.geom_id != RP_INVALID_ID &&
                                  (p.prim_id[q] != t->ref.hit.prim_id || p.tfar[q] != t->ref.ray.tfar ||
                                   p.u[q] != t->ref.hit.u || p.v[q] != t->ref.hit.v));
                    if (wrong && first == UINT32_MAX) first = q;
                    bad += wrong;
                }
                if (modes[m] == RP_TRAVERSAL_AUTO && !fr && !occ) st->rays += count;
                st->bad += bad;
                CHECKF(bad == 0,
                       "seed %llu: %s %ux%u %s, frustum %s, %s: %u of %u rays differ from single rays (first: slot %u, "
                       "ref geom %u prim %u t %.9g)",
                       (unsigned long long)seed, what, n, n, mode_names[m], fr ? "on" : "off",
                       occ ? "occluded" : "intersect", bad, count, first, rays[first].ref.hit.geom_id,
                       rays[first].ref.hit.prim_id, (double)rays[first].ref.ray.tfar);
            }
    free(valid);
    rp_rayhit_n_free(dev, &p);
}

/* Rays[0 .. count) as SIMD packets of W rays (slot order, dead rays as invalid lanes), closest
 * and any hit, against the reference; dead lanes must stay untouched. */
#define TRACE_SIMD(W)                                                                             \
    static uint32_t trace_simd_##W(rp_scene *scene, const test_ray *rays, uint32_t count, uint32_t *first) { \
        uint32_t bad = 0;                                                                         \
        for (uint32_t base = 0; base + W <= count; base += W) {                                   \
            rp_rayhit##W p;                                                                       \
            rp_ray##W o;                                                                          \
            int32_t valid[W];                                                                     \
            memset(&p, 0, sizeof p), memset(&o, 0, sizeof o);                                     \
            for (int i = 0; i < W; i++) {                                                         \
                const test_ray *t = &rays[base + (uint32_t)i];                                    \
                const rp_ray *r = &t->ray;                                                        \
                valid[i] = t->live ? -1 : 0;                                                      \
                p.ray.org_x[i] = o.org_x[i] = r->org_x, p.ray.org_y[i] = o.org_y[i] = r->org_y;   \
                p.ray.org_z[i] = o.org_z[i] = r->org_z, p.ray.dir_x[i] = o.dir_x[i] = r->dir_x;   \
                p.ray.dir_y[i] = o.dir_y[i] = r->dir_y, p.ray.dir_z[i] = o.dir_z[i] = r->dir_z;   \
                p.ray.tnear[i] = o.tnear[i] = r->tnear;                                           \
                p.ray.tfar[i] = o.tfar[i] = t->live ? r->tfar : 42.0f;                            \
                p.ray.mask[i] = o.mask[i] = r->mask;                                              \
                p.hit.geom_id[i] = RP_INVALID_ID, p.hit.prim_id[i] = 777u;                        \
            }                                                                                     \
            rp_intersect##W(scene, valid, &p);                                                    \
            rp_occluded##W(scene, valid, &o);                                                     \
            for (int i = 0; i < W; i++) {                                                         \
                const test_ray *t = &rays[base + (uint32_t)i];                                    \
                bool wrong;                                                                       \
                if (!t->live)                                                                     \
                    wrong = p.ray.tfar[i] != 42.0f || o.tfar[i] != 42.0f || p.hit.geom_id[i] != RP_INVALID_ID || \
                            p.hit.prim_id[i] != 777u;                                             \
                else                                                                              \
                    wrong = (o.tfar[i] == -INFINITY) != t->occluded || p.hit.geom_id[i] != t->ref.hit.geom_id || \
                            (t->ref.hit.geom_id != RP_INVALID_ID &&                               \
                             (p.hit.prim_id[i] != t->ref.hit.prim_id || p.ray.tfar[i] != t->ref.ray.tfar || \
                              p.hit.u[i] != t->ref.hit.u || p.hit.v[i] != t->ref.hit.v ||          \
                              p.hit.Ng_x[i] != t->ref.hit.Ng_x || p.hit.Ng_y[i] != t->ref.hit.Ng_y || \
                              p.hit.Ng_z[i] != t->ref.hit.Ng_z));                                 \
                if (wrong && *first == UINT32_MAX) *first = base + (uint32_t)i;                   \
                bad += wrong;                                                                     \
            }                                                                                     \
        }                                                                                         \
        return bad;                                                                               \
    }
TRACE_SIMD(4)
TRACE_SIMD(8)
TRACE_SIMD(16)

/* The SIMD packets of every width over the n x n rays. */
static void trace_simd_all(rp_scene *scene, const test_ray *rays, uint32_t count, const char *what, uint64_t seed,
                           stats *st) {
    uint32_t (*fn[3])(rp_scene *, const test_ray *, uint32_t, uint32_t *) = {trace_simd_4, trace_simd_8, trace_simd_16};
    static const int widths[3] = {4, 8, 16};
    for (int w = 0; w < 3; w++) {
        uint32_t first = UINT32_MAX, bad = fn[w](scene, rays, count, &first);
        st->bad += bad;
        CHECKF(bad == 0, "seed %llu: %s %d-ray SIMD packets: %u of %u rays differ from the reference (first: slot %u)",
               (unsigned long long)seed, what, widths[w], bad, count, first);
    }
}

/* One random camera: a primary packet, then shadow and reflection packets from its hits. The
 * references are ref_scene's single rays; the packets go to scene (with simd, its SIMD packets
 * too). */
static void check_camera(rp_device *dev, rp_scene *ref_scene, rp_scene *scene, const world *w, uint64_t seed, bool simd,
                         stats *st) {
    uint64_t s = seed;
    cam c;
    rand_camera(w, &s, &c);
    static const uint32_t sizes[] = {4, 8, 16, 32};
    uint32_t n = sizes[rng_below(&s, 4)];
    if ((int)n > c.width) n = 4;
    int x0 = (int)rng_below(&s, (uint32_t)(c.width - (int)n + 1)), y0 = (int)rng_below(&s, (uint32_t)(c.height - (int)n + 1));
    bool jitter = rng_below(&s, 3) == 0, shuffle = rng_below(&s, 3) == 0, dead = rng_below(&s, 2) == 0;
    uint32_t count = n * n;
    test_ray *prim = calloc(count, sizeof *prim), *sec = calloc(count, sizeof *sec);
    uint32_t *perm = malloc(sizeof(uint32_t) * count);
    for (uint32_t q = 0; q < count; q++) perm[q] = q;
    if (shuffle)
        for (uint32_t q = count - 1; q > 0; q--) {
            uint32_t j = rng_below(&s, q + 1), t = perm[q];
            perm[q] = perm[j], perm[j] = t;
        }
    /* slot perm[q] holds the ray of the block's pixel q (its Morton position when not shuffled) */
    for (uint32_t y = 0; y < n; y++)
        for (uint32_t x = 0; x < n; x++) {
            uint32_t q = perm[rp_packet_n_index(n, x, y)];
            test_ray *t = &prim[q];
            float jx = jitter ? rng_float(&s) : 0.5f, jy = jitter ? rng_float(&s) : 0.5f;
            cam_ray(&c, x0 + (int)x, y0 + (int)y, jx, jy, &t->ray);
            t->live = !dead || rng_below(&s, 8) != 0;
            if (t->live) reference(ref_scene, t);
        }
    trace_all(dev, scene, prim, n, RP_FRUSTUM_PRIMARY, NULL, "primary", seed, simd, st);
    if (simd) trace_simd_all(scene, prim, count, "primary", seed, st);
    float diag = 0.0f, light[3];
    for (int a = 0; a < 3; a++) diag += (w->hi[a] - w->lo[a]) * (w->hi[a] - w->lo[a]);
    diag = sqrtf(diag);
    for (int a = 0; a < 3; a++) light[a] = w->lo[a] + (w->hi[a] - w->lo[a]) * (1.4f * rng_float(&s) - 0.2f);
    for (int kind = 0; kind < 2; kind++) { /* 0: shadow toward the light, 1: mirror reflection */
        uint32_t live = 0;
        for (uint32_t q = 0; q < count; q++) {
            const rp_rayhit *h = &prim[q].ref;
            test_ray *t = &sec[q];
            memset(t, 0, sizeof *t);
            t->live = prim[q].live && h->hit.geom_id != RP_INVALID_ID;
            float d[3] = {h->ray.dir_x, h->ray.dir_y, h->ray.dir_z};
            float nrm[3] = {h->hit.Ng_x, h->hit.Ng_y, h->hit.Ng_z};
            if (t->live && !(dot(nrm, nrm) > 0.0f)) t->live = false;
            if (!t->live) {
                t->ray = prim[q].ray;
                continue;
            }
            float pt[3], nd[3];
            pt[0] = h->ray.org_x + h->ray.tfar * d[0], pt[1] = h->ray.org_y + h->ray.tfar * d[1];
            pt[2] = h->ray.org_z + h->ray.tfar * d[2];
            if (kind == 0) {
                for (int a = 0; a < 3; a++) nd[a] = light[a] - pt[a];
                t->ray = (rp_ray){.org_x = pt[0], .org_y = pt[1], .org_z = pt[2], .tnear = 1e-4f, .dir_x = nd[0],
                                  .dir_y = nd[1], .dir_z = nd[2], .tfar = 1.0f - 1e-4f, .mask = 0xFFFFFFFFu};
            } else {
                normalize(nrm);
                float cs = dot(d, nrm);
                for (int a = 0; a < 3; a++) nd[a] = d[a] - 2.0f * cs * nrm[a];
                t->ray = (rp_ray){.org_x = pt[0], .org_y = pt[1], .org_z = pt[2], .tnear = 1e-4f * diag,
                                  .dir_x = nd[0], .dir_y = nd[1], .dir_z = nd[2], .tfar = INFINITY, .mask = 0xFFFFFFFFu};
            }
            reference(ref_scene, t);
            live++;
        }
        if (!live) continue;
        if (kind == 0) trace_all(dev, scene, sec, n, RP_FRUSTUM_SHADOW, light, "shadow", seed, simd, st);
        else trace_all(dev, scene, sec, n, RP_FRUSTUM_SECONDARY, NULL, "reflection", seed, simd, st);
        if (simd) trace_simd_all(scene, sec, count, kind ? "reflection" : "shadow", seed, st);
    }
    for (uint32_t q = 0; q < count; q++) st->hits += prim[q].live && prim[q].ref.hit.geom_id != RP_INVALID_ID;
    st->cameras++;
    free(perm);
    free(prim);
    free(sec);
}

/* Traces one 32x32 primary packet of camera c (pixels 496..527 of its 1024x1024 image) with MLRT
 * and returns its counters and hits. */
static rp_counters_n mlrt_packet(rp_scene *scene, rp_rayhit_n *p, const cam *c, uint32_t *hits) {
    for (uint32_t y = 0; y < 32; y++)
        for (uint32_t x = 0; x < 32; x++) {
            rp_ray r;
            cam_ray(c, 496 + (int)x, 496 + (int)y, 0.5f, 0.5f, &r);
            uint32_t q = rp_packet_n_index(32, x, y);
            p->org_x[q] = r.org_x, p->org_y[q] = r.org_y, p->org_z[q] = r.org_z;
            p->dir_x[q] = r.dir_x, p->dir_y[q] = r.dir_y, p->dir_z[q] = r.dir_z;
            p->tnear[q] = 0.0f, p->tfar[q] = INFINITY, p->geom_id[q] = RP_INVALID_ID;
        }
    rp_counters_n cn;
    memset(&cn, 0, sizeof cn);
    rp_intersect_n(scene,
                   &(rp_query_n_desc){.traversal = RP_TRAVERSAL_MLRT, .frustum = RP_FRUSTUM_PRIMARY, .counters = &cn},
                   p);
    *hits = 0;
    for (uint32_t q = 0; q < 32 * 32; q++) *hits += p->geom_id[q] != RP_INVALID_ID;
    return cn;
}

static void look_at(cam *c, const float eye[3], const float look[3], float fov) {
    *c = (cam){.width = 1024, .height = 1024};
    for (int a = 0; a < 3; a++) c->eye[a] = eye[a], c->f[a] = look[a] - eye[a];
    normalize(c->f);
    float up[3] = {0, 1, 0};
    if (fabsf(c->f[1]) > 0.9f) up[0] = 1, up[1] = 0;
    cross(c->f, up, c->r);
    normalize(c->r);
    cross(c->r, c->f, c->u);
    c->th = tanf(0.5f * fov * 3.14159265f / 180.0f);
}

/* MLRT's entry points: over a 16x16 grid of separate quads seen from above, a narrow packet on one
 * quad starts all its rays deep below the root (the tree's clusters are what the frustum culls);
 * a packet aimed away from a shared scene traces nothing at all. */
static void check_mlrt_entries(const world *w) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_rayhit_n p;
    CHECK(rp_rayhit_n_alloc(dev, 32, &p));
    enum { G = 16 };
    float pos[G * G * 4 * 3];
    uint32_t idx[G * G * 6];
    for (int j = 0; j < G; j++)
        for (int i = 0; i < G; i++) {
            int c = j * G + i;
            const float qx[4] = {0, 1, 1, 0}, qz[4] = {0, 0, 1, 1};
            for (int v = 0; v < 4; v++) {
                pos[12 * c + 3 * v + 0] = 10.0f * (float)i + qx[v];
                pos[12 * c + 3 * v + 1] = 0.0f;
                pos[12 * c + 3 * v + 2] = 10.0f * (float)j + qz[v];
            }
            const uint32_t t[6] = {0, 1, 2, 0, 2, 3};
            for (int k = 0; k < 6; k++) idx[6 * c + k] = 4u * (uint32_t)c + t[k];
        }
    rp_scene *grid = make_scene(dev, &(rp_scene_data){.positions = pos, .vertex_count = G * G * 4, .indices = idx,
                                                      .triangle_count = G * G * 2});
    cam c;
    look_at(&c, (float[3]){70.5f, 40.0f, 90.5f}, (float[3]){70.5f, 0.0f, 90.5f}, 2.0f);
    uint32_t hits;
    rp_counters_n cn = mlrt_packet(grid, &p, &c, &hits);
    CHECKF(cn.traversal[6] == 1, "grid: the packet went to MLRT");
    CHECKF(hits == 1024 && cn.mlrt_rays_below_root == 1024 && cn.mlrt_entry_depth >= 6 * 1024,
           "grid: MLRT entry points: %llu of 1024 rays below the root, mean depth %.1f (%u hits)",
           (unsigned long long)cn.mlrt_rays_below_root,
           cn.mlrt_rays_below_root ? (double)cn.mlrt_entry_depth / (double)cn.mlrt_rays_below_root : 0.0, hits);
    rp_scene_release(grid);
    rp_scene *scene = make_scene(dev, &w->sd);
    float mid[3], diag = 0.0f, eye[3], away[3];
    for (int a = 0; a < 3; a++) {
        mid[a] = 0.5f * (w->lo[a] + w->hi[a]);
        diag += (w->hi[a] - w->lo[a]) * (w->hi[a] - w->lo[a]);
    }
    diag = sqrtf(diag);
    for (int a = 0; a < 3; a++) eye[a] = mid[a] + 2.0f * diag * (a == 0 ? 0.8f : 0.6f * (a == 2)), away[a] = 2 * eye[a] - mid[a];
    look_at(&c, eye, away, 30.0f);
    cn = mlrt_packet(scene, &p, &c, &hits);
    CHECKF(hits == 0 && cn.box_tests == 0 && cn.tri_tests == 0,
           "%s: a packet aimed away from the scene: %u hits, %llu box and %llu triangle tests", w->name, hits,
           (unsigned long long)cn.box_tests, (unsigned long long)cn.tri_tests);
    rp_rayhit_n_free(dev, &p);
    rp_scene_release(scene);
    rp_device_release(dev);
}

int main(int argc, char **argv) {
    int cameras = rp_test_sanitized() ? 150 : 1500; /* per scene, in CI (release: about 10 s) */
    uint64_t first = 1, only = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--long") == 0) {
            cameras = i + 1 < argc && argv[i + 1][0] != '-' ? atoi(argv[++i]) : 4000;
            first = 1000000; /* past the CI list */
        } else if (strcmp(argv[i], "--seed") == 0 && i + 1 < argc) {
            only = strtoull(argv[++i], NULL, 10);
        }
    }
    static const char *files[] = {"conference_geom.obj.gz", "bart_kitchen.tar.gz", "cornell_box/cornell_box.obj", "cornell_original/CornellBox-Original.obj",
                                  "stanford_bunny_bun_zipper.ply.gz", "spd_rings_s5.nff.gz"};
    for (size_t f = 0; f < sizeof files / sizeof files[0]; f++) {
        world w;
        if (!load_world(files[f], files[f], &w)) {
            CHECKF(0, "%s loads", files[f]);
            continue;
        }
        if (!only) check_mlrt_entries(&w);
        /* every ISA's kernels: the best with all the cameras, the others with a quarter */
        static const int isas[] = {16, 8, 4, 1};
        for (size_t ii = 0; ii < sizeof isas / sizeof isas[0]; ii++) {
            if (isas[ii] > sys_cpu_simd_width()) continue;
            int n_cams = isas[ii] == sys_cpu_simd_width() ? cameras : cameras / 4;
            rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1, .isa = isas[ii]});
            rp_scene *scene = make_scene(dev, &w.sd);
            stats st = {0};
            for (int c = 0; c < n_cams; c++) {
                uint64_t seed = ((uint64_t)f << 40) + first + (uint64_t)c;
                if (only && seed != only) continue;
                check_camera(dev, scene, scene, &w, seed, false, &st);
            }
            printf("%-40s %2d-wide %5llu cameras, %8llu rays, %6llu primary hits, %llu wrong answers\n", files[f],
                   isas[ii], (unsigned long long)st.cameras, (unsigned long long)st.rays, (unsigned long long)st.hits,
                   (unsigned long long)st.bad);
            /* the cameras must see the scene, or the test tests nothing */
            if (!only)
                CHECKF(st.hits > st.rays / 200, "%s: too few primary hits (%llu)", files[f], (unsigned long long)st.hits);
            rp_scene_release(scene);
            rp_device_release(dev);
        }
        /* the BIH's packets against the BVH's single rays */
        {
            rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
            rp_scene *ref = make_scene(dev, &w.sd), *scene = make_scene_accel(dev, &w.sd, RP_ACCEL_BIH);
            stats st = {0};
            for (int c = 0; c < cameras / 2; c++) {
                uint64_t seed = ((uint64_t)f << 40) + first + (uint64_t)c;
                if (only && seed != only) continue;
                check_camera(dev, ref, scene, &w, seed, true, &st);
            }
            printf("%-40s bih     %5llu cameras, %8llu rays, %6llu primary hits, %llu wrong answers\n", files[f],
                   (unsigned long long)st.cameras, (unsigned long long)st.rays, (unsigned long long)st.hits,
                   (unsigned long long)st.bad);
            if (!only)
                CHECKF(st.hits > st.rays / 200, "%s bih: too few primary hits (%llu)", files[f], (unsigned long long)st.hits);
            rp_scene_release(scene);
            rp_scene_release(ref);
            rp_device_release(dev);
        }
        rp_scene_data_free(&w.sd);
    }
    return RP_TEST_END();
}
