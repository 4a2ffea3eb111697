/* supervisor.c: see supervisor.h for what it does; this comment is about how.
 *
 * Task ids run 0 .. total_tasks-1 in write order: job 0's tasks (tasks.h numbering, offset by
 * the job's first_id), then job 1's, and so on.  Three cursors move only forward:
 *     write_task <= next_deal <= total_tasks
 * Tasks below write_task are on disk; tasks in [write_task, next_deal) are "outstanding"
 * (dealt, in the space, leased to a worker, or done and waiting for their band); tasks from
 * next_deal on have not been dealt.  INVARIANTS (asserted clause by clause by
 * assert_supervisor_state() in debug builds, `make asan`):
 *   S1. 0 <= write_task <= next_deal <= total_tasks, and write_job is the job of write_task
 *       (njobs once everything is written); jobs before it are finished.
 *   S2. next_deal - write_task <= ring_size, and the slot of every outstanding task id is
 *       ring[id % ring_size] with ring[...].id == id, so the ring holds every outstanding task.
 *   S3. A slot's counts are never negative: in_space >= 0, leased >= 0.
 *   S4. Every lease names a dealt task (0 <= task < next_deal; a straggler may still hold a
 *       copy of a task already written), and for an outstanding task the number of leases
 *       naming it never exceeds its slot's `leased`.
 *   S5. A job's rows_written <= height, and it only grows, except in a rewind (--verify takes
 *       back what a caught liar wrote, "spot checks"), which moves write_task back too.
 *   S6. live_workers is the number of joined workers (the id bound to a connection when it took
 *       the counter, then announced) whose connection is open.
 *   S7. pending_checks is the number of outstanding tasks in CHECK_PENDING, and each of those
 *       has its result (--verify: a check waiting for a second worker).
 *   S8. The indexes agree with what they index: a connection holds at most one lease, and
 *       lease_of_conn names it; worker_of_conn names the entry of every open worker connection.
 *   S9. Liveness: every outstanding task is in the space (in_space > 0), held under a lease of
 *       an open connection (leased > 0), with the pixel checker (checking), or has its result
 *       and awaits nothing that must be dealt (no check, or a check pending a second worker);
 *       a check copy that is out is in the space or held.  So the write front always moves
 *       once workers work: no copy is ever dropped without being dealt again (a check copy
 *       answered or failed by a worker it excludes, too).  Not while the render is failing.
 *
 * The watermark is the user's --watermark, or (auto) one band of tasks plus three per worker,
 * following the number of workers connected: workers may join at any time.
 *
 * A task's copies: `in_space` task tuples sit in the space, `leased` are held by workers (one
 * lease record each in `leases`).  When both reach zero before a result arrived, the task is
 * lost and is dealt again.  A result for a task that already has one, or is written, is
 * removed from the space and dropped.
 *
 * Results.  A result's chunks (farmproto.h) are checked when it arrives (on_out): a lease held
 * by this connection, then tf_result_check's structure against the task (no per-pixel work),
 * and with --verify-chunks that every chunk decodes.  A refused result is removed from the
 * space, counts as a failure of its worker, and the task is dealt again; nothing of it reaches
 * the file.  An accepted result stays in the space until every task before it is written; then
 * it is taken out and its tuple handed, as is, to the writer thread (rowwriter.h), which writes
 * its packed chunks raw.  Tasks are written one by one in id order, which is the file's chunk
 * order (a tile, or a block of rows). */
#include "coordinator/render/supervisor.h"
#include "clock.h"

#include <assert.h>
#include <inttypes.h>
#include <math.h>
#include <sodium.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "coordinator/render/affinity.h"
#include "coordinator/render/events.h"
#include "farmproto.h"
#include "coordinator/render/idmap.h"
#include "coordinator/render/resultcheck.h"
#include "coordinator/render/verify.h"
#include "log.h"

#define MAX_FAILED_WORKERS 8  /* per task: distinct workers that failed it, remembered */
#define MAX_TASK_FAILURES 64  /* per task: failures after which it has failed everywhere */
#define AUTO_WM_PER_WORKER 3   /* auto watermark: tasks dealt ahead per worker, beyond a band */
#define AUTO_WM_MAX_WORKERS 4096
#define MAX_DUPLICATES_IN_FLIGHT 2
#define STRAGGLER_FACTOR 3.0   /* a task is a straggler when held this many mean task times */
#define STRAGGLER_MIN_MS 500.0
#define STRAGGLER_SCAN_MS 20.0 /* the straggler scan runs at most this often */
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

/* ---- invariants (S1-S9 above), asserted clause by clause in debug builds ------------------
 * Each assert names the clause it checks, as SQLite's assert_pager_state does, so a failure
 * says which promise broke.  Called at the start and end of every step (the supervisor's scan);
 * inside a hook the counts may be mid-update (see on_take). */
#ifndef NDEBUG
static void assert_job_cursors(const tf_supervisor *s)
{
    assert(0 <= s->write_task && s->write_task <= s->next_deal &&
           s->next_deal <= s->total_tasks && "S1: write_task <= next_deal <= total_tasks");
    if (s->write_job < s->njobs) {
        const job_state *j = &s->jobs[s->write_job];
        assert((j->tasks.count == 0 ? s->write_task == j->first_id
                                    : s->write_task >= j->first_id &&
                                          s->write_task < j->first_id + j->tasks.count) &&
               "S1: write_job is the job of write_task");
    } else {
        assert(s->write_task == s->total_tasks && "S1: every task written once jobs are");
    }
    for (int j = 0; j < s->write_job && j < s->njobs; j++)
        assert(s->jobs[j].finished && "S1: jobs before write_job are finished");
    for (int j = 0; j < s->njobs; j++)
        assert(s->jobs[j].rows_written <= s->cfg.height && "S5: rows_written <= height");
}

/* S9 for one outstanding task: on disk is excluded (it is outstanding), so it is in the space,
 * held, with the checker, or has its result and waits for nothing dealt (no check, or a check
 * pending a second worker); a check copy that is out is in the space or held. */
static int task_alive(const task_slot *t)
{
    if (t->in_space > 0 || t->leased > 0 || t->checking)
        return 1;
    return t->has_result && (t->check == CHECK_NONE || t->check == CHECK_PENDING);
}

static void assert_ring(const tf_supervisor *s)
{
    int64_t pending = 0;
    assert(s->next_deal - s->write_task <= s->ring_size && "S2: outstanding tasks fit the ring");
    for (int64_t id = s->write_task; id < s->next_deal; id++) {
        const task_slot *t = &s->ring[id % s->ring_size];
        assert(t->id == id && "S2: the ring holds every outstanding task in its slot");
        assert(t->in_space >= 0 && t->leased >= 0 && "S3: copy counts are never negative");
        assert((t->check != CHECK_PENDING || t->has_result) &&
               "S7: a pending check has its result");
        assert((s->error[0] || task_alive(t)) &&
               "S9: an outstanding task is in the space, held, being checked, or waits only "
               "for a second worker");
        pending += t->check == CHECK_PENDING;
    }
    assert(pending == s->pending_checks && "S7: pending_checks counts the pending checks");
}

static void assert_leases(const tf_supervisor *s)
{
    for (int i = 0; i < s->nleases; i++) {
        int64_t task = s->leases[i].task, v;
        assert(task >= 0 && task < s->next_deal && "S4: every lease names a dealt task");
        if (task >= s->write_task) {
            int n = 0;
            for (int j = 0; j < s->nleases; j++)
                n += s->leases[j].task == task;
            assert(n <= s->ring[task % s->ring_size].leased &&
                   "S4: leases naming a task <= its slot's leased");
        }
        assert(tf_idmap_get(&s->lease_of_conn, s->leases[i].conn, &v) && v == i &&
               "S8: lease_of_conn names each connection's one lease");
    }
    assert(s->lease_of_conn.n == (size_t)s->nleases && "S8: one index entry per lease");
}

static void assert_workers(const tf_supervisor *s)
{
    int live = 0;
    for (int i = 0; i < s->stats.nworkers; i++) {
        const tf_worker_stats *w = &s->stats.workers[i];
        int64_t v;
        live += w->conn != 0;
        assert((!w->conn || (tf_idmap_get(&s->worker_of_conn, w->conn, &v) &&
                             s->stats.workers[v].conn == w->conn)) &&
               "S8: worker_of_conn names every open worker connection's entry");
    }
    assert(live == s->live_workers && "S6: live_workers counts the open worker connections");
}

static void assert_supervisor_state(const tf_supervisor *s)
{
    assert_job_cursors(s);
    assert_ring(s);
    assert_leases(s);
    assert_workers(s);
}
#else
#define assert_supervisor_state(s) ((void)0)
#endif

/* ---- small helpers ---------------------------------------------------------------------- */

/* The job holding global task id (0 <= id < total_tasks), by binary search (a job with no
 * tasks shares its first_id with the next one, which is the one returned). */
static job_state *job_of(const tf_supervisor *s, int64_t id)
{
    int lo = 0, hi = s->njobs - 1;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (s->jobs[mid].first_id <= id)
            lo = mid;
        else
            hi = mid - 1;
    }
    return &s->jobs[lo];
}

static tf_rect rect_of(const tf_supervisor *s, int64_t id)
{
    const job_state *j = job_of(s, id);
    return tf_task_rect(&j->tasks, (int)(id - j->first_id));
}

/* "task 12 (64x64 at 0,128)" or, in a sequence, "task 12 (frame 3, 64x64 at 0,128)" */
static const char *describe_task(const tf_supervisor *s, int64_t id, char *buf, size_t len)
{
    const job_state *j = job_of(s, id);
    tf_rect r = tf_task_rect(&j->tasks, (int)(id - j->first_id));
    if (j->job.frame >= 0)
        snprintf(buf, len, "task %" PRId64 " (frame %d, %dx%d at %d,%d)", id, j->job.frame, r.w,
                 r.h, r.x, r.y);
    else
        snprintf(buf, len, "task %" PRId64 " (%dx%d at %d,%d)", id, r.w, r.h, r.x, r.y);
    return buf;
}

