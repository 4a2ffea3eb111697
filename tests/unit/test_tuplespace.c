/* test_tuplespace.c: the in-process tuple store (common/linda/tuplespace.c): out/inp/rdp, FIFO
 * order, blocked requests served in arrival order (rd sees, in takes), cancel, re-entrant
 * callbacks, byte accounting, and that the (name, arity[, int]) index keeps lookups independent
 * of unrelated tuples (asserted on the comparison counter, not on time); a chooser ranks the
 * matches of a named taker's take, stored or waited for. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "linda/tuplespace.h"

static void out_task(ts_space *s, const char *name, int64_t id, double v)
{
    tf_tuple t;
    tf_tuple_init(&t);
    assert_int_equal(tf_tuple_pack(&t, "sid", name, id, v), 0);
    assert_int_equal(ts_space_out(s, &t), 0);
    assert_int_equal(t.nfields, 0); /* contents were taken */
}

static void make_tmpl(tf_tuple *m, const char *name)
{
    tf_tuple_init(m);
    assert_int_equal(tf_tuple_pack(m, "sID", name), 0);
}

static void test_out_inp_rdp_fifo(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    out_task(s, "task", 1, 0.5);
    out_task(s, "task", 2, 1.5);
    tf_tuple m, got;
    make_tmpl(&m, "task");
    assert_int_equal(ts_space_rdp(s, &m, &got), 1);
    int64_t id;
    tf_tuple_get_int(&got, 1, &id);
    assert_int_equal(id, 1);
    tf_tuple_clear(&got);
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    tf_tuple_get_int(&got, 1, &id);
    assert_int_equal(id, 1);
    tf_tuple_clear(&got);
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    tf_tuple_get_int(&got, 1, &id);
    assert_int_equal(id, 2);
    tf_tuple_clear(&got);
    assert_int_equal(ts_space_inp(s, &m, &got), 0);
    tf_tuple_clear(&m);

    /* int second-field index: look up a specific id among several */
    for (int i = 0; i < 10; i++)
        out_task(s, "result", i, i * 2.0);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "siD", "result", (int64_t)7);
    assert_int_equal(ts_space_count(s, &m), 1);
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    double v;
    tf_tuple_get_double(&got, 2, &v);
    assert_true(v == 14.0);
    tf_tuple_clear(&got);
    assert_int_equal(ts_space_inp(s, &m, &got), 0);
    tf_tuple_clear(&m);

    /* a formal-named template (the slow path) still finds tuples */
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "SiD", (int64_t)3);
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    ts_space_free(s);
}

typedef struct record {
    int calls[8];
    int64_t ids[8];
    int n;
} record;

typedef struct probe {
    record *rec;
    int who;
} probe;

static void on_tuple(void *ctx, uint64_t waiter_id, tf_tuple *t)
{
    (void)waiter_id;
    probe *p = ctx;
    int64_t id = -1;
    tf_tuple_get_int(t, 1, &id);
    p->rec->calls[p->rec->n] = p->who;
    p->rec->ids[p->rec->n++] = id;
    tf_tuple_clear(t);
}

