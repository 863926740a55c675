/* The query calls: argument checks at the boundary, then the device's kernels. */
#include <string.h>

#include "core/core.h"

/* A query needs a committed scene; anything else is an error, and the rays are left alone. */
static inline bool query_ok(rp_scene *scene, const void *rays, const char *fn) {
    if (RP_UNLIKELY(!scene)) return false;
    if (RP_UNLIKELY(!rays)) {
        device_error(scene->device, RP_ERROR_INVALID_ARGUMENT, fn);
        return false;
    }
    if (RP_UNLIKELY(!scene->committed)) {
        device_error(scene->device, RP_ERROR_NOT_COMMITTED, fn);
        return false;
    }
    return true;
}

static inline bool usable1(const rp_ray *r) {
    return ray_usable(r->org_x, r->org_y, r->org_z, r->dir_x, r->dir_y, r->dir_z, r->tnear, r->tfar);
}

/* The live lanes of a packet that can be traced (ray_usable); false when there is none. */
#define USABLE_LANES(W, valid, r, out)                                                                  \
    ({                                                                                                 \
        bool any_ = false;                                                                             \
        for (int i_ = 0; i_ < (W); i_++) {                                                             \
            bool u_ = (!(valid) || (valid)[i_]) &&                                                     \
                      ray_usable((r)->org_x[i_], (r)->org_y[i_], (r)->org_z[i_], (r)->dir_x[i_],       \
                                 (r)->dir_y[i_], (r)->dir_z[i_], (r)->tnear[i_], (r)->tfar[i_]);       \
            (out)[i_] = u_ ? -1 : 0;                                                                   \
            any_ |= u_;                                                                                \
        }                                                                                              \
        any_;                                                                                          \
    })

void rp_intersect1(rp_scene *scene, rp_rayhit *rayhit) {
    if (query_ok(scene, rayhit, "rp_intersect1") && usable1(&rayhit->ray))
        scene->kernels->intersect1(&scene->accel, rayhit);
}

void rp_occluded1(rp_scene *scene, rp_ray *ray) {
    if (query_ok(scene, ray, "rp_occluded1") && usable1(ray)) scene->kernels->occluded1(&scene->accel, ray);
}

void rp_intersect4(rp_scene *scene, const int32_t *valid, rp_rayhit4 *rayhit) {
    RP_ALIGN(64) int32_t live[4];
    if (query_ok(scene, rayhit, "rp_intersect4") && USABLE_LANES(4, valid, &rayhit->ray, live))
        scene->kernels->intersect4(&scene->accel, live, rayhit);
}

void rp_intersect8(rp_scene *scene, const int32_t *valid, rp_rayhit8 *rayhit) {
    RP_ALIGN(64) int32_t live[8];
    if (query_ok(scene, rayhit, "rp_intersect8") && USABLE_LANES(8, valid, &rayhit->ray, live))
        scene->kernels->intersect8(&scene->accel, live, rayhit);
}

void rp_intersect16(rp_scene *scene, const int32_t *valid, rp_rayhit16 *rayhit) {
    RP_ALIGN(64) int32_t live[16];
    if (query_ok(scene, rayhit, "rp_intersect16") && USABLE_LANES(16, valid, &rayhit->ray, live))
        scene->kernels->intersect16(&scene->accel, live, rayhit);
}

void rp_occluded4(rp_scene *scene, const int32_t *valid, rp_ray4 *ray) {
    RP_ALIGN(64) int32_t live[4];
    if (query_ok(scene, ray, "rp_occluded4") && USABLE_LANES(4, valid, ray, live))
        scene->kernels->occluded4(&scene->accel, live, ray);
}

void rp_occluded8(rp_scene *scene, const int32_t *valid, rp_ray8 *ray) {
    RP_ALIGN(64) int32_t live[8];
    if (query_ok(scene, ray, "rp_occluded8") && USABLE_LANES(8, valid, ray, live))
        scene->kernels->occluded8(&scene->accel, live, ray);
}

