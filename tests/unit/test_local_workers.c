/* test_local_workers.c: the coordinator's pool of forked workers at the end of a render
 * (coordinator/render/local_workers.c), with real forks over a real tuple-space server: the
 * drain serves the space while a worker still needs it (to read its stop tuple), reaps a worker
 * that closed its socket and only exits later (its exit, not its socket, ends the wait), and
 * kills a worker that stays past the grace.  The workers here are small loops, not renderers. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <errno.h>
#include <signal.h>
#include <unistd.h>

#include "clock.h"
#include "coordinator/render/local_workers.h"
#include "linda/tuplespace.h"

typedef struct {
    ts_space *space;
    ts_server *srv;
    tf_local_workers lw;
} pool;

static void pool_open(pool *p)
{
    p->space = ts_space_new();
    char err[256];
    p->srv = ts_server_new(p->space, NULL, NULL, err, sizeof err);
    assert_non_null(p->srv);
}

static void pool_start(pool *p, int n, tf_local_worker_fn loop)
{
    char err[256];
    assert_int_equal(tf_local_workers_start_loop(&p->lw, n, p->srv, NULL, NULL, "c", loop, err,
                                                 sizeof err),
                     0);
    assert_int_equal(tf_local_workers_alive(&p->lw), n);
}

static void pool_close(pool *p)
{
    tf_local_workers_free(&p->lw);
    ts_server_free(p->srv);
    ts_space_free(p->space);
}

static int gone(pid_t pid) { return kill(pid, 0) == -1 && errno == ESRCH; }

/* A worker that waits for ("stop") in the space, then leaves. */
static int reads_its_stop(ts_client *c, const tf_scene *s, const tf_heightfield *hf,
                          const char *kind, const char *backend)
{
    (void)s, (void)hf, (void)kind, (void)backend;
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    tf_tuple_add_string(&tmpl, "stop");
    return ts_in(c, &tmpl, &got) == 0 ? 0 : 1;
}

/* A worker that closes its socket and exits 0.3 s later (as one tearing down a device does). */
static int closes_then_lingers(ts_client *c, const tf_scene *s, const tf_heightfield *hf,
                               const char *kind, const char *backend)
{
    (void)s, (void)hf, (void)kind, (void)backend;
    ts_client_close(c);
    usleep(300000);
    _exit(0);
}

/* A worker that closes its socket and never exits. */
static int closes_then_stays(ts_client *c, const tf_scene *s, const tf_heightfield *hf,
                             const char *kind, const char *backend)
{
    (void)s, (void)hf, (void)kind, (void)backend;
    ts_client_close(c);
    for (;;)
        pause();
    return 0;
}

/* The workers block in an in() that only the drain's serving can answer. */
static void test_drain_serves_the_stop_tuple(void **state)
{
    (void)state;
    pool p;
    pool_open(&p);
    pool_start(&p, 2, reads_its_stop);
    for (int i = 0; i < 2; i++) {
        tf_tuple stop;
        tf_tuple_init(&stop);
        tf_tuple_add_string(&stop, "stop");
        assert_int_equal(ts_space_out(p.space, &stop), 0);
    }
    pid_t pids[2] = {p.lw.pid[0], p.lw.pid[1]};
    tf_local_workers_drain(&p.lw, 60.0);
    assert_int_equal(tf_local_workers_alive(&p.lw), 0);
    assert_true(gone(pids[0]) && gone(pids[1]));
    tf_tuple stop;
    tf_tuple_init(&stop);
    tf_tuple_add_string(&stop, "stop");
    assert_int_equal(ts_space_count(p.space, &stop), 0); /* each read its own */
    tf_tuple_clear(&stop);
    pool_close(&p);
}

/* Its socket closes 0.3 s before it exits: the drain still ends with the exit, reaped, well
 * within the grace (it neither returns early nor waits the grace out). */
static void test_drain_waits_for_the_exit_after_the_socket_closes(void **state)
{
    (void)state;
    pool p;
    pool_open(&p);
    pool_start(&p, 2, closes_then_lingers);
    pid_t pids[2] = {p.lw.pid[0], p.lw.pid[1]};
    double t0 = tf_now_s();
    tf_local_workers_drain(&p.lw, 60.0);
    assert_true(tf_now_s() - t0 < 50.0);
    assert_int_equal(tf_local_workers_alive(&p.lw), 0);
    assert_true(gone(pids[0]) && gone(pids[1]));
    pool_close(&p);
}

/* A worker that never leaves is killed once the grace is over. */
static void test_drain_kills_a_worker_past_the_grace(void **state)
{
    (void)state;
    pool p;
    pool_open(&p);
    pool_start(&p, 1, closes_then_stays);
    pid_t pid = p.lw.pid[0];
    tf_local_workers_drain(&p.lw, 0.2);
    assert_int_equal(tf_local_workers_alive(&p.lw), 0);
    assert_true(gone(pid));
    pool_close(&p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_drain_serves_the_stop_tuple),
        cmocka_unit_test(test_drain_waits_for_the_exit_after_the_socket_closes),
        cmocka_unit_test(test_drain_kills_a_worker_past_the_grace),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
