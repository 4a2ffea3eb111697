/* test_tasks.c: the coordinator's task geometry defaults (coordinator/render/tasks.c).
 *
 *   default_stamps   tf_task_spec_default: sides of 128 halving to 32 for at least 24 tasks a
 *                    worker; bands held to 512 K pixels (flatter stamps only past 4096 wide,
 *                    never under 8 rows); clipped to the image.
 *   auto_ahead       tf_tasks_auto_ahead: beyond the band, as many tasks as hold 4 M pixels,
 *                    but 3 to 16 a worker; nondecreasing in workers (the ring sized for the
 *                    most workers holds any fewer); none for no worker. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "coordinator/render/tasks.h"

static void assert_spec(int width, int height, int workers, int w, int h)
{
    tf_task_spec s = tf_task_spec_default(width, height, workers);
    assert_int_equal(s.shape, TF_TASKS_STAMPS);
    assert_int_equal(s.w, w);
    assert_int_equal(s.h, h);
}

static void default_stamps(void **state)
{
    (void)state;
    assert_spec(3840, 1280, 2, 128, 128);  /* 300 tasks; 512 K-pixel bands allow 136 rows */
    assert_spec(1920, 1080, 2, 128, 128);
    assert_spec(8192, 8192, 2, 128, 64);   /* 512 K / 8192 */
    assert_spec(65536, 4096, 2, 128, 8);   /* 8 rows at least */
    assert_spec(480, 270, 2, 32, 32);      /* 24 tasks a worker: 126 of 32x32 */
    assert_spec(480, 270, 1, 64, 64);
    assert_spec(20, 10, 4, 20, 10);        /* clipped to the image */
}

static tf_tasks stamps(int width, int height, int w, int h)
{
    tf_tasks t;
    tf_tasks_init(&t, width, height, 0, (tf_task_spec){TF_TASKS_STAMPS, w, h});
    return t;
}

static void auto_ahead(void **state)
{
    (void)state;
    tf_tasks small = stamps(2048, 1024, 8, 8), big = stamps(3840, 1280, 128, 128);
    tf_tasks huge = stamps(4096, 4096, 2048, 2048);
    assert_int_equal(tf_tasks_auto_ahead(&small, 0), 0);
    assert_int_equal(tf_tasks_auto_ahead(&small, 1024), 16 * 1024); /* 1 M pixels: the cap */
    assert_int_equal(tf_tasks_auto_ahead(&small, 4096), 16 * 4096); /* 4 M: still the cap */
    assert_int_equal(tf_tasks_auto_ahead(&big, 2), 16 * 2);
    assert_int_equal(tf_tasks_auto_ahead(&big, 64), 256);  /* 4 M / 16 K */
    assert_int_equal(tf_tasks_auto_ahead(&big, 17), 256);  /* not 17 * 15 */
    assert_int_equal(tf_tasks_auto_ahead(&big, 1024), 3 * 1024); /* the floor */
    assert_int_equal(tf_tasks_auto_ahead(&huge, 1), 3);
    const tf_tasks *all[] = {&small, &big, &huge};
    for (int k = 0; k < 3; k++) {
        int prev = 0;
        for (int w = 1; w <= 4096; w++) {
            int a = tf_tasks_auto_ahead(all[k], w);
            assert_true(a >= prev);
            assert_true(a >= TF_AUTO_AHEAD_MIN * w && a <= TF_AUTO_AHEAD_MAX * w);
            long px = (long)all[k]->tw * all[k]->th;
            assert_true(a == TF_AUTO_AHEAD_MIN * w || (long)a * px <= TF_AUTO_AHEAD_PIXELS);
            assert_true(a == TF_AUTO_AHEAD_MAX * w || (long)(a + 1) * px > TF_AUTO_AHEAD_PIXELS);
            prev = a;
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(default_stamps),
        cmocka_unit_test(auto_ahead),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