void rp_occluded16(rp_scene *scene, const int32_t *valid, rp_ray16 *ray) {
    RP_ALIGN(64) int32_t live[16];
    if (query_ok(scene, ray, "rp_occluded16") && USABLE_LANES(16, valid, ray, live))
        scene->kernels->occluded16(&scene->accel, live, ray);
}

/* Copies up to 16 rays of an array into a packet (SoA); returns the valid mask. */
static void pack16(const rp_ray *src, size_t stride, size_t n, rp_ray16 *p, int32_t valid[16]) {
    for (size_t i = 0; i < 16; i++) {
        if (i >= n) {
            valid[i] = 0;
            p->tnear[i] = 1.0f, p->tfar[i] = 0.0f;
            continue;
        }
        const rp_ray *r = (const rp_ray *)((const char *)src + i * stride);
        valid[i] = usable1(r) ? -1 : 0;
        p->org_x[i] = r->org_x, p->org_y[i] = r->org_y, p->org_z[i] = r->org_z, p->tnear[i] = r->tnear;
        p->dir_x[i] = r->dir_x, p->dir_y[i] = r->dir_y, p->dir_z[i] = r->dir_z, p->time[i] = r->time;
        p->tfar[i] = r->tfar, p->mask[i] = r->mask, p->id[i] = r->id, p->flags[i] = r->flags;
    }
}

void rp_intersect_array(rp_scene *scene, rp_rayhit *rayhits, size_t count, uint32_t flags) {
    if (count == 0 || !query_ok(scene, rayhits, "rp_intersect_array")) return;
    const rp_kernels *k = scene->kernels;
    if (!(flags & RP_QUERY_COHERENT)) {
        for (size_t i = 0; i < count; i++)
            if (usable1(&rayhits[i].ray)) k->intersect1(&scene->accel, &rayhits[i]);
        return;
    }
    for (size_t base = 0; base < count; base += 16) {
        size_t n = count - base < 16 ? count - base : 16;
        rp_rayhit16 p;
        int32_t valid[16];
        pack16(&rayhits[base].ray, sizeof(rp_rayhit), n, &p.ray, valid);
        for (int i = 0; i < 16; i++) p.hit.geom_id[i] = RP_INVALID_ID;
        k->intersect16(&scene->accel, valid, &p);
        for (size_t i = 0; i < n; i++) {
            if (p.hit.geom_id[i] == RP_INVALID_ID) continue;
            rp_rayhit *r = &rayhits[base + i];
            r->ray.tfar = p.ray.tfar[i];
            r->hit.Ng_x = p.hit.Ng_x[i], r->hit.Ng_y = p.hit.Ng_y[i], r->hit.Ng_z = p.hit.Ng_z[i];
            r->hit.u = p.hit.u[i], r->hit.v = p.hit.v[i];
            r->hit.prim_id = p.hit.prim_id[i], r->hit.geom_id = p.hit.geom_id[i], r->hit.inst_id = p.hit.inst_id[i];
        }
    }
}

void rp_occluded_array(rp_scene *scene, rp_ray *rays, size_t count, uint32_t flags) {
    if (count == 0 || !query_ok(scene, rays, "rp_occluded_array")) return;
    const rp_kernels *k = scene->kernels;
    if (!(flags & RP_QUERY_COHERENT)) {
        for (size_t i = 0; i < count; i++)
            if (usable1(&rays[i])) k->occluded1(&scene->accel, &rays[i]);
        return;
    }
    for (size_t base = 0; base < count; base += 16) {
        size_t n = count - base < 16 ? count - base : 16;
        rp_ray16 p;
        int32_t valid[16];
        pack16(&rays[base], sizeof(rp_ray), n, &p, valid);
        k->occluded16(&scene->accel, valid, &p);
        for (size_t i = 0; i < n; i++) rays[base + i].tfar = p.tfar[i];
    }
}
