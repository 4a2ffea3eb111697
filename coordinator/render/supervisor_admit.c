/* supervisor_admit.c: the supervisor's admission of a worker's requests, before the space sees
 * them (tf_supervisor_admit, the guard of the worker role, worker_role.c; supervisor.c says how
 * the whole works, supervisor_internal.h what its files share).  Joins, hellos, takes, task
 * returns, results and failures are checked against the worker id bound to the connection and
 * the leases it holds; a result must answer a task it holds and pass the checks that cost
 * nothing per pixel, and a check copy's result goes to the spot checks. */
#include "coordinator/render/supervisor_internal.h"

#include <inttypes.h>
#include <stdarg.h>
#include <string.h>

#include "clock.h"
#include "log.h"

/* ---- admission: the farm's checks on a worker's requests, before the space sees them ------
 * The guard of the worker role (coordinator/render/worker_role.c).  Everything a worker sends is
 * checked against what the supervisor knows: the worker id bound to its connection when it
 * took the counter, the leases it holds, the task a result answers.  A refusal changes nothing
 * (the server replies ERROR and logs it); a request that breaks the rules on a task the
 * connection holds also forfeits that lease, so the task is dealt again at once. */

static int holds_lease(const tf_supervisor *s, uint64_t conn, int64_t task)
{
    return sv_find_lease(s, conn, task) >= 0;
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
    int i = sv_find_lease(s, conn, m->id);
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
    task_slot *t = sv_slot_of(s, m.id);
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
        sv_remove_lease(s, conn, m.id);
        if (t)
            sv_redeal_if_lost(s, t);
        s->stats.results_dropped++;
        return TS_CAP_DISCARD;
    }
    tf_rect r = sv_rect_of(s, m.id);
    char reason[192];
    if (sv_refuse_result(s, &m, r, reason, sizeof reason) ||
        busy_beyond_lease(s, conn, &m, reason, sizeof reason)) {
        /* Dropped before it enters the space, counted against its worker, dealt again. */
        s->stats.results_refused++;
        sv_remove_lease(s, conn, m.id);
        if (!sv_note_failure(s, t, w->id))
            sv_redeal_if_lost(s, t);
        return refuse(why, len, "result of task %" PRId64 " (%dx%d at %d,%d): %s", m.id, r.w,
                      r.h, r.x, r.y, reason);
    }
    if (checking)
        return sv_admit_check(s, conn, t, &m);
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
    task_slot *t = sv_slot_of(s, m.id);
    tf_rect r = sv_rect_of(s, m.id);
    int altered = m.rect.x != r.x || m.rect.y != r.y || m.rect.w != r.w || m.rect.h != r.h ||
                  m.frame != sv_job_of(s, m.id)->job.frame;
    int excl_altered = 0;
    if (t) {
        /* A copy dealt earlier may list fewer workers (failures since), never others. */
        tf_task_msg now;
        sv_task_msg_of(s, t, &now);
        for (int i = 0; i < m.nexcluded; i++)
            excl_altered |= !tf_task_excludes(&now, m.excluded[i]);
    }
    sv_remove_lease(s, conn, m.id);
    if (t && (!t->has_result || (t->check && t->check != CHECK_PENDING))) {
        /* a task, or its check copy */
        t->in_space++;
        sv_deal_copy(s, t);
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

/* ("next_worker", ?n): a connection joins once, and not from an address whose worker failed a
 * spot check. */
static ts_cap_verdict admit_join(tf_supervisor *s, uint64_t conn, const tf_worker_stats *w,
                                 char *why, size_t len)
{
    if (w)
        return refuse(why, len, "joins twice (already worker %" PRId64 ")", w->id);
    if (s->nexcluded_addr > 0 && sv_address_excluded(s, sv_peer_name(s, conn)))
        return refuse(why, len, "joins from an address whose worker failed a spot check");
    return TS_CAP_ALLOW;
}

/* A hello names the worker it comes from. */
static ts_cap_verdict admit_hello(const tf_worker_stats *w, const tf_tuple *tuple, char *why,
                                  size_t len)
{
    tf_hello_msg m;
    if (tf_hello_unpack(tuple, &m))
        return refuse(why, len, "malformed hello tuple");
    if (m.worker != w->id)
        return refuse(why, len, "hello as worker %" PRId64 " from worker %" PRId64, m.worker,
                      w->id);
    return TS_CAP_ALLOW;
}

/* The take of a task: any task, never one chosen by id or place (a client may not pick the
 * task it wants to fail or to sit on), and one at a time. */
static ts_cap_verdict admit_take(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple,
                                 char *why, size_t len)
{
    for (int i = 1; i < tuple->nfields; i++)
        if (!tuple->f[i].formal)
            return refuse(why, len, "takes a task by a template with actual fields (only "
                          "(\"task\", ?id, ?x, ?y, ?w, ?h, ?excluded) is a worker's)");
    int64_t held = -1;
    if (sv_held_task(s, conn, &held))
        return refuse(why, len, "takes another task while holding task %" PRId64
                      " (one at a time)", held);
    return TS_CAP_ALLOW;
}

/* A failure report: from the worker it names, of a task its connection holds. */
static ts_cap_verdict admit_failed(tf_supervisor *s, uint64_t conn, const tf_worker_stats *w,
                                   const tf_tuple *tuple, char *why, size_t len)
{
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

ts_cap_verdict tf_supervisor_admit(void *ctx, uint64_t conn, int op, int blocking,
                                   const tf_tuple *tuple, char *why, size_t len)
{
    (void)blocking;
    tf_supervisor *s = ctx;
    const char *name = tf_tuple_name(tuple);
    tf_worker_stats *w = sv_worker_by_conn(s, conn);
    if (!strcmp(name, TF_TAG_NEXT_WORKER))
        return admit_join(s, conn, w, why, len);
    if (!w)
        return refuse(why, len, "%s (\"%s\", ...) before joining (take (\"next_worker\", ?n) "
                      "first)", ts_cap_op_name(op), name);
    if (w->excluded)
        return refuse(why, len, "worker %" PRId64 " is excluded (it failed a spot check)", w->id);
    if (!strcmp(name, TF_TAG_HELLO))
        return admit_hello(w, tuple, why, len);
    if (!strcmp(name, TF_TAG_TASK))
        return op == TS_CAP_IN ? admit_take(s, conn, tuple, why, len)
                               : admit_task_return(s, conn, tuple, why, len);
    if (!strcmp(name, TF_TAG_RESULT))
        return admit_result(s, conn, w, tuple, why, len);
    if (!strcmp(name, TF_TAG_FAILED))
        return admit_failed(s, conn, w, tuple, why, len);
    return refuse(why, len, "%s (\"%s\", ...) is not a worker's", ts_cap_op_name(op), name);
}
