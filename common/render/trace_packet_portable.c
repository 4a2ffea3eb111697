/* trace_packet_portable.c: the packet walk (trace_packet_kernel.h) for the baseline ISA, 2
 * lanes (one SSE2 register of doubles on x86-64; plain vectors elsewhere).  Chosen at run time
 * (trace_packet.c) where the CPU has nothing better, or under TF_TRACE_ISA=portable. */
#include "render/trace_packet_kernel.h"

#include <stdint.h>

/* The vector helpers are always inlined, so no vector crosses a call: GCC's note that passing
 * one would change the ABI does not apply. */
#pragma GCC diagnostic ignored "-Wpsabi"

#define W 2
#define TF_KERNEL tf_trace_packet_portable
typedef double vd __attribute__((vector_size(8 * W)));
typedef int64_t vl __attribute__((vector_size(8 * W)));

#define LANE static inline __attribute__((always_inline))
LANE unsigned bits_l(vl m)
{
    unsigned b = 0;
    for (int l = 0; l < W; l++)
        b |= (unsigned)(m[l] != 0) << l;
    return b;
}
LANE vd gather_f(const float *base, vl off)
{
    vd r;
    for (int l = 0; l < W; l++)
        r[l] = *(const float *)((intptr_t)base + (intptr_t)off[l] * (intptr_t)sizeof(float));
    return r;
}
LANE vl gather_i(const int64_t *table, vl idx)
{
    vl r;
    for (int l = 0; l < W; l++)
        r[l] = table[idx[l]];
    return r;
}
#undef LANE

#include "render/trace_packet_kernel.h"
