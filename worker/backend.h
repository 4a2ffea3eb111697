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
/* Render s from now on: a scene that differs from the backend's only in camera and sun (a
 * frame of the same sequence).  s must outlive its use.  0, or -1 with a message (the backend
 * then still renders its previous scene). */
int tf_backend_set_scene(tf_backend *b, const tf_scene *s, char *err, size_t errlen);
void tf_backend_free(tf_backend *b);

/* Before forking `processes` workers of backend `name` on this machine (render -j N, worker
 * -j N, a farm worker's processes for a job): PoCL runs each kernel on every core, so N OpenCL processes would start N times the
 * cores in threads, contending.  Each gets its share (cores / N, at least 1) through PoCL's
 * environment, inherited by the children, unless the user set PoCL's thread count; a share
 * of one core also selects PoCL's single-threaded "basic" device (POCL_DEVICES), unless the
 * user chose PoCL's devices or named a device (TERRAFARM_CL_DEVICE, --cl-device).  Nothing for
 * the C backend; a GPU device ignores it. */
void tf_backend_share_cores(const char *name, int processes);

#endif
