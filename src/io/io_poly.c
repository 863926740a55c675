/* Polygon triangulation for every loader. Most polygons are convex (quads, SPD patches) and take a
 * fan; concave ones (the 144-sided gears of SPD) need ear clipping, which a fan gets wrong. */
#include <math.h>

#include "io/io_internal.h"

/* Ear clipping is O(n^2) and worse on adversarial input: above this size a concave polygon gets a
 * fan instead, so a hostile file cannot hang the loader. */
#define POLY_EAR_MAX 1024u

static double cross2(const double *a, const double *b, const double *c) {
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

static void fan(uint32_t n, uint32_t *tris) {
    for (uint32_t i = 1; i + 1 < n; i++) {
        tris[3 * (i - 1)] = 0;
        tris[3 * (i - 1) + 1] = i;
        tris[3 * (i - 1) + 2] = i + 1;
    }
}

/* p inside or on triangle abc (counter-clockwise). */
static bool in_triangle(const double *a, const double *b, const double *c, const double *p) {
    return cross2(a, b, p) >= 0.0 && cross2(b, c, p) >= 0.0 && cross2(c, a, p) >= 0.0;
}

void poly_triangulate(const float *pts, uint32_t n, uint32_t *tris, uint32_t *scratch) {
    if (n < 3) return;
    if (n == 3) {
        tris[0] = 0, tris[1] = 1, tris[2] = 2;
        return;
    }
    /* Newell normal: its largest axis is the one to drop to project the polygon onto a plane. */
    double nx = 0, ny = 0, nz = 0;
    for (uint32_t i = 0; i < n; i++) {
        const float *a = pts + 3 * i, *b = pts + 3 * ((i + 1) % n);
        nx += ((double)a[1] - b[1]) * ((double)a[2] + b[2]);
        ny += ((double)a[2] - b[2]) * ((double)a[0] + b[0]);
        nz += ((double)a[0] - b[0]) * ((double)a[1] + b[1]);
    }
    int axis = fabs(nx) > fabs(ny) ? (fabs(nx) > fabs(nz) ? 0 : 2) : (fabs(ny) > fabs(nz) ? 1 : 2);
    int u = (axis + 1) % 3, v = (axis + 2) % 3;
    double sign = (axis == 0 ? nx : axis == 1 ? ny : nz) < 0 ? -1.0 : 1.0;

    /* Convex (every turn left or straight) -> fan. */
    bool convex = true;
    for (uint32_t i = 0; i < n && convex; i++) {
        const float *a = pts + 3 * i, *b = pts + 3 * ((i + 1) % n), *c = pts + 3 * ((i + 2) % n);
        double pa[2] = {a[u], a[v]}, pb[2] = {b[u], b[v]}, pc[2] = {c[u], c[v]};
        if (sign * cross2(pa, pb, pc) < 0.0) convex = false;
    }
    if (convex || n > POLY_EAR_MAX) {
        fan(n, tris);
        return;
    }

    /* Ear clipping on the projected, counter-clockwise polygon; the caller's
     * scratch holds the n-entry index ring. */
    uint32_t *ring = scratch;
    double *xy = NULL;
    double local[2 * 64];
    double *heap = NULL;
    if (n <= 64) {
        xy = local;
    } else {
        heap = io_malloc(2 * (size_t)n * sizeof(double));
        if (!heap) {
            fan(n, tris);
            return;
        }
        xy = heap;
    }
    for (uint32_t i = 0; i < n; i++) {
        ring[i] = i;
        xy[2 * i] = pts[3 * i + u];
        xy[2 * i + 1] = sign * pts[3 * i + v]; /* mirror clockwise projections to counter-clockwise */
    }
    uint32_t m = n, out = 0, i = 0, misses = 0;
    while (m > 3) {
        uint32_t ip = (i + m - 1) % m, in = (i + 1) % m;
        const double *a = xy + 2 * ring[ip], *b = xy + 2 * ring[i], *c = xy + 2 * ring[in];
        bool ear = cross2(a, b, c) > 0.0;
        for (uint32_t k = 0; ear && k < m; k++) {
            if (k == ip || k == i || k == in) continue;
            const double *p = xy + 2 * ring[k];
            if ((p[0] == a[0] && p[1] == a[1]) || (p[0] == b[0] && p[1] == b[1]) ||
                (p[0] == c[0] && p[1] == c[1]))
                continue; /* a vertex repeated at a corner does not block the ear */
            if (in_triangle(a, b, c, p)) ear = false;
        }
        if (!ear && ++misses < m) {
            i = (i + 1) % m;
            continue;
        }
        /* An ear, or none left (degenerate or self-intersecting input): clip anyway so the output
         * still has n - 2 triangles. */
        tris[out++] = ring[ip];
        tris[out++] = ring[i];
        tris[out++] = ring[in];
        memmove(ring + i, ring + i + 1, (m - i - 1) * sizeof(uint32_t));
        m--;
        misses = 0;
        if (i >= m) i = 0;
        else if (i > 0) i--; /* the previous vertex may have become an ear */
    }
    tris[out++] = ring[0];
    tris[out++] = ring[1];
    tris[out++] = ring[2];
    free(heap);
}
