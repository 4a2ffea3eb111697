/* trace_math.h: the arithmetic of one ray against the height field, written once for the C
 * tracer (trace.c, one ray) and the OpenCL walk (worker/kernels/packet_trace.cl, eight rays,
 * one per lane; common/portable.h says how one source is both): clipping to the terrain's box,
 * the tolerances of the walk, grid-line crossings, the altitude cull of a block, the
 * watertight triangle test and the hit normal.  trace.c's top comment explains all of it.
 *
 * The walks themselves (which cell or block comes next, the level changes, the re-entry
 * search after a descent) are the schedulers and stay per target: trace.c steps one ray
 * through branches, packet_trace.cl steps eight with lane masks and deals a stream of rays to
 * them. */
#ifndef TF_TRACE_MATH_H
#define TF_TRACE_MATH_H

#ifndef __OPENCL_VERSION__
#include <float.h>
#include "portable.h"
#endif

/* ---------------------------------------------------------------- setup */

/* Narrow [*t0, *t1] to the slab lo <= o + t*d <= hi: the samples whose interval stays
 * non-empty (a ray parallel to the slab keeps its interval if it lies inside). */
TF_SHARED tf_mask tf_clip_slab(tf_lane o, tf_lane d, tf_lane lo, tf_lane hi, tf_lane *t0,
                               tf_lane *t1)
{
    tf_mask flat = d == 0.0;
    tf_mask inside = (o >= lo) & (o <= hi);
    if (!TF_ANY(TF_NOT(flat)))
        return inside;
    tf_lane ta = (lo - o) / d, tb = (hi - o) / d;
    tf_mask swap = ta > tb;
    tf_lane a = TF_SEL(ta, tb, swap), b = TF_SEL(tb, ta, swap);
    tf_lane n0 = TF_SEL(*t0, a, a > *t0), n1 = TF_SEL(*t1, b, b < *t1);
    *t0 = TF_SEL(n0, *t0, flat);
    *t1 = TF_SEL(n1, *t1, flat);
    return TF_SELM(n0 <= n1, inside, flat);
}

/* The terrain box's top, widened so hits at exactly hmin or hmax stay inside after rounding,
 * for a ray from altitude oz. */
TF_SHARED tf_lane tf_box_zpad(double hmin, double hmax, tf_lane oz)
{
    return 1e-9 * (fabs(hmin) + fabs(hmax) + fabs(oz) + (hmax - hmin)) + DBL_MIN;
}

/* 1 / v rounded where that is a normal double, else 0: what the window test of a shared
 * direction multiplies an exit's distance by (trace.c window_in_box, packet_trace.cl
 * window_in_box8). */
TF_SHARED double tf_exit_inverse(double v)
{
    const double inv = 1.0 / v;
    return fabs(inv) >= DBL_MIN && fabs(inv) <= DBL_MAX ? inv : 0.0;
}

/* 1 / v, with +-DBL_MAX for an infinite quotient. */
TF_SHARED tf_lane tf_safe_inverse(tf_lane v)
{
    tf_lane inv = 1.0 / v;
    return TF_SEL(inv, copysign(TF_LANE(DBL_MAX), v), TF_ISINF(inv));
}

/* The walk's tolerances for a ray o + t d over [t0, t1] (inv_dx, inv_dy used on the axes the
 * ray steps along, step_x, step_y) on a grid `top` wide of cells `cell` wide, heights in
 * [hmin, hmax]:
 *   *tie_tol  crossings closer than this pass "through a corner".  Crossing parameters carry
 *             an absolute error of a few ulps of (|X*cell| + |ox|) * |inv_dx|; 1e-12 of that
 *             bound is thousands of times the error.
 *   *margin   altitude slack of the culling tests: rounding of z(t) itself, plus how far the
 *             ray (and the surface under it, whose slope is at most (hmax - hmin) / cell per
 *             axis) moves within tie_tol.
 * Either is INFINITY where it is not finite. */
