/* backend.c: see backend.h.  The C backend is tf_render_rect itself; the OpenCL backend lives in
 * backend_opencl.c behind the same three calls. */
#include "worker/backend.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "worker/backend_opencl.h"
#include "worker/opencl_ahead.h"
#include "log.h"

enum backend_kind { BACKEND_C, BACKEND_OPENCL };

struct tf_backend {
    enum backend_kind kind;
    tf_renderer *renderer;   /* BACKEND_C */
    tf_cl_backend *cl;       /* BACKEND_OPENCL */
    const tf_heightfield *hf;
};

/* The OpenCL backend: on the device started ahead (opencl_ahead.h) if there is one, else on
 * one opened now. */
static tf_cl_backend *opencl_backend(const tf_scene *s, const tf_heightfield *hf, char *err,
                                     size_t errlen)
{
    if (!tf_opencl_ahead_pending())
        return tf_cl_backend_new(s, hf, err, errlen);
    tf_cl_backend *cl = tf_opencl_ahead_take(err, errlen);
    if (cl && tf_cl_backend_attach(cl, s, hf, err, errlen)) {
        tf_cl_backend_free(cl);
        return NULL;
    }
    if (cl)
        tf_debug("OpenCL: the device started while the terrain was built");
    return cl;
}

tf_backend *tf_backend_new(const char *name, const tf_scene *s, const tf_heightfield *hf,
                           char *err, size_t errlen)
{
    tf_backend *b = calloc(1, sizeof *b);
    if (!b) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    b->hf = hf;
    if (!strcmp(name, "c")) {
        b->kind = BACKEND_C;
        b->renderer = tf_renderer_new(s, hf, err, errlen);
        if (b->renderer)
            return b;
    } else if (!strcmp(name, "opencl") || !strcmp(name, "auto")) {
        b->kind = BACKEND_OPENCL;
        b->cl = opencl_backend(s, hf, err, errlen);
        if (b->cl)
            return b;
        if (!strcmp(name, "auto")) { /* asked for: fall back to C, and say so */
            tf_warn("OpenCL unavailable (%s); this worker uses the C backend", err);
            b->kind = BACKEND_C;
            b->renderer = tf_renderer_new(s, hf, err, errlen);
            if (b->renderer)
                return b;
        }
    } else {
        tf_seterr(err, errlen, "unknown backend '%s' (expected c, opencl or auto)", name);
    }
    free(b);
    return NULL;
}

/* PoCL 3 reads POCL_MAX_PTHREAD_COUNT, PoCL 4 and later POCL_CPU_MAX_CU_COUNT.  A share of
 * one core also picks PoCL's "basic" CPU device, which runs a launch on the thread that waits
 * for it, instead of "pthread" with one thread of its own: the host thread and PoCL's no longer
 * hand every task back and forth (bench/README.md section 33: 480x270 -j 2 0.95x wall,
 * 1920x1080 0.975x; the same pixels). */
void tf_backend_share_cores(const char *name, int processes)
{
    if (!name || !strcmp(name, "c") || processes < 2 || getenv("POCL_MAX_PTHREAD_COUNT") ||
        getenv("POCL_CPU_MAX_CU_COUNT"))
        return;
    int share = tf_thread_count(0) / processes;
    char v[16];
    snprintf(v, sizeof v, "%d", share > 1 ? share : 1);
    setenv("POCL_MAX_PTHREAD_COUNT", v, 1);
    setenv("POCL_CPU_MAX_CU_COUNT", v, 1);
    if (share <= 1 && !getenv("TERRAFARM_CL_DEVICE")) /* a device the user named stands */
        setenv("POCL_DEVICES", "basic", 0);              /* as does their choice of PoCL's */
}

int tf_backend_render(tf_backend *b, tf_rect rect, tf_pixel *out, tf_render_counts *counts,
                      char *err, size_t errlen)
{
    if (b->kind == BACKEND_OPENCL)
        return tf_cl_backend_render(b->cl, rect, out, counts, err, errlen);
    tf_render_rect(b->renderer, rect, out, counts);
    return 0;
}

const char *tf_backend_name(const tf_backend *b) { return b->kind == BACKEND_C ? "c" : "opencl"; }

int tf_backend_set_scene(tf_backend *b, const tf_scene *s, char *err, size_t errlen)
{
    if (b->kind == BACKEND_OPENCL)
        return tf_cl_backend_set_scene(b->cl, s, err, errlen);
    tf_renderer *r = tf_renderer_new(s, b->hf, err, errlen);
    if (!r)
        return -1;
    tf_renderer_free(b->renderer);
    b->renderer = r;
    return 0;
}

void tf_backend_free(tf_backend *b)
{
    if (!b)
        return;
    tf_renderer_free(b->renderer);
    tf_cl_backend_free(b->cl);
    free(b);
}
