/* Instant radiosity (Keller 1997) with interleaved sampling and the discontinuity buffer (Wald,
 * Kollig, Benthin, Keller, Slusallek 2002; the survey's sec. 4.4). Every sample of a frame traces
 * fresh light paths: N x N sets of VPLs, each from its own light paths. Every N x N block of pixels
 * gathers each set once (pixel (x, y) set (x mod N) + N (y mod N), or a shuffle of it, ir_tile); a
 * tile of (N n) x (N n) pixels thus holds n x n pixels of each set, and
 * the shadow rays from those pixels to one VPL all meet at the VPL: they are traced as one coherent
 * n x n packet with a point frustum (rp_occluded_n), the point of interleaving for a packet tracer.
 *
 * Clamping: a VPL's contribution f cos_x I(w) / d^2 is singular as d -> 0 (bright blotches near
 * VPLs); the distance is taken as at least clamp times the scene's bounding radius
 * (rp_ir_desc.clamp, default 0.02), which loses the energy of short transport paths (corners look
 * darker than in a path traced image); clamp < 0 keeps the exact, unbiased but spiky estimate.
 *
 * Discontinuity buffer: the VPL sum of each pixel divided by its diffuse albedo (so textures stay
 * sharp) is averaged over a filter x filter window, over the neighbours whose depth is within 5%
 * and whose normal is within about 25 degrees of the pixel's; the window sees the different VPL sets
 * of the neighbours and so smooths the interleaving's structured noise without blurring across
 * edges. The filter needs one surface per pixel, so a frame renders its samples one pass at a
 * time (tile.c): each pass's primary rays are spread over the pixels as the path tracer's are,
 * its image is filtered, and the frame is the mean of the filtered images. Transport: VPLs are
 * deposited on diffuse (Lambert and plastic base) surfaces; mirrors and glass do not receive VPLs,
 * and a pixel that sees one follows its delta
 * chain (one lobe per bounce, up to max_depth) to the surface that gathers. The environment and
 * directional lights give infinite VPLs (a direction and its radiance over its density) and light
 * paths that enter from a disk of the scene's bounding radius. */
#include "pbr.h"

#include <stdlib.h>
#include <string.h>

#define PI_F 3.14159265358979323846f
/* Russian roulette's threshold when rp_ir_desc.rr is 0: a lane's mean unoccluded contribution
 * over the chunk's VPLs times this (ir_roulette; docs/rendering.md has the measurements). */
#define IR_RR_DEFAULT 2.0f
/* Scenes of at least this many triangles trace the shadow packets as SIMD rays (ir_frame_init). */
#define IR_SIMD_MIN_TRIANGLES 4096
/* A VPL's shadow rays beyond its last full SIMD ray get one of their own from this many on, else
 * they join the other VPLs' rests (ir_tile). */
#ifndef IR_SIMD_REST
#define IR_SIMD_REST 8u
#endif
#define IR_NO_RAY 0xFFFFu

static float max3(v3 c) { return render_fmaxf(c.x, render_fmaxf(c.y, c.z)); }

/* The diffuse albedo of a BSDF, the part that reflects VPL light onwards. */
static v3 diffuse_albedo(const render_bsdf *b) {
    switch (b->type) {
    case BSDF_LAMBERT: return b->kd;
    case BSDF_PLASTIC: /* glTF's (schlick) base loses F(0.04) = 4% at normal incidence */
        return v3_scale(b->kd, b->schlick ? 0.96f : 1.0f - render_fminf(1.0f, max3(b->ks)));
    case BSDF_CONDUCTOR:
    case BSDF_DIELECTRIC: return v3_make(0, 0, 0);
    }
    return v3_make(0, 0, 0);
}

/* Keeps v in a uniform random subset of at most V of the VPLs seen so far (reservoir sampling). */
static void vpl_keep(ir_vpl *out, int V, int *seen, ir_vpl v, render_sampler *pick) {
    int i = (*seen)++;
    if (i < V) {
        out[i] = v;
        return;
    }
    int j = (int)(sampler_1d(pick) * (float)(i + 1)); /* uniform in [0, i] */
    if (j < V) out[j] = v;
}

/* The VPLs of one set of one sample: V light paths (Keller's N), of whose C VPLs the set keeps a
 * uniform random V, each weighted C / V, which is unbiased for any V (filling the set until it is
 * full and dividing by the paths started instead loses the deeper bounces of the path that finds it
 * full: -6% of cornell_original's indirect light at 4 VPLs a set). Random numbers come from (set,
 * path, sample) so the VPLs depend on nothing else. */
static void ir_set(const render_frame *f, uint32_t sample, uint32_t set, ir_vpl *out, uint64_t *rays) {
    const pbr_frame *pf = f->pbr;
    const rp_render_scene *s = f->s;
    int V = pf->per_set, seen = 0;
    memset(out, 0, (size_t)V * sizeof *out);
    /* max_depth counts reflections as the path tracer does, the gathering surface's included. */
    int depth = f->desc.ir.depth > 0 ? f->desc.ir.depth : f->desc.max_depth - 1;
    render_sampler pick = sampler_start(0xFFFFFFF0u - set, 0xFFFFFFFFu, sample);
    for (int path = 0; path < V; path++) {
        render_sampler rng = sampler_start(0xFFFFFFF0u - set, (uint32_t)path, sample);
        float pmf;
        uint32_t li = light_pick(&s->light_pick, sampler_1d(&rng), &pmf);
        float u[4] = {sampler_1d(&rng), sampler_1d(&rng), sampler_1d(&rng), sampler_1d(&rng)};
        const rp_light_source *l = &s->pb_lights[li];
        v3 p, n, dir, power, org;
        if (l->type == RP_LIGHT_SOURCE_ENVIRONMENT || l->type == RP_LIGHT_SOURCE_DIRECTIONAL) {
            /* Light from infinity: an infinite VPL for the direct term, and a light path entering
             * the scene from a disk of its bounding radius facing that direction. */
            light_sample ls;
            if (!light_sample_li(s, l, s->center, u[0], u[1], &ls) || !(ls.pdf > 0.0f)) continue;
            power = v3_scale(ls.L, 1.0f / (ls.pdf * pmf));
            vpl_keep(out, V, &seen, (ir_vpl){.p = ls.wi, .power = power, .infinite = true}, &pick);
            v3 t, b;
            bsdf_frame(ls.wi, &t, &b);
            float r = s->radius * sqrtf(u[2]), phi = 6.28318530718f * u[3];
            org = v3_add(v3_madd(s->center, ls.wi, 2.0f * s->radius),
                         v3_add(v3_scale(t, r * cosf(phi)), v3_scale(b, r * sinf(phi))));
            dir = v3_neg(ls.wi);
            power = v3_scale(power, PI_F * s->radius * s->radius);
        } else {
            if (!light_sample_le(s, l, u, &p, &n, &dir, &power)) continue;
            power = v3_scale(power, 1.0f / pmf);
            vpl_keep(out, V, &seen, (ir_vpl){.p = p, .n = n, .power = power}, &pick);
            org = v3_is_zero(n) ? p : v3_madd(p, n, ray_offset(s)); /* a light's point: its triangle unknown here */
        }
        for (int bounce = 0; bounce < depth; bounce++) {
            rp_rayhit rh;
            render_ray_init(&rh.ray, org, dir, INFINITY);
            rh.hit.geom_id = rh.hit.prim_id = rh.hit.inst_id = RP_INVALID_ID;
            alpha_intersect1(s, &rh);
            (*rays)++;
            if (rh.hit.geom_id == RP_INVALID_ID) break;
            render_surface sf;
            scene_surface(s, &rh.ray, &rh.hit, &sf);
            render_bsdf b = material_bsdf(s, &s->materials[sf.material], &sf);
            v3 kd = diffuse_albedo(&b);
            if (v3_is_zero(kd)) break;
            power = v3_mul(power, kd);
            vpl_keep(out, V, &seen, (ir_vpl){.p = v3_madd(sf.p, sf.ng, sf.eps), .n = sf.ns, .power = power}, &pick);
            float q = render_fminf(1.0f, max3(kd));
            if (!(sampler_1d(&rng) < q)) break;
            power = v3_scale(power, 1.0f / q);
            v3 t, bb;
            bsdf_frame(sf.ns, &t, &bb);
            dir = bsdf_to_world(bsdf_cosine_hemisphere(sampler_1d(&rng), sampler_1d(&rng)), t, bb, sf.ns);
            if (v3_dot(dir, sf.ng) <= 0.0f) break;
            org = v3_madd(sf.p, sf.ng, sf.eps);
        }
    }
    float w = (seen > V ? (float)seen / (float)V : 1.0f) / (float)V;
    for (int i = 0; i < V && i < seen; i++) out[i].power = v3_scale(out[i].power, w);
}

typedef struct ir_set_job {
    render_frame *f;
    uint64_t *rays; /* per thread */
} ir_set_job;

static void ir_set_task(void *user, uint32_t index, uint32_t thread) {
    ir_set_job *job = user;
    const pbr_frame *pf = job->f->pbr;
    uint32_t sample = index / (uint32_t)pf->sets, set = index % (uint32_t)pf->sets;
    ir_set(job->f, (uint32_t)job->f->desc.sample_start + sample, set,
           pf->vpls + (size_t)index * (size_t)pf->per_set, &job->rays[thread * 8]);
}

bool ir_frame_init(render_frame *f) {
    pbr_frame *pf = f->pbr;
    const rp_ir_desc *ir = &f->desc.ir;
    pf->interleave = ir->interleave > 0 ? ir->interleave : 5;
    pf->per_set = ir->vpls > 0 ? ir->vpls : 16;
    pf->sets = pf->interleave * pf->interleave;
    pf->side = 8;
    /* A set's 8x8 shadow rays to one VPL start 5 pixels apart: in a large scene they share few
     * nodes, and the packet kernels' per-packet work (frustum, span, partition) costs more than it
     * saves; each SIMD ray of 4x4 of them (one set, one VPL) through the wide BVH was faster
     * (bart_kitchen, 110k triangles, 0.64-0.8x the frame's CPU time, docs/rendering.md). On few
     * triangles the packet wins (cornell_original, 36: SIMD rays 1.15x). The threshold is the
     * kernels' AUTO_SIMD_MIN_CELLS (4096 triangles); --traversal overrides it. */
    pf->shadow_traversal = f->traversal[RP_RAY_SHADOW];
    if (pf->shadow_traversal == RP_TRAVERSAL_AUTO && f->s->data && f->s->data->triangle_count >= IR_SIMD_MIN_TRIANGLES)
        pf->shadow_traversal = RP_TRAVERSAL_SIMD;
    float c = ir->clamp == 0.0f ? 0.02f : ir->clamp;
    pf->clamp_d2 = c > 0.0f ? (c * f->s->radius) * (c * f->s->radius) : 0.0f;
    pf->rr = ir->rr == 0.0f ? IR_RR_DEFAULT : (ir->rr > 0.0f ? ir->rr : 0.0f);
    size_t np = (size_t)f->desc.width * (size_t)f->desc.height;
    size_t nv = (size_t)f->desc.spp * (size_t)pf->sets * (size_t)pf->per_set;
    pf->vpls = malloc(nv * sizeof *pf->vpls);
    /* The discontinuity buffer's planes, zeroed, in one block the last frame gave back. */
    size_t v3b = (np * sizeof(v3) + 63u) & ~(size_t)63u, fb = (np * sizeof(float) + 63u) & ~(size_t)63u;
    if (np > SIZE_MAX / 64u) return false;
    pf->planes = render_scratch_take(f->s, 2 * v3b + 7 * fb + np);
    if (!pf->vpls || !pf->planes) return false;
    unsigned char *at = pf->planes;
    pf->albedo = (v3 *)at;
    pf->emit = (v3 *)(at + v3b);
    for (int k = 0; k < 3; k++) {
        pf->raw[k] = (float *)(at + 2 * v3b + (size_t)k * fb);
        pf->normal[k] = (float *)(at + 2 * v3b + (size_t)(3 + k) * fb);
    }
    pf->depth = (float *)(at + 2 * v3b + 6 * fb);
    pf->valid = at + 2 * v3b + 7 * fb;
    if (f->s->pb_light_count == 0 || f->desc.max_depth <= 0) { /* max_depth 0: emission only */
        memset(pf->vpls, 0, nv * sizeof *pf->vpls);
        return true;
    }
    int nthreads = rp_device_thread_count(f->s->device);
    if (nthreads < 1) nthreads = 1;
    uint64_t *rays = calloc((size_t)nthreads * 8, sizeof *rays);
    if (!rays) return false;
    ir_set_job job = {.f = f, .rays = rays};
    rp_device_parallel_for(f->s->device, (uint32_t)(f->desc.spp * pf->sets), ir_set_task, &job);
    for (int i = 0; i < nthreads; i++) f->threads[i].rays[RP_RAY_BOUNCE] += rays[i * 8];
    free(rays);
    return true;
}

/* Contribution of VPL v at point x, before the shadow ray; false when there is none. */
static inline bool vpl_contrib(const pbr_frame *pf, const ir_point *x, const ir_vpl *v, v3 *wi_out, float *dist_out,
                               v3 *c) {
    v3 wi;
    float d2 = 1.0f, dist = INFINITY, cv = PI_F; /* an infinite VPL: no distance, no 1/pi */
    if (v->infinite) {
        wi = v->p;
    } else {
        v3 d = v3_sub(v->p, x->org);
        d2 = v3_dot(d, d);
        if (!(d2 > 0.0f)) return false;
        dist = sqrtf(d2);
        wi = v3_scale(d, 1.0f / dist);
    }
    float cx = v3_dot(wi, x->ns);
    if (cx <= 0.0f || v3_dot(wi, x->ng) <= 0.0f) return false;
    if (!v->infinite) cv = v3_is_zero(v->n) ? 0.25f : -v3_dot(v->n, wi); /* 1/(4 pi) = (1/4) / pi */
    if (!(cv > 0.0f)) return false;
    v3 fv = x->is_lambert ? x->lambert
                          : v3_mul(x->beta, bsdf_eval(&x->bsdf, x->wo, bsdf_to_local(wi, x->t, x->b, x->ns)));
    float g = v->infinite ? 1.0f : (d2 > pf->clamp_d2 ? d2 : pf->clamp_d2);
    *c = v3_scale(v3_mul(fv, v->power), cx * cv / (PI_F * g));
    if (v3_is_zero(*c)) return false;
    *wi_out = wi;
    *dist_out = v->infinite ? INFINITY : dist * (1.0f - 1e-4f);
    return true;
}

/* A set's shading points in the packet's lane order (structure of arrays), for lanes_to_vpl. */
typedef struct ir_lanes {
    float ox[64], oy[64], oz[64], nsx[64], nsy[64], nsz[64], ngx[64], ngy[64], ngz[64];
    float lr[64], lg[64], lb[64];
    int32_t lambert[64]; /* -1: a valid Lambert point, whose contribution the loop takes */
    uint32_t key[64];        /* the lane's pixel sample's hashed PCG key (Russian roulette's numbers) */
    uint16_t li[64];         /* the lane's pixel in the tile (ly T + lx) */
} ir_lanes;

RENDER_INLINE void lanes_to_vpl_(uint32_t n, const ir_lanes *restrict L, const ir_vpl *v, float clamp_d2,
                                 const bool omni, float *restrict dx_out, float *restrict dy_out,
                                 float *restrict dz_out, float *restrict tf_out, float *restrict cr,
                                 float *restrict cg, float *restrict cb, int32_t *restrict live) {
    const float px = v->p.x, py = v->p.y, pz = v->p.z, vnx = v->n.x, vny = v->n.y, vnz = v->n.z;
    const float wr = v->power.x, wg = v->power.y, wb = v->power.z;
    for (uint32_t i = 0; i < n; i++) {
        float dx = px - L->ox[i], dy = py - L->oy[i], dz = pz - L->oz[i];
        float d2 = dx * dx + dy * dy + dz * dz;
        float dist = sqrtf(d2), inv = 1.0f / dist;
        float wx = dx * inv, wy = dy * inv, wz = dz * inv;
        float cx = wx * L->nsx[i] + wy * L->nsy[i] + wz * L->nsz[i];
        float cn = wx * L->ngx[i] + wy * L->ngy[i] + wz * L->ngz[i];
        float cv = omni ? 0.25f : -(vnx * wx + vny * wy + vnz * wz);
        float g = d2 > clamp_d2 ? d2 : clamp_d2;
        float k = cx * cv / (PI_F * g);
        float r = L->lr[i] * wr * k, gg = L->lg[i] * wg * k, b = L->lb[i] * wb * k;
        int32_t on = (d2 > 0.0f) & !(cx <= 0.0f) & !(cn <= 0.0f) & (cv > 0.0f) & ((r != 0.0f) | (gg != 0.0f) | (b != 0.0f));
        live[i] = L->lambert[i] & -on;
        dx_out[i] = wx, dy_out[i] = wy, dz_out[i] = wz;
        tf_out[i] = dist * (1.0f - 1e-4f);
        cr[i] = r, cg[i] = gg, cb[i] = b;
    }
}

/* vpl_contrib for n lanes of Lambert points and a finite VPL at once, the same arithmetic in the
 * same order (so the same bits), in the compiler's vectors: each lane's shadow ray (direction,
 * tfar) and contribution go into row k of the chunk, and live says whether it has one. */
RENDER_INLINE void lanes_to_vpl(uint32_t n, const ir_lanes *L, const ir_vpl *v, float clamp_d2, ir_chunk *c, int k) {
    if (v3_is_zero(v->n))
        lanes_to_vpl_(n, L, v, clamp_d2, true, c->dx[k], c->dy[k], c->dz[k], c->tf[k], c->cr[k], c->cg[k], c->cb[k],
                      c->live[k]);
    else
        lanes_to_vpl_(n, L, v, clamp_d2, false, c->dx[k], c->dy[k], c->dz[k], c->tf[k], c->cr[k], c->cg[k], c->cb[k],
                      c->live[k]);
}

