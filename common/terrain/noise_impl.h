/* noise_impl.h: the inner kernels of gradient noise, shared by noise.c (the public tf_noise2/3
 * and tf_fbm2/3) and fractal.c (the terrains).  Private to those two files.
 *
 * Why a header of static inline functions: the terrain builder evaluates one row of the height
 * field at a time, and along a row the y coordinate of every octave is the same for all
 * samples.  tf_noise_axis holds the y half of a 2D noise evaluation (lattice row, fraction,
 * fade) so it is computed once per row and octave instead of once per sample.  The point
 * functions go through exactly the same inline code, so a row and a point evaluation perform
 * the same floating-point operations in the same order and give the same bits.
 *
 * Noise definition (Perlin's gradient noise, Musgrave 2.3.1, with Perlin's 2002 quintic fade):
 * at each lattice point a gradient chosen by hashing the integer coordinates through the seeded
 * permutation; the value is the fade-weighted blend of the corners' g . (p - corner).  The value
 * is 0 at every lattice point.  Range: for unit gradients |N| <= sum_c w_c |p - c|, whose
 * maximum over the cell is at its centre: sqrt(n)/2 (checked numerically for the quintic fade,
 * 2D and 3D).  The final scales map that bound to slightly less than 1, so |N| < 1 with a margin
 * far larger than any rounding error. */
#ifndef TF_NOISE_IMPL_H
#define TF_NOISE_IMPL_H

#include <math.h>
#include <stdint.h>
#include "terrain/noise.h"

/* The constants (TF_NOISE_COORD_LIMIT, TF_NOISE2_SCALE, the gradients' TF_C1, TF_S1, TF_H1),
 * tf_fade, tf_noise_column and the column and blend arithmetic are in noise_kernel.h, which the
 * OpenCL kernels share. */

/* 16 unit gradients evenly spaced on the circle (22.5 degrees apart): nearly isotropic. */
static const double tf_grad2[TF_NOISE_GRADS][2] = {
    {1, 0},       {TF_C1, TF_S1},   {TF_H1, TF_H1},   {TF_S1, TF_C1},
    {0, 1},       {-TF_S1, TF_C1},  {-TF_H1, TF_H1},  {-TF_C1, TF_S1},
    {-1, 0},      {-TF_C1, -TF_S1}, {-TF_H1, -TF_H1}, {-TF_S1, -TF_C1},
    {0, -1},      {TF_S1, -TF_C1},  {TF_H1, -TF_H1},  {TF_C1, -TF_S1},
};

/* tf_floor_split, tf_noise_axis and tf_noise_axis_of: noise_kernel.h. */

static inline int64_t tf_floor_i64(double x)
{
    double fraction;
    return tf_floor_split(x, &fraction);
}

static inline void tf_noise_axis_set(tf_noise_axis *a, double y) { *a = tf_noise_axis_of(y); }

/* The noise along one lattice column (tf_noise_column, noise_kernel.h), from the gradients at
 * its two corners (tf_noise_column_grads).  Both the point kernel and the row evaluator build
 * the noise from these column lines, so they perform the same operations and agree to the bit. */
static inline void tf_noise_column_grads(const tf_noise *nz, int64_t xi, const tf_noise_axis *ay,
                                         const double **g0, const double **g1)
{
    const uint16_t *p = nz->perm;
    /* perm holds 0..255 twice, so perm[X] + Y + 1 <= 511 stays in bounds. */
    int a = p[xi & (TF_NOISE_LATTICE - 1)] + ay->lattice;
    *g0 = tf_grad2[p[a] & (TF_NOISE_GRADS - 1)];
    *g1 = tf_grad2[p[a + 1] & (TF_NOISE_GRADS - 1)];
}

static inline tf_noise_column tf_noise_column_at(const tf_noise *nz, int64_t xi,
                                                 const tf_noise_axis *ay)
{
    const double *g0, *g1;
    tf_noise_column_grads(nz, xi, ay, &g0, &g1);
    return tf_noise_column_line(g0[0], g0[1], g1[0], g1[1], ay->f0, ay->f1, ay->fade);
}

/* Noise at x offset fx from the column `left`, with `right` the next column. */
static inline double tf_noise_blend(double fx, tf_noise_column left, tf_noise_column right)
{
    return tf_noise_blend_faded(fx, tf_fade(fx), left, right);
}

/* 2D noise at (x, y) where `ay` was set from y. */
static inline double tf_noise2_axis(const tf_noise *nz, double x, const tf_noise_axis *ay)
{
    if (!(fabs(x) < TF_NOISE_COORD_LIMIT) || !ay->ok)
        return 0.0;
    double fx;
    int64_t xi = tf_floor_split(x, &fx);
    return tf_noise_blend(fx, tf_noise_column_at(nz, xi, ay),
                          tf_noise_column_at(nz, xi + 1, ay));
}

/* tf_noise_column_at's line in *line, and its derivative along y (noise_kernel.h's
 * tf_noise_column_dy) in *dy, with dfade = tf_fade_slope(ay->f0). */
