/* test_outbox.c: the ring of records a forked worker shares with its coordinator
 * (common/linda/outbox.c), both sides in one process: the worker's reservations are aligned,
 * in bounds and never overlap a record the coordinator still holds (a random run against a
 * model of the held records); a full ring says so and takes reservations again once the oldest
 * records are released, wrapping to its start; a record released out of order is reclaimed
 * only behind the ones before it; a loan keeps the outbox mapped after its creator let go; and
 * the coordinator's check refuses every payload no record could hold. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdlib.h>
#include <string.h>

#include "linda/outbox.h"

static tf_outbox *fresh(void)
{
    char err[160];
    tf_outbox *ob = tf_outbox_create(err, sizeof err);
    assert_non_null(ob);
    return ob;
}

/* Reserve a payload of n bytes and check it as the coordinator would: its offset (> 0). */
static int64_t reserve_ok(tf_outbox *ob, size_t n)
{
    int64_t off = tf_outbox_reserve(ob, n);
    assert_true(off > 0);
    char err[160];
    assert_int_equal(tf_outbox_payload_ok(ob, (uint64_t)off, n, err, sizeof err), 0);
    memset(tf_outbox_base(ob) + off, 0x5a, n); /* the payload is the worker's to fill */
    return off;
}

static void test_records_follow_each_other(void **state)
{
    (void)state;
    tf_outbox *ob = fresh();
    int64_t a = reserve_ok(ob, 100), b = reserve_ok(ob, 64), c = reserve_ok(ob, 1);
    assert_int_equal(a, TF_OUTBOX_HEADER);
    assert_int_equal(b, a + 128 + TF_OUTBOX_HEADER); /* 100 rounded up to 128 */
    assert_int_equal(c, b + 64 + TF_OUTBOX_HEADER);
    assert_int_equal(tf_outbox_reserve(ob, 0), -1);
    assert_int_equal(tf_outbox_reserve(ob, tf_outbox_size(ob)), -1); /* no room for a header */
    tf_outbox_unref(ob);
}

/* A full ring refuses; released from the oldest, it takes a record at its start again. */
static void test_full_ring_wraps_once_released(void **state)
{
    (void)state;
    tf_outbox *ob = fresh();
    size_t n = tf_outbox_size(ob) / 4 - TF_OUTBOX_HEADER; /* four records fill it exactly */
    int64_t off[4];
    tf_shared_bytes *loan[4];
    for (int i = 0; i < 4; i++) {
        off[i] = reserve_ok(ob, n);
        loan[i] = tf_outbox_lend(ob, (uint64_t)off[i]);
        assert_non_null(loan[i]);
    }
    assert_int_equal(tf_outbox_reserve(ob, 1), -1);
    tf_shared_bytes_release(loan[1]); /* out of order: the oldest still holds the ring */
    assert_int_equal(tf_outbox_reserve(ob, 1), -1);
    tf_shared_bytes_release(loan[0]); /* now the first two come back, in ring order */
    assert_int_equal(reserve_ok(ob, 2 * n), off[0]);
    assert_int_equal(tf_outbox_reserve(ob, 1), -1);
    tf_shared_bytes_release(loan[2]);
    tf_shared_bytes_release(loan[3]);
    tf_outbox_unref(ob);
}

/* The coordinator's loans hold the outbox: its creator's reference gone, a held payload is
 * still there to read until the last loan is released. */
static void test_loan_keeps_the_outbox(void **state)
{
    (void)state;
    tf_outbox *ob = fresh();
    int64_t off = reserve_ok(ob, 4096);
    uint8_t *payload = tf_outbox_base(ob) + off;
    tf_shared_bytes *loan = tf_outbox_lend(ob, (uint64_t)off);
    tf_outbox_unref(ob);
    for (int i = 0; i < 4096; i++)
        assert_int_equal(payload[i], 0x5a);
    tf_shared_bytes_release(loan); /* the last reference: unmapped (make asan: no leak) */
}

static void test_payload_check_refuses_what_no_record_holds(void **state)
{
    (void)state;
    tf_outbox *ob = fresh();
    uint64_t size = tf_outbox_size(ob);
    struct { uint64_t off, len; } bad[] = {
        {0, 64},                       /* where a header is */
        {TF_OUTBOX_HEADER + 8, 64},    /* not on a record's boundary */
        {TF_OUTBOX_HEADER, 0},         /* nothing */
        {TF_OUTBOX_HEADER, size},      /* past the end */
        {size, 1},                     /* at the end */
        {size + TF_OUTBOX_HEADER, 1},  /* beyond it */
        {UINT32_MAX & ~63ull, 1},      /* far beyond */
    };
    char err[160];
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        err[0] = 0;
        assert_int_equal(tf_outbox_payload_ok(ob, bad[i].off, bad[i].len, err, sizeof err), -1);
        assert_true(strlen(err) > 0);
    }
    assert_int_equal(tf_outbox_payload_ok(ob, TF_OUTBOX_HEADER, size - TF_OUTBOX_HEADER, err,
                                          sizeof err), 0);
    tf_outbox_unref(ob);
}

/* A random run: reservations of random sizes, releases of random held records.  Every record
 * the worker is given lies inside, on a boundary, and overlaps no record still held; and the
 * ring keeps taking work (it never stays full once everything is released). */
static void test_random_run_never_overlaps_a_held_record(void **state)
{
    (void)state;
    enum { HELD_MAX = 64 };
    tf_outbox *ob = fresh();
    uint64_t size = tf_outbox_size(ob);
    struct { uint64_t lo, hi; tf_shared_bytes *loan; } held[HELD_MAX];
    int nheld = 0, granted = 0, refused = 0;
    uint64_t x = 0x9e3779b97f4a7c15ull;
    for (int step = 0; step < 20000; step++) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        if (nheld > 0 && (x % 3 == 0 || nheld == HELD_MAX)) {
            int k = (int)((x >> 8) % (uint64_t)nheld);
            tf_shared_bytes_release(held[k].loan);
            held[k] = held[--nheld];
            continue;
        }
        size_t n = 1 + (size_t)((x >> 16) % (size / 6));
        int64_t off = tf_outbox_reserve(ob, n);
        if (off < 0) {
            refused++;
            continue;
        }
        granted++;
        uint64_t lo = (uint64_t)off - TF_OUTBOX_HEADER, hi = (uint64_t)off + n;
        assert_true(lo % TF_OUTBOX_HEADER == 0 && hi <= size);
        for (int k = 0; k < nheld; k++)
            assert_true(hi <= held[k].lo || lo >= held[k].hi);
        held[nheld].lo = lo;
        held[nheld].hi = hi;
        held[nheld].loan = tf_outbox_lend(ob, (uint64_t)off);
        nheld++;
    }
    while (nheld > 0)
        tf_shared_bytes_release(held[--nheld].loan);
    assert_true(granted > 1000 && refused > 0);
    assert_true(reserve_ok(ob, size / 2) > 0); /* all released: room for half the ring */
    tf_outbox_unref(ob);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_records_follow_each_other),
        cmocka_unit_test(test_full_ring_wraps_once_released),
        cmocka_unit_test(test_loan_keeps_the_outbox),
        cmocka_unit_test(test_payload_check_refuses_what_no_record_holds),
        cmocka_unit_test(test_random_run_never_overlaps_a_held_record),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