static void test_blocked_arrival_order(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    record rec = {0};
    probe rd1 = {&rec, 1}, in2 = {&rec, 2}, in3 = {&rec, 3}, rd4 = {&rec, 4};
    tf_tuple m;
    make_tmpl(&m, "task");
    uint64_t w1, w2, w3, w4;
    assert_int_equal(ts_wait(s, &m, 0, on_tuple, &rd1, &w1), 0);
    assert_int_equal(ts_wait(s, &m, 1, on_tuple, &in2, &w2), 0);
    assert_int_equal(ts_wait(s, &m, 1, on_tuple, &in3, &w3), 0);
    assert_int_equal(ts_wait(s, &m, 0, on_tuple, &rd4, &w4), 0);
    assert_true(w1 && w2 && w3 && w4);
    ts_space_stats st;
    ts_space_get_stats(s, &st);
    assert_int_equal(st.waiters, 4);

    /* first out: rd1 sees it, in2 takes it; in3 and rd4 (behind in2) see nothing */
    out_task(s, "task", 10, 0);
    assert_int_equal(rec.n, 2);
    assert_int_equal(rec.calls[0], 1);
    assert_int_equal(rec.calls[1], 2);
    assert_int_equal(rec.ids[1], 10);
    ts_space_get_stats(s, &st);
    assert_int_equal(st.tuples, 0);
    assert_int_equal(st.waiters, 2);

    /* second out: in3 arrived before rd4, so in3 takes it and rd4 keeps waiting */
    out_task(s, "task", 11, 0);
    assert_int_equal(rec.n, 3);
    assert_int_equal(rec.calls[2], 3);
    assert_int_equal(rec.ids[2], 11);

    /* cancel rd4; a later out is stored, not delivered */
    assert_int_equal(ts_cancel(s, w4), 1);
    assert_int_equal(ts_cancel(s, w4), 0);
    out_task(s, "task", 12, 0);
    assert_int_equal(rec.n, 3);
    ts_space_get_stats(s, &st);
    assert_int_equal(st.tuples, 1);
    assert_int_equal(st.waiters, 0);

    /* ts_wait when a tuple is already there: served at once with id 0 */
    uint64_t w5 = 99;
    assert_int_equal(ts_wait(s, &m, 1, on_tuple, &rd1, &w5), 1);
    assert_int_equal(w5, 0);
    assert_int_equal(rec.ids[3], 12);
    tf_tuple_clear(&m);
    ts_space_free(s);
}

static void test_wild_and_named_waiters_interleave(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    record rec = {0};
    probe wild = {&rec, 1}, named = {&rec, 2};
    tf_tuple any, m;
    tf_tuple_init(&any);
    tf_tuple_pack(&any, "SID");
    make_tmpl(&m, "task");
    ts_wait(s, &m, 1, on_tuple, &named, NULL);
    ts_wait(s, &any, 1, on_tuple, &wild, NULL);
    out_task(s, "task", 1, 0); /* the named waiter is older */
    out_task(s, "task", 2, 0);
    assert_int_equal(rec.n, 2);
    assert_int_equal(rec.calls[0], 2);
    assert_int_equal(rec.calls[1], 1);
    tf_tuple_clear(&any);
    tf_tuple_clear(&m);
    ts_space_free(s);
}

/* A callback that re-enters the space: it outs a follow-up tuple. */
static void reenter(void *ctx, uint64_t waiter_id, tf_tuple *t)
{
    (void)waiter_id;
    ts_space *s = ctx;
    int64_t id;
    tf_tuple_get_int(t, 1, &id);
    tf_tuple_clear(t);
    tf_tuple r;
    tf_tuple_init(&r);
    tf_tuple_pack(&r, "sid", "done", id, 1.0);
    ts_space_out(s, &r);
}

static void test_reentrant_callback(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    tf_tuple m, got;
    make_tmpl(&m, "task");
    ts_wait(s, &m, 1, reenter, s, NULL);
    out_task(s, "task", 5, 0);
    tf_tuple_clear(&m);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "siD", "done", (int64_t)5);
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    ts_space_free(s);
}

static void test_accounting(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    tf_tuple t, m, got;
    tf_tuple_init(&t);
    uint8_t blob[1000] = {0};
    tf_tuple_pack(&t, "sib", "result", (int64_t)1, blob, sizeof blob);
    size_t one = tf_tuple_bytes(&t);
    ts_space_out(s, &t);
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "sib", "result", (int64_t)2, blob, sizeof blob);
    ts_space_out(s, &t);
    ts_space_stats st;
    ts_space_get_stats(s, &st);
    assert_int_equal(st.tuples, 2);
    assert_int_equal(st.bytes, 2 * one);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "sIB", "result");
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    tf_tuple_clear(&got);
    ts_space_get_stats(s, &st);
    assert_int_equal(st.tuples, 1);
    assert_int_equal(st.bytes, one);
    assert_int_equal(st.max_bytes, 2 * one);
    assert_int_equal(st.max_tuples, 2);
    tf_tuple_init(&t); /* a tuple with formals is refused */
    tf_tuple_pack(&t, "sI", "bad");
    assert_int_equal(ts_space_out(s, &t), -1);
    tf_tuple_clear(&m);
    ts_space_free(s);
}

static void test_index_ignores_other_names(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    for (int i = 0; i < 100000; i++)
        out_task(s, i % 2 ? "noise" : "result", i, 0);
    out_task(s, "task", 1, 0);
    ts_space_stats before, after;
    tf_tuple m, got;
    make_tmpl(&m, "task");
    ts_space_get_stats(s, &before);
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    tf_tuple_clear(&got);
    ts_space_get_stats(s, &after);
    assert_true(after.comparisons - before.comparisons <= 1);
    tf_tuple_clear(&m);

    /* ("result", id) among 50k results: the int index makes it one comparison too */
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "siD", "result", (int64_t)77778);
    ts_space_get_stats(s, &before);
    assert_int_equal(ts_space_inp(s, &m, &got), 1);
    tf_tuple_clear(&got);
    ts_space_get_stats(s, &after);
    assert_true(after.comparisons - before.comparisons <= 1);
    tf_tuple_clear(&m);

    /* waking a waiter does not look at waiters of other names */
    record rec = {0};
    probe p = {&rec, 1};
    tf_tuple other;
    make_tmpl(&other, "other");
    for (int i = 0; i < 1000; i++)
        ts_wait(s, &other, 1, on_tuple, &p, NULL);
    make_tmpl(&m, "job");
    ts_wait(s, &m, 1, on_tuple, &p, NULL);
    ts_space_get_stats(s, &before);
    out_task(s, "job", 3, 0);
    ts_space_get_stats(s, &after);
    assert_int_equal(rec.n, 1);
    assert_true(after.comparisons - before.comparisons <= 1);
    tf_tuple_clear(&m);
    tf_tuple_clear(&other);
    ts_space_free(s);
}

/* The chooser of these tests: taker t wants ids 10t .. 10t+9 (rank 0), then the lowest id. */
static uint64_t rank_by_tens(void *ctx, uint64_t taker, const tf_tuple *t)
{
    int64_t id = 0;
    (*(int *)ctx)++;
    tf_tuple_get_int(t, 1, &id);
    return (uint64_t)id / 10 == taker ? 0 : 1 + (uint64_t)id;
}

/* The id of the tuple taker takes with template m (which it clears), or -1. */
static int64_t take_with(ts_space *s, tf_tuple *m, uint64_t taker)
{
    tf_tuple got;
    int64_t id = -1;
    if (ts_space_inp_as(s, m, taker, &got) == 1) {
        tf_tuple_get_int(&got, 1, &id);
        tf_tuple_clear(&got);
    }
    tf_tuple_clear(m);
    return id;
}

static int64_t take_as(ts_space *s, uint64_t taker)
{
    tf_tuple m;
    make_tmpl(&m, "task");
    return take_with(s, &m, taker);
}

static void test_chooser_ranks_stored_tuples(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    int calls = 0;
    int64_t ids[] = {1, 12, 25, 13, 3, 14};
    for (int i = 0; i < 6; i++)
        out_task(s, "task", ids[i], 0);
    out_task(s, "other", 20, 0);
    assert_int_equal(take_as(s, 2), 1); /* no chooser yet: FIFO, whoever takes */
    ts_space_set_chooser(s, rank_by_tens, &calls);
    assert_int_equal(take_as(s, 2), 25); /* its own, past older ones; "other" never matches */
    assert_int_equal(take_as(s, 1), 12); /* its own, the oldest of them */
    assert_int_equal(take_as(s, 1), 13);
    calls = 0;
    assert_int_equal(take_as(s, 0), 3); /* no taker named: FIFO, the chooser not asked */
    assert_int_equal(calls, 0);
    out_task(s, "task", 8, 0);
    assert_int_equal(take_as(s, 3), 8); /* none of its own: the lowest id, not the oldest */
    assert_int_equal(take_as(s, 3), 14);
    assert_int_equal(take_as(s, 3), -1);
    ts_space_free(s);
}

