/* supervisor.h: the farm's supervisor (Musgrave Appendix A), an in-process client of the tuple
 * space that runs in the coordinator's event-loop thread.
 *
 * It deals ("task", ...) tuples in id order, never more than `watermark` tasks beyond the write
 * front (the first task not yet written), so the space holds a bounded number of bytes whatever
 * the image size.  Results -- finished OpenEXR chunks the workers encoded (farmproto.h) -- are
 * checked against their task as they arrive and wait in the space until every task before
 * them is written; then it takes them out in order and hands them to the writer thread
 * (rowwriter.h), which writes the chunks raw and makes them durable at a bounded interval.
 *
 * Faults.  Every take of a task by a connection is a lease (server hook on_take).  When a
 * connection closes (worker killed, link cut, silence timeout) while it holds leases, those
 * tasks go back into the space (tasks_redealt).  A task a worker reports as failed, or loses by
 * dying, counts against that worker; after two failures there the worker is excluded from it
 * (the task tuple carries the exclusion list), and a task that fails on max_task_failures
 * distinct workers, or on every worker when all are the coordinator's forked ones and each is
 * excluded from it, stops the render (rows already written remain valid for --resume).
 * Stragglers: when no fresh task can be dealt and workers are idle, a task held for several
 * mean task times is dealt once more (a few at a time); the first result wins and later ones
 * are dropped.
 *
 * Sequences.  A render is a list of frame jobs (one for a still): each job is a frame to render
 * from its first row (and tile) not yet on disk, into its own output.  Task ids run on across
 * the jobs (job 0's tasks, then job 1's, ...), so the watermark and the write front simply move
 * on from one frame into the next: the next frame's first tasks are dealt while the last ones
 * of the frame before are in flight, and no worker waits at a frame boundary.  Each job's
 * output is opened (hooks.open) when its first task is about to be dealt, unless it was given
 * before (tf_supervisor_set_writer), and finished (hooks.finish) as soon as its last task is
 * written.
 *
 * Affinity (--affinity, affinity.h): with more than one task per band, the space's chooser
 * (tuplespace.h) gives each worker, among the tasks dealt and waiting, one in its own column
 * range first, then one in a neighbouring range, then the lowest id.  It chooses only among
 * what the watermark let in, so the dealing, the watermark and the writes are as without it.
 * With more workers than tasks in a band (ranges narrower than a task) it ranks nothing.
 *
 * Memory is O(watermark): per-task state lives in a ring indexed by task id modulo its size
 * (sized for the largest auto watermark, 4096 workers: a few MB, whatever the image size). */
#ifndef TF_SUPERVISOR_H
#define TF_SUPERVISOR_H

#include <stdint.h>

#include "coordinator/render/events.h"
#include "coordinator/render/rowwriter.h"
#include "coordinator/render/tasks.h"
#include "linda/tsserver.h"
#include "linda/tuplespace.h"

typedef struct tf_supervisor tf_supervisor;

typedef struct tf_worker_stats {
    int64_t id;
    char kind[16];     /* forked | networked */
    char host[64];
    char backend[16];
    uint64_t conn;     /* 0 once disconnected */
    int forked_conn;   /* its connection is a socketpair to a child this process forked */
    char peer[64];     /* the address its connection came from (for messages) */
    int64_t tasks;
    uint64_t rays;
    double busy_s;
    int checked;       /* --verify: passed a spot check (its results may be written) */
    int excluded;      /* --verify: caught lying; every request refused */
    int64_t written;   /* its results handed to the writer */
    int hello;         /* it said hello (counted once by --wait-workers) */
    /* its procedural terrain cache, as its accepted results say (render/counts.h) */
    uint64_t terrain_samples, terrain_hits, terrain_evictions;
    /* affinity.h: its column range [aff_x0, aff_x1) at its latest take of a task (both -1:
     * none, as with one task per band), and its takes by where the task lay for it then
     * (counted with --affinity off too: what FIFO dealing gives) */
    int aff_x0, aff_x1;
    int64_t aff_first, aff_second, aff_elsewhere;
    int64_t aff_switches; /* takes in another range than its take before (locality) */
    int aff_last;         /* the range of its latest take (-1: none) */
} tf_worker_stats;

/* One frame of a sequence (docs/contract.md: "frames"). */
typedef struct tf_frame_stats {
    int frame;                /* -1: a still */
    int rows_resumed, rows_rendered;
    uint64_t rays;            /* primary + shadow rays of this run's results for the frame */
    double start_ms, done_ms; /* first task dealt, last task written (0: not yet) */
} tf_frame_stats;

