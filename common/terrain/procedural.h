/* procedural.h: procedural terrain at every scale (Musgrave 6.3.2, A.7.2.3): a noise generator
 * evaluated where rays need it, at the level of detail a pixel can show, with no grid and no
 * size cap.
 *
 * Levels.  Level L is a grid of spacing s_L = extent / (32 * 2^L) over the terrain's square
 * [0, extent]^2, stored as tiles of 32 x 32 cells (tilecache.h) keyed by (L, tile x, tile y).
 * Its samples are the generator with the octaves that spacing can show: those of wavelength at
 * least 2 s_L, n(L) = 1 + log_lacunarity(feature_size / (2 s_L)) (fractional; at most the
 * scene's `octaves`), times height_scale.  H_L(x, y) is the bilinear interpolation of level L's
 * samples.  A sample is a pure function of (L, i, j): what a worker has cached never matters.
 *
 * Level of detail.  A view (eye position and the angle of a pixel) gives every horizontal
 * position a continuous level lambda(x, y) = log2(s_0 / footprint), where footprint is the
 * pixel's size at distance d = |(x, y) - eye_xy, dz| (dz: the eye's height above the highest
 * the terrain can reach, or 0), clamped to [0, max_level]: level lambda's spacing is one
 * pixel.  So of the two levels used at a place the finer one has spacing at most a pixel (a
 * pixel exactly where it alone is used), the coarser at most two.  The surface the view sees is
 *     h(x, y) = (1 - w) H_L(x, y) + w H_{L+1}(x, y),   L = floor(lambda), w = lambda - L:
 * continuous everywhere (no cracks between levels), detail fading in as the eye approaches
 * (no popping), and a function of the position and the view only, never of the ray, so camera
 * and shadow rays see one surface and every pixel is the same in any decomposition.
 *
 * Bounds.  tf_proc_bound bounds h over any box without evaluating a sample, from interval
 * arithmetic on the noise (fractal_bound.h): bilinear interpolation and the blend stay within
 * the range of the samples they mix, and those lie within the box widened by one cell of the
 * coarsest level used there, for the octave counts of the levels used there. */
#ifndef TF_PROCEDURAL_H
#define TF_PROCEDURAL_H

#include <assert.h>
#include <stddef.h>
#include <stdint.h>

#include "scene.h"
#include "terrain/fractal.h"
#include "terrain/fractal_bound.h"
#include "terrain/noise.h"
#include "terrain/tilecache.h"
#include "vec.h"

struct tf_heightfield;

#define TF_PROC_MAX_LEVELS 28

typedef struct tf_procedural {
    tf_noise noise;
    tf_fractal fractal;                         /* the scene's generator (bounds use its H...) */
    tf_octaves full;                            /* every octave's weight, for the bounds */
    uint64_t id;                                /* unique in the process (bound caches' key) */
    tf_fractal level[TF_PROC_MAX_LEVELS + 1];   /* the generator with n(L) octaves */
    double octaves[TF_PROC_MAX_LEVELS + 1];     /* n(L) */
    int max_level;
    double extent, height_scale;
    double spacing0;                            /* s_0 = extent / 32 */
    double lo, hi;                              /* bound of every height, world units */
    size_t cache_bytes;                         /* each rendering thread's tile cache budget */
    /* Detail over a grid (tf_procedural_over): the grid, and each level's share of the first
     * detail octave (0 where the level is no finer than the grid, 1 from twice as fine) */
    const struct tf_heightfield *base;
    double fade[TF_PROC_MAX_LEVELS + 1];
} tf_procedural;

/* What a view needs to pick levels: see above. */
typedef struct tf_proc_view {
    uint64_t id;        /* unique in the process (tf_proc_view_of): what a view's caches key on */
    tf_vec3 eye;
    double pixel_angle; /* radians per pixel (or tangent units for a pinhole: the same use) */
    double dz;          /* the eye's height above p->hi, or 0 */
    double min_dist;    /* distances below this count as this (keeps lambda finite) */
    /* lambda >= L exactly where d^2 <= reach2[L] (d as above): levels without a log2 */
    double reach2[TF_PROC_MAX_LEVELS + 1];
} tf_proc_view;

