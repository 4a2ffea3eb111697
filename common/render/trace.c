/* trace.c: grid tracing of a height field (Musgrave chapter 3), flat and hierarchical.
 *
 * The surface: cell (ci, cj) is split along its diagonal (ci, cj)-(ci+1, cj+1) into
 * T1 = (A, B, C) and T2 = (A, C, D) with A = (ci, cj), B = (ci+1, cj), C = (ci+1, cj+1),
 * D = (ci, cj+1).  Triangles are tested exactly and watertight: every vertex is sheared into
 * ray space once (Woop, Benthin & Wald 2013), and every edge function is computed by the one
 * function tf_edge_fn() from those vertex images, so an edge shared by two triangles gets values of
 * exactly opposite sign in both, and a point on it is accepted by at least one (values whose sign
 * rounding could flip are snapped to 0, which both accept).
 *
 * The walk (tf_trace_flat): Musgrave's modified DDA.  The ray, clipped to the terrain's box,
 * crosses the grid lines x = X*cell and y = Y*cell at parameters
 *     xcross(X) = (X*cell - ox) * inv_dx,   ycross(Y) = (Y*cell - oy) * inv_dy,
 * each a pure function of the line index.  The DDA processes these crossings in the order of
 * the key (t, x-before-y): at a cell it steps x when xcross <= ycross, else y.  Over a cell's
 * parameter segment [t_in, t_out] the ray's altitude spans z(t_in)..z(t_out) (z(t) = oz + t*dz is
 * monotone in t even in floating point); the cell is skipped when that span lies wholly above
 * maxgrid[0] or wholly below mingrid[0] (by a small per-ray margin).  Otherwise its triangles
 * are tested, and the first cell whose test hits ends the walk.
 *
 * The fast path (tf_trace): the same walk on level L of the max/min mipmap, where blocks are
 * 2^L cells wide and block boundaries are grid lines X = multiple of 2^L.  Their crossings are
 * the very same xcross(X) values, so the block sequence is the cell sequence grouped by block,
 * and a block's altitude span contains the span of every cell in it.  Skipping a block therefore
 * skips only cells the flat walk would skip, and at level 0 both walks test the same cells, in
 * the same order, with the same inputs: tf_trace returns exactly tf_trace_flat's hit, bit for
 * bit.  While a block is skipped the cell index on the axis not being stepped is not tracked;
 * each descent settles one more bit of it from the crossing order (settle_half: which half of
 * the block the ray is in), so that at level 0 it is the index the flat walk holds at that
 * moment (fix_stale_axis, which finds every bit at once, is the reference it is asserted
 * against).
 *
 * Rounding: the DDA can disagree with the triangle tests by a hair about which of two cells
 * meeting at a grid corner the ray passes through.  So a cell whose entry or exit crossings
 * nearly tie (the ray passes within tie_tol of a corner) also tests the two neighbours sharing
 * that corner.  This is part of the cell's test, a pure function of the cell and the ray, so
 * both walks still agree.  Rays that would hit a cell after the DDA has left it are covered by
 * the cull margin, which bounds the altitude error of the crossing parameters.
 *
 * Occlusion walks (tf_occluded, tf_occluded_coherent) ask one more test before a cell's
 * triangles: whether the ray is above both their planes (above_planes), which spares a shadow
 * ray skimming the surface most of its triangle tests and cannot skip a hit.  A coherent one
 * over a short span walks flat (walk_occlusion): the same hit, without the hierarchy.
 *
 * Coherence (tf_trace_coherent, tf_occluded_coherent; the two sections before the entry
 * points): a camera ray may skip the stretch the ray below it proves clear, and a shadow ray
 * may be proved occluded where its neighbour's went under the surface; the answers stay those
 * of tf_trace and tf_occluded. */
#include <assert.h>
#include <float.h>
#include <math.h>
#include "render/trace.h"
#include "render/trace_internal.h"
#include "terrain/grid_height.h" /* tf_grid_index */

/* The arithmetic of the walk and the triangle tests, shared with the OpenCL kernels
 * (packet_trace.cl); what is here is the walk itself. */
#include "render/trace_math.h"

/* An occlusion walk over a span crossing fewer cells than this walks flat (walk_occlusion). */
#define TF_FLAT_OCCLUSION_CELLS 64.0

/* The candidate hit and the ray's context are shared with the packet tracer (trace_internal.h). */
typedef tf_trace_cand candidate;
typedef tf_ray_ctx ray_ctx;
typedef tf_sheared sheared; /* a vertex in ray space (trace_math.h) */

/* ---- crossings ---------------------------------------------------------------------------- */

static inline double xcross(const ray_ctx *r, int X)
{
    return tf_grid_cross((double)X, r->hf->cell, r->o[0], r->inv_dx);
}

static inline double ycross(const ray_ctx *r, int Y)
{
    return tf_grid_cross((double)Y, r->hf->cell, r->o[1], r->inv_dy);
}

/* Crossing of the grid line where the ray leaves column ci (cells), or +inf if it never does. */
static inline double exit_x(const ray_ctx *r, int ci)
{
    return r->sx ? xcross(r, ci + (r->sx > 0)) : INFINITY;
}

static inline double exit_y(const ray_ctx *r, int cj)
{
    return r->sy ? ycross(r, cj + (r->sy > 0)) : INFINITY;
}

/* ---- triangle tests ----------------------------------------------------------------------- */

/* Triangle with barycentric edge values u, v, w (for vertices with ray-space depths za, zb, zc):
 * a hit if all three share a sign (either side: rays from below hit the underside). */
static inline void try_triangle(const ray_ctx *r, double u, double v, double w, double za,
                                double zb, double zc, int ci, int cj, int tri, candidate *best)
{
    double t;
    if (tf_triangle_hit(u, v, w, za, zb, zc, r->tmin, r->tmax, best->t, &t)) {
        best->t = t;
        best->ci = ci;
        best->cj = cj;
        best->tri = tri;
    }
}

/* tf_shear (trace_math.h) of a vertex with the ray's shear constants. */
static inline sheared shear_rel(double ax, double ay, double az, double shx, double shy,
                                double shz)
{
    return tf_shear(ax, ay, az, shx, shy, shz);
}

/* Both triangles of cell (ci, cj).  The four corners' offsets from the origin are
 * (i * cell - ox, j * cell - oy, h - oz); they share two x and two y offsets, computed once
 * each, and the branch on kz spells out the permutation (no indexing by kx/ky/kz). */
