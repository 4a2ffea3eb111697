/* fractal_bound.c: interval bounds of the noise and of the terrain functions (fractal_bound.h).
 *
 * The formulas mirror fractal.c's hetero_axes, hybrid_axes and ridged_axes and noise_impl.h's
 * tf_fbm2_axes operation for operation, in interval arithmetic; where they change, this file
 * must change with them (tests/unit/test_fractal_bound.c fails otherwise). */
#include "terrain/fractal_bound.h"

#include <math.h>

/* A box of noise space wider than this many lattice cells a side gets the whole range. */
#define BOUND_MAX_CELLS 4
/* Widening that covers the point evaluation's rounding (coordinates are products of up to 32
 * lacunarity steps; the sums a few dozen terms): orders of magnitude above it. */
#define BOUND_COORD_SLACK 1e-9
#define BOUND_VALUE_SLACK 1e-9

/* min and max without libm's calls (fmin and fmax are calls at -O2; no NaN reaches here but
 * a NaN bound would only ever widen to the other operand). */
static inline double lesser(double a, double b) { return a < b ? a : b; }
static inline double greater(double a, double b) { return a > b ? a : b; }
#define fmin lesser
#define fmax greater

static tf_interval iv(double lo, double hi) { return (tf_interval){lo, hi}; }
static tf_interval iv_hull(tf_interval a, tf_interval b)
{
    return iv(fmin(a.lo, b.lo), fmax(a.hi, b.hi));
}
static tf_interval iv_add(tf_interval a, tf_interval b) { return iv(a.lo + b.lo, a.hi + b.hi); }
static tf_interval iv_shift(tf_interval a, double c) { return iv(a.lo + c, a.hi + c); }
static tf_interval iv_scale(tf_interval a, double c) /* c >= 0 */
{
    return iv(a.lo * c, a.hi * c);
}
static tf_interval iv_mul(tf_interval a, tf_interval b)
{
    double p[4] = {a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi};
    return iv(fmin(fmin(p[0], p[1]), fmin(p[2], p[3])), fmax(fmax(p[0], p[1]), fmax(p[2], p[3])));
}
static tf_interval iv_clamp01(tf_interval a)
{
    return iv(fmin(fmax(a.lo, 0.0), 1.0), fmin(fmax(a.hi, 0.0), 1.0));
}
static tf_interval iv_abs(tf_interval a)
{
    if (a.lo >= 0)
        return a;
    if (a.hi <= 0)
        return iv(-a.hi, -a.lo);
    return iv(0.0, fmax(-a.lo, a.hi));
}
static tf_interval iv_square(tf_interval a)
{
    tf_interval m = iv_abs(a);
    return iv(m.lo * m.lo, m.hi * m.hi);
}

/* ------------------------------------------------------------------------------ noise */

/* The gradient at lattice corner (X, Y), as tf_noise_column_at looks it up. */
static const double *corner_gradient(const tf_noise *nz, int64_t X, int64_t Y)
{
    const uint16_t *p = nz->perm;
    int a = p[X & (TF_NOISE_LATTICE - 1)] + (int)(Y & (TF_NOISE_LATTICE - 1));
    return tf_grad2[p[a] & (TF_NOISE_GRADS - 1)];
}

/* g . (u, v) over u in [u0, u1], v in [v0, v1]: exact for a linear function. */
static tf_interval linear_bound(const double *g, double u0, double u1, double v0, double v1)
{
    return iv(fmin(g[0] * u0, g[0] * u1) + fmin(g[1] * v0, g[1] * v1),
              fmax(g[0] * u0, g[0] * u1) + fmax(g[1] * v0, g[1] * v1));
}

/* The noise over the part [u0, u1] x [v0, v1] (local coordinates, within [0, 1]) of cell
 * (X, Y): a convex blend of the four corners' linear functions. */
static tf_interval cell_bound(const tf_noise *nz, int64_t X, int64_t Y, double u0, double u1,
                              double v0, double v1)
{
    tf_interval b = linear_bound(corner_gradient(nz, X, Y), u0, u1, v0, v1);
    b = iv_hull(b, linear_bound(corner_gradient(nz, X + 1, Y), u0 - 1, u1 - 1, v0, v1));
    b = iv_hull(b, linear_bound(corner_gradient(nz, X, Y + 1), u0, u1, v0 - 1, v1 - 1));
    b = iv_hull(b, linear_bound(corner_gradient(nz, X + 1, Y + 1), u0 - 1, u1 - 1, v0 - 1,
                                v1 - 1));
    return iv_scale(b, TF_NOISE2_SCALE);
}