/* Evaluated samples live in a tile cache (tilecache.h) of each thread that renders, created
 * on its first read with cache_bytes, emptied when the thread renders another terrain. */
/* NULL with one line in err: not a noise generator, or out of memory. */
tf_procedural *tf_procedural_new(const tf_terrain *t, size_t cache_bytes, char *err,
                                 size_t errlen);
/* Procedural detail over a grid or a height map (Ammeter & Mikhailyuk's real data with generated
 * detail): level L's samples are the grid's height there (its two triangles) plus `detail`
 * metres times an fBm whose first octave has a wavelength of two grid cells, with the octaves
 * level L's spacing can show (t's H, lacunarity and octaves); a level no finer than the grid
 * adds nothing, and the first octave fades in from 0 to 1 as the spacing halves below it.
 * The grid must outlive the terrain (it is its height field). */
tf_procedural *tf_procedural_over(const tf_terrain *t, const struct tf_heightfield *grid,
                                  size_t cache_bytes, char *err, size_t errlen);
void tf_procedural_free(tf_procedural *p);
/* Change the budget of every thread's cache (from their next read on). */
void tf_procedural_set_cache(tf_procedural *p, size_t bytes);
/* Default per-worker cache budget: an eighth of the machine's memory, at most 512 MiB. */
size_t tf_procedural_default_cache_bytes(void);

tf_proc_view tf_proc_view_of(const tf_procedural *p, tf_vec3 eye, double pixel_angle);

/* x / 2^n for 0 <= n < 64: the bits of ldexp(x, -n) (a product by a power of two is exact, or
 * rounded once), without a call. */
static inline double tf_proc_halved(double x, int n)
{
    assert(n >= 0 && n < 64);
    return x * (1.0 / (double)((uint64_t)1 << n));
}

/* Level L's spacing s_L. */
static inline double tf_proc_spacing(const tf_procedural *p, int level)
{
    return tf_proc_halved(p->spacing0, level);
}
/* lambda at horizontal distance-squared d2 from the eye (see above). */
double tf_proc_lambda(const tf_procedural *p, const tf_proc_view *v, double d2);
/* A bound of |grad lambda| over the box: 1 / (ln 2 * its nearest distance, or min_dist). */
double tf_proc_lambda_slope(const tf_procedural *p, const tf_proc_view *v, double x0,
                            double x1, double y0, double y1);
/* The range of lambda over the box, as levels: floor(min) and the finest used, floor(max)+1
 * (capped at max_level). */
void tf_proc_box_levels(const tf_procedural *p, const tf_proc_view *v, double x0, double x1,
                        double y0, double y1, int *level_lo, int *level_hi);

/* Samples (i, j) of level L's grid, i in [i0, i0 + w), j in [j0, j0 + h), row-major into out.
 * They must lie in one tile: with T = min(i0 / 32, tiles - 1), i0 + w <= 32 T + 33 (the same
 * along j); a block of cells aligned to its own size (up to 32) always does. */
void tf_proc_samples(const tf_procedural *p, int level, int64_t i0, int64_t j0, int w, int h,
                     float *out);
/* The range of level L's samples over the aligned block of 2^k x 2^k cells (k in 1..5) that
 * holds cell (ci, cj): the exact bound of H_L there (tilecache.h's pyramid). */
void tf_proc_range(const tf_procedural *p, int level, int k, int64_t ci, int64_t cj, float *lo,
                   float *hi);
/* H_L at (x, y) (clamped to the terrain's square). */
double tf_proc_level_height(const tf_procedural *p, int level, double x, double y);
/* h at (x, y) for the view. */
double tf_proc_height(const tf_procedural *p, const tf_proc_view *v, double x, double y);
/* Bound of h over the box for the view, world units. */
tf_interval tf_proc_bound(const tf_procedural *p, const tf_proc_view *v, double x0, double x1,
                          double y0, double y1);
/* The same for levels lo..hi (tf_proc_box_levels'), whatever the view. */
tf_interval tf_proc_bound_levels(const tf_procedural *p, double x0, double x1, double y0,
                                 double y1, int lo, int hi);

#endif
