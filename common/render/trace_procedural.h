/* trace_procedural.h: exact tracing of the procedural terrain (terrain/procedural.h) for one
 * view, by a quad-tree over its square (Musgrave 6.3.2.2).
 *
 * A node is skipped when the ray passes above the bound of the surface over it
 * (tf_proc_bound: interval arithmetic, no samples evaluated), else its four children are
 * visited in the ray's order.  Nodes two cells of the finest level used there wide are leaves:
 * there the samples are read (evaluated and cached on first use) and the ray marches the
 * surface with steps no longer than the gap to it allows under a Lipschitz bound of the surface
 * over the leaf (from the samples' differences and the rate the level blend can change), so it
 * cannot step over a thin ridge.  A hit is where the gap falls below a thousandth of the
 * leaf's finest spacing.  Everything is a function of the ray and the view: the same bits on
 * any worker, whatever it has cached. */
#ifndef TF_TRACE_PROCEDURAL_H
#define TF_TRACE_PROCEDURAL_H

#include "render/trace.h"
#include "terrain/procedural.h"

/* As tf_trace: first hit of origin + t dir, t in (tmin, tmax).  hit->n is the surface's
 * normal (the gradient of h: smooth), hit->ci = hit->cj = 0. */
int tf_proc_trace(const tf_procedural *p, const tf_proc_view *v, tf_vec3 origin, tf_vec3 dir,
                  double tmin, double tmax, tf_hit *hit);
int tf_proc_occluded(const tf_procedural *p, const tf_proc_view *v, tf_vec3 origin, tf_vec3 dir,
                     double tmin, double tmax);
/* For k < n: found[k] = tf_proc_trace(p, v, o[k], d[k], tmin[k], tmax[k], &hits[k]) (hits[k]
 * written only on a hit), the same bits, the rays traced in packets: each node's facts asked
 * and each leaf loaded once for the rays that reach it.  Coherent rays (a row of a camera's,
 * shadow rays toward one sun) share most of their nodes. */
void tf_proc_trace_packet(const tf_procedural *p, const tf_proc_view *v, int n, const tf_vec3 *o,
                          const tf_vec3 *d, const double *tmin, const double *tmax,
                          unsigned char *found, tf_hit *hits);
/* For k < n: occluded[k] = tf_proc_occluded(p, v, o[k], d[k], tmin[k], tmax[k]), in packets. */
void tf_proc_occluded_packet(const tf_procedural *p, const tf_proc_view *v, int n,
                             const tf_vec3 *o, const tf_vec3 *d, const double *tmin,
                             const double *tmax, unsigned char *occluded);
/* How far a shadow ray from a hit at p starts above the surface: well above the hit
 * tolerance of the levels there. */
double tf_proc_shadow_lift(const tf_procedural *p, const tf_proc_view *v, tf_vec3 p_hit);

#endif