static void test_triangles(const ray_ctx *r, int ci, int cj, candidate *best)
{
    const tf_heightfield *hf = r->hf;
    const double x0 = (double)ci * hf->cell - r->o[0], x1 = (double)(ci + 1) * hf->cell - r->o[0];
    const double y0 = (double)cj * hf->cell - r->o[1], y1 = (double)(cj + 1) * hf->cell - r->o[1];
    const float *h = hf->h + (size_t)cj * hf->n + ci;
    const double za = (double)h[0] - r->o[2], zb = (double)h[1] - r->o[2];
    const double zd = (double)h[hf->n] - r->o[2], zc = (double)h[hf->n + 1] - r->o[2];
    const double shx = r->shx, shy = r->shy, shz = r->shz;
    sheared a, b, c, d;
    /* (kx, ky, kz) is (1, 2, 0), (2, 0, 1) or (0, 1, 2) (setup_ray). */
    if (r->kz == 0) {
        a = shear_rel(y0, za, x0, shx, shy, shz), b = shear_rel(y0, zb, x1, shx, shy, shz);
        c = shear_rel(y1, zc, x1, shx, shy, shz), d = shear_rel(y1, zd, x0, shx, shy, shz);
    } else if (r->kz == 1) {
        a = shear_rel(za, x0, y0, shx, shy, shz), b = shear_rel(zb, x1, y0, shx, shy, shz);
        c = shear_rel(zc, x1, y1, shx, shy, shz), d = shear_rel(zd, x0, y1, shx, shy, shz);
    } else {
        a = shear_rel(x0, y0, za, shx, shy, shz), b = shear_rel(x1, y0, zb, shx, shy, shz);
        c = shear_rel(x1, y1, zc, shx, shy, shz), d = shear_rel(x0, y1, zd, shx, shy, shz);
    }
    double e_ab = tf_edge_fn(a, b), e_bc = tf_edge_fn(b, c), e_ca = tf_edge_fn(c, a);
    double e_cd = tf_edge_fn(c, d), e_da = tf_edge_fn(d, a);
    /* T1 = (A, B, C): A's weight is the area across from it, edge BC; and so on. */
    try_triangle(r, e_bc, e_ca, e_ab, a.z, b.z, c.z, ci, cj, 0, best);
    /* T2 = (A, C, D); its diagonal edge AC is T1's CA reversed. */
    try_triangle(r, e_cd, e_da, -e_ca, a.z, c.z, d.z, ci, cj, 1, best);
}

static inline void test_if_inside(const ray_ctx *r, int ci, int cj, candidate *best)
{
    if ((unsigned)ci < (unsigned)r->hf->cells && (unsigned)cj < (unsigned)r->hf->cells)
        test_triangles(r, ci, cj, best);
}

/* The plane test: is the ray, from t_in to t_out, above both triangles' planes of cell
 * (ci, cj) by more than the margin?  Then neither triangle can report a hit there.  Each plane
 * minus the ray is linear along the ray, so it is below -margin all along if it is at the two
 * ends; the surface over the cell lies on one plane or the other at every point; and the
 * margin, which already covers the cull by the cell's maximum (a weaker test: the corners'
 * maximum bounds both planes over the cell), covers the rounding here too, of the points
 * o + t d and of the planes' values (tiny beside it), and the ray's motion within tie_tol of a
 * crossing.  [t_in, t_out] holds the ray's part over the cell's square (the walk's span: the
 * cell's, or a block's around it after a descent) but for hits no walk may report anyway:
 * before t0 or after t1, outside the box or (tmin, tmax).  So a skipped cell held no hit, and
 * the hit found is the same, bit for bit.  A shadow ray just above the surface skips ~80% of
 * its cells' triangle tests this way; a camera ray, arriving where it hits, ~20%, which does
 * not pay for the test (bench/README.md section 26): only occlusion walks ask it. */
static inline __attribute__((always_inline)) int above_planes(const ray_ctx *r, int ci, int cj,
                                                              double t_in, double t_out)
{
    const tf_heightfield *hf = r->hf;
    const float *h = hf->h + (size_t)cj * hf->n + ci;
    const double ha = h[0], hb = h[1], hd = h[hf->n], hc = h[hf->n + 1];
    const double x0 = (double)ci * hf->cell, y0 = (double)cj * hf->cell, ic = r->inv_cell;
    /* (u, v): the ends' offsets from corner A, in cells */
    const double ui = (r->o[0] + t_in * r->d[0] - x0) * ic;
    const double vi = (r->o[1] + t_in * r->d[1] - y0) * ic;
    const double uo = (r->o[0] + t_out * r->d[0] - x0) * ic;
    const double vo = (r->o[1] + t_out * r->d[1] - y0) * ic;
    const double zi = r->o[2] + t_in * r->d[2], zo = r->o[2] + t_out * r->d[2];
    /* T1 = (A, B, C): ha + (hb - ha) u + (hc - hb) v;  T2 = (A, C, D): ha + (hc - hd) u + (hd - ha) v */
    const double g1u = hb - ha, g1v = hc - hb, g2u = hc - hd, g2v = hd - ha, m = r->margin;
    return zi - (ha + g1u * ui + g1v * vi) > m && zi - (ha + g2u * ui + g2v * vi) > m &&
           zo - (ha + g1u * uo + g1v * vo) > m && zo - (ha + g2u * uo + g2v * vo) > m;
}

/* The two neighbours of cell (ci, cj) that share its corner toward (sx, sy). */
static void test_corner(const ray_ctx *r, int ci, int cj, int sx, int sy, candidate *best)
{
    test_if_inside(r, ci + sx, cj, best);
    test_if_inside(r, ci, cj + sy, best);
}

/* The crossings of the lines cell (ci, cj) is entered by (+inf on an axis not stepped). */
static inline double entry_x(const ray_ctx *r, int ci)
{
    return r->sx ? xcross(r, ci + (r->sx < 0)) : INFINITY;
}

static inline double entry_y(const ray_ctx *r, int cj)
{
    return r->sy ? ycross(r, cj + (r->sy < 0)) : INFINITY;
}

/* The neighbours of cell (ci, cj), whose exit crossings are tx, ty, that share its entry or
 * exit corner, tested when the ray passes that corner within tie_tol (see the top of the
 * file).  Returns 1 if anything has been hit.  The entry crossings are computed only when both
 * axes step (test_ties_at takes them from a walk that carries them). */
static int test_ties(const ray_ctx *r, int ci, int cj, double tx, double ty, candidate *best)
{
    if (r->sx && r->sy) {
        if (fabs(tx - ty) <= r->tie_tol)
            test_corner(r, ci, cj, r->sx, r->sy, best);
        if (fabs(entry_x(r, ci) - entry_y(r, cj)) <= r->tie_tol)
            test_corner(r, ci, cj, -r->sx, -r->sy, best);
    }
    return best->t < INFINITY;
}

/* test_ties for a walk that knows the cell's entry crossings tx_in, ty_in (of the lines it is
 * entered by: the exits of the cells before it). */
static int test_ties_at(const ray_ctx *r, int ci, int cj, double tx, double ty, double tx_in,
                        double ty_in, candidate *best)
{
    if (r->sx && r->sy) {
        if (fabs(tx - ty) <= r->tie_tol)
            test_corner(r, ci, cj, r->sx, r->sy, best);
        if (fabs(tx_in - ty_in) <= r->tie_tol)
            test_corner(r, ci, cj, -r->sx, -r->sy, best);
    }
    return best->t < INFINITY;
}

/* The complete test of cell (ci, cj): its own triangles and test_ties.  Returns 1 if anything
 * was hit. */
static int test_cell(const ray_ctx *r, int ci, int cj, double tx, double ty, candidate *best)
{
    test_triangles(r, ci, cj, best);
    return test_ties(r, ci, cj, tx, ty, best);
}

/* test_cell for a walk that meets the cell over [t_in, t_out]: its own triangles spared where
 * the plane test clears them (occlusion walks only, r->planes). */
static inline int test_cell_over(const ray_ctx *r, int ci, int cj, double tx, double ty,
                                 double t_in, double t_out, candidate *best)
{
    if (r->planes && above_planes(r, ci, cj, t_in, t_out))
        return test_ties(r, ci, cj, tx, ty, best);
    return test_cell(r, ci, cj, tx, ty, best);
}

/* test_cell_over for the flat walk, which carries the cell's entry crossings (the exits of the
 * cells before it on either axis): the same tests, and where the plane test clears the cell
 * and the ray passes neither corner within tie_tol -- nearly always -- no call at all. */
static inline __attribute__((always_inline)) int test_cell_flat(const ray_ctx *r, int ci, int cj,
                                                                double tx, double ty,
                                                                double tx_in, double ty_in,
                                                                double t_in, double t_out,
                                                                candidate *best)
{
    if (!(r->planes && above_planes(r, ci, cj, t_in, t_out)))
        test_triangles(r, ci, cj, best);
    else if (!(fabs(tx - ty) <= r->tie_tol) && !(fabs(tx_in - ty_in) <= r->tie_tol))
        return best->t < INFINITY;
    return test_ties_at(r, ci, cj, tx, ty, tx_in, ty_in, best);
}

/* ---- setup -------------------------------------------------------------------------------- */

/* Index of the cell containing coordinate v along one axis (terrain/grid_height.h's
 * tf_grid_index, which places it by the same products (double)i * cell that place the
 * vertices), its search started from a multiply, not a division. */
static int cell_of(const tf_heightfield *hf, double inv_cell, double v)
{
    return tf_grid_index(v, hf->cell, v * inv_cell, hf->cells);
}

/* A walk's setup, in steps: the box (the part of (tmin, tmax) inside the terrain's box), the
 * direction's steps and inverses, the start cell and the walk's tolerances, the direction's
 * ray space for the triangle tests.  setup_ray runs them all, in that order (the box's
 * divisions first: the start cell waits for them); a tf_ray_dir keeps the direction's parts
 * for many rays. */

/* tf_clip_slab, skipping its divisions where they cannot matter (inv: NULL, never).  For an
 * origin inside the slab and *t0 >= 0 the slab's entry parameter is <= 0 <= *t0, so
 * tf_clip_slab keeps *t0; it keeps *t1 too where the exit (gap / d, gap the distance to the
 * far side) lies beyond it.  A product with *inv (1 / d rounded, a normal double; 0: never)
 * proves that: gap * *inv is within 2.3e-16 of gap / d, relative, so exceeding *t1 (normal)
 * by 1e-12 of it puts gap / d, and so its rounded quotient, beyond *t1.  Everywhere else the
 * exact clip: the bits are tf_clip_slab's always. */
static inline int clip_slab(double o, double d, const double *inv, double lo, double hi,
                            double *t0, double *t1)
{
    if (inv && d != 0 && o >= lo && o <= hi && *t0 >= 0 && *t1 >= DBL_MIN &&
        (d > 0 ? hi - o : lo - o) * *inv > *t1 * (1 + 1e-12))
        return 1;
    return tf_clip_slab(o, d, lo, hi, t0, t1);
}

/* The box: r->t_square, t0, t1 for the ray from o along d over (tmin, tmax); exit_inv NULL or
 * the direction's (tf_ray_dir).  0 if the ray misses it. */
static inline __attribute__((always_inline)) int setup_box(ray_ctx *r, const tf_heightfield *hf,
                                                           tf_vec3 o, tf_vec3 d, double tmin,
                                                           double tmax, const double *exit_inv)
{
    /* The box, its top widened so hits at exactly hmin or hmax stay inside after rounding. */
    const double top = (double)hf->cells * hf->cell;
    const double hmin = hf->hmin, hmax = hf->hmax;
    const double zpad = tf_box_zpad(hmin, hmax, o.z);
    const double *ix = exit_inv, *iy = exit_inv ? exit_inv + 1 : NULL;
    const double *iz = exit_inv ? exit_inv + 2 : NULL;
    double t0 = tmin, t1 = tmax;
    if (!clip_slab(o.x, d.x, ix, 0, top, &t0, &t1) || !clip_slab(o.y, d.y, iy, 0, top, &t0, &t1))
        return 0;
    r->t_square = t0;
    if (!clip_slab(o.z, d.z, iz, hmin - zpad, hmax + zpad, &t0, &t1) || !isfinite(t0) ||
        !isfinite(t1))
        return 0;
    r->t0 = t0;
    r->t1 = t1;
    return 1;
}

/* The direction's steps across the grid and their inverses. */
static inline void setup_steps(ray_ctx *r, const tf_heightfield *hf, tf_vec3 d)
{
    r->sx = d.x > 0 ? 1 : d.x < 0 ? -1 : 0;
    r->sy = d.y > 0 ? 1 : d.y < 0 ? -1 : 0;
    r->inv_dx = r->sx ? tf_safe_inverse(d.x) : 0;
    r->inv_dy = r->sy ? tf_safe_inverse(d.y) : 0;
    r->inv_cell = 1.0 / hf->cell;
}

/* The start cell and the walk's tolerances, after setup_box and setup_steps. */
static inline void setup_start(ray_ctx *r, const tf_heightfield *hf, tf_vec3 o, tf_vec3 d)
{
    r->ci = cell_of(hf, r->inv_cell, o.x + r->t0 * d.x);
    r->cj = cell_of(hf, r->inv_cell, o.y + r->t0 * d.y);
    tf_walk_tolerances((double)hf->cells * hf->cell, hf->cell, hf->hmin, hf->hmax, o, d,
                       r->sx != 0, r->sy != 0, r->inv_dx, r->inv_dy, r->t0, r->t1, &r->tie_tol,
                       &r->margin);
}

/* Ray space: kz is the dominant axis of d. */
static inline void setup_shear(ray_ctx *r)
{
    const double ax = fabs(r->d[0]), ay = fabs(r->d[1]), az = fabs(r->d[2]);
    r->kz = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    r->kx = (r->kz + 1) % 3;
    r->ky = (r->kx + 1) % 3;
    r->shx = r->d[r->kx] / r->d[r->kz];
    r->shy = r->d[r->ky] / r->d[r->kz];
    r->shz = 1.0 / r->d[r->kz];
}

/* The ray's fields as given, for a walk over hf. */
static inline void setup_fields(ray_ctx *r, const tf_heightfield *hf, tf_vec3 o, tf_vec3 d,
                                double tmin, double tmax)
{
    r->hf = hf;
    r->o[0] = o.x, r->o[1] = o.y, r->o[2] = o.z;
    r->d[0] = d.x, r->d[1] = d.y, r->d[2] = d.z;
    r->tmin = tmin;
    r->tmax = tmax;
    r->planes = 0;
}

/* Can a walk over hf follow direction d (finite, not zero)? */
static inline int walkable(const tf_heightfield *hf, tf_vec3 d)
{
    return hf && isfinite(d.x) && isfinite(d.y) && isfinite(d.z) &&
           !(d.x == 0 && d.y == 0 && d.z == 0);
}

/* Can a walk start at o over the window (tmin, tmax)? */
static inline int startable(tf_vec3 o, double tmin, double tmax)
{
    return isfinite(o.x) && isfinite(o.y) && isfinite(o.z) && tmin < tmax;
}

/* Prepare a walk.  Returns 0 if the ray cannot meet the terrain in (tmin, tmax). */
static int setup_ray(ray_ctx *r, const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmin,
                     double tmax)
{
    if (!walkable(hf, d) || !startable(o, tmin, tmax))
        return 0;
    setup_fields(r, hf, o, d, tmin, tmax);
    if (!setup_box(r, hf, o, d, tmin, tmax, NULL))
        return 0;
    setup_steps(r, hf, d);
    setup_start(r, hf, o, d);
    setup_shear(r);
    return 1;
}

/* tf_walk_tolerances's parts that depend on the direction only, for dir_tolerances: the box's
 * top, |inv_dx|, |inv_dy|, |dz|, the heights' scale and range, and the slope's factor. */
enum { TOL_TOP, TOL_AX, TOL_AY, TOL_ADZ, TOL_HSCALE, TOL_HRANGE, TOL_SLOPE, TOL_PARTS };
_Static_assert(TOL_PARTS == sizeof ((tf_ray_dir *)0)->tol / sizeof(double), "tf_ray_dir.tol");

static void dir_tolerance_parts(tf_ray_dir *k, const tf_heightfield *hf)
{
    const double hmin = hf->hmin, hmax = hf->hmax, slope = (hmax - hmin) / hf->cell;
    k->tol[TOL_TOP] = (double)hf->cells * hf->cell;
    k->tol[TOL_AX] = fabs(k->inv_dx), k->tol[TOL_AY] = fabs(k->inv_dy);
    k->tol[TOL_ADZ] = fabs(k->d[2]);
    k->tol[TOL_HSCALE] = fabs(hmin) > fabs(hmax) ? fabs(hmin) : fabs(hmax);
    k->tol[TOL_HRANGE] = hmax - hmin;
    k->tol[TOL_SLOPE] = fabs(k->d[2]) + 2 * slope * (fabs(k->d[0]) + fabs(k->d[1]));
}

/* setup_start's tolerances for a ray of direction k from o (after setup_box): trace_math.h's
 * tf_walk_tolerances with k's parts of it computed once -- the same operations in the same
 * order, so the same bits (test_trace.c's test_shared_direction_setup_is_the_rays_own). */
static inline void dir_tolerances(ray_ctx *r, const tf_ray_dir *k, tf_vec3 o)
{
    double tie = 0.0;
    if (k->sx)
        tie = tie + (k->tol[TOL_TOP] + fabs(o.x)) * k->tol[TOL_AX];
    if (k->sy)
        tie = tie + (k->tol[TOL_TOP] + fabs(o.y)) * k->tol[TOL_AY];
    tie *= 1e-12;
    const double tabs = fabs(r->t0) > fabs(r->t1) ? fabs(r->t0) : fabs(r->t1);
    const double m = 1e-9 * (fabs(o.z) + k->tol[TOL_ADZ] * tabs + k->tol[TOL_HSCALE] +
                             k->tol[TOL_HRANGE]) +
                     2 * tie * k->tol[TOL_SLOPE];
    r->tie_tol = isfinite(tie) ? tie : INFINITY;
    r->margin = isfinite(m) ? m : INFINITY;
}

/* tf_ray_dir_init (trace.h): the direction's steps, inverses and shear, kept. */
static int dir_of(tf_ray_dir *k, const tf_heightfield *hf, tf_vec3 d)
{
    ray_ctx r;
    *k = (tf_ray_dir){.hf = hf, .d = {d.x, d.y, d.z}};
    if (!walkable(hf, d))
        return 0;
    setup_fields(&r, hf, v3(0, 0, 0), d, 0, 0);
    setup_steps(&r, hf, d);
    setup_shear(&r);
    k->sx = r.sx, k->sy = r.sy, k->inv_dx = r.inv_dx, k->inv_dy = r.inv_dy;
    k->inv_cell = r.inv_cell;
    k->kx = r.kx, k->ky = r.ky, k->kz = r.kz, k->shx = r.shx, k->shy = r.shy, k->shz = r.shz;
    k->exit_inv[0] = tf_exit_inverse(d.x);
    k->exit_inv[1] = tf_exit_inverse(d.y);
    k->exit_inv[2] = tf_exit_inverse(d.z);
    dir_tolerance_parts(k, hf);
    k->exit_xy[0] = d.x > 0 ? k->tol[TOL_TOP] : 0;
    k->exit_xy[1] = d.y > 0 ? k->tol[TOL_TOP] : 0;
    k->moves_all = d.x != 0 && d.y != 0 && d.z != 0;
    return k->ok = 1;
}

/* Would each of setup_box's three clip_slab shortcuts hold for the window (tmin, tmax) of a ray
 * of direction k from o?  Each keeps t0 = tmin and t1 = tmax, so the next one would see the
 * window unchanged, and the box is the window itself.  The same comparisons of the same values
 * (the exits' sides are the direction's), asked once each: a shadow ray the strips end nearly
 * always passes. */
static inline int window_in_box(const tf_ray_dir *k, tf_vec3 o, double tmin, double tmax)
{
    if (!(k->moves_all && tmin >= 0 && tmax >= DBL_MIN))
        return 0;
    const double beyond = tmax * (1 + 1e-12), top = k->tol[TOL_TOP];
    if (!(o.x >= 0 && o.x <= top && (k->exit_xy[0] - o.x) * k->exit_inv[0] > beyond))
        return 0;
    if (!(o.y >= 0 && o.y <= top && (k->exit_xy[1] - o.y) * k->exit_inv[1] > beyond))
        return 0;
    const tf_heightfield *hf = k->hf;
    const double zpad = tf_box_zpad(hf->hmin, hf->hmax, o.z);
    const double zlo = hf->hmin - zpad, zhi = hf->hmax + zpad;
    return o.z >= zlo && o.z <= zhi && ((k->d[2] > 0 ? zhi : zlo) - o.z) * k->exit_inv[2] > beyond;
}

/* setup_ray for a ray of direction k (tf_ray_dir): the same context, bit for bit. */
static int setup_ray_dir(ray_ctx *r, const tf_ray_dir *k, tf_vec3 o, double tmin, double tmax)
{
    if (!k->ok || !startable(o, tmin, tmax))
        return 0;
    const tf_vec3 d = {k->d[0], k->d[1], k->d[2]};
    setup_fields(r, k->hf, o, d, tmin, tmax);
    if (window_in_box(k, o, tmin, tmax))
        r->t_square = r->t0 = tmin, r->t1 = tmax;
    else if (!setup_box(r, k->hf, o, d, tmin, tmax, k->exit_inv))
        return 0;
    r->sx = k->sx, r->sy = k->sy, r->inv_dx = k->inv_dx, r->inv_dy = k->inv_dy;
    r->inv_cell = k->inv_cell;
    r->ci = cell_of(k->hf, r->inv_cell, o.x + r->t0 * d.x);
    r->cj = cell_of(k->hf, r->inv_cell, o.y + r->t0 * d.y);
    dir_tolerances(r, k, o);
    r->kx = k->kx, r->ky = k->ky, r->kz = k->kz, r->shx = k->shx, r->shy = k->shy, r->shz = k->shz;
    return 1;
}

