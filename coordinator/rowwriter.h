/* rowwriter.h: the checkpoint writer thread.  The supervisor hands it finished rows, a chunk at a
 * time; it compresses them into the OpenEXR output (exrfile.h) and makes them durable (fsync)
 * at a bounded interval, while the event loop goes on serving workers.  (Compressing a band in
 * the event-loop thread stalled every worker waiting for a reply; see supervisor.c.)
 *
 * Memory is bounded: at most `depth` chunks wait in the queue; tf_rowwriter_put blocks while the
 * queue is full, which slows dealing down to the disk's pace.  The writer thread is the only
 * user of the tf_exr_writer from start to finish. */
#ifndef TF_ROWWRITER_H
#define TF_ROWWRITER_H

#include <stddef.h>

#include "image/exrfile.h"

typedef struct tf_rowwriter tf_rowwriter;

/* Start the thread over w (positioned at its next row).  If preview_png is set, the thread also
 * streams a tone-mapped PNG of every row (so the preview is ready the moment the render is);
 * rows already in the file (a resume) are read back from `existing` first.  NULL with a
 * message on failure (w is then still the caller's). */
tf_rowwriter *tf_rowwriter_start(tf_exr_writer *w, int width, int height, int chunk_rows,
                                 int depth, int fsync_interval_ms, const char *preview_png,
                                 const char *existing, char *err, size_t errlen);
/* Queue nrows (1..chunk_rows) rows of width pixels (copied).  Rows must be whole chunks except
 * the image's last.  0, or -1 once the writer has failed (see tf_rowwriter_error). */
int tf_rowwriter_put(tf_rowwriter *rw, const void *rows, int nrows);
/* Rows the thread has written to the file so far (including those before it started). */
int tf_rowwriter_rows_written(tf_rowwriter *rw);
/* The first write/sync error, copied into buf; returns 1 if there was one. */
int tf_rowwriter_error(tf_rowwriter *rw, char *buf, size_t len);
/* Write what is queued, finish the file (offset table, fsync) and the preview, stop, free.
 * 0 or -1. */
int tf_rowwriter_finish(tf_rowwriter *rw, char *err, size_t errlen);
/* Write what is queued, fsync, close the file as a resumable partial render (no preview),
 * stop, free. */
void tf_rowwriter_abandon(tf_rowwriter *rw);

#endif
