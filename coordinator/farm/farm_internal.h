/* farm_internal.h: the standing farm's state, shared by its files: farm.c (life and the main
 * loop: renders started and reaped), farm_jobs.c (what people do: submit, list, control),
 * farm_workers.c (what workers do: ask for a job, report, heartbeat), farm_paint.c (Raypaint
 * jobs and their runs' tokens), farmapi.c (HTTP).
 *
 * One mutex guards everything below; the HTTP threads and the main loop take it for each
 * call.  The database is written before the memory it mirrors changes, so what a caller was
 * told is durable.  Only the main thread forks (a render dies with the thread that forked it,
 * PR_SET_PDEATHSIG): a caller that needs a render started sets `want` and waits on `changed`.
 *
 * Invariants (asserted in make asan, farm_assert_state):
 *   F1 runs[i] belongs to jobs[i]; a run has a pid only while its job's state is queued,
 *      or it is being stopped (stopping != 0);
 *   F2 a worker serves at most one job, and only one that exists;
 *   F3 jobs[i].workers counts exactly the live workers serving it. */
#ifndef TF_FARM_INTERNAL_H
#define TF_FARM_INTERNAL_H

#include <jansson.h>
#include <pthread.h>
#include <stdint.h>
#include <sys/types.h>

#include "coordinator/farm/farm.h"
#include "coordinator/farm/farmdb.h"
#include "farm_keys.h"

#define FARM_MAX_TERRAINS 16
#define FARM_MAX_BARS 16

typedef struct farm_run {
    pid_t pid;          /* the job's render, 0: none */
    int port;
    int want;           /* a worker waits for the render to start */
    int stopping;       /* we signalled it: its exit sets `then` */
    int closing;        /* a worker saw its stop tuple: it is about to exit, done */
    char then[16];      /* the state after a stop: queued, paused or cancelled */
    int failures;       /* renders in a row that failed on their own */
    int workers;        /* live workers serving the job */
    int http_port;      /* the render's dashboard */
    char token[TF_FARM_TOKEN_HEX]; /* its token (from the job's key) */
    double percent;     /* progress from the dashboard; -1: not known yet */
    char submit_token[TF_FARM_TOKEN_HEX]; /* a paint run's, for its page's Submit; "": none */
} farm_run;

typedef struct farm_bar {
    int64_t job;
    int failures;
    int64_t until_ms;   /* barred until then; 0: not barred (yet) */
} farm_bar;

typedef struct farm_worker {
    char name[96];
    char pool[64];
    char tags[256];
    char terrains[FARM_MAX_TERRAINS][65];
    int nterrains;
    int64_t job;        /* serving; 0: idle */
    int64_t seen_ms;
    int64_t sessions, retreats;
    farm_bar bars[FARM_MAX_BARS];
} farm_worker;

typedef struct tf_farm {
    pthread_mutex_t lock;
    pthread_cond_t changed;
    tf_farm_opts o;
    char exe[4096];
    char host[256];            /* where the renders listen, as workers reach it */
    int api_port;              /* where the API listens (a paint run submits there) */
    uint8_t key[32];
    char worker_token[TF_FARM_TOKEN_HEX];
    tf_farmdb *db;
    tf_job *jobs;
    farm_run *runs;
    int njobs, cap;
    farm_worker *workers;
    int nworkers, wcap;
    int64_t assignments;
    volatile int stop;
} tf_farm;

/* The caller of an API request, from its token. */
typedef struct farm_caller {
    char name[64];
    char role[16]; /* worker | submitter | admin | paint (a paint run: may only submit) */
    int64_t paint_job; /* role paint: the paint job whose run it is */
} farm_caller;

/* farm.c */
int farm_job_index(const tf_farm *f, int64_t id);
int farm_set_state(tf_farm *f, int i, const char *state, const char *reason, const char *event);
int farm_append_job(tf_farm *f, const tf_job *j);
void farm_stop_render(tf_farm *f, int i, const char *then);
int farm_after_state(const tf_farm *f, const tf_job *j);
int farm_assert_state(const tf_farm *f);

/* farm_jobs.c: each returns a JSON answer and sets *status (HTTP). */
json_t *farm_submit(tf_farm *f, const farm_caller *who, json_t *req, int *status);
json_t *farm_list(tf_farm *f, const farm_caller *who, int *status);
json_t *farm_show(tf_farm *f, const farm_caller *who, int64_t id, int *status);
json_t *farm_control(tf_farm *f, const farm_caller *who, int64_t id, const char *action,
                     json_t *req, int *status);
/* The output file of job id for its owner or an admin: a sequence's frame `frame` (the text of
 * the request's ?frame=, NULL: frame 0; a still ignores it).  0 or an HTTP status with a message
 * in err (400 for a frame that is not a number >= 0). */
int farm_output_path(tf_farm *f, const farm_caller *who, int64_t id, const char *frame,
                     char *path, size_t n, char *err, size_t errlen);
json_t *farm_error(int *status, int code, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* farm_workers.c */
json_t *farm_worker_next(tf_farm *f, const farm_caller *who, json_t *req, int *status);
json_t *farm_worker_heartbeat(tf_farm *f, const farm_caller *who, json_t *req, int *status);
json_t *farm_workers_json(tf_farm *f);
void farm_expire_workers(tf_farm *f, int64_t now_ms);

/* farm_paint.c */
/* POST /api/jobs/ID/paint on job i (who may see it): a paint job of its scene, queued. */
json_t *farm_paint_from_job(tf_farm *f, const farm_caller *who, int i, json_t *req, int *status);
/* 1 and *who (the job's owner, role "paint") when token is a live paint run's; takes the lock. */
int farm_paint_caller(tf_farm *f, const char *token, farm_caller *who);
/* The options (a JSON array's text) a paint job keeps of a render's, malloc'd. */
char *farm_paint_options(const char *options);
/* 0 when opts (a checked options array) holds only what a paint job takes, else -1 and err. */
int farm_paint_options_ok(json_t *opts, char *err, size_t errlen);

/* farmapi.c */
typedef struct farm_http farm_http;
/* Serve the API on listen; *port: the port bound (listen may say 0). */
farm_http *farm_http_start(tf_farm *f, const char *listen, int *port, char *err, size_t errlen);
void farm_http_stop(farm_http *h);

#endif
