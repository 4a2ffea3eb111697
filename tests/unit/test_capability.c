/* test_capability.c: the role check of common/linda/capability.c: a request no rule grants is
 * refused with a reason; the first rule whose op, name and arity match decides; a per-connection
 * cap on uses; a guard's verdicts (allow, refuse, discard), and a refused use not counted; the
 * size bound; templates without an actual name; a NULL role is privileged. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <string.h>

#include "linda/capability.h"
#include "log.h"

static int guard_calls;

static ts_cap_verdict guard(void *ctx, uint64_t conn, int op, int blocking, const tf_tuple *t,
                            char *why, size_t len)
{
    (void)ctx;
    (void)op;
    (void)blocking;
    guard_calls++;
    int64_t v = 0;
    tf_tuple_get_int(t, 1, &v);
    if (v == 13)
        return tf_seterr(why, len, "unlucky from %llu", (unsigned long long)conn),
               TS_CAP_REFUSE;
    return v == 7 ? TS_CAP_DISCARD : TS_CAP_ALLOW;
}

static const ts_cap_rule rules[] = {
    {TS_CAP_RD, "scene", 2, 0, NULL},
    {TS_CAP_IN, "counter", 2, 1, NULL},
    {TS_CAP_OUT, "result", 2, 0, guard},
};

static ts_role role = {"tester", rules, 3, NULL, 64};

static ts_cap_verdict check(ts_cap_usage *u, int op, const char *name, int64_t v)
{
    tf_tuple t;
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "si", name, v);
    char why[160] = "";
    ts_cap_verdict r = ts_cap_check(&role, u, 1, op, 0, &t, why, sizeof why);
    if (r == TS_CAP_REFUSE)
        assert_true(strlen(why) > 0);
    tf_tuple_clear(&t);
    return r;
}

static void test_rules(void **state)
{
    (void)state;
    ts_cap_usage u;
    memset(&u, 0, sizeof u);
    assert_int_equal(check(&u, TS_CAP_RD, "scene", (int64_t)1), TS_CAP_ALLOW);
    assert_int_equal(check(&u, TS_CAP_RD, "scene", (int64_t)1), TS_CAP_ALLOW);
    assert_int_equal(check(&u, TS_CAP_IN, "scene", (int64_t)1), TS_CAP_REFUSE); /* op */
    assert_int_equal(check(&u, TS_CAP_OUT, "other", (int64_t)1), TS_CAP_REFUSE); /* name */
    assert_int_equal(check(&u, TS_CAP_IN, "counter", (int64_t)1), TS_CAP_ALLOW);
    assert_int_equal(check(&u, TS_CAP_IN, "counter", (int64_t)1), TS_CAP_REFUSE); /* cap */
    guard_calls = 0;
    assert_int_equal(check(&u, TS_CAP_OUT, "result", (int64_t)1), TS_CAP_ALLOW);
    assert_int_equal(check(&u, TS_CAP_OUT, "result", (int64_t)7), TS_CAP_DISCARD);
    assert_int_equal(check(&u, TS_CAP_OUT, "result", (int64_t)13), TS_CAP_REFUSE);
    assert_int_equal(guard_calls, 3);
    assert_int_equal(u.uses[2], 2); /* the refused one is not counted */
}

static void test_shape_and_size(void **state)
{
    (void)state;
    ts_cap_usage u;
    memset(&u, 0, sizeof u);
    char why[160];
    tf_tuple t;
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "sii", "scene", (int64_t)1, (int64_t)2); /* arity 3 */
    assert_int_equal(ts_cap_check(&role, &u, 1, TS_CAP_RD, 1, &t, why, sizeof why), TS_CAP_REFUSE);
    tf_tuple_clear(&t);
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "SI"); /* no actual name: never matches a rule */
    assert_int_equal(ts_cap_check(&role, &u, 1, TS_CAP_RD, 1, &t, why, sizeof why), TS_CAP_REFUSE);
    assert_int_equal(ts_cap_check(NULL, &u, 1, TS_CAP_RD, 1, &t, why, sizeof why), TS_CAP_ALLOW);
    tf_tuple_clear(&t);
    char big[100];
    memset(big, 'x', sizeof big - 1);
    big[sizeof big - 1] = '\0';
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "ss", "scene", big); /* larger than the role's 64 bytes */
    assert_int_equal(ts_cap_check(&role, &u, 1, TS_CAP_RD, 1, &t, why, sizeof why), TS_CAP_REFUSE);
    assert_non_null(strstr(why, "at most 64"));
    tf_tuple_clear(&t);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_rules),
        cmocka_unit_test(test_shape_and_size),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
