/* rowwriter.h: the checkpoint writer thread.  The supervisor hands it results that passed their
 * checks, in file order, as the result tuples themselves (moved, not copied); the thread writes
 * their packed chunks into the OpenEXR output with OpenEXRCore's raw chunk writes (exrfile.h:
 * tf_exr_write_chunk -- no pixel is decoded or compressed here), makes them durable (fsync) at a
 * bounded interval, and stitches each result's preview share into the progress preview, which
 * it rewrites (PNG, atomic rename) every few seconds while the render runs and once at the end.
 * The event loop meanwhile goes on serving workers.  The thread is woken once `batch` results
 * are queued, not for each (a wake-up is a system call and a context switch of each thread);
 * fewer wait at most half the fsync interval, on the thread's own timer.  What it has written
 * goes out in one pwritev for as many results as came together.
 *
 * Memory is bounded: at most `depth` results wait in the queue; tf_rowwriter_put blocks while the
 * queue is full, which slows dealing down to the disk's pace.  The preview is the decimated
 * image (exrlayout.h: at most TF_PREVIEW_MAX_SIDE a side, 3 MB), whatever the image size.  The
 * writer thread is the only user of the tf_exr_writer from start to finish. */
#ifndef TF_ROWWRITER_H
#define TF_ROWWRITER_H

#include <stddef.h>

#include "image/exrfile.h"
#include "linda/tuple.h"

typedef struct tf_rowwriter tf_rowwriter;

typedef struct tf_rowwriter_config {
    int depth;                /* results the queue holds */
    int fsync_interval_ms;    /* at most this long between durable checkpoints */
    const char *preview_png;  /* or NULL: no preview */
    int preview_interval_ms;  /* rewrite the preview at most this often while rendering */
    const char *existing;     /* a resume: the output, whose verified chunks fill the preview */
    int batch;                /* results queued before the thread is woken (<= 1: each one);
                               * fewer wait at most half the fsync interval */
} tf_rowwriter_config;

/* Start the thread over w (positioned at its next chunk).  NULL with a message on failure (w is
 * then still the caller's). */
tf_rowwriter *tf_rowwriter_start(tf_exr_writer *w, const tf_exr_layout *layout,
                                 const tf_rowwriter_config *cfg, char *err, size_t errlen);
/* Queue a checked result tuple (farmproto.h) whose chunks are the next in file order; its
 * contents are moved out of *result.  0, or -1 once the writer has failed. */
int tf_rowwriter_put(tf_rowwriter *rw, tf_tuple *result);
/* The first write/sync error, copied into buf; returns 1 if there was one. */
int tf_rowwriter_error(tf_rowwriter *rw, char *buf, size_t len);
/* Write what is queued, finish the file (offset table, fsync) and the preview, stop, free.
 * 0 or -1. */
int tf_rowwriter_finish(tf_rowwriter *rw, char *err, size_t errlen);
/* Write what is queued, fsync, close the file as a resumable partial render (the preview
 * shows what is on disk), stop, free. */
void tf_rowwriter_abandon(tf_rowwriter *rw);

#endif
