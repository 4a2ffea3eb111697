/* snapshot.h: what the dashboard's HTTP threads may see of a render, and the one place the two
 * sides meet.
 *
 * The coordinator is single-threaded around its event loop; the HTTP server (httpd.h) runs in
 * threads of its own and must never touch the supervisor, the tuple space or the server.  So
 * the event loop copies the state it wants to show into a fresh tf_snapshot (dashboard.c, at
 * most every ~200 ms) and publishes it in the hub; HTTP threads take a reference to the current
 * snapshot, read it at leisure, and release it.  Snapshots are immutable once published.  While
 * no HTTP thread has come by for a while, snapshots are partial (counters only: no preview,
 * events or lists, the copies that cost); a reader that finds a partial one asks for a full
 * one and waits for the next publish (tf_hub_acquire). 
 * Controls flow the other way through the hub's small command queue, which the event loop
 * drains.  The event loop only ever *tries* the hub's lock (a busy lock means: publish next
 * time), so no HTTP request can stall the render; HTTP threads hold it only to move pointers
 * and commands, never while formatting or sending. */
#ifndef TF_SNAPSHOT_H
#define TF_SNAPSHOT_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>

#include "coordinator/render/events.h"
#include "image/pixel.h"

typedef enum tf_run_state {
    TF_RUN_STARTING,     /* terrain being built, workers being started */
    TF_RUN_RENDERING,
    TF_RUN_FINISHED,     /* every row on disk */
    TF_RUN_FAILED,
    TF_RUN_INTERRUPTED,  /* signal or stop from the dashboard: --resume continues */
} tf_run_state;

typedef enum tf_worker_state { TF_WS_IDLE, TF_WS_BUSY, TF_WS_LEFT, TF_WS_DROPPED } tf_worker_state;

typedef struct tf_snap_worker {
    int64_t id;
    char kind[16], host[64], backend[16];
    int64_t tasks;
    uint64_t rays;
    double busy_s;
    double since_s;        /* joined, seconds since the render started (-1: unknown) */
    double last_heard_s;   /* last message from it, same clock (-1: unknown) */
    tf_worker_state state;
    int64_t holding;       /* a task it holds, -1 if none */
} tf_snap_worker;

typedef struct tf_snap_task {  /* an outstanding task (dealt, not yet written) */
    int64_t id;
    tf_rect rect;
    int frame;             /* -1: a still */
    int done;              /* has its result, waits for its band */
    int64_t worker;        /* a worker holding it, -1 if none (waiting in the space) */
} tf_snap_task;

typedef struct tf_snap_sample {  /* one point of the throughput history */
    double t;              /* seconds since the render started */
    uint64_t rays;         /* rays so far */
    double busy_s;         /* sum of the workers' busy time so far */
    int rows;              /* rows written */
    int workers;           /* workers connected */
} tf_snap_sample;

typedef struct tf_snapshot {
    int refs;                      /* guarded by the hub's lock */
    uint64_t version;
    tf_run_state state;
    int exit_status;               /* -1 while running */
    char scene[512], output[1024], tasks_desc[64];
    int width, height;
    int frame, frames_total;       /* the frame being written, frames asked for (-1, -1: a still) */
    int frames_done;               /* frames complete on disk (-1 for a still) */
    int preview_frame;             /* the frame the preview shows (-1: a still, or none yet) */
    int rows_written, rows_at_start; /* over the whole render (every frame's rows) */
    int rows_total;                /* height, times frames_total in a sequence */
    double start_unix_s, elapsed_s, eta_s; /* eta_s < 0: unknown */
    double rays_per_s, rays_per_s_recent;
    uint64_t rays_total;
    double spp_avg;
    int watermark, watermark_min, watermark_max, outstanding, max_outstanding;
    int64_t tasks_total, tasks_written, tasks_redealt, task_failures;
    int task_w, task_h, task_cols, first_row; /* the task grid (tasks.h) */
    int live_workers;
    int joined_workers;            /* workers that said hello (--wait-workers counts these) */
    int nworkers;
    tf_snap_worker *workers;
    int ntasks;
    tf_snap_task *tasks;
    int nevents;                   /* the newest events, oldest first */
    tf_event *events;
    int nsamples;
    tf_snap_sample *samples;
    int preview_w, preview_h;
    int64_t preview_stamps;
    uint64_t preview_version;
    uint8_t *preview_rgba;         /* preview_w * preview_h * 4 */
    int partial;                   /* taken while nobody watched: no events, no preview */
} tf_snapshot;

typedef enum tf_command_kind { TF_CMD_STOP, TF_CMD_DROP_WORKER, TF_CMD_WATERMARK } tf_command_kind;
typedef struct tf_command {
    tf_command_kind kind;
    int64_t arg;                   /* worker id, or the watermark */
} tf_command;

#define TF_HUB_COMMANDS 16

typedef struct tf_dash_hub {
    pthread_mutex_t lock;
    pthread_cond_t changed;        /* broadcast after each publish and on stopping */
    tf_snapshot *current;
    int stopping;
    tf_command cmds[TF_HUB_COMMANDS];
    int ncmds;
    double last_read_s;            /* tf_now_s of the last acquire or wait (under lock) */
    atomic_int want_full;          /* a reader waits for a snapshot that is not partial */
} tf_dash_hub;

void tf_snapshot_free(tf_snapshot *s);

int tf_hub_init(tf_dash_hub *hub);
void tf_hub_destroy(tf_dash_hub *hub);
/* Event loop: make snap current.  With block = 0 only if the lock is free at once.  Returns 1
 * if published (the hub owns snap), 0 if not (the caller still owns it). */
int tf_hub_publish(tf_dash_hub *hub, tf_snapshot *snap, int block);
/* Event loop: take up to max queued commands, only if the lock is free at once. */
int tf_hub_take_commands(tf_dash_hub *hub, tf_command *out, int max);
/* HTTP side: a reference to the current snapshot (NULL before the first publish).  If it is
 * partial (nobody had been watching), asks the event loop for a full one and waits for it,
 * at most TF_HUB_FULL_WAIT_MS. */
tf_snapshot *tf_hub_acquire(tf_dash_hub *hub);
#define TF_HUB_FULL_WAIT_MS 500
/* Event loop: 2 if a reader waits for a full snapshot now (the request is cleared: the
 * caller publishes one), 1 if a reader came by in the last `window_s` seconds, else 0. */
int tf_hub_watched(tf_dash_hub *hub, double window_s);
void tf_hub_release(tf_dash_hub *hub, tf_snapshot *snap);
/* HTTP side: wait up to timeout_ms for a snapshot newer than `version` (or for stopping);
 * returns 1 if there is one, 0 on timeout, -1 when stopping. */
int tf_hub_wait(tf_dash_hub *hub, uint64_t version, int timeout_ms);
/* HTTP side: queue a command; 0, or -1 if the queue is full. */
int tf_hub_push_command(tf_dash_hub *hub, tf_command cmd);
/* Wake every waiter for good (before the HTTP server stops). */
void tf_hub_stop(tf_dash_hub *hub);

const char *tf_run_state_name(tf_run_state s);
const char *tf_worker_state_name(tf_worker_state s);

#endif
