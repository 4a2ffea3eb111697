/* noise_kernel.h: the arithmetic of tf_hash64 and of 2D gradient noise, written once for C and
 * OpenCL C (common/portable.h): noise.h and noise_impl.h build the C noise on it, and the
 * OpenCL build (worker/backend_opencl.c) loads this file so the kernels' texture noise and
 * lattice jitter run the same operations eight samples at a time.
 *
 * What is here is what both sides compute alike: the hash, the quintic fade and its slope, the
 * floor split of a coordinate, the y half of a 2D evaluation, a lattice column's line from its
 * two corner gradients and that line's derivative along y, and the blend of two column lines,
 * alone or with the noise's exact gradient (the textures' bump).  What is not: the lattice lookups (the
 * permutation and gradient tables are C arrays on one side and per-lane gathers on the other;
 * noise_impl.h and packet_shade.cl) and the octave loops.
 * noise_impl.h explains the noise itself. */
#ifndef TF_NOISE_KERNEL_H
#define TF_NOISE_KERNEL_H

#ifndef __OPENCL_VERSION__
#include "portable.h"
#endif

/* Beyond 2^52 a double has no fractional part: the lattice is meaningless there (and the
 * conversion to an integer would overflow for inf / NaN).  Noise is 0 outside this range. */
#define TF_NOISE_COORD_LIMIT 0x1p52
/* sqrt(2) and sqrt(2/3) rounded down in the 5th digit: see the range note in noise_impl.h. */
#define TF_NOISE2_SCALE 1.41421
#define TF_NOISE3_SCALE 0.816496
/* The permutation: 0..TF_NOISE_LATTICE-1, stored twice (TF_NOISE_PERM entries). */
#define TF_NOISE_LATTICE 256
#define TF_NOISE_PERM (2 * TF_NOISE_LATTICE)
/* 16 unit 2D gradients 22.5 degrees apart, by their constants cos/sin 22.5, 45 degrees: a
 * table of constants (not cos/sin at run time) so every libm gives the same bits. */
#define TF_NOISE_GRADS 16
#define TF_C1 0.92387953251128674
#define TF_S1 0.38268343236508977
#define TF_H1 0.70710678118654752

/* A 64-bit integer hash (splitmix64 finaliser) and a uniform double in [0,1) from it: the one
 * source of deterministic "randomness" everywhere (generators, jitter). */
TF_SHARED tf_lane_u64 tf_hash64(tf_lane_u64 x)
{
    x += 0x9e3779b97f4a7c15UL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9UL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebUL;
    return x ^ (x >> 31);
}

TF_SHARED tf_lane tf_hash_unit(tf_lane_u64 x)
{
    return TF_U64_TO_LANE(tf_hash64(x) >> 11) * 0x1.0p-53;
}

/* Perlin's 2002 quintic fade. */
TF_SHARED_HOT TF_SHARED tf_lane tf_fade(tf_lane t)
{
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}

/* The fade's derivative, 30 t^2 (t - 1)^2, expanded as tf_fade is. */
TF_SHARED_HOT TF_SHARED tf_lane tf_fade_slope(tf_lane t)
{
    return t * t * (t * (t * 30.0 - 60.0) + 30.0);
}

/* floor() for |x| < TF_NOISE_COORD_LIMIT without the libm call: truncate, then step down for
 * negative non-integers.  *fraction = x - floor(x).  One int->double conversion only (the
 * conversions were the hottest instructions of the terrain's row loop), and the step down is
 * done on the double too, which is exact below 2^53, so the bits equal x - (double)floor(x). */
TF_SHARED_HOT TF_SHARED tf_lane_i64 tf_floor_split(tf_lane x, tf_lane *fraction)
{
    tf_lane_i64 i = TF_LANE_TO_I64(x);
    tf_lane d = TF_I64_TO_LANE(i);
    tf_mask below = x < d;
    *fraction = x - (d - TF_SEL(0.0, 1.0, below));
    return i - TF_MASK_ONE(below);
}

/* The y half of a 2D noise evaluation.  ok == 0 marks an out-of-range y (noise is then 0). */
typedef struct tf_noise_axis {
    tf_lane_int lattice; /* floor(y) & (TF_NOISE_LATTICE - 1) */
    tf_mask ok;
    tf_lane f0, f1;      /* y - floor(y), and that minus 1 */
    tf_lane fade;        /* tf_fade(f0) */
} tf_noise_axis;

