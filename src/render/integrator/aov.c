/* Eye light (|cos| of the primary ray and the geometric normal) and the debug AOVs of a primary hit. */
#include "../render.h"

v3 aov_shade(const render_frame *f, const rp_ray *ray, const rp_hit *hit) {
    bool miss = hit->geom_id == RP_INVALID_ID;
    switch (f->desc.aov) {
    case RP_AOV_DEPTH:
        return v3_make(miss ? INFINITY : ray->tfar, 0, 0);
    case RP_AOV_PRIMID: {
        if (miss) return v3_make(0, 0, 0);
        rp_hit fh = *hit;
        scene_hit_flat(f->s, &fh); /* animated scenes: the same colours with and without instances */
        uint32_t h = render_hash(render_hash(fh.geom_id + 1u) ^ fh.prim_id);
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

bool eyelight_block(const render_frame *f, render_thread *th, int bx, int by, int x0, int y0, int tw, int tile_h,
                    int s) {
    const rp_render_desc *d = &f->desc;
    uint32_t n = (uint32_t)d->packet;
    whitted_level *lv = whitted_packet_level(f, th, 0);
    if (!lv) return false;
    uint64_t live = whitted_primary_rays(f, lv, bx, by, x0, y0, tw, tile_h, s);
    lv->rh.valid = lv->valid;
    rp_query_n_desc qd = whitted_packet_query(f, th, lv, RP_RAY_PRIMARY);
    rp_intersect_n(f->s->scene, &qd, &lv->rh);
    th->rays[RP_RAY_PRIMARY] += live;
    const rp_rayhit_n *p = &lv->rh;
    for (uint32_t j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            uint32_t q = rp_packet_n_index(n, i, j);
            if (!lv->valid[q]) continue;
            rp_rayhit rh;
            rh.ray.dir_x = p->dir_x[q];
            rh.ray.dir_y = p->dir_y[q];
            rh.ray.dir_z = p->dir_z[q];
            rh.hit.geom_id = p->geom_id[q];
            rh.hit.Ng_x = p->Ng_x[q];
            rh.hit.Ng_y = p->Ng_y[q];
            rh.hit.Ng_z = p->Ng_z[q];
            v3 c = eyelight_shade(&rh);
            int k = (by + (int)j - y0) * tw + (bx + (int)i - x0);
            th->accum[3 * k + 0] += c.x;
            th->accum[3 * k + 1] += c.y;
            th->accum[3 * k + 2] += c.z;
        }
    return true;
}
