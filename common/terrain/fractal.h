/* fractal.h: Musgrave's procedural terrains (dissertation 2.3.2) as point functions, and the
 * row evaluator the height-field builder uses.
 *
 * Noise-space functions take a point p already in noise units.  With N_i = N(p lacunarity^i)
 * and w_i = lacunarity^(-H i) (w_0 = 1; a fractional `octaves` scales the last, extra octave by
 * its fraction, 2.3.2.1):
 *
 *   fBm     sum_i w_i N_i                                              (tf_fbm2, noise.h)
 *   hetero  A_0 = N_0 + offset;  A_i = A_{i-1} + A_{i-1} (N_i + offset) w_i
 *           "statistics by altitude" (2.3.2.3): detail is scaled by the altitude so far, so
 *           terrain near sea level (A ~ 0) stays smooth and high ground grows rough.
 *   hybrid  s_0 = (N_0 + offset) / 2;  s_i = clamp(gain s_{i-1}, 0, 1) (N_i + offset) / 2;
 *           result = sum_i w_i s_i.  The large-scale terrain model (2.3.2.5, "Terrain()", gain
 *           = 1/threshold): each octave is weighted by the previous one, so valleys stay
 *           smooth at all smaller scales while peaks keep their detail.
 *   ridged  the same weighting with the basis (offset - |N_i|)^2 ("1 - abs(N)" of 2.3.2.5.3,
 *           squared to sharpen the ridges): Musgrave's ridged multifractal; offset ~ 1,
 *           gain ~ 2.
 *
 * Terrain functions map world (x, y) to noise space as (x / feature_size + ox, y /
 * feature_size + oy), with (ox, oy) derived from the seed and never a lattice point, so the
 * world origin is not a zero of every octave. */
#ifndef TF_FRACTAL_H
#define TF_FRACTAL_H

#include "terrain/noise.h"
#include "terrain/noise_impl.h"
#include "scene.h"
#include "terrain/terrain.h"

double tf_hetero2(const tf_noise *nz, double x, double y, double H, double lacunarity,
                  double octaves, double offset);
double tf_hybrid2(const tf_noise *nz, double x, double y, double H, double lacunarity,
                  double octaves, double offset, double gain);
double tf_ridged2(const tf_noise *nz, double x, double y, double H, double lacunarity,
                  double octaves, double offset, double gain);

/* A point generator prepared once (octave weights, seed offsets) and then evaluated many
 * times.  Read-only after tf_fractal_prepare, so any number of threads may share it. */
typedef struct tf_fractal {
    enum tf_generator generator;
    tf_octaves octaves;
    double H;      /* fractal increment (the plan's weights are lacunarity^(-H i)) */
    double offset, gain;
    double feature_size;
    double ox, oy; /* seed-derived noise-space offset */
} tf_fractal;

/* Returns 0, or -1 if t->generator is not a point generator (fbm, hetero, hybrid, ridged). */
int tf_fractal_prepare(tf_fractal *f, const tf_terrain *t);
/* Generator output (dimensionless) at world (x, y). */
double tf_fractal_eval(const tf_fractal *f, const tf_noise *nz, double x, double y);
/* Longest row tf_fractal_rowbuf accepts (bounds the allocation). */
#define TF_FRACTAL_ROW_MAX (1 << 20)

/* Scratch memory for tf_fractal_row: one per thread, for rows of up to `capacity` samples. */
typedef struct tf_fractal_rowbuf {
    int capacity;
    double *x;       /* each sample's noise-space x at the current octave */
    double *value;   /* running result (fbm, hybrid, ridged) or altitude (hetero) */
    double *signal;  /* previous octave's weighted signal (hybrid, ridged) */
    double *noise;   /* this octave's noise at each sample */
    tf_noise_column *columns; /* this octave's lattice columns spanning the row */
} tf_fractal_rowbuf;

/* 0, or -1 when out of memory (buf is then empty and tf_fractal_row still works, slower). */
int tf_fractal_rowbuf_init(tf_fractal_rowbuf *buf, int capacity);
void tf_fractal_rowbuf_free(tf_fractal_rowbuf *buf);

/* out[i] = (float)(scale * tf_fractal_eval(f, nz, (double)i * cell, y)) for i in [0, count):
 * bit for bit the same values, faster: octave by octave over the whole row, with the lattice
 * columns of each octave hashed once for all the samples that share them.  buf may be NULL or
 * too small, in which case every sample is evaluated as a point. */
void tf_fractal_row(const tf_fractal *f, const tf_noise *nz, double y, double cell, int count,
                    double scale, float *out, tf_fractal_rowbuf *buf);

/* The same for samples first .. first + count - 1: out[k] = (float)(scale *
 * tf_fractal_eval(f, nz, (double)(first + k) * cell, y)), bit for bit. */
void tf_fractal_row_at(const tf_fractal *f, const tf_noise *nz, double y, double cell,
                       int64_t first, int count, double scale, float *out,
                       tf_fractal_rowbuf *buf);

/* The seed-derived noise-space offset of the terrain functions (exposed for tests). */
void tf_fractal_seed_offset(uint64_t seed, double *ox, double *oy);

#endif