static task_slot *slot_of(tf_supervisor *s, int64_t id)
{
    if (id < s->write_task || id >= s->next_deal)
        return NULL;
    task_slot *t = &s->ring[id % s->ring_size];
    return t->id == id ? t : NULL;
}

static void fail(tf_supervisor *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void fail(tf_supervisor *s, const char *fmt, ...)
{
    if (s->error[0])
        return;
    va_list ap;
    va_start(ap, fmt);
    tf_vseterr(s->error, sizeof s->error, fmt, ap);
    va_end(ap);
}

static tf_worker_stats *worker_by_id(tf_supervisor *s, int64_t id)
{
    /* ids come from the counter, 1, 2, 3, ..., and workers are added as they join */
    if (id >= 1 && id <= s->stats.nworkers && s->stats.workers[id - 1].id == id)
        return &s->stats.workers[id - 1];
    for (int i = 0; i < s->stats.nworkers; i++)
        if (s->stats.workers[i].id == id)
            return &s->stats.workers[i];
    return NULL;
}

static tf_worker_stats *worker_by_conn(tf_supervisor *s, uint64_t conn)
{
    int64_t i;
    if (tf_idmap_get(&s->worker_of_conn, conn, &i) && i < s->stats.nworkers &&
        s->stats.workers[i].conn == conn)
        return &s->stats.workers[i];
    return NULL;
}

/* A connection's peer, for messages only (the lookup scans the connections). */
static const char *peer_name(const tf_supervisor *s, uint64_t conn)
{
    const char *peer = s->srv ? ts_server_peer(s->srv, conn) : NULL;
    return peer ? peer : "?";
}

/* Worker w's connection is conn from now on (0: closed). */
static void bind_conn(tf_supervisor *s, tf_worker_stats *w, uint64_t conn)
{
    if (w->conn && w->conn != conn)
        tf_idmap_del(&s->worker_of_conn, w->conn);
    w->conn = conn;
    w->forked_conn = conn && s->srv && ts_server_conn_trusted(s->srv, conn);
    if (conn)
        snprintf(w->peer, sizeof w->peer, "%s", peer_name(s, conn));
    if (conn && tf_idmap_put(&s->worker_of_conn, conn, w - s->stats.workers))
        fail(s, "out of memory indexing a worker");
}

/* ---- leases: who holds which task copy ---- */

/* A connection holds at most one lease: the worker role refuses a second `in` of a task while
 * it holds one (tf_supervisor_admit), and every connection has that role.  So the index maps a
 * connection to the one entry of `leases` it holds (S8). */

/* The index in leases of conn's lease, or -1. */
static int lease_of(const tf_supervisor *s, uint64_t conn)
{
    int64_t v;
    return tf_idmap_get(&s->lease_of_conn, conn, &v) ? (int)v : -1;
}

/* The index in leases of conn's lease of task, or -1. */
static int find_lease(const tf_supervisor *s, uint64_t conn, int64_t task)
{
    int i = lease_of(s, conn);
    return i >= 0 && s->leases[i].task == task ? i : -1;
}

/* 1 and the task in *task if conn holds a lease, else 0. */
static int held_task(const tf_supervisor *s, uint64_t conn, int64_t *task)
{
    int i = lease_of(s, conn);
    if (i < 0)
        return 0;
    *task = s->leases[i].task;
    return 1;
}

static int add_lease(tf_supervisor *s, uint64_t conn, int64_t task)
{
    assert(lease_of(s, conn) < 0);
    if (s->nleases == s->cap_leases) {
        int cap = s->cap_leases ? 2 * s->cap_leases : 64;
        lease *nl = realloc(s->leases, (size_t)cap * sizeof *nl);
        if (!nl)
            return -1;
        s->leases = nl;
        s->cap_leases = cap;
    }
    if (tf_idmap_put(&s->lease_of_conn, conn, s->nleases))
        return -1;
    s->leases[s->nleases++] = (lease){conn, task, tf_now_msf()};
    return 0;
}

/* Remove leases[i] (the last one moves into its place); returns its task. */
static int64_t remove_lease_at(tf_supervisor *s, int i)
{
    lease gone = s->leases[i];
    int last = --s->nleases;
    tf_idmap_del(&s->lease_of_conn, gone.conn);
    if (i != last) {
        s->leases[i] = s->leases[last];
        tf_idmap_put(&s->lease_of_conn, s->leases[i].conn, i); /* an update: cannot fail */
    }
    return gone.task;
}

static tf_worker_stats *add_worker(tf_supervisor *s, int64_t id)
{
    tf_worker_stats *w = worker_by_id(s, id);
    if (w)
        return w;
    if (s->stats.nworkers == s->cap_workers) {
        int cap = s->cap_workers ? 2 * s->cap_workers : 16;
        tf_worker_stats *nw = realloc(s->stats.workers, (size_t)cap * sizeof *nw);
        if (!nw)
            return NULL;
        s->stats.workers = nw;
        s->cap_workers = cap;
    }
    w = &s->stats.workers[s->stats.nworkers++];
    memset(w, 0, sizeof *w);
    w->id = id;
    w->aff_x0 = w->aff_x1 = w->aff_last = -1;
    snprintf(w->kind, sizeof w->kind, "networked");
    return w;
}

/* The task as the supervisor deals it now: its rectangle and the workers it must avoid. */
static void task_msg_of(const tf_supervisor *s, const task_slot *t, tf_task_msg *m)
{
    memset(m, 0, sizeof *m);
    m->id = t->id;
    m->frame = job_of(s, t->id)->job.frame;
    m->rect = rect_of(s, t->id);
    for (int i = 0; i < t->nfailed && m->nexcluded < TF_EXCLUDED_MAX; i++)
        if (t->failed_count[i] >= FAILURES_TO_EXCLUDE)
            m->excluded[m->nexcluded++] = t->failed_worker[i];
    /* a check copy goes to a worker that has not rendered it yet (a pending check deals none) */
    int checked_by = t->check == CHECK_PENDING ? 0 : t->check;
    for (int i = 0; i < checked_by && m->nexcluded < TF_EXCLUDED_MAX; i++)
        m->excluded[m->nexcluded++] = t->check_worker[i];
}

/* Put a task tuple for `id` in the space, carrying the workers it must avoid. */
static int deal_copy(tf_supervisor *s, task_slot *t)
{
    tf_task_msg m;
    task_msg_of(s, t, &m);
    tf_tuple tup;
    if (tf_task_pack(&tup, &m) || ts_space_out(s->space, &tup)) {
        fail(s, "out of memory dealing task %" PRId64, t->id);
        return -1;
    }
    /* ts_space_out may have handed it straight to a blocked worker: on_take has then already
     * moved the copy from in_space to leased, so count it as in the space first. */
    return 0;
}

/* Job j's first task is about to be dealt (or it has none): its output must exist. */
static int open_job(tf_supervisor *s, job_state *j)
{
    tf_frame_stats *fs = &s->stats.frames[j - s->jobs];
    if (fs->start_ms == 0)
        fs->start_ms = tf_now_msf();
    if (j->opened)
        return 0;
    char err[1024] = "cannot open the output";
    j->writer = s->cfg.hooks.open ? s->cfg.hooks.open(s->cfg.hooks.ctx, (int)(j - s->jobs), err,
                                                      sizeof err)
                                  : NULL;
    if (!j->writer) {
        fail(s, "%s", err);
        return -1;
    }
    j->opened = 1;
    return 0;
}

/* --wait-workers: 1 while too few workers have said hello for the first task to be dealt.
 * Once open, the gate stays open (a worker leaving later does not stop the render). */
static int waiting_for_workers(tf_supervisor *s)
{
    if (s->wait_workers <= 0)
        return 0;
    if (s->joined_workers < s->wait_workers)
        return 1;
    tf_info("%d worker%s joined: dealing tasks", s->joined_workers,
            s->joined_workers == 1 ? "" : "s");
    s->wait_workers = 0;
    return 0;
}

static void deal_new_tasks(tf_supervisor *s)
{
    if (waiting_for_workers(s))
        return;
    while (!s->error[0] && s->next_deal < s->total_tasks &&
           s->next_deal - s->write_task < s->watermark) {
        job_state *j = job_of(s, s->next_deal);
        if (s->next_deal == j->first_id && open_job(s, j))
            return;
        int64_t id = s->next_deal++;
        task_slot *t = &s->ring[id % s->ring_size];
        memset(t, 0, sizeof *t);
        t->id = id;
        t->in_space = 1;
        int outstanding = (int)(s->next_deal - s->write_task);
        if (outstanding > s->stats.max_outstanding_tasks)
            s->stats.max_outstanding_tasks = outstanding;
        deal_copy(s, t);
    }
}

/* 1 if a connected worker in good standing has not failed task t yet. */
static int untried_worker_left(const tf_supervisor *s, const task_slot *t)
{
    for (int i = 0; i < s->stats.nworkers; i++) {
        const tf_worker_stats *w = &s->stats.workers[i];
        if (!w->conn || w->excluded)
            continue;
        int failed = 0;
        for (int k = 0; k < t->nfailed && !failed; k++)
            failed = t->failed_worker[k] == w->id;
        if (!failed)
            return 1;
    }
    return 0;
}

/* Record that `worker` failed task t; returns 1 if the task has now failed everywhere. */
static int note_failure(tf_supervisor *s, task_slot *t, int64_t worker)
{
    s->stats.task_failures++;
    t->failures++;
    int i;
    for (i = 0; i < t->nfailed; i++)
        if (t->failed_worker[i] == worker)
            break;
    if (i == t->nfailed) {
        if (t->nfailed == MAX_FAILED_WORKERS)
            i = MAX_FAILED_WORKERS - 1;
        else
            t->nfailed++;
        t->failed_worker[i] = worker;
        t->failed_count[i] = 0;
    }
    t->failed_count[i]++;
    if (t->failed_count[i] == FAILURES_TO_EXCLUDE)
        tf_events_add(s->events, TF_EV_EXCLUSION, worker, t->id, "worker %" PRId64
                      " is no longer dealt task %" PRId64, worker, t->id);
    /* A task has failed everywhere when --max-task-failures different workers failed it and no
     * connected worker is left that has not: many connections of one client failing a task
     * (each joins as a worker of its own) cannot stop a render that real workers can finish.
     * Past MAX_FAILED_WORKERS the last entry is reused, so a huge farm failing a task for real
     * stops at MAX_TASK_FAILURES instead of dealing it round forever. */
    if (t->nfailed >= s->cfg.max_task_failures &&
        (t->failures >= MAX_TASK_FAILURES || !untried_worker_left(s, t))) {
        char what[128];
        fail(s, "%s failed on %d different workers; stopping (rows written so far are kept: "
                "rerun with --resume)",
             describe_task(s, t->id, what, sizeof what), t->nfailed);
        return 1;
    }
    return 0;
}

/* A copy of task t was lost (its worker died or gave up): deal it again if no copy is left. */
static void redeal_if_lost(tf_supervisor *s, task_slot *t)
{
    if ((t->has_result && (!t->check || t->check == CHECK_PENDING)) || t->checking ||
        t->in_space > 0 || t->leased > 0 || s->error[0])
        return;
    t->in_space++;
    s->stats.tasks_redealt++;
    char what[128];
    describe_task(s, t->id, what, sizeof what);
    tf_info("re-dealing %s", what);
    tf_events_add(s->events, TF_EV_REDEAL, -1, t->id, "%s dealt again", what);
    deal_copy(s, t);
}

/* Remove any task tuples of a finished task still waiting in the space. */
static void withdraw_copies(tf_supervisor *s, task_slot *t)
{
    tf_tuple tmpl, got;
    if (tf_task_template(&tmpl, t->id))
        return;
    while (t->in_space > 0) {
        tf_tuple_init(&got);
        if (ts_space_inp(s->space, &tmpl, &got) != 1)
            break;
        tf_tuple_clear(&got);
        t->in_space--;
    }
    tf_tuple_clear(&tmpl);
}

/* ---- affinity (affinity.h): which of the waiting tasks a worker gets ----------------------- */

/* 1 if task id's copies are dealt excluding worker (task_msg_of): it would only put it back. */
static int excludes(tf_supervisor *s, int64_t id, int64_t worker)
{
    const task_slot *t = slot_of(s, id);
    if (!t || (t->nfailed == 0 && (t->check == CHECK_NONE || t->check == CHECK_PENDING)))
        return 0;
    tf_task_msg m;
    task_msg_of(s, t, &m);
    return tf_task_excludes(&m, worker);
}

/* The space's chooser: task tuple t's rank for the worker on connection taker (0: any).  A
 * task that excludes the worker comes last, so it does not bounce on one of its own range.
 * With more workers than tasks in a band, ranges are narrower than a task and most workers
 * would own none (and scan every waiting task on each take): plain FIFO then. */
static uint64_t rank_task(void *ctx, uint64_t taker, const tf_tuple *t)
{
    tf_supervisor *s = ctx;
    const char *name = tf_tuple_name(t);
    int64_t id;
    if (tf_affinity_workers(s->affinity) > s->band_tasks || !name ||
        strcmp(name, TF_TAG_TASK) || tf_tuple_get_int(t, 1, &id) || id < 0 ||
        id >= s->total_tasks)
        return 0;
    tf_worker_stats *w = worker_by_conn(s, taker);
    if (!w)
        return 0;
    if (excludes(s, id, w->id))
        return UINT64_MAX;
    return tf_affinity_rank(s->affinity, w->id, rect_of(s, id), id);
}

/* Worker w said hello (joined, 1) or its connection closed (0): the ranges follow. */
static void affinity_member(tf_supervisor *s, const tf_worker_stats *w, int joined)
{
    if (!s->affinity)
        return;
    if (!joined)
        tf_affinity_leave(s->affinity, w->id);
    else if (tf_affinity_join(s->affinity, w->id))
        fail(s, "out of memory giving worker %" PRId64 " its column range", w->id);
}

/* The worker on conn took task id: count where it lay for it, and keep the range it had. */
static void count_choice(tf_supervisor *s, uint64_t conn, int64_t id)
{
    tf_worker_stats *w = s->affinity ? worker_by_conn(s, conn) : NULL;
    if (!w)
        return;
    tf_affinity_range(s->affinity, w->id, &w->aff_x0, &w->aff_x1);
    tf_rect r = rect_of(s, id);
    int range = tf_affinity_range_of(s->affinity, r);
    w->aff_switches += w->aff_last >= 0 && range != w->aff_last;
    w->aff_last = range;
    tf_affinity_choice c = tf_affinity_choice_of(s->affinity, w->id, r);
    if (c == TF_AFFINITY_FIRST)
        w->aff_first++;
    else if (c == TF_AFFINITY_SECOND)
        w->aff_second++;
    else if (c == TF_AFFINITY_ELSEWHERE)
        w->aff_elsewhere++;
}

/* When a band has more than one task (rows:K spans the width), the ranges are kept and the
 * takes counted by where they lay; --affinity on also ranks the takes by them.  Off, the counts
 * show what plain FIFO dealing gives. */
static int start_affinity(tf_supervisor *s, char *err, size_t errlen)
{
    if (s->band_tasks < 2)
        return 0;
    s->affinity = tf_affinity_new(s->cfg.width);
    if (!s->affinity)
        return tf_seterr(err, errlen, "out of memory");
    if (s->cfg.affinity)
        ts_space_set_chooser(s->space, rank_task, s);
    s->stats.affinity = s->cfg.affinity;
    return 0;
}

/* ---- writing ------------------------------------------------------------------------------ */

/* Task id is written next and has its result: take the accepted tuple out of the space and hand
 * it to the writer thread.  Its chunks are never looked at here (they were checked). */
static int write_task(tf_supervisor *s, job_state *j, task_slot *t)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&got);
    if (tf_result_template(&tmpl, t->id, t->result_worker) ||
        ts_space_inp(s->space, &tmpl, &got) != 1) {
        tf_tuple_clear(&tmpl);
        fail(s, "internal error: the result of task %" PRId64 " left the space", t->id);
        return -1;
    }
    tf_tuple_clear(&tmpl);
    tf_worker_stats *w = worker_by_id(s, t->result_worker);
    if (w)
        w->written++;
    if (s->written_by)
        s->written_by[t->id] = t->result_worker;
    if (tf_rowwriter_put(j->writer, &got)) {
        char err[512];
        tf_rowwriter_error(j->writer, err, sizeof err);
        fail(s, "%s", err);
        return -1;
    }
    tf_rect r = rect_of(s, t->id);
    int end = r.y + r.h;
    if (r.x + r.w == j->tasks.width && end > j->rows_written) { /* the last task of its rows */
        s->stats.rows_rendered += end - j->rows_written;
        s->stats.frames[j - s->jobs].rows_rendered += end - j->rows_written;
        j->rows_written = end;
    }
    return 0;
}

