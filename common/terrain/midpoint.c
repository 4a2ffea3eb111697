/* midpoint.c: random midpoint displacement (diamond-square) under Koh & Hearn's control
 * envelope -- tf_gen_midpoint, the TF_GEN_MIDPOINT generator.
 *
 * Source: E.-K. Koh, D. D. Hearn, "Fast Generation and Surface Structuring Methods for
 * Terrain and Other Natural Phenomena", Computer Graphics Forum (Eurographics '92), 1992; the
 * sections below are that paper's.
 *
 *  - Section 2, random midpoint displacement, eqs. (9) and (10): a new point is the average of
 *    its already-known neighbours plus a random displacement whose amplitude shrinks with the
 *    grid separation.  We use the diamond-square arrangement: level l first sets square centres
 *    from their 4 corners (eq. 10), then edge midpoints from their 4 (3 at the border) diamond
 *    neighbours.  The amplitude is multiplied by 2^-roughness per level (roughness = H).
 *
 *  - Section 3, "Specifying the Surface Envelope" / "Calculating Control Elevations": the
 *    envelope is given as envelope_n x envelope_n control points over the whole terrain; each
 *    control square is split into two triangles along the diagonal (ci,cj)-(ci+1,cj+1) (the
 *    same split the tracer uses), and the control elevation of a grid point is the plane of its
 *    triangle, eq. (12).  The grid corners start ON the envelope (as in the paper).
 *
 *  - Section 3, "Modified Gaussian Distribution Function", eq. (11): the displacement's mean
 *    and deviation follow the mismatch between the neighbour average A and the control
 *    elevation C: mu_F = C - A, sigma_F = s |mu_F|.  Taken literally (mean exactly C - A) every
 *    level re-draws the surface around the envelope and nothing of the coarser random detail
 *    survives; the paper only asks mu to follow the difference, and adds that sigma may also
 *    be "proportional to grid separations times a surface roughness factor".  We split the
 *    mismatch C - A into the envelope's own bend C - A_c (A_c: the same average taken over the
 *    control elevations), followed fully, and the inherited deviation A - A_c, of which a
 *    fraction P (MP_PULL, now 0: see there) is pulled back per level:
 *        mu = (C - A) + (1 - P)(A - A_c),   sigma = S |C - A_c| + a_l,   height = A + mu + sigma g
 *    with S = 0.1 (the paper's results section) and |mu| taken as the bend |C - A_c| alone, a_l = tolerance * 2^-(roughness * l) / 2 and
 *    g ~ N(0, 1).  The deviation from the envelope is then itself a midpoint-displacement
 *    fractal of roughness H.  Finally the height is limited to C +- envelope_tolerance, which
 *    makes "every sample within tolerance of the envelope" a guarantee; with these constants
 *    the limit binds on ~0% of samples for roughness >= 0.5 (on ~10% at roughness 0, white
 *    noise, where the band does the work).
 *
 * Without an envelope (envelope_n = 0) it is plain diamond-square: corners are random with
 * amplitude 1/2, the displacement amplitude at level l is 2^-(roughness * l) / 2, output is
 * roughly -1..1.
 *
 * Determinism: each displacement is a hash of (seed, level, global i, global j); each phase
 * (diamond or square step of one level) reads only values fixed by earlier phases, so rows are
 * split among threads freely.  The global indices are at the k = 13 scale (i << (13 - k)), so
 * a smaller grid is exactly the subsampling of a larger one for the same seed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "terrain/gridgen.h"
#include "terrain/terrain.h"
#include "log.h"

#define MP_KMAX 13
/* P: fraction of the inherited deviation pulled back per level.  0: any pull leaves each
 * coarser sample standing (P x its deviation) above its finer neighbours, level after level,
 * which shows as a lattice of single-sample spikes; the final clamp to C +- tolerance is what
 * keeps the surface inside the envelope. */
#define MP_PULL 0.0
#define MP_SIGMA_SCALE 0.1   /* S: Koh & Hearn's scaling factor s of eq. (11) */
#define MP_ROUGH_SCALE 0.5   /* a_l = tolerance * MP_ROUGH_SCALE * 2^-(H l) */
#define MP_FREE_AMP 0.5      /* amplitude of corners and level 0 without an envelope */

/* One control coordinate: cell index and fraction for grid index i of n along a side with
 * `cn` control points.  Integer arithmetic, so control points land exactly on grid points. */
static void envelope_coord(int i, int n, int cn, int *cell, double *frac)
{
    long long num = (long long)i * (cn - 1);
    int c = (int)(num / (n - 1));
    long long rem = num % (n - 1);
    if (c >= cn - 1) { /* the far edge belongs to the last cell */
        c = cn - 2;
        rem = n - 1;
    }
    *cell = c;
    *frac = (double)rem / (double)(n - 1);
}

/* Control elevation at grid point (i, j) of an n x n grid: the plane of the control triangle
 * over it (Koh & Hearn eq. 12), the envelope split along the (0,0)-(1,1) diagonal of each
 * control square.  Needs t->envelope_n >= 2. */
static double envelope_plane(const tf_terrain *t, int ci, double fx, int cj, double fy)
{
    int cn = t->envelope_n;
    const double *e = t->envelope;
    double z00 = e[cj * cn + ci], z10 = e[cj * cn + ci + 1];
    double z01 = e[(cj + 1) * cn + ci], z11 = e[(cj + 1) * cn + ci + 1];
    /* Barycentric weights: exactly 0 or 1 at the control points, which are thus reproduced
     * exactly (and the two triangles agree on the diagonal fx == fy). */
    if (fx >= fy) /* triangle (0,0) (1,0) (1,1) */
        return (1.0 - fx) * z00 + (fx - fy) * z10 + fy * z11;
    return (1.0 - fy) * z00 + (fy - fx) * z01 + fx * z11; /* triangle (0,0) (0,1) (1,1) */
}

double tf_envelope_at(const tf_terrain *t, int n, int i, int j)
{
    int ci, cj;
    double fx, fy;
    envelope_coord(i, n, t->envelope_n, &ci, &fx);
    envelope_coord(j, n, t->envelope_n, &cj, &fy);
    return envelope_plane(t, ci, fx, cj, fy);
}

typedef struct {
    float *h;
    int n, k;
    const tf_terrain *t;
    int enveloped;
    double tol;
    int step, half; /* this level: squares of side `step`, new points at offset `half` */
    int level;      /* 1 for the first subdivision */
    double amp;     /* displacement amplitude at this level */
    int *ecell;     /* envelope_coord of every grid index (both axes), precomputed: */
    double *efrac;  /* control elevations then cost no division */
} mp_ctx;

/* tf_envelope_at from the precomputed per-index coordinates: the same numbers, same bits. */
static inline double mp_envelope(const mp_ctx *c, int i, int j)
{
    return envelope_plane(c->t, c->ecell[i], c->efrac[i], c->ecell[j], c->efrac[j]);
}

/* Store height z at (i, j), limited to the envelope band when there is one.  The float that
 * is stored is itself checked against the band (rounding to float must not leave it). */
static void mp_store(mp_ctx *c, int i, int j, double z)
{
    float f;
    if (c->enveloped) {
        double ctl = mp_envelope(c, i, j);
        double lo = ctl - c->tol, hi = ctl + c->tol;
        if (z < lo) z = lo;
        if (z > hi) z = hi;
        f = (float)z;
        /* The invariant, as computed: fabs((double)f - ctl) <= tol.  tol >= 1e-5 *
         * max(1, |ctl|) (validated) is far above float spacing: at most a step or two. */
        while ((double)f - ctl > c->tol) f = nextafterf(f, -INFINITY);
        while (ctl - (double)f > c->tol) f = nextafterf(f, INFINITY);
    } else {
        f = (float)z;
    }
    c->h[(size_t)j * c->n + i] = f;
}

/* New height at (i, j) from the neighbour average `avg` and the same average of the control
 * elevations `avg_ctl` (eqs. 9-11, see the top comment). */
