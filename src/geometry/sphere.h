/* Ray-sphere intersection. */
#ifndef RP_SPHERE_H
#define RP_SPHERE_H
#include <stdbool.h>

/* Nearest t in [tnear, tfar] where the ray meets the sphere, using the numerically stable form
 * of the quadratic (Hearn-Baker / Ray Tracing Gems ch. 7). */
bool sphere_intersect(const float org[3], const float dir[3], float tnear, float tfar, const float center[3],
                      float radius, float *t_out);
#endif