/* Every task of the write job is queued: hand its output to hooks.finish, move on. */
static int finish_job(tf_supervisor *s, job_state *j)
{
    char err[1024] = "cannot finish the output";
    tf_rowwriter *w = j->writer;
    j->writer = NULL;
    j->finished = 1;
    s->stats.frames[j - s->jobs].done_ms = tf_now_msf();
    if (s->cfg.hooks.finish && s->cfg.hooks.finish(s->cfg.hooks.ctx, (int)(j - s->jobs), w, err,
                                                   sizeof err)) {
        fail(s, "%s", err);
        return -1;
    }
    s->stats.frames_done++;
    s->write_job++;
    return 0;
}

/* --verify: a result is written once its check (if any) agreed, and only if its worker has
 * passed a check, so a liar is caught before anything of it reaches the file.  A worker that is
 * alone in the farm is not trusted for being alone: its results wait (pending checks) until a
 * second worker joins and checks them; the watermark bounds how many wait. */
static int writable(tf_supervisor *s, const task_slot *t)
{
    if (s->cfg.verify_fraction <= 0)
        return 1;
    if (t->check)
        return 0;
    tf_worker_stats *w = worker_by_id(s, t->result_worker);
    return !w || w->checked;
}

/* Advance the write front over every task whose result is in, in id (= file) order, and over
 * the end of each job whose tasks are then all queued. */
static void write_ready_tasks(tf_supervisor *s)
{
    while (!s->error[0] && s->write_job < s->njobs) {
        job_state *j = &s->jobs[s->write_job];
        if (j->tasks.count == 0) {
            /* every row was on disk already (a frame killed while it was being finished):
             * it only needs finishing */
            if (open_job(s, j) || finish_job(s, j))
                return;
            continue;
        }
        if (s->write_task >= s->next_deal)
            return;
        task_slot *t = slot_of(s, s->write_task);
        if (!t || !t->has_result || !writable(s, t))
            return;
        if (write_task(s, j, t))
            return;
        withdraw_copies(s, t);
        t->id = -1;
        s->write_task++;
        if (s->write_task == j->first_id + j->tasks.count && finish_job(s, j))
            return;
    }
}

