/* Point clouds: a scene with vertices and nothing else (a PLY with a vertex element and no faces,
 * an OBJ of `v` lines alone) is a point cloud, and each finite vertex becomes a sphere of the
 * default material (of the vertex's colour, where the file gives colours) (RTfact's point-cloud rendering, here with the core's spheres, so every
 * structure, integrator and tool takes it as it is). The radius is the caller's, else half the
 * median distance from a vertex to its nearest neighbour, over up to POINT_SAMPLES vertices spread
 * through the file: the spheres of a regularly sampled surface then touch and close it. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "io/io_internal.h"

/* Vertices whose nearest neighbour is sought for the automatic radius: O(POINT_SAMPLES * n). */
#define POINT_SAMPLES 64

static int float_less(const void *a, const void *b) {
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

static bool finite3(const float *p) { return isfinite(p[0]) && isfinite(p[1]) && isfinite(p[2]); }

/* Half the median nearest-neighbour distance of the samples; 0 when there is no pair apart. */
static float auto_radius(const float *pos, size_t n) {
    float d[POINT_SAMPLES];
    size_t m = 0, step = n / POINT_SAMPLES ? n / POINT_SAMPLES : 1;
    for (size_t s = 0; s < n && m < POINT_SAMPLES; s += step) {
        const float *p = &pos[3 * s];
        if (!finite3(p)) continue;
        float best = INFINITY;
        for (size_t i = 0; i < n; i++) {
            const float *q = &pos[3 * i];
            float dx = q[0] - p[0], dy = q[1] - p[1], dz = q[2] - p[2], d2 = dx * dx + dy * dy + dz * dz;
            if (d2 > 0.0f && d2 < best) best = d2; /* NaN and duplicates never win */
        }
        if (best < INFINITY) d[m++] = sqrtf(best);
    }
    if (m == 0) return 0.0f;
    qsort(d, m, sizeof *d, float_less);
    return 0.5f * d[m / 2];
}

bool io_points_to_spheres(rp_scene_data *s, float radius) {
    size_t n = s->vertex_count, live = 0;
    for (size_t i = 0; i < n; i++) live += finite3(&s->positions[3 * i]);
    if (live == 0) return true;
    if (!(radius > 0.0f && radius < INFINITY)) radius = auto_radius(s->positions, n);
    if (!(radius > 0.0f)) { /* a single point, or all at one place: a size from the coordinates */
        float mag = 0.0f;
        for (size_t i = 0; i < n; i++)
            if (finite3(&s->positions[3 * i]))
                for (int k = 0; k < 3; k++) mag = fmaxf(mag, fabsf(s->positions[3 * i + k]));
        radius = mag > 0.0f ? mag * 1e-3f : 1e-3f;
    }
    rp_sphere_data *sp = io_malloc(live * sizeof *sp);
    float *col = s->colors ? io_malloc(3 * live * sizeof *col) : NULL;
    if (!sp || (s->colors && !col)) {
        free(sp);
        free(col);
        return false;
    }
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        const float *p = &s->positions[3 * i];
        if (!finite3(p)) continue;
        if (col) memcpy(col + 3 * k, s->colors + 3 * i, 3 * sizeof(float));
        sp[k++] = (rp_sphere_data){{p[0], p[1], p[2]}, radius, 0};
    }
    s->sphere_colors = col;
    s->spheres = sp;
    s->sphere_count = live;
    return true;
}
