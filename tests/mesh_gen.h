/* Meshes generated for tests: random triangle soups and closed tessellated spheres. */
#ifndef RP_MESH_GEN_H
#define RP_MESH_GEN_H
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

typedef struct test_mesh {
    float *v;      /* 3 per vertex */
    uint32_t *idx; /* 3 per triangle */
    uint32_t nv, nt;
} test_mesh;

/* Deterministic generator (PCG32). */
typedef struct test_rng {
    uint64_t s;
} test_rng;
static inline uint32_t test_rng_u32(test_rng *r) {
    uint64_t old = r->s;
    r->s = old * 6364136223846793005ull + 1442695040888963407ull;
    uint32_t x = (uint32_t)(((old >> 18u) ^ old) >> 27u), rot = (uint32_t)(old >> 59u);
    return (x >> rot) | (x << ((-rot) & 31));
}
static inline float test_rng_float(test_rng *r) { return (float)(test_rng_u32(r) >> 8) * (1.0f / 16777216.0f); }

static inline void test_mesh_free(test_mesh *m) {
    free(m->v);
    free(m->idx);
    m->v = NULL, m->idx = NULL, m->nv = m->nt = 0;
}

/* n random triangles of size about `size` in the unit cube. */
static inline test_mesh test_mesh_soup(uint32_t n, float size, uint64_t seed) {
    test_rng r = {seed};
    test_mesh m = {malloc(sizeof(float) * 9 * n), malloc(sizeof(uint32_t) * 3 * n), 3 * n, n};
    for (uint32_t t = 0; t < n; t++) {
        float c[3] = {test_rng_float(&r), test_rng_float(&r), test_rng_float(&r)};
        for (int k = 0; k < 3; k++) {
            for (int a = 0; a < 3; a++) m.v[9 * t + 3 * k + a] = c[a] + (test_rng_float(&r) - 0.5f) * size;
            m.idx[3 * t + k] = 3 * t + (uint32_t)k;
        }
    }
    return m;
}

/* Closed UV sphere (shared vertices, poles as single vertices) of radius rad around c. */
static inline test_mesh test_mesh_sphere(int rings, int segs, const float c[3], float rad) {
    uint32_t nv = (uint32_t)(2 + (rings - 1) * segs), nt = (uint32_t)(2 * segs * (rings - 1));
    test_mesh m = {malloc(sizeof(float) * 3 * nv), malloc(sizeof(uint32_t) * 3 * nt), nv, nt};
    uint32_t k = 0;
    m.v[0] = c[0], m.v[1] = c[1], m.v[2] = c[2] + rad; /* north pole */
    k = 1;
    for (int i = 1; i < rings; i++) {
        double th = M_PI * i / rings;
        for (int j = 0; j < segs; j++) {
            double ph = 2.0 * M_PI * j / segs;
            m.v[3 * k + 0] = c[0] + (float)(rad * sin(th) * cos(ph));
            m.v[3 * k + 1] = c[1] + (float)(rad * sin(th) * sin(ph));
            m.v[3 * k + 2] = c[2] + (float)(rad * cos(th));
            k++;
        }
    }
    uint32_t south = k;
    m.v[3 * k + 0] = c[0], m.v[3 * k + 1] = c[1], m.v[3 * k + 2] = c[2] - rad;
    uint32_t t = 0;
#define RING(i, j) (1u + (uint32_t)((i) - 1) * (uint32_t)segs + (uint32_t)((j) % segs))
    for (int j = 0; j < segs; j++) {
        m.idx[3 * t] = 0, m.idx[3 * t + 1] = RING(1, j), m.idx[3 * t + 2] = RING(1, j + 1), t++;
        m.idx[3 * t] = south, m.idx[3 * t + 1] = RING(rings - 1, j + 1), m.idx[3 * t + 2] = RING(rings - 1, j), t++;
    }
    for (int i = 1; i < rings - 1; i++)
        for (int j = 0; j < segs; j++) {
            m.idx[3 * t] = RING(i, j), m.idx[3 * t + 1] = RING(i + 1, j), m.idx[3 * t + 2] = RING(i + 1, j + 1), t++;
            m.idx[3 * t] = RING(i, j), m.idx[3 * t + 1] = RING(i + 1, j + 1), m.idx[3 * t + 2] = RING(i, j + 1), t++;
        }
#undef RING
    m.nt = t;
    return m;
}
#endif
