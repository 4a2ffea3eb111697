/* supervisor_deal.c: the supervisor's dealing (supervisor.c says how the whole works; its state
 * and what its files share are in supervisor_internal.h).  Leases record which connection holds
 * which task copy; tasks are dealt in id order up to the watermark, each copy carrying the
 * workers it must avoid, the output of a frame job opened as its first task is dealt; and with
 * --affinity the space's chooser ranks the waiting tasks for each worker by its column range. */
#include "coordinator/render/supervisor_internal.h"

#include <assert.h>
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "log.h"

/* ---- leases: who holds which task copy ---- */

/* A connection holds at most one lease: the worker role refuses a second `in` of a task while
 * it holds one (tf_supervisor_admit), and every connection has that role.  So the index maps a
 * connection to the one entry of `leases` it holds (S8). */

/* The index in leases of conn's lease, or -1. */
int sv_lease_of(const tf_supervisor *s, uint64_t conn)
{
    int64_t v;
    return tf_idmap_get(&s->lease_of_conn, conn, &v) ? (int)v : -1;
}

/* The index in leases of conn's lease of task, or -1. */
int sv_find_lease(const tf_supervisor *s, uint64_t conn, int64_t task)
{
    int i = sv_lease_of(s, conn);
    return i >= 0 && s->leases[i].task == task ? i : -1;
}

/* 1 and the task in *task if conn holds a lease, else 0. */
int sv_held_task(const tf_supervisor *s, uint64_t conn, int64_t *task)
{
    int i = sv_lease_of(s, conn);
    if (i < 0)
        return 0;
    *task = s->leases[i].task;
    return 1;
}

int sv_add_lease(tf_supervisor *s, uint64_t conn, int64_t task)
{
    assert(sv_lease_of(s, conn) < 0);
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
int64_t sv_remove_lease_at(tf_supervisor *s, int i)
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

void sv_remove_lease(tf_supervisor *s, uint64_t conn, int64_t task)
{
    int i = sv_find_lease(s, conn, task);
    if (i < 0)
        return;
    sv_remove_lease_at(s, i);
    task_slot *t = sv_slot_of(s, task);
    if (t && t->leased > 0)
        t->leased--;
}

/* The task as the supervisor deals it now: its rectangle and the workers it must avoid. */
void sv_task_msg_of(const tf_supervisor *s, const task_slot *t, tf_task_msg *m)
{
    memset(m, 0, sizeof *m);
    m->id = t->id;
    m->frame = sv_job_of(s, t->id)->job.frame;
    m->rect = sv_rect_of(s, t->id);
    for (int i = 0; i < t->nfailed && m->nexcluded < TF_EXCLUDED_MAX; i++)
        if (t->failed_count[i] >= FAILURES_TO_EXCLUDE)
            m->excluded[m->nexcluded++] = t->failed_worker[i];
    /* a check copy goes to a worker that has not rendered it yet (a pending check deals none) */
    int checked_by = t->check == CHECK_PENDING ? 0 : t->check;
    for (int i = 0; i < checked_by && m->nexcluded < TF_EXCLUDED_MAX; i++)
        m->excluded[m->nexcluded++] = t->check_worker[i];
}

/* Put a task tuple for `id` in the space, carrying the workers it must avoid. */
int sv_deal_copy(tf_supervisor *s, task_slot *t)
{
    tf_task_msg m;
    sv_task_msg_of(s, t, &m);
    tf_tuple tup;
    if (tf_task_pack(&tup, &m) || ts_space_out(s->space, &tup)) {
        sv_fail(s, "out of memory dealing task %" PRId64, t->id);
        return -1;
    }
    /* ts_space_out may have handed it straight to a blocked worker: on_take has then already
     * moved the copy from in_space to leased, so count it as in the space first. */
    return 0;
}

/* Job j's first task is about to be dealt (or it has none): its output must exist. */
int sv_open_job(tf_supervisor *s, job_state *j)
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
        sv_fail(s, "%s", err);
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

void sv_deal_new_tasks(tf_supervisor *s)
{
    if (waiting_for_workers(s))
        return;
    while (!s->error[0] && s->next_deal < s->total_tasks &&
           s->next_deal - s->write_task < s->watermark) {
        job_state *j = sv_job_of(s, s->next_deal);
        if (s->next_deal == j->first_id && sv_open_job(s, j))
            return;
        int64_t id = s->next_deal++;
        task_slot *t = &s->ring[id % s->ring_size];
        memset(t, 0, sizeof *t);
        t->id = id;
        t->in_space = 1;
        int outstanding = (int)(s->next_deal - s->write_task);
        if (outstanding > s->stats.max_outstanding_tasks)
            s->stats.max_outstanding_tasks = outstanding;
        sv_deal_copy(s, t);
    }
}

/* ---- affinity (affinity.h): which of the waiting tasks a worker gets ----------------------- */

/* 1 if task id's copies are dealt excluding worker (sv_task_msg_of): it would only put it back. */
static int excludes(tf_supervisor *s, int64_t id, int64_t worker)
{
    const task_slot *t = sv_slot_of(s, id);
    if (!t || (t->nfailed == 0 && (t->check == CHECK_NONE || t->check == CHECK_PENDING)))
        return 0;
    tf_task_msg m;
    sv_task_msg_of(s, t, &m);
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
    tf_worker_stats *w = sv_worker_by_conn(s, taker);
    if (!w)
        return 0;
    if (excludes(s, id, w->id))
        return UINT64_MAX;
    return tf_affinity_rank(s->affinity, w->id, sv_rect_of(s, id), id);
}

/* Worker w said hello (joined, 1) or its connection closed (0): the ranges follow. */
void sv_affinity_member(tf_supervisor *s, const tf_worker_stats *w, int joined)
{
    if (!s->affinity)
        return;
    if (!joined)
        tf_affinity_leave(s->affinity, w->id);
    else if (tf_affinity_join(s->affinity, w->id))
        sv_fail(s, "out of memory giving worker %" PRId64 " its column range", w->id);
}

/* The worker on conn took task id: count where it lay for it, and keep the range it had. */
void sv_count_choice(tf_supervisor *s, uint64_t conn, int64_t id)
{
    tf_worker_stats *w = s->affinity ? sv_worker_by_conn(s, conn) : NULL;
    if (!w)
        return;
    tf_affinity_range(s->affinity, w->id, &w->aff_x0, &w->aff_x1);
    tf_rect r = sv_rect_of(s, id);
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
int sv_start_affinity(tf_supervisor *s, char *err, size_t errlen)
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
