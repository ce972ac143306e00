/* vec3.h — the few 3-vector operations the effects' host code needs (double[3]), in one
 * place so the energy wave, its light rig and the compound eye cannot drift apart. */
#ifndef FX_VEC3_H
#define FX_VEC3_H

#include <math.h>

static inline double vec3_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* out = a × b (out may alias a or b). */
static inline void vec3_cross(const double a[3], const double b[3], double out[3])
{
    double r0 = a[1] * b[2] - a[2] * b[1], r1 = a[2] * b[0] - a[0] * b[2], r2 = a[0] * b[1] - a[1] * b[0];
    out[0] = r0;
    out[1] = r1;
    out[2] = r2;
}

/* Scales v to unit length (a zero vector stays zero); returns the length it had. */
static inline double vec3_normalize(double v[3])
{
    double n = sqrt(vec3_dot(v, v));
    if (n > 0)
        for (int k = 0; k < 3; k++) v[k] /= n;
    return n;
}

/* A unit vector normal to the unit vector n: n × (x or y, whichever is further from n). */
static inline void vec3_any_normal(const double n[3], double out[3])
{
    double helper[3] = {fabs(n[0]) < 0.9 ? 1.0 : 0.0, fabs(n[0]) < 0.9 ? 0.0 : 1.0, 0.0};
    vec3_cross(helper, n, out);
    vec3_normalize(out);
}

#endif
