/* test_fans.h: fans of camera rays for the coherence tests (test_trace_coherent.c for trace.c's
 * tf_trace_coherent, test_opencl.c for the kernels' walk): rays from one origin -- above the
 * hills, outside the square, low and grazing the near hills, or under the surface -- climbing
 * row by row and drifting sideways by from nothing (a vertical fan) to far more than slope_max
 * allows, some ending at a water plane's tmax.  Header-only (static functions), with the
 * tests' small random source; include after test_terrains.h. */
#ifndef TF_TEST_FANS_H
#define TF_TEST_FANS_H

#include <math.h>
#include <stdint.h>

#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "vec.h"

typedef struct rng { uint64_t s; } rng;
static double uni(rng *r) { return tf_hash_unit(r->s++); }
static double range(rng *r, double lo, double hi) { return lo + (hi - lo) * uni(r); }

enum { FAN_ROWS = 48 };
enum origin_kind { HIGH, OUTSIDE, LOW, UNDER, KINDS };

typedef struct ray_fan {
    tf_vec3 o, d[FAN_ROWS]; /* d[0] lowest */
    double tmax;
} ray_fan;

/* Fan number n over hf (its origin of kind n % KINDS), drawn from r. */
static void make_fan(const tf_heightfield *hf, rng *r, int n, ray_fan *f)
{
    const double e = hf->cells * hf->cell, lo = hf->hmin, hi = hf->hmax, span = hi - lo + 1;
    const int kind = n % KINDS;
    if (kind == HIGH)
        f->o = v3(range(r, 0, e), range(r, 0, e), hi + range(r, 0.1, 1) * span);
    else if (kind == OUTSIDE)
        f->o = v3(range(r, -0.3, 1.3) * e, -range(r, 0.01, 0.3) * e, range(r, lo, hi + span));
    else if (kind == LOW) /* inside the height range: grazing the near hills */
        f->o = v3(range(r, 0, e), range(r, 0, e), range(r, lo, hi));
    else
        f->o = v3(range(r, 0, e), range(r, 0, e), lo - range(r, 0, span));
    const double az = range(r, 0, 2 * M_PI), pitch = range(r, -0.6, 0.0);
    const tf_vec3 d0 = v3(cos(az), sin(az), pitch);
    const double step = range(r, 1e-4, 5e-3);
    const tf_vec3 up = v3(0, 0, step);
    const double drift = uni(r) < 0.3 ? 0 : step * pow(10, range(r, -3, 1));
    const tf_vec3 side = v3(-sin(az) * drift, cos(az) * drift, 0);
    f->tmax = uni(r) < 0.3 ? range(r, 0.2, 2) * e : INFINITY; /* a water plane */
    for (int i = 0; i < FAN_ROWS; i++)
        f->d[i] = v3_add(v3_add(d0, v3_scale(up, i)), v3_scale(side, range(r, -1, 1)));
}

/* Where only the prefix walk (trace.c's C3) finds a hit: a hill by the square's south edge
 * (field edge_hill, k = 7, extent 1000) and, from outside the south-west corner, two rays
 * whose headings differ by a hundredth.  The upper one enters through the south edge at a run
 * of ~335 and hits the hill at ~381, before the lower one enters at ~500; the lower one is
 * above the surface from there to the plain at 700, so its record vouches for the upper ray
 * (the climbs differ by 0.03, slope_max is 0.64), from where the lower ray entered on. */
static double edge_hill(int i, int j, int n)
{
    const double x = 1000.0 * i / (n - 1) - 400, y = 1000.0 * j / (n - 1) - 20;
    return 40 * exp(-(x * x + y * y) / (2 * 40.0 * 40.0));
}

static void prefix_rays(tf_vec3 *o, tf_vec3 *lower, tf_vec3 *upper)
{
    const double nl = hypot(1, 0.02), nu = hypot(1, 0.03);
    *o = v3(-10, -10, 35);
    *lower = v3(1 / nl, 0.02 / nl, -0.05);
    *upper = v3(1 / nu, 0.03 / nu, -0.02);
}

#endif
