/* test_terrains.h: small analytic height fields shared by the tracer tests (test_trace.c,
 * test_trace_surface.c): smooth hills with ridges, white noise, terraces (exact ties with the
 * max grids), and make_field to wrap one into a tf_heightfield.  Header-only (static
 * functions): each test program is its own executable.  Include after <cmocka.h>. */
#ifndef TF_TEST_TERRAINS_H
#define TF_TEST_TERRAINS_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "terrain/heightfield.h"
#include "terrain/noise.h"

typedef double (*height_fn)(int i, int j, int n);

/* White noise: every cell steep and different. */
static double rough(int i, int j, int n) { return tf_hash_unit((uint64_t)j * n + i) * 40 - 20; }
/* Smooth hills with ridges. */
static double hills(int i, int j, int n)
{
    double x = (double)i / (n - 1), y = (double)j / (n - 1);
    return 8 * sin(6.1 * x) * cos(4.3 * y) + 3 * sin(17.0 * x + 11.0 * y) + 2 * fabs(sin(23.0 * y));
}
/* Terraces: many equal heights, flat cells and exact ties with the max grids. */
static double terraces(int i, int j, int n) { return floor(hills(i, j, n) / 3) * 3; }

static tf_heightfield *make_field(height_fn f, int k, double extent)
{
    int n = (1 << k) + 1;
    float *h = malloc((size_t)n * n * sizeof *h);
    assert_non_null(h);
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++)
            h[(size_t)j * n + i] = (float)f(i, j, n);
    tf_heightfield *hf = tf_heightfield_wrap(h, k, extent, 1);
    assert_non_null(hf);
    return hf;
}

#endif
