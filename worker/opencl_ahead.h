/* opencl_ahead.h: an OpenCL device started on a thread while the worker builds its terrain
 * (issue 23: "overlap the build with the terrain").  Starting the OpenCL implementation (PoCL
 * and LLVM, or a GPU driver) and making the program take from 0.1 s to seconds and need no
 * scene; a networked worker's terrain build takes as long, on other threads.
 *
 * One device at a time per process, started by tf_opencl_ahead_start and then either taken by
 * the next OpenCL backend made (worker/backend.c) or dropped.  OpenCL state does not cross a
 * fork: a process that will fork workers must not start one (worker/networked.c starts it only
 * when it serves with one process). */
#ifndef TF_OPENCL_AHEAD_H
#define TF_OPENCL_AHEAD_H

#include <stddef.h>
#include "worker/backend_opencl.h"

/* Start opening the device on a thread (tf_cl_backend_open).  0, or -1 when the thread cannot
 * start or one is already started (the backend then opens its device when it is made). */
int tf_opencl_ahead_start(void);
/* Whether a device was started and not yet taken or dropped. */
int tf_opencl_ahead_pending(void);
/* Wait for the started device and take it: the opened (unattached) backend, or NULL with its
 * failure's one-line message in err.  Only when tf_opencl_ahead_pending(). */
tf_cl_backend *tf_opencl_ahead_take(char *err, size_t errlen);
/* Wait for the started device, if any, and free it. */
void tf_opencl_ahead_drop(void);

#endif
