/* Large ray packets (Overbeck, Ramamoorthi, Mark 2008): argument checks, the frustum, the choice
 * of traversal, then the device's packet kernels (src/traverse/packet_n.inc). */
#include <math.h>
#include <string.h>

#include "core/core.h"
#include "simd/simd.h"
#include "traverse/packet_n.h"

rp_query_n_desc rp_query_n_desc_defaults(const rp_query_n_desc *desc) {
    rp_query_n_desc d = desc ? *desc : (rp_query_n_desc){0};
    return d; /* every zero field is already its default: auto, no frustum, no counters */
}

uint32_t rp_packet_n_index(uint32_t n, uint32_t x, uint32_t y) {
    /* 4x4 tiles in row order; inside a tile, 2x2 quads in row order; inside a quad, row order */
    uint32_t tile = (y >> 2) * (n >> 2) + (x >> 2);
    uint32_t quad = ((y >> 1) & 1) * 2 + ((x >> 1) & 1);
    return tile * 16 + quad * 4 + (y & 1) * 2 + (x & 1);
}

static bool n_ok(uint32_t n) { return n >= 4 && n <= RP_PACKET_N_MAX && n % 4 == 0; }

/* Float arrays of a packet, in order: org xyz, tnear, dir xyz, tfar, Ng xyz, u, v; then the
 * uint32_t arrays prim_id, geom_id, inst_id. */
#define PACKET_ARRAYS 16

bool rp_rayhit_n_alloc(rp_device *device, uint32_t n, rp_rayhit_n *out) {
    if (!out) return false;
    memset(out, 0, sizeof *out);
    if (!device) return false;
    if (!n_ok(n)) {
        device_error(device, RP_ERROR_INVALID_ARGUMENT, "rp_rayhit_n_alloc: n must be a multiple of 4 in 4..32");
        return false;
    }
    size_t each = (size_t)n * n * 4; /* a multiple of 64 bytes */
    char *mem = sys_alloc(&device->alloc, each * PACKET_ARRAYS);
    if (!mem) {
        device_error(device, RP_ERROR_OUT_OF_MEMORY, "rp_rayhit_n_alloc");
        return false;
    }
    float **f[13] = {&out->org_x, &out->org_y, &out->org_z, &out->tnear, &out->dir_x, &out->dir_y, &out->dir_z,
                     &out->tfar, &out->Ng_x, &out->Ng_y, &out->Ng_z, &out->u, &out->v};
    for (int i = 0; i < 13; i++) *f[i] = (float *)(void *)(mem + (size_t)i * each);
    out->prim_id = (uint32_t *)(void *)(mem + 13 * each);
    out->geom_id = (uint32_t *)(void *)(mem + 14 * each);
    out->inst_id = (uint32_t *)(void *)(mem + 15 * each);
    out->n = n;
    return true;
}

void rp_rayhit_n_free(rp_device *device, rp_rayhit_n *packet) {
    if (!device || !packet || !packet->org_x) return;
    size_t each = (size_t)packet->n * packet->n * 4;
    sys_free(&device->alloc, packet->org_x, each * PACKET_ARRAYS);
    memset(packet, 0, sizeof *packet);
}

void rp_counters_n_add(rp_counters_n *dst, const rp_counters_n *src) {
    if (!dst || !src) return;
    const uint64_t *s = (const uint64_t *)src;
    uint64_t *d = (uint64_t *)dst;
    for (size_t i = 0; i < sizeof *dst / sizeof(uint64_t); i++) d[i] += s[i];
}

static const rp_kernels_n *kernels_n(const rp_device *device) {
    switch (device->kernels->isa) {
    case 16: return &rp_kernels_n_avx512;
    case 8: return &rp_kernels_n_avx2;
    case 4: return &rp_kernels_n_sse;
    default: return &rp_kernels_n_scalar;
    }
}

static bool packet_ok(rp_scene *scene, const rp_rayhit_n *p, bool hits, const char *fn) {
    if (!scene) return false;
    if (!p || !n_ok(p->n) || !p->org_x || !p->org_y || !p->org_z || !p->tnear || !p->dir_x || !p->dir_y ||
        !p->dir_z || !p->tfar ||
        (hits && (!p->Ng_x || !p->Ng_y || !p->Ng_z || !p->u || !p->v || !p->prim_id || !p->geom_id || !p->inst_id))) {
        device_error(scene->device, RP_ERROR_INVALID_ARGUMENT, fn);
        return false;
    }
    if (!scene->committed) {
        device_error(scene->device, RP_ERROR_NOT_COMMITTED, fn);
        return false;
    }
    return true;
}

static bool live(const rp_rayhit_n *p, uint32_t i) {
    return (!p->valid || p->valid[i]) && p->tnear[i] <= p->tfar[i];
}

