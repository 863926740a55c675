/* The participating medium: trilinear density over the sparse brick grid, a majorant per brick,
 * delta tracking, ratio tracking and ray marching along a DDA over the bricks, and the
 * Henyey-Greenstein phase function (see medium.h for the model). Everything runs in the grid's
 * index space: a ray's parameter t is the same there as in the world (the map is affine), so
 * distances, and extinction per world unit, need no conversion. */
#include "medium.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

#define PI_F 3.14159265358979323846f
#define B RP_VOLUME_BRICK
/* Extinction scale beyond which tracking would take too many steps to be of use. */
#define MEDIUM_MAX_SCALE 1e6f

static v3 xfm_point(const float m[12], v3 p) {
    return v3_make(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                   m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
}
static v3 xfm_dir(const float m[12], v3 d) {
    return v3_make(m[0] * d.x + m[1] * d.y + m[2] * d.z, m[4] * d.x + m[5] * d.y + m[6] * d.z,
                   m[8] * d.x + m[9] * d.y + m[10] * d.z);
}

/* The inverse of an affine 3x4 map (in double); false when it is singular. */
static bool xfm_invert(const float m[12], float out[12]) {
    double a[3][3], inv[3][3];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) a[r][c] = m[4 * r + c];
    double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                 a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if (!(fabs(det) > 1e-300) || !isfinite(det)) return false;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            /* the cofactor of (c, r) */
            int r0 = (c + 1) % 3, r1 = (c + 2) % 3, c0 = (r + 1) % 3, c1 = (r + 2) % 3;
            inv[r][c] = (a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / det;
        }
    for (int r = 0; r < 3; r++) {
        double t = 0.0;
        for (int c = 0; c < 3; c++) {
            out[4 * r + c] = (float)inv[r][c];
            t -= inv[r][c] * m[4 * c + 3];
        }
        out[4 * r + 3] = (float)t;
    }
    return true;
}

static uint32_t cell_slot(const rp_volume_data *v, uint32_t cx, uint32_t cy, uint32_t cz) {
    return v->brick_slot[((size_t)cz * v->dims[1] + cy) * v->dims[0] + cx];
}

bool medium_init(render_medium *m, const rp_volume_data *vol, const rp_medium_desc *desc) {
    memset(m, 0, sizeof *m);
    m->vol = vol;
    rp_medium_desc d = desc ? *desc : (rp_medium_desc){0};
    m->density_scale = d.density_scale > 0.0f ? render_fminf(d.density_scale, MEDIUM_MAX_SCALE) : 1.0f;
    if (d.albedo[0] == 0.0f && d.albedo[1] == 0.0f && d.albedo[2] == 0.0f) m->albedo = v3_make(1, 1, 1);
    else
        m->albedo = v3_make(render_fminf(render_fmaxf(d.albedo[0], 0.0f), 1.0f), render_fminf(render_fmaxf(d.albedo[1], 0.0f), 1.0f),
                            render_fminf(render_fmaxf(d.albedo[2], 0.0f), 1.0f));
    m->g = isfinite(d.hg_g) ? render_fminf(render_fmaxf(d.hg_g, -0.99f), 0.99f) : 0.0f;
    memcpy(m->i2w, vol->index_to_world, sizeof m->i2w);
    if (!xfm_invert(m->i2w, m->w2i)) { /* a degenerate transform: the medium is left empty */
        memset(m->w2i, 0, sizeof m->w2i);
    }
    size_t cells = (size_t)vol->dims[0] * vol->dims[1] * vol->dims[2];
    m->majorant = calloc(cells ? cells : 1, sizeof *m->majorant);
    if (!m->majorant) return false;
    for (uint32_t z = 0; z < vol->dims[2]; z++)
        for (uint32_t y = 0; y < vol->dims[1]; y++)
            for (uint32_t x = 0; x < vol->dims[0]; x++) {
                /* trilinear lookups in a brick read the first voxels of its +x, +y, +z neighbours */
                float mx = 0.0f;
                for (uint32_t k = 0; k < 8; k++) {
                    uint32_t nx = x + (k & 1), ny = y + (k >> 1 & 1), nz = z + (k >> 2);
                    if (nx >= vol->dims[0] || ny >= vol->dims[1] || nz >= vol->dims[2]) continue;
                    uint32_t s = cell_slot(vol, nx, ny, nz);
                    if (s != RP_VOLUME_EMPTY && vol->brick_max[s] > mx) mx = vol->brick_max[s];
                }
                float mj = mx * m->density_scale;
                m->majorant[((size_t)z * vol->dims[1] + y) * vol->dims[0] + x] = mj;
                if (mj > m->max_majorant) m->max_majorant = mj;
            }
    /* the world box of the widened active box's corners */
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int c = 0; c < 8; c++) {
        v3 p = v3_make((float)(c & 1 ? vol->active_max[0] + 1 : vol->active_min[0] - 1),
                       (float)(c & 2 ? vol->active_max[1] + 1 : vol->active_min[1] - 1),
                       (float)(c & 4 ? vol->active_max[2] + 1 : vol->active_min[2] - 1));
        v3 w = xfm_point(m->i2w, p);
        for (int a = 0; a < 3; a++) {
            lo[a] = render_fminf(lo[a], v3_at(w, a));
            hi[a] = render_fmaxf(hi[a], v3_at(w, a));
        }
    }
    m->bounds = (rp_bounds){.lower_x = lo[0], .lower_y = lo[1], .lower_z = lo[2],
                            .upper_x = hi[0], .upper_y = hi[1], .upper_z = hi[2]};
    return true;
}

