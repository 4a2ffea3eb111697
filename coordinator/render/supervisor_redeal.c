/* supervisor_redeal.c: how the supervisor gets a task done when its copy does not come back
 * (supervisor.c says how the whole works; supervisor_internal.h what its files share).  A
 * worker's failure of a task is remembered (and stops the render once the task has failed
 * everywhere); a lost copy is dealt again; a finished task's waiting copies are withdrawn; a
 * straggler gets a second copy dealt to an idle worker; and the auto watermark follows the
 * number of workers connected. */
#include "coordinator/render/supervisor_internal.h"

#include <inttypes.h>

#include "clock.h"
#include "coordinator/render/events.h"
#include "log.h"

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

/* Times worker `id` failed task t (as far as t remembers). */
static int failures_of(const task_slot *t, int64_t id)
{
    for (int k = 0; k < t->nfailed; k++)
        if (t->failed_worker[k] == id)
            return t->failed_count[k];
    return 0;
}

/* 1 if the connected workers in good standing are all ones this coordinator forked (no
 * client's connections among them) and each is no longer dealt task t. */
static int forked_workers_all_excluded(const tf_supervisor *s, const task_slot *t)
{
    int any = 0;
    for (int i = 0; i < s->stats.nworkers; i++) {
        const tf_worker_stats *w = &s->stats.workers[i];
        if (!w->conn || w->excluded)
            continue;
        if (!w->forked_conn || failures_of(t, w->id) < FAILURES_TO_EXCLUDE)
            return 0;
        any = 1;
    }
    return any;
}

/* Record that `worker` failed task t; returns 1 if the task has now failed everywhere. */
int sv_note_failure(tf_supervisor *s, task_slot *t, int64_t worker)
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
     * stops at MAX_TASK_FAILURES instead of dealing it round forever.  Workers this coordinator
     * forked are no client's connections: when they are all the farm has and none may be dealt
     * the task any more, it has failed everywhere too (else two of them, each excluded, left
     * the task to bounce between them forever, the render hung). */
    if ((t->nfailed >= s->cfg.max_task_failures &&
         (t->failures >= MAX_TASK_FAILURES || !untried_worker_left(s, t))) ||
        forked_workers_all_excluded(s, t)) {
        char what[128];
        sv_fail(s, "%s failed on %d different workers; stopping (rows written so far are kept: "
                "rerun with --resume)",
             sv_describe_task(s, t->id, what, sizeof what), t->nfailed);
        return 1;
    }
    return 0;
}

/* A copy of task t was lost (its worker died or gave up): deal it again if no copy is left. */
void sv_redeal_if_lost(tf_supervisor *s, task_slot *t)
{
    if ((t->has_result && (!t->check || t->check == CHECK_PENDING)) || t->checking ||
        t->in_space > 0 || t->leased > 0 || s->error[0])
        return;
    t->in_space++;
    s->stats.tasks_redealt++;
    char what[128];
    sv_describe_task(s, t->id, what, sizeof what);
    tf_info("re-dealing %s", what);
    tf_events_add(s->events, TF_EV_REDEAL, -1, t->id, "%s dealt again", what);
    sv_deal_copy(s, t);
}

/* Remove any task tuples of a finished task still waiting in the space.  Nearly every task
 * has none left by its result (a worker took its one copy): then no template is built. */
void sv_withdraw_copies(tf_supervisor *s, task_slot *t)
{
    tf_tuple tmpl, got;
    if (t->in_space <= 0 || tf_task_template(&tmpl, t->id))
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

/* ---- stragglers ------------------------------------------------------------------------------- */

int sv_stragglers_matter(tf_supervisor *s)
{
    ts_space_stats st;
    ts_space_get_stats(s->space, &st);
    if (st.waiters == 0)
        return 0;
    return !(s->next_deal < s->total_tasks && s->next_deal - s->write_task < s->watermark);
}

/* Workers are idle and nothing fresh can be dealt (the image is all dealt, or the watermark
 * holds dealing back behind a slow task): deal a second copy of the oldest task that has been
 * held for several mean task times.  Bounded (MAX_DUPLICATES_IN_FLIGHT), because a worker busy
 * on a duplicate cannot take the fresh tasks that appear once the original comes back. */
void sv_deal_duplicate(tf_supervisor *s)
{
    if (s->dups_in_flight >= MAX_DUPLICATES_IN_FLIGHT || s->results_seen == 0)
        return;
    /* It scans every outstanding task: not on every step (thousands a second with hundreds of
     * workers), a few times within the shortest patience instead. */
    double now = tf_now_msf();
    if (now - s->last_straggler_scan_ms < STRAGGLER_SCAN_MS)
        return;
    s->last_straggler_scan_ms = now;
    if (!sv_stragglers_matter(s))
        return;
    for (int64_t id = s->write_task; id < s->next_deal; id++) {
        task_slot *t = sv_slot_of(s, id);
        if (t && t->in_space > 0 && !t->has_result)
            return; /* an undealt copy is waiting: idle workers will take it */
    }
    double patience = STRAGGLER_FACTOR * s->mean_task_ms;
    if (patience < STRAGGLER_MIN_MS)
        patience = STRAGGLER_MIN_MS;
    for (int64_t id = s->write_task; id < s->next_deal; id++) {
        task_slot *t = sv_slot_of(s, id);
        if (!t || t->has_result || t->duplicated || t->leased == 0 || now - t->taken_ms < patience)
            continue;
        t->duplicated = 1;
        t->in_space++;
        s->dups_in_flight++;
        s->stats.tasks_duplicated++;
        tf_debug("straggler: task %" PRId64 " held %.0f ms (mean task %.0f ms); dealing a second "
                 "copy", id, now - t->taken_ms, s->mean_task_ms);
        sv_deal_copy(s, t);
        return;
    }
}

/* The auto watermark: one band plus tf_tasks_auto_ahead's tasks for the connected (or
 * expected) workers. */
void sv_update_watermark(tf_supervisor *s)
{
    if (!s->auto_watermark)
        return;
    int workers = tf_supervisor_live_workers(s);
    if (workers < s->cfg.expected_workers)
        workers = s->cfg.expected_workers;
    if (workers > AUTO_WM_MAX_WORKERS)
        workers = AUTO_WM_MAX_WORKERS;
    int wm = s->band_tasks + tf_tasks_auto_ahead(&s->jobs[0].tasks, workers);
    if (wm > s->ring_size)
        wm = s->ring_size;
    s->watermark = wm;
    if (wm > s->stats.watermark)
        s->stats.watermark = wm;
}
