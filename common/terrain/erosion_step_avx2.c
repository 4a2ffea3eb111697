/* erosion_step_avx2.c: the erosion kernel (erosion_kernel.h) for AVX2, 8 lanes: one ymm
 * register (vpminsd, vpblendvb, vminps, ...).  Chosen at run time (erosion_step.c). */
#include "terrain/erosion_kernel.h"

#ifdef TF_EROSION_X86
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

#define W 8
#define TF_KERNEL tf_erosion_kernel_avx2
typedef int32_t vi __attribute__((vector_size(32)));
typedef float vf __attribute__((vector_size(32)));
typedef vi vm; /* all bits of a lane set, or none */

#define LANE static inline __attribute__((always_inline))
LANE vm gt_i(vi a, vi b) { return a > b; }
LANE vm eq_i(vi a, vi b) { return a == b; }
LANE vm lt_f(vf a, vf b) { return a < b; }
LANE vm m_and(vm a, vm b) { return a & b; }
LANE vm m_or(vm a, vm b) { return a | b; }
LANE vm m_all(int yes) { return (vm){0} - (yes != 0); }
LANE vi sel_i(vm m, vi a, vi b)
{
    return (vi)_mm256_blendv_epi8((__m256i)b, (__m256i)a, (__m256i)m);
}
LANE vf sel_f(vm m, vf a, vf b) { return (vf)_mm256_blendv_ps((__m256)b, (__m256)a, (__m256)m); }
LANE vi keep_i(vm m, vi x) { return x & m; }
LANE vi min_i(vi a, vi b) { return (vi)_mm256_min_epi32((__m256i)a, (__m256i)b); }
LANE vi max_i(vi a, vi b) { return (vi)_mm256_max_epi32((__m256i)a, (__m256i)b); }
LANE vf min_f(vf a, vf b) { return (vf)_mm256_min_ps((__m256)a, (__m256)b); }
LANE vf max_f(vf a, vf b) { return (vf)_mm256_max_ps((__m256)a, (__m256)b); }
LANE vf to_f(vi x) { return (vf)_mm256_cvtepi32_ps((__m256i)x); }
LANE vi to_i(vf x) { return (vi)_mm256_cvttps_epi32((__m256)x); }
LANE int any_i(vi x) { return !_mm256_testz_si256((__m256i)x, (__m256i)x); }
LANE int64_t sum_i(vi x)
{
    __m256i lo = _mm256_cvtepi32_epi64(_mm256_castsi256_si128((__m256i)x));
    __m256i hi = _mm256_cvtepi32_epi64(_mm256_extracti128_si256((__m256i)x, 1));
    __m256i s = _mm256_add_epi64(lo, hi);
    __m128i t = _mm_add_epi64(_mm256_castsi256_si128(s), _mm256_extracti128_si256(s, 1));
    return _mm_cvtsi128_si64(t) + _mm_extract_epi64(t, 1);
}
#undef LANE

#include "terrain/erosion_kernel.h"
#ifdef __clang__
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif
