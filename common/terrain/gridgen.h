/* gridgen.h: helpers shared by the whole-grid terrain generators (midpoint.c, fault.c,
 * subdivide.c, weathering.c): a deterministic parallel-for over index ranges, and the hashed
 * random variates every generator draws from.
 *
 * Determinism contract: a generator's output must be bit-identical for every thread count.  The
 * generators guarantee it by (a) making every random number a pure function of
 * (seed, stream, level, i, j) through tf_hash64, never of a sequential PRNG, and (b) splitting
 * work only into pieces whose results do not depend on one another within one parallel phase
 * (each output element is written by exactly one piece, reading only data fixed before the
 * phase).  tf_grid_parallel only decides WHO computes a piece, never WHAT is computed. */
#ifndef TF_GRIDGEN_H
#define TF_GRIDGEN_H

#include <stddef.h>
#include <stdint.h>
#include "terrain/noise.h"
#include "scene.h"

/* Largest thread count honoured; more are clamped (the pieces stay the same either way). */
#define TF_GRID_MAX_THREADS 64

/* Run fn(ctx, piece, begin, end) over [0, count) split into contiguous ranges, one per thread,
 * with `threads` threads (<= 1: the caller's thread runs everything).  Returns when all are
 * done.  Ranges smaller than `min_chunk` are not split further (thread start-up costs
 * microseconds).  `piece` is 0 .. tf_grid_pieces(...) - 1, for per-piece scratch memory.
 * If a thread cannot be started its range runs on the caller's thread: same result. */
typedef void (*tf_grid_range_fn)(void *ctx, int piece, int begin, int end);
void tf_grid_parallel(int count, int threads, int min_chunk, tf_grid_range_fn fn, void *ctx);
/* How many pieces tf_grid_parallel will use for these arguments (>= 1). */
int tf_grid_pieces(int count, int threads, int min_chunk);

/* Stream tags keep the generators' random numbers independent of one another. */
enum {
    TF_STREAM_MIDPOINT = 1,
    TF_STREAM_FAULT = 2,
    TF_STREAM_SUBDIVIDE = 3,
};

/* One 64-bit hash of (seed, stream, level, i, j): the key of one random draw.  Each input is
 * folded in through its own round of the splitmix64 finaliser, so nearby keys decorrelate. */
static inline uint64_t tf_grid_key(uint64_t seed, uint32_t stream, uint32_t level, uint32_t i,
                                   uint32_t j)
{
    uint64_t x = tf_hash64(seed ^ ((uint64_t)stream << 56));
    x = tf_hash64(x ^ level);
    x = tf_hash64(x ^ (((uint64_t)j << 32) | i));
    return x;
}

/* Uniform double in [0, 1) from a key. */
static inline double tf_grid_unit(uint64_t key) { return (double)(key >> 11) * 0x1.0p-53; }

/* Approximately Gaussian variate with mean 0 and variance 1, bounded by |g| <= 2*sqrt(3):
 * the Irwin-Hall sum of four 16-bit uniforms taken from one hashed key, recentred and scaled.
 * Plain integer and double arithmetic, so every machine computes the same bits. */
#define TF_GRID_GAUSS_MAX 3.4641016151377544 /* 2 * sqrt(3) */
static inline double tf_grid_gauss(uint64_t key)
{
    uint64_t h = tf_hash64(key);
    uint32_t sum = (uint32_t)(h & 0xffff) + (uint32_t)((h >> 16) & 0xffff) +
                   (uint32_t)((h >> 32) & 0xffff) + (uint32_t)(h >> 48);
    /* sum / 65536 is in [0, 4) with mean ~2 and variance 4/12; (sum + 2) centres it exactly. */
    double u = ((double)sum + 2.0) * (1.0 / 65536.0) - 2.0;
    return u * 1.7320508075688772; /* sqrt(3): variance 1/3 -> 1 */
}

/* Koh & Hearn control elevation (midpoint.c) at grid point (i, j) of an n x n grid over the
 * same square as the t->envelope_n^2 control points (needs envelope_n >= 2): linear on the two
 * triangles of each control square, split along its (0,0)-(1,1) diagonal. */
double tf_envelope_at(const tf_terrain *t, int n, int i, int j);

#endif