/* ---- hooks ---------------------------------------------------------------------------------- */

static void remove_lease(tf_supervisor *s, uint64_t conn, int64_t task)
{
    int i = find_lease(s, conn, task);
    if (i < 0)
        return;
    remove_lease_at(s, i);
    task_slot *t = slot_of(s, task);
    if (t && t->leased > 0)
        t->leased--;
}

/* A connection took the worker counter: its worker id is bound to the connection here, once,
 * and the counter goes back at once (by the supervisor, so no worker can hold it). */
static void on_join(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    int64_t id;
    if (tf_next_worker_unpack(tuple, &id))
        return;
    if (id >= s->next_worker_id)
        s->next_worker_id = id + 1;
    tf_tuple next;
    if (tf_next_worker_pack(&next, s->next_worker_id) || ts_space_out(s->space, &next)) {
        fail(s, "out of memory putting the worker counter back");
        return;
    }
    tf_worker_stats *w = add_worker(s, id);
    if (w) {
        if (!w->conn)
            s->live_workers++; /* S6 */
        bind_conn(s, w, conn);
    }
}

static void on_take(void *ctx, uint64_t conn, const tf_tuple *tuple)
{
    tf_supervisor *s = ctx;
    const char *name = tf_tuple_name(tuple);
    if (name && !strcmp(name, TF_TAG_NEXT_WORKER)) {
        on_join(s, conn, tuple);
        return;
    }
    if (!name || strcmp(name, TF_TAG_TASK))
        return;
    tf_task_msg m;
    if (tf_task_unpack(tuple, &m) || m.id < 0)
        return;
    task_slot *t = slot_of(s, m.id);
    if (!t)
        return;
    /* May go to -1 for a moment: when a worker puts a task back (on_task_returned) and the
     * space hands it straight to a waiting worker, on_take for the taker runs before on_out
     * for the returner. */
    t->in_space--;
    if (add_lease(s, conn, m.id)) {
        fail(s, "out of memory recording a lease");
        return;
    }
    t->leased++;
    if (t->taken_ms == 0)
        t->taken_ms = tf_now_msf();
    count_choice(s, conn, m.id);
}

/* A worker put a task back (it is excluded from it): the copy is in the space again. */
static void on_task_returned(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_task_msg m;
    if (tf_task_unpack(tuple, &m) || m.id < 0)
        return;
    task_slot *t = slot_of(s, m.id);
    remove_lease(s, conn, m.id);
    if (t)
        t->in_space++;
}


/* Take this very tuple (all fields actual) out of the space. */
static void remove_exact(tf_supervisor *s, const tf_tuple *tuple)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    if (tf_tuple_copy(&tmpl, tuple) == 0 && ts_space_inp(s->space, &tmpl, &got) == 1)
        tf_tuple_clear(&got);
    tf_tuple_clear(&tmpl);
}

/* The checks of a result against its task that cost nothing per pixel (farmproto.h): its
 * structure, and counts no render of the task could have reached.  0 if accepted, else -1 with
 * the reason.  (Its pixels are checked off the event loop: needs_pixel_check.) */
static int refuse_result(tf_supervisor *s, tf_result_msg *m, tf_rect r, char *why, size_t len)
{
    if (tf_result_check(m, &s->cfg.layout, &s->grid, r, why, len))
        return -1;
    return tf_result_counts_check(m, r, s->cfg.aa_max_depth, why, len);
}

/* Take this very result out of the space (not "a result of task id from worker w": a second
 * tuple claiming the same id and worker must never take the accepted one with it). */
static void drop_result(tf_supervisor *s, const tf_tuple *tuple)
{
    remove_exact(s, tuple);
}
static void start_check(tf_supervisor *s, task_slot *t, const tf_result_msg *m);

/* A result that passed every check: it counts, the task's other copies leave, and its spot
 * check (--verify) starts unless it is itself the third render that decided one. */
static void accept_result(tf_supervisor *s, task_slot *t, const tf_result_msg *m, int replaced)
{
    t->has_result = 1;
    t->result_worker = m->worker;
    s->last_accepted = m->id;
    if (t->duplicated)
        s->dups_in_flight--;
    t->duplicated = 0;
    withdraw_copies(s, t);
    if (!replaced)
        start_check(s, t, m);
    s->results_seen++;
    s->mean_task_ms += ((double)m->busy_ns * 1e-6 - s->mean_task_ms) / (double)s->results_seen;
    tf_worker_stats *w = worker_by_id(s, m->worker);
    if (!w)
        w = add_worker(s, m->worker);
    if (w) {
        w->tasks++;
        w->rays += m->counts.primary_rays + m->counts.shadow_rays;
        w->busy_s += (double)m->busy_ns * 1e-9;
        w->terrain_samples += m->counts.terrain_samples;
        w->terrain_hits += m->counts.terrain_hits;
        w->terrain_evictions += m->counts.terrain_evictions;
    }
    s->stats.terrain_samples += m->counts.terrain_samples;
    s->stats.primary_rays += m->counts.primary_rays;
    s->stats.shadow_rays += m->counts.shadow_rays;
    s->stats.frames[job_of(s, m->id) - s->jobs].rays +=
        m->counts.primary_rays + m->counts.shadow_rays;
    s->stats.external_rays += m->counts.external_rays;
    s->stats.spp_sum += (double)m->spp_total;
    s->stats.pixels += m->counts.pixels;
}

/* Are this connection's pixels to be checked?  A worker this process did not fork sends bytes
 * nobody has looked at; a forked child encodes what its own loop checked, so only
 * --verify-chunks asks for its pixels too. */
static int needs_pixel_check(tf_supervisor *s, uint64_t conn)
{
    const tf_worker_stats *w = worker_by_conn(s, conn);
    return s->cfg.verify_chunks || !w || !w->forked_conn;
}

/* The result leaves the space for the checker until its verdict (collect_checked).  Nothing
 * else of this worker for this task is in the space: a second result of one lease is refused
 * at admission and dropped here, so the (task, worker) template takes this very tuple. */
static void send_to_checker(tf_supervisor *s, task_slot *t, const tf_result_msg *m, int replaced)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&got);
    int rc = tf_result_template(&tmpl, m->id, m->worker) ||
             ts_space_inp(s->space, &tmpl, &got) != 1 || tf_resultcheck_submit(s->checker, &got);
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    if (rc) {
        fail(s, "out of memory checking the result of task %" PRId64, m->id);
        return;
    }
    t->checking = replaced ? 2 : 1;
    t->checking_worker = m->worker;
}

static void on_result(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_result_msg m;
    if (tf_result_unpack(tuple, &m)) {
        tf_warn("malformed result tuple from %s dropped", peer_name(s, conn));
        remove_exact(s, tuple);
        return;
    }
    remove_lease(s, conn, m.id);
    task_slot *t = slot_of(s, m.id);
    int replaced = t && t->replacing;
    if (replaced) {
        t->has_result = 0; /* the first result was a lie and left the space: this one counts */
        t->replacing = 0;
    }
    if (!t || t->has_result || t->checking) {
        drop_result(s, tuple);
        s->stats.results_dropped++;
        return;
    }
    tf_rect r = rect_of(s, m.id);
    char why[256];
    if (refuse_result(s, &m, r, why, sizeof why)) {
        /* Only on privileged paths: a worker's result is checked before it enters the space
         * (tf_supervisor_admit). */
        tf_warn("result of task %" PRId64 " (%dx%d at %d,%d) from %s refused: %s", m.id, r.w,
                r.h, r.x, r.y, peer_name(s, conn), why);
        s->stats.results_refused++;
        drop_result(s, tuple);
        tf_events_add(s->events, TF_EV_FAILURE, m.worker, m.id, "result refused: %s", why);
        if (!note_failure(s, t, m.worker))
            redeal_if_lost(s, t);
        return;
    }
    if (needs_pixel_check(s, conn))
        send_to_checker(s, t, &m, replaced);
    else
        accept_result(s, t, &m, replaced);
    /* Results are handed to the writer by tf_supervisor_step, after the server has flushed its
     * replies: the worker does not wait for anything of the writing. */
}

/* A verdict of the pixel checker on task t's result m: refused like any lie (its task dealt
 * again), or accepted and put back into the space, where the writer will find it. */
static void checked_result(tf_supervisor *s, tf_tuple *tuple, int refused, const char *why)
{
    tf_result_msg m;
    task_slot *t = tf_result_unpack(tuple, &m) ? NULL : slot_of(s, m.id);
    if (!t || !t->checking || t->checking_worker != m.worker)
        return; /* the task moved on meanwhile (a rewind): nothing waits for this verdict */
    int replaced = t->checking == 2;
    t->checking = 0;
    tf_worker_stats *w = worker_by_id(s, m.worker);
    if (refused) {
        tf_rect r = rect_of(s, m.id);
        tf_warn("result of task %" PRId64 " (%dx%d at %d,%d) from worker %" PRId64 " (%s) "
                "refused: %s", m.id, r.w, r.h, r.x, r.y, m.worker, w ? w->peer : "?", why);
        s->stats.results_refused++;
        tf_events_add(s->events, TF_EV_FAILURE, m.worker, m.id, "result refused: %s", why);
        if (!note_failure(s, t, m.worker))
            redeal_if_lost(s, t);
        return;
    }
    if (w && w->excluded) { /* caught lying (--verify) while this result was being checked */
        redeal_if_lost(s, t);
        return;
    }
    tf_rect r = rect_of(s, m.id);
    m.counts.pixels = (uint64_t)r.w * (uint64_t)r.h; /* as tf_result_check found at arrival */
    accept_result(s, t, &m, replaced); /* m borrows the tuple: before it moves into the space */
    if (ts_space_out(s->space, tuple))
        fail(s, "out of memory keeping the result of task %" PRId64, m.id);
}

