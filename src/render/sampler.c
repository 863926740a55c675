/* The pixel sampler: every random number is a function of (pixel, sample index, dimension), the
 * determinism contract of DESIGN.md, so an image is the same whatever the thread count, the tile
 * order or the number of MPI ranks, and frames can resume at any sample index (sample_start).
 * Numbers are hashed PCG (Jarzynski and Olano 2020, "Hash Functions for GPU Rendering": pcg's
 * output permutation of a linear congruential step); independent per dimension. */
#include "render.h"

static inline uint32_t pcg_hash(uint32_t v) {
    uint32_t state = v * 747796405u + 2891336453u;
    uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

render_sampler sampler_start(uint32_t x, uint32_t y, uint32_t sample) {
    render_sampler s = {.key = pcg_hash(x + pcg_hash(y + pcg_hash(sample + 0x68e31da4u))), .dim = 0};
    return s;
}

float sampler_at(const render_sampler *s, uint32_t d) {
    uint32_t h = pcg_hash(s->key ^ pcg_hash(d * 0x9e3779b9u + 0x1b873593u));
    return (float)(h >> 8) * (1.0f / 16777216.0f);
}

float sampler_1d(render_sampler *s) { return sampler_at(s, s->dim++); }