void medium_free(render_medium *m) {
    if (!m) return;
    free(m->majorant);
    m->majorant = NULL;
}

/* ---- density ---- */

/* Voxel (x, y, z), counted from the volume's origin; 0 outside the stored bricks. */
static float voxel(const rp_volume_data *v, int32_t x, int32_t y, int32_t z) {
    if (x < 0 || y < 0 || z < 0) return 0.0f;
    uint32_t cx = (uint32_t)x / B, cy = (uint32_t)y / B, cz = (uint32_t)z / B;
    if (cx >= v->dims[0] || cy >= v->dims[1] || cz >= v->dims[2]) return 0.0f;
    uint32_t s = cell_slot(v, cx, cy, cz);
    if (s == RP_VOLUME_EMPTY) return 0.0f;
    return v->density[(size_t)s * B * B * B + (size_t)((((uint32_t)z % B) * B + (uint32_t)y % B) * B + (uint32_t)x % B)];
}

/* Trilinear density at index-space point p (voxel centres at integer coordinates). */
static float density_index(const rp_volume_data *v, v3 p) {
    float lx = p.x - (float)v->origin[0], ly = p.y - (float)v->origin[1], lz = p.z - (float)v->origin[2];
    if (!(lx >= 0.0f && ly >= 0.0f && lz >= 0.0f)) return 0.0f;
    float fx = floorf(lx), fy = floorf(ly), fz = floorf(lz);
    if (fx >= (float)(v->dims[0] * B) || fy >= (float)(v->dims[1] * B) || fz >= (float)(v->dims[2] * B)) return 0.0f;
    int32_t x = (int32_t)fx, y = (int32_t)fy, z = (int32_t)fz;
    float tx = lx - fx, ty = ly - fy, tz = lz - fz;
    float c[8];
    if (x % B < B - 1 && y % B < B - 1 && z % B < B - 1) { /* all eight in one brick */
        uint32_t s = cell_slot(v, (uint32_t)x / B, (uint32_t)y / B, (uint32_t)z / B);
        if (s == RP_VOLUME_EMPTY) return 0.0f;
        const float *d = v->density + (size_t)s * B * B * B + (size_t)(((z % B) * B + y % B) * B + x % B);
        c[0] = d[0], c[1] = d[1], c[2] = d[B], c[3] = d[B + 1];
        c[4] = d[B * B], c[5] = d[B * B + 1], c[6] = d[B * B + B], c[7] = d[B * B + B + 1];
    } else {
        for (int k = 0; k < 8; k++) c[k] = voxel(v, x + (k & 1), y + (k >> 1 & 1), z + (k >> 2));
    }
    float c00 = c[0] + (c[1] - c[0]) * tx, c10 = c[2] + (c[3] - c[2]) * tx;
    float c01 = c[4] + (c[5] - c[4]) * tx, c11 = c[6] + (c[7] - c[6]) * tx;
    float c0 = c00 + (c10 - c00) * ty, c1 = c01 + (c11 - c01) * ty;
    return c0 + (c1 - c0) * tz;
}

float medium_sigma_t(const render_medium *m, v3 p) {
    return m->density_scale * density_index(m->vol, xfm_point(m->w2i, p));
}

/* ---- the DDA over bricks ---- */

typedef struct brick_walk {
    v3 o, d;                 /* the ray in index space */
    int32_t c[3], step[3];
    float tnext[3], tdelta[3];
    float t, tend;
    bool done;
} brick_walk;

static bool walk_start(const render_medium *m, v3 org, v3 dir, float tmax, brick_walk *w) {
    const rp_volume_data *v = m->vol;
    w->o = xfm_point(m->w2i, org);
    w->d = xfm_dir(m->w2i, dir);
    float t0 = 0.0f, t1 = tmax;
    for (int a = 0; a < 3; a++) {
        float o = v3_at(w->o, a), d = v3_at(w->d, a);
        float lo = (float)v->origin[a], hi = (float)v->origin[a] + (float)(v->dims[a] * B);
        if (d == 0.0f) {
            if (!(o >= lo && o <= hi)) return false;
            continue;
        }
        float inv = 1.0f / d, ta = (lo - o) * inv, tb = (hi - o) * inv;
        if (ta > tb) {
            float s = ta;
            ta = tb;
            tb = s;
        }
        t0 = ta > t0 ? ta : t0;
        t1 = tb < t1 ? tb : t1;
    }
    if (!(t0 < t1)) return false;
    w->t = t0;
    w->tend = t1;
    w->done = false;
    v3 p = v3_madd(w->o, w->d, t0); /* a cell off by one through rounding only makes an empty segment */
    for (int a = 0; a < 3; a++) {
        float o = v3_at(w->o, a), d = v3_at(w->d, a), base = (float)v->origin[a];
        /* clamped as a float: converting one beyond int32's range would be undefined */
        float cf = render_fminf(render_fmaxf(floorf((v3_at(p, a) - base) / (float)B), 0.0f), (float)(v->dims[a] - 1));
        int32_t c = (int32_t)cf;
        w->c[a] = c;
        if (d > 0.0f) {
            w->step[a] = 1;
            w->tnext[a] = (base + (float)((c + 1) * B) - o) / d;
            w->tdelta[a] = (float)B / d;
        } else if (d < 0.0f) {
            w->step[a] = -1;
            w->tnext[a] = (base + (float)(c * B) - o) / d;
            w->tdelta[a] = -(float)B / d;
        } else {
            w->step[a] = 0;
            w->tnext[a] = INFINITY;
            w->tdelta[a] = INFINITY;
        }
    }
    return true;
}

/* The next brick the ray crosses: [*a, *b) and its majorant; false past the end. */
static bool walk_next(const render_medium *m, brick_walk *w, float *a, float *b, float *mu) {
    const rp_volume_data *v = m->vol;
    if (w->done) return false;
    int k = w->tnext[0] < w->tnext[1] ? (w->tnext[0] < w->tnext[2] ? 0 : 2) : (w->tnext[1] < w->tnext[2] ? 1 : 2);
    *a = w->t;
    *b = render_fmaxf(*a, render_fminf(w->tnext[k], w->tend)); /* never backwards, whatever rounding did to the first cell */
    *mu = m->majorant[((size_t)w->c[2] * v->dims[1] + (size_t)w->c[1]) * v->dims[0] + (size_t)w->c[0]];
    w->t = *b;
    if (w->tnext[k] >= w->tend) {
        w->done = true;
    } else {
        w->c[k] += w->step[k];
        w->tnext[k] += w->tdelta[k];
        if (w->c[k] < 0 || w->c[k] >= (int32_t)v->dims[k]) w->done = true;
    }
    return true;
}

bool medium_sample_collision(const render_medium *m, v3 org, v3 dir, float tmax, medium_rng *rng, float *t) {
    brick_walk w;
    if (!walk_start(m, org, dir, tmax, &w)) return false;
    float a, b, mu;
    while (walk_next(m, &w, &a, &b, &mu)) {
        if (!(mu > 0.0f)) continue;
        float s = a;
        for (;;) {
            s -= logf(1.0f - medium_rng_next(rng)) / mu;
            if (!(s < b)) break; /* memoryless: the next brick starts afresh at b */
            float sigma = m->density_scale * density_index(m->vol, v3_madd(w.o, w.d, s));
            if (medium_rng_next(rng) * mu < sigma) {
                *t = s;
                return true;
            }
        }
    }
    return false;
}

float medium_transmittance(const render_medium *m, v3 org, v3 dir, float tmax, medium_rng *rng) {
    brick_walk w;
    if (!walk_start(m, org, dir, tmax, &w)) return 1.0f;
    float a, b, mu, tr = 1.0f;
    while (walk_next(m, &w, &a, &b, &mu)) {
        if (!(mu > 0.0f)) continue;
        float s = a;
        for (;;) {
            s -= logf(1.0f - medium_rng_next(rng)) / mu;
            if (!(s < b)) break;
            float sigma = m->density_scale * density_index(m->vol, v3_madd(w.o, w.d, s));
            tr *= 1.0f - sigma / mu;
            if (tr < 0.1f) { /* Russian roulette: unbiased, and dense media end early */
                if (medium_rng_next(rng) >= 0.5f) return 0.0f;
                tr *= 2.0f;
            }
        }
    }
    return tr;
}

float medium_transmittance_march(const render_medium *m, v3 org, v3 dir, float tmax) {
    brick_walk w;
    if (!walk_start(m, org, dir, tmax, &w)) return 1.0f;
    float dl = v3_length(w.d);
    if (!(dl > 0.0f)) return 1.0f;
    float h = 0.5f / dl; /* half a voxel, in t */
    float a, b, mu;
    double tau = 0.0;
    while (walk_next(m, &w, &a, &b, &mu)) {
        if (!(mu > 0.0f) || !(b > a)) continue;
        float n = ceilf((b - a) / h), dt = (b - a) / n;
        for (float i = 0.5f; i < n; i += 1.0f)
            tau += (double)(m->density_scale * density_index(m->vol, v3_madd(w.o, w.d, a + i * dt)) * dt);
        if (tau > 50.0) return 0.0f;
    }
    return (float)exp(-tau);
}

/* ---- phase function ---- */

float medium_phase(float g, v3 d_in, v3 d_out) {
    float mu = v3_dot(d_in, d_out), denom = 1.0f + g * g - 2.0f * g * mu;
    return (1.0f - g * g) / (4.0f * PI_F * denom * sqrtf(denom));
}

v3 medium_phase_sample(float g, v3 d_in, float u0, float u1) {
    float mu;
    if (fabsf(g) < 1e-3f) {
        mu = 1.0f - 2.0f * u0;
    } else { /* the inverse of the cosine's distribution function */
        float q = (1.0f - g * g) / (1.0f - g + 2.0f * g * u0);
        mu = (1.0f + g * g - q * q) / (2.0f * g);
    }
    mu = render_fminf(1.0f, render_fmaxf(-1.0f, mu));
    float st = sqrtf(render_fmaxf(0.0f, 1.0f - mu * mu)), phi = 2.0f * PI_F * u1;
    v3 t, b;
    bsdf_frame(d_in, &t, &b);
    return v3_add(v3_add(v3_scale(t, st * cosf(phi)), v3_scale(b, st * sinf(phi))), v3_scale(d_in, mu));
}
