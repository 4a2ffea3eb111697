/* test_http_client.c: unit tests for common/http_client.c's tf_http_error_text, the line a
 * command prints for a service's error answer: the JSON "error" when there is one, a body's
 * first line otherwise, bounded, with a hostile server's control bytes made harmless. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <string.h>

#include "http_client.h"

static void said(const char *body, char *out, size_t n)
{
    tf_http_error_text(body, strlen(body), out, n);
}

static void test_json_error_string(void **state)
{
    (void)state;
    char out[320];
    said("{\"error\":\"options: --size '0x1': expected WxH\"}", out, sizeof out);
    assert_string_equal(out, "options: --size '0x1': expected WxH");
    /* an "error" that is no string, or no JSON object: the body's first line as it is */
    said("{\"error\": 5}", out, sizeof out);
    assert_string_equal(out, "{\"error\": 5}");
    said("Bad gateway\nmore text", out, sizeof out);
    assert_string_equal(out, "Bad gateway");
    said("", out, sizeof out);
    assert_string_equal(out, "");
}

static void test_control_bytes_and_length(void **state)
{
    (void)state;
    char out[320];
    /* a terminal escape sequence, in the JSON string and in a raw body */
    said("{\"error\":\"\\u001b[2Jgone\\r\\tx\"}", out, sizeof out);
    assert_string_equal(out, "?[2Jgone??x");
    said("\x1b]0;title\x07 rest", out, sizeof out);
    assert_string_equal(out, "?]0;title? rest");
    char longer[1000];
    memset(longer, 'a', sizeof longer - 1);
    longer[sizeof longer - 1] = '\0';
    said(longer, out, sizeof out);
    assert_int_equal(strlen(out), 300);
    char small[8];
    said("{\"error\":\"0123456789\"}", small, sizeof small);
    assert_string_equal(small, "0123456");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_json_error_string),
        cmocka_unit_test(test_control_bytes_and_length),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
