/* local_workers.h: the coordinator's forked local workers (Musgrave's fork model of eval()).
 * Each child inherits the parsed scene and the height field copy-on-write, talks to the
 * coordinator over one end of a socketpair (a trusted connection of the tuple-space server),
 * and never returns.  The pool restarts a worker that dies (up to a limit), gives up on one
 * that says it cannot start, and at the end waits for them to leave. */
#ifndef TF_LOCAL_WORKERS_H
#define TF_LOCAL_WORKERS_H

#include <stdint.h>
#include <sys/types.h>

#include "terrain/heightfield.h"
#include "scene.h"
#include "linda/tsclient.h"
#include "linda/tsserver.h"

/* What a forked worker runs over its end of the socketpair; its exit status.  NULL in the pool
 * means tf_worker_loop (worker/worker.h); Raypaint forks its own (worker/paint_worker.h). */
typedef int (*tf_local_worker_fn)(ts_client *c, const tf_scene *s, const tf_heightfield *hf,
                                  const char *kind, const char *backend);

typedef struct tf_local_workers {
    int n;
    pid_t *pid;        /* 0: not running */
    uint64_t *conn;    /* its connection in srv (gone once it closed its end) */
    int *pidfd;        /* readable once it has exited; -1: none (the kernel has no pidfds) */
    int *respawns;
    int gave_up;       /* workers that could not start or kept dying: not restarted */
    /* what a restart needs */
    ts_server *srv;
    const tf_scene *scene;
    const tf_heightfield *hf;
    const char *backend;
    tf_local_worker_fn loop;
} tf_local_workers;

/* Fork n workers.  0, or -1 with a message in err (those already forked stay in the pool). */
int tf_local_workers_start(tf_local_workers *lw, int n, ts_server *srv, const tf_scene *s,
                           const tf_heightfield *hf, const char *backend, char *err,
                           size_t errlen);
/* The same, each running loop. */
int tf_local_workers_start_loop(tf_local_workers *lw, int n, ts_server *srv, const tf_scene *s,
                                const tf_heightfield *hf, const char *backend,
                                tf_local_worker_fn loop, char *err, size_t errlen);
/* Reap workers that exited; restart those that died (respawn != 0). */
void tf_local_workers_reap(tf_local_workers *lw, int respawn);
/* How many are running. */
int tf_local_workers_alive(const tf_local_workers *lw);
/* After the stop tuple: serve the space for up to grace_s until the workers have left (they
 * need it to read the stop tuple), then kill any left behind.  A worker closes its socket just
 * before it exits, so once none is connected the drain waits for the exits themselves. */
void tf_local_workers_drain(tf_local_workers *lw, double grace_s);
void tf_local_workers_free(tf_local_workers *lw);

#endif
