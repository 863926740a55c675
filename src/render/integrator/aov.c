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

/* |cos| of the hit's geometric normal and the ray (both engines of eye light compute it so). */
static inline float eyelight_cos(float nx, float ny, float nz, float dx, float dy, float dz) {
    v3 ng = v3_normalize(v3_make(nx, ny, nz));
    float c = fabsf(v3_dot(ng, v3_make(dx, dy, dz)));
    return c <= 1.0f ? c : c > 1.0f ? 1.0f : 0.0f; /* 0: NaN from a zero-area triangle */
}

v3 eyelight_shade(const rp_rayhit *rh) {
    if (rh->hit.geom_id == RP_INVALID_ID) return v3_make(0, 0, 0);
    float c = eyelight_cos(rh->hit.Ng_x, rh->hit.Ng_y, rh->hit.Ng_z, rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z);
    return v3_make(c, c, c);
}

float rp_render_eyelight(const rp_rayhit *rayhit) { return eyelight_shade(rayhit).x; }

/* The eye light of a traced block into the tile's accumulator: the shading lane by lane in the
 * packet's order (vectorised: CMakeLists.txt compiles this file without errno and FP traps), then
 * the block's pixels row by row, each from its lane (render_frame.lane_of). */
RENDER_INLINE void eyelight_store_body(const render_frame *f, render_thread *th, const rp_rayhit_n *p, int bx,
                                       int by, int x0, int y0, int tw, int tile_h) {
    uint32_t n = (uint32_t)f->desc.packet;
    float c[RENDER_LANES_MAX];
    const float *restrict nx = p->Ng_x, *restrict ny = p->Ng_y, *restrict nz = p->Ng_z;
    const float *restrict dx = p->dir_x, *restrict dy = p->dir_y, *restrict dz = p->dir_z;
    const uint32_t *restrict g = p->geom_id;
    for (uint32_t q = 0; q < n * n; q++) {
        float v = eyelight_cos(nx[q], ny[q], nz[q], dx[q], dy[q], dz[q]);
        c[q] = g[q] == RP_INVALID_ID ? 0.0f : v;
    }
    /* the live lanes (whitted_primary_rays): pixels inside the tile */
    int xe = x0 + tw - bx, ye = y0 + tile_h - by;
    uint32_t ni = xe < (int)n ? (uint32_t)xe : n, nj = ye < (int)n ? (uint32_t)ye : n;
    for (uint32_t j = 0; j < nj; j++) {
        float *restrict a = th->accum + 3 * ((by + (int)j - y0) * tw + (bx - x0));
        const uint16_t *lane = f->lane_of + j * n;
        for (uint32_t i = 0; i < ni; i++) {
            float v = c[lane[i]];
            a[3 * i + 0] += v;
            a[3 * i + 1] += v;
            a[3 * i + 2] += v;
        }
    }
}

static void eyelight_store_base(const render_frame *f, render_thread *th, const rp_rayhit_n *p, int bx, int by,
                                int x0, int y0, int tw, int tile_h) {
    eyelight_store_body(f, th, p, bx, by, x0, y0, tw, tile_h);
}

#if RENDER_X86_AVX2
__attribute__((target("avx2"))) static void eyelight_store_avx2(const render_frame *f, render_thread *th,
                                                                const rp_rayhit_n *p, int bx, int by, int x0,
                                                                int y0, int tw, int tile_h) {
    eyelight_store_body(f, th, p, bx, by, x0, y0, tw, tile_h);
}
#endif

bool eyelight_block(const render_frame *f, render_thread *th, int bx, int by, int x0, int y0, int tw, int tile_h,
                    int s) {
    whitted_level *lv = whitted_packet_level(f, th, 0);
    if (!lv) return false;
    uint64_t live = whitted_primary_rays(f, lv, bx, by, x0, y0, tw, tile_h, s);
    lv->rh.valid = lv->valid;
    rp_query_n_desc qd = whitted_packet_query(f, th, lv, RP_RAY_PRIMARY);
    alpha_intersect_n(f->s, &qd, &lv->rh);
    th->rays[RP_RAY_PRIMARY] += live;
#if RENDER_X86_AVX2
    if (f->avx2) {
        eyelight_store_avx2(f, th, &lv->rh, bx, by, x0, y0, tw, tile_h);
        return true;
    }
#endif
    eyelight_store_base(f, th, &lv->rh, bx, by, x0, y0, tw, tile_h);
    return true;
}
