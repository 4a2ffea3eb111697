/* test_supervisor_wait.c: how long the coordinator's event loop may sleep between supervisor
 * steps (tf_supervisor_wait_ms, coordinator/render/supervisor.c), on a real supervisor over a
 * real tuple space and output file, driven the way the server drives it (its hooks): 250 ms
 * while nothing but the progress line needs it; 50 ms once a worker waits for a task and none
 * can be dealt (a straggler's second copy may fall due); 1 ms while a result's pixels are being
 * checked (the checker's verdict arrives without a message to wake the loop). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdlib.h>
#include <string.h>

#include "farmproto.h"
#include "image/exrencode.h"
#include "linda/tuplespace.h"
#include "supervisor_still.h"

typedef struct {
    ts_space *space;
    tf_supervisor *sup;
    ts_server_hooks hooks;
} farm;

static void farm_open(farm *f)
{
    tf_supervisor_config cfg = still_config(1, 64);
    f->sup = still_supervisor_new(&cfg, &f->space);
    f->hooks = tf_supervisor_hooks(f->sup);
}

static void farm_close(farm *f)
{
    still_abandon_output(f->sup);
    tf_supervisor_free(f->sup);
    ts_space_free(f->space);
}

/* Take every task tuple now in the space, one a connection from `conn` on, as workers' in()
 * would (the hook sees each take; a worker holds one lease at a time). */
static int take_all_tasks(farm *f, uint64_t conn)
{
    int n = 0;
    for (;;) {
        tf_tuple tmpl, got;
        tf_tuple_init(&got);
        assert_int_equal(tf_task_template(&tmpl, TF_TASK_ANY), 0);
        int rc = ts_space_inp(f->space, &tmpl, &got);
        tf_tuple_clear(&tmpl);
        if (rc != 1)
            return n;
        f->hooks.on_take(f->hooks.ctx, conn + (uint64_t)n, &got);
        tf_tuple_clear(&got);
        n++;
    }
}

static void never_served(void *ctx, uint64_t waiter, tf_tuple *t)
{
    (void)ctx, (void)t, (void)waiter;
    fail_msg("a waiter for a task that is never dealt was served");
}

/* Task 0's result (rows 0-7) from worker `worker`, its pixels finite and varied. */
static void result_of_task0(int64_t worker, tf_tuple *t)
{
    char err[256];
    tf_rect r = {0, 0, W, 8};
    tf_pixel px[W * 8];
    for (int i = 0; i < W * 8; i++)
        px[i] = (tf_pixel){(float)(i % 7) * 0.1f, 0.5f, 0.25f, 1.0f, 10.0f + (float)i, 4.0f};
    tf_exr_encoder *enc = tf_exr_encoder_new(&layout, err, sizeof err);
    assert_non_null(enc);
    tf_chunk_payload p;
    assert_int_equal(tf_exr_encode_rect(enc, r, px, &p, err, sizeof err), 0);
    tf_render_counts c = {.primary_rays = W * 8, .pixels = W * 8};
    assert_int_equal(tf_result_pack(t, 0, worker, &c, 1000, W * 8 * 4, &p), 0);
    tf_exr_encoder_free(enc);
}

static void test_wait_follows_what_the_loop_waits_for(void **state)
{
    (void)state;
    farm f;
    farm_open(&f);
    const uint64_t conn = 7; /* networked workers' connections (7, 8): their pixels are checked */
    assert_int_equal(tf_supervisor_wait_ms(f.sup), 250); /* nothing dealt, nobody waiting */

    tf_supervisor_step(f.sup, 1000.0); /* deals both tasks */
    assert_int_equal(take_all_tasks(&f, conn), 2);
    assert_int_equal(tf_supervisor_wait_ms(f.sup), 250); /* busy workers, nobody waiting */

    tf_tuple tmpl;
    assert_int_equal(tf_task_template(&tmpl, TF_TASK_ANY), 0);
    uint64_t waiter = 0;
    assert_int_equal(ts_wait(f.space, &tmpl, 1, never_served, NULL, &waiter), 0);
    tf_tuple_clear(&tmpl);
    assert_int_equal(tf_supervisor_wait_ms(f.sup), 50); /* idle, and all is dealt */

    tf_tuple result;
    result_of_task0(1, &result);
    tf_tuple copy;
    assert_int_equal(tf_tuple_copy(&copy, &result), 0);
    assert_int_equal(ts_space_out(f.space, &result), 0);
    f.hooks.on_out(f.hooks.ctx, conn, &copy); /* to the checker */
    tf_tuple_clear(&copy);
    assert_int_equal(tf_supervisor_wait_ms(f.sup), 1); /* its verdict comes unannounced */

    tf_supervisor_step(f.sup, 1001.0); /* collects the verdict */
    assert_int_equal(tf_supervisor_wait_ms(f.sup), 50);
    ts_cancel(f.space, waiter);
    assert_int_equal(tf_supervisor_wait_ms(f.sup), 250);
    farm_close(&f);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_wait_follows_what_the_loop_waits_for),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
