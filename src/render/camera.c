/* Pinhole camera of DESIGN.md, and the camera given to scenes that bring none. */
#include "render.h"

#include <float.h>
#include <stdlib.h>
#include <math.h>

void camera_setup(const rp_camera *cam, int width, int height, render_camera *out) {
    switch (cam->type) {
    case RP_CAMERA_PINHOLE: {
        const rp_pinhole_camera *p = &cam->pinhole;
        out->eye = v3_load(p->eye);
        out->f = v3_normalize(v3_sub(v3_load(p->look), out->eye));
        out->r = v3_normalize(v3_cross(out->f, v3_load(p->up)));
        out->u = v3_cross(out->r, out->f);
        out->tan_half = tanf(p->fov_deg * 0.5f * (3.14159265358979f / 180.0f));
        break;
    }
    }
    out->width = (float)width;
    out->height = (float)height;
    out->aspect = (float)width / (float)height;
}

bool camera_valid(const rp_camera *cam) {
    if (cam->type != RP_CAMERA_PINHOLE) return false;
    const rp_pinhole_camera *p = &cam->pinhole;
    if (!(p->fov_deg > 0.0f && p->fov_deg < 180.0f)) return false;
    double d[3], u[3], dd = 0.0, uu = 0.0;
    for (int k = 0; k < 3; k++) {
        float dk = p->look[k] - p->eye[k]; /* in float, as camera_setup */
        if (!isfinite(p->eye[k]) || !isfinite(p->look[k]) || !isfinite(p->up[k]) || !isfinite(dk)) return false;
        d[k] = dk, u[k] = p->up[k];
        dd += d[k] * d[k], uu += u[k] * u[k];
    }
    double c[3] = {d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2], d[0] * u[1] - d[1] * u[0]};
    /* sin^2 of the angle between the view and up at least 1e-10: else the right vector is noise */
    return dd > 0.0 && uu > 0.0 && c[0] * c[0] + c[1] * c[1] + c[2] * c[2] > 1e-10 * dd * uu;
}

/* dir = normalize(f + (2x/W - 1) tan(fov/2) (W/H) r + (1 - 2y/H) tan(fov/2) u), x and y already
 * offset within the pixel (x + 0.5 for its centre). */
void camera_ray(const render_camera *c, float x, float y, rp_ray *ray) {
    float a = (2.0f * x / c->width - 1.0f) * c->tan_half * c->aspect;
    float b = (1.0f - 2.0f * y / c->height) * c->tan_half;
    v3 d = v3_normalize(v3_add(v3_add(c->f, v3_scale(c->r, a)), v3_scale(c->u, b)));
    render_ray_init(ray, c->eye, d, INFINITY);
}

void rp_render_primary_rays(const rp_camera *camera, int width, int height, rp_ray *out) {
    render_camera c;
    camera_setup(camera, width, height, &c);
    for (int y = 0; y < height; y++)
        for (int x = 0; x < width; x++)
            camera_ray(&c, (float)x + 0.5f, (float)y + 0.5f, &out[(size_t)y * (size_t)width + (size_t)x]);
}

/* camera_rays_n's work, inlined into a baseline and an AVX2 copy of it (below): the per-lane loops
 * vectorise 8 wide with AVX2 (its 32-bit multiplies hash the sample offsets), and no FMA is enabled,
 * so both copies make the same IEEE operations in the same order and give the same rays. */
