/* backend_opencl.c: NOT IMPLEMENTED YET.  The OpenCL backend is being written (issue: OpenCL
 * worker backend on PoCL); until then --backend opencl fails with a clear message. */
#include "backend_opencl.h"

#include <stdio.h>

tf_cl_backend *tf_cl_backend_new(const tf_scene *s, const tf_heightfield *hf, char *err,
                                 size_t errlen)
{
    (void)s;
    (void)hf;
    snprintf(err, errlen, "the OpenCL backend is not implemented yet; use --backend c");
    return NULL;
}

int tf_cl_backend_render(tf_cl_backend *b, tf_rect rect, tf_pixel *out, tf_render_counts *counts,
                         char *err, size_t errlen)
{
    (void)b;
    (void)rect;
    (void)out;
    (void)counts;
    snprintf(err, errlen, "the OpenCL backend is not implemented yet");
    return -1;
}

void tf_cl_backend_free(tf_cl_backend *b) { (void)b; }
