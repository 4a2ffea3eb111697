/* test_worker.c: the worker loop (worker/worker.c) against malformed tasks.  Whatever a task
 * tuple says -- no size, a size no image has, a rectangle outside the image -- and whatever the
 * renderer produces (a NaN), the worker reports a failure for that task and goes on; it never
 * crashes, exits or sends a non-finite pixel.  The worker runs tf_worker_serve in a thread over
 * a socketpair to a real tuple-space server driven by the test's main thread. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <pthread.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "clock.h"
#include "farmproto.h"
#include "linda/tsclient.h"
#include "linda/tsserver.h"
#include "worker/worker.h"

#define IMG_W 64
#define IMG_H 32
#define NAN_TASK 4

typedef struct run {
    ts_client *c;
    int status;
    volatile int done;
} run;

static int fake_render(void *ctx, int frame, tf_rect r, tf_pixel *px, tf_render_counts *counts,
                       int64_t *busy_ns, char *err, size_t errlen)
{
    (void)ctx;
    (void)frame;
    (void)err;
    (void)errlen;
    for (int i = 0; i < r.w * r.h; i++)
        px[i] = (tf_pixel){0.25f, 0.5f, 0.75f, 1.0f, 3.0f, 4.0f};
    if (r.x == 1 && r.y == 1) /* the task the test marks: the renderer goes wrong */
        px[r.w * r.h - 1].g = NAN;
    counts->pixels = (uint64_t)r.w * (uint64_t)r.h;
    *busy_ns = 1;
    return 0;
}

static void *serve_main(void *arg)
{
    run *rn = arg;
    tf_worker_step step = {NULL, fake_render, IMG_W, IMG_H};
    tf_exr_layout layout = {IMG_W, IMG_H, 0, 0, 0, TF_PIXEL_HALF};
    rn->status = tf_worker_serve(rn->c, 7, &layout, &step);
    rn->done = 1;
    return NULL;
}

static void put_task(ts_space *space, int64_t id, int x, int y, int w, int h)
{
    tf_task_msg m;
    memset(&m, 0, sizeof m);
    m.id = id;
    m.frame = -1; /* a still */
    m.rect = (tf_rect){x, y, w, h};
    tf_tuple t;
    assert_int_equal(tf_task_pack(&t, &m), 0);
    assert_int_equal(ts_space_out(space, &t), 0);
}

static void test_malformed_tasks_become_failures(void **state)
{
    (void)state;
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    ts_space *space = ts_space_new();
    char err[256];
    ts_server *srv = ts_server_new(space, NULL, NULL, err, sizeof err);
    assert_non_null(srv);
    assert_true(ts_server_add_fd(srv, sv[0], "worker 7") > 0);
    run rn = {ts_client_from_fd(sv[1]), -1, 0};
    assert_non_null(rn.c);
    put_task(space, 1, 0, 0, 0, 8);            /* no width */
    put_task(space, 2, 0, 0, 1 << 20, 1 << 20); /* larger than any task */
    put_task(space, 3, 60, 0, 8, 8);           /* past the right edge */
    put_task(space, NAN_TASK, 1, 1, 4, 4);     /* the renderer makes a NaN */
    put_task(space, 5, 0, 8, IMG_W, 4);        /* fine: four whole rows of a scanline file */
    put_task(space, TF_TASK_STOP, 0, 0, 0, 0);
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, serve_main, &rn), 0);
    int64_t deadline = tf_now_ms() + 20000;
    while (!rn.done && tf_now_ms() < deadline)
        ts_server_run_once(srv, 20);
    for (int i = 0; i < 10; i++)
        ts_server_run_once(srv, 5);
    assert_true(rn.done);
    pthread_join(th, NULL);
    assert_int_equal(rn.status, TF_SERVE_STOPPED);

    for (int64_t id = 1; id <= NAN_TASK; id++) {
        tf_tuple tmpl, got;
        assert_int_equal(tf_failed_template(&tmpl, id, 7), 0);
        assert_int_equal(ts_space_inp(space, &tmpl, &got), 1);
        tf_tuple_clear(&got);
        tf_tuple_clear(&tmpl);
    }
    tf_tuple tmpl, got;
    assert_int_equal(tf_result_template(&tmpl, NAN_TASK, -1), 0);
    assert_int_equal(ts_space_inp(space, &tmpl, &got), 0); /* never sent */
    tf_tuple_clear(&tmpl);
    assert_int_equal(tf_result_template(&tmpl, 5, 7), 0);
    assert_int_equal(ts_space_inp(space, &tmpl, &got), 1);
    tf_result_msg m;
    assert_int_equal(tf_result_unpack(&got, &m), 0);
    assert_int_equal(m.nchunks, 4); /* a scanline file: one chunk per row of the task */
    tf_tuple_clear(&got);
    tf_tuple_clear(&tmpl);
    ts_client_close(rn.c);
    ts_server_free(srv);
    ts_space_free(space);
}

static void test_rect_problems(void **state)
{
    (void)state;
    assert_null(tf_task_rect_problem((tf_rect){0, 0, 64, 32}, 64, 32));
    assert_non_null(tf_task_rect_problem((tf_rect){0, 0, 0, 1}, 64, 32));
    assert_non_null(tf_task_rect_problem((tf_rect){0, 0, 1, 0}, 0, 0));
    assert_non_null(tf_task_rect_problem((tf_rect){-1, 0, 1, 1}, 64, 32));
    assert_non_null(tf_task_rect_problem((tf_rect){0, 31, 1, 2}, 64, 32));
    assert_non_null(tf_task_rect_problem((tf_rect){0, 0, 1 << 20, 1 << 20}, 0, 0));
    tf_pixel px[3];
    memset(px, 0, sizeof px);
    assert_int_equal(tf_first_non_finite(px, 3), -1);
    px[2].spp = INFINITY;
    assert_int_equal(tf_first_non_finite(px, 3), 2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_malformed_tasks_become_failures),
        cmocka_unit_test(test_rect_problems),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
