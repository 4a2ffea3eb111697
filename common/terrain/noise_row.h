/* noise_row.h: the inner loop of the terrain's row evaluator (fractal.c, noise_row there) many
 * samples at a time: each sample's noise from a table of the octave's lattice columns.
 *
 * noise[k] = tf_noise_blend(fx, columns[xi - first], columns[xi - first + 1]) where xi and fx
 * are tf_floor_split(x[k]) (noise_impl.h): the same IEEE operations in the same order as the
 * scalar code, eight samples per instruction with AVX-512, so the bits are the same;
 * tests/unit/test_fractal.c compares the kernels.  The kernel is chosen once from the CPU;
 * TF_NOISE_ISA=portable forces the scalar one. */
#ifndef TF_NOISE_ROW_H
#define TF_NOISE_ROW_H

#include <stdint.h>
#include "terrain/noise.h"

/* Blend samples [0, count) as above, where every floor(x[k]) - first lies in [0, columns - 2]
 * (the caller's table spans the row, and has TF_NOISE_ROW_SLACK readable entries past its end).  Returns how many leading samples it did (a multiple of
 * the vector width, 0 with the portable kernel); the caller does the rest one by one. */
#define TF_NOISE_ROW_SLACK 8
int tf_noise_row_blend(const double *x, int count, int64_t first, const tf_noise_column *columns,
                       double *noise);

/* The two other loops of a row's octave, with the same kernel: x[k] *= by, and
 * v[k] += amp * n[k] (one multiply, one add, rounded each: the scalar expressions). */
void tf_row_scale(double *x, int count, double by);
void tf_row_accumulate(double *v, double amp, const double *n, int count);

/* The kernel tf_noise_row_blend uses: "avx512" or "portable". */
const char *tf_noise_row_isa(void);
/* Use kernel `isa` from now on (NULL: the best again; tests compare the kernels).  -1 when
 * this CPU cannot run it or the name is unknown. */
int tf_noise_row_force_isa(const char *isa);

#endif
