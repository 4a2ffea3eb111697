/* test_idmap.c: the supervisor's connection index (coordinator/render/idmap.c) against a plain array
 * under a long random mix of puts, updates and deletions: backward-shift deletion must never
 * lose an entry of a probe run, including runs that wrap round the end of the table. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdlib.h>
#include <cmocka.h>

#include "coordinator/render/idmap.h"

#define KEYS 3000

static void test_matches_a_plain_array(void **state)
{
    (void)state;
    static int64_t want[KEYS + 1];
    static int present[KEYS + 1];
    tf_idmap m = {0};
    unsigned seed = 12345;
    for (int step = 0; step < 200000; step++) {
        uint64_t key = 1 + (uint64_t)(rand_r(&seed) % KEYS);
        int op = rand_r(&seed) % 3;
        if (op < 2) {
            int64_t v = rand_r(&seed);
            assert_int_equal(tf_idmap_put(&m, key, v), 0);
            want[key] = v;
            present[key] = 1;
        } else {
            tf_idmap_del(&m, key);
            present[key] = 0;
        }
        if (step % 997 == 0) {
            size_t n = 0;
            for (uint64_t k = 1; k <= KEYS; k++) {
                int64_t got = -1;
                int found = tf_idmap_get(&m, k, &got);
                assert_int_equal(found, present[k]);
                if (found)
                    assert_int_equal(got, want[k]);
                n += (size_t)present[k];
            }
            assert_int_equal(m.n, n);
        }
    }
    tf_idmap_free(&m);
}

static void test_consecutive_ids_and_key_zero(void **state)
{
    (void)state;
    tf_idmap m = {0};
    int64_t v;
    assert_int_equal(tf_idmap_get(&m, 5, &v), 0); /* empty map */
    assert_int_equal(tf_idmap_put(&m, 0, 1), -1); /* 0 means "no connection" */
    for (uint64_t k = 1; k <= 10000; k++)
        assert_int_equal(tf_idmap_put(&m, k, (int64_t)k * 7), 0);
    for (uint64_t k = 1; k <= 10000; k += 2)
        tf_idmap_del(&m, k);
    for (uint64_t k = 1; k <= 10000; k++) {
        int found = tf_idmap_get(&m, k, &v);
        assert_int_equal(found, k % 2 == 0);
        if (found)
            assert_int_equal(v, (int64_t)k * 7);
    }
    assert_int_equal(m.n, 5000);
    tf_idmap_free(&m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_matches_a_plain_array),
        cmocka_unit_test(test_consecutive_ids_and_key_zero),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
