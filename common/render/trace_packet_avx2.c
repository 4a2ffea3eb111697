/* trace_packet_avx2.c: the packet walk (trace_packet_kernel.h) for AVX2, 8 lanes: two ymm
 * registers of doubles.  Chosen at run time (trace_packet.c). */
#include "render/trace_packet_kernel.h"

#ifdef TF_TRACE_X86
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
#define TF_KERNEL tf_trace_packet_avx2
typedef double vd __attribute__((vector_size(8 * W)));
typedef int64_t vl __attribute__((vector_size(8 * W)));

#include "render/trace_packet_kernel.h"
#ifdef __clang__
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif
