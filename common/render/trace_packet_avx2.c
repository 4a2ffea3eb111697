/* trace_packet_avx2.c: the packet walk (trace_packet_kernel.h) for AVX2, 4 lanes: one ymm
 * register of doubles; the blocks' bounds by vgatherqps.  Chosen at run time (trace_packet.c). */
#include "render/trace_packet_kernel.h"

#ifdef TF_TRACE_X86
#include <immintrin.h>
/* Every function below is compiled for the ISA (clang has no target pragma, but applies the
 * attribute to a region). */
#ifdef __clang__
#pragma clang attribute push(__attribute__((target("avx2"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx2")
#endif

#pragma GCC diagnostic ignored "-Wpsabi" /* no vector crosses a call: all inlined */

#define W 4
#define TF_KERNEL tf_trace_packet_avx2
typedef double vd __attribute__((vector_size(8 * W)));
typedef int64_t vl __attribute__((vector_size(8 * W)));

#define LANE static inline __attribute__((always_inline))
LANE unsigned bits_l(vl m) { return (unsigned)_mm256_movemask_pd((__m256d)m); }
LANE vd gather_f(const float *base, vl off)
{
    return (vd)_mm256_cvtps_pd(_mm256_i64gather_ps(base, (__m256i)off, 4));
}
LANE vl gather_i(const int64_t *table, vl idx)
{
    return (vl)_mm256_i64gather_epi64((const long long *)table, (__m256i)idx, 8);
}
#undef LANE

#include "render/trace_packet_kernel.h"
#ifdef __clang__
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif
