/* Scalar vectors and boxes. */
#ifndef RP_VEC_H
#define RP_VEC_H

#include <math.h>
#include <stdbool.h>

typedef struct vec3 {
    float x, y, z;
} vec3;

typedef struct box3 {
    vec3 lo, hi;
} box3;

static inline vec3 v3(float x, float y, float z) { return (vec3){x, y, z}; }
static inline vec3 v3_add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline vec3 v3_sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline vec3 v3_mul(vec3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline vec3 v3_min(vec3 a, vec3 b) {
    return v3(a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z);
}
static inline vec3 v3_max(vec3 a, vec3 b) {
    return v3(a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z);
}
static inline float v3_get(vec3 a, int axis) { return axis == 0 ? a.x : axis == 1 ? a.y : a.z; }
static inline float v3_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline vec3 v3_cross(vec3 a, vec3 b) {
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline bool v3_finite(vec3 a) { return isfinite(a.x) && isfinite(a.y) && isfinite(a.z); }
static inline bool v3_eq(vec3 a, vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

static inline box3 box3_empty(void) {
    return (box3){v3(INFINITY, INFINITY, INFINITY), v3(-INFINITY, -INFINITY, -INFINITY)};
}
static inline box3 box3_union(box3 a, box3 b) { return (box3){v3_min(a.lo, b.lo), v3_max(a.hi, b.hi)}; }
static inline box3 box3_extend(box3 a, vec3 p) { return (box3){v3_min(a.lo, p), v3_max(a.hi, p)}; }
static inline bool box3_is_empty(box3 a) { return !(a.lo.x <= a.hi.x); }
/* Half the surface area (the SAH only needs ratios); 0 for empty boxes. Computed in double so
 * huge coordinates do not overflow to inf. */
static inline double box3_half_area(box3 a) {
    if (box3_is_empty(a)) return 0.0;
    double dx = (double)a.hi.x - a.lo.x, dy = (double)a.hi.y - a.lo.y, dz = (double)a.hi.z - a.lo.z;
    return dx * dy + dy * dz + dz * dx;
}

#endif
