/* noise.h: seeded gradient (Perlin) noise in 2D and 3D and fBm sums of it (Musgrave 2.3.1,
 * 2.3.2.1).  The basis of every procedural terrain and of the renderer's textures (bump detail,
 * snow line perturbation, water ripples).  Deterministic from the seed on every machine: a
 * permutation built by a fixed integer PRNG, gradients from fixed tables, plain double
 * arithmetic.  Values of tf_noise2/3 lie in [-1, 1] and are 0 at integer lattice points. */
#ifndef TF_NOISE_H
#define TF_NOISE_H

#include <stdint.h>
#include "terrain/noise_kernel.h"

struct tf_noise {
    uint64_t seed;
    uint16_t perm[TF_NOISE_PERM]; /* permutation of 0..255, repeated */
};
typedef struct tf_noise tf_noise;

void tf_noise_init(tf_noise *nz, uint64_t seed);
double tf_noise2(const tf_noise *nz, double x, double y);
double tf_noise3(const tf_noise *nz, double x, double y, double z);
/* tf_noise2, bit for bit, and its exact gradient (d/dx, d/dy) in *gx, *gy. */
double tf_noise2_gradient(const tf_noise *nz, double x, double y, double *gx, double *gy);

/* fBm: sum over octaves i of noise(p * lacunarity^i) * lacunarity^(-H i); a fractional
 * remainder of `octaves` adds that fraction of one more octave. */
double tf_fbm2(const tf_noise *nz, double x, double y, double H, double lacunarity, double octaves);
/* tf_fbm2, bit for bit, and its exact gradient in *gx, *gy (the textures' bump, shade.c). */
double tf_fbm2_gradient(const tf_noise *nz, double x, double y, double H, double lacunarity,
                        double octaves, double *gx, double *gy);
double tf_fbm3(const tf_noise *nz, double x, double y, double z, double H, double lacunarity,
               double octaves);

/* tf_hash64 and tf_hash_unit: noise_kernel.h (shared with the OpenCL kernels). */

#endif
