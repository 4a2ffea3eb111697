/* test_affinity.c: horizontal-extent affinity (coordinator/render/affinity.c): the column ranges for n
 * workers (they tile the width in worker id order), first / second / elsewhere for a task's
 * centre column, the ranks (own range first, then the neighbours' and the rest by lowest id),
 * and the ranges following joins and leaves. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "coordinator/render/affinity.h"

static tf_rect stamp(int x, int w) { return (tf_rect){x, 0, w, 16}; }

static void assert_range(const tf_affinity *a, int64_t worker, int x0, int x1)
{
    int g0 = -2, g1 = -2;
    assert_int_equal(tf_affinity_range(a, worker, &g0, &g1), 0);
    assert_int_equal(g0, x0);
    assert_int_equal(g1, x1);
}

static void test_ranges_tile_the_width(void **state)
{
    (void)state;
    for (int width = 1; width <= 67; width += 11)
        for (int n = 1; n <= 9; n++) {
            tf_affinity *a = tf_affinity_new(width);
            for (int i = n; i >= 1; i--) /* joined in any order: ranges follow the ids */
                assert_int_equal(tf_affinity_join(a, 10 * i), 0);
            assert_int_equal(tf_affinity_workers(a), n);
            int prev = 0;
            for (int i = 1; i <= n; i++) {
                int x0, x1;
                assert_int_equal(tf_affinity_range(a, 10 * i, &x0, &x1), 0);
                assert_int_equal(x0, prev);
                assert_true(x1 >= x0 && x1 - x0 <= width / n + 1);
                prev = x1;
            }
            assert_int_equal(prev, width);
            tf_affinity_free(a);
        }
}

static void test_first_second_elsewhere(void **state)
{
    (void)state;
    tf_affinity *a = tf_affinity_new(640);
    for (int64_t w = 1; w <= 4; w++)
        assert_int_equal(tf_affinity_join(a, w), 0);
    assert_range(a, 1, 0, 160);
    assert_range(a, 2, 160, 320);
    assert_int_equal(tf_affinity_choice_of(a, 2, stamp(192, 64)), TF_AFFINITY_FIRST);
    assert_int_equal(tf_affinity_choice_of(a, 2, stamp(0, 64)), TF_AFFINITY_SECOND);
    assert_int_equal(tf_affinity_choice_of(a, 2, stamp(320, 64)), TF_AFFINITY_SECOND);
    assert_int_equal(tf_affinity_choice_of(a, 2, stamp(576, 64)), TF_AFFINITY_ELSEWHERE);
    assert_int_equal(tf_affinity_choice_of(a, 1, stamp(320, 64)), TF_AFFINITY_ELSEWHERE);
    /* a stamp across a boundary belongs where its centre column is */
    assert_int_equal(tf_affinity_choice_of(a, 1, stamp(128, 64)), TF_AFFINITY_SECOND);
    assert_int_equal(tf_affinity_choice_of(a, 2, stamp(128, 64)), TF_AFFINITY_FIRST);
    assert_int_equal(tf_affinity_choice_of(a, 9, stamp(0, 64)), TF_AFFINITY_NONE);
    assert_int_equal(tf_affinity_range_of(a, stamp(128, 64)), 1);
    assert_int_equal(tf_affinity_range_of(a, stamp(576, 64)), 3);
    tf_affinity_free(a);
}

static void test_ranks(void **state)
{
    (void)state;
    tf_affinity *a = tf_affinity_new(640);
    for (int64_t w = 1; w <= 4; w++)
        tf_affinity_join(a, w);
    uint64_t own_old = tf_affinity_rank(a, 2, stamp(192, 64), 90);
    uint64_t own_new = tf_affinity_rank(a, 2, stamp(256, 64), 91);
    uint64_t second_low = tf_affinity_rank(a, 2, stamp(0, 64), 3);
    uint64_t second_high = tf_affinity_rank(a, 2, stamp(384, 64), 40);
    uint64_t far_low = tf_affinity_rank(a, 2, stamp(576, 64), 0);
    uint64_t far_high = tf_affinity_rank(a, 2, stamp(576, 64), 50);
    assert_true(own_old == 0 && own_new == 0); /* the oldest of its own is taken */
    assert_true(second_low > 0 && second_low < second_high);
    assert_true(second_high < far_low && far_low < far_high);
    assert_true(tf_affinity_rank(a, 7, stamp(576, 64), 50) == 0); /* no range: no preference */
    tf_affinity_free(a);
}

static void test_join_and_leave(void **state)
{
    (void)state;
    tf_affinity *a = tf_affinity_new(300);
    assert_int_equal(tf_affinity_join(a, 5), 0);
    assert_range(a, 5, 0, 300);
    assert_int_equal(tf_affinity_join(a, 2), 0);
    assert_int_equal(tf_affinity_join(a, 2), 0); /* twice: once */
    assert_int_equal(tf_affinity_workers(a), 2);
    assert_range(a, 2, 0, 150);
    assert_range(a, 5, 150, 300);
    assert_int_equal(tf_affinity_join(a, 9), 0);
    assert_range(a, 2, 0, 100);
    assert_range(a, 5, 100, 200);
    assert_range(a, 9, 200, 300);
    tf_affinity_leave(a, 5);
    tf_affinity_leave(a, 5); /* unknown now: nothing */
    assert_int_equal(tf_affinity_workers(a), 2);
    assert_range(a, 2, 0, 150);
    assert_range(a, 9, 150, 300);
    int x0, x1;
    assert_int_equal(tf_affinity_range(a, 5, &x0, &x1), -1);
    assert_int_equal(tf_affinity_choice_of(a, 9, stamp(150, 20)), TF_AFFINITY_FIRST);
    tf_affinity_leave(a, 2);
    tf_affinity_leave(a, 9);
    assert_int_equal(tf_affinity_workers(a), 0);
    assert_int_equal(tf_affinity_choice_of(a, 9, stamp(150, 20)), TF_AFFINITY_NONE);
    tf_affinity_free(a);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ranges_tile_the_width),
        cmocka_unit_test(test_first_second_elsewhere),
        cmocka_unit_test(test_ranks),
        cmocka_unit_test(test_join_and_leave),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
