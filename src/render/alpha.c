/* Alpha cutouts (alpha-tested geometry: leaves, fences, grilles as textured quads). The core stays
 * material-agnostic, as Embree's does; the rendering layer's queries go through these wrappers,
 * which, in scenes with at least one alpha-tested material (rp_render_scene.cutouts, set once at
 * scene setup), fix up the core's answers afterwards:
 *   - closest hit: a hit on a cut-out point is passed through: the ray is traced on alone from
 *     just past it (tnear the next float above the hit's t: the kernels take hits in [tnear, tfar),
 *     so the surface just passed is not found again) until an opaque hit or a miss;
 *   - occlusion: an occluded ray is traced again for its closest opaque hit over its segment, and
 *     is unoccluded where only cut-out surfaces lie on it.
 * A ray passes at most ALPHA_LAYERS cut-out surfaces; one that finds more is taken as a miss (never
 * as a hit on a cut-out point, which shading must not see). Scenes without cutouts call the core
 * directly, at no cost. MASK cuts where alpha < cutoff; BLEND where alpha is below a hash of the
 * ray and of the hit's distance (pbrt-v4's stochastic alpha test), so images stay deterministic for
 * any thread count and tile order. */
#include "render.h"

#include <string.h>

/* Cut-out surfaces one ray passes at most (leaves of a dense tree seen edge on). */
#define ALPHA_LAYERS 64
/* Rays of an array fixed up at a time (their segment ends are kept on the stack). */
#define ALPHA_CHUNK 256

bool alpha_scene_has_cutouts(const rp_render_scene *s) {
    size_t n = s->data->material_count;
    for (size_t i = 0; i < n; i++)
        if (s->materials[i].alpha_mode != RP_ALPHA_OPAQUE) return true;
    return false;
}

/* True when the hit (geom, prim, inst as the core gives them; barycentrics u, v) is on a cut-out
 * point of its surface. */
static bool hit_cut(const rp_render_scene *s, const float org[3], const float dir[3], float t, uint32_t geom,
                    uint32_t prim, uint32_t inst, float u, float v) {
    const rp_scene_data *d = s->data;
    scene_ids_flat(s, &geom, &prim, &inst);
    uint32_t mat;
    bool tri = geom == s->geom_ids[RENDER_GEOM_TRIANGLES] && prim < d->triangle_count;
    if (tri) mat = d->tri_materials ? d->tri_materials[prim] : 0;
    else if (geom == s->geom_ids[RENDER_GEOM_SPHERES] && prim < d->sphere_count) mat = d->spheres[prim].material;
    else if (geom == s->geom_ids[RENDER_GEOM_CONES] && prim < d->cone_count) mat = d->cones[prim].material;
    else return false;
    if (mat >= d->material_count) return false; /* scene_surface's material 0: the default, opaque */
    const rp_material *m = &s->materials[mat];
    if (m->alpha_mode == RP_ALPHA_OPAQUE) return false;
    float a = m->alpha;
    if (tri && m->alpha_texture >= 0 && d->texcoords && d->texcoord_indices) {
        /* the texture coordinates as scene_surface interpolates them */
        const uint32_t *ti = d->texcoord_indices + 3 * (size_t)prim;
        const float *t0 = d->texcoords + 2 * (size_t)ti[0], *t1 = d->texcoords + 2 * (size_t)ti[1],
                    *t2 = d->texcoords + 2 * (size_t)ti[2];
        float b0 = 1.0f - u - v;
        float uv[2] = {b0 * t0[0] + u * t1[0] + v * t2[0], b0 * t0[1] + u * t1[1] + v * t2[1]};
        if (m->uv_transform) { /* the material's texture transform, as scene_surface applies it */
            const float *x = m->uv_matrix, u0 = uv[0], v0 = uv[1];
            uv[0] = x[0] * u0 + x[1] * v0 + x[2];
            uv[1] = x[3] * u0 + x[4] * v0 + x[5];
        }
        a *= material_texture_alpha(s, m->alpha_texture, uv);
    }
    if (m->alpha_mode == RP_ALPHA_MASK) return a < m->alpha_cutoff;
    /* BLEND: passed with probability 1 - alpha, by a hash of the ray and of the hit's distance */
    uint32_t bits[7];
    memcpy(bits, org, 3 * sizeof(float));
    memcpy(bits + 3, dir, 3 * sizeof(float));
    memcpy(bits + 6, &t, sizeof(float));
    uint32_t h = 0x9e3779b9u;
    for (int k = 0; k < 7; k++) h = render_hash(h ^ bits[k]);
    return (float)(h >> 8) * (1.0f / 16777216.0f) >= a;
}

