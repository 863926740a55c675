/* The pixel sampler: every random number is a function of (pixel, sample index, dimension), the
 * determinism contract of DESIGN.md, so an image is the same whatever the thread count, the tile
 * order or the number of MPI ranks, and frames can resume at any sample index (sample_start).
 * Numbers are hashed PCG (Jarzynski and Olano 2020, "Hash Functions for GPU Rendering": pcg's
 * output permutation of a linear congruential step); independent per dimension. Or scrambled
 * Sobol (rp_render_desc.sampler): Burley 2020, "Practical Hash-based Owen Scrambling": the first
 * four Sobol dimensions (Joe and Kuo's direction numbers), the dimensions taken four at a time,
 * each group with its own shuffle of the sample index and each dimension its own Owen scramble
 * (nested uniform scrambling by the Laine-Karras hash), seeded by the pixel. */
#include "render.h"

static inline uint32_t pcg_hash(uint32_t v) { return render_pcg_hash(v); }

render_sampler sampler_start(uint32_t x, uint32_t y, uint32_t sample) {
    render_sampler s = {.key = pcg_hash(x + pcg_hash(y + pcg_hash(sample + 0x68e31da4u))), .dim = 0};
    return s;
}

render_sampler sampler_start_pixel(rp_sampler_type type, uint32_t x, uint32_t y, uint32_t sample) {
    if (type != RP_SAMPLER_SOBOL) return sampler_start(x, y, sample);
    render_sampler s = {.key = pcg_hash(x + pcg_hash(y + 0x2545f491u)), .index = sample, .sobol = true};
    return s;
}

/* Direction numbers of Sobol dimensions 0-3 (dimension 0: van der Corput; then Joe and Kuo's
 * primitive polynomials x + 1, x^2 + x + 1, x^3 + x + 1 with m = 1; 1, 3; 1, 3, 1). */
static const uint32_t SOBOL_V[4][32] = {
    {0x80000000u, 0x40000000u, 0x20000000u, 0x10000000u, 0x08000000u, 0x04000000u, 0x02000000u, 0x01000000u,
     0x00800000u, 0x00400000u, 0x00200000u, 0x00100000u, 0x00080000u, 0x00040000u, 0x00020000u, 0x00010000u,
     0x00008000u, 0x00004000u, 0x00002000u, 0x00001000u, 0x00000800u, 0x00000400u, 0x00000200u, 0x00000100u,
     0x00000080u, 0x00000040u, 0x00000020u, 0x00000010u, 0x00000008u, 0x00000004u, 0x00000002u, 0x00000001u},
    {0x80000000u, 0xc0000000u, 0xa0000000u, 0xf0000000u, 0x88000000u, 0xcc000000u, 0xaa000000u, 0xff000000u,
     0x80800000u, 0xc0c00000u, 0xa0a00000u, 0xf0f00000u, 0x88880000u, 0xcccc0000u, 0xaaaa0000u, 0xffff0000u,
     0x80008000u, 0xc000c000u, 0xa000a000u, 0xf000f000u, 0x88008800u, 0xcc00cc00u, 0xaa00aa00u, 0xff00ff00u,
     0x80808080u, 0xc0c0c0c0u, 0xa0a0a0a0u, 0xf0f0f0f0u, 0x88888888u, 0xccccccccu, 0xaaaaaaaau, 0xffffffffu},
    {0x80000000u, 0xc0000000u, 0x60000000u, 0x90000000u, 0xe8000000u, 0x5c000000u, 0x8e000000u, 0xc5000000u,
     0x68800000u, 0x9cc00000u, 0xee600000u, 0x55900000u, 0x80680000u, 0xc09c0000u, 0x60ee0000u, 0x90550000u,
     0xe8808000u, 0x5cc0c000u, 0x8e606000u, 0xc5909000u, 0x6868e800u, 0x9c9c5c00u, 0xeeee8e00u, 0x5555c500u,
     0x8000e880u, 0xc0005cc0u, 0x60008e60u, 0x9000c590u, 0xe8006868u, 0x5c009c9cu, 0x8e00eeeeu, 0xc5005555u},
    {0x80000000u, 0xc0000000u, 0x20000000u, 0x50000000u, 0xf8000000u, 0x74000000u, 0xa2000000u, 0x93000000u,
     0xd8800000u, 0x25400000u, 0x59e00000u, 0xe6d00000u, 0x78080000u, 0xb40c0000u, 0x82020000u, 0xc3050000u,
     0x208f8000u, 0x51474000u, 0xfbea2000u, 0x75d93000u, 0xa0858800u, 0x914e5400u, 0xdbe79e00u, 0x25db6d00u,
     0x58800080u, 0xe54000c0u, 0x79e00020u, 0xb6d00050u, 0x800800f8u, 0xc00c0074u, 0x200200a2u, 0x50050093u},
};

static uint32_t reverse_bits(uint32_t x) {
    x = (x << 16) | (x >> 16);
    x = ((x & 0x00ff00ffu) << 8) | ((x & 0xff00ff00u) >> 8);
    x = ((x & 0x0f0f0f0fu) << 4) | ((x & 0xf0f0f0f0u) >> 4);
    x = ((x & 0x33333333u) << 2) | ((x & 0xccccccccu) >> 2);
    return ((x & 0x55555555u) << 1) | ((x & 0xaaaaaaaau) >> 1);
}

/* Owen scrambling of the bits of x, most significant first (Burley 2020, the Laine-Karras hash on
 * the reversed bits). */
static uint32_t nested_uniform_scramble(uint32_t x, uint32_t seed) {
    x = reverse_bits(x);
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return reverse_bits(x);
}

static float sobol_owen(uint32_t index, uint32_t dim, uint32_t seed) {
    uint32_t group = pcg_hash(seed ^ pcg_hash(dim >> 2 | 0x80000000u)), d = dim & 3u;
    uint32_t i = nested_uniform_scramble(index, group), x = 0;
    for (uint32_t b = 0; i; b++, i >>= 1)
        if (i & 1u) x ^= SOBOL_V[d][b];
    x = nested_uniform_scramble(x, pcg_hash(group + d));
    return (float)(x >> 8) * (1.0f / 16777216.0f);
}

float sampler_sobol_at(const render_sampler *s, uint32_t d) { return sobol_owen(s->index, d, s->key); }