static void mp_displace(mp_ctx *c, int i, int j, double avg, double avg_ctl)
{
    int shift = MP_KMAX - c->k;
    uint64_t key = tf_grid_key(c->t->seed, TF_STREAM_MIDPOINT, (uint32_t)c->level,
                               (uint32_t)i << shift, (uint32_t)j << shift);
    double g = tf_grid_gauss(key);
    if (!c->enveloped) {
        mp_store(c, i, j, avg + c->amp * g);
        return;
    }
    double ctl = mp_envelope(c, i, j);
    /* mu = (C - A) + (1 - P) (A - A_c): all of the envelope's own bend C - A_c is followed,
     * a fraction P of the inherited deviation A - A_c is pulled back. */
    double mu = (ctl - avg) + (1.0 - MP_PULL) * (avg - avg_ctl);
    /* sigma follows the envelope's own bend, not the inherited deviation: the deviation does
     * not shrink with the level, so s |mu| would add white noise of a fixed size at every
     * level and leave single-sample spikes on the finest grid. */
    double sigma = MP_SIGMA_SCALE * fabs(ctl - avg_ctl) + c->amp;
    mp_store(c, i, j, avg + mu + sigma * g);
}

static inline double mp_at(const mp_ctx *c, int i, int j) { return c->h[(size_t)j * c->n + i]; }

/* Control elevation at (i, j), or 0 without an envelope (then unused). */
static inline double mp_ctl(const mp_ctx *c, int i, int j)
{
    return c->enveloped ? mp_envelope(c, i, j) : 0.0;
}

/* Diamond step: the centre of every square of side `step`; rows are the square rows. */
static void mp_diamond_rows(void *arg, int piece, int begin, int end)
{
    mp_ctx *c = arg;
    (void)piece;
    int s = c->step, hs = c->half;
    for (int r = begin; r < end; r++) {
        int j = hs + r * s;
        for (int i = hs; i < c->n; i += s) {
            double avg = (mp_at(c, i - hs, j - hs) + mp_at(c, i + hs, j - hs) +
                          mp_at(c, i - hs, j + hs) + mp_at(c, i + hs, j + hs)) * 0.25;
            double avg_ctl = (mp_ctl(c, i - hs, j - hs) + mp_ctl(c, i + hs, j - hs) +
                              mp_ctl(c, i - hs, j + hs) + mp_ctl(c, i + hs, j + hs)) * 0.25;
            mp_displace(c, i, j, avg, avg_ctl);
        }
    }
}

/* Square step: edge midpoints, each the average of its 4 diamond neighbours (3 at the border).
 * Row r is grid row j = r * half; on square-corner rows the new points sit at odd multiples of
 * half, on centre rows at even multiples. */
static void mp_square_rows(void *arg, int piece, int begin, int end)
{
    mp_ctx *c = arg;
    (void)piece;
    int s = c->step, hs = c->half, n = c->n;
    for (int r = begin; r < end; r++) {
        int j = r * hs;
        for (int i = (j % s == 0) ? hs : 0; i < n; i += s) {
            double sum = 0.0, sum_ctl = 0.0;
            int cnt = 0;
            if (i - hs >= 0) { sum += mp_at(c, i - hs, j); sum_ctl += mp_ctl(c, i - hs, j); cnt++; }
            if (i + hs < n)  { sum += mp_at(c, i + hs, j); sum_ctl += mp_ctl(c, i + hs, j); cnt++; }
            if (j - hs >= 0) { sum += mp_at(c, i, j - hs); sum_ctl += mp_ctl(c, i, j - hs); cnt++; }
            if (j + hs < n)  { sum += mp_at(c, i, j + hs); sum_ctl += mp_ctl(c, i, j + hs); cnt++; }
            mp_displace(c, i, j, sum / cnt, sum_ctl / cnt);
        }
    }
}