typedef struct tf_farm_stats {
    int64_t tasks_total, tasks_redealt, tasks_duplicated, results_dropped, task_failures;
    int64_t results_refused;  /* failed the result checks (structure, counts, pixels) */
    double pixel_check_cpu_s; /* the pixel checker's CPU time (resultcheck.h) */
    uint64_t pixels_checked;  /* and the pixels it decoded and scanned */
    /* --verify: checks dealt (a second render of a task), mismatches (a third render decided),
     * workers excluded for lying, and the worker time the checks cost */
    int64_t verify_checks, verify_mismatches, workers_excluded;
    double verify_busy_s;
    double verify_fraction;
    int rows_resumed, rows_rendered;
    uint64_t primary_rays, shadow_rays, external_rays;
    uint64_t terrain_samples; /* procedural terrain samples evaluated, all workers */
    double spp_sum;           /* sum of the spp channel over rendered pixels */
    uint64_t pixels;
    int max_outstanding_tasks;
    int watermark;
    size_t max_tuple_bytes;
    int affinity;             /* horizontal-extent affinity ranked the takes (--affinity on and
                               * more than one task per band) */
    int nworkers;
    tf_worker_stats *workers;
    int nframes;              /* = the number of jobs */
    tf_frame_stats *frames;
    int frames_done;          /* jobs whose output was handed to hooks.finish */
} tf_farm_stats;

typedef struct tf_frame_job {
    int frame;                /* -1 for a still, else the animation frame (task tuples carry it) */
    int first_row;            /* rows [0, first_row) of this frame are already on disk */
    int first_tiles;          /* and, in a tiled file, this many tiles of the next tile row */
} tf_frame_job;

typedef struct tf_frame_hooks {
    void *ctx;
    /* Job `job` is about to be dealt: open its output, positioned after what is on disk.  The
     * writer, or NULL with one line in err (the render stops). */
    tf_rowwriter *(*open)(void *ctx, int job, char *err, size_t errlen);
    /* Every task of job `job` is queued to w: finish the file (w is the callee's from now on).
     * 0, or -1 with one line in err (the render stops). */
    int (*finish)(void *ctx, int job, tf_rowwriter *w, char *err, size_t errlen);
    /* --verify caught a liar whose results job `job` already wrote: close w (the callee's from
     * now on) and reopen the output keeping only its first keep_chunks chunks, through the
     * resume path.  The new writer, or NULL with one line in err (the render stops).  NULL
     * hook: such a liar stops the render. */
    tf_rowwriter *(*rewind)(void *ctx, int job, tf_rowwriter *w, int64_t keep_chunks, char *err,
                            size_t errlen);
} tf_frame_hooks;

typedef struct tf_supervisor_config {
    int width, height;
    int njobs;                /* >= 1 */
    const tf_frame_job *jobs; /* copied */
    tf_frame_hooks hooks;
    tf_exr_layout layout;     /* of the output: what results must carry (farmproto.h) */
    int verify_chunks;        /* --verify-chunks: check the pixels of forked workers' results
                               * too (networked workers' always are: resultcheck.h) */
    int aa_max_depth;         /* the scene's antialiasing depth: bounds a task's rays */
    double verify_fraction;   /* --verify: fraction of tasks rendered twice (0: none) */
    uint64_t verify_seed;     /* which ones (verify.h) */
    tf_task_spec spec;
    int watermark;            /* >= tasks per band (checked); 0 = auto (follows the workers) */
    int expected_workers;     /* auto watermark: workers to plan for before they connect */
    int wait_workers;         /* --wait-workers: deal no task before this many workers said
                               * hello (forked ones count; 0: deal at once) */
    int max_task_failures;
    int affinity;             /* --affinity: rank each worker's takes by its column range
                               * (affinity.h); only where a band has more than one task */
} tf_supervisor_config;

/* NULL with a message on error (e.g. watermark smaller than a band). */
tf_supervisor *tf_supervisor_new(ts_space *space, const tf_supervisor_config *cfg, char *err,
                                 size_t errlen);
void tf_supervisor_free(tf_supervisor *sup);
/* The writer of job `job`'s output, opened by the caller before the first tf_supervisor_step
 * (so the first output's problems show before any worker starts); others open through hooks. */
