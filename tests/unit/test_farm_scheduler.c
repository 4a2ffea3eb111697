/* test_farm_scheduler.c: the standing farm's policy (coordinator/farm/scheduler.c) on hand-made
 * snapshots: priority first; fair share (the fewest workers) with the terrain-affinity rule (a
 * terrain the worker must build counts as one worker more); the oldest job on ties; paused,
 * done, cancelled and failed jobs and jobs waiting for (or after a failed) dependency never
 * picked; pools ("" = "default"); tags as a subset with their edge cases (empty lists, empty
 * items, prefixes like "gp" against "gpu"); barred jobs; and when a busy worker should leave
 * its job (a higher priority servable job, its own job no longer servable) and when not (only
 * equal or lower priority waiting). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdio.h>
#include <string.h>

#include "coordinator/farm/scheduler.h"

#define MAXJ 8

/* A snapshot: jobs[i] describes tf_jobs[i]. */
typedef struct snap {
    tf_job tf_jobs[MAXJ];
    tf_sched_job jobs[MAXJ];
    int n;
} snap;

/* Add a queued job: id, priority, workers, terrain; pool "default", no tags. */
static int add(snap *s, int64_t id, int priority, int workers, const char *terrain)
{
    int i = s->n++;
    tf_job *j = &s->tf_jobs[i];
    memset(j, 0, sizeof *j);
    j->id = id;
    j->priority = priority;
    snprintf(j->state, sizeof j->state, "queued");
    snprintf(j->pool, sizeof j->pool, "default");
    snprintf(j->terrain, sizeof j->terrain, "%s", terrain ? terrain : "t0");
    s->jobs[i] = (tf_sched_job){.job = j, .workers = workers};
    return i;
}

static tf_sched_worker plain_worker(void)
{
    return (tf_sched_worker){"default", "", NULL, 0, NULL, NULL};
}

/* ---- tags ---- */

static void tags_cover_subsets(void **state)
{
    (void)state;
    assert_true(tf_sched_tags_cover("", ""));
    assert_true(tf_sched_tags_cover("gpu,big", ""));
    assert_true(tf_sched_tags_cover("gpu,big", "gpu"));
    assert_true(tf_sched_tags_cover("gpu,big", "big,gpu"));
    assert_true(tf_sched_tags_cover("gpu,big", "big"));
    assert_false(tf_sched_tags_cover("", "gpu"));
    assert_false(tf_sched_tags_cover("gpu", "gpu,big"));
    assert_false(tf_sched_tags_cover("big", "gpu"));
}

static void tags_cover_edges(void **state)
{
    (void)state;
    /* prefixes and extensions of a name are other names */
    assert_false(tf_sched_tags_cover("gpu", "gp"));
    assert_false(tf_sched_tags_cover("gp", "gpu"));
    assert_false(tf_sched_tags_cover("gpu2", "gpu"));
    assert_false(tf_sched_tags_cover("xgpu", "gpu"));
    assert_false(tf_sched_tags_cover("gpu,big", "pu"));
    assert_false(tf_sched_tags_cover("a,b", "a,c"));
    /* empty items (a trailing or doubled comma) ask for nothing */
    assert_true(tf_sched_tags_cover("gpu", "gpu,"));
    assert_true(tf_sched_tags_cover("gpu", ",gpu"));
    assert_true(tf_sched_tags_cover("gpu", "gpu,,"));
    assert_true(tf_sched_tags_cover("gpu,", "gpu"));
    assert_true(tf_sched_tags_cover("", ","));
    assert_false(tf_sched_tags_cover("gpu,", "big,"));
    /* an empty item in have is not a wildcard */
    assert_false(tf_sched_tags_cover(",", "gpu"));
    assert_false(tf_sched_tags_cover("gpu,,", "big"));
    /* the last item of either list counts */
    assert_true(tf_sched_tags_cover("a,b,c", "c"));
    assert_true(tf_sched_tags_cover("c", "c"));
    assert_false(tf_sched_tags_cover("a,b,c", "a,d"));
}

/* ---- what is servable ---- */

static void states_never_picked(void **state)
{
    (void)state;
    const char *states[] = {"paused", "done", "cancelled", "failed", "running", ""};
    for (size_t k = 0; k < sizeof states / sizeof *states; k++) {
        snap s = {0};
        int i = add(&s, 1, 9, 0, NULL);
        snprintf(s.tf_jobs[i].state, sizeof s.tf_jobs[i].state, "%s", states[k]);
        tf_sched_worker w = plain_worker();
        assert_false(tf_sched_servable(&s.jobs[i], &w));
        assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), -1);
        add(&s, 2, 0, 5, NULL); /* a queued job of lower priority with many workers */
        assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 1);
    }
}