/* Collect every verdict the checker has reached. */
static void collect_checked(tf_supervisor *s)
{
    tf_tuple tuple;
    char why[192];
    int verdict;
    tf_tuple_init(&tuple);
    while (!s->error[0] &&
           (verdict = tf_resultcheck_next(s->checker, &tuple, why, sizeof why)) >= 0) {
        checked_result(s, &tuple, verdict, why);
        tf_tuple_clear(&tuple);
    }
}

static void on_hello(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_hello_msg m;
    if (!tf_hello_unpack(tuple, &m)) {
        tf_worker_stats *w = add_worker(s, m.worker);
        if (w) {
            s->joined_workers += !w->hello; /* its first hello */
            w->hello = 1;
            snprintf(w->kind, sizeof w->kind, "%s", m.kind);
            snprintf(w->host, sizeof w->host, "%s", m.host);
            snprintf(w->backend, sizeof w->backend, "%s", m.backend);
            if (!w->conn)
                s->live_workers++;
            bind_conn(s, w, conn);
            affinity_member(s, w, 1);
            const char *peer = s->srv ? ts_server_peer(s->srv, conn) : NULL;
            tf_debug("worker %" PRId64 " joined: %s on %s (pid %" PRId64 ", %s backend, %s)",
                     m.worker, m.kind, m.host, m.pid, m.backend, peer ? peer : "?");
            tf_events_add(s->events, TF_EV_JOIN, m.worker, -1, "%s worker on %s (%s backend, %s)",
                          w->kind, w->host, w->backend, peer ? peer : "?");
        }
    }
    remove_exact(s, tuple);
}

static void on_failed(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_failed_msg m;
    if (!tf_failed_unpack(tuple, &m)) {
        tf_warn("worker %" PRId64 " failed task %" PRId64 ": %s", m.worker, m.id, m.message);
        tf_events_add(s->events, TF_EV_FAILURE, m.worker, m.id, "%s", m.message);
        remove_lease(s, conn, m.id);
        task_slot *t = slot_of(s, m.id);
        if (t && (t->has_result || !note_failure(s, t, m.worker)))
            redeal_if_lost(s, t); /* a failed check copy is dealt again too (S9) */
    }
    remove_exact(s, tuple);
}

static void on_out(void *ctx, uint64_t conn, const tf_tuple *tuple)
{
    tf_supervisor *s = ctx;
    s->last_accepted = -1;
    const char *name = tf_tuple_name(tuple);
    if (!name)
        return;
    if (!strcmp(name, TF_TAG_RESULT))
        on_result(s, conn, tuple);
    else if (!strcmp(name, TF_TAG_TASK))
        on_task_returned(s, conn, tuple);
    else if (!strcmp(name, TF_TAG_HELLO))
        on_hello(s, conn, tuple);
    else if (!strcmp(name, TF_TAG_FAILED))
        on_failed(s, conn, tuple);
}

static void on_disconnect(void *ctx, uint64_t conn, const char *peer)
{
    tf_supervisor *s = ctx;
    tf_worker_stats *w = worker_by_conn(s, conn);
    int64_t worker = w ? w->id : -(int64_t)conn; /* a connection that never said hello */
    for (int i = 0; w && i < s->stats.nworkers; i++)
        if (s->stats.workers[i].conn == conn) {
            bind_conn(s, &s->stats.workers[i], 0);
            s->live_workers--;
        }
    if (w) {
        affinity_member(s, w, 0);
        tf_events_add(s->events, TF_EV_LEAVE, w->id, -1, "connection closed (%s)",
                      peer ? peer : "?");
    }
    int i = lease_of(s, conn);
    if (i < 0)
        return;
    int64_t id = remove_lease_at(s, i);
    task_slot *t = slot_of(s, id);
    if (!t)
        return;
    if (t->leased > 0)
        t->leased--;
    if (t->has_result) {
        redeal_if_lost(s, t); /* a check copy, if one is out: dealt again */
        return;
    }
    tf_warn("worker %s left holding task %" PRId64, peer ? peer : "?", id);
    tf_events_add(s->events, TF_EV_FAILURE, worker, id, "left holding the task");
    if (!note_failure(s, t, worker))
        redeal_if_lost(s, t);
}

/* ---- spot checks (--verify, verify.h) -------------------------------------------------------
 * A task whose first result is accepted is checked when the random choice picks it, or when its
 * worker has not passed a check yet: a check copy is dealt to a worker that has not rendered
 * it (the task tuple excludes those that have), and until the check is over the result is not
 * written.  With no second worker connected the check waits (CHECK_PENDING) until one joins.
 * The second result is never stored, only its digest compared: equal, both workers have
 * passed a check; different, a third copy goes to a third worker, whose result sides with one
 * of the two.  The other is excluded (its connection closed, every request refused), its
 * results still in the space are taken out and their tasks dealt again; if the first was the
 * liar, the third result replaces it.  A worker that passed a check and lied later may have
 * lies on disk already: chunks are never rewritten in place, so the output is rewound instead
 * (rewind_liar: reopened through the resume path without them, every task since dealt again);
 * only a frame already finished cannot be, and the render then stops saying so. */

static void start_check(tf_supervisor *s, task_slot *t, const tf_result_msg *m)
{
    if (s->cfg.verify_fraction <= 0)
        return;
    tf_worker_stats *w = worker_by_id(s, m->worker);
    if (!tf_verify_selected(s->cfg.verify_seed, s->cfg.verify_fraction, t->id) &&
        (!w || w->checked))
        return;
    t->check_worker[0] = m->worker;
    tf_result_digest(m, t->digest[0]);
    s->stats.verify_checks++;
    if (tf_supervisor_live_workers(s) < 2) { /* nobody else to render it: wait for someone */
        t->check = CHECK_PENDING;
        s->pending_checks++;
        if (!s->told_pending) {
            tf_info("--verify: worker %" PRId64 " is the only worker; its results wait until a "
                    "second worker joins to check them", m->worker);
            s->told_pending = 1;
        }
        return;
    }
    t->check = CHECK_SECOND;
    t->in_space++;
    deal_copy(s, t);
}

/* Deal the check copies of pending checks once a second worker is there to render them. */
static void start_pending_checks(tf_supervisor *s)
{
    if (s->pending_checks == 0 || tf_supervisor_live_workers(s) < 2)
        return;
    for (int64_t id = s->write_task; id < s->next_deal && s->pending_checks > 0; id++) {
        task_slot *t = slot_of(s, id);
        if (!t || t->check != CHECK_PENDING)
            continue;
        s->pending_checks--;
        t->check = CHECK_SECOND;
        t->in_space++;
        deal_copy(s, t);
    }
    s->told_pending = 0;
}

/* Worker `liar` disagreed with two others about task `task`: exclude it, deal again every
 * task whose accepted result is its. */
/* "10.0.0.7:5123" -> "10.0.0.7"; labels without a port ("local worker 2") stay whole. */
static void address_of(const char *peer, char *addr, size_t len)
{
    snprintf(addr, len, "%s", peer);
    char *colon = strrchr(addr, ':');
    if (colon && (addr[0] != '[' || colon[-1] == ']'))
        *colon = '\0';
}

static int address_excluded(const tf_supervisor *s, const char *peer)
{
    char addr[96];
    address_of(peer, addr, sizeof addr);
    for (int i = 0; i < s->nexcluded_addr; i++)
        if (!strcmp(s->excluded_addr[i], addr))
            return 1;
    return 0;
}

/* The ring, grown to hold at least `need` outstanding tasks (slots keep their ids). */
static int grow_ring(tf_supervisor *s, int64_t need)
{
    int size = s->ring_size;
    while (size < need)
        size *= 2;
    if (size == s->ring_size)
        return 0;
    task_slot *ring = calloc((size_t)size, sizeof *ring);
    if (!ring)
        return -1;
    for (int i = 0; i < size; i++)
        ring[i].id = -1;
    for (int64_t id = s->write_task; id < s->next_deal; id++)
        ring[id % size] = s->ring[id % s->ring_size];
    free(s->ring);
    s->ring = ring;
    s->ring_size = size;
    return 0;
}

/* Worker w lied and some of its results are already written: take them back through the
 * resume path.  The write job's file is closed as a partial render and reopened keeping only
 * the chunks before the liar's first written task (hooks.rewind: the shorter file is made
 * beside and renamed over it, so a crash meanwhile leaves a resumable partial either way);
 * every task from there to the write front is dealt again, whoever wrote it, and the write
 * front moves back.  0 when done; -1 when it cannot be (the render stops, saying why). */
