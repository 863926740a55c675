/* Bounding frusta of large ray packets (Overbeck et al. 2008, sec. 4): four side planes that every
 * ray of a packet stays inside, between a near and a far rectangle across the packet's dominant
 * axis k. Primary and shadow frusta have an apex (sec. 4.1, 4.2: the near rectangle is a point, the
 * far one the slopes (u, v) / k at distance 1); reflection and refraction frusta span the origins'
 * near plane and the scene's far plane (sec. 4.3). The kernels gather the rectangles with SIMD
 * (packet_n.inc); the planes are made here. Every frustum is widened by margins larger than the
 * rounding of rays and of the plane tests, so culling never removes a hit (the tests check this
 * ray by ray). */
#ifndef RP_FRUSTUM_H
#define RP_FRUSTUM_H

#include <stdbool.h>
#include <stdint.h>

#include "raypack.h"

typedef struct frustum {
    bool valid;       /* false: nothing bounds the packet, so nothing is culled */
    bool cone;        /* an apex frustum: every ray's line passes through apex (within rounding) */
    float apex[3];
    float n[4][3];    /* plane normals (unit length); inside: n . p + d >= 0 */
    float d[4];
    float tol;        /* a point is outside a plane when n . p + d < -tol */
    int near_k;       /* the near plane across the dominant axis: every point of every ray has */
    float near_s;     /* near_s * p[near_k] >= near_d (apex frusta: the apex's plane; near/far */
    float near_d;     /* frusta: the rearmost origin's); boxes wholly behind it are culled */
} frustum;

/* What a kernel needs to build a packet's frustum. */
typedef struct frustum_req {
    rp_frustum_kind kind;
    float point[3];   /* shadow: the common end point */
    float scale;      /* largest coordinate magnitude of the scene (and the point): the rounding scale */
    float lo[3], hi[3]; /* the scene's bounds (sec. 4.3's far plane) */
    float auto_span;    /* auto traversal: the largest direction spread traced with Span */
    float auto_simd;    /* ... and the largest always traced as a packet (infinite: all) */
    const rp_auto_tally *tally; /* ... and what it learned of the classes it cannot settle (NULL:
                                   their fixed ways; packet_n.h, auto_way) */
} frustum_req;

/* The u and v axes across dominant axis k. */
static inline void frustum_axes(int k, int *iu, int *iv) {
    *iu = k == 0 ? 1 : 0;
    *iv = k == 2 ? 1 : 2;
}

/* Apex frustum: the cone from apex through slopes [lo, hi] (of (u, v) per unit of s * k); sets
 * cone and apex. */
void frustum_apex(frustum *f, const float apex[3], int k, float s, const float lo[2], const float hi[2], float scale);
/* Near/far frustum (sec. 4.3): rectangle r0 on the plane s * p_k = k0 (behind every origin), r1 on
 * s * p_k = k1 > k0 (beyond the scene). */
void frustum_near_far(frustum *f, int k, float s, float k0, float k1, const float lo0[2], const float hi0[2],
                      const float lo1[2], const float hi1[2], float scale);
/* Fills the scene's part of a request. */
void frustum_req_init(frustum_req *q, rp_frustum_kind kind, const float point[3], const rp_bounds *scene);

/* True when the box [lo, hi] lies outside one plane of the frustum (the near plane included: a
 * box behind the apex can straddle all four side planes). */
static inline bool frustum_culls_box(const frustum *f, const float lo[3], const float hi[3]) {
    if (f->near_s * (f->near_s > 0.0f ? hi[f->near_k] : lo[f->near_k]) < f->near_d - f->tol) return true;
    for (int i = 0; i < 4; i++) {
        const float *n = f->n[i];
        float x = n[0] >= 0.0f ? hi[0] : lo[0];
        float y = n[1] >= 0.0f ? hi[1] : lo[1];
        float z = n[2] >= 0.0f ? hi[2] : lo[2];
        if (n[0] * x + n[1] * y + n[2] * z + f->d[i] < -f->tol) return true;
    }
    return false;
}

#endif
