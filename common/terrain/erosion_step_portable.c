/* erosion_step_portable.c: the erosion kernel (erosion_kernel.h) for the baseline ISA, 4 lanes:
 * one SSE2 register on x86-64 (minps, maxps, cvtdq2ps, cvttps2dq; SSE2 has no blend and no
 * 32-bit integer min, so those are compare and mask), one NEON register elsewhere.  (Eight
 * lanes here were two registers' worth that GCC broke into scalars: 10x slower.) */
#include "terrain/erosion_kernel.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* The vector helpers are always inlined, so no vector crosses a call: GCC's note that passing
 * one would change the ABI does not apply. */
#pragma GCC diagnostic ignored "-Wpsabi"

#define W 4
#define TF_KERNEL tf_erosion_kernel_portable
typedef int32_t vi __attribute__((vector_size(16)));
typedef float vf __attribute__((vector_size(16)));
typedef vi vm; /* all bits of a lane set, or none */

#define LANE static inline __attribute__((always_inline))
LANE vm gt_i(vi a, vi b) { return a > b; }
LANE vm eq_i(vi a, vi b) { return a == b; }
LANE vm lt_f(vf a, vf b) { return a < b; }
LANE vm m_and(vm a, vm b) { return a & b; }
LANE vm m_or(vm a, vm b) { return a | b; }
LANE vm m_all(int yes) { return (vm){0} - (yes != 0); }
LANE vi sel_i(vm m, vi a, vi b) { return (a & m) | (b & ~m); }
LANE vf sel_f(vm m, vf a, vf b) { return (vf)(((vi)a & m) | ((vi)b & ~m)); }
LANE vi keep_i(vm m, vi x) { return x & m; }
LANE vi min_i(vi a, vi b) { return sel_i(b > a, a, b); }
LANE vi max_i(vi a, vi b) { return sel_i(a > b, a, b); }
#if defined(__SSE2__)
LANE vf min_f(vf a, vf b) { return (vf)_mm_min_ps((__m128)a, (__m128)b); }
LANE vf max_f(vf a, vf b) { return (vf)_mm_max_ps((__m128)a, (__m128)b); }
LANE vf to_f(vi x) { return (vf)_mm_cvtepi32_ps((__m128i)x); }
LANE vi to_i(vf x) { return (vi)_mm_cvttps_epi32((__m128)x); }
#else
LANE vf min_f(vf a, vf b) { return sel_f(a < b, a, b); }
LANE vf max_f(vf a, vf b) { return sel_f(a > b, a, b); }
LANE vf to_f(vi x) { return __builtin_convertvector(x, vf); }
LANE vi to_i(vf x) { return __builtin_convertvector(x, vi); } /* truncates toward zero */
#endif
LANE int any_i(vi x) { return (x[0] | x[1] | x[2] | x[3]) != 0; }
LANE int64_t sum_i(vi x) { return (int64_t)x[0] + x[1] + x[2] + x[3]; }
#undef LANE

#include "terrain/erosion_kernel.h"
