/* test_seal.c: sealed records (common/linda/seal.c): what one side seals the other opens, in
 * order, as the frame stream it was; a flipped byte, a replayed, reordered or dropped record,
 * a record of the other direction or of another connection (other nonces) all fail to open. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <string.h>

#include "linda/auth.h"
#include "linda/seal.h"

typedef struct sides {
    tf_seal ctx, crx, stx, srx;
} sides;

static void make_sides(sides *s, uint8_t nc0)
{
    uint8_t key[TF_KEY_BYTES], ns[TF_NONCE_BYTES], nc[TF_NONCE_BYTES];
    assert_int_equal(tf_secret_from_bytes("a secret of some length", 23, key), 0);
    memset(ns, 7, sizeof ns);
    memset(nc, nc0, sizeof nc);
    tf_seal_init(key, ns, nc, 1, &s->ctx, &s->crx);
    tf_seal_init(key, ns, nc, 0, &s->stx, &s->srx);
}

/* Seal three messages client -> server; returns the record offsets in b. */
static void three_records(sides *s, tf_buf *b, size_t off[4])
{
    const char *msg[3] = {"first frame", "second frame, longer", "third"};
    for (int i = 0; i < 3; i++) {
        off[i] = b->len;
        assert_int_equal(tf_seal_append(&s->ctx, b, (const uint8_t *)msg[i], strlen(msg[i])), 0);
    }
    off[3] = b->len;
}

static long open_at(tf_seal *rx, tf_buf *b, size_t from, size_t to, tf_buf *plain)
{
    char err[160];
    return tf_seal_open(rx, tf_buf_head(b) + from, to - from, plain, err, sizeof err);
}

static void test_round_trip_in_order(void **state)
{
    (void)state;
    sides s;
    make_sides(&s, 1);
    tf_buf b, plain;
    tf_buf_init(&b);
    tf_buf_init(&plain);
    size_t off[4];
    three_records(&s, &b, off);
    for (int i = 0; i < 3; i++)
        assert_int_equal(open_at(&s.srx, &b, off[i], off[i + 1], &plain),
                         (long)(off[i + 1] - off[i]));
    assert_int_equal(plain.len, strlen("first framesecond frame, longerthird"));
    assert_memory_equal(tf_buf_head(&plain), "first framesecond frame, longerthird", plain.len);
    /* incomplete record: wait */
    assert_int_equal(open_at(&s.srx, &b, off[0], off[0] + 10, &plain), 0);
    /* a large plaintext is split into records the other side reassembles */
    static uint8_t big[3 * TF_SEAL_RECORD_MAX + 5];
    memset(big, 0xab, sizeof big);
    tf_buf r, out;
    tf_buf_init(&r);
    tf_buf_init(&out);
    assert_int_equal(tf_seal_append(&s.stx, &r, big, sizeof big), 0);
    size_t at = 0;
    while (at < r.len) {
        long n = open_at(&s.crx, &r, at, r.len, &out);
        assert_true(n > 0);
        at += (size_t)n;
    }
    assert_int_equal(out.len, sizeof big);
    assert_memory_equal(tf_buf_head(&out), big, sizeof big);
    tf_buf_free(&r);
    tf_buf_free(&out);
    tf_buf_free(&b);
    tf_buf_free(&plain);
}

static void test_tampering_fails(void **state)
{
    (void)state;
    tf_buf b, plain;
    size_t off[4];
    for (int attack = 0; attack < 6; attack++) {
        sides s;
        make_sides(&s, 1);
        tf_buf_init(&b);
        tf_buf_init(&plain);
        three_records(&s, &b, off);
        long rc = 0;
        switch (attack) {
        case 0: /* a flipped byte of the ciphertext */
            tf_buf_head(&b)[off[0] + 6] ^= 0x01;
            rc = open_at(&s.srx, &b, off[0], off[1], &plain);
            break;
        case 1: /* a flipped bit of the length (associated data) */
            tf_buf_head(&b)[off[1]] ^= 0x01;
            assert_true(open_at(&s.srx, &b, off[0], off[1], &plain) > 0);
            rc = open_at(&s.srx, &b, off[1], off[3], &plain);
            break;
        case 2: /* replay record 0 */
            assert_true(open_at(&s.srx, &b, off[0], off[1], &plain) > 0);
            rc = open_at(&s.srx, &b, off[0], off[1], &plain);
            break;
        case 3: /* reorder: record 1 first */
            rc = open_at(&s.srx, &b, off[1], off[2], &plain);
            break;
        case 4: /* reflected back to its sender (the other direction's key) */
            rc = open_at(&s.crx, &b, off[0], off[1], &plain);
            break;
        case 5: { /* from another connection (other nonces) */
            sides t;
            make_sides(&t, 2);
            rc = open_at(&t.srx, &b, off[0], off[1], &plain);
            break;
        }
        }
        assert_int_equal(rc, -1);
        assert_int_equal(plain.len, attack == 1 || attack == 2 ? strlen("first frame") : 0);
        tf_buf_free(&b);
        tf_buf_free(&plain);
    }
}

static void test_length_bounds(void **state)
{
    (void)state;
    sides s;
    make_sides(&s, 1);
    tf_buf plain;
    tf_buf_init(&plain);
    char err[160];
    uint8_t huge[4] = {0xff, 0xff, 0xff, 0x7f}, tiny[4] = {16, 0, 0, 0};
    assert_int_equal(tf_seal_open(&s.srx, huge, 4, &plain, err, sizeof err), -1);
    assert_int_equal(tf_seal_open(&s.srx, tiny, 4, &plain, err, sizeof err), -1);
    tf_buf_free(&plain);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip_in_order),
        cmocka_unit_test(test_tampering_fails),
        cmocka_unit_test(test_length_bounds),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
