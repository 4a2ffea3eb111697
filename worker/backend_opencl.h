/* backend_opencl.h: the OpenCL backend (PoCL on the CPU, any OpenCL GPU elsewhere): the same
 * renderer as common/render/render.h, as OpenCL C 1.2 kernels in worker/kernels/. */
#ifndef TF_BACKEND_OPENCL_H
#define TF_BACKEND_OPENCL_H

#include <stddef.h>
#include "terrain/heightfield.h"
#include "render/render.h"
#include "scene.h"

typedef struct tf_cl_backend tf_cl_backend;

/* Choose a platform and device (TERRAFARM_CL_DEVICE overrides: "platform:device" indices or a
 * substring of the device name), build the kernels (showing the build log on failure),
 * upload the height field and its max grids.  NULL with a one-line message on failure. */
tf_cl_backend *tf_cl_backend_new(const tf_scene *s, const tf_heightfield *hf, char *err,
                                 size_t errlen);
int tf_cl_backend_render(tf_cl_backend *b, tf_rect rect, tf_pixel *out, tf_render_counts *counts,
                         char *err, size_t errlen);
void tf_cl_backend_free(tf_cl_backend *b);
/* The chosen device's name, and the seconds clBuildProgram took (a PoCL cache hit is fast). */
const char *tf_cl_backend_device(const tf_cl_backend *b);
double tf_cl_backend_build_seconds(const tf_cl_backend *b);
/* Device seconds spent so far in the corner and the pixel kernels (profiling events). */
void tf_cl_backend_kernel_seconds(const tf_cl_backend *b, double *corners, double *pixels);

#endif
