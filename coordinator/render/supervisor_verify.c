/* supervisor_verify.c: the supervisor's spot checks (--verify, verify.h; supervisor.c says how
 * the whole works, supervisor_internal.h what its files share): which results are checked, the
 * check copies dealt to other workers, the verdict on a second and third render, and what
 * happens to a liar: excluded with its address, its waiting results dealt again, and what it
 * already wrote taken back by rewinding the output. */
#include "coordinator/render/supervisor_internal.h"

#include <inttypes.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "coordinator/render/events.h"
#include "log.h"

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

void sv_start_check(tf_supervisor *s, task_slot *t, const tf_result_msg *m)
{
    if (s->cfg.verify_fraction <= 0)
        return;
    tf_worker_stats *w = sv_worker_by_id(s, m->worker);
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
    sv_deal_copy(s, t);
}

/* Deal the check copies of pending checks once a second worker is there to render them. */
void sv_start_pending_checks(tf_supervisor *s)
{
    if (s->pending_checks == 0 || tf_supervisor_live_workers(s) < 2)
        return;
    for (int64_t id = s->write_task; id < s->next_deal && s->pending_checks > 0; id++) {
        task_slot *t = sv_slot_of(s, id);
        if (!t || t->check != CHECK_PENDING)
            continue;
        s->pending_checks--;
        t->check = CHECK_SECOND;
        t->in_space++;
        sv_deal_copy(s, t);
    }
    s->told_pending = 0;
}

/* "10.0.0.7:5123" -> "10.0.0.7"; labels without a port ("local worker 2") stay whole. */
static void address_of(const char *peer, char *addr, size_t len)
{
    snprintf(addr, len, "%s", peer);
    char *colon = strrchr(addr, ':');
    if (colon && (addr[0] != '[' || colon[-1] == ']'))
        *colon = '\0';
}

int sv_address_excluded(const tf_supervisor *s, const char *peer)
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

/* The liar's first written task in the write job j (-1 when it wrote none there);
 * *before: how many it wrote before that, in frames already finished. */
static int64_t first_written_in_job(const tf_supervisor *s, const tf_worker_stats *w,
                                    const job_state *j, int64_t *before)
{
    *before = 0;
    for (int64_t id = 0; s->written_by && id < s->write_task; id++)
        if (s->written_by[id] == w->id) {
            if (j && id >= j->first_id)
                return id;
            (*before)++;
        }
    return -1;
}

/* The write job's file reopened keeping only the chunks before task k0 (hooks.rewind).  0, or
 * -1 when the render stops (said). */
static int rewind_output(tf_supervisor *s, job_state *j, int64_t k0, const tf_worker_stats *w)
{
    int64_t keep = 0;
    int count = 0;
    char err[1024] = "cannot rewind the output";
    if (grow_ring(s, s->next_deal - k0) ||
        tf_layout_rect_chunks(&s->cfg.layout, sv_rect_of(s, k0), &keep, &count)) {
        sv_fail(s, "worker %" PRId64 " lied: cannot take back its results (out of memory)", w->id);
        return -1;
    }
    j->writer = s->cfg.hooks.rewind(s->cfg.hooks.ctx, (int)(j - s->jobs), j->writer, keep, err,
                                    sizeof err);
    if (!j->writer) {
        sv_fail(s, "%s", err);
        return -1;
    }
    tf_warn("worker %" PRId64 " lied after passing a check: taking back the %" PRId64 " tasks "
            "written since its first written result (task %" PRId64 ", row %d): the output is "
            "rewound to %" PRId64 " chunks and they are dealt again", w->id, s->write_task - k0,
            k0, sv_rect_of(s, k0).y, keep);
    tf_events_add(s->events, TF_EV_REDEAL, w->id, k0, "rewound the output to task %" PRId64
                  " to take back what a liar wrote", k0);
    return 0;
}

/* Tasks [k0, end) written no more: each slot fresh and dealt again, whoever wrote it. */
static void redeal_unwritten(tf_supervisor *s, int64_t k0, int64_t end)
{
    for (int64_t id = k0; id < end; id++) {
        task_slot *t = &s->ring[id % s->ring_size];
        memset(t, 0, sizeof *t);
        t->id = id;
        for (int i = 0; i < s->nleases; i++) /* a straggler may still hold a copy (S4) */
            t->leased += s->leases[i].task == id;
        tf_worker_stats *by = sv_worker_by_id(s, s->written_by[id]);
        if (by && by->written > 0)
            by->written--;
        s->written_by[id] = 0;
        t->in_space = 1;
        s->stats.tasks_redealt++;
        sv_deal_copy(s, t);
    }
}

/* The job's rows on disk now end where row `row` begins (none before its first row). */
static void unwrite_rows(tf_supervisor *s, job_state *j, int row)
{
    int frame = (int)(j - s->jobs);
    int rows = row > j->job.first_row ? row : j->job.first_row;
    if (rows < j->rows_written) {
        s->stats.rows_rendered -= j->rows_written - rows;
        s->stats.frames[frame].rows_rendered -= j->rows_written - rows;
        j->rows_written = rows;
    }
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
    int64_t before;
    int64_t k0 = first_written_in_job(s, w, j, &before);
    if (before > 0 || k0 < 0 || !j || !j->writer || !s->cfg.hooks.rewind) {
        sv_fail(s, "worker %" PRId64 " (%s) lied, and %" PRId64 " of its results are in a frame "
             "already finished, which cannot be taken back; render that frame again with "
             "--overwrite", w->id, w->host, w->written);
        return -1;
    }
    if (rewind_output(s, j, k0, w))
        return -1;
    int64_t old_write = s->write_task;
    s->write_task = k0;
    redeal_unwritten(s, k0, old_write);
    unwrite_rows(s, j, sv_rect_of(s, k0).y);
    w->written = 0;
    return 0;
}

/* Worker `liar` disagreed with two others about task `task`: exclude it, deal again every
 * task whose accepted result is its. */
static void exclude_liar(tf_supervisor *s, int64_t liar, int64_t task)
{
    tf_worker_stats *w = sv_worker_by_id(s, liar);
    if (!w || w->excluded)
        return;
    w->excluded = 1;
    s->stats.workers_excluded++;
    const char *peer = w->conn ? sv_peer_name(s, w->conn) : "gone";
    if (w->conn && s->nexcluded_addr < 32)
        address_of(peer, s->excluded_addr[s->nexcluded_addr++], sizeof s->excluded_addr[0]);
    tf_warn("worker %" PRId64 " (%s, %s) lied: its result of task %" PRId64 " differs from two "
            "other workers'; excluded, and every task it rendered is dealt again",
            liar, w->host, peer, task);
    if (w->written > 0 && rewind_liar(s, w))
        return;
    int redealt = 0;
    for (int64_t id = s->write_task; id < s->next_deal; id++) {
        task_slot *t = sv_slot_of(s, id);
        if (!t || !t->has_result || t->result_worker != liar || t->replacing)
            continue;
        tf_tuple tmpl, got;
        tf_tuple_init(&got);
        if (tf_result_template(&tmpl, id, liar) == 0 && ts_space_inp(s->space, &tmpl, &got) == 1)
            tf_tuple_clear(&got);
        tf_tuple_clear(&tmpl);
        sv_withdraw_copies(s, t);
        t->has_result = 0;
        if (t->check == CHECK_PENDING)
            s->pending_checks--;
        t->check = CHECK_NONE;
        t->in_space++;
        s->stats.tasks_redealt++;
        sv_deal_copy(s, t);
        redealt++;
    }
    if (redealt)
        tf_info("re-dealing %d task%s rendered by worker %" PRId64, redealt,
                redealt == 1 ? "" : "s", liar);
    if (w->conn)
        ts_server_close_conn(s->srv, w->conn);
}

/* Worker id's result agreed with another's: it has passed a check (unknown ids: nothing). */
static void mark_checked(tf_supervisor *s, int64_t id)
{
    tf_worker_stats *w = sv_worker_by_id(s, id);
    if (w)
        w->checked = 1;
}

/* The second copy's digest d, from worker m->worker: the same bytes as the first pass both; else
 * a third worker decides. */
static ts_cap_verdict second_copy(tf_supervisor *s, task_slot *t, const tf_result_msg *m,
                                  const uint8_t *d)
{
    if (sodium_memcmp(d, t->digest[0], TF_DIGEST_BYTES) == 0) {
        mark_checked(s, t->check_worker[0]);
        mark_checked(s, m->worker);
        t->check = CHECK_NONE;
        sv_withdraw_copies(s, t);
        return TS_CAP_DISCARD;
    }
    s->stats.verify_mismatches++;
    tf_warn("task %" PRId64 ": workers %" PRId64 " and %" PRId64 " rendered different bytes; "
            "a third worker decides", t->id, t->check_worker[0], m->worker);
    t->check = CHECK_THIRD;
    t->check_worker[1] = m->worker;
    memcpy(t->digest[1], d, TF_DIGEST_BYTES);
    sv_withdraw_copies(s, t);
    t->in_space++;
    sv_deal_copy(s, t);
    return TS_CAP_DISCARD;
}

/* The first result, stored, was the lie: it leaves the space, and no longer counts as its
 * worker's; the third's, which agrees with the second, takes its place (TS_CAP_ALLOW). */
static ts_cap_verdict replace_first(tf_supervisor *s, task_slot *t)
{
    t->replacing = 1;
    tf_tuple tmpl, got;
    tf_tuple_init(&got);
    if (tf_result_template(&tmpl, t->id, t->check_worker[0]) == 0 &&
        ts_space_inp(s->space, &tmpl, &got) == 1)
        tf_tuple_clear(&got);
    tf_tuple_clear(&tmpl);
    tf_worker_stats *first = sv_worker_by_id(s, t->check_worker[0]);
    if (first && first->written == 0 && first->tasks > 0)
        first->tasks--;
    exclude_liar(s, t->check_worker[0], t->id);
    return TS_CAP_ALLOW;
}

/* The third copy's digest d decides: with the first, the second lied; with the second, the
 * first did; with neither, a pixel depends on more than the scene and the render stops. */
static ts_cap_verdict third_copy(tf_supervisor *s, task_slot *t, const tf_result_msg *m,
                                 const uint8_t *d)
{
    sv_withdraw_copies(s, t);
    t->check = CHECK_NONE;
    if (sodium_memcmp(d, t->digest[0], TF_DIGEST_BYTES) == 0) {
        mark_checked(s, t->check_worker[0]);
        mark_checked(s, m->worker);
        exclude_liar(s, t->check_worker[1], t->id);
        return TS_CAP_DISCARD;
    }
    if (sodium_memcmp(d, t->digest[1], TF_DIGEST_BYTES) == 0) {
        mark_checked(s, m->worker);
        mark_checked(s, t->check_worker[1]);
        return replace_first(s, t);
    }
    sv_fail(s, "task %" PRId64 ": workers %" PRId64 ", %" PRId64 " and %" PRId64 " rendered three "
         "different results; a pixel should depend only on the scene: stopping", t->id,
         t->check_worker[0], t->check_worker[1], m->worker);
    return TS_CAP_DISCARD;
}

/* A result for a task whose check copy is out, from a worker that has not rendered it: decide.
 * The result is never stored except when it replaces a lying first one (TS_CAP_ALLOW). */
ts_cap_verdict sv_admit_check(tf_supervisor *s, uint64_t conn, task_slot *t,
                              const tf_result_msg *m)
{
    uint8_t d[TF_DIGEST_BYTES];
    tf_result_digest(m, d);
    sv_remove_lease(s, conn, t->id);
    s->stats.verify_busy_s += (double)m->busy_ns * 1e-9;
    return t->check == CHECK_SECOND ? second_copy(s, t, m, d) : third_copy(s, t, m, d);
}