TF_SHARED void tf_walk_tolerances(double top, double cell, double hmin, double hmax,
                                  tf_lane3 o, tf_lane3 d, tf_mask step_x, tf_mask step_y,
                                  tf_lane inv_dx, tf_lane inv_dy, tf_lane t0, tf_lane t1,
                                  tf_lane *tie_tol, tf_lane *margin)
{
    tf_lane tie = TF_LANE(0.0);
    tie = TF_SEL(tie, tie + (top + fabs(o.x)) * fabs(inv_dx), step_x);
    tie = TF_SEL(tie, tie + (top + fabs(o.y)) * fabs(inv_dy), step_y);
    tie *= 1e-12;
    tf_lane tabs = TF_SEL(fabs(t1), fabs(t0), fabs(t0) > fabs(t1));
    double hscale = fabs(hmin) > fabs(hmax) ? fabs(hmin) : fabs(hmax);
    double slope = (hmax - hmin) / cell;
    tf_lane m = 1e-9 * (fabs(o.z) + fabs(d.z) * tabs + hscale + (hmax - hmin)) +
                2 * tie * (fabs(d.z) + 2 * slope * (fabs(d.x) + fabs(d.y)));
    *tie_tol = TF_SEL(INFINITY, tie, TF_ISFINITE(tie));
    *margin = TF_SEL(INFINITY, m, TF_ISFINITE(m));
}

/* ---------------------------------------------------------------- the walk's arithmetic */

/* The ray parameter where it crosses grid line `line` (a line index, as a double) of an axis
 * along which it starts at o and moves 1 / inv per unit t. */
TF_SHARED tf_lane tf_grid_cross(tf_lane line, double cell, tf_lane o, tf_lane inv)
{
    return (line * cell - o) * inv;
}

/* Is the altitude span z_in..z_out wholly above hi or wholly below lo (by the margin)? */
TF_SHARED tf_mask tf_span_culled(tf_lane z_in, tf_lane z_out, tf_lane hi, tf_lane lo,
                                 tf_lane margin)
{
    tf_mask rising = z_in < z_out;
    tf_lane zlo = TF_SEL(z_out, z_in, rising), zhi = TF_SEL(z_in, z_out, rising);
    return TF_OR(zlo > hi + margin, zhi < lo - margin);
}

/* ---------------------------------------------------------------- triangles */

/* A vertex sheared into ray space: x, y in the plane across the ray, z scaled along it. */
typedef struct tf_sheared { tf_lane x, y, z; } tf_sheared;

/* The vertex whose offsets from the ray origin, permuted to ray-space order, are (ax, ay, az):
 * (ax - shx * az, ay - shy * az, shz * az). */
TF_SHARED tf_sheared tf_shear(tf_lane ax, tf_lane ay, tf_lane az, tf_lane shx, tf_lane shy,
                              tf_lane shz)
{
    tf_sheared s = {ax - shx * az, ay - shy * az, shz * az};
    return s;
}

/* Twice the signed area of (origin, p, q) in ray space.  tf_edge_fn(q, p) == -tf_edge_fn(p, q)
 * exactly (the two products just trade places), and a value within the rounding error of the
 * subtraction is returned as 0, so no sign is ever wrong, only undecided. */
TF_SHARED tf_lane tf_edge_fn(tf_sheared p, tf_sheared q)
{
    tf_lane a = p.x * q.y, b = p.y * q.x, e = a - b;
    return TF_SEL(e, 0.0, fabs(e) <= 8 * DBL_EPSILON * (fabs(a) + fabs(b)));
}

/* The triangle with barycentric edge values u, v, w (for vertices with ray-space depths za,
 * zb, zc) is hit (from either side) where all three share a sign and the triangle is not
 * edge-on; the hit is taken where its parameter *t lies in (tmin, tmax) and before best_t.
 * *t is set only when some sample's triangle is hit. */
TF_SHARED tf_mask tf_triangle_hit(tf_lane u, tf_lane v, tf_lane w, tf_lane za, tf_lane zb,
                                  tf_lane zc, tf_lane tmin, tf_lane tmax, tf_lane best_t,
                                  tf_lane *t)
{
    tf_mask mixed = TF_AND(TF_OR(TF_OR(u < 0.0, v < 0.0), w < 0.0),
                           TF_OR(TF_OR(u > 0.0, v > 0.0), w > 0.0));
    tf_mask hit = TF_NOT(mixed);
    if (!TF_ANY(hit))
        return hit;
    tf_lane det = u + v + w;
    hit = TF_AND(hit, det != 0.0); /* not: the ray in the triangle's plane, or edge-on */
    if (!TF_ANY(hit))
        return hit;
    tf_lane th = (u * za + v * zb + w * zc) / det;
    *t = th;
    return TF_AND(hit, TF_AND(TF_AND(th > tmin, th < tmax), th < best_t));
}

/* The unit normal of triangle `first` ? (A, B, C) : (A, C, D) of a cell with corner heights
 * ha = A, hb = B, hc = C, hd = D, `cell` wide. */
