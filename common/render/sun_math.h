/* sun_math.h: where a shadow ray is proved to stay above the terrain for good -- the query of
 * the sun's strips (render/sun_strips.h), written once for C and OpenCL C (common/portable.h),
 * one ray at a time in both.
 *
 * The strips: the terrain's square cut along the sun's heading u into strips `w` cells wide,
 * each cut into bins `ds` cells long.  Across and along are, in cells,
 *     across(x, y) = a_p x + b_p y,   along(x, y) = a_s x + b_s y      (x, y world)
 * (a_s, b_s) = u / cell.  A shadow ray (the sun's direction d) from o keeps its `across`, so it
 * stays in one strip, and gains climb = d.z cell / |d.xy| of height per cell of run:
 *     z(along) = o.z + climb (along - along(o)).
 * Bin b of a strip begins at along_0 + b ds, and reach[strip][b] is an upper bound, rounded up,
 * of   max over bins b' >= b of the strip of  (surface's top over bin b') - climb (its start).
 * So where  o.z - climb along(o) - eps > reach[strip][b],  the ray is above the surface by more
 * than eps at every point of run along >= along_0 + b ds: it is lowest in a bin where it
 * enters it.  A walk of the ray over the run before that point answers the shadow question:
 * past it no triangle test can hit (eps, 1e-7 of the scene's size, is orders above a test's
 * rounding), and tf_occluded over (0, tmax) says 1 exactly when some hit lies inside (0, tmax).
 *
 * tf_sun_clear_after gives that ray parameter (a little more: rounding), or TF_FAR_AWAY where
 * the first `look` bins ahead prove nothing.  Its rounding: along(o) and the products carry
 * relative errors of ~1e-16, far inside eps and the 1e-6 strip margin (a ray within it of a strip's
 * edge must be proved in both strips). */
#ifndef TF_SUN_MATH_H
#define TF_SUN_MATH_H

#ifndef __OPENCL_VERSION__
#include <stddef.h>
#include "portable.h"
#include "render/constants.h"
#define TF_GLOBAL
#else
#define TF_GLOBAL __global
#endif

/* The numbers of one set of strips (what the kernels get in P[] / I[]). */
typedef struct tf_sun_frame {
    double a_s, b_s, a_p, b_p;   /* along and across per world unit of x and y, in cells */
    double along0, across0;      /* where bin 0 and strip 0 begin, cells */
    double inv_w, inv_ds, ds;    /* strip width, bin length (cells) and their inverses */
    double climb;                /* height gained per cell of run */
    double t_per_cell;           /* ray parameter per cell of run: cell / |d.xy| */
    double eps;                  /* the clearance asked */
    int strips, bins, look;      /* look: bins ahead tried */
} tf_sun_frame;

/* The ray parameter past which a shadow ray from (ox, oy, oz) is proved clear of the surface,
 * or TF_FAR_AWAY. */
TF_SHARED double tf_sun_clear_after(const tf_sun_frame *f, TF_GLOBAL const float *reach,
                                    double ox, double oy, double oz)
{
    const double along = f->a_s * ox + f->b_s * oy, across = f->a_p * ox + f->b_p * oy;
    const double k = (across - f->across0) * f->inv_w, b = (along - f->along0) * f->inv_ds;
    /* inside the strips, a margin from their edge (a NaN fails too) */
    if (!(k >= 1.0 && k < f->strips - 1.0 && b >= 0.0 && b < f->bins - 1.0))
        return TF_FAR_AWAY;
    const int ka = (int)(k - 1e-6), kb = (int)(k + 1e-6), b0 = (int)b;
    const double level = oz - f->climb * along - f->eps;
    TF_GLOBAL const float *ra = reach + (size_t)ka * (size_t)f->bins;
    TF_GLOBAL const float *rb = reach + (size_t)kb * (size_t)f->bins;
    const int end = b0 + f->look < f->bins - 1 ? b0 + f->look : f->bins - 1;
    for (int c = b0 + 1; c <= end; c++)
        if (level > ra[c] && level > rb[c]) {
            const double run = f->along0 + c * f->ds - along; /* > 0: c > b */
            return run * f->t_per_cell * (1 + 1e-9) + 1e-9 * f->t_per_cell;
        }
    return TF_FAR_AWAY;
}

#endif
