/* terrain.h: the terrain generators, as seen by heightfield.c.
 *
 * Two families.  Point generators (noise.c, fractal.c) evaluate a function of (x, y) and can be
 * sampled anywhere; heightfield.c calls them per sample from several threads.  Grid generators
 * (midpoint.c, fault.c, subdivide.c, weathering.c) fill or modify a whole (2^k+1)^2 grid.
 *
 * Every generator is deterministic from the scene's seed alone and must give bit-identical
 * output whatever the `threads` argument (threads <= 1 means single-threaded).
 * Grids are row-major: h[j * n + i], i along x, j along y, n = 2^k + 1.
 * Output heights are dimensionless (roughly -1..1 or 0..1, generator-specific);
 * heightfield.c multiplies by terrain.height_scale. */
#ifndef TF_TERRAIN_H
#define TF_TERRAIN_H

#include "scene.h"

/* Point generators: value of the scene's procedural generator (fbm, hetero, hybrid, ridged)
 * at world position (x, y).  `t` is the scene's terrain block. */
typedef struct tf_noise tf_noise; /* seeded permutation tables, see noise.h */
double tf_terrain_point(const tf_terrain *t, const tf_noise *noise, double x, double y);

/* Grid generators. Return 0 on success, -1 with a message in err on failure. */
int tf_gen_midpoint(float *h, int k, const tf_terrain *t, int threads, char *err, size_t errlen);
int tf_gen_fault(float *h, int k, const tf_terrain *t, int threads, char *err, size_t errlen);
int tf_gen_subdivide(float *h, int k, const tf_terrain *t, int threads, char *err, size_t errlen);
/* Post-process: thermal weathering (talus relaxation) of an existing grid of world heights,
 * cell size `cell` world units. */
int tf_weather_thermal(float *h, int n, double cell, const tf_terrain *t, int threads, char *err,
                       size_t errlen);

#endif
