/* opencl_ahead.c: see opencl_ahead.h.  The thread is joined by whoever takes or drops its
 * device, so the process never forks or exits with it running. */
#include "worker/opencl_ahead.h"

#include <pthread.h>
#include <signal.h>
#include <stdio.h>

static struct {
    int started;        /* a thread was created and not joined yet */
    pthread_t thread;
    tf_cl_backend *cl;  /* what it opened, or NULL with err */
    char err[512];
} ahead;

/* The thread.  The first OpenCL start of a process may have LLVM (PoCL's compiler) install its
 * signal handlers and, on this thread, an alternate signal stack of its own, which the thread's
 * exit would then hand back to whoever set the one before (under ASan: an munmap of LLVM's
 * malloc'd block, a fatal CHECK).  The thread leaves the alternate stack as it found it. */
static void *open_device(void *unused)
{
    (void)unused;
    stack_t before;
    int saved = sigaltstack(NULL, &before) == 0;
    ahead.cl = tf_cl_backend_open(ahead.err, sizeof ahead.err);
    if (saved)
        sigaltstack(&before, NULL);
    return NULL;
}

int tf_opencl_ahead_start(void)
{
    if (ahead.started)
        return -1;
    tf_cl_prepare_environment(); /* its setenv here, not beside the terrain build's getenv */
    ahead.cl = NULL;
    ahead.err[0] = 0;
    if (pthread_create(&ahead.thread, NULL, open_device, NULL) != 0)
        return -1;
    ahead.started = 1;
    return 0;
}

int tf_opencl_ahead_pending(void) { return ahead.started; }

tf_cl_backend *tf_opencl_ahead_take(char *err, size_t errlen)
{
    if (!ahead.started) {
        snprintf(err, errlen, "OpenCL: no device was started ahead");
        return NULL;
    }
    pthread_join(ahead.thread, NULL);
    ahead.started = 0;
    tf_cl_backend *cl = ahead.cl;
    ahead.cl = NULL;
    if (!cl)
        snprintf(err, errlen, "%s", ahead.err);
    return cl;
}

void tf_opencl_ahead_drop(void)
{
    char err[16];
    if (ahead.started)
        tf_cl_backend_free(tf_opencl_ahead_take(err, sizeof err));
}