bool alpha_rayhit_cut(const rp_render_scene *s, const rp_rayhit *rh) {
    const float org[3] = {rh->ray.org_x, rh->ray.org_y, rh->ray.org_z}, dir[3] = {rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z};
    return hit_cut(s, org, dir, rh->ray.tfar, rh->hit.geom_id, rh->hit.prim_id, rh->hit.inst_id, rh->hit.u, rh->hit.v);
}

/* Traces a ray whose closest hit (in rh, at rh->ray.tfar) is cut out on past it, up to tfar (its
 * segment's end before the first query): rh ends with the first opaque hit, or as a miss (tfar
 * restored, ids RP_INVALID_ID). tnear is left as it was. */
static void pass_through(const rp_render_scene *s, rp_rayhit *rh, float tfar) {
    float tnear = rh->ray.tnear;
    for (int layer = 0; layer < ALPHA_LAYERS; layer++) {
        rh->ray.tnear = nextafterf(rh->ray.tfar, INFINITY);
        rh->ray.tfar = tfar;
        rh->hit.geom_id = rh->hit.prim_id = rh->hit.inst_id = RP_INVALID_ID;
        rp_intersect1(s->scene, rh);
        if (rh->hit.geom_id == RP_INVALID_ID) break;
        if (!alpha_rayhit_cut(s, rh)) {
            rh->ray.tnear = tnear;
            return;
        }
    }
    rh->ray.tnear = tnear;
    rh->ray.tfar = tfar;
    rh->hit.geom_id = rh->hit.prim_id = rh->hit.inst_id = RP_INVALID_ID;
}

/* Whether a ray the core found occluded over [tnear, tfar) has an opaque surface there. */
static bool opaque_on(const rp_render_scene *s, const rp_ray *ray, float tfar) {
    rp_rayhit rh;
    rh.ray = *ray;
    rh.ray.tfar = tfar;
    rh.hit.geom_id = rh.hit.prim_id = rh.hit.inst_id = RP_INVALID_ID;
    rp_intersect1(s->scene, &rh);
    if (rh.hit.geom_id != RP_INVALID_ID && alpha_rayhit_cut(s, &rh)) pass_through(s, &rh, tfar);
    return rh.hit.geom_id != RP_INVALID_ID;
}

/* The fix-ups of one ray the core answered; tfar: its segment's end before the query. */
static void fix_closest(const rp_render_scene *s, rp_rayhit *rh, float tfar) {
    if (rh->hit.geom_id != RP_INVALID_ID && alpha_rayhit_cut(s, rh)) pass_through(s, rh, tfar);
}

static void fix_occluded(const rp_render_scene *s, rp_ray *ray, float tfar) {
    if (ray->tfar < 0.0f && tfar >= 0.0f && !opaque_on(s, ray, tfar)) ray->tfar = tfar;
}

void alpha_fix_traced(const rp_render_scene *s, rp_rayhit *rayhit, float tfar, bool occlusion) {
    if (!s->cutouts) return;
    if (occlusion) fix_occluded(s, &rayhit->ray, tfar);
    else fix_closest(s, rayhit, tfar);
}

void alpha_intersect1(const rp_render_scene *s, rp_rayhit *rh) {
    float tfar = rh->ray.tfar;
    rp_intersect1(s->scene, rh);
    if (s->cutouts) fix_closest(s, rh, tfar);
}

void alpha_occluded1(const rp_render_scene *s, rp_ray *ray) {
    float tfar = ray->tfar;
    rp_occluded1(s->scene, ray);
    if (s->cutouts) fix_occluded(s, ray, tfar);
}

/* An array of closest-hit (rh) or occlusion (r) queries, the other NULL, fixed up ALPHA_CHUNK at a
 * time. */
