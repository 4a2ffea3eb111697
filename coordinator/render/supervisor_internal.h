/* supervisor_internal.h: what the supervisor's files (supervisor*.c, this folder) share, and
 * nothing outside them includes: its limits, a task's slot in the ring, a lease, a frame job's
 * state, struct tf_supervisor itself (its invariants S1-S9 are stated and asserted in
 * supervisor.c), and the functions one of its files calls in another, named sv_ (each is
 * described where it is defined). */
#ifndef TF_SUPERVISOR_INTERNAL_H
#define TF_SUPERVISOR_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "coordinator/render/affinity.h"
#include "coordinator/render/idmap.h"
#include "coordinator/render/resultcheck.h"
#include "coordinator/render/supervisor.h"
#include "coordinator/render/verify.h"
#include "farmproto.h"

#define MAX_FAILED_WORKERS 8  /* per task: distinct workers that failed it, remembered */
#define MAX_TASK_FAILURES 64  /* per task: failures after which it has failed everywhere */
#define AUTO_WM_MAX_WORKERS 4096 /* auto watermark: workers counted at most (tasks.h) */
#define MAX_DUPLICATES_IN_FLIGHT 2
#define STRAGGLER_FACTOR 3.0   /* a task is a straggler when held this many mean task times */
#define STRAGGLER_MIN_MS 500.0
#define STRAGGLER_SCAN_MS 20.0 /* the straggler scan runs at most this often */
/* How long the event loop may wait for a message (tf_supervisor_wait_ms): while a straggler's
 * copy may fall due, a few times within the shortest patience; otherwise only for what nothing
 * announces (the progress line, the dashboard, reaping children), a few times a second. */
#define SV_WAIT_STRAGGLERS_MS 50
#define SV_WAIT_IDLE_MS 250
#define FAILURES_TO_EXCLUDE 2 /* failures of one task on one worker before it is excluded */

typedef struct task_slot {
    int64_t id;          /* task in this slot, -1 if none */
    int has_result;
    int64_t result_worker; /* whose result was accepted (its tuple waits in the space) */
    int duplicated;      /* a straggler copy was dealt */
    double taken_ms;     /* when a worker first took it (0: not yet) */
    int in_space;        /* task tuples in the space */
    int leased;          /* copies held by workers */
    int nfailed;
    int failures;        /* every failure of it, remembered or not */
    int64_t failed_worker[MAX_FAILED_WORKERS];
    int failed_count[MAX_FAILED_WORKERS];
    /* --verify (see "spot checks"): CHECK_PENDING while its check waits for a second worker,
     * CHECK_SECOND or CHECK_THIRD while a check copy is out; who rendered it first and second,
     * and the digests of their results */
    int check;
    int64_t check_worker[2];
    uint8_t digest[2][TF_DIGEST_BYTES];
    int replacing;       /* the third render sided with the second: its result replaces the first */
    int checking;        /* its result is with the pixel checker (resultcheck.h), out of the
                          * space: 1, or 2 when that result replaces a lying first one */
    int64_t checking_worker; /* whose result that is */
} task_slot;

/* CHECK_SECOND and CHECK_THIRD are also how many of check_worker a check copy excludes. */
enum { CHECK_NONE = 0, CHECK_SECOND = 1, CHECK_THIRD = 2, CHECK_PENDING = 3 };

typedef struct lease {
    uint64_t conn;
    int64_t task;
    double taken_ms;     /* when the copy was handed to the connection */
} lease;

/* One frame job: its tasks, where its ids start, its output. */
typedef struct job_state {
    tf_frame_job job;
    tf_tasks tasks;
    int64_t first_id;        /* global id of its task 0 */
    tf_rowwriter *writer;    /* from open (or tf_supervisor_set_writer) until finish */
    int opened, finished;
    int rows_written;        /* whole rows handed to its writer (plus first_row) */
} job_state;

