/* test_isa.c: the choice of a SIMD kernel's build (common/isa.h).
 *
 *   runs          "portable" runs everywhere, an unknown name nowhere, and on x86-64 "avx512" only
 *                 where "avx2" does too.
 *   find          a table's entries by name, n for a name not in it.
 *   choose        the best build the CPU runs; a cap never lets a better build in; an unknown
 *                 cap is no cap; the last entry when nothing better runs. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>

#include "isa.h"

typedef struct entry {
    const char *name;
    int tag;
} entry;

static const entry family[] = {{"avx512", 16}, {"avx2", 8}, {"portable", 2}};
enum { N = 3 };

static int best_running(void)
{
    return tf_isa_runs("avx512") ? 0 : tf_isa_runs("avx2") ? 1 : 2;
}

static void runs(void **state)
{
    (void)state;
    assert_true(tf_isa_runs("portable"));
    assert_false(tf_isa_runs("sse9"));
    assert_false(tf_isa_runs(""));
    if (tf_isa_runs("avx512"))
        assert_true(tf_isa_runs("avx2"));
}

static void find(void **state)
{
    (void)state;
    assert_int_equal(tf_isa_find(family, sizeof family[0], N, "avx512"), 0);
    assert_int_equal(tf_isa_find(family, sizeof family[0], N, "portable"), 2);
    assert_int_equal(tf_isa_find(family, sizeof family[0], N, "neon"), N);
}

static void choose(void **state)
{
    (void)state;
    const int best = best_running();
    assert_int_equal(tf_isa_choose(family, sizeof family[0], N, NULL), best);
    assert_int_equal(tf_isa_choose(family, sizeof family[0], N, "no-such-isa"), best);
    assert_int_equal(tf_isa_choose(family, sizeof family[0], N, "portable"), 2);
    assert_int_equal(family[tf_isa_choose(family, sizeof family[0], N, "portable")].tag, 2);
    /* a cap of avx2: avx2 where it runs, never avx512 */
    assert_int_equal(tf_isa_choose(family, sizeof family[0], N, "avx2"), best == 2 ? 2 : 1);
    /* a family without a vector build */
    static const entry plain[] = {{"portable", 1}};
    assert_int_equal(tf_isa_choose(plain, sizeof plain[0], 1, "avx512"), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(runs),
        cmocka_unit_test(find),
        cmocka_unit_test(choose),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