RENDER_INLINE void camera_rays_body(const render_camera *c, int bx, int by, int s, uint32_t count, const uint8_t *li,
                                const uint8_t *lj, rp_rayhit_n *p) {
    float ox[RENDER_LANES_MAX], oy[RENDER_LANES_MAX];
    if (s == 0) {
        for (uint32_t q = 0; q < count; q++) ox[q] = oy[q] = 0.5f; /* render_sample_offset of sample 0 */
    } else {
        /* render_sample_offset's render_random(x, y, s, d) = hash(x ^ hash(y ^ hash(s ^ hash(d + k)))):
         * the inner part once per row of the block (lj < 32), the outer per lane */
        uint32_t k0 = render_hash((uint32_t)s ^ render_hash(0u + 0x9e3779b9u));
        uint32_t k1 = render_hash((uint32_t)s ^ render_hash(1u + 0x9e3779b9u));
        uint32_t row0[32], row1[32];
        for (uint32_t j = 0; j < 32; j++) {
            row0[j] = render_hash((uint32_t)(by + (int)j) ^ k0);
            row1[j] = render_hash((uint32_t)(by + (int)j) ^ k1);
        }
        for (uint32_t q = 0; q < count; q++) {
            uint32_t x = (uint32_t)(bx + li[q]);
            ox[q] = (float)(render_hash(x ^ row0[lj[q] & 31u]) >> 8) * (1.0f / 16777216.0f);
            oy[q] = (float)(render_hash(x ^ row1[lj[q] & 31u]) >> 8) * (1.0f / 16777216.0f);
        }
    }
    /* camera_ray's operations in its order, lane by lane, so that the loop vectorises (CMakeLists.txt
     * compiles this file without errno and FP traps for that) and every ray is camera_ray's */
    const float fx = c->f.x, fy = c->f.y, fz = c->f.z, rx = c->r.x, ry = c->r.y, rz = c->r.z;
    const float ux = c->u.x, uy = c->u.y, uz = c->u.z, w = c->width, h = c->height;
    const float th = c->tan_half, aspect = c->aspect, ex = c->eye.x, ey = c->eye.y, ez = c->eye.z;
    float *restrict dx = p->dir_x, *restrict dy = p->dir_y, *restrict dz = p->dir_z;
    for (uint32_t q = 0; q < count; q++) {
        float x = (float)(bx + li[q]) + ox[q], y = (float)(by + lj[q]) + oy[q];
        float a = (2.0f * x / w - 1.0f) * th * aspect;
        float b = (1.0f - 2.0f * y / h) * th;
        float vx = (fx + rx * a) + ux * b, vy = (fy + ry * a) + uy * b, vz = (fz + rz * a) + uz * b;
        float l = sqrtf(vx * vx + vy * vy + vz * vz);
        float inv = 1.0f / l;
        bool ok = l > 0.0f; /* v3_normalize */
        dx[q] = ok ? vx * inv : vx;
        dy[q] = ok ? vy * inv : vy;
        dz[q] = ok ? vz * inv : vz;
    }
    float *restrict o_x = p->org_x, *restrict o_y = p->org_y, *restrict o_z = p->org_z;
    float *restrict tn = p->tnear, *restrict tf = p->tfar;
    uint32_t *restrict g = p->geom_id, *restrict pr = p->prim_id, *restrict in = p->inst_id;
    for (uint32_t q = 0; q < count; q++) o_x[q] = ex;
    for (uint32_t q = 0; q < count; q++) o_y[q] = ey;
    for (uint32_t q = 0; q < count; q++) o_z[q] = ez;
    for (uint32_t q = 0; q < count; q++) tn[q] = 0.0f;
    for (uint32_t q = 0; q < count; q++) tf[q] = INFINITY;
    for (uint32_t q = 0; q < count; q++) g[q] = pr[q] = in[q] = RP_INVALID_ID;
}

static void camera_rays_base(const render_camera *c, int bx, int by, int s, uint32_t count, const uint8_t *li,
                             const uint8_t *lj, rp_rayhit_n *p) {
    camera_rays_body(c, bx, by, s, count, li, lj, p);
}

#if RENDER_X86_AVX2
__attribute__((target("avx2"))) static void camera_rays_avx2(const render_camera *c, int bx, int by, int s,
                                                             uint32_t count, const uint8_t *li, const uint8_t *lj,
                                                             rp_rayhit_n *p) {
    camera_rays_body(c, bx, by, s, count, li, lj, p);
}
#endif

void camera_rays_n(const render_camera *c, int bx, int by, int s, uint32_t count, const uint8_t *li,
                   const uint8_t *lj, bool avx2, rp_rayhit_n *p) {
#if RENDER_X86_AVX2
    if (avx2) {
        camera_rays_avx2(c, bx, by, s, count, li, lj, p);
        return;
    }
#endif
    (void)avx2;
    camera_rays_base(c, bx, by, s, count, li, lj, p);
}

/* Score of a view: primary hits on front faces minus hits on back faces, on a coarse grid, and the
 * number of distinct primitives hit (*distinct). Closed meshes score the same from every side; a room
 * open on one side (the Cornell box) is seen through its opening. The rays pass through cut-out
 * points (alpha.c), as the image's do: a leaf's holes neither frame the view nor hide it. */
static int view_score(const rp_render_scene *scene, const rp_camera *cam, int *distinct) {
    enum { N = 12 };
    render_camera rc;
    camera_setup(cam, N, N, &rc);
    rp_rayhit rh[N * N];
    for (int y = 0; y < N; y++) {
        for (int x = 0; x < N; x++) {
            rp_rayhit *h = &rh[y * N + x];
            camera_ray(&rc, (float)x + 0.5f, (float)y + 0.5f, &h->ray);
            h->hit.geom_id = RP_INVALID_ID;
            h->hit.prim_id = RP_INVALID_ID;
            h->hit.inst_id = RP_INVALID_ID;
        }
    }
    alpha_intersect_array(scene, rh, N * N, RP_QUERY_INCOHERENT);
    int score = 0;
    *distinct = 0;
    for (int i = 0; i < N * N; i++) {
        if (rh[i].hit.geom_id == RP_INVALID_ID) continue;
        float d = rh[i].hit.Ng_x * rh[i].ray.dir_x + rh[i].hit.Ng_y * rh[i].ray.dir_y +
                  rh[i].hit.Ng_z * rh[i].ray.dir_z;
        score += d < 0.0f ? 1 : (d > 0.0f ? -1 : 0);
        bool seen = false;
        for (int j = 0; j < i && !seen; j++)
            seen = rh[j].hit.geom_id == rh[i].hit.geom_id && rh[j].hit.prim_id == rh[i].hit.prim_id;
        *distinct += !seen;
    }
    return score;
}

