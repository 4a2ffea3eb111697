/* heightfield.h: the terrain as the renderer sees it: (2^k+1)^2 height samples over a square of
 * side `extent`, plus a hierarchy of max-altitude grids ("A grids", Musgrave 3.x; a max mipmap).
 *
 * Sample (i, j) sits at world (i * cell, j * cell, h[j*n + i]).  Cell (ci, cj), 0 <= ci, cj < n-1,
 * is the square between samples (ci, cj) and (ci+1, cj+1); it is split into two triangles along
 * the diagonal from (ci, cj) to (ci+1, cj+1).
 *
 * maxgrid[0][cj * cells + ci] is the maximum of the cell's four corner heights; maxgrid[L] has
 * (cells >> L)^2 entries, each the max of the 2x2 block of level L-1 below it; the last level is
 * 1x1 (the whole terrain).  mingrid likewise with minimum (rays from below).
 *
 * Built once by the coordinator before forking workers (shared copy-on-write), and by each
 * networked worker from the scene text.  Construction uses all cores and is bit-identical
 * whatever the thread count. */
#ifndef TF_HEIGHTFIELD_H
#define TF_HEIGHTFIELD_H

#include "scene.h"

typedef struct tf_heightfield {
    int k;             /* n = 2^k + 1 */
    int n;             /* samples per side */
    int cells;         /* n - 1 cells per side */
    double extent;     /* world size of a side */
    double cell;       /* extent / cells */
    float *h;          /* n * n world heights */
    float hmin, hmax;  /* range of h */
    int levels;        /* number of max-grid levels: k + 1 (cells, cells/2, ..., 1) */
    float **maxgrid;   /* maxgrid[L]: (cells >> L)^2 entries */
    float **mingrid;   /* mingrid[L]: same shape, minima */
    /* The steepest slope of the surface (the largest gradient norm of its triangles, rise per
     * unit of horizontal run), rounded up: no two points of the surface differ in height by
     * more than slope_max times their horizontal distance (render/trace.h's coherence).  NaN
     * where a sample is NaN (a hole: the surface is not continuous, nothing is bounded), +inf
     * where the gradients overflow; users ask for 0 <= slope_max < inf. */
    double slope_max;
    /* [terrain] procedural = yes: the terrain is this function, evaluated where rays need it.
     * With a noise generator there are no samples and no grids (h, maxgrid, mingrid NULL, n =
     * k = 0); extent, hmin and hmax are its square and its bound, cell nominal (the grid of
     * size_exp's) for the shading scales that derive from it.  With a grid generator or a
     * height map the grid stays (the base the detail is added to) and hmin, hmax widen to the
     * procedural bound. */
    struct tf_procedural *proc;
    /* [erosion]: the erosion's maps (n * n world metres; NULL without erosion): standing and
     * running water depth, deposited silt, and the decaying flow of water through each vertex
     * (terrain/eroded.h); the shading darkens wet beds and colours deposits with them */
    float *water, *silt, *flow;
    /* What a later layer derives from the heights alone and keeps with them, so that the
     * processes forked after it was made share one copy (render/sun_strips.h keeps the sun's
     * strips here before a farm forks its workers); NULL, or freed with the height field by
     * derived_free. */
    void *derived;
    void (*derived_free)(void *);
} tf_heightfield;

/* Build the scene's height field with `threads` threads (0 = all online CPUs); for a
 * procedural scene, the procedural terrain with a cache of `tf_procedural_default_cache_bytes`
 * (tf_heightfield_set_cache changes it).
 * Returns NULL with a one-line message in err on failure (e.g. out of memory). */
tf_heightfield *tf_heightfield_build(const tf_scene *s, int threads, char *err, size_t errlen);
/* Wrap existing heights (copied) and build the max/min grids; for tests and tools. */
tf_heightfield *tf_heightfield_from_heights(const float *h, int k, double extent, int threads);
/* Take ownership of h (malloc'd n*n world heights) and build the grids: what
 * tf_heightfield_build calls once the heights are generated.  NULL on out of memory (h freed). */
tf_heightfield *tf_heightfield_wrap(float *h, int k, double extent, int threads);
void tf_heightfield_free(tf_heightfield *hf);
/* A procedural terrain's per-process cache budget in bytes (no effect on a grid). */
void tf_heightfield_set_cache(tf_heightfield *hf, size_t bytes);

/* Height at world (x, y) by the same two-triangle interpolation the tracer
 * uses (clamped to the terrain's edge); a procedural terrain's at its finest level. */
double tf_heightfield_height_at(const tf_heightfield *hf, double x, double y);

/* The grid's own height there, whether or not a procedural terrain is over it. */
double tf_heightfield_grid_height_at(const tf_heightfield *hf, double x, double y);
/* The range of the grid's heights over the cells that meet [x0, x1] x [y0, y1] (clamped to
 * the square), from the max/min grids: a bound of the surface there. */
void tf_heightfield_range(const tf_heightfield *hf, double x0, double x1, double y0, double y1,
                          float *lo, float *hi);

/* malloc for a large array of heights or grid entries (free() frees it): 2 MB aligned and
 * marked for transparent huge pages when it is large.  NULL when out of memory. */
float *tf_alloc_heights(size_t bytes);

/* Number of worker threads to use for `threads` (0 -> online CPUs). */
int tf_thread_count(int threads);

#endif