static int rewind_liar(tf_supervisor *s, tf_worker_stats *w)
{
    job_state *j = s->write_job < s->njobs ? &s->jobs[s->write_job] : NULL;
    int64_t k0 = -1, before = 0;
    for (int64_t id = 0; s->written_by && id < s->write_task; id++)
        if (s->written_by[id] == w->id) {
            if (j && id >= j->first_id) {
                k0 = id;
                break;
            }
            before++;
        }
    if (before > 0 || k0 < 0 || !j || !j->writer || !s->cfg.hooks.rewind) {
        fail(s, "worker %" PRId64 " (%s) lied, and %" PRId64 " of its results are in a frame "
             "already finished, which cannot be taken back; render that frame again with "
             "--overwrite", w->id, w->host, w->written);
        return -1;
    }
    int64_t old_write = s->write_task;
    tf_rect r0 = rect_of(s, k0);
    int64_t keep = 0;
    int count = 0;
    char err[1024] = "cannot rewind the output";
    if (grow_ring(s, s->next_deal - k0) ||
        tf_layout_rect_chunks(&s->cfg.layout, r0, &keep, &count)) {
        fail(s, "worker %" PRId64 " lied: cannot take back its results (out of memory)", w->id);
        return -1;
    }
    tf_rowwriter *nw = s->cfg.hooks.rewind(s->cfg.hooks.ctx, (int)(j - s->jobs), j->writer, keep,
                                           err, sizeof err);
    j->writer = nw;
    if (!nw) {
        fail(s, "%s", err);
        return -1;
    }
    tf_warn("worker %" PRId64 " lied after passing a check: taking back the %" PRId64 " tasks "
            "written since its first written result (task %" PRId64 ", row %d): the output is "
            "rewound to %" PRId64 " chunks and they are dealt again", w->id, old_write - k0, k0,
            r0.y, keep);
    tf_events_add(s->events, TF_EV_REDEAL, w->id, k0, "rewound the output to task %" PRId64
                  " to take back what a liar wrote", k0);
    s->write_task = k0;
    for (int64_t id = k0; id < old_write; id++) {
        task_slot *t = &s->ring[id % s->ring_size];
        memset(t, 0, sizeof *t);
        t->id = id;
        for (int i = 0; i < s->nleases; i++) /* a straggler may still hold a copy (S4) */
            t->leased += s->leases[i].task == id;
        tf_worker_stats *by = worker_by_id(s, s->written_by[id]);
        if (by && by->written > 0)
            by->written--;
        s->written_by[id] = 0;
        t->in_space = 1;
        s->stats.tasks_redealt++;
        deal_copy(s, t);
    }
    int frame = (int)(j - s->jobs);
    int rows = r0.y > j->job.first_row ? r0.y : j->job.first_row;
    if (rows < j->rows_written) {
        s->stats.rows_rendered -= j->rows_written - rows;
        s->stats.frames[frame].rows_rendered -= j->rows_written - rows;
        j->rows_written = rows;
    }
    w->written = 0;
    return 0;
}

static void exclude_liar(tf_supervisor *s, int64_t liar, int64_t task)
{
    tf_worker_stats *w = worker_by_id(s, liar);
    if (!w || w->excluded)
        return;
    w->excluded = 1;
    s->stats.workers_excluded++;
    const char *peer = w->conn ? peer_name(s, w->conn) : "gone";
    if (w->conn && s->nexcluded_addr < 32)
        address_of(peer, s->excluded_addr[s->nexcluded_addr++], sizeof s->excluded_addr[0]);
    tf_warn("worker %" PRId64 " (%s, %s) lied: its result of task %" PRId64 " differs from two "
            "other workers'; excluded, and every task it rendered is dealt again",
            liar, w->host, peer, task);
    if (w->written > 0 && rewind_liar(s, w))
        return;
    int redealt = 0;
    for (int64_t id = s->write_task; id < s->next_deal; id++) {
        task_slot *t = slot_of(s, id);
        if (!t || !t->has_result || t->result_worker != liar || t->replacing)
            continue;
        tf_tuple tmpl, got;
        tf_tuple_init(&got);
        if (tf_result_template(&tmpl, id, liar) == 0 && ts_space_inp(s->space, &tmpl, &got) == 1)
            tf_tuple_clear(&got);
        tf_tuple_clear(&tmpl);
        withdraw_copies(s, t);
        t->has_result = 0;
        if (t->check == CHECK_PENDING)
            s->pending_checks--;
        t->check = CHECK_NONE;
        t->in_space++;
        s->stats.tasks_redealt++;
        deal_copy(s, t);
        redealt++;
    }
    if (redealt)
        tf_info("re-dealing %d task%s rendered by worker %" PRId64, redealt,
                redealt == 1 ? "" : "s", liar);
    if (w->conn)
        ts_server_close_conn(s->srv, w->conn);
}

/* A result for a task whose check copy is out, from a worker that has not rendered it: decide.
 * The result is never stored except when it replaces a lying first one (TS_CAP_ALLOW). */
static ts_cap_verdict admit_check(tf_supervisor *s, uint64_t conn, task_slot *t,
                                  const tf_result_msg *m)
{
    uint8_t d[TF_DIGEST_BYTES];
    tf_result_digest(m, d);
    remove_lease(s, conn, t->id);
    s->stats.verify_busy_s += (double)m->busy_ns * 1e-9;
    if (t->check == CHECK_SECOND) {
        if (sodium_memcmp(d, t->digest[0], TF_DIGEST_BYTES) == 0) {
            tf_worker_stats *a = worker_by_id(s, t->check_worker[0]), *b = worker_by_id(s, m->worker);
            if (a)
                a->checked = 1;
            if (b)
                b->checked = 1;
            t->check = CHECK_NONE;
            withdraw_copies(s, t);
            return TS_CAP_DISCARD;
        }
        s->stats.verify_mismatches++;
        tf_warn("task %" PRId64 ": workers %" PRId64 " and %" PRId64 " rendered different bytes; "
                "a third worker decides", t->id, t->check_worker[0], m->worker);
        t->check = CHECK_THIRD;
        t->check_worker[1] = m->worker;
        memcpy(t->digest[1], d, TF_DIGEST_BYTES);
        withdraw_copies(s, t);
        t->in_space++;
        deal_copy(s, t);
        return TS_CAP_DISCARD;
    }
    /* CHECK_THIRD */
    withdraw_copies(s, t);
    t->check = CHECK_NONE;
    tf_worker_stats *third = worker_by_id(s, m->worker);
    if (sodium_memcmp(d, t->digest[0], TF_DIGEST_BYTES) == 0) {
        tf_worker_stats *first = worker_by_id(s, t->check_worker[0]);
        if (first)
            first->checked = 1;
        if (third)
            third->checked = 1;
        exclude_liar(s, t->check_worker[1], t->id);
        return TS_CAP_DISCARD;
    }
    if (sodium_memcmp(d, t->digest[1], TF_DIGEST_BYTES) == 0) {
        if (third)
            third->checked = 1;
        tf_worker_stats *second = worker_by_id(s, t->check_worker[1]);
        if (second)
            second->checked = 1;
        /* The first was the liar: its stored result leaves, this one takes its place. */
        t->replacing = 1;
        tf_tuple tmpl, got;
        tf_tuple_init(&got);
        if (tf_result_template(&tmpl, t->id, t->check_worker[0]) == 0 &&
            ts_space_inp(s->space, &tmpl, &got) == 1)
            tf_tuple_clear(&got);
        tf_tuple_clear(&tmpl);
        tf_worker_stats *first = worker_by_id(s, t->check_worker[0]);
        if (first && first->written == 0 && first->tasks > 0)
            first->tasks--; /* that result no longer counts as its */
        exclude_liar(s, t->check_worker[0], t->id);
        return TS_CAP_ALLOW;
    }
    fail(s, "task %" PRId64 ": workers %" PRId64 ", %" PRId64 " and %" PRId64 " rendered three "
         "different results; a pixel should depend only on the scene: stopping", t->id,
         t->check_worker[0], t->check_worker[1], m->worker);
    return TS_CAP_DISCARD;
}

/* ---- admission: the farm's checks on a worker's requests, before the space sees them ------
 * The guard of the worker role (coordinator/render/worker_role.c).  Everything a worker sends is
 * checked against what the supervisor knows: the worker id bound to its connection when it
 * took the counter, the leases it holds, the task a result answers.  A refusal changes nothing
 * (the server replies ERROR and logs it); a request that breaks the rules on a task the
 * connection holds also forfeits that lease, so the task is dealt again at once. */

static int holds_lease(const tf_supervisor *s, uint64_t conn, int64_t task)
{
    return find_lease(s, conn, task) >= 0;
}

