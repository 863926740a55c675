#include "geometry/sphere.h"

#include <math.h>

bool sphere_intersect(const float org[3], const float dir[3], float tnear, float tfar, const float center[3],
                      float radius, float *t_out) {
    double f[3] = {(double)org[0] - center[0], (double)org[1] - center[1], (double)org[2] - center[2]};
    double d[3] = {dir[0], dir[1], dir[2]};
    double a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if (!(a > 0.0)) return false;
    double b = -(f[0] * d[0] + f[1] * d[1] + f[2] * d[2]);
    /* discriminant from the distance of the centre to the line, which loses no precision */
    double l[3] = {f[0] + b / a * d[0], f[1] + b / a * d[1], f[2] + b / a * d[2]};
    double r2 = (double)radius * radius;
    double disc = r2 - (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]);
    if (disc < 0.0) return false;
    double c = f[0] * f[0] + f[1] * f[1] + f[2] * f[2] - r2;
    double q = b + copysign(sqrt(a * disc), b);
    double t0 = q != 0.0 ? c / q : 0.0, t1 = q / a;
    if (t0 > t1) {
        double s = t0;
        t0 = t1, t1 = s;
    }
    if (t0 >= tnear && t0 <= tfar) {
        *t_out = (float)t0;
        return true;
    }
    if (t1 >= tnear && t1 <= tfar) {
        *t_out = (float)t1;
        return true;
    }
    return false;
}