static void dependency(void **state)
{
    (void)state;
    snap s = {0};
    int a = add(&s, 1, 9, 0, NULL), b = add(&s, 2, 0, 0, NULL);
    tf_sched_worker w = plain_worker();
    s.jobs[a].after_state = 1; /* waiting */
    assert_false(tf_sched_servable(&s.jobs[a], &w));
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), b);
    s.jobs[a].after_state = 2; /* what it waits for failed */
    assert_false(tf_sched_servable(&s.jobs[a], &w));
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), b);
    s.jobs[a].after_state = 0; /* done */
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), a);
}

/* A render a worker saw finish takes no new worker, whatever its priority. */
static void closing_never_picked(void **state)
{
    (void)state;
    snap s = {0};
    int a = add(&s, 1, 9, 0, NULL), b = add(&s, 2, 0, 0, NULL);
    tf_sched_worker w = plain_worker();
    s.jobs[a].closing = 1;
    assert_false(tf_sched_servable(&s.jobs[a], &w));
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), b);
    s.jobs[a].closing = 0;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), a);
}

static void empty_and_none(void **state)
{
    (void)state;
    snap s = {0};
    tf_sched_worker w = plain_worker();
    assert_int_equal(tf_sched_pick(s.jobs, 0, &w), -1);
    assert_true(tf_sched_should_leave(s.jobs, 0, 0, &w));
    add(&s, 1, 0, 0, NULL);
    assert_true(tf_sched_should_leave(s.jobs, s.n, -1, &w));
    assert_true(tf_sched_should_leave(s.jobs, s.n, 1, &w));
    assert_false(tf_sched_should_leave(s.jobs, s.n, 0, &w));
}

static void pools(void **state)
{
    (void)state;
    snap s = {0};
    int d = add(&s, 1, 0, 0, NULL), g = add(&s, 2, 5, 0, NULL);
    snprintf(s.tf_jobs[g].pool, sizeof s.tf_jobs[g].pool, "gpu");
    tf_sched_worker w = plain_worker();
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), d);
    w.pool = ""; /* "" is the default pool */
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), d);
    w.pool = NULL;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), d);
    w.pool = "gpu";
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), g);
    w.pool = "gp"; /* no prefix matching */
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), -1);
    /* a job stored with pool "" is in the default pool too */
    s.tf_jobs[d].pool[0] = 0;
    w.pool = "default";
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), d);
    w.pool = "";
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), d);
}

static void tags(void **state)
{
    (void)state;
    snap s = {0};
    int big = add(&s, 1, 5, 0, NULL), plain = add(&s, 2, 0, 0, NULL);
    snprintf(s.tf_jobs[big].tags, sizeof s.tf_jobs[big].tags, "big,gpu");
    tf_sched_worker w = plain_worker();
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), plain);
    w.tags = NULL;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), plain);
    w.tags = "gpu";
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), plain);
    w.tags = "gp,big,bigger";
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), plain);
    w.tags = "fast,gpu,big";
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), big);
    /* a worker with tags still serves jobs that ask for none */
    s.tf_jobs[big].priority = -1;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), plain);
}

static int64_t barred_id;
static int barred_calls;
static int bar_one(void *ctx, int64_t job)
{
    assert_ptr_equal(ctx, &barred_id);
    barred_calls++;
    return job == barred_id;
}

static void barred(void **state)
{
    (void)state;
    snap s = {0};
    int hi = add(&s, 7, 9, 0, NULL), lo = add(&s, 8, 0, 0, NULL);
    tf_sched_worker w = plain_worker();
    w.barred = bar_one;
    w.ctx = &barred_id;
    barred_id = 7;
    barred_calls = 0;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), lo);
    assert_true(barred_calls > 0);
    assert_false(tf_sched_servable(&s.jobs[hi], &w));
    barred_id = 8;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), hi);
    /* a worker barred from its own job leaves it */
    assert_true(tf_sched_should_leave(s.jobs, s.n, lo, &w));
    barred_id = 0;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), hi);
}

/* ---- the order among servable jobs ---- */

static void priority_first(void **state)
{
    (void)state;
    snap s = {0};
    add(&s, 1, 0, 0, NULL);
    add(&s, 2, 5, 9, NULL);  /* many workers, but higher priority */
    add(&s, 3, -3, 0, NULL);
    add(&s, 4, 4, 0, NULL);
    tf_sched_worker w = plain_worker();
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 1);
    s.tf_jobs[1].priority = 3;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 3);
    /* negative priorities order too */
    s.tf_jobs[0].priority = -5;
    s.tf_jobs[1].priority = -4;
    s.tf_jobs[3].priority = -9;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 2);
}

static void fair_share_fewest_workers(void **state)
{
    (void)state;
    snap s = {0};
    add(&s, 1, 5, 3, NULL);
    add(&s, 2, 5, 1, NULL);
    add(&s, 3, 5, 2, NULL);
    add(&s, 4, 4, 0, NULL); /* fewest, but a lower priority */
    tf_sched_worker w = plain_worker();
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 1);
    s.jobs[1].workers = 4;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 2);
}

