/* subdivide.c: Ammeter & Mikhailyuk's recursive subdivision -- tf_gen_subdivide, the
 * TF_GEN_SUBDIVIDE generator.
 *
 * Source: H. Ammeter, M. V. Mikhailyuk, "Generation and Rendering of Virtual Terrain",
 * section 3.  The corners are level 0; at each following level the midpoints
 * between already-determined points get
 *
 *     H = A + (R - W) * (1 + A)^2 * M / L^E
 *
 * A: the interpolated average of the neighbour points from the previous level (the two ends
 *    of an edge; for the centre of a square, its four corners),
 * R: uniform random in [0, 1),  L: level of recursion (1 for the first midpoints),
 * M > 0: maximum height,  E > 1: level exponent (roughness),  0 <= W <= 1: water.
 * The formula is used exactly as printed (divisor L^E; the paper's prose speaks of dividing by
 * E per level, the printed formula by L^E: we follow the formula).  Level 0 has no neighbours
 * and L^E would be 0, so each corner is H = (R - W) * M, the same formula with A = 0 and no
 * level divisor.
 *
 * Water, as the paper defines it: heights below 0 are water (sea level 0).  W shifts every
 * displacement down by W * (1 + A)^2 * M / L^E, so W = 0 gives no water at all (every
 * displacement >= 0 and the corners >= 0) and W = 1 gives no land above the highest corner
 * (every displacement <= 0).  Output is in units of M (the caller scales by height_scale);
 * a parameter set whose heights overflow the float range is reported as an error.
 *
 * Determinism: R is a hash of (seed, level, i, j) with i, j at the k = 13 scale, so a smaller
 * grid is exactly the subsampling of a larger one; all points of one level depend only on
 * earlier levels, so the rows of a level are split among threads freely. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "terrain/gridgen.h"
#include "terrain/terrain.h"
#include "log.h"

#define SUB_KMAX 13

typedef struct {
    float *h;
    int n, k;
    const tf_terrain *t;
    int step, half, level;
    double scale;     /* M / L^E at this level */
    int *overflow;    /* per piece: a height left the float range */
} sub_ctx;

static double sub_random(const sub_ctx *c, int level, int i, int j)
{
    int shift = SUB_KMAX - c->k;
    return tf_grid_unit(tf_grid_key(c->t->seed, TF_STREAM_SUBDIVIDE, (uint32_t)level,
                                    (uint32_t)i << shift, (uint32_t)j << shift));
}

static inline double sub_at(const sub_ctx *c, int i, int j) { return c->h[(size_t)j * c->n + i]; }

/* The paper's formula at (i, j) given the neighbour average A; returns 0 if the result does
 * not fit a float. */
static int sub_set(sub_ctx *c, int i, int j, double A)
{
    double R = sub_random(c, c->level, i, j);
    double H = A + (R - c->t->sub_W) * (1.0 + A) * (1.0 + A) * c->scale;
    float f = (float)H;
    c->h[(size_t)j * c->n + i] = f;
    return isfinite(f);
}

/* Level rows [begin, end): row r is grid row j = r * half.  Rows on the previous level's
 * lattice (j % step == 0) get edge midpoints between horizontal neighbours; the rows between
 * get edge midpoints between vertical neighbours (i % step == 0) and square centres. */
static void sub_rows(void *arg, int piece, int begin, int end)
{
    sub_ctx *c = arg;
    int s = c->step, hs = c->half, ok = 1;
    for (int r = begin; r < end; r++) {
        int j = r * hs;
        if (j % s == 0) {
            for (int i = hs; i < c->n; i += s)
                ok &= sub_set(c, i, j, (sub_at(c, i - hs, j) + sub_at(c, i + hs, j)) * 0.5);
            continue;
        }
        for (int i = 0; i < c->n; i += hs) {
            double A;
            if (i % s == 0)
                A = (sub_at(c, i, j - hs) + sub_at(c, i, j + hs)) * 0.5;
            else
                A = (sub_at(c, i - hs, j - hs) + sub_at(c, i + hs, j - hs) +
                     sub_at(c, i - hs, j + hs) + sub_at(c, i + hs, j + hs)) * 0.25;
            ok &= sub_set(c, i, j, A);
        }
    }
    if (!ok)
        c->overflow[piece] = 1;
}

static int sub_validate(int k, const tf_terrain *t, char *err, size_t errlen)
{
    if (k < 1 || k > SUB_KMAX) {
        tf_seterr(err, errlen, "subdivide: size exponent %d out of range 1..%d", k, SUB_KMAX);
        return -1;
    }
    if (!(t->sub_M > 0.0 && t->sub_M <= 1e6)) {
        tf_seterr(err, errlen, "subdivide: M = %g must be > 0 (and at most 1e6)", t->sub_M);
        return -1;
    }
    if (!(t->sub_E > 1.0 && t->sub_E <= 64.0)) {
        tf_seterr(err, errlen, "subdivide: E = %g must be > 1 (and at most 64)", t->sub_E);
        return -1;
    }
    if (!(t->sub_W >= 0.0 && t->sub_W <= 1.0)) {
        tf_seterr(err, errlen, "subdivide: W = %g out of range 0..1", t->sub_W);
        return -1;
    }
    return 0;
}

int tf_gen_subdivide(float *h, int k, const tf_terrain *t, int threads, char *err, size_t errlen)
{
    if (sub_validate(k, t, err, errlen) != 0)
        return -1;
    int n = (1 << k) + 1;
    int overflow[TF_GRID_MAX_THREADS] = {0};
    sub_ctx c = {.h = h, .n = n, .k = k, .t = t, .overflow = overflow};

    for (int q = 0; q < 4; q++) { /* level 0: H = (R - W) * M */
        int i = (q & 1) ? n - 1 : 0, j = (q & 2) ? n - 1 : 0;
        h[(size_t)j * n + i] = (float)((sub_random(&c, 0, i, j) - t->sub_W) * t->sub_M);
    }
    for (int step = n - 1, level = 1; step >= 2; step /= 2, level++) {
        c.step = step;
        c.half = step / 2;
        c.level = level;
        c.scale = t->sub_M / pow((double)level, t->sub_E);
        int rows = (n - 1) / c.half + 1;
        tf_grid_parallel(rows, threads, 1 + 8192 / rows, sub_rows, &c);
        for (int p = 0; p < TF_GRID_MAX_THREADS; p++) {
            if (overflow[p]) {
                snprintf(err, errlen,
                         "subdivide: heights overflow at level %d (M = %g too large for E = %g)",
                         level, t->sub_M, t->sub_E);
                return -1;
            }
        }
    }
    return 0;
}
