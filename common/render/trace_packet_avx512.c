/* trace_packet_avx512.c: the packet walk (trace_packet_kernel.h) for AVX-512 (F, DQ, VL, BW),
 * 16 lanes: two zmm registers of doubles.  Chosen at run time (trace_packet.c). */
#include "render/trace_packet_kernel.h"

#ifdef TF_TRACE_X86
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
#define TF_KERNEL tf_trace_packet_avx512
typedef double vd __attribute__((vector_size(8 * W)));
typedef int64_t vl __attribute__((vector_size(8 * W)));

#include "render/trace_packet_kernel.h"
#ifdef __clang__
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif
