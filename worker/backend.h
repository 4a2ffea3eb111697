/* backend.h: what renders a worker's tasks.  "c" is the portable C renderer (common/render/render.h)
 * on one core; "opencl" runs the same renderer as OpenCL kernels (backend_opencl.c).  A worker
 * creates its backend after fork (OpenCL contexts must not cross a fork). */
#ifndef TF_BACKEND_H
#define TF_BACKEND_H

#include <stddef.h>
#include "terrain/heightfield.h"
#include "render/render.h"
#include "scene.h"

typedef struct tf_backend tf_backend;

/* name: "c", "opencl", or "auto" (OpenCL if a usable device exists, else C with a warning).
 * NULL with a one-line message on failure. */
tf_backend *tf_backend_new(const char *name, const tf_scene *s, const tf_heightfield *hf,
                           char *err, size_t errlen);
/* Render rect into out (rect.w * rect.h pixels); adds to counts.  0, or -1 with a message. */
int tf_backend_render(tf_backend *b, tf_rect rect, tf_pixel *out, tf_render_counts *counts,
                      char *err, size_t errlen);
const char *tf_backend_name(const tf_backend *b);
void tf_backend_free(tf_backend *b);

#endif
