/* paint_role.c: Raypaint's leases, role, hooks and results (paint_role.h). */
#include "coordinator/paint/paint_role.h"

#include <assert.h>
#include <inttypes.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "farmproto.h"
#include "log.h"

/* ---- the leases ---- */

static tf_paint_lease *find_lease(tf_paint_role *r, int64_t id)
{
    for (int i = 0; i < r->nleases; i++)
        if (r->leases[i].id == id)
            return &r->leases[i];
    return NULL;
}

static void drop_lease(tf_paint_role *r, tf_paint_lease *l)
{
    free(l->nodes);
    *l = r->leases[--r->nleases];
}

/* Its cells wait again (it will not be answered), and it is forgotten. */
static void requeue_lease(tf_paint_role *r, tf_paint_lease *l)
{
    if (r->tree)
        tf_paint_tree_requeue(r->tree, l->nodes, l->count);
    drop_lease(r, l);
}

static int add_lease(tf_paint_role *r, int64_t id, const tf_paint_node *nodes, int count)
{
    if (r->nleases == r->cap) {
        int cap = r->cap ? 2 * r->cap : 16;
        tf_paint_lease *l = realloc(r->leases, (size_t)cap * sizeof *l);
        if (!l)
            return -1;
        r->leases = l;
        r->cap = cap;
    }
    tf_paint_node *copy = malloc((size_t)count * sizeof *copy);
    if (!copy)
        return -1;
    memcpy(copy, nodes, (size_t)count * sizeof *copy);
    r->leases[r->nleases++] = (tf_paint_lease){id, 0, 0, 0, count, copy};
    return 0;
}

/* ---- the role's guards ---- */

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

/* Only the stop task goes back into the space. */
static ts_cap_verdict stop_only(void *ctx, uint64_t conn, int op, int blocking,
                                const tf_tuple *t, char *why, size_t len)
{
    (void)ctx, (void)conn, (void)op, (void)blocking;
    tf_paint_task_msg m;
    if (tf_paint_task_unpack(t, &m) || m.gen >= 0)
        return refuse(why, len, "a paint task put back that is not the stop task");
    return TS_CAP_ALLOW;
}

static ts_cap_verdict admit_result(void *ctx, uint64_t conn, int op, int blocking,
                                   const tf_tuple *t, char *why, size_t len)
{
    (void)op, (void)blocking;
    tf_paint_role *r = ctx;
    tf_paint_result_msg m;
    if (tf_paint_result_unpack(t, &m))
        return refuse(why, len, "malformed paint result");
    if (m.gen >= 0 && m.gen < r->gen) {
        r->stale++;
        return TS_CAP_DISCARD; /* of a view the page has left: never drawn */
    }
    tf_paint_lease *l = m.gen == r->gen ? find_lease(r, m.id) : NULL;
    if (l && l->conn == conn && !l->answered)
        return TS_CAP_ALLOW;
    if (!l && m.gen == r->gen && m.id > 0 && m.id < r->next_id) {
        r->stale++;
        return TS_CAP_DISCARD; /* late: its lease expired or went back with its connection */
    }
    return refuse(why, len, "a result for paint task %" PRId64 " of view %" PRId64
                  ", which this connection does not hold", m.id, m.gen);
}

static const ts_cap_rule rules[] = {
    {TS_CAP_RD, TF_TAG_SCENE, TF_SCENE_FIELDS, 0, NULL},
    {TS_CAP_RD, "heightmap", 4, 0, NULL},
    {TS_CAP_RD, "heightmap_chunk", 3, 0, NULL},
    {TS_CAP_RD, "eroded", 4, 0, NULL},
    {TS_CAP_RD, "eroded_chunk", 3, 0, NULL},
    {TS_CAP_RD, TF_TAG_PAINT_VIEW, TF_PAINT_VIEW_FIELDS, 0, NULL},
    {TS_CAP_IN, TF_TAG_NEXT_WORKER, TF_NEXT_WORKER_FIELDS, 1, NULL},
    {TS_CAP_OUT, TF_TAG_HELLO, TF_HELLO_FIELDS, 1, NULL},
    {TS_CAP_IN, TF_TAG_PAINT_TASK, TF_PAINT_TASK_FIELDS, 0, NULL},
    {TS_CAP_OUT, TF_TAG_PAINT_TASK, TF_PAINT_TASK_FIELDS, 0, stop_only},
    {TS_CAP_OUT, TF_TAG_PAINT_RESULT, TF_PAINT_RESULT_FIELDS, 0, admit_result},
};