static inline void tf_noise_column_pair_at(const tf_noise *nz, int64_t xi, const tf_noise_axis *ay,
                                           double dfade, tf_noise_column *line,
                                           tf_noise_column *dy)
{
    const double *g0, *g1;
    tf_noise_column_grads(nz, xi, ay, &g0, &g1);
    *line = tf_noise_column_line(g0[0], g0[1], g1[0], g1[1], ay->f0, ay->f1, ay->fade);
    *dy = tf_noise_column_dy(g0[0], g0[1], g1[0], g1[1], ay->f0, ay->f1, ay->fade, dfade);
}

/* tf_noise2_axis(nz, x, ay), bit for bit, and its exact gradient (per lattice unit) in *dx,
 * *dy; dfade = tf_fade_slope(ay->f0).  Where the noise is 0 for range, so is the gradient. */
static inline double tf_noise2_gradient_axis(const tf_noise *nz, double x,
                                             const tf_noise_axis *ay, double dfade, double *dx,
                                             double *dy)
{
    *dx = *dy = 0.0;
    if (!(fabs(x) < TF_NOISE_COORD_LIMIT) || !ay->ok)
        return 0.0;
    double fx;
    int64_t xi = tf_floor_split(x, &fx);
    tf_noise_column left, right, left_dy, right_dy;
    tf_noise_column_pair_at(nz, xi, ay, dfade, &left, &left_dy);
    tf_noise_column_pair_at(nz, xi + 1, ay, dfade, &right, &right_dy);
    return tf_noise_blend_gradient(fx, tf_fade(fx), tf_fade_slope(fx), left, right, left_dy,
                                   right_dy, dx, dy);
}

/* Octave plan shared by every spectral sum: amp[i] is the weight lacunarity^(-H i) of octave i
 * (amp[0] = 1), computed as pow(frequency, -H) with frequency multiplied up octave by octave as
 * in Musgrave's fBm(); the last entry carries the fractional remainder of `octaves` (2.3.2.1:
 * "if (i < 1.0) amplitude *= i").  `count` is the number of noise evaluations (>= 1). */
#define TF_MAX_OCTAVES 32
typedef struct tf_octaves {
    int count;
    double lacunarity;
    double amp[TF_MAX_OCTAVES + 1];
} tf_octaves;

/* The shape of a plan of `octaves` octaves, clamped to [1, TF_MAX_OCTAVES] (a NaN counts as
 * 1): *whole octaves at full weight and a *remainder fraction of one more; returns the number
 * of noise evaluations. */
static inline int tf_octaves_split(double octaves, int *whole, double *remainder)
{
    if (!(octaves >= 1.0))
        octaves = 1.0;
    if (octaves > TF_MAX_OCTAVES)
        octaves = TF_MAX_OCTAVES;
    *whole = (int)octaves;
    *remainder = octaves - *whole;
    return *whole + (*remainder > 0.0);
}

static inline void tf_octaves_plan(tf_octaves *o, double H, double lacunarity, double octaves)
{
    int whole;
    double remainder;
    o->lacunarity = lacunarity;
    o->count = tf_octaves_split(octaves, &whole, &remainder);
    double frequency = 1.0;
    o->amp[0] = 1.0;
    for (int i = 1; i < o->count; i++) {
        frequency *= lacunarity;
        o->amp[i] = pow(frequency, -H);
    }
    if (remainder > 0.0)
        o->amp[whole] *= remainder;
}

/* Fill axes[0 .. o->count-1] with the y halves of every octave of noise-space y. */
static inline void tf_octave_axes(const tf_octaves *o, double y, tf_noise_axis *axes)
{
    /* count >= 1 always (tf_octaves_plan); the do-while says so to the compiler too. */
    int i = 0;
    do {
        tf_noise_axis_set(&axes[i], y);
        y *= o->lacunarity;
    } while (++i < o->count);
}

/* fBm (Musgrave 2.3.2.1): sum of amp[i] * N(p * lacunarity^i). */
static inline double tf_fbm2_axes(const tf_noise *nz, const tf_octaves *o, double x,
                                  const tf_noise_axis *axes)
{
    double result = 0.0;
    for (int i = 0; i < o->count; i++) {
        result += o->amp[i] * tf_noise2_axis(nz, x, &axes[i]);
        x *= o->lacunarity;
    }
    return result;
}

/* tf_fbm2_axes, bit for bit, and the sum's exact gradient in *gx, *gy (per unit of x and y:
 * octave i's noise gradient weighted by amp[i] lacunarity^i). */
static inline double tf_fbm2_gradient_axes(const tf_noise *nz, const tf_octaves *o, double x,
                                           const tf_noise_axis *axes, double *gx, double *gy)
{
    double result = 0.0, sx = 0.0, sy = 0.0, frequency = 1.0;
    for (int i = 0; i < o->count; i++) {
        double dx, dy;
        double n = tf_noise2_gradient_axis(nz, x, &axes[i], tf_fade_slope(axes[i].f0), &dx, &dy);
        double w = o->amp[i] * frequency;
        result += o->amp[i] * n;
        sx += w * dx;
        sy += w * dy;
        x *= o->lacunarity;
        frequency *= o->lacunarity;
    }
    *gx = sx;
    *gy = sy;
    return result;
}

#endif
