/* sun_math.h: what the sun's strips (render/sun_strips.h) prove about a shadow ray -- clear of
 * the terrain for good past some point, or under it somewhere -- written once for C and OpenCL
 * C (common/portable.h), one ray at a time in both.
 *
 * The strips: the terrain's square cut along the sun's heading u into strips `w` cells wide,
 * each cut into bins `ds` cells long.  Across and along are, in cells,
 *     across(x, y) = a_p x + b_p y,   along(x, y) = a_s x + b_s y      (x, y world)
 * (a_s, b_s) = u / cell.  A shadow ray (the sun's direction d) from o keeps its `across`, so it
 * stays in one strip, and gains climb = d.z cell / |d.xy| of height per cell of run:
 *     z(along) = o.z + climb (along - along(o)),
 * lowest in a bin where it enters it, highest where it leaves.  Bin b of a strip begins at
 * along0 + b ds; the table holds TF_SUN_BIN floats a bin:
 *   reach  an upper bound, rounded up, of  max over bins b' >= b of the strip of
 *          (the surface's top over bin b') - climb (along0 + b' ds);
 *   sink   a lower bound, rounded down, of  max over bins c >= b of the strip that lie wholly
 *          inside the square of  (the surface's bottom over bin c) - climb (along0 + (c+1) ds)
 *          (-inf where there is no such bin).  Sinks never grow toward the sun, so the bin c
 *          that gives sink[b] is the last one whose sink is still sink[b]: a binary search.
 * Clear: where  o.z - climb along(o) - eps > reach[b],  the ray is above the surface by more
 *   than eps at every point of run along >= along0 + b ds.  A walk over the run before that
 *   point answers the shadow question: past it no triangle test can hit (eps, 1e-7 of the
 *   scene's size, is orders above a test's rounding), and tf_occluded over (0, tmax) says 1
 *   exactly when some hit lies inside (0, tmax).
 * Under: where  o.z - climb along(o) + eps < sink[b0 + 1]  (b0 the start's bin), the ray
 *   leaves the bin c > b0 that gives that sink under the least of the surface over that bin
 *   by eps, so it is under the surface by eps all through the bin, which lies inside the
 *   square.  If the ray starts inside the square above the surface by eps, it crosses the
 *   surface in between (the square is convex, the surface continuous over it), and the
 *   watertight walk finds that crossing (trace.c "coherence of shadow rays"): tf_occluded says
 *   1 without walking.  The suffix maximum makes this one comparison for bins at any
 *   distance: an occluder 100 cells off is proved as cheaply as one in the next bin
 *   (bench/README.md section 25).
 *
 * tf_sun_strips_say asks the under bound first (not for a ray within the strip margin below),
 * then tries bins b0+1 .. b0+look for the first that proves the ray clear, and past them finds
 * it by halving: reach never grows away from the sun, so once a bin proves the ray clear every
 * later one does (bench/README.md section 27).  Its rounding: along(o) and the products carry
 * relative errors of ~1e-16, far inside eps and the 1e-6 strip margin (a ray within it of a
 * strip's edge must be proved in both strips); the height under the start interpolates the
 * very triangles the walk tests. */
#ifndef TF_SUN_MATH_H
#define TF_SUN_MATH_H

#ifndef __OPENCL_VERSION__
#include <stddef.h>
#include "portable.h"
#include "render/constants.h"
#include "terrain/grid_height.h" /* TF_GLOBAL, tf_grid_height */
#endif

/* The query inlined where C calls it, its name_under a constant there (sun_strips.c). */
#ifdef __OPENCL_VERSION__
#define TF_SUN_INLINE
#else
#define TF_SUN_INLINE __attribute__((always_inline))
#endif

/* The numbers of one set of strips (what the kernels get in P[] / I[]). */
typedef struct tf_sun_frame {
    double a_s, b_s, a_p, b_p;   /* along and across per world unit of x and y, in cells */
    double along0, across0;      /* where bin 0 and strip 0 begin, cells */
    double inv_w, inv_ds, ds;    /* strip width, bin length (cells) and their inverses */
    double climb;                /* height gained per cell of run */
    double t_per_cell;           /* ray parameter per cell of run: cell / |d.xy| */
    double eps;                  /* the clearance asked */
    double dx, dy;               /* the sun's direction's x and y */
    double cell;                 /* the height field's cell, world units */
    int strips, bins, look;      /* look: bins ahead tried */
    int n;                       /* the height field's samples a side (cells + 1) */
} tf_sun_frame;

enum { TF_SUN_UNKNOWN = 0, TF_SUN_CLEAR_AFTER = 1, TF_SUN_UNDER = 2 };

/* Floats a bin in the table: reach, sink (above). */
#define TF_SUN_BIN 2

/* The height of the surface at (x, y), inside the square: the triangle of trace.c's split that
 * holds the point, interpolated as tf_heightfield_grid_height_at interpolates it (both are
 * terrain/grid_height.h's tf_grid_height). */
