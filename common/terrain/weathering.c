/* weathering.c: thermal weathering (talus relaxation) of a height field -- tf_weather_thermal,
 * the optional post-process applied by terrain_build.c to world heights.
 *
 * Source: F. K. Musgrave, "Methods for Realistic Landscape Imaging", PhD dissertation, Yale
 * University, 1993, section 2.4.2.
 * At each time step every vertex v is compared with its neighbours u; where the drop
 * a_v - a_u exceeds the talus slope T, a fixed fraction c_t of the excess moves onto u:
 *
 *     a_u(t+1) = a_u(t) + c_t (a_v(t) - a_u(t) - T)      if a_v(t) - a_u(t) > T
 *
 * and the same amount leaves v, so material is conserved ("with care taken to assure the
 * equitable distribution of talus material to all neighbouring vertices").  Here:
 *  - neighbours are the 4 axis neighbours at distance `cell`; T = cell * tan(talus angle), so
 *    the talus angle is a real slope in world units;
 *  - every transfer is computed from the heights of step t only (a Jacobi, double-buffered
 *    update), so the result does not depend on the order cells are visited, nor on threads;
 *  - c_t = 1/8: a cell may give to all four neighbours at once; with c_t <= 1/8 the update is
 *    monotone (a vertex never drops below a neighbour it gave to within one step; the linear
 *    part is explicit diffusion, stable up to 1/4, non-oscillating up to 1/8);
 *  - the edge of the grid is closed: nothing flows out, so the sum of heights is conserved up
 *    to float rounding.  The transfer across an edge is computed once per side from the same
 *    two numbers, and fl(b - a) = -fl(a - b), so what one side loses the other gains exactly
 *    (in double; only the final store to float rounds).
 * The slope between neighbours approaches T asymptotically; thermal_iterations time steps.
 *
 * Fluvial erosion (2.4.1) and dry creep (2.4.3) are terrain/erosion.h's, which run after this;
 * that model shares the Jacobi update and the exact antisymmetry of transfers used here. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/gridgen.h"
#include "terrain/terrain.h"
#include "log.h"

#define THERMAL_FRACTION 0.125 /* c_t */
#define THERMAL_MAX_N 8193
#define THERMAL_MAX_ITERATIONS 1000000

typedef struct {
    const float *in;
    float *out;
    int n;
    double talus; /* T: largest stable height difference between neighbours */
} thermal_ctx;

/* Material moving from the cell of height a to its neighbour of height b in one step (negative:
 * it moves from b to a).  Antisymmetric bit for bit: thermal_move(b, a) == -thermal_move(a, b). */
static inline double thermal_move(double a, double b, double T)
{
    double d = a - b;
    if (d > T)
        return THERMAL_FRACTION * (d - T);
    if (d < -T)
        return THERMAL_FRACTION * (d + T);
    return 0.0;
}

static void thermal_rows(void *arg, int piece, int begin, int end)
{
    thermal_ctx *c = arg;
    int n = c->n;
    double T = c->talus;
    (void)piece;
    for (int j = begin; j < end; j++) {
        const float *row = c->in + (size_t)j * n;
        for (int i = 0; i < n; i++) {
            double a = row[i], v = a;
            /* Fixed order: left, right, below, above. */
            if (i > 0)     v -= thermal_move(a, row[i - 1], T);
            if (i < n - 1) v -= thermal_move(a, row[i + 1], T);
            if (j > 0)     v -= thermal_move(a, row[i - n], T);
            if (j < n - 1) v -= thermal_move(a, row[i + n], T);
            c->out[(size_t)j * n + i] = (float)v;
        }
    }
}

static int thermal_validate(int n, double cell, const tf_terrain *t, char *err, size_t errlen)
{
    if (n < 2 || n > THERMAL_MAX_N) {
        tf_seterr(err, errlen, "thermal weathering: grid side %d out of range 2..%d", n,
                 THERMAL_MAX_N);
        return -1;
    }
    if (!(cell > 0.0 && isfinite(cell))) {
        tf_seterr(err, errlen, "thermal weathering: cell size %g must be a positive number", cell);
        return -1;
    }
    if (t->thermal_iterations < 0 || t->thermal_iterations > THERMAL_MAX_ITERATIONS) {
        tf_seterr(err, errlen, "thermal weathering: iterations %d out of range 0..%d",
                 t->thermal_iterations, THERMAL_MAX_ITERATIONS);
        return -1;
    }
    if (!(t->talus_deg > 0.0 && t->talus_deg < 90.0)) {
        tf_seterr(err, errlen, "thermal weathering: talus angle %g must be between 0 and 90 degrees",
                 t->talus_deg);
        return -1;
    }
    return 0;
}

int tf_weather_thermal(float *h, int n, double cell, const tf_terrain *t, int threads, char *err,
                       size_t errlen)
{
    if (thermal_validate(n, cell, t, err, errlen) != 0)
        return -1;
    if (t->thermal_iterations == 0)
        return 0;
    float *tmp = malloc((size_t)n * n * sizeof *tmp);
    if (!tmp) {
        tf_seterr(err, errlen, "thermal weathering: out of memory for a %dx%d grid", n, n);
        return -1;
    }
    thermal_ctx c = {.n = n, .talus = cell * tan(t->talus_deg * (M_PI / 180.0))};
    float *cur = h, *next = tmp;
    for (int it = 0; it < t->thermal_iterations; it++) {
        c.in = cur;
        c.out = next;
        tf_grid_parallel(n, threads, 1 + 16384 / n, thermal_rows, &c);
        float *swap = cur;
        cur = next;
        next = swap;
    }
    if (cur != h)
        memcpy(h, cur, (size_t)n * n * sizeof *h);
    free(tmp);
    return 0;
}