TF_SHARED tf_lane3 tf_hit_normal(tf_lane ha, tf_lane hb, tf_lane hc, tf_lane hd, double cell,
                                 tf_mask first)
{
    return tf_l3_norm(tf_l3(TF_SEL(-(hc - hd), -(hb - ha), first),
                            TF_SEL(-(hd - ha), -(hc - hb), first), TF_LANE(cell)));
}

/* ---------------------------------------------------------------- coherence (trace.c)
 *
 * trace.c's "coherence" section proves when a camera ray may skip the part of its walk that a
 * lower ray from the same origin vouches for; these are its formulas, for C's one ray and the
 * kernels' eight. */

/* The clearance both coherence proofs ask of a ray from (ox, oy, oz) over a terrain `extent`
 * wide with heights in [hmin, hmax]: 1e-7 times the scene's size, orders above the rounding of
 * a triangle test or of an interpolated height. */
TF_SHARED tf_lane tf_clearance_eps(double extent, double hmin, double hmax, tf_lane ox,
                                   tf_lane oy, tf_lane oz)
{
    return 1e-7 * (extent + fabs(hmin) + fabs(hmax) + fabs(ox) + fabs(oy) + fabs(oz));
}

/* A direction's heading (ux, uy: unit, horizontal), climb k (dz per unit of horizontal run) and
 * run per unit of t; false where the run is 0 or overflows (the outputs are then not used). */
TF_SHARED tf_mask tf_heading(tf_lane dx, tf_lane dy, tf_lane dz, tf_lane *run, tf_lane *ux,
                             tf_lane *uy, tf_lane *k)
{
    *run = sqrt(dx * dx + dy * dy);
    const tf_lane inv = 1 / *run; /* C1's margin covers the roundings of the products */
    *ux = dx * inv, *uy = dy * inv, *k = dz * inv;
    return TF_AND(*run > 0, TF_ISFINITE(*run));
}

/* Does a lower ray's record (heading lux, luy, climb lk; above the surface over the runs
 * [ls_in, ls_free)) vouch for part of this ray (heading ux, uy, climb k, `run` per unit of t,
 * entering the square at t_square, its walk starting at t0), from the same origin, over a
 * surface of slope at most L (finite, >= 0), with clearance eps (C1-C3 of trace.c)?  Where it
 * does, *t_pre is where the prefix walk ends (<= t0: no prefix) and *t_skip where the main
 * walk starts. */
TF_SHARED tf_mask tf_vouched(tf_lane ux, tf_lane uy, tf_lane k, tf_lane run, tf_lane t_square,
                             tf_lane t0, tf_lane lux, tf_lane luy, tf_lane lk, tf_lane ls_in,
                             tf_lane ls_free, double L, tf_lane eps, tf_lane *t_pre,
                             tf_lane *t_skip)
{
    /* |u - lu| <= |dx| + |dy|: a looser bound, but no square root on the chain every camera
     * ray's walk waits for; nor a second division on it: s_lo / run is s_lo times 1 / run
     * (known before D), rounded up */
    const tf_lane dx = ux - lux, dy = uy - luy, inv_run = 1 / run;
    const tf_lane D = (k - lk) - L * (fabs(dx) + fabs(dy)) - 1e-9 * (1 + fabs(k) + fabs(lk) + L);
    const tf_lane q = eps / D, s_lo = TF_SEL(ls_in, q, q > ls_in);
    const tf_lane s_hi = ls_free * (1 - 1e-9);
    *t_pre = TF_SEL(TF_LANE(0.0), s_lo * inv_run * (1 + 1e-14), t_square * run < s_lo);
    *t_skip = s_hi * inv_run;
    return TF_AND(TF_AND(ls_free > 0, D > 0), TF_AND(s_hi > s_lo, *t_skip > t0));
}

/* Was a hit on triangle `first` ? (A, B, C) : (A, C, D) of a cell `cell` wide with corner
 * heights ha = A, hb = B, hc = C, hd = D made from above (d . n < 0, n the triangle's upward
 * normal, unnormalised), by more than the dot product's rounding? */
TF_SHARED tf_mask tf_hit_from_above(tf_lane ha, tf_lane hb, tf_lane hc, tf_lane hd, double cell,
                                    tf_mask first, tf_lane3 d)
{
    const tf_lane gx = TF_SEL(hc - hd, hb - ha, first), gy = TF_SEL(hd - ha, hc - hb, first);
    const tf_lane a = -d.x * gx, b = -d.y * gy, z = d.z * cell;
    return a + b + z < -1e-12 * (fabs(a) + fabs(b) + fabs(z));
}

#endif