TF_SHARED double tf_sun_surface_at(const tf_sun_frame *f, TF_GLOBAL const float *h, double x,
                                   double y)
{
    return tf_grid_height(h, f->n, f->cell, x, y);
}

/* Is (x, y) inside the terrain's square? */
TF_SHARED int tf_sun_in_square(const tf_sun_frame *f, double x, double y)
{
    const double top = (double)(f->n - 1) * f->cell;
    return x >= 0 && x <= top && y >= 0 && y <= top; /* a NaN is not */
}

/* The bin that gives sink = row's sink at bin b1: the last one whose sink is still that
 * (sinks never grow away from the sun), by halving. */
TF_SHARED int tf_sun_sink_bin(const tf_sun_frame *f, TF_GLOBAL const float *row, int b1,
                              float sink)
{
    int lo = b1, hi = f->bins - 1;
    while (lo < hi) {
        const int mid = (lo + hi + 1) / 2;
        if (row[TF_SUN_BIN * mid + 1] >= sink)
            lo = mid;
        else
            hi = mid - 1;
    }
    return lo;
}

/* What the strips prove of the shadow ray from (ox, oy, oz): TF_SUN_CLEAR_AFTER with *t the
 * parameter past which it is clear for good (a little more: rounding), TF_SUN_UNDER (it is
 * occluded), or TF_SUN_UNKNOWN.  With name_under an occluded ray's *t is a parameter where it
 * is under the surface (sun_strips.h's tf_sun_strips_named: a neighbour's shadow ray looks for
 * the surface there first); without, *t is 0 and the search for that point is spared. */
TF_SUN_INLINE TF_SHARED int tf_sun_strips_say(const tf_sun_frame *f,
                                              TF_GLOBAL const float *table,
                                              TF_GLOBAL const float *h, double ox, double oy,
                                              double oz, int name_under, double *t)
{
    const double along = f->a_s * ox + f->b_s * oy, across = f->a_p * ox + f->b_p * oy;
    const double k = (across - f->across0) * f->inv_w, b = (along - f->along0) * f->inv_ds;
    /* inside the strips, a margin from their edge (a NaN fails too) */
    if (!(k >= 1.0 && k < f->strips - 1.0 && b >= 0.0 && b < f->bins - 1.0))
        return TF_SUN_UNKNOWN;
    const int ka = (int)(k - 1e-6), kb = (int)(k + 1e-6), b0 = (int)b;
    const double base = oz - f->climb * along; /* the ray's z at run `along`: base + climb along */
    TF_GLOBAL const float *ra = table + TF_SUN_BIN * (size_t)ka * (size_t)f->bins;
    TF_GLOBAL const float *rb = table + TF_SUN_BIN * (size_t)kb * (size_t)f->bins;
    const int b1 = b0 + 1; /* < bins: b < bins - 1 */
    /* under in the bin that gives the sink; *t may name its middle.  Not asked within the margin
     * of a strip's edge (ka != kb): the bin, and so the point, would depend on the strip. */
    const float sink = ra[TF_SUN_BIN * b1 + 1];
    if (ka == kb && base + f->eps < sink && tf_sun_in_square(f, ox, oy) &&
        oz - tf_sun_surface_at(f, h, ox, oy) > f->eps) {
        *t = 0;
        if (name_under) {
            const int named = tf_sun_sink_bin(f, ra, b1, sink);
            *t = (f->along0 + (named + 0.5) * f->ds - along) * f->t_per_cell;
        }
        return TF_SUN_UNDER;
    }
    const int end = b0 + f->look < f->bins - 1 ? b0 + f->look : f->bins - 1;
    const double need = base - f->eps;
    int c = b1;
    if (ka == kb) /* one strip (nearly every ray): one comparison a bin */
        while (c <= end && !(need > ra[TF_SUN_BIN * c]))
            c++;
    else
        while (c <= end && !(need > ra[TF_SUN_BIN * c] && need > rb[TF_SUN_BIN * c]))
            c++;
    if (c > end) {
        /* Not within `look` bins.  Reach never grows away from the sun, so whether a bin
         * clears the ray is false up to some bin and true from it on: found by halving. */
        int lo = end + 1, hi = f->bins - 1;
        if (lo > hi || !(need > ra[TF_SUN_BIN * hi] && need > rb[TF_SUN_BIN * hi]))
            return TF_SUN_UNKNOWN;
        while (lo < hi) {
            const int mid = (lo + hi) / 2;
            if (need > ra[TF_SUN_BIN * mid] && need > rb[TF_SUN_BIN * mid])
                hi = mid;
            else
                lo = mid + 1;
        }
        c = lo;
    }
    const double start = f->along0 + c * f->ds; /* > along: c > b */
    *t = (start - along) * f->t_per_cell * (1 + 1e-9) + 1e-9 * f->t_per_cell;
    return TF_SUN_CLEAR_AFTER;
}

#endif
