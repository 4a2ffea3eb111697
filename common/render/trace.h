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

/* Coherence of camera rays: what a traced ray vouches for about the rays just above it.
 * A ray that stays above the surface out to horizontal distance s_free keeps any ray from the
 * same origin that climbs faster than it by more than the terrain's steepest slope
 * (hf->slope_max) times the angle between their headings above the surface that far too
 * (trace.c, "Coherence", proves it and the margins).  So a camera ray traced after the one
 * below it starts its walk where that one hit.  Only speed depends on this: the hit is
 * tf_trace's, bit for bit, whatever record is passed. */
/* Shadow rays toward one sun are parallel: where one went under the surface, its neighbour,
 * started a little aside, most likely does too, and one height lookup there proves it
 * (tf_occluded_coherent). */
typedef struct tf_shadow_clear {
    double d[3];        /* the direction (a record helps rays of this very direction only) */
    double t_under;     /* a parameter at which the ray was under the surface; 0: none known;
                         * < 0: the sun's strips proved it under, the point not yet named
                         * (sun_strips.h: tf_sun_strips_named names it, from o) */
    double o[3];        /* the ray's origin, where t_under < 0 */
} tf_shadow_clear;

typedef struct tf_ray_clear {
    double o[3];        /* the origin (a record helps rays from this very origin only) */
    double ux, uy, k;   /* heading (unit, horizontal) and climb (dz per unit of horizontal run) */
    double s_in;        /* horizontal distance where the ray enters the terrain's square */
    double s_free;      /* above the surface over [s_in, s_free); 0: the ray vouches for nothing */
} tf_ray_clear;

/* tf_trace with tmin = 0, helped by `lower` (a record of another ray, or NULL); fills *mine
 * (if not NULL) with this ray's record.  The same return and hit as tf_trace. */
int tf_trace_coherent(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmax,
                      const tf_ray_clear *lower, tf_hit *hit, tf_ray_clear *mine);
/* tf_trace_coherent helped by whichever of lowers[0 .. n) (NULL entries allowed) vouches for
 * the longest skip: the same return and hit. */
int tf_trace_coherent_among(const tf_heightfield *hf, tf_vec3 origin, tf_vec3 dir, double tmax,
                            const tf_ray_clear *const *lowers, int n, tf_hit *hit,
                            tf_ray_clear *mine);
/* What a walk's setup computes from a direction alone: its steps, inverses and shear (a dozen
 * divisions), made once by tf_ray_dir_init for every ray of that direction over `hf` -- the
 * sun's shadow rays.  Fields are trace.c's; callers only hold it. */
typedef struct tf_ray_dir {
    const tf_heightfield *hf;
    double d[3];
    int ok;                /* 0: no walk (d zero or not finite, or hf NULL) */
    int sx, sy;            /* -1, 0, +1: direction of travel across columns / rows */
    double inv_dx, inv_dy; /* the walk's inverses (tf_safe_inverse) on axes with a step */
    double exit_inv[3];    /* 1 / d per axis where that is a normal double, else 0: the
                            * box's exit proved beyond tmax by a product (trace.c) */
    double inv_cell;
    int kx, ky, kz;        /* ray-space axes and shear (trace.c's triangle test) */
    double shx, shy, shz;
    double tol[7];         /* the walk's tolerances' parts that depend on the direction only */
    double exit_xy[2];     /* the box's side a ray leaves by on x and y (cells * cell or 0) */
    int moves_all;         /* d has no zero component (trace.c's window_in_box) */
} tf_ray_dir;

/* Fill *dir for rays of direction d over hf; returns dir->ok. */
int tf_ray_dir_init(tf_ray_dir *dir, const tf_heightfield *hf, tf_vec3 d);

/* tf_occluded over dir->hf with tmin = 0 and direction dir->d, helped by `near` (a record of a
 * parallel ray, or NULL): the same answer, bit for bit.  Fills *mine (if not NULL) with this
 * ray's record. */
int tf_occluded_coherent(const tf_ray_dir *dir, tf_vec3 origin, double tmax,
                         const tf_shadow_clear *near, tf_shadow_clear *mine);

#endif