static void array_fixed(const rp_render_scene *s, rp_rayhit *rh, rp_ray *r, size_t count, uint32_t flags) {
    float tfar[ALPHA_CHUNK];
    for (size_t i0 = 0; i0 < count; i0 += ALPHA_CHUNK) {
        size_t n = count - i0 < ALPHA_CHUNK ? count - i0 : ALPHA_CHUNK;
        for (size_t i = 0; i < n; i++) tfar[i] = rh ? rh[i0 + i].ray.tfar : r[i0 + i].tfar;
        if (rh) rp_intersect_array(s->scene, rh + i0, n, flags);
        else rp_occluded_array(s->scene, r + i0, n, flags);
        for (size_t i = 0; i < n; i++) {
            if (rh) fix_closest(s, &rh[i0 + i], tfar[i]);
            else fix_occluded(s, &r[i0 + i], tfar[i]);
        }
    }
}

void alpha_intersect_array(const rp_render_scene *s, rp_rayhit *rayhits, size_t count, uint32_t flags) {
    if (s->cutouts) array_fixed(s, rayhits, NULL, count, flags);
    else rp_intersect_array(s->scene, rayhits, count, flags);
}

void alpha_occluded_array(const rp_render_scene *s, rp_ray *rays, size_t count, uint32_t flags) {
    if (s->cutouts) array_fixed(s, NULL, rays, count, flags);
    else rp_occluded_array(s->scene, rays, count, flags);
}

/* Lane q of a large packet as a single ray. */
static rp_ray lane_ray(const rp_rayhit_n *p, uint32_t q, float tfar) {
    return (rp_ray){.org_x = p->org_x[q], .org_y = p->org_y[q], .org_z = p->org_z[q], .tnear = p->tnear[q],
                    .dir_x = p->dir_x[q], .dir_y = p->dir_y[q], .dir_z = p->dir_z[q], .tfar = tfar,
                    .mask = p->mask ? p->mask[q] : 0xFFFFFFFFu};
}

/* A large packet's closest-hit or occlusion query, fixed up lane by lane. */
static void packet_fixed(const rp_render_scene *s, const rp_query_n_desc *desc, rp_rayhit_n *p, bool occluded) {
    uint32_t nn = p->n * p->n;
    float tfar[RENDER_LANES_MAX];
    for (uint32_t q = 0; q < nn; q++) tfar[q] = p->tfar[q];
    if (occluded) rp_occluded_n(s->scene, desc, p);
    else rp_intersect_n(s->scene, desc, p);
    for (uint32_t q = 0; q < nn; q++) {
        if (p->valid && !p->valid[q]) continue;
        if (occluded) {
            if (!(p->tfar[q] < 0.0f && tfar[q] >= 0.0f)) continue;
            rp_ray r = lane_ray(p, q, tfar[q]);
            if (!opaque_on(s, &r, tfar[q])) p->tfar[q] = tfar[q];
            continue;
        }
        if (p->geom_id[q] == RP_INVALID_ID) continue;
        const float org[3] = {p->org_x[q], p->org_y[q], p->org_z[q]}, dir[3] = {p->dir_x[q], p->dir_y[q], p->dir_z[q]};
        if (!hit_cut(s, org, dir, p->tfar[q], p->geom_id[q], p->prim_id[q], p->inst_id[q], p->u[q], p->v[q])) continue;
        rp_rayhit rh = {.ray = lane_ray(p, q, p->tfar[q])};
        pass_through(s, &rh, tfar[q]);
        p->tfar[q] = rh.ray.tfar;
        p->Ng_x[q] = rh.hit.Ng_x, p->Ng_y[q] = rh.hit.Ng_y, p->Ng_z[q] = rh.hit.Ng_z;
        p->u[q] = rh.hit.u, p->v[q] = rh.hit.v;
        p->prim_id[q] = rh.hit.prim_id, p->geom_id[q] = rh.hit.geom_id, p->inst_id[q] = rh.hit.inst_id;
    }
}

void alpha_intersect_n(const rp_render_scene *s, const rp_query_n_desc *desc, rp_rayhit_n *p) {
    if (s->cutouts) packet_fixed(s, desc, p, false);
    else rp_intersect_n(s->scene, desc, p);
}

void alpha_occluded_n(const rp_render_scene *s, const rp_query_n_desc *desc, rp_rayhit_n *p) {
    if (s->cutouts) packet_fixed(s, desc, p, true);
    else rp_occluded_n(s->scene, desc, p);
}