/* Fewer distinct primitives than this in the best outside view: a flat wall (sponza's outside). */
#define VIEW_FEW_PRIMS 8

rp_camera camera_frame_bounds(const rp_render_scene *scene, const rp_bounds *b) {
    rp_camera cam = {.type = RP_CAMERA_PINHOLE};
    rp_pinhole_camera *p = &cam.pinhole;
    p->fov_deg = 45.0f;
    if (!(b->lower_x <= b->upper_x && b->lower_y <= b->upper_y && b->lower_z <= b->upper_z)) {
        float eye[3] = {0, 0, 5}, up[3] = {0, 1, 0};
        for (int k = 0; k < 3; k++) {
            p->eye[k] = eye[k];
            p->look[k] = 0.0f;
            p->up[k] = up[k];
        }
        return cam;
    }
    v3 lo = v3_make(b->lower_x, b->lower_y, b->lower_z);
    v3 hi = v3_make(b->upper_x, b->upper_y, b->upper_z);
    v3 c = v3_scale(v3_add(lo, hi), 0.5f);
    float radius = 0.5f * v3_length(v3_sub(hi, lo));
    if (!isfinite(radius)) { /* the squared extent of a scene 1e20 wide overflows a float: an Inf, NaN eye */
        double dx = (double)b->upper_x - b->lower_x, dy = (double)b->upper_y - b->lower_y, dz = (double)b->upper_z - b->lower_z;
        radius = (float)(0.5 * sqrt(dx * dx + dy * dy + dz * dz));
    }
    if (!(radius > 0.0f)) radius = 1.0f;
    float dist = radius / sinf(p->fov_deg * 0.5f * (3.14159265358979f / 180.0f));
    /* Candidate directions, y up (the common convention). +z first: glTF's front faces +z, and so do
     * most models made for a y-up viewer (Suzanne, the Stanford bunny). Another direction wins only
     * when it sees clearly more front faces (by an eighth): Suzanne's back of the head scores 26 of
     * 144 rays against her face's 24, and was the view. */
    static const float dirs[4][3] = {{0, 0, 1}, {0, 0, -1}, {1, 0, 0}, {-1, 0, 0}};
    int best = -1, best_score = 0, best_distinct = 0;
    for (int i = 0; i < 4; i++) {
        rp_camera cand = cam;
        for (int k = 0; k < 3; k++) {
            cand.pinhole.look[k] = v3_at(c, k);
            cand.pinhole.eye[k] = v3_at(c, k) + dirs[i][k] * dist;
            cand.pinhole.up[k] = k == 1 ? 1.0f : 0.0f;
        }
        int distinct, s = view_score(scene, &cand, &distinct);
        if (best < 0 || s > best_score + abs(best_score) / 8) {
            best = i;
            best_score = s;
            best_distinct = distinct;
            cam = cand;
        }
    }
    if (best_score > 0 && best_distinct >= VIEW_FEW_PRIMS) return cam;
    /* Seen from outside the scene shows back faces or one flat wall: a room or a building whose
     * walls face inwards (the conference room, sponza's atrium). Look along each horizontal axis
     * from near one end of the box, at a fifth of its height (eye level in a building); the view that sees front faces and the
     * most distinct primitives wins, if it sees more than the outside one. */
    for (int i = 0; i < 4; i++) {
        rp_camera cand = cam;
        cand.pinhole.fov_deg = 60.0f;
        for (int k = 0; k < 3; k++) {
            float half = 0.5f * (v3_at(hi, k) - v3_at(lo, k));
            float at = k == 1 ? v3_at(lo, k) + 0.2f * (v3_at(hi, k) - v3_at(lo, k)) : v3_at(c, k);
            cand.pinhole.eye[k] = at - dirs[i][k] * 0.8f * half;
            cand.pinhole.look[k] = at + dirs[i][k] * half;
            cand.pinhole.up[k] = k == 1 ? 1.0f : 0.0f;
        }
        int distinct, s = view_score(scene, &cand, &distinct);
        if (s > 0 && distinct > best_distinct) {
            best_distinct = distinct;
            cam = cand;
        }
    }
    return cam;
}