void tf_supervisor_set_writer(tf_supervisor *sup, int job, tf_rowwriter *writer);
/* Writers of jobs opened and not finished (for an interrupted render to close): fills up to
 * max, returns how many; the supervisor forgets them. */
int tf_supervisor_take_open_writers(tf_supervisor *sup, tf_rowwriter **out, int *jobs, int max);
/* The server the workers use; needed to name peers.  Call once after ts_server_new. */
void tf_supervisor_attach(tf_supervisor *sup, ts_server *srv);
/* Hooks for ts_server_new (ctx = the supervisor). */
ts_server_hooks tf_supervisor_hooks(tf_supervisor *sup);

/* The guard of the worker role (capability.h, coordinator/render/worker_role.c; ctx = the
 * supervisor): checks a worker connection's request against the supervisor's state (its bound
 * worker id, its leases, the task a result answers). */
ts_cap_verdict tf_supervisor_admit(void *ctx, uint64_t conn, int op, int blocking,
                                   const tf_tuple *tuple, char *why, size_t len);

/* Deal, duplicate for stragglers, write, sync.  Call after every server iteration. */
void tf_supervisor_step(tf_supervisor *sup, double now_ms);
/* All rows written (the writer is then finished by the caller). */
int tf_supervisor_done(const tf_supervisor *sup);
/* Results whose pixels are being checked (resultcheck.h): their verdicts come on a later step. */
int tf_supervisor_checks_pending(tf_supervisor *sup);
/* How long the caller's event loop may wait for a message before the next step: 1 ms while
 * verdicts are pending, 50 while a straggler's copy may fall due, else 250 (every wait with
 * nothing arriving costs a sleep and a wake-up: a tenth of the coordinator's CPU at 50 ms). */
int tf_supervisor_wait_ms(tf_supervisor *sup);
/* A fatal farm error (a task failed everywhere, a write error): the message, else NULL. */
const char *tf_supervisor_error(const tf_supervisor *sup);
/* Put the stop tuple out so workers leave. */
void tf_supervisor_stop_workers(tf_supervisor *sup);
/* Rows of job `job` handed to its writer so far (its first_row + rows this run). */
int tf_supervisor_rows_written(const tf_supervisor *sup, int job);
/* The job at the write front (njobs once every job is done). */
int tf_supervisor_write_job(const tf_supervisor *sup);
/* Live statistics (pointers valid until the next call into the supervisor). */
const tf_farm_stats *tf_supervisor_stats(tf_supervisor *sup);
/* Workers that said hello since the start (left or not): --wait-workers counts these. */
int tf_supervisor_joined_workers(const tf_supervisor *sup);
/* Connected workers that said hello and have not left. */
int tf_supervisor_live_workers(const tf_supervisor *sup);


/* ---- for the dashboard (coordinator/dashboard/dashboard.h), in the event-loop thread ---- */

/* One outstanding task (dealt, not yet written). */
typedef struct tf_task_view {
    int64_t id;
    int has_result;          /* done, waiting for the rest of its band */
    int leased;              /* copies held by workers */
    uint64_t holder_conn;    /* one connection holding it, 0 if none */
} tf_task_view;

/* Record joins, leaves, re-deals, failures and exclusions there (NULL: nowhere). */
void tf_supervisor_set_events(tf_supervisor *sup, tf_events *events);
/* Tasks dealt beyond the write front, and the watermark in force (and its largest value). */
int tf_supervisor_outstanding(const tf_supervisor *sup);
int tf_supervisor_watermark(const tf_supervisor *sup);
int tf_supervisor_watermark_max(const tf_supervisor *sup);
/* Fix the watermark from now on (ends the auto watermark): 0, or -1 if out of range. */
int tf_supervisor_set_watermark(tf_supervisor *sup, int watermark, char *err, size_t errlen);
/* Task id's rectangle and frame (-1: a still): 0, or -1 if no task has that id. */
int tf_supervisor_task_rect(const tf_supervisor *sup, int64_t id, tf_rect *rect, int *frame);
/* The task whose result the last on_out hook accepted (passed the result checks and was the
 * first for its task), or -1 if that hook accepted none: for hooks that wrap the supervisor's
 * (dashboard.c) and may only use a result it accepted. */
int64_t tf_supervisor_last_accepted(const tf_supervisor *sup);
/* The write front (tasks below it are on disk) and the outstanding tasks in id order, at most
 * max; returns the count. */
int tf_supervisor_task_views(const tf_supervisor *sup, int64_t *write_task, tf_task_view *out,
                             int max);

#endif
