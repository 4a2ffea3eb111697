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
 * order (a tile, or a block of rows).
 *
 * The supervisor is split by concern, one file each, all sharing supervisor_internal.h (its
 * state, struct tf_supervisor, and the sv_ functions one file calls in another): this file
 * holds the invariants' asserts, the small helpers and the public calls; supervisor_deal.c
 * leases, dealing and affinity; supervisor_redeal.c failures, re-deals, stragglers and the
 * watermark; supervisor_results.c checking results and the in-order handoff to the writer;
 * supervisor_hooks.c the server's hooks; supervisor_admit.c admission of a worker's requests;
 * supervisor_verify.c the spot checks. */
#include "coordinator/render/supervisor_internal.h"

#include <assert.h>
#include <inttypes.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

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
job_state *sv_job_of(const tf_supervisor *s, int64_t id)
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

tf_rect sv_rect_of(const tf_supervisor *s, int64_t id)
{
    const job_state *j = sv_job_of(s, id);
    return tf_task_rect(&j->tasks, (int)(id - j->first_id));
}

/* "task 12 (64x64 at 0,128)" or, in a sequence, "task 12 (frame 3, 64x64 at 0,128)" */
const char *sv_describe_task(const tf_supervisor *s, int64_t id, char *buf, size_t len)
{
    const job_state *j = sv_job_of(s, id);
    tf_rect r = tf_task_rect(&j->tasks, (int)(id - j->first_id));
    if (j->job.frame >= 0)
        snprintf(buf, len, "task %" PRId64 " (frame %d, %dx%d at %d,%d)", id, j->job.frame, r.w,
                 r.h, r.x, r.y);
    else
        snprintf(buf, len, "task %" PRId64 " (%dx%d at %d,%d)", id, r.w, r.h, r.x, r.y);
    return buf;
}

task_slot *sv_slot_of(tf_supervisor *s, int64_t id)
{
    if (id < s->write_task || id >= s->next_deal)
        return NULL;
    task_slot *t = &s->ring[id % s->ring_size];
    return t->id == id ? t : NULL;
}

void sv_fail(tf_supervisor *s, const char *fmt, ...)
{
    if (s->error[0])
        return;
    va_list ap;
    va_start(ap, fmt);
    tf_vseterr(s->error, sizeof s->error, fmt, ap);
    va_end(ap);
}

tf_worker_stats *sv_worker_by_id(tf_supervisor *s, int64_t id)
{
    /* ids come from the counter, 1, 2, 3, ..., and workers are added as they join */
    if (id >= 1 && id <= s->stats.nworkers && s->stats.workers[id - 1].id == id)
        return &s->stats.workers[id - 1];
    for (int i = 0; i < s->stats.nworkers; i++)
        if (s->stats.workers[i].id == id)
            return &s->stats.workers[i];
    return NULL;
}

tf_worker_stats *sv_worker_by_conn(tf_supervisor *s, uint64_t conn)
{
    int64_t i;
    if (tf_idmap_get(&s->worker_of_conn, conn, &i) && i < s->stats.nworkers &&
        s->stats.workers[i].conn == conn)
        return &s->stats.workers[i];
    return NULL;
}

/* A connection's peer, for messages only (the lookup scans the connections). */
const char *sv_peer_name(const tf_supervisor *s, uint64_t conn)
{
    const char *peer = s->srv ? ts_server_peer(s->srv, conn) : NULL;
    return peer ? peer : "?";
}

/* Worker w's connection is conn from now on (0: closed). */
void sv_bind_conn(tf_supervisor *s, tf_worker_stats *w, uint64_t conn)
{
    if (w->conn && w->conn != conn)
        tf_idmap_del(&s->worker_of_conn, w->conn);
    w->conn = conn;
    w->forked_conn = conn && s->srv && ts_server_conn_trusted(s->srv, conn);
    if (conn)
        snprintf(w->peer, sizeof w->peer, "%s", sv_peer_name(s, conn));
    if (conn && tf_idmap_put(&s->worker_of_conn, conn, w - s->stats.workers))
        sv_fail(s, "out of memory indexing a worker");
}

tf_worker_stats *sv_add_worker(tf_supervisor *s, int64_t id)
{
    tf_worker_stats *w = sv_worker_by_id(s, id);
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

/* ---- public --------------------------------------------------------------------------------- */

/* Job i (a frame, or the still) and its tasks, after the jobs before it.  0, or -1 with err. */
static int start_job(tf_supervisor *s, int i, char *err, size_t errlen)
{
    const tf_supervisor_config *cfg = &s->cfg;
    job_state *j = &s->jobs[i];
    j->job = cfg->jobs[i];
    if (j->job.first_row < 0 || j->job.first_row > cfg->height)
        return tf_seterr(err, errlen, "internal error: frame job %d starts at row %d of %d", i,
                         j->job.first_row, cfg->height);
    tf_tasks_init(&j->tasks, cfg->width, cfg->height, j->job.first_row, cfg->spec);
    tf_tasks_skip(&j->tasks, j->job.first_tiles);
    j->first_id = s->total_tasks;
    j->rows_written = j->job.first_row;
    s->total_tasks += j->tasks.count;
    s->stats.frames[i].frame = j->job.frame;
    s->stats.frames[i].rows_resumed = j->job.first_row;
    s->stats.rows_resumed += j->job.first_row;
    return 0;
}

/* Every job of cfg, numbered into one run of task ids.  0, or -1 with err. */
static int start_jobs(tf_supervisor *s, char *err, size_t errlen)
{
    int n = s->cfg.njobs;
    s->njobs = n;
    s->jobs = calloc(n > 0 ? (size_t)n : 1, sizeof *s->jobs);
    s->stats.frames = calloc(n > 0 ? (size_t)n : 1, sizeof *s->stats.frames);
    if (!s->jobs || !s->stats.frames)
        return tf_seterr(err, errlen, "out of memory");
    if (n < 1)
        return tf_seterr(err, errlen, "internal error: nothing to render");
    s->stats.nframes = n;
    for (int i = 0; i < n; i++)
        if (start_job(s, i, err, errlen))
            return -1;
    return 0;
}

/* The watermark (a fixed one must let the first band be written) and the ring of outstanding
 * tasks' slots it needs.  The ring is not initialised: a slot is only read for an outstanding
 * task (sv_slot_of checks the range first), and dealing a task fills its slot.  Sized for the
 * largest automatic watermark, it is megabytes that are never touched on a small farm.  0, or
 * -1 with err. */
static int start_ring(tf_supervisor *s, char *err, size_t errlen)
{
    int wm = s->cfg.watermark;
    s->band_tasks = s->jobs[0].tasks.cols;
    s->auto_watermark = wm <= 0;
    if (!s->auto_watermark && wm < s->band_tasks)
        return tf_seterr(err, errlen,
                         "--watermark %d is smaller than the %d tasks of one row band: the first "
                         "band could never be written; use at least %d",
                         wm, s->band_tasks, s->band_tasks);
    int most_ahead = tf_tasks_auto_ahead(&s->jobs[0].tasks, AUTO_WM_MAX_WORKERS);
    if (most_ahead > s->total_tasks) /* no more can be outstanding: the slots stay small */
        most_ahead = (int)s->total_tasks;
    s->ring_size = s->auto_watermark ? s->band_tasks + most_ahead : wm;
    s->watermark = s->auto_watermark ? 0 : wm;
    s->ring = calloc((size_t)s->ring_size, sizeof *s->ring);
    return s->ring ? 0 : tf_seterr(err, errlen, "out of memory");
}

/* What watches the results: affinity, --verify's record of who wrote what, the preview grid,
 * the pixel checker.  0, or -1 with err. */
static int start_watch(tf_supervisor *s, char *err, size_t errlen)
{
    const tf_supervisor_config *cfg = &s->cfg;
    if (sv_start_affinity(s, err, errlen))
        return -1;
    if (cfg->verify_fraction > 0) {
        s->written_by = calloc((size_t)(s->total_tasks > 0 ? s->total_tasks : 1),
                               sizeof *s->written_by);
        if (!s->written_by)
            return tf_seterr(err, errlen, "out of memory");
    }
    s->grid = tf_preview_grid_for(cfg->width, cfg->height);
    s->checker = tf_resultcheck_new(&cfg->layout, 1, err, errlen);
    return s->checker ? 0 : -1;
}

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
    s->cfg = *cfg; /* its jobs are read in start_jobs, not kept (cfg->jobs is the caller's) */
    s->wait_workers = cfg->wait_workers;
    if (s->cfg.max_task_failures < 1)
        s->cfg.max_task_failures = 3;
    if (start_jobs(s, err, errlen) || start_ring(s, err, errlen) || start_watch(s, err, errlen)) {
        tf_supervisor_free(s);
        return NULL;
    }
    s->cfg.jobs = NULL;
    s->stats.tasks_total = s->total_tasks;
    s->stats.verify_fraction = cfg->verify_fraction;
    s->stats.watermark = s->watermark;
    sv_update_watermark(s);
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
            sv_fail(s, "%s", err);
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
    sv_collect_checked(s);
    sv_start_pending_checks(s);
    sv_write_ready_tasks(s);
    sv_update_watermark(s);
    sv_deal_new_tasks(s);
    sv_deal_duplicate(s);
    assert_supervisor_state(s);
}

int tf_supervisor_checks_pending(tf_supervisor *s)
{
    return tf_resultcheck_pending(s->checker) > 0;
}

int tf_supervisor_wait_ms(tf_supervisor *s)
{
    if (tf_supervisor_checks_pending(s))
        return 1; /* the checker's verdicts come without a message */
    return sv_stragglers_matter(s) ? SV_WAIT_STRAGGLERS_MS : SV_WAIT_IDLE_MS;
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

/* ---- for the dashboard (coordinator/dashboard/dashboard.c), in the event-loop thread ---- */

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
    const job_state *j = sv_job_of(s, id);
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
