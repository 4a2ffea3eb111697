/* render_internal.h: the renderer's insides, for the renderer itself, its tests and the
 * antialiasing benchmark.  Not part of the interface workers use (that is render.h).
 *
 * The sample lattice: with D = antialias.max_depth and N = 2^D, lattice point (X, Y) (integers,
 * 0 <= X <= width*N, 0 <= Y <= height*N) is sampled at image position
 *     ((X + jx) / N, (Y + jy) / N),  jx, jy in [-1/2, 1/2)
 * where (jx, jy) is tf_hash64 of (seed, X, Y) and nothing else.  Pixel (px, py)'s corners are
 * lattice points (px*N, py*N) .. ((px+1)*N, (py+1)*N); its quads at depth d are spaced N/2^d.
 * A sample's value is therefore the same whichever pixel or rectangle asks for it. */
#ifndef TF_RENDER_INTERNAL_H
#define TF_RENDER_INTERNAL_H

#include <stdint.h>
#include "render/camera.h"
#include "render/render.h"
#include "render/shade.h"

/* TF_AA_MAX_DEPTH (the deepest subdivision) and TF_AA_PROBE_FRACTION (when a quad gets its
 * centre probe): render/constants.h, shared with the OpenCL kernels. */
#include "render/constants.h"

struct tf_renderer {
    const tf_scene *scene;
    const tf_heightfield *hf;
    tf_camera camera;
    tf_shader shader;
    int depth;          /* antialias.max_depth */
    int lattice;        /* N = 2^depth lattice steps per pixel */
    double threshold;   /* antialias.threshold */
    uint64_t jitter_key;/* hash of the scene seed, start of every jitter hash */
    struct tf_sun_strips *sun_strips; /* built for this renderer (NULL: none, or the strips
                                       * kept with the height field, borrowed) */
};

/* Samples helped by the samples below them (trace.h's coherence) in tf_render_rect, whose
 * pixel rows go bottom to top for it: 1 on, 0 off, -1 the default (on for a grid terrain
 * unless TF_COHERENCE=0).  Only the time changes; the tests compare the bits both ways. */
void tf_render_coherence_force(int on);

/* Trace and shade lattice sample (X, Y) (see above). */
void tf_render_lattice_sample(const tf_renderer *r, int64_t X, int64_t Y, tf_sample *out,
                              uint64_t *shadow_rays);

/* Trace and shade the camera ray through image position (x, y). */
void tf_render_point(const tf_renderer *r, double x, double y, tf_sample *out,
                     uint64_t *shadow_rays);

/* The comparison sampler: n x n stratified samples in pixel (px, py), each jittered uniformly
 * within its stratum by a hash of (seed, px, py, stratum); equal weights.  Adds to counts. */
void tf_render_pixel_uniform(const tf_renderer *r, int px, int py, int n, tf_pixel *out,
                             tf_render_counts *counts);

/* A sample channel as the eye sees it, for the subdivision decision: sqrt of the linear value
 * (close to the sRGB curve), clamped to the displayable [0, 1].  A quad's contrast is the widest
 * per-channel range of these over its samples. */
double tf_display_level(double v);

#endif