/* What Russian roulette compares: the luminance (Rec. 709 weights) of a contribution. */
static inline float ir_lum(float r, float g, float b) { return 0.2126f * r + 0.7152f * g + 0.0722f * b; }

/* Russian roulette on the chunk's shadow rays (rp_ir_desc.rr): a lane's threshold is rr times the
 * mean luminance of its unoccluded contributions over the chunk's nv VPLs; a contribution of
 * luminance l below the threshold t keeps its shadow ray with probability l / t (a number hashed
 * from the pixel sample's PCG key and the VPL's index in its set) and is then weighted t / l, else
 * it is dropped. The
 * threshold depends on the point and the VPLs only, never on visibility, so the expectation of each
 * contribution is what it was: the estimate stays unbiased and gains noise. */
RENDER_INLINE void ir_roulette(ir_chunk *c, const ir_lanes *L, uint32_t Q, int nv, int v0, float rr) {
    float thr[64];
    for (uint32_t q = 0; q < Q; q++) thr[q] = 0.0f;
    for (int k = 0; k < nv; k++)
        for (uint32_t q = 0; q < Q; q++)
            thr[q] += c->live[k][q] ? ir_lum(c->cr[k][q], c->cg[k][q], c->cb[k][q]) : 0.0f;
    float scale = rr / (float)nv;
    for (uint32_t q = 0; q < Q; q++) thr[q] *= scale;
    for (int k = 0; k < nv; k++) {
        /* the pixel sample's hashed PCG key and the dimension IR_RR_DIM + (the VPL's index in its
         * set), hashed together; branch-free, so that the loop runs in vectors */
        uint32_t hd = sampler_pcg_dim(IR_RR_DIM + (uint32_t)(v0 + k));
        for (uint32_t q = 0; q < Q; q++) {
            float l = ir_lum(c->cr[k][q], c->cg[k][q], c->cb[k][q]), t = thr[q];
            float u = (float)(int32_t)(render_hash(L->key[q] ^ hd) >> 8) * (1.0f / 16777216.0f);
            /* NaN and inf are traced as they are */
            int32_t cand = (c->live[k][q] != 0) & (l > 0.0f) & (l < t), kill = cand & !(u * t < l);
            float w = cand ? t / l : 1.0f;
            c->live[k][q] = kill ? 0 : c->live[k][q];
            c->cr[k][q] *= w, c->cg[k][q] *= w, c->cb[k][q] *= w;
        }
    }
}

RENDER_INLINE bool ir_tile_body(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1) {
    pbr_thread *pt = th->pbr;
    pbr_frame *pf = f->pbr;
    const rp_render_scene *s = f->s;
    int N = pf->interleave, P = pf->side, T = N * P, tw = x1 - x0;
    const uint32_t *lane = pt->lane;
    /* This pass's primary hits, P x P packets of neighbouring pixels, spread over each pixel like
     * the path tracer's (the box filter of DESIGN.md's radiometry contract). */
    uint32_t sample = (uint32_t)(f->desc.sample_start + f->pass);
    for (int by = 0; by < T; by += P)
        for (int bx = 0; bx < T; bx += P) {
            for (int j = 0; j < P; j++)
                for (int i = 0; i < P; i++) {
                    uint32_t q = rp_packet_n_index((uint32_t)P, (uint32_t)i, (uint32_t)j);
                    int x = x0 + bx + i, y = y0 + by + j;
                    render_sampler rng = sampler_start_pixel(f->desc.sampler, (uint32_t)x, (uint32_t)y, sample);
                    rp_ray r;
                    camera_ray(&f->cam, (float)x + sampler_at(&rng, 0), (float)y + sampler_at(&rng, 1), &r);
                    packet_set_ray(&pt->prim, q, v3_make(r.org_x, r.org_y, r.org_z), v3_make(r.dir_x, r.dir_y, r.dir_z),
                                   r.tfar);
                    pt->prim_valid[q] = x < x1 && y < y1 ? -1 : 0;
                }
            pt->prim.valid = pt->prim_valid;
            rp_query_n_desc qd = pbr_query(f, th, RP_RAY_PRIMARY);
            alpha_intersect_n(s, &qd, &pt->prim);
            rp_rayhit_n *p = &pt->prim;
            for (int j = 0; j < P; j++)
                for (int i = 0; i < P; i++) {
                    uint32_t q = rp_packet_n_index((uint32_t)P, (uint32_t)i, (uint32_t)j);
                    int lx = bx + i, ly = by + j;
                    ir_point *pt_ = &pt->points[ly * T + lx];
                    pt_->valid = false;
                    pt->ir_sum[ly * T + lx] = v3_make(0, 0, 0);
                    if (!pt->prim_valid[q]) continue;
                    th->rays[RP_RAY_PRIMARY]++;
                    size_t gi = (size_t)(y0 + ly) * (size_t)f->desc.width + (size_t)(x0 + lx);
                    pf->valid[gi] = 0;
                    pf->emit[gi] = v3_make(0, 0, 0);
                    if (p->geom_id[q] == RP_INVALID_ID) {
                        pf->emit[gi] = light_env_radiance(s, v3_make(p->dir_x[q], p->dir_y[q], p->dir_z[q]));
                        continue;
                    }
                    rp_ray ray;
                    render_ray_init(&ray, v3_make(p->org_x[q], p->org_y[q], p->org_z[q]),
                                    v3_make(p->dir_x[q], p->dir_y[q], p->dir_z[q]), p->tfar[q]);
                    rp_hit hit = {.Ng_x = p->Ng_x[q], .Ng_y = p->Ng_y[q], .Ng_z = p->Ng_z[q], .u = p->u[q],
                                  .v = p->v[q], .prim_id = p->prim_id[q], .geom_id = p->geom_id[q],
                                  .inst_id = p->inst_id[q]};
                    render_surface sf;
                    scene_surface(s, &ray, &hit, &sf);
                    material_normal_map(s, &s->materials[sf.material], &sf);
                    v3 emit = material_emission(s, sf.material, &sf), beta = v3_make(1, 1, 1);
                    render_bsdf bsdf = material_bsdf(s, &s->materials[sf.material], &sf);
                    float depth = ray.tfar;
                    bool hit_surface = true;
                    /* Mirrors and glass: follow the delta chain (one lobe per bounce, chosen from the
                     * pixel's numbers) to the diffuse surface that gathers the VPLs. */
                    render_sampler rng =
                        sampler_start_pixel(f->desc.sampler, (uint32_t)(x0 + lx), (uint32_t)(y0 + ly), sample);
                    rng.dim = 2;
                    for (int k = 0; bsdf_is_delta(&bsdf) && k < f->desc.max_depth; k++) {
                        v3 t, b;
                        bsdf_frame(sf.ns, &t, &b);
                        v3 dir = v3_make(ray.dir_x, ray.dir_y, ray.dir_z);
                        v3 wo = bsdf_to_local(v3_neg(dir), t, b, sf.ns);
                        float u[3] = {sampler_1d(&rng), sampler_1d(&rng), sampler_1d(&rng)};
                        bsdf_sample bs;
                        if (!bsdf_sample_dir(&bsdf, wo, u, &bs) || !(bs.pdf > 0.0f)) {
                            hit_surface = false;
                            break;
                        }
                        beta = v3_mul(beta, v3_scale(bs.f, fabsf(bs.wi.z) / bs.pdf));
                        v3 wi = bsdf_to_world(bs.wi, t, b, sf.ns);
                        rp_rayhit rh;
                        render_ray_init(&rh.ray, v3_madd(sf.p, sf.ng, bs.wi.z < 0.0f ? -sf.eps : sf.eps), wi, INFINITY);
                        rh.hit.geom_id = rh.hit.prim_id = rh.hit.inst_id = RP_INVALID_ID;
                        alpha_intersect1(s, &rh);
                        th->rays[bs.wi.z < 0.0f ? RP_RAY_REFRACTION : RP_RAY_REFLECTION]++;
                        if (rh.hit.geom_id == RP_INVALID_ID) {
                            emit = v3_add(emit, v3_mul(beta, light_env_radiance(s, wi)));
                            hit_surface = false;
                            break;
                        }
                        ray = rh.ray;
                        depth += rh.ray.tfar;
                        scene_surface(s, &rh.ray, &rh.hit, &sf);
                        material_normal_map(s, &s->materials[sf.material], &sf);
                        emit = v3_add(emit, v3_mul(beta, material_emission(s, sf.material, &sf)));
                        bsdf = material_bsdf(s, &s->materials[sf.material], &sf);
                    }
                    pf->emit[gi] = emit;
                    pt_->bsdf = bsdf;
                    pt_->org = v3_madd(sf.p, sf.ng, sf.eps);
                    pt_->ng = sf.ng;
                    pt_->ns = sf.ns;
                    bsdf_frame(sf.ns, &pt_->t, &pt_->b);
                    pt_->wo = bsdf_to_local(v3_neg(v3_make(ray.dir_x, ray.dir_y, ray.dir_z)), pt_->t, pt_->b, sf.ns);
                    /* Lambert points, and points whose BSDF gives one value towards every VPL
                     * (smooth plastic), take the VPLs lane by lane (lanes_to_vpl) */
                    v3 fc;
                    pt_->is_lambert = bsdf.type == BSDF_LAMBERT;
                    pt_->beta = beta;
                    pt_->lambert = v3_mul(beta, v3_scale(bsdf.kd, 1.0f / PI_F));
                    if (!pt_->is_lambert && bsdf_eval_constant(&bsdf, pt_->wo, &fc)) {
                        pt_->is_lambert = true;
                        pt_->lambert = v3_mul(beta, fc);
                    }
                    pt_->valid = hit_surface && !bsdf_is_delta(&bsdf);
                    pf->depth[gi] = depth;
                    pf->normal[0][gi] = sf.ns.x, pf->normal[1][gi] = sf.ns.y, pf->normal[2][gi] = sf.ns.z;
                    pf->albedo[gi] = v3_mul(beta, diffuse_albedo(&bsdf));
                    pf->valid[gi] = pt_->valid ? 1 : 0;
                }
        }
    /* Which pixel of each N x N block sees which set: (x mod N, y mod N) when the filter's window
     * spans a block, as in Wald et al. 2002. A narrower window (the 3x3 default under 5x5 sets)
     * would average the same sets at the same place of every block, so each set's error would
     * repeat with period N and show as a grid of dots; then every block of every sample orders
     * its sets at random (a shuffle hashed from the block and the sample), and the error is noise.
     * Blocks are the image's (tiles and regions start on them, tile.c), so the order does not
     * depend on the tiling. at[set]: the pixel in the tile, one per block, a packet lane each. */
    int rad = ir_filter_radius(&f->desc), NN = N * N;
    bool shuffle = N > 1 && 2 * rad + 1 < N;
    for (int b = 0; b < P; b++)
        for (int a = 0; a < P; a++) {
            uint16_t *at = pt->ir_at + (size_t)(b * P + a) * (size_t)NN;
            for (int k = 0; k < NN; k++) at[k] = (uint16_t)((N * b + k / N) * T + N * a + k % N);
            if (!shuffle) continue;
            uint32_t h = render_hash((uint32_t)(x0 / N + a) ^
                                     render_hash((uint32_t)(y0 / N + b) ^ render_hash(sample ^ 0x5bd1e995u)));
            for (int k = NN - 1; k > 0; k--) {
                h = render_hash(h + (uint32_t)k);
                int j = (int)(((uint64_t)h * (uint64_t)(k + 1)) >> 32);
                uint16_t t = at[k];
                at[k] = at[j], at[j] = t;
            }
        }
    /* Each set's pixels of the tile against each of its VPLs, IR_CHUNK VPLs at a time: their
     * contributions first (chunk c), then Russian roulette, then the shadow rays that are left:
     * one P x P packet per VPL with its point frustum, or, as SIMD rays (large scenes), the
     * chunk's live rays packed densely (VPL by VPL, lanes in packet order) into one packet. */
    ir_lanes lanes;
    ir_chunk *c = pt->chunk;
    const bool pack = pf->shadow_traversal == RP_TRAVERSAL_SIMD;
    const uint32_t Q = (uint32_t)(P * P);
    for (int set = 0; set < NN; set++) {
        const ir_vpl *vs = pf->vpls + ((size_t)f->pass * (size_t)pf->sets + (size_t)set) * (size_t)pf->per_set;
        /* The set's points in lane order: origins into the packet once, the rest for lanes_to_vpl. */
        ir_lanes *L = &lanes;
        rp_rayhit_n *vp = &pt->vpl_packet;
        bool slow = false; /* a lane of the set takes vpl_contrib (a valid point, not Lambert) */
        for (int b = 0; b < P; b++)
            for (int a = 0; a < P; a++) {
                uint32_t q = lane[b * P + a];
                int li = pt->ir_at[(size_t)(b * P + a) * (size_t)NN + (size_t)set], lx = li % T, ly = li / T;
                const ir_point *x = &pt->points[li];
                bool ok = lx < tw && y0 + ly < y1 && x->valid;
                v3 o = ok ? x->org : v3_make(0, 0, 0), ns = ok ? x->ns : v3_make(0, 0, 1), ng = ok ? x->ng : ns;
                v3 lam = ok ? x->lambert : v3_make(0, 0, 0);
                L->ox[q] = o.x, L->oy[q] = o.y, L->oz[q] = o.z;
                L->nsx[q] = ns.x, L->nsy[q] = ns.y, L->nsz[q] = ns.z;
                L->ngx[q] = ng.x, L->ngy[q] = ng.y, L->ngz[q] = ng.z;
                L->lr[q] = lam.x, L->lg[q] = lam.y, L->lb[q] = lam.z;
                L->lambert[q] = ok && x->is_lambert ? -1 : 0;
                slow |= ok && !x->is_lambert;
                L->key[q] = sampler_start((uint32_t)(x0 + lx), (uint32_t)(y0 + ly), sample).key;
                L->li[q] = (uint16_t)li;
                packet_set_ray(vp, q, o, v3_make(0, 0, 1), 0.0f);
            }
        for (int v0 = 0; v0 < pf->per_set; v0 += IR_CHUNK) {
            int nv = pf->per_set - v0 < IR_CHUNK ? pf->per_set - v0 : IR_CHUNK;
            uint64_t live = 0;
            for (int k = 0; k < nv; k++) {
                const ir_vpl *vl = &vs[v0 + k];
                if (v3_is_zero(vl->power)) {
                    memset(c->live[k], 0, Q * sizeof c->live[k][0]);
                    continue;
                }
                if (!vl->infinite) {
                    lanes_to_vpl(Q, L, vl, pf->clamp_d2, c, k);
                } else {
                    for (uint32_t q = 0; q < Q; q++) {
                        c->dx[k][q] = vl->p.x, c->dy[k][q] = vl->p.y, c->dz[k][q] = vl->p.z;
                        c->tf[k][q] = INFINITY, c->live[k][q] = 0;
                    }
                }
                if (!vl->infinite && !slow) { /* every lane's contribution is lanes_to_vpl's (0 where invalid) */
                    for (uint32_t q = 0; q < Q; q++) live += c->live[k][q] != 0;
                    continue;
                }
                for (uint32_t q = 0; q < Q; q++) {
                    if (!vl->infinite && L->lambert[q]) {
                        live += c->live[k][q] != 0;
                        continue;
                    }
                    /* other BSDFs and infinite VPLs: one lane at a time */
                    int li = L->li[q], lx = li % T, ly = li / T;
                    c->live[k][q] = 0;
                    const ir_point *x = &pt->points[li];
                    if (lx >= tw || y0 + ly >= y1 || !x->valid) continue;
                    v3 wi, cq;
                    float tfar;
                    if (!vpl_contrib(pf, x, vl, &wi, &tfar, &cq)) continue;
                    c->dx[k][q] = wi.x, c->dy[k][q] = wi.y, c->dz[k][q] = wi.z, c->tf[k][q] = tfar;
                    c->cr[k][q] = cq.x, c->cg[k][q] = cq.y, c->cb[k][q] = cq.z;
                    c->live[k][q] = -1;
                    live++;
                }
            }
            if (!live) continue;
            if (pf->rr > 0.0f) ir_roulette(c, L, Q, nv, v0, pf->rr);
            if (pack) {
                /* Each VPL's live rays packed into whole SIMD rays of 16, so that each of those
                 * ends at one point, which keeps it coherent for the kernels (per-ray masks);
                 * the VPLs one after the other. A VPL's last few rays (fewer than IR_SIMD_REST)
                 * would leave most of their SIMD ray's lanes idle: all VPLs' such rests go
                 * together at the end, densely, where the kernels trace them one by one. */
                rp_rayhit_n *rp = &pt->rr_packet;
                uint32_t m = 0, traced = 0, nrest = 0;
                uint16_t rest[IR_CHUNK * 16];
                for (int k = 0; k < nv; k++) {
                    /* the live lanes' indices, branch-free (each lane written at m, which only the
                     * live ones advance: at most 64 k + 63 < IR_CHUNK * 64) */
                    uint32_t m0 = m;
                    for (uint32_t q = 0; q < Q; q++) {
                        pt->rr_from[m] = (uint16_t)((uint32_t)k * 64u + q);
                        m += c->live[k][q] != 0;
                    }
                    traced += m - m0;
                    if ((m - m0) % 16u < IR_SIMD_REST)
                        for (; m % 16u; m--) rest[nrest++] = pt->rr_from[m - 1];
                    for (; m % 16u; m++) pt->rr_from[m] = IR_NO_RAY;
                }
                for (uint32_t i = 0; i < nrest; i++) pt->rr_from[m++] = rest[i];
                for (uint32_t i = 0; i < m; i++) {
                    uint32_t fr = pt->rr_from[i], k = fr / 64u, q = fr % 64u;
                    pt->rr_valid[i] = fr == IR_NO_RAY ? 0 : -1;
                    if (fr == IR_NO_RAY) continue;
                    rp->org_x[i] = L->ox[q], rp->org_y[i] = L->oy[q], rp->org_z[i] = L->oz[q];
                    rp->dir_x[i] = c->dx[k][q], rp->dir_y[i] = c->dy[k][q], rp->dir_z[i] = c->dz[k][q];
                    rp->tnear[i] = 0.0f, rp->tfar[i] = c->tf[k][q];
                }
                if (!traced) continue;
                th->rays[RP_RAY_SHADOW] += traced;
                uint32_t n = 4;
                while (n * n < m) n += 4;
                for (uint32_t i = m; i < n * n; i++) pt->rr_valid[i] = 0;
                rp->n = n;
                rp->valid = pt->rr_valid;
                rp_query_n_desc qd = pbr_query(f, th, RP_RAY_SHADOW);
                qd.traversal = RP_TRAVERSAL_SIMD;
                qd.frustum = RP_FRUSTUM_NONE;
                alpha_occluded_n(s, &qd, rp);
                for (uint32_t i = 0; i < m; i++)
                    if (pt->rr_valid[i] && rp->tfar[i] < 0.0f) c->live[pt->rr_from[i] / 64u][pt->rr_from[i] % 64u] = 0;
            } else {
                for (int k = 0; k < nv; k++) {
                    const ir_vpl *vl = &vs[v0 + k];
                    uint64_t lk = 0;
                    for (uint32_t q = 0; q < Q; q++) lk += c->live[k][q] != 0;
                    if (!lk) continue;
                    /* (Lanes that are not live hold rays of this tile's own points too, so nothing
                     * in the packet depends on what the thread traced before.) */
                    memcpy(vp->dir_x, c->dx[k], Q * sizeof(float));
                    memcpy(vp->dir_y, c->dy[k], Q * sizeof(float));
                    memcpy(vp->dir_z, c->dz[k], Q * sizeof(float));
                    memcpy(vp->tfar, c->tf[k], Q * sizeof(float));
                    th->rays[RP_RAY_SHADOW] += lk;
                    rp_query_n_desc qd = pbr_query(f, th, RP_RAY_SHADOW);
                    qd.traversal = pf->shadow_traversal;
                    if (vl->infinite) qd.frustum = RP_FRUSTUM_NONE; /* parallel rays: no common point */
                    qd.point[0] = vl->p.x;
                    qd.point[1] = vl->p.y;
                    qd.point[2] = vl->p.z;
                    vp->valid = c->live[k];
                    alpha_occluded_n(s, &qd, vp);
                    for (uint32_t q = 0; q < Q; q++)
                        if (vp->tfar[q] < 0.0f) c->live[k][q] = 0;
                }
            }
            /* the unoccluded contributions, VPL by VPL (each pixel's sum in the VPLs' order),
             * branch-free in the lanes' order, then into the pixels */
            RP_ALIGN(64) float sr[64], sg[64], sb[64];
            for (uint32_t q = 0; q < Q; q++) sr[q] = sg[q] = sb[q] = 0.0f;
            for (int k = 0; k < nv; k++)
                for (uint32_t q = 0; q < Q; q++) {
                    bool on = c->live[k][q] != 0;
                    sr[q] += on ? c->cr[k][q] : 0.0f;
                    sg[q] += on ? c->cg[k][q] : 0.0f;
                    sb[q] += on ? c->cb[k][q] : 0.0f;
                }
            for (uint32_t q = 0; q < Q; q++) {
                v3 *sum = &pt->ir_sum[L->li[q]];
                *sum = v3_add(*sum, v3_make(sr[q], sg[q], sb[q]));
            }
        }
    }
    /* The pass's buffers: the VPL sum over the albedo (or as is, where there is none). */
    for (int ly = 0; ly < y1 - y0; ly++)
        for (int lx = 0; lx < tw; lx++) {
            size_t gi = (size_t)(y0 + ly) * (size_t)f->desc.width + (size_t)(x0 + lx);
            v3 sum = pt->ir_sum[ly * T + lx], a = pf->albedo[gi];
            pf->raw[0][gi] = a.x > 0.0f ? sum.x / a.x : sum.x;
            pf->raw[1][gi] = a.y > 0.0f ? sum.y / a.y : sum.y;
            pf->raw[2][gi] = a.z > 0.0f ? sum.z / a.z : sum.z;
        }
    return true;
}

