/* grid_height.h: the height of a grid height field at a point of its square, interpolated on
 * the very triangles render/trace.c tests (cell (ci, cj) split along its diagonal
 * (ci, cj)-(ci+1, cj+1)).  Written once for C (terrain/heightfield.c's
 * tf_heightfield_grid_height_at) and for OpenCL C (the shadow rays' under proof,
 * render/sun_math.h, in the kernels too; common/portable.h says how one source is both): that
 * proof holds only while this interpolates exactly what the walk tests.  One point at a time,
 * on plain doubles, in both languages. */
#ifndef TF_GRID_HEIGHT_H
#define TF_GRID_HEIGHT_H

#ifndef __OPENCL_VERSION__
#include <stddef.h>
#include "portable.h"
#endif

#ifndef TF_GLOBAL
#ifdef __OPENCL_VERSION__
#define TF_GLOBAL __global
#else
#define TF_GLOBAL
#endif
#endif

/* The index i of the cell holding coordinate v along one axis, decided by the products
 * (double)i * cell that place the samples: i * cell <= v < (i + 1) * cell, clamped to
 * [0, cells - 1] (the last cell closed).  guess, v / cell or any value near it (a multiply by
 * 1 / cell), is only where the search starts: both loops test monotone predicates, so the
 * index they settle on does not depend on it.  A NaN or huge guess starts at an end. */
TF_SHARED int tf_grid_index(double v, double cell, double guess, int cells)
{
    int i = guess > 0 ? (guess < cells ? (int)guess : cells - 1) : 0;
    while (i > 0 && (double)i * cell > v)
        i--;
    while (i < cells - 1 && (double)(i + 1) * cell <= v)
        i++;
    return i;
}

/* tf_grid_index of v (in [0, cells * cell]) and v's fraction of the way across that cell in
 * *frac. */
TF_SHARED int tf_grid_cell_of(double v, double cell, int cells, double *frac)
{
    const int i = tf_grid_index(v, cell, v / cell, cells);
    *frac = (v - (double)i * cell) / cell;
    return i;
}

/* The surface at (x, y) inside the square of n x n samples h, `cell` apart: the lower-right
 * triangle (A, B, C) where u >= v, the upper-left (A, C, D) where u < v (on the diagonal both
 * give the same). */
TF_SHARED double tf_grid_height(TF_GLOBAL const float *h, int n, double cell, double x, double y)
{
    double u, v;
    const int ci = tf_grid_cell_of(x, cell, n - 1, &u), cj = tf_grid_cell_of(y, cell, n - 1, &v);
    TF_GLOBAL const float *row = h + (size_t)cj * (size_t)n + (size_t)ci;
    const double ha = row[0], hb = row[1];   /* (ci, cj), (ci+1, cj) */
    const double hd = row[n], hc = row[n + 1]; /* (ci, cj+1), (ci+1, cj+1) */
    if (u >= v)
        return ha + (hb - ha) * u + (hc - hb) * v;
    return ha + (hc - hd) * u + (hd - ha) * v;
}

#endif
