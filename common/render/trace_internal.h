/* trace_internal.h: the pieces of trace.c's single-ray walk that the packet tracer
 * (trace_packet.c and its kernels) calls lane by lane, so that every lane runs exactly the
 * single-ray code where it matters: the ray's setup, a level-0 cell's triangle tests and the
 * hit record.
 * Not an interface for anyone else: render code calls trace.h or trace_packet.h. */
#ifndef TF_TRACE_INTERNAL_H
#define TF_TRACE_INTERNAL_H

#include "render/trace.h"

/* A triangle hit found so far. */
typedef struct tf_trace_cand {
    double t;
    int ci, cj;
    int tri; /* 0: (A, B, C), 1: (A, C, D) */
} tf_trace_cand;

/* Everything a walk needs about one ray, computed once (trace.c's setup_ray). */
typedef struct tf_ray_ctx {
    const tf_heightfield *hf;
    double o[3], d[3];
    double inv_dx, inv_dy; /* only used on axes with a nonzero step */
    int sx, sy;            /* -1, 0, +1: direction of travel across columns / rows */
    double tmin, tmax;     /* the caller's open interval for hits */
    double t0, t1;         /* the part of [tmin, tmax] inside the terrain box (widened a hair) */
    double t_square;       /* where the ray enters the terrain's square (x and y only) */
    double margin;         /* altitude slack of the culling tests */
    double tie_tol;        /* crossings closer than this pass "through a corner" */
    int ci, cj;            /* the cell containing the point at t0 */
    double inv_cell;       /* 1 / cell: first guesses of cell indices, never a final one */
    int kx, ky, kz;        /* ray-space axes (kz: the dominant direction) */
    double shx, shy, shz;  /* shear constants */
    int planes;            /* a cell's triangles tested only where the ray may dip below their
                            * planes (trace.c, "The plane test"): occlusion walks */
} tf_ray_ctx;

/* walk_hier's stale axis after a block step. */
enum { TF_STALE_NONE, TF_STALE_X, TF_STALE_Y };

/* 0 if the ray cannot meet the terrain in (tmin, tmax); else *r is ready for a walk. */
int tf_trace_setup(tf_ray_ctx *r, const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmin,
                   double tmax);
/* tf_trace_setup for a ray of direction dir->d (tf_ray_dir_init): the same context, bit for
 * bit, with fewer divisions (what tf_occluded_coherent does; the tests compare the two). */
int tf_trace_setup_dir(tf_ray_ctx *r, const tf_ray_dir *dir, tf_vec3 o, double tmin,
                       double tmax);
/* The complete test of level-0 cell (ci, cj) whose exit crossings are tx, ty: 1 on a hit. */
int tf_trace_test_cell(const tf_ray_ctx *r, int ci, int cj, double tx, double ty,
                       tf_trace_cand *best);
/* trace.c's fix_stale_axis (the index on `axis` the flat walk holds at t_event), the reference
 * the walks' settle_half is checked against: the packet kernels assert, in builds with
 * assertions, that each lane's settled index agrees with it. */
int tf_trace_fix_stale(const tf_ray_ctx *r, int axis, int stale, int level, double t_event,
                       int strict);
/* Fill *hit from the winning candidate. */
void tf_trace_finish(const tf_ray_ctx *r, const tf_trace_cand *c, tf_hit *hit);

#endif
