/* erosion_step_avx512.c: the erosion kernel (erosion_kernel.h) for AVX-512 (F, BW, VL, DQ), 16
 * lanes: one zmm register, lane masks in mask registers (compares write them, blends and
 * zeroing moves read them).  Chosen at run time (erosion_step.c). */
#include "terrain/erosion_kernel.h"

#ifdef TF_EROSION_X86
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

#define W 16
#define TF_KERNEL tf_erosion_kernel_avx512
typedef int32_t vi __attribute__((vector_size(64)));
typedef float vf __attribute__((vector_size(64)));
typedef __mmask16 vm; /* bit l: lane l */

#define LANE static inline __attribute__((always_inline))
LANE vm gt_i(vi a, vi b) { return _mm512_cmpgt_epi32_mask((__m512i)a, (__m512i)b); }
LANE vm eq_i(vi a, vi b) { return _mm512_cmpeq_epi32_mask((__m512i)a, (__m512i)b); }
LANE vm lt_f(vf a, vf b) { return _mm512_cmp_ps_mask((__m512)a, (__m512)b, _CMP_LT_OS); }
LANE vm m_and(vm a, vm b) { return a & b; }
LANE vm m_or(vm a, vm b) { return a | b; }
LANE vm m_all(int yes) { return yes ? 0xffff : 0; }
LANE vi sel_i(vm m, vi a, vi b) { return (vi)_mm512_mask_blend_epi32(m, (__m512i)b, (__m512i)a); }
LANE vf sel_f(vm m, vf a, vf b) { return (vf)_mm512_mask_blend_ps(m, (__m512)b, (__m512)a); }
LANE vi keep_i(vm m, vi x) { return (vi)_mm512_maskz_mov_epi32(m, (__m512i)x); }
LANE vi min_i(vi a, vi b) { return (vi)_mm512_min_epi32((__m512i)a, (__m512i)b); }
LANE vi max_i(vi a, vi b) { return (vi)_mm512_max_epi32((__m512i)a, (__m512i)b); }
LANE vf min_f(vf a, vf b) { return (vf)_mm512_min_ps((__m512)a, (__m512)b); }
LANE vf max_f(vf a, vf b) { return (vf)_mm512_max_ps((__m512)a, (__m512)b); }
LANE vf to_f(vi x) { return (vf)_mm512_cvtepi32_ps((__m512i)x); }
LANE vi to_i(vf x) { return (vi)_mm512_cvttps_epi32((__m512)x); }
LANE int any_i(vi x) { return _mm512_test_epi32_mask((__m512i)x, (__m512i)x) != 0; }
LANE int64_t sum_i(vi x)
{
    __m512i lo = _mm512_cvtepi32_epi64(_mm512_castsi512_si256((__m512i)x));
    __m512i hi = _mm512_cvtepi32_epi64(_mm512_extracti64x4_epi64((__m512i)x, 1));
    return _mm512_reduce_add_epi64(_mm512_add_epi64(lo, hi));
}
#undef LANE

#include "terrain/erosion_kernel.h"
#ifdef __clang__
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif
