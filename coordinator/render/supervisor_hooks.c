/* supervisor_hooks.c: the tuple-space server's hooks into the supervisor (tf_supervisor_hooks;
 * supervisor.c says how the whole works, supervisor_internal.h what its files share): a take
 * (a worker joining through the counter, or taking a task copy under a lease), an out (a result,
 * a task put back, a hello, a failure), and a connection closing, whose lease is then lost and
 * its task dealt again. */
#include "coordinator/render/supervisor_internal.h"

#include <inttypes.h>
#include <stdio.h>
#include <string.h>

#include "clock.h"
#include "coordinator/render/events.h"
#include "log.h"

/* ---- hooks ---------------------------------------------------------------------------------- */

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
        sv_fail(s, "out of memory putting the worker counter back");
        return;
    }
    tf_worker_stats *w = sv_add_worker(s, id);
    if (w) {
        if (!w->conn)
            s->live_workers++; /* S6 */
        sv_bind_conn(s, w, conn);
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
    task_slot *t = sv_slot_of(s, m.id);
    if (!t)
        return;
    /* May go to -1 for a moment: when a worker puts a task back (on_task_returned) and the
     * space hands it straight to a waiting worker, on_take for the taker runs before on_out
     * for the returner. */
    t->in_space--;
    if (sv_add_lease(s, conn, m.id)) {
        sv_fail(s, "out of memory recording a lease");
        return;
    }
    t->leased++;
    if (t->taken_ms == 0)
        t->taken_ms = tf_now_msf();
    sv_count_choice(s, conn, m.id);
}

/* A worker put a task back (it is excluded from it): the copy is in the space again. */
static void on_task_returned(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_task_msg m;
    if (tf_task_unpack(tuple, &m) || m.id < 0)
        return;
    task_slot *t = sv_slot_of(s, m.id);
    sv_remove_lease(s, conn, m.id);
    if (t)
        t->in_space++;
}

static void on_hello(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_hello_msg m;
    if (!tf_hello_unpack(tuple, &m)) {
        tf_worker_stats *w = sv_add_worker(s, m.worker);
        if (w) {
            s->joined_workers += !w->hello; /* its first hello */
            w->hello = 1;
            snprintf(w->kind, sizeof w->kind, "%s", m.kind);
            snprintf(w->host, sizeof w->host, "%s", m.host);
            snprintf(w->backend, sizeof w->backend, "%s", m.backend);
            if (!w->conn)
                s->live_workers++;
            sv_bind_conn(s, w, conn);
            sv_affinity_member(s, w, 1);
            const char *peer = s->srv ? ts_server_peer(s->srv, conn) : NULL;
            tf_debug("worker %" PRId64 " joined: %s on %s (pid %" PRId64 ", %s backend, %s)",
                     m.worker, m.kind, m.host, m.pid, m.backend, peer ? peer : "?");
            tf_events_add(s->events, TF_EV_JOIN, m.worker, -1, "%s worker on %s (%s backend, %s)",
                          w->kind, w->host, w->backend, peer ? peer : "?");
        }
    }
    sv_remove_exact(s, tuple);
}

static void on_failed(tf_supervisor *s, uint64_t conn, const tf_tuple *tuple)
{
    tf_failed_msg m;
    if (!tf_failed_unpack(tuple, &m)) {
        tf_warn("worker %" PRId64 " failed task %" PRId64 ": %s", m.worker, m.id, m.message);
        tf_events_add(s->events, TF_EV_FAILURE, m.worker, m.id, "%s", m.message);
        sv_remove_lease(s, conn, m.id);
        task_slot *t = sv_slot_of(s, m.id);
        if (t && (t->has_result || !sv_note_failure(s, t, m.worker)))
            sv_redeal_if_lost(s, t); /* a failed check copy is dealt again too (S9) */
    }
    sv_remove_exact(s, tuple);
}

static void on_out(void *ctx, uint64_t conn, const tf_tuple *tuple)
{
    tf_supervisor *s = ctx;
    s->last_accepted = -1;
    const char *name = tf_tuple_name(tuple);
    if (!name)
        return;
    if (!strcmp(name, TF_TAG_RESULT))
        sv_on_result(s, conn, tuple);
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
    tf_worker_stats *w = sv_worker_by_conn(s, conn);
    int64_t worker = w ? w->id : -(int64_t)conn; /* a connection that never said hello */
    for (int i = 0; w && i < s->stats.nworkers; i++)
        if (s->stats.workers[i].conn == conn) {
            sv_bind_conn(s, &s->stats.workers[i], 0);
            s->live_workers--;
        }
    if (w) {
        sv_affinity_member(s, w, 0);
        tf_events_add(s->events, TF_EV_LEAVE, w->id, -1, "connection closed (%s)",
                      peer ? peer : "?");
    }
    int i = sv_lease_of(s, conn);
    if (i < 0)
        return;
    int64_t id = sv_remove_lease_at(s, i);
    task_slot *t = sv_slot_of(s, id);
    if (!t)
        return;
    if (t->leased > 0)
        t->leased--;
    if (t->has_result) {
        sv_redeal_if_lost(s, t); /* a check copy, if one is out: dealt again */
        return;
    }
    tf_warn("worker %s left holding task %" PRId64, peer ? peer : "?", id);
    tf_events_add(s->events, TF_EV_FAILURE, worker, id, "left holding the task");
    if (!sv_note_failure(s, t, worker))
        sv_redeal_if_lost(s, t);
}

ts_server_hooks tf_supervisor_hooks(tf_supervisor *sup)
{
    ts_server_hooks h = {sup, on_take, on_out, on_disconnect};
    return h;
}
