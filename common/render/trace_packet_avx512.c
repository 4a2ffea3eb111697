/* trace_packet_avx512.c: the packet walk (trace_packet_kernel.h) for AVX-512 (F, DQ, VL, BW),
 * 8 lanes: one zmm register of doubles, lane masks in mask
 * registers; the blocks' bounds by vgatherqps.  Chosen at run time (trace_packet.c). */
#include "render/trace_packet_kernel.h"

#ifdef TF_TRACE_X86
#include <immintrin.h>
/* Every function below is compiled for the ISA (clang has no target pragma, but applies the
 * attribute to a region). */
#ifdef __clang__
#pragma clang attribute push(__attribute__((target("avx512f,avx512bw,avx512vl,avx512dq"))), \
                             apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx512f,avx512bw,avx512vl,avx512dq")
#endif

#pragma GCC diagnostic ignored "-Wpsabi" /* no vector crosses a call: all inlined */

#define W 8
#define TF_KERNEL tf_trace_packet_avx512
typedef double vd __attribute__((vector_size(8 * W)));
typedef int64_t vl __attribute__((vector_size(8 * W)));

#define LANE static inline __attribute__((always_inline))
LANE unsigned bits_l(vl m) { return (unsigned)_mm512_movepi64_mask((__m512i)m); }
LANE vd gather_f(const float *base, vl off)
{
    return (vd)_mm512_cvtps_pd(_mm512_i64gather_ps((__m512i)off, base, 4));
}
/* table[idx] by a permute of its first 16 entries (a gather's latency sat on every step's
 * critical path); the grids have at most 16 levels up to 32768^2 cells, beyond that a gather. */
LANE vl gather_i(const int64_t *table, vl idx)
{
    if (__builtin_expect(_mm512_cmpgt_epi64_mask((__m512i)idx, _mm512_set1_epi64(15)) == 0, 1))
        return (vl)_mm512_permutex2var_epi64(_mm512_loadu_si512(table), (__m512i)idx,
                                             _mm512_loadu_si512(table + 8));
    return (vl)_mm512_i64gather_epi64((__m512i)idx, table, 8);
}
#undef LANE

#include "render/trace_packet_kernel.h"
#ifdef __clang__
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif
