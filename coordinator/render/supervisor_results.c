/* supervisor_results.c: the supervisor's results (supervisor.c says how the whole works;
 * supervisor_internal.h what its files share).  A result from a worker the space stored is
 * checked against its task (structure and counts here, pixels by the checker thread,
 * resultcheck.h), then accepted or refused; accepted results wait in the space and are handed
 * in task id order, which is the file's chunk order, to the writer thread (the in-order
 * handoff), each frame job's output finished once all its tasks are queued. */
#include "coordinator/render/supervisor_internal.h"

#include <inttypes.h>

#include "clock.h"
#include "coordinator/render/events.h"
#include "log.h"

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
        sv_fail(s, "internal error: the result of task %" PRId64 " left the space", t->id);
        return -1;
    }
    tf_tuple_clear(&tmpl);
    tf_worker_stats *w = sv_worker_by_id(s, t->result_worker);
    if (w)
        w->written++;
    if (s->written_by)
        s->written_by[t->id] = t->result_worker;
    if (tf_rowwriter_put(j->writer, &got)) {
        char err[512];
        tf_rowwriter_error(j->writer, err, sizeof err);
        sv_fail(s, "%s", err);
        return -1;
    }
    tf_rect r = sv_rect_of(s, t->id);
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
        sv_fail(s, "%s", err);
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
    tf_worker_stats *w = sv_worker_by_id(s, t->result_worker);
    return !w || w->checked;
}

/* Advance the write front over every task whose result is in, in id (= file) order, and over
 * the end of each job whose tasks are then all queued. */
void sv_write_ready_tasks(tf_supervisor *s)
{
    while (!s->error[0] && s->write_job < s->njobs) {
        job_state *j = &s->jobs[s->write_job];
        if (j->tasks.count == 0) {
            /* every row was on disk already (a frame killed while it was being finished):
             * it only needs finishing */
            if (sv_open_job(s, j) || finish_job(s, j))
                return;
            continue;
        }
        if (s->write_task >= s->next_deal)
            return;
        task_slot *t = sv_slot_of(s, s->write_task);
        if (!t || !t->has_result || !writable(s, t))
            return;
        if (write_task(s, j, t))
            return;
        sv_withdraw_copies(s, t);
        t->id = -1;
        s->write_task++;
        if (s->write_task == j->first_id + j->tasks.count && finish_job(s, j))
            return;
    }
}

/* Take this very tuple (all fields actual) out of the space. */
void sv_remove_exact(tf_supervisor *s, const tf_tuple *tuple)
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
int sv_refuse_result(tf_supervisor *s, tf_result_msg *m, tf_rect r, char *why, size_t len)
{
    if (tf_result_check(m, &s->cfg.layout, &s->grid, r, why, len))
        return -1;
    return tf_result_counts_check(m, r, s->cfg.aa_max_depth, why, len);
}

/* Take this very result out of the space (not "a result of task id from worker w": a second
 * tuple claiming the same id and worker must never take the accepted one with it). */
static void drop_result(tf_supervisor *s, const tf_tuple *tuple)
{
    sv_remove_exact(s, tuple);
}

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
    sv_withdraw_copies(s, t);
    if (!replaced)
        sv_start_check(s, t, m);
    s->results_seen++;
    s->mean_task_ms += ((double)m->busy_ns * 1e-6 - s->mean_task_ms) / (double)s->results_seen;
    tf_worker_stats *w = sv_worker_by_id(s, m->worker);
    if (!w)
        w = sv_add_worker(s, m->worker);
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
    s->stats.frames[sv_job_of(s, m->id) - s->jobs].rays +=
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
    const tf_worker_stats *w = sv_worker_by_conn(s, conn);
    return s->cfg.verify_chunks || !w || !w->forked_conn;
}

/* The result leaves the space for the checker until its verdict (sv_collect_checked).  Nothing
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
        sv_fail(s, "out of memory checking the result of task %" PRId64, m->id);
        return;
    }
    t->checking = replaced ? 2 : 1;
    t->checking_worker = m->worker;
}

void sv_on_result(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_result_msg m;
    if (tf_result_unpack(tuple, &m)) {
        tf_warn("malformed result tuple from %s dropped", sv_peer_name(s, conn));
        sv_remove_exact(s, tuple);
        return;
    }
    sv_remove_lease(s, conn, m.id);
    task_slot *t = sv_slot_of(s, m.id);
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
    tf_rect r = sv_rect_of(s, m.id);
    char why[256];
    if (sv_refuse_result(s, &m, r, why, sizeof why)) {
        /* Only on privileged paths: a worker's result is checked before it enters the space
         * (tf_supervisor_admit). */
        tf_warn("result of task %" PRId64 " (%dx%d at %d,%d) from %s refused: %s", m.id, r.w,
                r.h, r.x, r.y, sv_peer_name(s, conn), why);
        s->stats.results_refused++;
        drop_result(s, tuple);
        tf_events_add(s->events, TF_EV_FAILURE, m.worker, m.id, "result refused: %s", why);
        if (!sv_note_failure(s, t, m.worker))
            sv_redeal_if_lost(s, t);
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
    task_slot *t = tf_result_unpack(tuple, &m) ? NULL : sv_slot_of(s, m.id);
    if (!t || !t->checking || t->checking_worker != m.worker)
        return; /* the task moved on meanwhile (a rewind): nothing waits for this verdict */
    int replaced = t->checking == 2;
    t->checking = 0;
    tf_worker_stats *w = sv_worker_by_id(s, m.worker);
    if (refused) {
        tf_rect r = sv_rect_of(s, m.id);
        tf_warn("result of task %" PRId64 " (%dx%d at %d,%d) from worker %" PRId64 " (%s) "
                "refused: %s", m.id, r.w, r.h, r.x, r.y, m.worker, w ? w->peer : "?", why);
        s->stats.results_refused++;
        tf_events_add(s->events, TF_EV_FAILURE, m.worker, m.id, "result refused: %s", why);
        if (!sv_note_failure(s, t, m.worker))
            sv_redeal_if_lost(s, t);
        return;
    }
    if (w && w->excluded) { /* caught lying (--verify) while this result was being checked */
        sv_redeal_if_lost(s, t);
        return;
    }
    tf_rect r = sv_rect_of(s, m.id);
    m.counts.pixels = (uint64_t)r.w * (uint64_t)r.h; /* as tf_result_check found at arrival */
    accept_result(s, t, &m, replaced); /* m borrows the tuple: before it moves into the space */
    if (ts_space_out(s->space, tuple))
        sv_fail(s, "out of memory keeping the result of task %" PRId64, m.id);
}

/* Collect every verdict the checker has reached. */
void sv_collect_checked(tf_supervisor *s)
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