/* Is the altitude span z_in..z_out wholly above hi or wholly below lo (by the margin)? */
static inline int culled(double z_in, double z_out, float hi, float lo, double margin)
{
    return tf_span_culled(z_in, z_out, hi, lo, margin);
}

/* Fill *hit from the winning candidate. */
static void finish_hit(const ray_ctx *r, const candidate *c, tf_hit *hit)
{
    const tf_heightfield *hf = r->hf;
    const float *h = hf->h + (size_t)c->cj * hf->n + c->ci;
    double ha = h[0], hb = h[1], hd = h[hf->n], hc = h[hf->n + 1];
    hit->t = c->t;
    hit->p = v3(r->o[0] + c->t * r->d[0], r->o[1] + c->t * r->d[1], r->o[2] + c->t * r->d[2]);
    hit->n = tf_hit_normal(ha, hb, hc, hd, hf->cell, c->tri == 0);
    hit->ci = c->ci;
    hit->cj = c->cj;
}

/* ---- the flat walk -------------------------------------------------------------------------- */

/* The flat walk, for a ray that rises (dz > 0: the altitude span of a cell is z_in..z_out in
 * that order, so culled() needs no ordering -- the same cells culled) or any ray. */
static inline __attribute__((always_inline)) int walk_flat_as(const ray_ctx *r, candidate *best,
                                                              int rising)
{
    const tf_heightfield *hf = r->hf;
    const float *mx = hf->maxgrid[0], *mn = hf->mingrid[0];
    const unsigned cells = (unsigned)hf->cells;
    const double oz = r->o[2], dz = r->d[2], t1 = r->t1, cell = hf->cell;
    int ci = r->ci, cj = r->cj;
    double t_cur = r->t0, z_cur = oz + t_cur * dz;
    double tx = exit_x(r, ci), ty = exit_y(r, cj);
    double tx_in = entry_x(r, ci), ty_in = entry_y(r, cj);
    /* the exit lines' offsets from (ci, cj), and the cell's index in the grids and its steps,
     * kept as the walk goes instead of recomputed from (ci, cj) */
    const int ax = r->sx > 0, ay = r->sy > 0;
    size_t idx = (size_t)cj * cells + (unsigned)ci;
    const ptrdiff_t di = r->sx, dj = (ptrdiff_t)r->sy * (ptrdiff_t)cells;
    for (;;) {
        /* tx <= ty ? tx : ty, the crossings never NaN (finite lines times a finite inverse,
         * or INFINITY): a minsd */
        double tc = ty < tx ? ty : tx;
        double t_out = tc < t1 ? tc : t1;
        if (t_out < t_cur)
            t_out = t_cur;
        double z_out = oz + t_out * dz;
        const int skip = rising ? z_cur > mx[idx] + r->margin || z_out < mn[idx] - r->margin
                                : culled(z_cur, z_out, mx[idx], mn[idx], r->margin);
        if (!skip &&
            test_cell_flat(r, ci, cj, tx, ty, tx_in, ty_in, t_cur, t_out, best))
            return 1;
        if (!(tc < t1))
            return 0;
        t_cur = t_out;
        z_cur = z_out;
        /* a finite crossing (tc < t1) on the axis stepped: that axis moves (sx or sy != 0) */
        if (tx <= ty) {
            ci += r->sx;
            if ((unsigned)ci >= cells)
                return 0;
            idx += di;
            tx_in = tx; /* the line just crossed: exit_x of the cell before is entry_x of this */
            tx = tf_grid_cross((double)(ci + ax), cell, r->o[0], r->inv_dx); /* exit_x(r, ci) */
        } else {
            cj += r->sy;
            if ((unsigned)cj >= cells)
                return 0;
            idx += dj;
            ty_in = ty;
            ty = tf_grid_cross((double)(cj + ay), cell, r->o[1], r->inv_dy);
        }
    }
}

static int walk_flat(const ray_ctx *r, candidate *best)
{
    return r->d[2] > 0 ? walk_flat_as(r, best, 1) : walk_flat_as(r, best, 0);
}

/* ---- the hierarchical walk ---------------------------------------------------------------- */

enum { STALE_NONE = TF_STALE_NONE, STALE_X = TF_STALE_X, STALE_Y = TF_STALE_Y };

/* After a block step the index on the other axis was not followed.  Recompute it inside the
 * current level-L block as the flat walk has it right after the crossing at t_event: on an x
 * crossing, the rows whose entry crossing is < t_event have been entered (x goes first on ties);
 * on a y crossing, the columns whose entry crossing is <= t_event.  `stale` is the old index,
 * which can only lag behind the true one. */
static int fix_stale_axis(const ray_ctx *r, int axis, int stale, int level, double t_event,
                          int strict)
{
    const int s = axis == 0 ? r->sx : r->sy;
    const int lo = (stale >> level) << level, hi = lo + (1 << level) - 1;
    const double o = r->o[axis], dd = r->d[axis];
    /* entered(j): was the crossing into index j processed before the event? */
#define ENTRY_T(j) (axis == 0 ? xcross(r, (j) + (s < 0)) : ycross(r, (j) + (s < 0)))
#define ENTERED(j) (strict ? ENTRY_T(j) < t_event : ENTRY_T(j) <= t_event)
    double g = (o + t_event * dd) * r->inv_cell; /* a guess: see cell_of */
    int j = g > lo ? (g < hi ? (int)g : hi) : lo;
    if (s > 0) {
        if (j < stale)
            j = stale;
        while (j > stale && !ENTERED(j))
            j--;
        while (j < hi && ENTERED(j + 1))
            j++;
    } else {
        if (j > stale)
            j = stale;
        while (j < stale && !ENTERED(j))
            j++;
        while (j > lo && ENTERED(j - 1))
            j--;
    }
#undef ENTERED
#undef ENTRY_T
    return j;
}

/* A descent from level `level` with the index on `axis` stale needs that index only to the
 * next level's block: which half of the current block the ray is in at t_event.  One
 * crossing, the line between the halves, decides it, by fix_stale_axis's rule (the index
 * whose entry crossing came before the event; `strict` as there): the index moves to the
 * first one of the far half if the ray has entered it, else stays.  Either way it is right to
 * the next level and still lags behind the true one below, so the axis stays stale until
 * level 0, where every bit has been settled this way, one a descent.  (fix_stale_axis finds
 * all the bits at once with two or more crossings; 5 descents a primary ray fixed an axis.) */
static int settle_half(const ray_ctx *r, int axis, int stale, int level, double t_event,
                       int strict)
{
    const int s = axis == 0 ? r->sx : r->sy;
    const int mid = ((stale >> level) << level) + (1 << (level - 1));
    if (s > 0 ? stale >= mid : stale < mid)
        return stale; /* already in the half it can only move into */
    double t = axis == 0 ? xcross(r, mid) : ycross(r, mid);
    int entered = strict ? t < t_event : t <= t_event;
    int settled = entered ? (s > 0 ? mid : mid - 1) : stale;
#ifndef NDEBUG
    const int exact = fix_stale_axis(r, axis, stale, level, t_event, strict);
    assert(settled >> (level - 1) == exact >> (level - 1) &&
           "settle_half: the next level's block is fix_stale_axis's");
    assert((s > 0 ? settled <= exact : settled >= exact) &&
           "settle_half: the index still lags behind fix_stale_axis's");
#endif
    return settled;
}

/* Does the altitude z lie within level L's block around cell (ci, cj), widened by the margin?
 * Then the walk's cull test of that block, over any span that contains z, fails (culled()'s
 * comparisons negated term for term): the walk would descend from it without moving.  Only the
 * index bits at and above L are used, which are right even on a stale axis. */
static inline size_t block_index(const tf_heightfield *hf, int L, int ci, int cj)
{
    return (size_t)(cj >> L) * (size_t)(hf->cells >> L) + (size_t)(ci >> L);
}

static inline int inside_block(const tf_heightfield *hf, int L, int ci, int cj, double z,
                               double margin)
{
    const size_t idx = block_index(hf, L, ci, cj);
    return z <= hf->maxgrid[L][idx] + margin && z >= hf->mingrid[L][idx] - margin;
}

static int walk_hier(const ray_ctx *r, candidate *best)
{
    const tf_heightfield *hf = r->hf;
    const int cells = hf->cells, top = hf->levels - 1;
    /* Local copies of the hot fields; the crossing expressions are xcross()/ycross() spelled
     * out, term for term, so they give the same bits.  One function on purpose: split into
     * steps over a struct of this state, the walk ran 0.7-2% more instructions (the struct
     * left the registers; bench/README.md section 46). */
    const double ox = r->o[0], oy = r->o[1], oz = r->o[2], dz = r->d[2], t1 = r->t1;
    const double cell = hf->cell, inv_dx = r->inv_dx, inv_dy = r->inv_dy, margin = r->margin;
    const int sx = r->sx, sy = r->sy, x_ahead = sx > 0, y_ahead = sy > 0;
    int ci = r->ci, cj = r->cj;
    int stale = STALE_NONE;
    double t_cur = r->t0, t_event = r->t0;
    /* Where to start: level 0, the flat walk itself, from which the usual climbing begins.
     * The hit is the same from any start level: every level's walk groups the same cell
     * sequence and skips only culled blocks (top of the file).  A ray that starts at or under
     * the surface nearby (a shadow ray, a camera down in a valley) would only descend, in
     * place, from any higher level; one that starts above the terrain climbs as it goes.  A
     * search for the highest level whose block around the start does not hold z(t0), a load
     * and two comparisons a level, cost more than the climbs it spared: renders took 1.5-2%
     * more CPU with it (bench/README.md section 42). */
    int level = 0;
    for (;;) {
        const int bi = ci >> level, bj = cj >> level;
        double tx = sx ? tf_grid_cross((double)((bi + x_ahead) << level), cell, ox, inv_dx)
                       : INFINITY;
        double ty = sy ? tf_grid_cross((double)((bj + y_ahead) << level), cell, oy, inv_dy)
                       : INFINITY;
        double tc = ty < tx ? ty : tx; /* tx <= ty ? tx : ty: never NaN (walk_flat) */
        double t_out = tc < t1 ? tc : t1;
        if (t_out < t_cur)
            t_out = t_cur;
        size_t idx = (size_t)bj * (size_t)(cells >> level) + (size_t)bi;
        if (!culled(oz + t_cur * dz, oz + t_out * dz, hf->maxgrid[level][idx],
                    hf->mingrid[level][idx], margin)) {
            if (level == 0) {
                if (test_cell_over(r, ci, cj, tx, ty, t_cur, t_out, best))
                    return 1;
            } else {
                if (stale == STALE_Y)
                    cj = settle_half(r, 1, cj, level, t_event, 1);
                else if (stale == STALE_X)
                    ci = settle_half(r, 0, ci, level, t_event, 0);
                level--;
                if (level == 0)
                    stale = STALE_NONE;
                continue;
            }
        }
        if (!(tc < t1))
            return 0;
        t_cur = t_out;
        t_event = tc;
        int boundary; /* the grid line crossed, in units of level-L blocks */
        if (tx <= ty) {
            boundary = bi + x_ahead;
            ci = x_ahead ? boundary << level : (boundary << level) - 1;
            if ((unsigned)ci >= (unsigned)cells)
                return 0;
            stale = level > 0 && sy ? STALE_Y : STALE_NONE;
        } else {
            boundary = bj + y_ahead;
            cj = y_ahead ? boundary << level : (boundary << level) - 1;
            if ((unsigned)cj >= (unsigned)cells)
                return 0;
            stale = level > 0 && sx ? STALE_X : STALE_NONE;
        }
        /* A line that also bounds the parent block lets the walk climb back up, one level per
         * step (climbing straight to the largest aligned block costs more re-descents), unless
         * the parent holds the altitude where the ray enters it: that block is not culled, and
         * the walk would descend from it at once to where it is now.  Its settle_half could not
         * move the stale index: the line between the parent's halves on the stale axis is the
         * one this step did not cross.  (4 of a primary ray's 5 climbs were such round trips.) */
        if (level < top && !(boundary & 1) &&
            !inside_block(hf, level + 1, ci, cj, oz + t_cur * dz, margin))
            level++;
    }
}

/* ---- coherence: a camera ray helped by the one below it --------------------------------------

   Two rays from one origin O, headings u1, u2 (unit, horizontal) and climbs k1, k2 (height per
   unit of horizontal run s): at run s they are at O + s (u_i, k_i), a horizontal distance
   s |u2 - u1| apart.  Let the surface f have slope at most L (hf->slope_max) and ray 1 be above
   it, z1(s) >= f(p1(s)), over the run [s_in1, s_free1) in which p1(s) is inside the square.
   Where p2(s) is inside the square too, the segment p1 p2 is (the square is convex), so
       z2(s) - f(p2(s)) >= z1(s) - f(p1(s)) + s (k2 - k1) - L s |u2 - u1| >= s D,
   D = k2 - k1 - L |u2 - u1|; where p2(s) is outside, there is no surface under it at all.
   With D > 0 ray 2 is above the surface over [s_in1, s_free1): the same cells as ever, culled
   or tested, find no hit there.  Margins, so that this holds in floating point too:
     C1. D is computed with |u2 - u1| <= |dx| + |dy| (no square root), then lowered by
         1e-9 (1 + |k1| + |k2| + L), far above the few roundings in k, u and L (L itself is
         rounded up: heightfield.c's steepest_slope).
     C2. Ray 1 may be below the surface by a rounding where its tests missed a graze; ray 2 is
         vouched for only from the run s_eps = eps / D on, where its clearance s D >= eps =
         1e-7 times the scene's size, orders above the error of a triangle test.
     C3. The run from ray 2's own entry into the square up to max(s_in1, s_eps) is not vouched
         for: it is walked as usual (the prefix, its end rounded up by 1e-14: walking a hair
         more is always safe), then the walk resumes at s_free1 (times 1 - 1e-9).
   Why the hit stays tf_trace's, bit for bit: the prefix walk is the usual walk with its end
   t1 moved in, so it meets the same cells with the same tests until then; a cell it culls on
   the shortened span has no hit up to the new end, and past it lies the vouched-for run (a hit
   beyond that, in the same cell, the main walk meets in that cell again).  The
   main walk starts at t_skip with the cell indices the flat walk holds there (index_at: every
   exit crossing before t_skip processed), which is a state the flat walk passes through; from
   there both walks are one.  Its first cell is culled on a shorter span than the flat walk's,
   which matters only for a hit before t_skip, and there is none.  Ray 1 "above the surface":
   its first hit comes from above (d . n < 0), or it misses and starts (at t0) above its
   cell's maximum; either way no crossing comes before the end of its walk. */