/* A take of ("task", ?id, 1.0) as taker. */
static int64_t take_v1_as(ts_space *s, uint64_t taker)
{
    tf_tuple m;
    tf_tuple_init(&m);
    assert_int_equal(tf_tuple_pack(&m, "sId", "task", 1.0), 0);
    return take_with(s, &m, taker);
}

/* The scan ranks a tuple before it matches it (and matches only what could win): the
 * best-ranked match is taken, whatever the ranks of the tuples the template rejects. */
static void test_chooser_takes_the_best_match(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    int calls = 0;
    ts_space_set_chooser(s, rank_by_tens, &calls);
    out_task(s, "task", 20, 0.0); /* taker 2's own (rank 0), but v = 0 */
    out_task(s, "task", 5, 1.0);  /* rank 6 */
    out_task(s, "task", 3, 0.0);  /* rank 4: outranks 5 and 4, but v = 0 */
    out_task(s, "task", 4, 1.0);  /* rank 5 */
    out_task(s, "task", 21, 1.0); /* taker 2's own */
    assert_int_equal(take_v1_as(s, 2), 21);
    assert_int_equal(take_v1_as(s, 2), 4);
    assert_int_equal(take_v1_as(s, 2), 5);
    assert_int_equal(take_v1_as(s, 2), -1); /* 20 and 3 stay: no match */
    assert_int_equal(take_as(s, 2), 20);
    assert_int_equal(take_as(s, 2), 3);
    ts_space_free(s);
}

static void test_chooser_picks_the_waiter(void **state)
{
    (void)state;
    ts_space *s = ts_space_new();
    int calls = 0;
    ts_space_set_chooser(s, rank_by_tens, &calls);
    record rec = {0};
    probe in1 = {&rec, 1}, rd3 = {&rec, 3}, in2 = {&rec, 2}, in0 = {&rec, 0};
    tf_tuple m;
    make_tmpl(&m, "task");
    assert_int_equal(ts_wait_as(s, &m, 1, 1, on_tuple, &in1, NULL), 0);
    assert_int_equal(ts_wait_as(s, &m, 0, 3, on_tuple, &rd3, NULL), 0);
    assert_int_equal(ts_wait_as(s, &m, 1, 2, on_tuple, &in2, NULL), 0);
    /* 25 is taker 2's own: it goes there, past the older taker 1; the rd before it sees it */
    out_task(s, "task", 25, 0);
    assert_int_equal(rec.n, 2);
    assert_int_equal(rec.calls[0], 3);
    assert_int_equal(rec.calls[1], 2);
    assert_int_equal(rec.ids[1], 25);
    /* nobody better waits: taker 1 gets 7 */
    out_task(s, "task", 7, 0);
    assert_int_equal(rec.n, 3);
    assert_int_equal(rec.calls[2], 1);
    /* a waiter naming no taker ranks 0: it keeps its place in line */
    assert_int_equal(ts_wait_as(s, &m, 1, 0, on_tuple, &in0, NULL), 0);
    assert_int_equal(ts_wait_as(s, &m, 1, 2, on_tuple, &in2, NULL), 0);
    out_task(s, "task", 26, 0);
    assert_int_equal(rec.calls[3], 0);
    out_task(s, "task", 5, 0);
    assert_int_equal(rec.calls[4], 2);
    ts_space_stats st;
    ts_space_get_stats(s, &st);
    assert_int_equal(st.waiters, 0);
    assert_int_equal(st.tuples, 0);
    tf_tuple_clear(&m);
    ts_space_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_out_inp_rdp_fifo),
        cmocka_unit_test(test_blocked_arrival_order),
        cmocka_unit_test(test_wild_and_named_waiters_interleave),
        cmocka_unit_test(test_reentrant_callback),
        cmocka_unit_test(test_accounting),
        cmocka_unit_test(test_index_ignores_other_names),
        cmocka_unit_test(test_chooser_ranks_stored_tuples),
        cmocka_unit_test(test_chooser_takes_the_best_match),
        cmocka_unit_test(test_chooser_picks_the_waiter),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
