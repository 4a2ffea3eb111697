/* dashboard.h: the coordinator's web dashboard and JSON API, seen from the event loop.
 *
 * The coordinator opens it before the tuple-space server (so a busy --http port fails before
 * the output is touched), wraps the supervisor's server hooks with tf_dashboard_hooks (to draw
 * results into the live preview and note when each worker was last heard), starts serving once
 * the local workers are forked, and calls tf_dashboard_tick after every event-loop iteration:
 * that publishes a snapshot (snapshot.h) at most every DASH_PUBLISH_MS and carries out the
 * controls queued by HTTP requests (stop, drop a worker, change the watermark).  The HTTP
 * server itself (httpd.h) runs in its own threads and sees only the snapshots. */
#ifndef TF_DASHBOARD_H
#define TF_DASHBOARD_H

#include <stdint.h>

#include "coordinator/render/events.h"
#include "coordinator/dashboard/snapshot.h"
#include "coordinator/render/supervisor.h"
#include "coordinator/render/tasks.h"
#include "linda/tsserver.h"

#define TF_DEFAULT_HTTP "127.0.0.1:7880"

typedef struct tf_dashboard tf_dashboard;

typedef struct tf_dashboard_config {
    const char *http;            /* HOST:PORT, NULL = TF_DEFAULT_HTTP (ephemeral if busy) */
    const char *token_file;      /* --http-token-file, or NULL */
    const uint8_t *farm_key;     /* the farm secret's key (32 bytes), or NULL */
    double t_start;              /* tf_now_s() when the render started */
    const char *scene, *output, *tasks_desc;
    int width, height, first_row;
    const char *resume_exr;      /* a resumed output whose rows [0, first_row) seed the preview */
    int frames_total;            /* frames asked for; -1 for a still */
    int rows_total;              /* rows of the whole render: height, times frames_total */
    int rows_at_start;           /* of those, already on disk (resumed, complete frames) */
    int first_frame;             /* the frame of resume_exr, and the first one rendered (-1: a still) */
} tf_dashboard_config;

/* Check the token rules, load the web files and bind the socket.  NULL with a message in err. */
tf_dashboard *tf_dashboard_open(const tf_dashboard_config *cfg, char *err, size_t errlen);
/* Server hooks that call `inner` (the supervisor's) and then watch the traffic. */
ts_server_hooks tf_dashboard_hooks(tf_dashboard *d, ts_server_hooks inner);
/* The event log, for tf_supervisor_set_events. */
tf_events *tf_dashboard_events(tf_dashboard *d);
/* What to look at and act on; before the first tick. */
void tf_dashboard_attach(tf_dashboard *d, tf_supervisor *sup, ts_server *srv, const tf_tasks *tasks);
/* Start the HTTP threads and log the URL.  0, or -1 with a message. */
int tf_dashboard_serve(tf_dashboard *d, char *err, size_t errlen);
/* A sequence's progress, before tick or end: the frame at the write front (being written) and
 * how many frames are complete on disk. */
void tf_dashboard_frames(tf_dashboard *d, int frame, int frames_done);
/* After each event-loop iteration.  rows_written: rows on disk (over every frame, like
 * rows_total).  Returns 1 if a stop was requested from the dashboard. */
int tf_dashboard_tick(tf_dashboard *d, int rows_written);
/* The render ended: publish its final state (waiting for the lock, this once). */
void tf_dashboard_end(tf_dashboard *d, tf_run_state state, int exit_status, int rows_written);
/* Stop serving and free (NULL is fine). */
void tf_dashboard_close(tf_dashboard *d);
/* Its URL once serving ("" if not, or d is NULL). */
const char *tf_dashboard_url(const tf_dashboard *d);

#endif
