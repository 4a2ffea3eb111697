/* trace_packet.h: many rays through the grid height field at once, in SIMD packets (2 lanes
 * portable, 4 AVX2, 8 AVX-512: one register of doubles; trace_packet_kernel.h), each ray's
 * hit bit-identical to tf_trace's and each occlusion to tf_occluded's.  The renderer uses it
 * for coherent rays: a corner row's camera rays and their shadow rays (render.c).
 *
 * TF_TRACE_ISA=portable|avx2|avx512 caps the ISA (like TF_EROSION_ISA).  TF_TRACE_PACKETS=0
 * turns the renderer's packets off, =1 on; unset, they are on only with the AVX-512 kernel,
 * the one not slower than single rays (bench/README.md, "Packets of rays": on this EPYC
 * AVX-512 packets match single camera rays, lose on shadow rays (0.8x) and leave a whole
 * render unchanged (1.00-1.01x); the AVX2 and portable walks are slower than the scalar walk,
 * kept correct and tested for A/B and for other CPUs).
 *
 * These functions walk grid height fields; a procedural terrain's packets need its view and
 * go through the quad-tree (tf_proc_trace_packet, trace_procedural.h): given one (hf->proc),
 * these fall back to single rays. */
#ifndef TF_TRACE_PACKET_H
#define TF_TRACE_PACKET_H

#include "render/trace.h"

/* For i < n: found[i] = tf_trace(hf, o[i], d[i], tmin[i], tmax[i], &hits[i]) (hits[i] written
 * only on a hit). */
void tf_trace_packets(const tf_heightfield *hf, int n, const tf_vec3 *o, const tf_vec3 *d,
                      const double *tmin, const double *tmax, unsigned char *found,
                      tf_hit *hits);
/* For i < n: occluded[i] = tf_occluded(hf, o[i], d[i], tmin[i], tmax[i]). */
void tf_occluded_packets(const tf_heightfield *hf, int n, const tf_vec3 *o, const tf_vec3 *d,
                         const double *tmin, const double *tmax, unsigned char *occluded);

/* The ISA the packets run on now ("avx512", "avx2" or "portable"), and its lanes. */
const char *tf_trace_packet_isa(void);
int tf_trace_packet_lanes(void);
/* Cap the ISA for this process, over TF_TRACE_ISA (NULL: TF_TRACE_ISA decides again).
 * -1 if the name is unknown or this CPU cannot run it. */
int tf_trace_packet_force_isa(const char *isa);

/* Whether the renderer traces a grid's rays in packets: TF_TRACE_PACKETS ("0": no, anything
 * else: yes; unset: yes with the AVX-512 kernel only), unless forced (1 on, 0 off, -1: the
 * variable decides again). */
int tf_trace_packets_enabled(void);
void tf_trace_packets_force(int on);
/* The same switch with `unset` as the answer when neither the variable nor a force says (a
 * procedural terrain's packets, trace_procedural.h, are no SIMD kernel: on unless switched
 * off, as fast as single rays, bench/README.md section 47). */
int tf_trace_packets_wanted(int unset);

#endif
