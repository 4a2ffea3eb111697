/* trace.h: grid tracing of a height field (Musgrave chapter 3).
 *
 * tf_trace_flat is the reference: Musgrave's modified DDA over the cells of the height field,
 * tracking the ray's altitude across each cell and testing a cell's two triangles exactly only
 * when the ray dips below the cell's maximum altitude (maxgrid[0]).
 * tf_trace is the fast path: the same walk over the hierarchy of max grids, descending a level
 * where the ray may hit and skipping whole blocks where it passes above.  Both must report the
 * same hits (tests compare them on random rays). */
#ifndef TF_TRACE_H
#define TF_TRACE_H

#include "terrain/heightfield.h"
#include "vec.h"

typedef struct tf_hit {
    double t;        /* ray parameter of the hit (dir need not be unit: t scales with it) */
    tf_vec3 p;       /* hit point */
    tf_vec3 n;       /* geometric normal of the triangle hit (unit, z > 0) */
    int ci, cj;      /* cell hit */
} tf_hit;

/* First intersection of origin + t*dir, t in (tmin, tmax), with the terrain surface.
 * Returns 1 and fills *hit, or 0 for a miss.  Rays from any origin (above, below, beside the
 * terrain's box) and any direction, including axis-parallel and vertical, must be handled. */
int tf_trace(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmin, double tmax,
             tf_hit *hit);
int tf_trace_flat(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmin, double tmax,
                  tf_hit *hit);
/* Any hit in (tmin, tmax)? (shadow rays; may stop at the first hit found) */
int tf_occluded(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmin, double tmax);

#endif
