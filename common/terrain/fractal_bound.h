/* fractal_bound.h: conservative bounds of Musgrave's terrain functions over a square, by
 * interval arithmetic on the noise (dissertation 6.3.2.2.1): what lets the procedural tracer
 * (render/trace_procedural.c) skip a part of the world its ray passes above without evaluating
 * a single sample there.
 *
 * Noise over a box.  Inside one lattice cell the gradient noise is a fade-weighted (convex)
 * blend of its four corners' linear functions g . (p - corner) (noise_impl.h), so over a box it
 * lies between the least and the greatest of those four linear functions over the box, which
 * interval arithmetic gives exactly; a box over several cells takes the union over them, and
 * a box over many cells the noise's whole range [-1, 1].
 *
 * A terrain over a box.  Each octave's noise interval goes through the generator's own
 * formulas (fBm sum, hetero's product, hybrid's and ridged's clamped weights) in interval
 * arithmetic.  The procedural terrain evaluates each level of detail with its own, possibly
 * fractional, octave count; tf_fractal_bound bounds every plan whose count lies in [lo, hi]:
 * the value of a plan of w whole octaves and a fraction r lies between the values after w and
 * after w + 1 whole octaves (each formula is linear in the last octave's weight), so the bound
 * is the hull of the running intervals over those prefixes.
 *
 * Every result is widened by far more than the rounding of the point evaluation, so the bound
 * holds for the bits tf_fractal_eval returns (tests/unit/test_fractal_bound.c tries it on
 * random boxes). */
#ifndef TF_FRACTAL_BOUND_H
#define TF_FRACTAL_BOUND_H

#include "terrain/fractal.h"

typedef struct tf_interval {
    double lo, hi;
} tf_interval;

/* Bound of tf_noise2 over the noise-space box [x0, x1] x [y0, y1] (x0 <= x1, y0 <= y1). */
tf_interval tf_noise2_bound(const tf_noise *nz, double x0, double x1, double y0, double y1);

/* The weights of every octave at full strength, for tf_fractal_bound (made once). */
void tf_fractal_bound_plan(tf_octaves *full, const tf_fractal *f);

/* Bound of the generator output (dimensionless, as tf_fractal_eval) over the world box
 * [x0, x1] x [y0, y1], for every octave count in [octaves_lo, octaves_hi] with f's H,
 * lacunarity, offset and gain (f's own octave count is not used); `full` is
 * tf_fractal_bound_plan's. */
tf_interval tf_fractal_bound(const tf_fractal *f, const tf_octaves *full, const tf_noise *nz,
                             double x0, double x1, double y0, double y1, double octaves_lo,
                             double octaves_hi);

#endif
