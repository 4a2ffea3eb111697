/* render.h: the renderer core that every backend and every worker calls.
 *
 * The one entry point that matters is tf_render_rect: given the scene, its height field and a
 * rectangle of the image, produce the rectangle's pixels.  This is what a worker does with a task.
 *
 * THE DECOMPOSITION INVARIANT (docs/contract.md section 4): a pixel's value depends only on the scene
 * and the pixel's coordinates.  tf_render_rect over any rectangle yields, for each of its pixels,
 * exactly the same bits as over any other rectangle containing that pixel.  Adaptive
 * antialiasing decides subdivision from samples at pixel corners; the corner samples on the
 * rectangle's far edges (one row and one column outside, "external samples") are computed by the
 * rectangle itself, and every sample position (including its jitter) is a function of its
 * position on the global sample lattice and the seed, never of the rectangle. */
#ifndef TF_RENDER_H
#define TF_RENDER_H

#include <stdint.h>
#include "terrain/heightfield.h"
#include "image/pixel.h"
#include "render/counts.h"
#include "scene.h"


typedef struct tf_renderer tf_renderer;

/* Prepare a renderer: camera basis, sun direction, noise tables for textures.  The height field
 * must outlive it.  Returns NULL with a message on error. */
tf_renderer *tf_renderer_new(const tf_scene *s, const tf_heightfield *hf, char *err, size_t errlen);
void tf_renderer_free(tf_renderer *r);

/* What every renderer of scene s over hf would build for itself from the terrain alone (the
 * sun's strips), built once on `threads` threads (0: all online CPUs) and kept with hf
 * (sun_strips.h): a process calls it before it forks its renderers, which then share it.
 * Changes no pixel, only who spends the time; nothing happens where it would not pay. */
void tf_render_prepare(const tf_scene *s, tf_heightfield *hf, int threads);

/* Render `rect` (must lie inside the image) into out[rect.w * rect.h], row-major.
 * Adds to *counts if not NULL.  Thread-safe: a renderer may be shared by threads. */
void tf_render_rect(const tf_renderer *r, tf_rect rect, tf_pixel *out, tf_render_counts *counts);

/* The sample tf_render_rect traces at the top-left corner of pixel (cx, cy), 0 <= cx <= width,
 * 0 <= cy <= height (the image's far edges included): its linear RGB, the same bits whoever
 * asks (Raypaint's coarse views are made of these, worker/paint_worker.h).  Adds to *counts. */
void tf_render_corner(const tf_renderer *r, int cx, int cy, float rgb[3], tf_render_counts *counts);

#endif
