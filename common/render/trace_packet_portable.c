/* trace_packet_portable.c: the packet walk (trace_packet_kernel.h) for the baseline ISA, 4
 * lanes (two SSE2 registers of doubles on x86-64; plain vectors elsewhere).  Chosen at run time
 * (trace_packet.c) where the CPU has nothing better, or under TF_TRACE_ISA=portable. */
#include "render/trace_packet_kernel.h"

/* The vector helpers are always inlined, so no vector crosses a call: GCC's note that passing
 * one would change the ABI does not apply. */
#pragma GCC diagnostic ignored "-Wpsabi"

#define W 4
#define TF_KERNEL tf_trace_packet_portable
typedef double vd __attribute__((vector_size(8 * W)));
typedef int64_t vl __attribute__((vector_size(8 * W)));

#include "render/trace_packet_kernel.h"