tf_interval tf_noise2_bound(const tf_noise *nz, double x0, double x1, double y0, double y1)
{
    double sx = BOUND_COORD_SLACK * fmax(1.0, fmax(fabs(x0), fabs(x1)));
    double sy = BOUND_COORD_SLACK * fmax(1.0, fmax(fabs(y0), fabs(y1)));
    x0 -= sx, x1 += sx, y0 -= sy, y1 += sy;
    if (!(fmax(fabs(x0), fabs(x1)) < TF_NOISE_COORD_LIMIT / 2 &&
          fmax(fabs(y0), fabs(y1)) < TF_NOISE_COORD_LIMIT / 2))
        return iv(-1.0, 1.0);
    int64_t X0 = (int64_t)floor(x0), X1 = (int64_t)floor(x1);
    int64_t Y0 = (int64_t)floor(y0), Y1 = (int64_t)floor(y1);
    if (X1 - X0 >= BOUND_MAX_CELLS || Y1 - Y0 >= BOUND_MAX_CELLS)
        return iv(-1.0, 1.0);
    tf_interval b = iv(INFINITY, -INFINITY);
    for (int64_t Y = Y0; Y <= Y1; Y++)
        for (int64_t X = X0; X <= X1; X++)
            b = iv_hull(b, cell_bound(nz, X, Y, fmax(x0 - (double)X, 0.0),
                                      fmin(x1 - (double)X, 1.0), fmax(y0 - (double)Y, 0.0),
                                      fmin(y1 - (double)Y, 1.0)));
    return iv(fmax(b.lo - BOUND_VALUE_SLACK, -1.0), fmin(b.hi + BOUND_VALUE_SLACK, 1.0));
}

/* ------------------------------------------------------------------------------ terrains */

/* The running state of one spectral sum in intervals: `value` is fBm's, hybrid's and ridged's
 * result or hetero's altitude; `signal` the previous octave's weighted signal. */
typedef struct sum_state {
    tf_interval value, signal;
} sum_state;

static void first_octave(const tf_fractal *f, tf_interval n, sum_state *s)
{
    switch (f->generator) {
    case TF_GEN_HETERO:
        s->value = iv_shift(n, f->offset);
        break;
    case TF_GEN_HYBRID:
        s->signal = s->value = iv_scale(iv_shift(n, f->offset), 0.5);
        break;
    case TF_GEN_RIDGED:
        s->signal = s->value = iv_square(iv_shift(iv_abs(n), -f->offset));
        break;
    default:
        s->value = n;
        break;
    }
    if (f->generator == TF_GEN_FBM || f->generator == TF_GEN_HETERO)
        s->signal = s->value; /* unused by these two */
}

static void next_octave(const tf_fractal *f, tf_interval n, double amp, sum_state *s)
{
    tf_interval weight = iv_clamp01(iv_scale(s->signal, f->gain));
    switch (f->generator) {
    case TF_GEN_HETERO: /* altitude += altitude * increment */
        s->value = iv_mul(s->value, iv_shift(iv_scale(iv_shift(n, f->offset), amp), 1.0));
        break;
    case TF_GEN_HYBRID:
        s->signal = iv_mul(weight, iv_scale(iv_shift(n, f->offset), 0.5));
        s->value = iv_add(s->value, iv_scale(s->signal, amp));
        break;
    case TF_GEN_RIDGED: /* ridge = (offset - |n|)^2 */
        s->signal = iv_mul(weight, iv_square(iv_shift(iv_abs(n), -f->offset)));
        s->value = iv_add(s->value, iv_scale(s->signal, amp));
        break;
    default:
        s->value = iv_add(s->value, iv_scale(n, amp));
        break;
    }
}

void tf_fractal_bound_plan(tf_octaves *full, const tf_fractal *f)
{
    tf_octaves_plan(full, f->H, f->octaves.lacunarity, (double)TF_MAX_OCTAVES);
}

tf_interval tf_fractal_bound(const tf_fractal *f, const tf_octaves *full, const tf_noise *nz,
                             double x0, double x1, double y0, double y1, double octaves_lo,
                             double octaves_hi)
{
    octaves_lo = fmin(fmax(octaves_lo, 1.0), TF_MAX_OCTAVES);
    octaves_hi = fmin(fmax(octaves_hi, octaves_lo), TF_MAX_OCTAVES);
    int first = (int)octaves_lo, last = (int)octaves_hi + 1;
    if (last > TF_MAX_OCTAVES)
        last = TF_MAX_OCTAVES;
    double nx0 = x0 / f->feature_size + f->ox, nx1 = x1 / f->feature_size + f->ox;
    double ny0 = y0 / f->feature_size + f->oy, ny1 = y1 / f->feature_size + f->oy;
    sum_state s = {{0, 0}, {0, 0}};
    first_octave(f, tf_noise2_bound(nz, nx0, nx1, ny0, ny1), &s);
    tf_interval hull = first <= 1 ? s.value : iv(INFINITY, -INFINITY);
    for (int i = 1; i < last; i++) {
        nx0 *= full->lacunarity, nx1 *= full->lacunarity;
        ny0 *= full->lacunarity, ny1 *= full->lacunarity;
        next_octave(f, tf_noise2_bound(nz, nx0, nx1, ny0, ny1), full->amp[i], &s);
        if (i + 1 >= first)
            hull = iv_hull(hull, s.value);
    }
    double slack = BOUND_VALUE_SLACK * fmax(1.0, fmax(fabs(hull.lo), fabs(hull.hi)));
    return iv(hull.lo - slack, hull.hi + slack);
}