TF_SHARED_HOT TF_SHARED tf_noise_axis tf_noise_axis_of(tf_lane y)
{
    tf_noise_axis a;
    tf_lane unused;
    a.ok = fabs(y) < TF_NOISE_COORD_LIMIT;
    tf_lane_i64 yi = TF_SELI64(0, tf_floor_split(TF_SEL(0.0, y, a.ok), &unused), a.ok);
    a.lattice = TF_I64_TO_INT(yi & (TF_NOISE_LATTICE - 1));
    a.f0 = TF_SEL(0.0, y - TF_I64_TO_LANE(yi), a.ok);
    a.f1 = a.f0 - 1.0;
    a.fade = tf_fade(a.f0);
    return a;
}

/* The noise along one lattice column X with the y half fixed: the two corners (X, Y) and
 * (X, Y + 1), gradients g0 and g1, blend by the y fade into the line slope * (x - X) +
 * intercept (f0 = y - Y, f1 = f0 - 1). */
typedef struct tf_noise_column {
    tf_lane slope, intercept;
} tf_noise_column;

TF_SHARED_HOT TF_SHARED tf_noise_column tf_noise_column_line(tf_lane g0x, tf_lane g0y,
                                                             tf_lane g1x, tf_lane g1y,
                                                             tf_lane f0, tf_lane f1,
                                                             tf_lane fade)
{
    tf_lane e0 = g0y * f0, e1 = g1y * f1;
    tf_noise_column c;
    c.slope = g0x + fade * (g1x - g0x);
    c.intercept = e0 + fade * (e1 - e0);
    return c;
}

/* Noise at x offset fx (fade u = tf_fade(fx)) from the column `left`, `right` the next one. */
TF_SHARED_HOT TF_SHARED tf_lane tf_noise_blend_faded(tf_lane fx, tf_lane u, tf_noise_column left,
                                                     tf_noise_column right)
{
    tf_lane l = left.slope * fx + left.intercept;
    tf_lane r = right.slope * (fx - 1.0) + right.intercept;
    return (l + u * (r - l)) * TF_NOISE2_SCALE;
}

/* A column line's derivative along y: tf_noise_column_line's slope and intercept
 * differentiated by y (f0 and f1 move with y, the fade by dfade = tf_fade_slope(f0)). */
TF_SHARED_HOT TF_SHARED tf_noise_column tf_noise_column_dy(tf_lane g0x, tf_lane g0y, tf_lane g1x,
                                                           tf_lane g1y, tf_lane f0, tf_lane f1,
                                                           tf_lane fade, tf_lane dfade)
{
    tf_lane e0 = g0y * f0, e1 = g1y * f1;
    tf_noise_column c;
    c.slope = dfade * (g1x - g0x);
    c.intercept = g0y + dfade * (e1 - e0) + fade * (g1y - g0y);
    return c;
}

/* Noise at x offset fx and its gradient, exact (not by differences): the value is
 * tf_noise_blend_faded(fx, u, left, right), bit for bit; du = tf_fade_slope(fx), and left_dy,
 * right_dy are the columns' tf_noise_column_dy.  *dx and *dy are per lattice unit. */
TF_SHARED_HOT TF_SHARED tf_lane tf_noise_blend_gradient(tf_lane fx, tf_lane u, tf_lane du,
                                                        tf_noise_column left, tf_noise_column right,
                                                        tf_noise_column left_dy,
                                                        tf_noise_column right_dy, tf_lane *dx,
                                                        tf_lane *dy)
{
    tf_lane l = left.slope * fx + left.intercept;
    tf_lane r = right.slope * (fx - 1.0) + right.intercept;
    tf_lane ly = left_dy.slope * fx + left_dy.intercept;
    tf_lane ry = right_dy.slope * (fx - 1.0) + right_dy.intercept;
    *dx = (left.slope + du * (r - l) + u * (right.slope - left.slope)) * TF_NOISE2_SCALE;
    *dy = (ly + u * (ry - ly)) * TF_NOISE2_SCALE;
    return (l + u * (r - l)) * TF_NOISE2_SCALE;
}

#endif
