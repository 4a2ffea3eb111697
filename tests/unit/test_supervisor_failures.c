/* test_supervisor_failures.c: when a task has failed everywhere (coordinator/render/
 * supervisor_redeal.c, docs/contract.md section 3), on a real supervisor over a real tuple
 * space and server, driven the way the server drives it (its hooks).  Workers joined through
 * socketpairs the server trusts are the coordinator's forked ones; a connection id the server
 * does not know stands for a networked client.
 *   - The render's only workers are two forked ones and each has failed a task twice (so it is
 *     no longer dealt it): the render stops, naming the task, instead of leaving the task to
 *     bounce between two workers that may not take it (the hang this test was written for).
 *   - The same two forked workers beside a networked one that has not failed the task: the
 *     render goes on (it may still be dealt it).
 *   - One networked worker that failed a task twice: the render waits for another worker
 *     (one client's connections cannot stop a render by failing: max_task_failures). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "farmproto.h"
#include "linda/tsserver.h"
#include "linda/tuplespace.h"
#include "supervisor_still.h"

#define NETWORKED_CONN 9999 /* a connection id the server never handed out: not forked */

typedef struct {
    ts_space *space;
    tf_supervisor *sup;
    ts_server *srv;
    ts_server_hooks hooks;
    int far_end[4]; /* the workers' ends of the socketpairs */
    int nfar;
} farm;

static void farm_open(farm *f)
{
    tf_supervisor_config cfg = still_config(2, 3);
    char err[256];
    memset(f, 0, sizeof *f);
    f->sup = still_supervisor_new(&cfg, &f->space);
    f->hooks = tf_supervisor_hooks(f->sup);
    f->srv = ts_server_new(f->space, NULL, &f->hooks, err, sizeof err);
    if (!f->srv)
        print_message("ts_server_new: %s\n", err);
    assert_non_null(f->srv);
    tf_supervisor_attach(f->sup, f->srv);
}

static void farm_close(farm *f)
{
    ts_server_free(f->srv);
    for (int i = 0; i < f->nfar; i++)
        close(f->far_end[i]);
    still_abandon_output(f->sup);
    tf_supervisor_free(f->sup);
    ts_space_free(f->space);
}

/* A forked worker's connection: a socketpair the server serves as trusted. */
static uint64_t forked_conn(farm *f, const char *peer)
{
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    uint64_t conn = ts_server_add_fd(f->srv, sv[0], peer);
    assert_true(conn > 0);
    f->far_end[f->nfar++] = sv[1];
    return conn;
}

/* Connection conn takes the worker counter (its worker id is `id` from now on). */
static void join(farm *f, uint64_t conn, int64_t id)
{
    tf_tuple t;
    assert_int_equal(tf_next_worker_pack(&t, id), 0);
    f->hooks.on_take(f->hooks.ctx, conn, &t);
    tf_tuple_clear(&t);
}

/* Connection conn takes a copy of task `id` from the space and fails it as worker `worker`;
 * 0, or -1 when no copy of the task is in the space. */
static int take_and_fail(farm *f, uint64_t conn, int64_t id, int64_t worker)
{
    tf_tuple tmpl, got, failed, copy;
    tf_tuple_init(&got);
    assert_int_equal(tf_task_template(&tmpl, id), 0);
    int rc = ts_space_inp(f->space, &tmpl, &got);
    tf_tuple_clear(&tmpl);
    if (rc != 1)
        return -1;
    f->hooks.on_take(f->hooks.ctx, conn, &got);
    tf_tuple_clear(&got);
    assert_int_equal(tf_failed_pack(&failed, id, worker, "non-finite pixels"), 0);
    assert_int_equal(tf_tuple_copy(&copy, &failed), 0);
    assert_int_equal(ts_space_out(f->space, &failed), 0);
    f->hooks.on_out(f->hooks.ctx, conn, &copy);
    tf_tuple_clear(&copy);
    return 0;
}

/* Two forked workers joined: ids 1 (*a) and 2 (*b). */
static void two_forked_workers(farm *f, uint64_t *a, uint64_t *b)
{
    *a = forked_conn(f, "local worker 0");
    *b = forked_conn(f, "local worker 1");
    join(f, *a, 1);
    join(f, *b, 2);
}

/* Worker `worker` on conn fails task 0 twice: it is no longer dealt it. */
static void fail_twice(farm *f, uint64_t conn, int64_t worker, double *now)
{
    for (int k = 0; k < 2; k++) {
        tf_supervisor_step(f->sup, (*now += 10.0));
        assert_int_equal(take_and_fail(f, conn, 0, worker), 0);
    }
}

static void test_forked_workers_all_failing_stop_the_render(void **state)
{
    (void)state;
    farm f;
    farm_open(&f);
    uint64_t a, b;
    two_forked_workers(&f, &a, &b);
    double now = 1000.0;
    fail_twice(&f, a, 1, &now);
    assert_null(tf_supervisor_error(f.sup)); /* worker 2 may still be dealt it */
    fail_twice(&f, b, 2, &now);
    const char *err = tf_supervisor_error(f.sup);
    if (!err || !strstr(err, "failed on 2 different workers"))
        fail_msg("the render goes on with every worker excluded from task 0: %s",
                 err ? err : "(no error)");
    farm_close(&f);
}

static void test_a_networked_worker_left_keeps_the_render_going(void **state)
{
    (void)state;
    farm f;
    farm_open(&f);
    uint64_t a, b;
    two_forked_workers(&f, &a, &b);
    join(&f, NETWORKED_CONN, 3);
    double now = 1000.0;
    fail_twice(&f, a, 1, &now);
    fail_twice(&f, b, 2, &now);
    assert_null(tf_supervisor_error(f.sup)); /* worker 3 may still be dealt it */
    farm_close(&f);
}

static void test_one_networked_worker_failing_waits_for_another(void **state)
{
    (void)state;
    farm f;
    farm_open(&f);
    join(&f, NETWORKED_CONN, 1);
    double now = 1000.0;
    fail_twice(&f, NETWORKED_CONN, 1, &now);
    assert_null(tf_supervisor_error(f.sup));
    farm_close(&f);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_forked_workers_all_failing_stop_the_render),
        cmocka_unit_test(test_a_networked_worker_left_keeps_the_render_going),
        cmocka_unit_test(test_one_networked_worker_failing_waits_for_another),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
