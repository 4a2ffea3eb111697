/* affinity.h: horizontal-extent affinity (Musgrave, Appendix A.7.2.3.1-2), a dealing policy of
 * the supervisor.  Procedural terrain workers keep what they evaluated; a worker that keeps
 * rendering the same columns of the image re-uses it.  So each connected worker prefers the
 * tasks in its own column range (the image width split evenly among the workers, in worker id
 * order: recomputed whenever one joins or leaves), then those of the neighbouring ranges
 * (second choice), then the lowest task id left (helping the laggard).
 *
 * It only ranks: which task a worker gets among those already dealt into the space
 * (tuplespace.h's chooser).  The dealing, the watermark and the writes in order are untouched,
 * and so are the pixels.  A task belongs to the range holding its centre column. */
#ifndef TF_AFFINITY_H
#define TF_AFFINITY_H

#include <stdint.h>

#include "image/pixel.h"

typedef struct tf_affinity tf_affinity;

typedef enum tf_affinity_choice {
    TF_AFFINITY_FIRST,     /* in the worker's own range */
    TF_AFFINITY_SECOND,    /* in a neighbouring range */
    TF_AFFINITY_ELSEWHERE, /* farther away */
    TF_AFFINITY_NONE       /* the worker has no range (not joined) */
} tf_affinity_choice;

/* For an image `width` pixels wide (>= 1); NULL when out of memory. */
tf_affinity *tf_affinity_new(int width);
void tf_affinity_free(tf_affinity *a);
/* Worker `worker` is connected (again: a no-op) / gone (unknown: a no-op).  0, or -1 when out
 * of memory. */
int tf_affinity_join(tf_affinity *a, int64_t worker);
void tf_affinity_leave(tf_affinity *a, int64_t worker);
/* Workers with a range now. */
int tf_affinity_workers(const tf_affinity *a);
/* Worker's columns [*x0, *x1): 0, or -1 when it has no range. */
int tf_affinity_range(const tf_affinity *a, int64_t worker, int *x0, int *x1);
/* The range (0 .. workers-1, in id order) holding r's centre column; -1 with no workers. */
int tf_affinity_range_of(const tf_affinity *a, tf_rect r);
/* Where a task of rectangle r lies for worker. */
tf_affinity_choice tf_affinity_choice_of(const tf_affinity *a, int64_t worker, tf_rect r);
/* The rank of task `id` (rectangle r) for worker, lower first: 0 for its own range (the
 * oldest dealt is taken), then the neighbours' and then the rest, each by lowest id.  0 for
 * everything when the worker has no range. */
uint64_t tf_affinity_rank(const tf_affinity *a, int64_t worker, tf_rect r, int64_t id);

#endif
