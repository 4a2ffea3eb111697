/* test_clock.c: tf_parse_duration_ms (common/clock.c), the one parser of every duration flag
 * (render --lease-timeout, worker --timeout): units, bare milliseconds, rounding, and the
 * spellings it must refuse. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "clock.h"

static int64_t ok(const char *text)
{
    int64_t ms = -12345;
    if (tf_parse_duration_ms(text, &ms) != 0)
        fail_msg("\"%s\" refused", text);
    return ms;
}

static void test_units(void **state)
{
    (void)state;
    assert_int_equal(ok("15000"), 15000); /* a bare number keeps meaning milliseconds */
    assert_int_equal(ok("500ms"), 500);
    assert_int_equal(ok("15s"), 15000);
    assert_int_equal(ok("1.5s"), 1500);
    assert_int_equal(ok("2m"), 120000);
    assert_int_equal(ok("1h"), 3600000);
    assert_int_equal(ok("0"), 0);
    assert_int_equal(ok("0.25ms"), 0);  /* rounded to whole milliseconds */
    assert_int_equal(ok("0.0016s"), 2);
    assert_int_equal(ok("720h"), 2592000000LL); /* 30 days: the largest */
}

static void test_refused(void **state)
{
    (void)state;
    static const char *const bad[] = {"", "s", "-1s", "+5s", " 5s", "5s ", "5 s", "5sec",
                                      "5S", "1e3", "0x10", ".5s", "5.s", "inf", "nan", "5ms5",
                                      "721h", "99999999999999999999", "2m30s"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        int64_t ms = 7;
        if (tf_parse_duration_ms(bad[i], &ms) == 0)
            fail_msg("\"%s\" accepted as %lld ms", bad[i], (long long)ms);
        assert_int_equal(ms, 7); /* untouched */
    }
    int64_t ms;
    assert_int_equal(tf_parse_duration_ms(NULL, &ms), -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_units),
        cmocka_unit_test(test_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
