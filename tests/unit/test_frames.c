/* test_frames.c: unit tests for coordinator/render/frames.c: --frames / --frame ranges (and their
 * one-line refusals) and the #### output pattern. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdlib.h>
#include <string.h>

#include "coordinator/render/frames.h"

static void test_ranges(void **state)
{
    (void)state;
    char err[256];
    tf_frame_range r;
    assert_int_equal(tf_frame_range_parse("--frames", "3-10:2", &r, err, sizeof err), 0);
    assert_int_equal(r.first, 3);
    assert_int_equal(r.last, 10);
    assert_int_equal(r.step, 2);
    assert_int_equal(tf_frame_range_count(&r), 4); /* 3 5 7 9 */
    assert_int_equal(tf_frame_range_parse("--frame", "7", &r, err, sizeof err), 0);
    assert_int_equal(r.first, 7);
    assert_int_equal(r.last, 7);
    assert_int_equal(tf_frame_range_count(&r), 1);
    assert_int_equal(tf_frame_range_parse("--frames", "0-95", &r, err, sizeof err), 0);
    assert_int_equal(tf_frame_range_count(&r), 96);
    const char *bad[] = {"", "-3", "a-b", "3-", "3-5:", "3-5:0", "3-5:x", "1e3", "3 - 5",
                         "99999999999", "100000", "2-5:2x", "+3"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        err[0] = '\0';
        if (tf_frame_range_parse("--frames", bad[i], &r, err, sizeof err) == 0)
            fail_msg("accepted \"%s\"", bad[i]);
        assert_non_null(strstr(err, "--frames '"));
        assert_null(strchr(err, '\n'));
    }
    assert_int_equal(tf_frame_range_parse("--frames", "9-2", &r, err, sizeof err), -1);
    assert_string_equal(err, "--frames '9-2': the last frame is before the first");
}

static void check_path(const char *pattern, int frame, const char *want)
{
    char *got = tf_frame_output_path(pattern, frame);
    assert_non_null(got);
    assert_string_equal(got, want);
    free(got);
}

static void test_patterns(void **state)
{
    (void)state;
    check_path("out/alps.####.exr", 42, "out/alps.0042.exr");
    check_path("out/alps.##.exr", 42, "out/alps.42.exr");
    check_path("out/alps.##.exr", 123, "out/alps.123.exr"); /* wider than the run: not cut */
    check_path("a#b/f.###.exr", 5, "a#b/f.005.exr");         /* the last run counts */
    check_path("plain.exr", 5, "plain.exr");
    assert_true(tf_frame_pattern_has_number("x.#.exr"));
    assert_false(tf_frame_pattern_has_number("x.exr"));
    char *d = tf_frame_default_pattern("scenes/flyby.scene");
    assert_string_equal(d, "out/flyby.####.exr");
    free(d);
    d = tf_frame_default_pattern("odd");
    assert_string_equal(d, "out/odd.####.exr");
    free(d);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ranges),
        cmocka_unit_test(test_patterns),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
