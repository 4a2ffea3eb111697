/* tasks.h: screen-space decomposition of a render into tasks (Musgrave Appendix A 7.2.1):
 * scanline blocks of K rows or near-square postage stamps of W x H pixels.
 *
 * Tasks are numbered in write order: band by band from the top (the first row still to be
 * rendered), left to right within a band.  A band is a horizontal strip as tall as one task;
 * the coordinator can write a band's rows once every task of the band has its result.  Task
 * ids are therefore also the dealing order, which keeps the watermark simple: the tasks dealt
 * and not yet written always form one contiguous range of ids. */
#ifndef TF_TASKS_H
#define TF_TASKS_H

#include "render/render.h"

enum tf_task_shape { TF_TASKS_ROWS, TF_TASKS_STAMPS };

typedef struct tf_task_spec {
    enum tf_task_shape shape;
    int w, h;   /* stamps: w x h pixels; rows: w = image width, h = K */
} tf_task_spec;

typedef struct tf_tasks {
    int width, height;  /* image */
    int first_row;      /* rows before it are already on disk (resume) */
    int skip;           /* tasks of the first band already on disk (a tiled resume) */
    int tw, th;         /* task size (the last column / band may be smaller) */
    int cols, bands;    /* tasks per band, number of bands */
    int count;          /* cols * bands - skip */
} tf_tasks;

/* Parse "rows:K" or "stamps:WxH".  Returns 0, or -1 with a one-line message. */
int tf_task_spec_parse(const char *text, tf_task_spec *spec, char *err, size_t errlen);
/* Default: near-square stamps sized so each worker gets many tasks (load balance) while the
 * border overhead (external samples) stays small. */
tf_task_spec tf_task_spec_default(int width, int height, int workers);
/* The auto watermark's tasks beyond one band for `workers` workers (0 for none): as many as
 * hold TF_AUTO_AHEAD_PIXELS pixels in all (their results are what the coordinator keeps), but
 * at least TF_AUTO_AHEAD_MIN and at most TF_AUTO_AHEAD_MAX a worker.  Nondecreasing in
 * workers, so a ring sized for the most workers holds the watermark of any fewer. */
#define TF_AUTO_AHEAD_MIN 3
#define TF_AUTO_AHEAD_MAX 16
#define TF_AUTO_AHEAD_PIXELS (4L << 20)
int tf_tasks_auto_ahead(const tf_tasks *t, int workers);

void tf_tasks_init(tf_tasks *t, int width, int height, int first_row, tf_task_spec spec);
/* A resume of a tiled file that holds the first n tiles of the first band: those tasks are not
 * dealt (ids start after them). */
void tf_tasks_skip(tf_tasks *t, int n);
/* Rectangle of task id (0 <= id < count). */
tf_rect tf_task_rect(const tf_tasks *t, int id);
/* A band's rows [y0, y0 + rows). */
void tf_band_rows(const tf_tasks *t, int band, int *y0, int *rows);

#endif