static bool ir_tile_base(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1) {
    return ir_tile_body(f, th, x0, y0, x1, y1);
}

#if RENDER_X86_AVX2
__attribute__((target("avx2"))) static bool ir_tile_avx2(const render_frame *f, render_thread *th, int x0, int y0,
                                                         int x1, int y1) {
    return ir_tile_body(f, th, x0, y0, x1, y1);
}
#endif

/* A tile's pass: its loops over lanes and VPLs in the AVX2 copy where the frame says so (the same
 * values: render.h, RENDER_X86_AVX2). */
bool ir_tile(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1) {
#if RENDER_X86_AVX2
    if (f->avx2) return ir_tile_avx2(f, th, x0, y0, x1, y1);
#endif
    return ir_tile_base(f, th, x0, y0, x1, y1);
}

typedef struct ir_filter_job {
    render_frame *f;
} ir_filter_job;

int ir_filter_radius(const rp_render_desc *d) { return d->ir.filter == 0 ? 1 : (d->ir.filter > 1 ? d->ir.filter / 2 : 0); }

/* One row of the written pixels (f->ox0..ox1 of row f->oy0 + row); its neighbours were rendered.
 * IR_FILTER_RUN pixels of the row at a time: for each neighbour offset (rows, then columns, as a
 * pixel's own loop takes them) the whole run's tests and sums lane by lane, branch free (a neighbour
 * left out adds 0 and counts 0, which changes no sum: a sum that starts at +0 never becomes -0), so
 * that the loops vectorize; each pixel's sum is made in the same order as before, so the image is
 * the same. Pixel by pixel with a branch per neighbour, the filter took 450 instructions a pixel. */
enum { IR_FILTER_RUN = 64 };

/* n pixels of a run against their neighbours at one offset: va..rz the neighbours' planes, dc..ncz
 * the pixels' own depth, depth limit and normal, sr..cnt their sums. (ivdep: the sums are the
 * stack's, the planes the frame's; without it GCC wanted more run-time alias checks than it makes,
 * and kept the loop scalar.) */
RENDER_INLINE void ir_filter_offset(int n, const uint8_t *restrict va, const float *restrict de,
                                    const float *restrict nx, const float *restrict ny, const float *restrict nz,
                                    const float *restrict rx, const float *restrict ry, const float *restrict rz,
                                    const float *restrict dc, const float *restrict lim, const float *restrict ncx,
                                    const float *restrict ncy, const float *restrict ncz, float *restrict sr,
                                    float *restrict sg, float *restrict sb, float *restrict cnt) {
#pragma GCC ivdep
    for (int i = 0; i < n; i++) {
        const float dot = nx[i] * ncx[i] + ny[i] * ncy[i] + nz[i] * ncz[i];
        const bool ok = (va[i] != 0) & !(fabsf(de[i] - dc[i]) > lim[i]) & !(dot < 0.9f);
        sr[i] += ok ? rx[i] : 0.0f;
        sg[i] += ok ? ry[i] : 0.0f;
        sb[i] += ok ? rz[i] : 0.0f;
        cnt[i] += ok ? 1.0f : 0.0f;
    }
}

