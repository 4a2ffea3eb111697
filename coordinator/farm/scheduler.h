/* scheduler.h: the standing farm's policy, as pure functions over a snapshot of its jobs: which
 * job an idle worker serves next, and whether a busy worker should leave its job for another.
 *
 * A worker may serve a job when the job is queued (not paused, finished or cancelled) and its
 * render is not closing (a worker saw its stop tuple; the process is about to exit), the job
 * it waits for (--after) is done, its pool is the worker's, every tag it asks for is one of
 * the worker's, and the worker is not barred from it (too many failed sessions lately).
 * Among those: the highest priority first; then fair share, the fewest workers, counting a
 * terrain the worker would have to build as one worker more (so it goes where its cached
 * terrain is unless that leaves another job of the same priority two workers behind); then
 * the oldest job.  A busy worker leaves when its job is no longer servable or a servable job
 * of higher priority exists (priority preempts at once; fair share among equals is restored as
 * workers finish, not by preemption). */
#ifndef TF_SCHEDULER_H
#define TF_SCHEDULER_H

#include <stdint.h>

#include "coordinator/farm/farmdb.h"

typedef struct tf_sched_job {
    const tf_job *job;
    int workers;     /* workers serving it now */
    int after_state; /* 0: no dependency or it is done; 1: waiting for it; 2: it failed */
    int closing;     /* its render has finished (a worker saw the stop tuple): no new workers */
} tf_sched_job;

typedef struct tf_sched_worker {
    const char *pool;             /* "" counts as "default" */
    const char *tags;             /* comma list */
    const char *const *terrains;  /* terrain keys it holds */
    int nterrains;
    /* 1 when the worker is barred from job id now; NULL: never */
    int (*barred)(void *ctx, int64_t job);
    void *ctx;
} tf_sched_worker;

/* 1 when w may serve j now. */
int tf_sched_servable(const tf_sched_job *j, const tf_sched_worker *w);
/* The index of the job w serves next, or -1 when none. */
int tf_sched_pick(const tf_sched_job *jobs, int n, const tf_sched_worker *w);
/* 1 when w, serving jobs[current], should leave it now. */
int tf_sched_should_leave(const tf_sched_job *jobs, int n, int current,
                          const tf_sched_worker *w);
/* 1 when every tag of the comma list `need` is in the comma list `have`. */
int tf_sched_tags_cover(const char *have, const char *need);

#endif
