/* trace_packet.c: tf_trace_packets and tf_occluded_packets (trace_packet.h): the packet kernel
 * for the best ISA the CPU has (trace_packet_kernel.h: AVX-512, AVX2, or the portable one),
 * capped by TF_TRACE_ISA; and the renderer's switch, TF_TRACE_PACKETS (unset: on with the
 * AVX-512 kernel only). */
#include "render/trace_packet.h"

#include <stdlib.h>
#include <string.h>

#include "isa.h"
#include "render/trace_packet_kernel.h"

static const struct {
    const char *name; /* first: a kernel table of isa.h */
    int lanes;
    tf_trace_packet_kernel *fn;
} kernels[] = {
#ifdef TF_TRACE_X86
    {"avx512", 8, tf_trace_packet_avx512},
    {"avx2", 4, tf_trace_packet_avx2},
#endif
    {"portable", 2, tf_trace_packet_portable},
};
enum { KERNELS = sizeof kernels / sizeof kernels[0] };

static const char *forced = NULL; /* NULL: TF_TRACE_ISA decides */

/* The best kernel this CPU runs, no better than the cap (isa.h). */
static int chosen(void)
{
    const char *cap = forced ? forced : getenv("TF_TRACE_ISA");
    return tf_isa_choose(kernels, sizeof kernels[0], KERNELS, cap);
}

int tf_trace_packet_force_isa(const char *isa)
{
    if (isa && (tf_isa_find(kernels, sizeof kernels[0], KERNELS, isa) == KERNELS ||
                !tf_isa_runs(isa)))
        return -1;
    forced = isa;
    return 0;
}

const char *tf_trace_packet_isa(void) { return kernels[chosen()].name; }
int tf_trace_packet_lanes(void) { return kernels[chosen()].lanes; }

static int packets_forced = -1;

/* Unset, packets are on only with the AVX-512 kernel, the one not slower than single rays
 * (bench/README.md, "Packets of rays": a whole render 1.00-1.01x with it; the AVX2 kernel
 * 0.97-0.98x, its rays 0.7x; the portable one 0.3x). */
int tf_trace_packets_wanted(int unset)
{
    if (packets_forced >= 0)
        return packets_forced;
    const char *v = getenv("TF_TRACE_PACKETS");
    if (v && *v)
        return strcmp(v, "0") != 0;
    return unset;
}

int tf_trace_packets_enabled(void)
{
    return tf_trace_packets_wanted(!strcmp(kernels[chosen()].name, "avx512"));
}

void tf_trace_packets_force(int on) { packets_forced = on < 0 ? -1 : on != 0; }

/* A procedural terrain without its view (trace_packet.h): one ray at a time. */
static void single_rays(const tf_heightfield *hf, int n, const tf_vec3 *o, const tf_vec3 *d,
                        const double *tmin, const double *tmax, unsigned char *found,
                        tf_hit *hits)
{
    for (int i = 0; i < n; i++)
        found[i] = (unsigned char)(hits ? tf_trace(hf, o[i], d[i], tmin[i], tmax[i], &hits[i])
                                        : tf_occluded(hf, o[i], d[i], tmin[i], tmax[i]));
}

void tf_trace_packets(const tf_heightfield *hf, int n, const tf_vec3 *o, const tf_vec3 *d,
                      const double *tmin, const double *tmax, unsigned char *found,
                      tf_hit *hits)
{
    if (!hf || hf->proc)
        single_rays(hf, n, o, d, tmin, tmax, found, hits);
    else
        kernels[chosen()].fn(hf, n, o, d, tmin, tmax, found, hits);
}

void tf_occluded_packets(const tf_heightfield *hf, int n, const tf_vec3 *o, const tf_vec3 *d,
                         const double *tmin, const double *tmax, unsigned char *occluded)
{
    if (!hf || hf->proc)
        single_rays(hf, n, o, d, tmin, tmax, occluded, NULL);
    else
        kernels[chosen()].fn(hf, n, o, d, tmin, tmax, occluded, NULL);
}