RENDER_INLINE void ir_filter_row_body(const render_frame *f, uint32_t row) {
    const pbr_frame *pf = f->pbr;
    const int W = f->desc.width, H = f->desc.height, r = ir_filter_radius(&f->desc);
    const int y = f->oy0 + (int)row;
    const uint8_t *valid = pf->valid;
    const float *depth = pf->depth;
    for (int x0 = f->ox0; x0 < f->ox1; x0 += IR_FILTER_RUN) {
        const int m = f->ox1 - x0 < IR_FILTER_RUN ? f->ox1 - x0 : IR_FILTER_RUN;
        const size_t g0 = (size_t)y * (size_t)W + (size_t)x0;
        float sr[IR_FILTER_RUN], sg[IR_FILTER_RUN], sb[IR_FILTER_RUN], cnt[IR_FILTER_RUN];
        float dc[IR_FILTER_RUN], lim[IR_FILTER_RUN], ncx[IR_FILTER_RUN], ncy[IR_FILTER_RUN], ncz[IR_FILTER_RUN];
        for (int i = 0; i < m; i++) {
            dc[i] = depth[g0 + (size_t)i], lim[i] = 0.05f * dc[i];
            ncx[i] = pf->normal[0][g0 + (size_t)i], ncy[i] = pf->normal[1][g0 + (size_t)i];
            ncz[i] = pf->normal[2][g0 + (size_t)i];
            sr[i] = sg[i] = sb[i] = cnt[i] = 0.0f;
        }
        for (int dy = -r; dy <= r; dy++) {
            const int yy = y + dy;
            if (yy < 0 || yy >= H) continue;
            for (int dx = -r; dx <= r; dx++) {
                /* the run's pixels i in [lo, hi) whose neighbour x0 + i + dx lies in [0, W) */
                const int lo = -dx - x0 > 0 ? -dx - x0 : 0, hi = W - dx - x0 < m ? W - dx - x0 : m;
                if (lo >= hi) continue;
                const size_t gl = (size_t)((ptrdiff_t)yy * W + x0 + dx + lo); /* neighbour of pixel lo */
                ir_filter_offset(hi - lo, valid + gl, depth + gl, pf->normal[0] + gl, pf->normal[1] + gl,
                                 pf->normal[2] + gl, pf->raw[0] + gl, pf->raw[1] + gl, pf->raw[2] + gl, dc + lo,
                                 lim + lo, ncx + lo, ncy + lo, ncz + lo, sr + lo, sg + lo, sb + lo, cnt + lo);
            }
        }
        for (int i = 0; i < m; i++) {
            const size_t gi = g0 + (size_t)i;
            v3 out = pf->emit[gi];
            if (valid[gi]) {
                v3 e = v3_scale(v3_make(sr[i], sg[i], sb[i]), 1.0f / cnt[i]), a = pf->albedo[gi];
                out = v3_add(out, v3_make(a.x > 0.0f ? e.x * a.x : e.x, a.y > 0.0f ? e.y * a.y : e.y,
                                          a.z > 0.0f ? e.z * a.z : e.z));
            }
            /* The frame is the mean of its samples' filtered images. */
            float *px = f->pixels + gi * 3;
            if (f->desc.spp > 1) out = v3_scale(out, 1.0f / (float)f->desc.spp);
            if (f->pass > 0) out = v3_add(out, v3_make(px[0], px[1], px[2]));
            px[0] = out.x;
            px[1] = out.y;
            px[2] = out.z;
        }
    }
}

static void ir_filter_row_base(const render_frame *f, uint32_t row) { ir_filter_row_body(f, row); }
#if RENDER_X86_AVX2
__attribute__((target("avx2"))) static void ir_filter_row_avx2(const render_frame *f, uint32_t row) {
    ir_filter_row_body(f, row);
}
#endif

static void ir_filter_row(void *user, uint32_t row, uint32_t thread) {
    (void)thread;
    const render_frame *f = ((ir_filter_job *)user)->f;
#if RENDER_X86_AVX2
    if (f->avx2) {
        ir_filter_row_avx2(f, row);
        return;
    }
#endif
    ir_filter_row_base(f, row);
}

void ir_frame_finish(render_frame *f) {
    ir_filter_job job = {.f = f};
    rp_device_parallel_for(f->s->device, (uint32_t)(f->oy1 - f->oy0), ir_filter_row, &job);
}