static void oldest_on_ties(void **state)
{
    (void)state;
    snap s = {0};
    /* listed out of id order: the lowest id (oldest) wins, not the first listed */
    add(&s, 9, 5, 1, NULL);
    add(&s, 3, 5, 1, NULL);
    add(&s, 6, 5, 1, NULL);
    tf_sched_worker w = plain_worker();
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 1);
    s.jobs[1].workers = 2;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), 2);
}

static void terrain_affinity(void **state)
{
    (void)state;
    const char *held[] = {"tB"};
    tf_sched_worker w = plain_worker();
    w.terrains = held;
    w.nterrains = 1;
    snap s = {0};
    int a = add(&s, 1, 5, 0, "tA"), b = add(&s, 2, 5, 0, "tB");
    /* equal workers: the terrain it holds wins over the older job */
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), b);
    /* one worker behind: building counts as one more, a tie, so the oldest (a) */
    s.jobs[b].workers = 1;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), a);
    /* with a younger job needing the build: a tie again goes to the oldest, now b's side */
    snap s2 = {0};
    int a2 = add(&s2, 1, 5, 1, "tB"), b2 = add(&s2, 2, 5, 0, "tA");
    assert_int_equal(tf_sched_pick(s2.jobs, s2.n, &w), a2);
    /* two workers behind: fair share wins over affinity */
    s.jobs[b].workers = 2;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), a);
    s2.jobs[a2].workers = 2;
    assert_int_equal(tf_sched_pick(s2.jobs, s2.n, &w), b2);
    /* affinity never beats priority */
    s.jobs[b].workers = 0;
    s.tf_jobs[a].priority = 6;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), a);
    /* a worker holding nothing: every job costs one more alike, plain fair share */
    w.nterrains = 0;
    s.tf_jobs[a].priority = 5;
    s.jobs[a].workers = 1;
    assert_int_equal(tf_sched_pick(s.jobs, s.n, &w), b);
}

/* ---- leaving ---- */

static void should_leave_for_higher_priority(void **state)
{
    (void)state;
    snap s = {0};
    int cur = add(&s, 1, 5, 1, NULL), other = add(&s, 2, 5, 0, NULL);
    tf_sched_worker w = plain_worker();
    /* only equal priority waiting (with fewer workers): stay */
    assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    /* lower priority: stay */
    s.tf_jobs[other].priority = 1;
    assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    /* higher priority and servable: leave */
    s.tf_jobs[other].priority = 6;
    assert_true(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    /* higher priority but not servable (paused, other pool, tags, waiting, barred): stay */
    snprintf(s.tf_jobs[other].state, sizeof s.tf_jobs[other].state, "paused");
    assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    snprintf(s.tf_jobs[other].state, sizeof s.tf_jobs[other].state, "queued");
    snprintf(s.tf_jobs[other].pool, sizeof s.tf_jobs[other].pool, "gpu");
    assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    snprintf(s.tf_jobs[other].pool, sizeof s.tf_jobs[other].pool, "default");
    snprintf(s.tf_jobs[other].tags, sizeof s.tf_jobs[other].tags, "gpu");
    assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    s.tf_jobs[other].tags[0] = 0;
    s.jobs[other].after_state = 1;
    assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    s.jobs[other].after_state = 0;
    w.barred = bar_one;
    w.ctx = &barred_id;
    barred_id = 2;
    assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    barred_id = 0;
    assert_true(tf_sched_should_leave(s.jobs, s.n, cur, &w));
}

static void should_leave_when_current_unservable(void **state)
{
    (void)state;
    const char *states[] = {"paused", "done", "cancelled", "failed"};
    for (size_t k = 0; k < sizeof states / sizeof *states; k++) {
        snap s = {0};
        int cur = add(&s, 1, 5, 1, NULL);
        tf_sched_worker w = plain_worker();
        assert_false(tf_sched_should_leave(s.jobs, s.n, cur, &w));
        snprintf(s.tf_jobs[cur].state, sizeof s.tf_jobs[cur].state, "%s", states[k]);
        assert_true(tf_sched_should_leave(s.jobs, s.n, cur, &w));
    }
    snap s = {0};
    int cur = add(&s, 1, 5, 1, NULL);
    tf_sched_worker w = plain_worker();
    w.pool = "gpu"; /* the worker moved to another pool */
    assert_true(tf_sched_should_leave(s.jobs, s.n, cur, &w));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(tags_cover_subsets),
        cmocka_unit_test(tags_cover_edges),
        cmocka_unit_test(states_never_picked),
        cmocka_unit_test(dependency),
        cmocka_unit_test(closing_never_picked),
        cmocka_unit_test(empty_and_none),
        cmocka_unit_test(pools),
        cmocka_unit_test(tags),
        cmocka_unit_test(barred),
        cmocka_unit_test(priority_first),
        cmocka_unit_test(fair_share_fewest_workers),
        cmocka_unit_test(oldest_on_ties),
        cmocka_unit_test(terrain_affinity),
        cmocka_unit_test(should_leave_for_higher_priority),
        cmocka_unit_test(should_leave_when_current_unservable),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