/* The clearance both coherence proofs ask of a ray from (ox, oy, oz) (trace_math.h). */
static double clearance_eps(const tf_heightfield *hf, double ox, double oy, double oz)
{
    return tf_clearance_eps(hf->extent, hf->hmin, hf->hmax, ox, oy, oz);
}

/* The exit crossing of index c on axis 0 (x) or 1 (y). */
static inline double exit_on(const ray_ctx *r, int axis, int c)
{
    return axis ? exit_y(r, c) : exit_x(r, c);
}

/* The index on `axis` the flat walk holds at parameter t: its first index c0 moved over every
 * exit crossing before t (those are monotone in the index); -1 if the walk leaves the grid
 * first. */
static int index_at(const ray_ctx *r, int axis, int c0, double t)
{
    const int s = axis ? r->sy : r->sx;
    if (!s)
        return c0;
    int c = cell_of(r->hf, r->inv_cell, r->o[axis] + t * r->d[axis]); /* a guess */
    if (s > 0 ? c < c0 : c > c0)
        c = c0;
    while (c != c0 && !(exit_on(r, axis, c - s) < t))
        c -= s;
    while (exit_on(r, axis, c) < t) {
        c += s;
        if ((unsigned)c >= (unsigned)r->hf->cells)
            return -1;
    }
    return c;
}

/* Move the walk's start to t (> t0): 0 if the walk has ended by then. */
static int skip_to(ray_ctx *r, double t)
{
    if (!(t < r->t1))
        return 0;
    int ci = index_at(r, 0, r->ci, t), cj = index_at(r, 1, r->cj, t);
    if (ci < 0 || cj < 0)
        return 0;
    r->t0 = t, r->ci = ci, r->cj = cj;
    return 1;
}

/* A ray's heading and climb (tf_ray_clear's ux, uy, k) and its run per unit of t; 0 for a
 * vertical ray or one whose run overflows. */
typedef struct heading {
    double run, ux, uy, k;
} heading;

static int heading_of(const ray_ctx *r, heading *h)
{
    return tf_heading(r->d[0], r->d[1], r->d[2], &h->run, &h->ux, &h->uy, &h->k);
}

/* Does `lower` vouch for part of this ray (C1-C3)?  Then *t_pre is where the prefix walk ends
 * (t0 or less: no prefix) and *t_skip where the main walk starts. */
static int vouched(const ray_ctx *r, const heading *h, const tf_ray_clear *lower, double *t_pre,
                   double *t_skip)
{
    const tf_heightfield *hf = r->hf;
    if (lower->o[0] != r->o[0] || lower->o[1] != r->o[1] || lower->o[2] != r->o[2])
        return 0;
    if (!(hf->slope_max >= 0 && hf->slope_max < INFINITY)) /* no bound (heights that overflow) */
        return 0;
    const double eps = clearance_eps(hf, r->o[0], r->o[1], r->o[2]);
    return tf_vouched(h->ux, h->uy, h->k, h->run, r->t_square, r->t0, lower->ux, lower->uy,
                      lower->k, lower->s_in, lower->s_free, hf->slope_max, eps, t_pre, t_skip);
}

/* tf_vouched's D before its margin is positive: false only where tf_vouched's D (the same
 * expression, less a margin) is not positive either, and without tf_vouched's divisions. */
static inline int climbs_clear(const ray_ctx *r, const heading *h, const tf_ray_clear *lower)
{
    const double dx = h->ux - lower->ux, dy = h->uy - lower->uy;
    return (h->k - lower->k) - r->hf->slope_max * (fabs(dx) + fabs(dy)) > 0;
}

/* The first of lowers[0 .. n) (NULL entries allowed) that vouches for part of the ray: its
 * prefix end and skip (vouched); 0 if none does.  Any one that vouches is a proof of its own,
 * so which is taken changes only the time: callers list the likeliest to reach furthest
 * first. */
static int first_vouched(const ray_ctx *r, const heading *h, const tf_ray_clear *const *lowers,
                         int n, double *t_pre, double *t_skip)
{
    for (int m = 0; m < n; m++)
        if (lowers[m] && lowers[m]->s_free > 0 && climbs_clear(r, h, lowers[m]) &&
            vouched(r, h, lowers[m], t_pre, t_skip))
            return 1;
    return 0;
}

/* walk_hier, skipping what the first of `lowers` that can vouches for. */
static int walk_coherent(ray_ctx *r, const heading *h, const tf_ray_clear *const *lowers, int n,
                         candidate *best)
{
    double t_pre, t_skip;
    if (!first_vouched(r, h, lowers, n, &t_pre, &t_skip))
        return walk_hier(r, best);
    if (t_pre > r->t0) { /* the prefix: the walk with its end moved in */
        const double t1 = r->t1;
        r->t1 = t_pre < t1 ? t_pre : t1;
        int found = walk_hier(r, best);
        r->t1 = t1;
        if (found)
            return 1;
    }
    return skip_to(r, t_skip) && walk_hier(r, best);
}

/* Was hit c made from above (d . n < 0, n the triangle's upward normal, unnormalised), by more
 * than the dot product's rounding? */
static int from_above(const ray_ctx *r, const candidate *c)
{
    const tf_heightfield *hf = r->hf;
    const float *p = hf->h + (size_t)c->cj * hf->n + c->ci;
    const tf_vec3 d = {r->d[0], r->d[1], r->d[2]};
    return tf_hit_from_above(p[0], p[1], p[hf->n + 1], p[hf->n], hf->cell, c->tri == 0, d);
}

/* Does the ray start (at t0, as set up) above its cell's maximum? */
static int starts_above(const ray_ctx *r)
{
    const size_t idx = (size_t)r->cj * (size_t)r->hf->cells + (size_t)r->ci;
    return r->o[2] + r->t0 * r->d[2] > r->hf->maxgrid[0][idx] + r->margin;
}

/* This ray's record (c its hit or NULL; above: starts_above before the walk). */
static void note_clear(const ray_ctx *r, const heading *h, const candidate *c, int above,
                       tf_ray_clear *mine)
{
    mine->ux = h->ux, mine->uy = h->uy, mine->k = h->k;
    mine->s_in = r->t_square * h->run;
    if (c ? from_above(r, c) : above)
        mine->s_free = (c ? c->t : r->t1) * h->run;
}

