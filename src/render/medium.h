/* The participating medium of a render scene (medium.c): a density grid (rp_volume_data, the
 * sparse brick grid a .vdb loads into) with its extinction scale, single-scattering albedo and
 * Henyey-Greenstein phase function, and the estimators the integrators use on it.
 *
 * Model: extinction sigma_t(x) = density_scale * density(x) per world unit, density trilinear
 * between voxel centres (0 outside the active voxels); scattering sigma_s = albedo sigma_t, the
 * rest absorbed; no emission. Free paths are sampled by delta tracking (Woodcock), transmittance
 * to lights estimated by ratio tracking, both against a majorant per brick (the largest density of
 * a brick and of the first voxels of its +x, +y, +z neighbours, which trilinear lookups in the
 * brick read), walked brick by brick with a 3D DDA in index space. */
#ifndef RP_RENDER_MEDIUM_H
#define RP_RENDER_MEDIUM_H

#include "render.h"

typedef struct render_medium {
    const rp_volume_data *vol;
    float w2i[12];        /* world to index space (3x4, row-major) */
    float i2w[12];        /* index to world: the volume's transform */
    float *majorant;      /* per brick cell (vol->dims), extinction per world unit */
    float max_majorant;
    float density_scale;
    v3 albedo;
    float g;              /* Henyey-Greenstein asymmetry */
    rp_bounds bounds;     /* world box of where the density can be non-zero */
} render_medium;

/* A stream of random numbers for the unbounded loops of tracking: a function of the seed alone
 * (built from pixel, sample and path depth), so images stay the same for every thread count. */
typedef struct medium_rng {
    uint32_t state;
} medium_rng;
static inline medium_rng medium_rng_seed(uint32_t a, uint32_t b, uint32_t c) {
    return (medium_rng){render_hash(a ^ render_hash(b ^ render_hash(c + 0x68bc21ebu)))};
}
static inline float medium_rng_next(medium_rng *r) {
    r->state = r->state * 747796405u + 2891336453u; /* PCG's LCG step, its output hashed */
    return (float)(render_hash(r->state) >> 8) * (1.0f / 16777216.0f);
}

/* Builds the medium from a volume and the desc's parameters; false when out of memory. */
bool medium_init(render_medium *m, const rp_volume_data *vol, const rp_medium_desc *desc);
void medium_free(render_medium *m);
/* Extinction (per world unit) at world point p. */
float medium_sigma_t(const render_medium *m, v3 p);
/* Delta tracking along org + t dir (dir unit), t in [0, tmax): true and *t at a real collision
 * (scattering or absorption: the caller weights by the albedo), false when the ray gets through. */
bool medium_sample_collision(const render_medium *m, v3 org, v3 dir, float tmax, medium_rng *rng, float *t);
/* Ratio tracking: an unbiased estimate of the transmittance over [0, tmax) (Russian roulette below
 * 0.1 keeps dense media cheap). */
float medium_transmittance(const render_medium *m, v3 org, v3 dir, float tmax, medium_rng *rng);
/* The transmittance by ray marching (midpoints, half a voxel apart, empty bricks skipped):
 * deterministic, for the integrators that show the medium's opacity (eye light, Whitted, AO). */
float medium_transmittance_march(const render_medium *m, v3 org, v3 dir, float tmax);
/* Henyey-Greenstein: the density of scattering from propagation direction d_in to d_out (unit),
 * per steradian; sampling d_out from u0, u1 (its density is the value, the weight 1). */
float medium_phase(float g, v3 d_in, v3 d_out);
v3 medium_phase_sample(float g, v3 d_in, float u0, float u1);

#endif
