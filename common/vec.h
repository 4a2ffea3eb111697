/* vec.h: three-component double vectors, inline.  Used by the camera, the tracer and shading.
 * Everything is plain double arithmetic (no FMA contraction: see the Makefile) so results are
 * the same on every machine. */
#ifndef TF_VEC_H
#define TF_VEC_H
#include <math.h>

typedef struct tf_vec3 { double x, y, z; } tf_vec3;

static inline tf_vec3 v3(double x, double y, double z) { tf_vec3 r = {x, y, z}; return r; }
static inline tf_vec3 v3_add(tf_vec3 a, tf_vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline tf_vec3 v3_sub(tf_vec3 a, tf_vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline tf_vec3 v3_mul(tf_vec3 a, tf_vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline tf_vec3 v3_scale(tf_vec3 a, double s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline double  v3_dot(tf_vec3 a, tf_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline tf_vec3 v3_cross(tf_vec3 a, tf_vec3 b)
{
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double  v3_len(tf_vec3 a) { return sqrt(v3_dot(a, a)); }
static inline tf_vec3 v3_norm(tf_vec3 a)
{
    double l = v3_len(a);
    return l > 0 ? v3_scale(a, 1.0 / l) : a;
}
static inline tf_vec3 v3_lerp(tf_vec3 a, tf_vec3 b, double t)
{
    return v3(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t);
}

#endif