struct tf_supervisor {
    ts_space *space;
    ts_server *srv;
    job_state *jobs;
    int njobs;
    int write_job;           /* the job of write_task */
    int64_t total_tasks;
    int band_tasks;          /* tasks per band (every frame has the same width and task shape) */
    tf_supervisor_config cfg;
    int64_t write_task, next_deal;
    int ring_size;
    int64_t next_worker_id;  /* the counter tuple's value, put back on every join */
    /* --verify: addresses of excluded liars; no new worker may join from them (a liar that
     * came back under a new id would side with its own lies) */
    char excluded_addr[32][96];
    int nexcluded_addr;
    int auto_watermark;      /* watermark follows the connected workers */
    int watermark;           /* in force now */
    int dups_in_flight;      /* duplicate copies dealt whose task has no result yet */
    double mean_task_ms;     /* running mean of task render times (busy_ns of results) */
    int64_t results_seen;
    task_slot *ring;
    int64_t *written_by;     /* --verify: the worker whose result of each task was written */
    lease *leases;
    int nleases, cap_leases;
    /* Indexes (idmap.h): connection -> its entry in stats.workers; connection -> its lease's
     * index in leases. */
    tf_idmap worker_of_conn, lease_of_conn;
    tf_preview_grid grid;    /* of the output's progress preview */
    tf_resultcheck *checker; /* the pixels of results from workers it did not fork */
    int64_t pending_checks;  /* --verify: tasks in CHECK_PENDING */
    int told_pending;        /* the "only worker" line was logged since the last pending start */
    double last_straggler_scan_ms;
    int stop_sent;
    char error[512];
    tf_farm_stats stats;
    int cap_workers;
    int live_workers;        /* workers connected and announced: kept, not counted per step */
    int joined_workers;      /* workers that said hello, ever (--wait-workers) */
    int wait_workers;        /* --wait-workers: deal nothing before joined_workers reaches it */
    tf_events *events;       /* the dashboard's event log, or NULL */
    int64_t last_accepted;   /* tf_supervisor_last_accepted */
    tf_affinity *affinity;   /* --affinity, when a band has more than one task; else NULL */
};

/* ---- supervisor.c: helpers ---- */
job_state *sv_job_of(const tf_supervisor *s, int64_t id);
tf_rect sv_rect_of(const tf_supervisor *s, int64_t id);
const char *sv_describe_task(const tf_supervisor *s, int64_t id, char *buf, size_t len);
task_slot *sv_slot_of(tf_supervisor *s, int64_t id);
void sv_fail(tf_supervisor *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
tf_worker_stats *sv_worker_by_id(tf_supervisor *s, int64_t id);
tf_worker_stats *sv_worker_by_conn(tf_supervisor *s, uint64_t conn);
const char *sv_peer_name(const tf_supervisor *s, uint64_t conn);
void sv_bind_conn(tf_supervisor *s, tf_worker_stats *w, uint64_t conn);
tf_worker_stats *sv_add_worker(tf_supervisor *s, int64_t id);

/* ---- supervisor_deal.c: leases, dealing, affinity ---- */
int sv_lease_of(const tf_supervisor *s, uint64_t conn);
int sv_find_lease(const tf_supervisor *s, uint64_t conn, int64_t task);
int sv_held_task(const tf_supervisor *s, uint64_t conn, int64_t *task);
int sv_add_lease(tf_supervisor *s, uint64_t conn, int64_t task);
int64_t sv_remove_lease_at(tf_supervisor *s, int i);
void sv_remove_lease(tf_supervisor *s, uint64_t conn, int64_t task);
void sv_task_msg_of(const tf_supervisor *s, const task_slot *t, tf_task_msg *m);
int sv_deal_copy(tf_supervisor *s, task_slot *t);
int sv_open_job(tf_supervisor *s, job_state *j);
void sv_deal_new_tasks(tf_supervisor *s);
void sv_affinity_member(tf_supervisor *s, const tf_worker_stats *w, int joined);
void sv_count_choice(tf_supervisor *s, uint64_t conn, int64_t id);
int sv_start_affinity(tf_supervisor *s, char *err, size_t errlen);

/* ---- supervisor_redeal.c: failures, re-deals, stragglers, the watermark ---- */
int sv_note_failure(tf_supervisor *s, task_slot *t, int64_t worker);
void sv_redeal_if_lost(tf_supervisor *s, task_slot *t);
void sv_withdraw_copies(tf_supervisor *s, task_slot *t);
void sv_deal_duplicate(tf_supervisor *s);
/* Could a straggler's second copy fall due: workers wait for work and nothing fresh can be
 * dealt (the image is all dealt, or the watermark holds dealing back). */
int sv_stragglers_matter(tf_supervisor *s);
void sv_update_watermark(tf_supervisor *s);

/* ---- supervisor_results.c: results and the in-order handoff ---- */
void sv_write_ready_tasks(tf_supervisor *s);
void sv_remove_exact(tf_supervisor *s, const tf_tuple *tuple);
int sv_refuse_result(tf_supervisor *s, tf_result_msg *m, tf_rect r, char *why, size_t len);
void sv_on_result(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple);
void sv_collect_checked(tf_supervisor *s);

/* ---- supervisor_verify.c: spot checks ---- */
void sv_start_check(tf_supervisor *s, task_slot *t, const tf_result_msg *m);
void sv_start_pending_checks(tf_supervisor *s);
int sv_address_excluded(const tf_supervisor *s, const char *peer);
ts_cap_verdict sv_admit_check(tf_supervisor *s, uint64_t conn, task_slot *t,
                              const tf_result_msg *m);

#endif
