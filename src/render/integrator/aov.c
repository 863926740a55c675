/* Eye light (|cos| of the primary ray and the geometric normal) and the debug AOVs of a primary hit. */
#include "../render.h"

v3 aov_shade(const render_frame *f, const rp_ray *ray, const rp_hit *hit) {
    bool miss = hit->geom_id == RP_INVALID_ID;
    switch (f->desc.aov) {
    case RP_AOV_DEPTH:
        return v3_make(miss ? INFINITY : ray->tfar, 0, 0);
    case RP_AOV_PRIMID: {
        if (miss) return v3_make(0, 0, 0);
        uint32_t h = render_hash(render_hash(hit->geom_id + 1u) ^ hit->prim_id);
        return v3_make((float)(h & 255u) / 255.0f, (float)((h >> 8) & 255u) / 255.0f,
                       (float)((h >> 16) & 255u) / 255.0f);
    }
    case RP_AOV_NORMAL:
    case RP_AOV_ALBEDO: {
        if (miss) return v3_make(0, 0, 0);
        render_surface sf;
        scene_surface(f->s, ray, hit, &sf);
        if (f->desc.aov == RP_AOV_NORMAL) return v3_madd(v3_make(0.5f, 0.5f, 0.5f), sf.ns_raw, 0.5f);
        return material_albedo(f->s, &f->s->materials[sf.material], &sf);
    }
    }
    return v3_make(0, 0, 0);
}

v3 eyelight_shade(const rp_rayhit *rh) {
    if (rh->hit.geom_id == RP_INVALID_ID) return v3_make(0, 0, 0);
    v3 ng = v3_normalize(v3_make(rh->hit.Ng_x, rh->hit.Ng_y, rh->hit.Ng_z));
    float c = fabsf(v3_dot(ng, v3_make(rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z)));
    if (!(c <= 1.0f)) c = c > 1.0f ? 1.0f : 0.0f; /* NaN from a zero-area triangle */
    return v3_make(c, c, c);
}