void tf_paint_role_init(tf_paint_role *r, ts_space *space, int w, int h,
                        const tf_paint_params *p)
{
    memset(r, 0, sizeof *r);
    r->space = space;
    r->w = w;
    r->h = h;
    r->next_id = 1;
    r->next_worker = 1;
    r->role.name = "paint worker";
    r->role.rules = rules;
    r->role.nrules = (int)(sizeof rules / sizeof rules[0]);
    r->role.guard_ctx = r;
    /* the largest answer: a task's rays' worth of exact pixels, and one more node */
    size_t node = (size_t)p->root * (size_t)p->root + 4 * (size_t)p->root + 1;
    r->role.max_tuple_bytes = ((size_t)p->task_rays + node) * TF_PAINT_PIXEL_FLOATS * 4 + 65536;
}

void tf_paint_role_free(tf_paint_role *r)
{
    while (r->nleases > 0)
        drop_lease(r, &r->leases[0]);
    free(r->leases);
    free(r->hellos);
    r->leases = NULL;
    r->hellos = NULL;
}

/* ---- the hooks ---- */

static void on_take(void *ctx, uint64_t conn, const tf_tuple *t)
{
    tf_paint_role *r = ctx;
    const char *name = tf_tuple_name(t);
    tf_paint_task_msg m;
    if (name && !strcmp(name, TF_TAG_NEXT_WORKER)) { /* Linda's counter, put back by us */
        tf_tuple next;
        if (tf_next_worker_pack(&next, ++r->next_worker) || ts_space_out(r->space, &next))
            tf_warn("out of memory: no more paint workers can join");
    } else if (name && !strcmp(name, TF_TAG_PAINT_TASK) && !tf_paint_task_unpack(t, &m) &&
               m.gen == r->gen) {
        tf_paint_lease *l = find_lease(r, m.id);
        if (l) {
            l->conn = conn;
            l->taken_s = tf_now_s();
        }
    }
}

static void on_out(void *ctx, uint64_t conn, const tf_tuple *t)
{
    tf_paint_role *r = ctx;
    const char *name = tf_tuple_name(t);
    tf_paint_result_msg m;
    if (name && !strcmp(name, TF_TAG_HELLO)) {
        if (r->workers == r->hellos_cap) {
            int cap = r->hellos_cap ? 2 * r->hellos_cap : 16;
            uint64_t *h = realloc(r->hellos, (size_t)cap * sizeof *h);
            if (!h)
                return;
            r->hellos = h;
            r->hellos_cap = cap;
        }
        r->hellos[r->workers++] = conn;
    } else if (name && !strcmp(name, TF_TAG_PAINT_RESULT) && !tf_paint_result_unpack(t, &m)) {
        tf_paint_lease *l = find_lease(r, m.id);
        if (l && m.gen == r->gen)
            l->answered = 1;
    }
}

static void on_disconnect(void *ctx, uint64_t conn, const char *peer)
{
    (void)peer;
    tf_paint_role *r = ctx;
    for (int i = 0; i < r->workers; i++)
        if (r->hellos[i] == conn) {
            r->hellos[i] = r->hellos[--r->workers];
            break;
        }
    for (int i = r->nleases - 1; i >= 0; i--)
        if (r->leases[i].conn == conn && !r->leases[i].answered)
            requeue_lease(r, &r->leases[i]);
}

ts_server_hooks tf_paint_role_hooks(tf_paint_role *r)
{
    return (ts_server_hooks){r, on_take, on_out, on_disconnect};
}

/* ---- views and dealing ---- */

void tf_paint_role_new_view(tf_paint_role *r, int64_t gen, tf_paint_tree *tree)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    if (tf_tuple_pack(&tmpl, "siIB", TF_TAG_PAINT_TASK, r->gen) == 0)
        for (tf_tuple_init(&got); ts_space_inp(r->space, &tmpl, &got) == 1; tf_tuple_init(&got))
            tf_tuple_clear(&got);
    tf_tuple_clear(&tmpl);
    if (tf_tuple_pack(&tmpl, "siSS", TF_TAG_PAINT_VIEW, r->gen) == 0 &&
        ts_space_inp(r->space, &tmpl, &got) == 1)
        tf_tuple_clear(&got);
    tf_tuple_clear(&tmpl);
    while (r->nleases > 0)
        drop_lease(r, &r->leases[0]);
    r->gen = gen;
    r->tree = tree;
}

/* Leases held too long: taken back (their late results are refused as not held). */
static void expire_leases(tf_paint_role *r)
{
    double now = tf_now_s();
    for (int i = r->nleases - 1; i >= 0; i--) {
        tf_paint_lease *l = &r->leases[i];
        if (l->conn && !l->answered && now - l->taken_s > TF_PAINT_LEASE_S) {
            tf_warn("%s held paint task %" PRId64 " for %.0f s: dealt again",
                    r->srv ? ts_server_peer(r->srv, l->conn) : "a worker", l->id,
                    now - l->taken_s);
            r->expired++;
            requeue_lease(r, l);
        }
    }
}

void tf_paint_role_deal(tf_paint_role *r, tf_paint_tree *tree)
{
    static tf_paint_node nodes[TF_PAINT_MAX_NODES];
    expire_leases(r);
    int watermark = 2 * (r->workers > 0 ? r->workers : 1) + 1;
    while (r->nleases < watermark) {
        int count = tf_paint_tree_next(tree, nodes, TF_PAINT_MAX_NODES);
        if (count == 0)
            return;
        tf_tuple t;
        int64_t id = r->next_id++;
        if (add_lease(r, id, nodes, count) || tf_paint_task_pack(&t, r->gen, id, nodes, count) ||
            ts_space_out(r->space, &t)) {
            tf_warn("out of memory dealing paint task %" PRId64, id);
            tf_paint_lease *l = find_lease(r, id);
            if (l)
                drop_lease(r, l);
            tf_paint_tree_requeue(tree, nodes, count);
            return;
        }
    }
}

/* ---- results ---- */

static int refuse_result(tf_paint_role *r, tf_paint_lease *l, const char *why)
{
    uint64_t conn = l->conn;
    tf_warn("%s: paint result %" PRId64 " refused: %s; its cells are dealt again",
            r->srv && conn ? ts_server_peer(r->srv, conn) : "a worker", l->id, why);
    r->refused++;
    requeue_lease(r, l);
    if (r->srv && conn)
        ts_server_close_conn(r->srv, conn); /* its other leases come back with it */
    return 0;
}

int tf_paint_role_take_result(tf_paint_role *r, tf_paint_tree *tree, const tf_tuple *t,
                              int aa_depth, float **values, size_t *cap, tf_paint_bytes *msgs)
{
    tf_paint_result_msg m;
    tf_paint_lease *l = NULL;
    if (tf_paint_result_unpack(t, &m) || m.gen != r->gen || !(l = find_lease(r, m.id))) {
        r->stale++; /* its view or its lease ended after it was admitted */
        return 0;
    }
    size_t want = tf_paint_task_values(l->nodes, l->count, r->w, r->h);
    if (want > *cap) {
        float *v = realloc(*values, want * sizeof *v);
        if (!v)
            return refuse_result(r, l, "out of memory here");
        *values = v;
        *cap = want;
    }
    char err[256];
    if (tf_paint_values_check(m.values, m.values_len, l->nodes, l->count, r->w, r->h, aa_depth,
                              *values, err, sizeof err))
        return refuse_result(r, l, err);
    if (tf_paint_tree_apply(tree, l->nodes, l->count, *values, msgs))
        tf_warn("out of memory: part of paint result %" PRId64 " is not shown", m.id);
    drop_lease(r, l);
    r->results++;
    return 1;
}

int tf_paint_role_check(const tf_paint_role *r)
{
    for (int i = 0; i < r->nleases; i++) {
        assert(r->leases[i].count > 0 && r->leases[i].id < r->next_id &&
               "L1: a lease is a task dealt in this view");
        assert((r->leases[i].conn == 0 || r->srv) && "L2: a held lease names a connection");
    }
    assert(r->workers >= 0 && r->workers <= r->hellos_cap && "L3: workers counts open hellos");
    return 1;
}