/* The packets' per-ray loops below (slab tests against instance boxes, the rays mapped into an
 * instance, inverse directions, live tnear, merges of occlusion, ray_usable's lanes): each an
 * always-inlined body (NAME_body) compiled twice, for the baseline and for AVX2, and NAME(avx2, ...)
 * runs the copy its first argument names (ray_avx2: the CPU has AVX2 and the device's kernels are
 * 8 or 16 wide, so --isa sse and scalar run the baseline copy, as the render library's loops do,
 * render.h). Without FMA both copies make the same IEEE operations in the same order, so they give
 * the same values (test_isa_images compares them). (GCC's target_clones made such copies through an
 * ifunc, whose resolver runs before ThreadSanitizer's runtime is up: every TSan binary crashed at
 * load.) */
#define RAY_BODY static inline __attribute__((always_inline))
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define RAY_COPIES(T, name, params, args)                                                                 \
    static T name##_base params { return name##_body args; }                                              \
    __attribute__((target("avx2"))) static T name##_avx2 params { return name##_body args; }              \
    static inline T name(bool avx2, RAY_UNPAREN params) { return avx2 ? name##_avx2 args : name##_base args; }
#define RAY_COPIES_VOID(name, params, args)                                                               \
    static void name##_base params { name##_body args; }                                                  \
    __attribute__((target("avx2"))) static void name##_avx2 params { name##_body args; }                  \
    static inline void name(bool avx2, RAY_UNPAREN params) {                                              \
        if (avx2) name##_avx2 args;                                                                       \
        else name##_base args;                                                                            \
    }
static bool ray_avx2(const rp_scene *scene) {
    return scene->device->kernels->isa >= 8 && __builtin_cpu_supports("avx2");
}
#else
#define RAY_COPIES(T, name, params, args)                                                                 \
    static inline T name(bool avx2, RAY_UNPAREN params) { (void)avx2; return name##_body args; }
#define RAY_COPIES_VOID(name, params, args)                                                               \
    static inline void name(bool avx2, RAY_UNPAREN params) { (void)avx2; name##_body args; }
static bool ray_avx2(const rp_scene *scene) {
    (void)scene;
    return false;
}
#endif
#define RAY_UNPAREN(...) __VA_ARGS__ /* RAY_UNPAREN (a, b): a, b */

/* A packet's rays as SIMD rays of the kernels' width W, W at a time (count is a multiple of 16): each
 * group filled straight into the W-wide layout (an earlier version filled a 16-wide one and copied
 * all its fields into the narrow one and back, a fifth of this function's instructions), and for
 * occlusion only tfar read back. */
#define TRACE_SIMD_DEFINE(W)                                                                                 \
    static void trace_simd_##W(const rp_kernels *k, const rp_accel *acc, rp_rayhit_n *p, uint32_t count,   \
                               bool any) {                                                                 \
        for (uint32_t base = 0; base < count; base += W) {                                                 \
            rp_rayhit##W s;                                                                                \
            int32_t valid[W];                                                                              \
            memcpy(s.ray.org_x, p->org_x + base, sizeof s.ray.org_x);                                      \
            memcpy(s.ray.org_y, p->org_y + base, sizeof s.ray.org_y);                                      \
            memcpy(s.ray.org_z, p->org_z + base, sizeof s.ray.org_z);                                      \
            memcpy(s.ray.dir_x, p->dir_x + base, sizeof s.ray.dir_x);                                      \
            memcpy(s.ray.dir_y, p->dir_y + base, sizeof s.ray.dir_y);                                      \
            memcpy(s.ray.dir_z, p->dir_z + base, sizeof s.ray.dir_z);                                      \
            memcpy(s.ray.tnear, p->tnear + base, sizeof s.ray.tnear);                                      \
            memcpy(s.ray.tfar, p->tfar + base, sizeof s.ray.tfar);                                         \
            int32_t any_live = 0;                                                                          \
            for (int j = 0; j < W; j++) { /* live(), branch free */                                        \
                int32_t on = (p->valid ? p->valid[base + (uint32_t)j] != 0 : 1) & (s.ray.tnear[j] <= s.ray.tfar[j]); \
                valid[j] = -on;                                                                            \
                any_live |= on;                                                                            \
            }                                                                                              \
            if (!any_live) continue;                                                                       \
            for (int j = 0; j < W; j++) {                                                                  \
                s.ray.time[j] = 0.0f, s.ray.id[j] = 0, s.ray.flags[j] = 0;                                 \
                s.ray.mask[j] = p->mask ? p->mask[base + (uint32_t)j] : 0xFFFFFFFFu;                       \
                s.hit.geom_id[j] = RP_INVALID_ID;                                                          \
            }                                                                                              \
            if (any) {                                                                                     \
                k->occluded##W(acc, valid, &s.ray);                                                        \
                for (int j = 0; j < W; j++) /* the live rays' tfar (-inf where occluded), branch free */   \
                    p->tfar[base + (uint32_t)j] = valid[j] ? s.ray.tfar[j] : p->tfar[base + (uint32_t)j];   \
                continue;                                                                                  \
            }                                                                                              \
            k->intersect##W(acc, valid, &s);                                                               \
            for (int j = 0; j < W; j++) {                                                                  \
                uint32_t q = base + (uint32_t)j;                                                           \
                if (!valid[j] || s.hit.geom_id[j] == RP_INVALID_ID) continue;                              \
                p->tfar[q] = s.ray.tfar[j];                                                                \
                p->u[q] = s.hit.u[j], p->v[q] = s.hit.v[j];                                                \
                p->Ng_x[q] = s.hit.Ng_x[j], p->Ng_y[q] = s.hit.Ng_y[j], p->Ng_z[q] = s.hit.Ng_z[j];        \
                p->geom_id[q] = s.hit.geom_id[j], p->prim_id[q] = s.hit.prim_id[j];                        \
                p->inst_id[q] = s.hit.inst_id[j];                                                          \
            }                                                                                              \
        }                                                                                                  \
    }
TRACE_SIMD_DEFINE(4)
TRACE_SIMD_DEFINE(8)
TRACE_SIMD_DEFINE(16)
#undef TRACE_SIMD_DEFINE

/* RP_TRAVERSAL_SINGLE and RP_TRAVERSAL_SIMD: the rays without the large packet. */
static void trace_small(rp_scene *scene, rp_traversal mode, rp_rayhit_n *p, bool any) {
    const rp_kernels *k = scene->kernels;
    const rp_accel *acc = &scene->accel;
    uint32_t count = p->n * p->n;
    if (mode == RP_TRAVERSAL_SINGLE) {
        for (uint32_t q = 0; q < count; q++) {
            if (!live(p, q)) continue;
            rp_rayhit one;
            memset(&one, 0, sizeof one);
            one.ray.org_x = p->org_x[q], one.ray.org_y = p->org_y[q], one.ray.org_z = p->org_z[q];
            one.ray.dir_x = p->dir_x[q], one.ray.dir_y = p->dir_y[q], one.ray.dir_z = p->dir_z[q];
            one.ray.tnear = p->tnear[q], one.ray.tfar = p->tfar[q];
            one.ray.mask = p->mask ? p->mask[q] : 0xFFFFFFFFu;
            one.hit.geom_id = RP_INVALID_ID;
            if (any) {
                k->occluded1(acc, &one.ray);
                p->tfar[q] = one.ray.tfar;
                continue;
            }
            k->intersect1(acc, &one);
            if (one.hit.geom_id == RP_INVALID_ID) continue;
            p->tfar[q] = one.ray.tfar;
            p->u[q] = one.hit.u, p->v[q] = one.hit.v;
            p->Ng_x[q] = one.hit.Ng_x, p->Ng_y[q] = one.hit.Ng_y, p->Ng_z[q] = one.hit.Ng_z;
            p->geom_id[q] = one.hit.geom_id, p->prim_id[q] = one.hit.prim_id, p->inst_id[q] = one.hit.inst_id;
        }
        return;
    }
    if (k->isa >= 16) trace_simd_16(k, acc, p, count, any);
    else if (k->isa >= 8) trace_simd_8(k, acc, p, count, any);
    else trace_simd_4(k, acc, p, count, any);
}

/* Adds a packet of class c with `rays` live rays that took `ticks` by way `way`. */
static void tally_add(rp_auto_tally *t, int c, int way, uint64_t rays, uint64_t ticks) {
    uint64_t *n = &t->packets[c][way], *r = &t->rays[c][way], *sum = &t->ticks[c][way];
    if (*n >= TALLY_WARM) {
        double cap = TALLY_CAP * (double)*sum / (double)*r * (double)rays;
        if ((double)ticks > cap) ticks = (uint64_t)cap;
    }
    t->seen[c]++;
    (*n)++;
    *r += rays;
    *sum += ticks;
    if (*n >= 2 * TALLY_WINDOW) {
        *n /= 2;
        *r /= 2;
        *sum /= 2;
    }
}

static void trace_usable(rp_scene *scene, const rp_query_n_desc *desc, rp_rayhit_n *p, bool any);


static inline float fmin2(float a, float b) { return a < b ? a : b; }
static inline float fmax2(float a, float b) { return a > b ? a : b; }

/* Instances in one scene at most for trace_instances (an animated scene's top level holds a few). */
#define FANOUT_MAX_INSTANCES 64

/* A scene of nothing but instances (an animated scene's top level): the prim BVH over them would
 * take the packet's rays one by one into the instanced scenes. */
static bool instances_only(const rp_scene *s) {
    if (s->stats.triangles || s->stats.spheres || s->geom_count == 0 || s->geom_count > FANOUT_MAX_INSTANCES)
        return false;
    for (uint32_t i = 0; i < s->geom_count; i++)
        if (s->geoms[i] && (s->geoms[i]->type != RP_GEOMETRY_INSTANCE || !s->geoms[i]->inst)) return false;
    return true;
}

/* Which rays of a packet meet an instance's box (lower xyz, upper xyz): slab tests, branch free
 * (rays not live start at tn0 = +inf, occluded ones end at tfar = -inf). Returns how many do. The
 * loop vectorizes in both copies, whose restrict parameters tell the compiler the arrays are apart;
 * inlined into trace_instances, as it once was, GCC left it scalar. */
RAY_BODY uint32_t instance_slabs_body(uint32_t n, const float box[6], const float *restrict ox,
                                      const float *restrict oy, const float *restrict oz, const float *restrict ix,
                                      const float *restrict iy, const float *restrict iz, const float *restrict tn0,
                                      const float *restrict tfar, int32_t *restrict valid) {
    const float l0 = box[0], l1 = box[1], l2 = box[2], h0 = box[3], h1 = box[4], h2 = box[5];
    uint32_t on_n = 0;
    for (uint32_t i = 0; i < n; i++) {
        float t0 = tn0[i], t1 = tfar[i];
        float a = (l0 - ox[i]) * ix[i], b = (h0 - ox[i]) * ix[i];
        t0 = fmax2(t0, fmin2(a, b)), t1 = fmin2(t1, fmax2(a, b));
        a = (l1 - oy[i]) * iy[i], b = (h1 - oy[i]) * iy[i];
        t0 = fmax2(t0, fmin2(a, b)), t1 = fmin2(t1, fmax2(a, b));
        a = (l2 - oz[i]) * iz[i], b = (h2 - oz[i]) * iz[i];
        t0 = fmax2(t0, fmin2(a, b)), t1 = fmin2(t1, fmax2(a, b));
        int32_t on = t0 <= t1;
        valid[i] = -on;
        on_n += (uint32_t)on;
    }
    return on_n;
}
RAY_COPIES(uint32_t, instance_slabs,
           (uint32_t n, const float box[6], const float *restrict ox, const float *restrict oy,
            const float *restrict oz, const float *restrict ix, const float *restrict iy,
            const float *restrict iz, const float *restrict tn0, const float *restrict tfar,
            int32_t *restrict valid),
           (n, box, ox, oy, oz, ix, iy, iz, tn0, tfar, valid))

/* Bounds over a packet's live rays (tn0 finite) of what instance_slabs reads: origins, inverse
 * directions, tn0 and tfar; from them one interval test per instance box can tell that no ray of
 * the packet meets it (packet_misses_box) before the rays are tested one by one. */
typedef struct {
    float olo[3], ohi[3], ilo[3], ihi[3], tn0_min, tfar_max;
} packet_bounds;

/* One pass over the lanes, four at a time (count is a multiple of 16); lanes not live (tn0 +inf)
 * count for nothing. */
static void packet_bounds_make(uint32_t count, const rp_rayhit_n *p, const float *const inv[3], const float *tn0,
                               packet_bounds *b) {
    const float *arr[7] = {p->org_x, p->org_y, p->org_z, inv[0], inv[1], inv[2], p->tfar};
    const vf4 inf = vf4_splat(INFINITY), ninf = vf4_splat(-INFINITY);
    vf4 lo[7], hi[7], tmin = inf;
    for (int k = 0; k < 7; k++) lo[k] = inf, hi[k] = ninf;
    for (uint32_t i = 0; i < count; i += 4) {
        vf4 t = vf4_load(tn0 + i);
        vi4 on = t < inf;
        tmin = vf4_min(tmin, t);
        for (int k = 0; k < 7; k++) {
            vf4 v = vf4_load(arr[k] + i);
            lo[k] = vf4_min(lo[k], vf4_select(on, v, inf));
            hi[k] = vf4_max(hi[k], vf4_select(on, v, ninf));
        }
    }
    float l[7], h[7];
    for (int k = 0; k < 7; k++) {
        l[k] = fmin2(fmin2(lo[k][0], lo[k][1]), fmin2(lo[k][2], lo[k][3]));
        h[k] = fmax2(fmax2(hi[k][0], hi[k][1]), fmax2(hi[k][2], hi[k][3]));
    }
    for (int k = 0; k < 3; k++) b->olo[k] = l[k], b->ohi[k] = h[k], b->ilo[k] = l[3 + k], b->ihi[k] = h[3 + k];
    b->tfar_max = h[6];
    b->tn0_min = fmin2(fmin2(tmin[0], tmin[1]), fmin2(tmin[2], tmin[3]));
}

/* True when no ray within the bounds b can pass instance_slabs' test against box: every ray's
 * (l - o) * inv on an axis lies between the products at the corners of [l - ohi, l - olo] x
 * [ilo, ihi] (rounding is monotone, so this holds for the float products too), so its entry is at
 * least the lowest of those and its exit at most the highest; when the latest lowest entry (or
 * tn0) is past the earliest highest exit (or tfar), every ray's test fails. NaN bounds cull
 * nothing. */
static bool packet_misses_box(const packet_bounds *b, const float box[6]) {
    float enter = b->tn0_min, leave = b->tfar_max;
    for (int k = 0; k < 3; k++) {
        float lo = INFINITY, hi = -INFINITY;
        for (int s = 0; s < 2; s++) {
            float plane = box[3 * s + k];
            float u0 = plane - b->ohi[k], u1 = plane - b->olo[k];
            float c[4] = {u0 * b->ilo[k], u0 * b->ihi[k], u1 * b->ilo[k], u1 * b->ihi[k]};
            for (int j = 0; j < 4; j++) lo = fmin2(lo, c[j]), hi = fmax2(hi, c[j]);
        }
        enter = fmax2(enter, lo), leave = fmin2(leave, hi);
    }
    return enter > leave;
}

/* tnear of the live rays (live()), +inf for the others: branch free, so that it vectorizes. */
RAY_BODY void live_tnear_body(uint32_t n, const rp_rayhit_n *p, float *restrict tn0) {
    const float *restrict tn = p->tnear, *restrict tf = p->tfar;
    const int32_t *restrict v = p->valid;
    if (v)
        for (uint32_t i = 0; i < n; i++) tn0[i] = ((v[i] != 0) & (tn[i] <= tf[i])) ? tn[i] : INFINITY;
    else
        for (uint32_t i = 0; i < n; i++) tn0[i] = tn[i] <= tf[i] ? tn[i] : INFINITY;
}
RAY_COPIES_VOID(live_tnear, (uint32_t n, const rp_rayhit_n *p, float *restrict tn0), (n, p, tn0))

/* 1 / d of n directions; a zero (or denormal) component becomes +-1e30, which never makes a NaN and
 * keeps the slab tests conservative. One array at a time, branch free, so that it vectorizes. */
RAY_BODY void inverse_dirs_body(uint32_t n, const float *restrict d, float *restrict inv) {
    for (uint32_t i = 0; i < n; i++) {
        float x = d[i];
        bool ok = fabsf(x) > 1e-30f;
        float r = 1.0f / (ok ? x : 1.0f); /* no division by zero, so no trap to keep it from vectorizing */
        inv[i] = ok ? r : copysignf(1e30f, x);
    }
}
RAY_COPIES_VOID(inverse_dirs, (uint32_t n, const float *restrict d, float *restrict inv), (n, d, inv))

/* Points (with the translation) or directions of n rays through the 3x4 map m, as instance_ray maps
 * them. */
RAY_BODY void instance_map_body(uint32_t n, const float m[12], bool points, const float *restrict x,
                                const float *restrict y, const float *restrict z, float *restrict ox,
                                float *restrict oy, float *restrict oz) {
    const float m0 = m[0], m1 = m[1], m2 = m[2], m3 = m[3], m4 = m[4], m5 = m[5], m6 = m[6], m7 = m[7], m8 = m[8],
                m9 = m[9], m10 = m[10], m11 = m[11];
    if (points) {
        for (uint32_t i = 0; i < n; i++) {
            ox[i] = m0 * x[i] + m1 * y[i] + m2 * z[i] + m3;
            oy[i] = m4 * x[i] + m5 * y[i] + m6 * z[i] + m7;
            oz[i] = m8 * x[i] + m9 * y[i] + m10 * z[i] + m11;
        }
        return;
    }
    for (uint32_t i = 0; i < n; i++) {
        ox[i] = m0 * x[i] + m1 * y[i] + m2 * z[i];
        oy[i] = m4 * x[i] + m5 * y[i] + m6 * z[i];
        oz[i] = m8 * x[i] + m9 * y[i] + m10 * z[i];
    }
}
RAY_COPIES_VOID(instance_map,
           (uint32_t n, const float m[12], bool points, const float *restrict x, const float *restrict y,
            const float *restrict z, float *restrict ox, float *restrict oy, float *restrict oz),
           (n, m, points, x, y, z, ox, oy, oz))

/* Shadow rays of a packet occluded in an instance (tfar -inf there) are occluded in the packet. */
RAY_BODY void occluded_merge_body(uint32_t n, const int32_t *restrict valid, const float *restrict qtfar,
                                  float *restrict tfar) {
    for (uint32_t i = 0; i < n; i++) {
        int32_t hit = (valid[i] != 0) & (qtfar[i] == -INFINITY); /* & rather than &&: no branch */
        tfar[i] = hit ? -INFINITY : tfar[i];
    }
}
RAY_COPIES_VOID(occluded_merge,
           (uint32_t n, const int32_t *restrict valid, const float *restrict qtfar, float *restrict tfar),
           (n, valid, qtfar, tfar))

/* The hits q found in instance gi (valid lanes whose geom_id is set) replace p's, their normals
 * mapped back by the inverse transpose of m: four lanes at a time (n is a multiple of 16), a lane
 * without a new hit getting its own values back. */
static void hits_merge(uint32_t n, const int32_t *valid, const float m[12], uint32_t gi, const rp_rayhit_n *q,
                       rp_rayhit_n *p) {
    const vf4 m0 = vf4_splat(m[0]), m1 = vf4_splat(m[1]), m2 = vf4_splat(m[2]), m4 = vf4_splat(m[4]),
              m5 = vf4_splat(m[5]), m6 = vf4_splat(m[6]), m8 = vf4_splat(m[8]), m9 = vf4_splat(m[9]),
              m10 = vf4_splat(m[10]);
    const vi4 none = vi4_splat((int32_t)RP_INVALID_ID), zero = vi4_splat(0), inst = vi4_splat((int32_t)gi);
    for (uint32_t i = 0; i < n; i += 4) {
        vi4 g = vi4_load(q->geom_id + i);
        vi4 hit = (vi4_load(valid + i) != zero) & (g != none);
        if (vi4_movemask(hit) == 0) continue;
        vf4 nx = vf4_load(q->Ng_x + i), ny = vf4_load(q->Ng_y + i), nz = vf4_load(q->Ng_z + i);
        /* the products and sums in the order of the scalar m[0] * nx + m[4] * ny + m[8] * nz */
        vf4 wx = m0 * nx + m4 * ny + m8 * nz, wy = m1 * nx + m5 * ny + m9 * nz, wz = m2 * nx + m6 * ny + m10 * nz;
        vf4_store(p->tfar + i, vf4_select(hit, vf4_load(q->tfar + i), vf4_load(p->tfar + i)));
        vf4_store(p->Ng_x + i, vf4_select(hit, wx, vf4_load(p->Ng_x + i)));
        vf4_store(p->Ng_y + i, vf4_select(hit, wy, vf4_load(p->Ng_y + i)));
        vf4_store(p->Ng_z + i, vf4_select(hit, wz, vf4_load(p->Ng_z + i)));
        vf4_store(p->u + i, vf4_select(hit, vf4_load(q->u + i), vf4_load(p->u + i)));
        vf4_store(p->v + i, vf4_select(hit, vf4_load(q->v + i), vf4_load(p->v + i)));
        vi4_store(p->geom_id + i, vi4_select(hit, g, vi4_load(p->geom_id + i)));
        vi4_store(p->prim_id + i, vi4_select(hit, vi4_load(q->prim_id + i), vi4_load(p->prim_id + i)));
        vi4_store(p->inst_id + i, vi4_select(hit, inst, vi4_load(p->inst_id + i)));
    }
}

/* The packet goes into each instance's scene in turn, mapped into its space as instance_ray maps a
 * single ray (scene.c), so the packet kernels walk the instanced scenes (their frusta cull the
 * instances it misses); a closer hit replaces a farther one, its normal mapped back by the inverse
 * transpose and inst_id the instance's geom_id (the outermost level writes last). The scratch
 * packet of a packet up to 16x16 is on the stack and each instance's box in this scene's space is
 * the one its commit made (rp_geometry.box): with a heap copy and the boxes' corners mapped per
 * packet, this took as long as the kernels on instant radiosity's 8x8 shadow packets (kitchen). */
static void trace_instances(rp_scene *scene, const rp_query_n_desc *d, rp_rayhit_n *p, bool any) {
    enum { SCRATCH = PACKET_ARRAYS + 5, STACK_RAYS = 16 * 16 };
    uint32_t count = p->n * p->n;
    size_t each = (size_t)count * 4;
    RP_ALIGN(64) char stack[SCRATCH * STACK_RAYS * 4];
    char *mem = count <= STACK_RAYS ? stack : sys_alloc(&scene->device->alloc, each * SCRATCH);
    if (!mem) { /* no memory for the copy: the rays one by one, as the prim BVH takes them */
        trace_small(scene, RP_TRAVERSAL_SINGLE, p, any);
        return;
    }
    rp_rayhit_n q = {.n = p->n};
    float **f[13] = {&q.org_x, &q.org_y, &q.org_z, &q.tnear, &q.dir_x, &q.dir_y, &q.dir_z,
                     &q.tfar, &q.Ng_x, &q.Ng_y, &q.Ng_z, &q.u, &q.v};
    for (int i = 0; i < 13; i++) *f[i] = (float *)(void *)(mem + (size_t)i * each);
    q.prim_id = (uint32_t *)(void *)(mem + 13 * each);
    q.geom_id = (uint32_t *)(void *)(mem + 14 * each);
    q.inst_id = (uint32_t *)(void *)(mem + 15 * each);
    int32_t *valid = (int32_t *)(void *)(mem + 16 * each);
    q.valid = valid;
    q.mask = p->mask;
    /* the rays' inverse directions for the slab tests and the packet's bounds, once for every
     * instance */
    float *ix = (float *)(void *)(mem + 17 * each), *iy = ix + count, *iz = iy + count, *tn0 = iz + count;
    const bool avx2 = ray_avx2(scene);
    live_tnear(avx2, count, p, tn0);
    inverse_dirs(avx2, count, p->dir_x, ix);
    inverse_dirs(avx2, count, p->dir_y, iy);
    inverse_dirs(avx2, count, p->dir_z, iz);
    const float *inv[3] = {ix, iy, iz};
    packet_bounds pb;
    packet_bounds_make(count, p, inv, tn0, &pb);
    for (uint32_t gi = 0; gi < scene->geom_count; gi++) {
        const rp_geometry *g = scene->geoms[gi];
        if (!g || g->mask == 0) continue;
        /* the instance's box (rays that miss it cannot hit inside, so they, and an instance no ray
         * reaches, are skipped) */
        if (!(g->box[0] <= g->box[3])) continue;
        /* a packet the box's interval test culls skips the rays' tests (at most one of the kitchen's
         * five car and wheel instances is met by a packet in ten) */
        if (packet_misses_box(&pb, g->box)) continue;
        const float *m = g->inv;
        uint32_t live_n =
            instance_slabs(avx2, count, g->box, p->org_x, p->org_y, p->org_z, ix, iy, iz, tn0, p->tfar, valid);
        if (!live_n) continue;
        if (p->mask)
            for (uint32_t i = 0; i < count; i++)
                if (valid[i] && (p->mask[i] & g->mask) == 0) valid[i] = 0, live_n--;
        instance_map(avx2, count, m, true, p->org_x, p->org_y, p->org_z, q.org_x, q.org_y, q.org_z);
        instance_map(avx2, count, m, false, p->dir_x, p->dir_y, p->dir_z, q.dir_x, q.dir_y, q.dir_z);
        memcpy(q.tnear, p->tnear, each);
        memcpy(q.tfar, p->tfar, each);
        if (!any) /* hits_merge reads them; occlusion reads tfar alone */
            for (uint32_t i = 0; i < count; i++) q.geom_id[i] = RP_INVALID_ID;
        rp_query_n_desc sd = *d;
        if (sd.frustum == RP_FRUSTUM_SHADOW) { /* the common end point, in the instance's space */
            float x = d->point[0], y = d->point[1], z = d->point[2];
            for (int r = 0; r < 3; r++) sd.point[r] = m[4 * r] * x + m[4 * r + 1] * y + m[4 * r + 2] * z + m[4 * r + 3];
        }
        trace_usable(g->inst, &sd, &q, any);
        if (any) occluded_merge(avx2, count, valid, q.tfar, p->tfar);
        else hits_merge(count, valid, m, gi, &q, p);
    }
    if (mem != stack) sys_free(&scene->device->alloc, mem, each * SCRATCH);
}

static void trace_n(rp_scene *scene, const rp_query_n_desc *desc, rp_rayhit_n *p, bool any) {
    rp_query_n_desc d = rp_query_n_desc_defaults(desc);
    if (d.traversal != RP_TRAVERSAL_SINGLE && instances_only(scene)) {
        trace_instances(scene, &d, p, any);
        return;
    }
    if (d.traversal == RP_TRAVERSAL_SINGLE || d.traversal == RP_TRAVERSAL_SIMD) {
        trace_small(scene, d.traversal, p, any);
        return;
    }
    /* the large-packet kernels walk the BVH; a kd-tree's or BIH's packet goes to its structure's
     * packet traversal where it has one (the BIH's), else as its SIMD rays */
    if (scene->accel.alt) {
        if (scene->kernels->trace_n) scene->kernels->trace_n(&scene->accel, p, any);
        else trace_small(scene, RP_TRAVERSAL_SIMD, p, any);
        return;
    }
    /* a packet too small for frustum tests to pay (packet_n.inc) gets none */
    rp_frustum_kind kind = p->n * p->n >= FRUSTUM_MIN_RAYS ? d.frustum : RP_FRUSTUM_NONE;
    frustum_req q;
    frustum_req_init(&q, kind, d.point, &scene->bounds);
    /* cells of 4 triangles (a measure of the scene's density; the SAH sizes the real leaves) */
    float cells = (float)scene->stats.triangles / 4.0f;
    q.auto_span = AUTO_SPAN_CELLS / sqrtf(cells > 1.0f ? cells : 1.0f);
    q.auto_simd = cells >= AUTO_SIMD_MIN_CELLS ? AUTO_SIMD_CELLS / sqrtf(cells) : INFINITY;
    pkt_alg alg = PKT_AUTO;
    switch (d.traversal) {
    case RP_TRAVERSAL_MASKED: alg = PKT_MASKED; break;
    case RP_TRAVERSAL_RANGED: alg = PKT_RANGED; break;
    case RP_TRAVERSAL_PARTITION: alg = PKT_PARTITION; break;
    case RP_TRAVERSAL_SPAN: alg = PKT_SPAN; break;
    case RP_TRAVERSAL_MLRT: alg = PKT_MLRT; break;
    case RP_TRAVERSAL_AUTO:
    case RP_TRAVERSAL_SINGLE:
    case RP_TRAVERSAL_SIMD: alg = PKT_AUTO; break;
    }
    rp_counters_n *c = d.counters;
    if (c) {
        c->packets++;
        c->rays += p->n * p->n;
    }
    const rp_kernels_n *k = kernels_n(scene->device);
    rp_auto_tally *t = alg == PKT_AUTO ? d.tally : NULL;
    q.tally = t;
    kn_result r = any ? k->occluded_n(&scene->accel, &q, alg, p, c) : k->intersect_n(&scene->accel, &q, alg, p, c);
    if (r.cls == AUTO_INCOHERENT && r.way) trace_small(scene, RP_TRAVERSAL_SIMD, p, any);
    if (t && r.cls != AUTO_COHERENT) tally_add(t, (int)r.cls, r.way, r.live, sys_ticks() - r.start);
}

/* Traces p with its unusable rays (ray_usable: NaN/Inf, zero directions, empty intervals) taken
 * out of its valid mask, so they are misses and never reach the kernels or the frustum; a packet
 * without such rays goes as it is. The mask is made in one branch-free pass the compiler
 * vectorizes (the two scalar passes it replaced cost a third as much as the 16x16 kernel itself on
 * Cornell's primary rays, and twice that with bad rays mixed in: bench --bad-rays). */
/* ray_usable lane by lane, with & and |, into live (-1 or 0); returns how many valid lanes are not
 * usable. */
RAY_BODY int32_t usable_lanes_body(uint32_t count, const rp_rayhit_n *p, const int32_t *restrict valid,
                                      int32_t *restrict live) {
    const float *restrict ox = p->org_x, *restrict oy = p->org_y, *restrict oz = p->org_z;
    const float *restrict dx = p->dir_x, *restrict dy = p->dir_y, *restrict dz = p->dir_z;
    const float *restrict tn = p->tnear, *restrict tf = p->tfar;
    int32_t bad = 0;
    for (uint32_t i = 0; i < count; i++) {
        float f = (ox[i] - ox[i]) + (oy[i] - oy[i]) + (oz[i] - oz[i]) + (dx[i] - dx[i]) + (dy[i] - dy[i]) +
                  (dz[i] - dz[i]);
        int32_t ok = (f == 0.0f) & ((dx[i] != 0.0f) | (dy[i] != 0.0f) | (dz[i] != 0.0f)) & (tn[i] <= tf[i]) &
                     (tn[i] < INFINITY);
        int32_t v = valid[i] != 0;
        live[i] = -(v & ok);
        bad += v & (ok ^ 1);
    }
    return bad;
}
RAY_COPIES(int32_t, usable_lanes,
           (uint32_t count, const rp_rayhit_n *p, const int32_t *restrict valid, int32_t *restrict live),
           (count, p, valid, live))

static void trace_usable(rp_scene *scene, const rp_query_n_desc *desc, rp_rayhit_n *p, bool any) {
    uint32_t count = p->n * p->n;
    static const int32_t all_live[RP_PACKET_N_MAX * RP_PACKET_N_MAX] = {[0 ... RP_PACKET_N_MAX * RP_PACKET_N_MAX - 1] = -1};
    const int32_t *valid = p->valid ? p->valid : all_live; /* (no branch in the loop) */
    RP_ALIGN(64) int32_t live[RP_PACKET_N_MAX * RP_PACKET_N_MAX];
    int32_t bad = usable_lanes(ray_avx2(scene), count, p, valid, live);
    if (RP_LIKELY(bad == 0)) {
        trace_n(scene, desc, p, any);
        return;
    }
    if ((uint32_t)bad == count) return;
    rp_rayhit_n q = *p; /* the same arrays, another mask */
    q.valid = live;
    trace_n(scene, desc, &q, any);
}

void rp_intersect_n(rp_scene *scene, const rp_query_n_desc *desc, rp_rayhit_n *packet) {
    if (packet_ok(scene, packet, true, "rp_intersect_n")) trace_usable(scene, desc, packet, false);
}

void rp_occluded_n(rp_scene *scene, const rp_query_n_desc *desc, rp_rayhit_n *packet) {
    if (packet_ok(scene, packet, false, "rp_occluded_n")) trace_usable(scene, desc, packet, true);
}