int tf_trace_coherent_among(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmax,
                            const tf_ray_clear *const *lowers, int n, tf_hit *hit,
                            tf_ray_clear *mine)
{
    ray_ctx r;
    heading h;
    candidate best = {INFINITY, 0, 0, 0};
    if (mine)
        *mine = (tf_ray_clear){{origin.x, origin.y, origin.z}, 0, 0, 0, INFINITY, 0};
    if (!setup_ray(&r, hf, origin, dir, 0.0, tmax))
        return 0;
    if (hf->proc || !heading_of(&r, &h)) /* no slope_max, or no heading: the plain walk */
        n = 0, mine = NULL;
    const int above = mine && starts_above(&r);
    int found = walk_coherent(&r, &h, lowers, n, &best); /* may move r's start, never o, d, t1 */
    if (mine)
        note_clear(&r, &h, found ? &best : NULL, above, mine);
    if (found && hit)
        finish_hit(&r, &best, hit);
    return found;
}

int tf_trace_coherent(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmax,
                      const tf_ray_clear *lower, tf_hit *hit, tf_ray_clear *mine)
{
    return tf_trace_coherent_among(hf, origin, dir, tmax, &lower, lower != NULL, hit, mine);
}

/* ---- coherence of shadow rays: under the surface where the neighbour was ----------------------

   A ray that starts inside the terrain's square above the surface (by eps) and is under it (by
   eps) at a parameter t in (0, tmax), inside the square, crosses the surface in between: the
   square is convex, so the segment stays over the surface's domain, and the surface is
   continuous there.  The walk finds that crossing -- its triangle tests are watertight and it
   tests every cell where the ray may dip below the cell's maximum (the top of the file) -- so
   tf_occluded says 1, and so may we, after a lookup or two of the height under the ray instead
   of the walk.  Where to look: where a parallel neighbour was found under the surface, and a
   cell or three further on.  eps is 1e-7 times the scene's size, orders above the rounding of
   tf_heightfield_height_at, which interpolates the very triangles the walk tests. */

/* The altitude of p over the surface (< 0: under it); NAN outside the terrain's square. */
static double over_surface(const tf_heightfield *hf, tf_vec3 p)
{
    const double top = (double)hf->cells * hf->cell;
    if (!(p.x >= 0 && p.x <= top && p.y >= 0 && p.y <= top))
        return NAN;
    return p.z - tf_heightfield_height_at(hf, p.x, p.y);
}

/* A parameter in (0, tmax) at which the ray is provably under the surface, found from the
 * neighbour's; 0 if none. */
static double under_like_near(const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmax,
                              const tf_shadow_clear *near)
{
    if (!near || !(near->t_under > 0) || near->d[0] != d.x || near->d[1] != d.y ||
        near->d[2] != d.z || hf->proc)
        return 0;
    const double eps = clearance_eps(hf, o.x, o.y, o.z);
    if (!(over_surface(hf, o) > eps))
        return 0;
    const double run = sqrt(d.x * d.x + d.y * d.y), step = run > 0 ? hf->cell / run : 0;
    const double probes[3] = {near->t_under, near->t_under + step, near->t_under + 3 * step};
    for (int k = 0; k < 3; k++) {
        const double t = probes[k];
        if (t > 0 && t < tmax && over_surface(hf, v3_add(o, v3_scale(d, t))) < -eps)
            return t;
    }
    return 0;
}

/* An occlusion walk over the ray's span: the flat walk where the span crosses fewer than
 * TF_FLAT_OCCLUSION_CELLS cells, else the hierarchical one.  Both find the same first hit (the top of the file); a shadow ray the sun's
 * strips prove clear a few bins on skims the surface all the way, where no block above level
 * 0 can be culled, and the flat walk spares it the climbs and descents (bench/README.md
 * section 27). */
static int walk_occlusion(const ray_ctx *r, candidate *best)
{
    const double cells_per_t = (fabs(r->d[0]) + fabs(r->d[1])) * r->inv_cell;
    const double span = (r->t1 - r->t0) * cells_per_t;
    return span < TF_FLAT_OCCLUSION_CELLS ? walk_flat(r, best) : walk_hier(r, best);
}

int tf_occluded_coherent(const tf_ray_dir *dir, tf_vec3 origin, double tmax,
                         const tf_shadow_clear *near, tf_shadow_clear *mine)
{
    const tf_vec3 d = {dir->d[0], dir->d[1], dir->d[2]};
    double t = dir->ok ? under_like_near(dir->hf, origin, d, tmax, near) : 0;
    ray_ctx r;
    if (!(t > 0) && setup_ray_dir(&r, dir, origin, 0.0, tmax)) {
        candidate best = {INFINITY, 0, 0, 0};
        r.planes = 1; /* an occlusion walk: the plane test */
        if (walk_occlusion(&r, &best))
            t = best.t;
    }
    if (mine)
        *mine = (tf_shadow_clear){{d.x, d.y, d.z}, t > 0 ? t : 0, {0, 0, 0}};
    return t > 0;
}

int tf_ray_dir_init(tf_ray_dir *dir, const tf_heightfield *hf, tf_vec3 d)
{
    return dir_of(dir, hf, d);
}

/* ---- public entry points ---------------------------------------------------------------------- */

/* Trace one ray with the flat or the hierarchical walk (the same hit, bit for bit); the hit is
 * filled in when `hit` is not NULL. */
static int trace_ray(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmin,
                     double tmax, int flat, tf_hit *hit)
{
    ray_ctx r;
    candidate best = {INFINITY, 0, 0, 0};
    if (!setup_ray(&r, hf, origin, dir, tmin, tmax))
        return 0;
    if (!(flat ? walk_flat(&r, &best) : walk_hier(&r, &best)))
        return 0;
    if (hit)
        finish_hit(&r, &best, hit);
    return 1;
}

int tf_trace_flat(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmin, double tmax,
                  tf_hit *hit)
{
    return trace_ray(hf, origin, dir, tmin, tmax, 1, hit);
}

int tf_trace(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmin, double tmax,
             tf_hit *hit)
{
    return trace_ray(hf, origin, dir, tmin, tmax, 0, hit);
}

/* The first cell whose test hits ends the walk, so this is already an early exit; the plane
 * test spares most of the cells a ray skimming the surface meets their triangle tests. */
int tf_occluded(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmin, double tmax)
{
    ray_ctx r;
    candidate best = {INFINITY, 0, 0, 0};
    if (!setup_ray(&r, hf, origin, dir, tmin, tmax))
        return 0;
    r.planes = 1;
    return walk_hier(&r, &best);
}

/* ---- the pieces the packet tracer calls per lane (trace_internal.h) -------------------------- */

int tf_trace_setup(tf_ray_ctx *r, const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmin,
                   double tmax)
{
    return setup_ray(r, hf, o, d, tmin, tmax);
}

int tf_trace_setup_dir(tf_ray_ctx *r, const tf_ray_dir *dir, tf_vec3 o, double tmin,
                       double tmax)
{
    return setup_ray_dir(r, dir, o, tmin, tmax);
}

int tf_trace_test_cell(const tf_ray_ctx *r, int ci, int cj, double tx, double ty,
                       tf_trace_cand *best)
{
    return test_cell(r, ci, cj, tx, ty, best);
}

int tf_trace_fix_stale(const tf_ray_ctx *r, int axis, int stale, int level, double t_event,
                       int strict)
{
    return fix_stale_axis(r, axis, stale, level, t_event, strict);
}

void tf_trace_finish(const tf_ray_ctx *r, const tf_trace_cand *c, tf_hit *hit)
{
    finish_hit(r, c, hit);
}
