/* terrain_build.h: the height samples of a scene's terrain, before the max/min grids are built
 * around them.  tf_heightfield_build (heightfield.h) is tf_terrain_heights followed by
 * tf_heightfield_wrap; tools that only need the heights (terrafarm heightfield) call this
 * directly and skip the grids' memory. */
#ifndef TF_TERRAIN_BUILD_H
#define TF_TERRAIN_BUILD_H

#include <stddef.h>
#include <stdint.h>
#include "scene.h"

/* Largest size_exp accepted: 8193^2 floats = 268 MB of heights. */
#define TF_TERRAIN_MAX_SIZE_EXP 13

/* World heights of the terrain t: a malloc'd array of n * n floats, n = 2^size_exp + 1,
 * row-major h[j * n + i] for the sample at world (i * cell, j * cell), cell = extent / (n - 1).
 * Point generators are evaluated with `threads` threads (<= 0: all online CPUs), each claiming
 * the next unclaimed row; a row's bits never depend on who computed it or the thread count.  Grid generators fill
 * the grid, then heights are scaled by height_scale, then thermal weathering runs if asked.
 * generator = file reads the height map (heightmap_file.h) instead.  *extent (if not NULL)
 * gets the world size of a side: t->extent, or for a height map what its georeferencing says.
 * Returns NULL with one line in err on failure (bad size, out of memory, non-finite output). */
float *tf_terrain_heights(const tf_terrain *t, int threads, double *extent, char *err,
                          size_t errlen);

/* The same heights, and for an [erosion] scene the maps of its erosion (maps and rep may be
 * NULL; maps are left zero when there is no erosion).  An eroded terrain comes from the blob
 * t->eroded_bytes when the scene has one (a networked worker's, from its coordinator), else from
 * the erosion cache, else from eroding now (terrain/eroded.h); rep says which. */
struct tf_eroded_maps;
struct tf_erosion_report;
float *tf_terrain_heights_maps(const tf_terrain *t, int threads, double *extent,
                               struct tf_eroded_maps *maps, struct tf_erosion_report *rep,
                               char *err, size_t errlen);

/* The start of t's erosion: its generated, weathered heights made into the erosion's model and
 * initial state (erosion_state.h; what every farm worker derives alike); *extent (if not
 * NULL) the terrain's side.  0, or -1 with one line in err. */
struct tf_erosion_model;
struct tf_erosion_state;
int tf_terrain_erosion_start(const tf_terrain *t, double *extent, struct tf_erosion_model *m,
                             struct tf_erosion_state *st, char *err, size_t errlen);

/* The blob of t's eroded terrain (terrain/eroded.h): generated, weathered and eroded here, or
 * read from the erosion cache.  0, or -1 with one line in err. */
int tf_terrain_eroded_bytes(const tf_terrain *t, int threads, uint8_t **bytes, size_t *len,
                            struct tf_erosion_report *rep, char *err, size_t errlen);

#endif
