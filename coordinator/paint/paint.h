/* paint.h: `terrafarm paint SCENE`, Raypaint (Musgrave A.7.2.4): the scene on the farm's workers
 * as a quad-tree refinement, coarse to fine, shown in the browser as it comes into focus, the
 * area a person points at first; the camera, sun and mist edited in the page restart it.
 * docs/paint.md is the user's guide; painttree.h the policy, paintproto.h the wire. */
#ifndef TF_PAINT_H
#define TF_PAINT_H

#include "coordinator/paint/painttree.h"

typedef struct tf_paint_opts {
    const char *scene_path;
    int width, height;            /* > 0: instead of the scene's [image] size */
    int workers;                  /* forked workers; < 0: one a core */
    const char *listen;           /* networked workers' address, or NULL: forked only */
    const char *secret_file;      /* needed to listen beyond loopback */
    const char *http;             /* the page: HOST:PORT (default 127.0.0.1:0, printed) */
    const char *http_token_file;
    const char *output;           /* write the painted image (OpenEXR) once every pixel is exact */
    const char *save;             /* where the page's Save writes the edited scene */
    const char *farm;             /* a standing farm (HOST:PORT) the page's Submit sends it to */
    const char *farm_token_file;  /* its token; NULL: $TERRAFARM_TOKEN_FILE */
    int pixel;                    /* TF_PIXEL_HALF (default) or TF_PIXEL_FLOAT, as render's */
    tf_paint_params params;
    int until_painted;            /* leave once the first view is painted (and written) */
    int paused;                   /* start with dealing paused (the page resumes it) */
    int wait_workers;             /* deal nothing until this many workers (forked ones too) have
                                   * said hello; once open the gate stays open */
} tf_paint_opts;

void tf_paint_opts_init(tf_paint_opts *o);
/* Run until SIGINT/SIGTERM (or painted, with until_painted).  An exit status: 0; 1 a failure;
 * 2 a usage error (one line each). */
int tf_paint_run(const tf_paint_opts *o);

#endif
