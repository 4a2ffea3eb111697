/* farm_worker.h: a worker that stays (`terrafarm worker --connect http://FARM`): it asks a
 * standing farm (coordinator/farm/farm.h) which job to serve, joins that job's render with N
 * processes sharing the job's terrain copy-on-write (painting, when the job is a paint job:
 * worker/paint_worker.h), and when the job ends (or the farm sends
 * it away, or its machine's owner comes back) asks again.  It keeps the terrains of recent jobs
 * (terrain_shelf.h), so moving between jobs it has served costs no rebuild.
 *
 * Piranha (Musgrave A.7.2.3.3), with an owner watch: it asks for work only while the owner is
 * away, and while serving samples the owner every few tens of milliseconds; when the owner
 * returns it retreats at once: its processes are killed, the tasks they held are dealt again
 * by the job's render (it sees their connections close), and the worker waits until the owner
 * has been away for the idle time before it asks for work again.  Killing rather than freezing
 * gives the machine back entirely (memory and CPU) and lets the farm finish the task elsewhere
 * now; what is lost is at most one task per process. */
#ifndef TF_FARM_WORKER_H
#define TF_FARM_WORKER_H

#include <stddef.h>

/* Is the machine's owner here?  1 present, 0 away, -1 error (why says). */
typedef struct tf_owner_watch {
    int (*present)(void *ctx, char *why, size_t whylen);
    void *ctx;
    int interval_ms;   /* sampling period while serving (default 50) */
    int idle_after_ms; /* the owner must be away this long before work is taken */
} tf_owner_watch;

typedef struct tf_farm_worker_opts {
    const char *farm;          /* HOST:PORT of the farm's API */
    const char *secret_file;   /* the farm secret */
    const char *pool;          /* NULL: default */
    const char *tags;          /* comma list, or NULL */
    const char *name;          /* NULL: HOST:PID */
    int processes;             /* per job; 0 = online CPUs */
    const char *backend;
    size_t terrain_cache;      /* procedural cache per process; 0 = default */
    size_t terrain_memory;     /* kept terrains; 0 = an eighth of memory */
    const tf_owner_watch *owner; /* NULL: serve whenever there is work */
    int max_sessions;          /* leave after this many job sessions; 0 = never */
    /* Simulated (simulate.h): each session joins the job's render as `processes` synthetic
     * workers sleeping the cost map's modelled costs instead of tracing; NULL: real ones. */
    const char *simulate_model;
    double pixel_us;
    const char *payloads;      /* their results: this recording's chunks (payloads.h), or NULL */
} tf_farm_worker_opts;

/* Serve the farm until SIGINT/SIGTERM (or max_sessions).  Returns the exit status. */
int tf_farm_worker_run(const tf_farm_worker_opts *o);

#endif