/* Parameter checks; returns 0 or -1 with a message. */
static int mp_validate(int k, const tf_terrain *t, char *err, size_t errlen)
{
    if (k < 1 || k > MP_KMAX) {
        tf_seterr(err, errlen, "midpoint: size exponent %d out of range 1..%d", k, MP_KMAX);
        return -1;
    }
    if (!isfinite(t->roughness) || t->roughness < 0.0 || t->roughness > 4.0) {
        tf_seterr(err, errlen, "midpoint: roughness %g out of range 0..4", t->roughness);
        return -1;
    }
    if (t->envelope_n == 0)
        return 0;
    if (t->envelope_n < 2 || t->envelope_n > TF_ENVELOPE_MAX) {
        tf_seterr(err, errlen, "midpoint: envelope_n %d must be 0 or 2..%d", t->envelope_n,
                 TF_ENVELOPE_MAX);
        return -1;
    }
    double maxabs = 1.0;
    for (int q = 0; q < t->envelope_n * t->envelope_n; q++) {
        if (!isfinite(t->envelope[q]) || fabs(t->envelope[q]) > 1e6) {
            tf_seterr(err, errlen, "midpoint: envelope value %d (%g) not a finite number below 1e6",
                     q, t->envelope[q]);
            return -1;
        }
        if (fabs(t->envelope[q]) > maxabs)
            maxabs = fabs(t->envelope[q]);
    }
    /* The band must be wide enough to hold a float at every point: float spacing near |z| is
     * at most |z| * 2^-23 ~ 1.2e-7 |z|. */
    if (!isfinite(t->envelope_tolerance) || t->envelope_tolerance < 1e-5 * maxabs) {
        tf_seterr(err, errlen, "midpoint: envelope_tolerance %g must be at least %g",
                 t->envelope_tolerance, 1e-5 * maxabs);
        return -1;
    }
    return 0;
}

/* Corners: on the envelope, or random with amplitude MP_FREE_AMP. */
static void mp_corners(mp_ctx *c)
{
    int n = c->n, shift = MP_KMAX - c->k;
    for (int q = 0; q < 4; q++) {
        int i = (q & 1) ? n - 1 : 0, j = (q & 2) ? n - 1 : 0;
        if (c->enveloped) {
            mp_store(c, i, j, tf_envelope_at(c->t, n, i, j));
        } else {
            uint64_t key = tf_grid_key(c->t->seed, TF_STREAM_MIDPOINT, 0, (uint32_t)i << shift,
                                       (uint32_t)j << shift);
            mp_store(c, i, j, MP_FREE_AMP * tf_grid_gauss(key));
        }
    }
}

int tf_gen_midpoint(float *h, int k, const tf_terrain *t, int threads, char *err, size_t errlen)
{
    if (mp_validate(k, t, err, errlen) != 0)
        return -1;
    mp_ctx c = {
        .h = h, .n = (1 << k) + 1, .k = k, .t = t,
        .enveloped = t->envelope_n != 0, .tol = t->envelope_tolerance,
    };
    /* Amplitude ratio per level.  The level count is relative to the whole terrain (level l
     * has separation 2^(13-l) at the k = 13 scale), so amplitudes match across sizes. */
    double ratio = pow(2.0, -t->roughness);
    double amp = c.enveloped ? c.tol * MP_ROUGH_SCALE : MP_FREE_AMP;
    if (c.enveloped) {
        c.ecell = malloc((size_t)c.n * sizeof *c.ecell);
        c.efrac = malloc((size_t)c.n * sizeof *c.efrac);
        if (!c.ecell || !c.efrac) {
            free(c.ecell), free(c.efrac);
            tf_seterr(err, errlen, "midpoint: out of memory");
            return -1;
        }
        for (int i = 0; i < c.n; i++)
            envelope_coord(i, c.n, t->envelope_n, &c.ecell[i], &c.efrac[i]);
    }
    mp_corners(&c);
    for (int step = c.n - 1, level = 1; step >= 2; step /= 2, level++) {
        c.step = step;
        c.half = step / 2;
        c.level = level;
        c.amp = amp;
        int rows = (c.n - 1) / step;
        int per_row = rows + 1;
        tf_grid_parallel(rows, threads, 1 + 8192 / per_row, mp_diamond_rows, &c);
        tf_grid_parallel((c.n - 1) / c.half + 1, threads, 1 + 8192 / per_row, mp_square_rows, &c);
        amp *= ratio;
    }
    free(c.ecell), free(c.efrac);
    return 0;
}