static ts_cap_verdict refuse(char *why, size_t len, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static ts_cap_verdict refuse(char *why, size_t len, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    tf_vseterr(why, len, fmt, ap);
    va_end(ap);
    return TS_CAP_REFUSE;
}

/* A worker's busy time cannot exceed how long it held the task by the coordinator's clock
 * (give or take 1% and 50 ms for a clock that runs at another rate): 0, or -1 with why. */
static int busy_beyond_lease(const tf_supervisor *s, uint64_t conn, const tf_result_msg *m,
                             char *why, size_t len)
{
    int i = find_lease(s, conn, m->id);
    double held_ms = i < 0 ? 0 : tf_now_msf() - s->leases[i].taken_ms;
    double busy_ms = (double)m->busy_ns * 1e-6;
    if (i < 0 || busy_ms <= held_ms * 1.01 + 50.0)
        return 0;
    return tf_seterr(why, len, "claims %.0f ms of rendering for a task it held %.0f ms", busy_ms,
                     held_ms);
}

static ts_cap_verdict admit_result(tf_supervisor *s, uint64_t conn, const tf_worker_stats *w,
                                   const tf_tuple *tuple, char *why, size_t len)
{
    tf_result_msg m;
    if (tf_result_unpack(tuple, &m))
        return refuse(why, len, "malformed result tuple");
    if (m.worker != w->id)
        return refuse(why, len, "result signed as worker %" PRId64 " by worker %" PRId64,
                      m.worker, w->id);
    if (!holds_lease(s, conn, m.id))
        return refuse(why, len, "result for task %" PRId64 ", which this connection does not "
                      "hold", m.id);
    task_slot *t = slot_of(s, m.id);
    if (t && t->has_result && t->check == CHECK_PENDING && m.worker != t->check_worker[0]) {
        t->check = CHECK_SECOND; /* another worker's copy (a straggler's) is the check */
        s->pending_checks--;
    }
    int checking = t && t->has_result && t->check && m.worker != t->check_worker[0] &&
                   (t->check == CHECK_SECOND || m.worker != t->check_worker[1]);
    if (!t || (t->has_result && !checking)) {
        /* A straggler's second copy, or a task already written: the first result won.  Or a
         * check copy answered by a worker it excludes (one that rendered the task already):
         * that is no check, so the copy is dealt again (S9). */
        remove_lease(s, conn, m.id);
        if (t)
            redeal_if_lost(s, t);
        s->stats.results_dropped++;
        return TS_CAP_DISCARD;
    }
    tf_rect r = rect_of(s, m.id);
    char reason[192];
    if (refuse_result(s, &m, r, reason, sizeof reason) ||
        busy_beyond_lease(s, conn, &m, reason, sizeof reason)) {
        /* Dropped before it enters the space, counted against its worker, dealt again. */
        s->stats.results_refused++;
        remove_lease(s, conn, m.id);
        if (!note_failure(s, t, w->id))
            redeal_if_lost(s, t);
        return refuse(why, len, "result of task %" PRId64 " (%dx%d at %d,%d): %s", m.id, r.w,
                      r.h, r.x, r.y, reason);
    }
    if (checking)
        return admit_check(s, conn, t, &m);
    return TS_CAP_ALLOW;
}

/* A worker puts back a task it will not render (it is excluded).  Only a task it holds, and
 * the supervisor deals its own copy: the worker's tuple is never stored, so a rectangle or an
 * exclusion list cannot be altered on the way. */
static ts_cap_verdict admit_task_return(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple,
                                        char *why, size_t len)
{
    tf_task_msg m;
    if (tf_task_unpack(tuple, &m))
        return refuse(why, len, "malformed task tuple");
    if (m.id == TF_TASK_STOP) {
        /* The stop task goes round every worker: the one who took it puts it back. */
        tf_tuple tmpl;
        size_t present = 0;
        if (tf_task_template(&tmpl, TF_TASK_STOP) == 0)
            present = ts_space_count(s->space, &tmpl);
        tf_tuple_clear(&tmpl);
        if (!s->stop_sent || present > 0 || m.rect.w || m.rect.h || m.rect.x || m.rect.y ||
            m.nexcluded)
            return refuse(why, len, "forged stop task");
        return TS_CAP_ALLOW;
    }
    if (!holds_lease(s, conn, m.id))
        return refuse(why, len, "puts back task %" PRId64 ", which this connection does not "
                      "hold", m.id);
    task_slot *t = slot_of(s, m.id);
    tf_rect r = rect_of(s, m.id);
    int altered = m.rect.x != r.x || m.rect.y != r.y || m.rect.w != r.w || m.rect.h != r.h ||
                  m.frame != job_of(s, m.id)->job.frame;
    int excl_altered = 0;
    if (t) {
        /* A copy dealt earlier may list fewer workers (failures since), never others. */
        tf_task_msg now;
        task_msg_of(s, t, &now);
        for (int i = 0; i < m.nexcluded; i++)
            excl_altered |= !tf_task_excludes(&now, m.excluded[i]);
    }
    remove_lease(s, conn, m.id);
    if (t && (!t->has_result || (t->check && t->check != CHECK_PENDING))) {
        /* a task, or its check copy */
        t->in_space++;
        deal_copy(s, t);
    }
    if (altered)
        return refuse(why, len, "task %" PRId64 " put back with rectangle %dx%d at %d,%d "
                      "instead of %dx%d at %d,%d", m.id, m.rect.w, m.rect.h, m.rect.x, m.rect.y,
                      r.w, r.h, r.x, r.y);
    if (excl_altered)
        return refuse(why, len, "task %" PRId64 " put back excluding workers it was not dealt "
                      "to exclude", m.id);
    return TS_CAP_DISCARD;
}

ts_cap_verdict tf_supervisor_admit(void *ctx, uint64_t conn, int op, int blocking,
                                   const tf_tuple *tuple, char *why, size_t len)
{
    (void)blocking;
    tf_supervisor *s = ctx;
    const char *name = tf_tuple_name(tuple);
    tf_worker_stats *w = worker_by_conn(s, conn);
    if (!strcmp(name, TF_TAG_NEXT_WORKER)) {
        if (w)
            return refuse(why, len, "joins twice (already worker %" PRId64 ")", w->id);
        if (s->nexcluded_addr > 0 && address_excluded(s, peer_name(s, conn)))
            return refuse(why, len, "joins from an address whose worker failed a spot check");
        return TS_CAP_ALLOW;
    }
    if (!w)
        return refuse(why, len, "%s (\"%s\", ...) before joining (take (\"next_worker\", ?n) "
                      "first)", ts_cap_op_name(op), name);
    if (w->excluded)
        return refuse(why, len, "worker %" PRId64 " is excluded (it failed a spot check)", w->id);
    if (!strcmp(name, TF_TAG_HELLO)) {
        tf_hello_msg m;
        if (tf_hello_unpack(tuple, &m))
            return refuse(why, len, "malformed hello tuple");
        if (m.worker != w->id)
            return refuse(why, len, "hello as worker %" PRId64 " from worker %" PRId64, m.worker,
                          w->id);
        return TS_CAP_ALLOW;
    }
    if (!strcmp(name, TF_TAG_TASK) && op == TS_CAP_IN) {
        /* Any task, never one chosen by id or place: a client may not pick the task it wants
         * to fail or to sit on. */
        for (int i = 1; i < tuple->nfields; i++)
            if (!tuple->f[i].formal)
                return refuse(why, len, "takes a task by a template with actual fields (only "
                              "(\"task\", ?id, ?x, ?y, ?w, ?h, ?excluded) is a worker's)");
        int64_t held = -1;
        if (held_task(s, conn, &held))
            return refuse(why, len, "takes another task while holding task %" PRId64
                          " (one at a time)", held);
        return TS_CAP_ALLOW;
    }
    if (!strcmp(name, TF_TAG_TASK))
        return admit_task_return(s, conn, tuple, why, len);
    if (!strcmp(name, TF_TAG_RESULT))
        return admit_result(s, conn, w, tuple, why, len);
    if (!strcmp(name, TF_TAG_FAILED)) {
        tf_failed_msg m;
        if (tf_failed_unpack(tuple, &m))
            return refuse(why, len, "malformed failed tuple");
        if (m.worker != w->id)
            return refuse(why, len, "failure reported as worker %" PRId64 " by worker %" PRId64,
                          m.worker, w->id);
        if (!holds_lease(s, conn, m.id))
            return refuse(why, len, "failure of task %" PRId64 ", which this connection does not "
                          "hold", m.id);
        return TS_CAP_ALLOW;
    }
    return refuse(why, len, "%s (\"%s\", ...) is not a worker's", ts_cap_op_name(op), name);
}

ts_server_hooks tf_supervisor_hooks(tf_supervisor *sup)
{
    ts_server_hooks h = {sup, on_take, on_out, on_disconnect};
    return h;
}

/* ---- stragglers ------------------------------------------------------------------------------- */

/* Workers are idle and nothing fresh can be dealt (the image is all dealt, or the watermark
 * holds dealing back behind a slow task): deal a second copy of the oldest task that has been
 * held for several mean task times.  Bounded (MAX_DUPLICATES_IN_FLIGHT), because a worker busy
 * on a duplicate cannot take the fresh tasks that appear once the original comes back. */
static void deal_duplicate(tf_supervisor *s)
{
    if (s->dups_in_flight >= MAX_DUPLICATES_IN_FLIGHT || s->results_seen == 0)
        return;
    /* It scans every outstanding task: not on every step (thousands a second with hundreds of
     * workers), a few times within the shortest patience instead. */
    double now = tf_now_msf();
    if (now - s->last_straggler_scan_ms < STRAGGLER_SCAN_MS)
        return;
    s->last_straggler_scan_ms = now;
    ts_space_stats st;
    ts_space_get_stats(s->space, &st);
    if (st.waiters == 0)
        return;
    if (s->next_deal < s->total_tasks && s->next_deal - s->write_task < s->watermark)
        return; /* fresh work can still be dealt */
    for (int64_t id = s->write_task; id < s->next_deal; id++) {
        task_slot *t = slot_of(s, id);
        if (t && t->in_space > 0 && !t->has_result)
            return; /* an undealt copy is waiting: idle workers will take it */
    }
    double patience = STRAGGLER_FACTOR * s->mean_task_ms;
    if (patience < STRAGGLER_MIN_MS)
        patience = STRAGGLER_MIN_MS;
    for (int64_t id = s->write_task; id < s->next_deal; id++) {
        task_slot *t = slot_of(s, id);
        if (!t || t->has_result || t->duplicated || t->leased == 0 || now - t->taken_ms < patience)
            continue;
        t->duplicated = 1;
        t->in_space++;
        s->dups_in_flight++;
        s->stats.tasks_duplicated++;
        tf_debug("straggler: task %" PRId64 " held %.0f ms (mean task %.0f ms); dealing a second "
                 "copy", id, now - t->taken_ms, s->mean_task_ms);
        deal_copy(s, t);
        return;
    }
}

/* The auto watermark: one band plus a few tasks per connected (or expected) worker. */
static void update_watermark(tf_supervisor *s)
{
    if (!s->auto_watermark)
        return;
    int workers = tf_supervisor_live_workers(s);
    if (workers < s->cfg.expected_workers)
        workers = s->cfg.expected_workers;
    if (workers > AUTO_WM_MAX_WORKERS)
        workers = AUTO_WM_MAX_WORKERS;
    int wm = s->band_tasks + AUTO_WM_PER_WORKER * workers;
    if (wm > s->ring_size)
        wm = s->ring_size;
    s->watermark = wm;
    if (wm > s->stats.watermark)
        s->stats.watermark = wm;
}

/* ---- public --------------------------------------------------------------------------------- */

tf_supervisor *tf_supervisor_new(ts_space *space, const tf_supervisor_config *cfg, char *err,
                                 size_t errlen)
{
    tf_supervisor *s = calloc(1, sizeof *s);
    if (!s) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    s->space = space;
    s->last_accepted = -1;
    s->cfg = *cfg;
    s->wait_workers = cfg->wait_workers;
    if (s->cfg.max_task_failures < 1)
        s->cfg.max_task_failures = 3;
    s->cfg.jobs = NULL; /* copied below */
    s->njobs = cfg->njobs;
    s->jobs = calloc(cfg->njobs > 0 ? (size_t)cfg->njobs : 1, sizeof *s->jobs);
    s->stats.frames = calloc(cfg->njobs > 0 ? (size_t)cfg->njobs : 1, sizeof *s->stats.frames);
    if (!s->jobs || !s->stats.frames) {
        tf_seterr(err, errlen, "out of memory");
        tf_supervisor_free(s);
        return NULL;
    }
    if (cfg->njobs < 1) {
        tf_seterr(err, errlen, "internal error: nothing to render");
        tf_supervisor_free(s);
        return NULL;
    }
    s->stats.nframes = cfg->njobs;
    for (int i = 0; i < cfg->njobs; i++) {
        job_state *j = &s->jobs[i];
        j->job = cfg->jobs[i];
        if (j->job.first_row < 0 || j->job.first_row > cfg->height) {
            tf_seterr(err, errlen, "internal error: frame job %d starts at row %d of %d", i,
                      j->job.first_row, cfg->height);
            tf_supervisor_free(s);
            return NULL;
        }
        tf_tasks_init(&j->tasks, cfg->width, cfg->height, j->job.first_row, cfg->spec);
        tf_tasks_skip(&j->tasks, j->job.first_tiles);
        j->first_id = s->total_tasks;
        j->rows_written = j->job.first_row;
        s->total_tasks += j->tasks.count;
        s->stats.frames[i].frame = j->job.frame;
        s->stats.frames[i].rows_resumed = j->job.first_row;
        s->stats.rows_resumed += j->job.first_row;
    }
    s->band_tasks = s->jobs[0].tasks.cols;
    s->auto_watermark = cfg->watermark <= 0;
    if (!s->auto_watermark && cfg->watermark < s->band_tasks) {
        snprintf(err, errlen,
                 "--watermark %d is smaller than the %d tasks of one row band: the first band "
                 "could never be written; use at least %d",
                 cfg->watermark, s->band_tasks, s->band_tasks);
        tf_supervisor_free(s);
        return NULL;
    }
    s->ring_size = s->auto_watermark
                       ? s->band_tasks + AUTO_WM_PER_WORKER * AUTO_WM_MAX_WORKERS
                       : cfg->watermark;
    s->watermark = s->auto_watermark ? 0 : cfg->watermark;
    s->ring = calloc((size_t)s->ring_size, sizeof *s->ring);
    if (start_affinity(s, err, errlen)) {
        tf_supervisor_free(s);
        return NULL;
    }
    if (cfg->verify_fraction > 0)
        s->written_by = calloc((size_t)(s->total_tasks > 0 ? s->total_tasks : 1),
                               sizeof *s->written_by);
    s->grid = tf_preview_grid_for(cfg->width, cfg->height);
    s->checker = tf_resultcheck_new(&cfg->layout, 1, err, errlen);
    if (!s->checker) {
        tf_supervisor_free(s);
        return NULL;
    }
    if (!s->ring || (cfg->verify_fraction > 0 && !s->written_by)) {
        tf_seterr(err, errlen, "out of memory");
        tf_supervisor_free(s);
        return NULL;
    }
    /* The ring is not initialised: a slot is only read for an outstanding task (slot_of checks
     * the range first), and dealing a task fills its slot.  Sized for the largest automatic
     * watermark, it is megabytes that are never touched on a small farm. */
    s->stats.tasks_total = s->total_tasks;
    s->stats.verify_fraction = cfg->verify_fraction;
    s->stats.watermark = s->watermark;
    update_watermark(s);
    return s;
}

void tf_supervisor_free(tf_supervisor *s)
{
    if (!s)
        return;
    if (s->stats.affinity)
        ts_space_set_chooser(s->space, NULL, NULL);
    tf_affinity_free(s->affinity);
    free(s->ring);
    free(s->written_by);
    tf_idmap_free(&s->worker_of_conn);
    tf_idmap_free(&s->lease_of_conn);
    free(s->leases);
    tf_resultcheck_free(s->checker);
    free(s->stats.workers);
    free(s->stats.frames);
    free(s->jobs);
    free(s);
}

void tf_supervisor_attach(tf_supervisor *s, ts_server *srv) { s->srv = srv; }

void tf_supervisor_set_writer(tf_supervisor *s, int job, tf_rowwriter *writer)
{
    s->jobs[job].writer = writer;
    s->jobs[job].opened = 1;
}

int tf_supervisor_take_open_writers(tf_supervisor *s, tf_rowwriter **out, int *jobs, int max)
{
    int n = 0;
    for (int i = 0; i < s->njobs && n < max; i++)
        if (s->jobs[i].writer) {
            out[n] = s->jobs[i].writer;
            jobs[n++] = i;
            s->jobs[i].writer = NULL;
        }
    return n;
}

/* The first write error of any open output. */
static int writer_failed(tf_supervisor *s)
{
    char err[512];
    for (int i = s->write_job; i < s->njobs; i++) {
        job_state *j = &s->jobs[i];
        if (!j->opened)
            break; /* jobs open in order */
        if (j->writer && tf_rowwriter_error(j->writer, err, sizeof err)) {
            fail(s, "%s", err);
            return 1;
        }
    }
    return 0;
}

void tf_supervisor_step(tf_supervisor *s, double now_ms)
{
    (void)now_ms;
    if (s->error[0])
        return;
    if (writer_failed(s))
        return;
    assert_supervisor_state(s);
    collect_checked(s);
    start_pending_checks(s);
    write_ready_tasks(s);
    update_watermark(s);
    deal_new_tasks(s);
    deal_duplicate(s);
    assert_supervisor_state(s);
}

int tf_supervisor_checks_pending(tf_supervisor *s)
{
    return tf_resultcheck_pending(s->checker) > 0;
}

int tf_supervisor_done(const tf_supervisor *s)
{
    return s->write_job == s->njobs && !s->error[0];
}

const char *tf_supervisor_error(const tf_supervisor *s) { return s->error[0] ? s->error : NULL; }

void tf_supervisor_stop_workers(tf_supervisor *s)
{
    if (s->stop_sent)
        return;
    tf_task_msg m;
    memset(&m, 0, sizeof m);
    m.id = TF_TASK_STOP;
    tf_tuple t;
    if (tf_task_pack(&t, &m) == 0 && ts_space_out(s->space, &t) == 0)
        s->stop_sent = 1;
}

int tf_supervisor_rows_written(const tf_supervisor *s, int job)
{
    return s->jobs[job].rows_written;
}

int tf_supervisor_write_job(const tf_supervisor *s) { return s->write_job; }

const tf_farm_stats *tf_supervisor_stats(tf_supervisor *s)
{
    ts_space_stats st;
    ts_space_get_stats(s->space, &st);
    s->stats.max_tuple_bytes = st.max_bytes;
    tf_resultcheck_totals(s->checker, &s->stats.pixel_check_cpu_s, &s->stats.pixels_checked);
    return &s->stats;
}

int tf_supervisor_joined_workers(const tf_supervisor *s) { return s->joined_workers; }

int tf_supervisor_live_workers(const tf_supervisor *s)
{
    return s->live_workers; /* == entries of stats.workers with conn != 0 (S6) */
}

/* ---- for the dashboard (coordinator/dashboard/dashboard.c), in the event-loop thread ----------------- */

void tf_supervisor_set_events(tf_supervisor *s, tf_events *events) { s->events = events; }

int tf_supervisor_outstanding(const tf_supervisor *s) { return (int)(s->next_deal - s->write_task); }

int tf_supervisor_watermark(const tf_supervisor *s) { return s->watermark; }

int tf_supervisor_watermark_max(const tf_supervisor *s) { return s->ring_size; }

int tf_supervisor_set_watermark(tf_supervisor *s, int watermark, char *err, size_t errlen)
{
    if (watermark < s->band_tasks || watermark > s->ring_size)
        return tf_seterr(err, errlen, "watermark %d is outside %d (one band of tasks) .. %d",
                         watermark, s->band_tasks, s->ring_size);
    s->auto_watermark = 0;
    s->watermark = watermark;
    if (watermark > s->stats.watermark)
        s->stats.watermark = watermark;
    return 0;
}

int tf_supervisor_task_rect(const tf_supervisor *s, int64_t id, tf_rect *rect, int *frame)
{
    if (id < 0 || id >= s->total_tasks)
        return -1;
    const job_state *j = job_of(s, id);
    *rect = tf_task_rect(&j->tasks, (int)(id - j->first_id));
    *frame = j->job.frame;
    return 0;
}

int64_t tf_supervisor_last_accepted(const tf_supervisor *s) { return s->last_accepted; }

int tf_supervisor_task_views(const tf_supervisor *s, int64_t *write_task, tf_task_view *out,
                             int max)
{
    int n = 0;
    *write_task = s->write_task;
    for (int64_t id = s->write_task; id < s->next_deal && n < max; id++, n++) {
        const task_slot *t = &s->ring[id % s->ring_size];
        out[n] = (tf_task_view){id, t->has_result, t->leased, 0};
    }
    for (int i = 0; i < s->nleases; i++) {
        int64_t k = s->leases[i].task - s->write_task;
        if (k >= 0 && k < n && out[k].holder_conn == 0)
            out[k].holder_conn = s->leases[i].conn;
    }
    return n;
}
