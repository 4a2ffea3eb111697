/* test_tuple.c: tuples and templates (common/linda/tuple.c) and frame parsing (common/linda/proto.c):
 * encode/decode round trips of every field type, matching rules, decoder rejection of malformed
 * input, and frame header validation. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "linda/auth.h"
#include "linda/proto.h"
#include "linda/sock.h"
#include "linda/tuple.h"

static void round_trip(const tf_tuple *t, int allow_formals)
{
    size_t n = tf_tuple_encoded_size(t);
    uint8_t buf[4096];
    assert_true(n <= sizeof buf);
    assert_int_equal(tf_tuple_encode(t, buf), n);
    tf_tuple back;
    char err[128];
    assert_int_equal(tf_tuple_decode(buf, n, &back, allow_formals, err, sizeof err), 0);
    assert_true(tf_tuple_equal(t, &back));
    tf_tuple_clear(&back);
}

static void test_round_trip_every_type(void **state)
{
    (void)state;
    tf_tuple t;
    tf_tuple_init(&t);
    uint8_t blob[300];
    for (int i = 0; i < 300; i++)
        blob[i] = (uint8_t)(i * 7);
    assert_int_equal(tf_tuple_pack(&t, "sidsbb", "task", (int64_t)-9000000000LL, -0.0, "",
                                   blob, sizeof blob, blob, (size_t)0), 0);
    assert_int_equal(t.nfields, 6);
    round_trip(&t, 0);
    const char *s;
    assert_int_equal(tf_tuple_get_string(&t, 3, &s), 0);
    assert_string_equal(s, "");
    const uint8_t *b;
    size_t bl;
    assert_int_equal(tf_tuple_get_blob(&t, 5, &b, &bl), 0);
    assert_int_equal(bl, 0);
    tf_tuple_clear(&t);

    tf_tuple_init(&t);
    assert_int_equal(tf_tuple_pack(&t, "SIDB"), 0);
    round_trip(&t, 1);
    tf_tuple_clear(&t);

    tf_tuple_init(&t); /* the empty tuple */
    round_trip(&t, 0);
}

static void test_max_fields(void **state)
{
    (void)state;
    tf_tuple t;
    tf_tuple_init(&t);
    for (int i = 0; i < TF_TUPLE_MAX_FIELDS; i++)
        assert_int_equal(tf_tuple_add_int(&t, i), 0);
    assert_int_equal(tf_tuple_add_int(&t, 99), -1);
    round_trip(&t, 0);
    assert_int_equal(tf_tuple_add_stringn(&(tf_tuple){0}, "a\0b", 3), -1);
}

static void test_match_rules(void **state)
{
    (void)state;
    tf_tuple t, m;
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "sidb", "result", (int64_t)7, 1.5, "xy", (size_t)2);

    tf_tuple_init(&m); /* all actuals, equal */
    tf_tuple_pack(&m, "sidb", "result", (int64_t)7, 1.5, "xy", (size_t)2);
    assert_true(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);

    tf_tuple_init(&m); /* formals */
    tf_tuple_pack(&m, "SIDB");
    assert_true(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);

    tf_tuple_init(&m); /* different actual */
    tf_tuple_pack(&m, "siDB", "result", (int64_t)8);
    assert_false(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);

    tf_tuple_init(&m); /* type mismatch: formal double where an int is */
    tf_tuple_pack(&m, "sDDB", "result");
    assert_false(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);

    tf_tuple_init(&m); /* arity mismatch */
    tf_tuple_pack(&m, "siD", "result", (int64_t)7);
    assert_false(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);

    tf_tuple_init(&m); /* blob prefix is not equal */
    tf_tuple_pack(&m, "sidb", "result", (int64_t)7, 1.5, "x", (size_t)1);
    assert_false(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);

    tf_tuple_clear(&t);
    tf_tuple_init(&t); /* doubles compare bitwise: 0.0 is not -0.0 */
    tf_tuple_pack(&t, "sd", "z", 0.0);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "sd", "z", -0.0);
    assert_false(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "sd", "z", 0.0);
    assert_true(tf_tuple_match(&m, &t));
    tf_tuple_clear(&m);
    tf_tuple_clear(&t);
}

static void test_decode_rejects_malformed(void **state)
{
    (void)state;
    tf_tuple out;
    char err[128];
    const uint8_t too_many[] = {17};
    assert_int_equal(tf_tuple_decode(too_many, 1, &out, 1, err, sizeof err), -1);
    const uint8_t long_string[] = {1, 3, 0xff, 0xff, 0xff, 0x7f, 'a'};
    assert_int_equal(tf_tuple_decode(long_string, sizeof long_string, &out, 1, err, sizeof err), -1);
    assert_non_null(strstr(err, "exceeds"));
    const uint8_t bad_type[] = {1, 9};
    assert_int_equal(tf_tuple_decode(bad_type, 2, &out, 1, err, sizeof err), -1);
    const uint8_t formal[] = {1, 0x81};
    assert_int_equal(tf_tuple_decode(formal, 2, &out, 0, err, sizeof err), -1);
    assert_int_equal(tf_tuple_decode(formal, 2, &out, 1, err, sizeof err), 0);
    tf_tuple_clear(&out);
    const uint8_t trailing[] = {0, 0};
    assert_int_equal(tf_tuple_decode(trailing, 2, &out, 1, err, sizeof err), -1);
    const uint8_t nul_string[] = {1, 3, 1, 0, 0, 0, 0};
    assert_int_equal(tf_tuple_decode(nul_string, sizeof nul_string, &out, 1, err, sizeof err), -1);
    const uint8_t short_int[] = {1, 1, 1, 2, 3};
    assert_int_equal(tf_tuple_decode(short_int, sizeof short_int, &out, 1, err, sizeof err), -1);
    assert_int_equal(out.nfields, 0);
}

/* tf_tuple_view: equal to the decoded tuple, its blobs inside the encoding (not copied), its
 * strings copies; the same rejections as the decoder, formals included; a failed view is
 * empty (a blob before the fault is not freed: the sanitizer build would catch it). */
static void test_view_borrows_blobs(void **state)
{
    (void)state;
    tf_tuple t, v;
    tf_tuple_init(&t);
    uint8_t blob[100], enc[512];
    memset(blob, 0xab, sizeof blob);
    assert_int_equal(tf_tuple_pack(&t, "sibs", "result", (int64_t)7, blob, sizeof blob, "x"), 0);
    size_t n = tf_tuple_encode(&t, enc);
    char err[128];
    assert_int_equal(tf_tuple_view(enc, n, &v, err, sizeof err), 0);
    assert_true(tf_tuple_equal(&t, &v));
    assert_true(v.f[2].v.bytes.ptr > enc && v.f[2].v.bytes.ptr + 100 <= enc + n);
    assert_true(v.f[0].v.bytes.ptr < enc || v.f[0].v.bytes.ptr >= enc + n);
    tf_tuple_view_clear(&v);
    assert_int_equal(v.nfields, 0);
    const uint8_t formal[] = {1, 0x84};
    assert_int_equal(tf_tuple_view(formal, 2, &v, err, sizeof err), -1);
    assert_int_equal(tf_tuple_view(enc, n - 1, &v, err, sizeof err), -1);
    assert_int_equal(v.nfields, 0);
    tf_tuple_clear(&t);
}

/* tf_tuple_decode_shared: blobs of min_shared bytes or more stay in the encoding's memory (a
 * reference to its owner), smaller ones and strings are copies; the tuple keeps that memory
 * alive after the caller lets go of it, a copy of the tuple does not need it, and the last
 * reference frees it (make asan: no use after free, no leak).  A malformed encoding leaves an
 * empty tuple and gives back the references taken before the fault. */
static void test_decode_shared_keeps_large_blobs_in_place(void **state)
{
    (void)state;
    tf_tuple t, d, copy;
    tf_tuple_init(&t);
    uint8_t big[5000], little[10];
    memset(big, 0x5a, sizeof big);
    memset(little, 0x11, sizeof little);
    assert_int_equal(tf_tuple_pack(&t, "sbbb", "result", big, sizeof big, little, sizeof little,
                                   big, (size_t)4096), 0);
    size_t n = tf_tuple_encoded_size(&t);
    uint8_t *enc = malloc(n);
    assert_non_null(enc);
    assert_int_equal(tf_tuple_encode(&t, enc), n);
    tf_shared_bytes *owner = tf_shared_bytes_adopt(enc);
    assert_non_null(owner);
    char err[128];
    assert_int_equal(tf_tuple_decode_shared(enc, n, owner, 4096, &d, err, sizeof err), 0);
    assert_true(tf_tuple_equal(&t, &d));
    assert_ptr_equal(d.f[1].v.bytes.shared, owner);
    assert_true(d.f[1].v.bytes.ptr > enc && d.f[1].v.bytes.ptr + sizeof big <= enc + n);
    assert_ptr_equal(d.f[3].v.bytes.shared, owner);
    assert_null(d.f[2].v.bytes.shared); /* under min_shared: a copy */
    assert_true(d.f[2].v.bytes.ptr < enc || d.f[2].v.bytes.ptr >= enc + n);
    assert_null(d.f[0].v.bytes.shared);
    tf_shared_bytes_release(owner); /* the caller's reference: d's two keep enc */
    assert_int_equal(tf_tuple_copy(&copy, &d), 0);
    assert_null(copy.f[1].v.bytes.shared);
    assert_int_equal(d.f[1].v.bytes.ptr[4999], 0x5a);
    tf_tuple_clear(&d); /* the last references: enc is freed */
    assert_true(tf_tuple_equal(&t, &copy));
    tf_tuple_clear(&copy);

    /* a fault after a shared blob: nothing kept, its reference given back */
    enc = malloc(n);
    assert_non_null(enc);
    tf_tuple_encode(&t, enc);
    owner = tf_shared_bytes_adopt(enc);
    assert_int_equal(tf_tuple_decode_shared(enc, n - 1, owner, 4096, &d, err, sizeof err), -1);
    assert_int_equal(d.nfields, 0);
    tf_shared_bytes_release(owner); /* the only reference left: freed (else a leak) */
    tf_tuple_clear(&t);
}

static void test_frame_parse(void **state)
{
    (void)state;
    tf_buf b;
    tf_buf_init(&b);
    tf_tuple t;
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "si", "task", (int64_t)3);
    assert_int_equal(tf_frame_append_tuple(&b, TF_OP_OUT, 42, &t), 0);
    tf_frame f;
    char err[128];
    for (size_t cut = 0; cut < b.len; cut++) /* every prefix: need more */
        assert_int_equal(tf_frame_parse(tf_buf_head(&b), cut, &f, err, sizeof err), 0);
    assert_int_equal(tf_frame_parse(tf_buf_head(&b), b.len, &f, err, sizeof err), (long)b.len);
    assert_int_equal(f.op, TF_OP_OUT);
    assert_int_equal(f.request_id, 42);
    tf_tuple back;
    assert_int_equal(tf_tuple_decode(f.body, f.body_len, &back, 0, err, sizeof err), 0);
    assert_true(tf_tuple_equal(&t, &back));
    tf_tuple_clear(&back);
    tf_tuple_clear(&t);
    tf_buf_free(&b);

    const uint8_t oversized[4] = {0xff, 0xff, 0xff, 0xff};
    assert_int_equal(tf_frame_parse(oversized, 4, &f, err, sizeof err), -1);
    const uint8_t tiny[4] = {5, 0, 0, 0};
    assert_int_equal(tf_frame_parse(tiny, 4, &f, err, sizeof err), -1);
    const uint8_t badver[6] = {6, 0, 0, 0, 2, 1};
    assert_int_equal(tf_frame_parse(badver, 6, &f, err, sizeof err), -1);
    const uint8_t badop[6] = {6, 0, 0, 0, 1, 99};
    assert_int_equal(tf_frame_parse(badop, 6, &f, err, sizeof err), -1);
    assert_non_null(strstr(err, "unknown op"));
}

/* tf_buf_trim gives back an empty buffer's memory only past `keep`, never a buffer in use. */
static void test_buf_trim(void **state)
{
    (void)state;
    tf_buf b;
    tf_buf_init(&b);
    static uint8_t big[300 * 1024];
    assert_int_equal(tf_buf_append(&b, big, sizeof big), 0);
    tf_buf_trim(&b, 256 * 1024);
    assert_non_null(b.data); /* holds bytes: kept */
    tf_buf_consume(&b, sizeof big);
    tf_buf_trim(&b, 256 * 1024);
    assert_null(b.data);
    assert_int_equal(b.cap, 0);
    assert_int_equal(tf_buf_append(&b, big, 1000), 0); /* usable again */
    tf_buf_consume(&b, 1000);
    tf_buf_trim(&b, 256 * 1024);
    assert_non_null(b.data); /* small: kept for reuse */
    tf_buf_free(&b);
}

static void test_hostport_and_loopback(void **state)
{
    (void)state;
    char h[64], p[16], err[128];
    assert_int_equal(tf_split_hostport("127.0.0.1:7000", h, sizeof h, p, sizeof p, err, sizeof err), 0);
    assert_string_equal(h, "127.0.0.1");
    assert_string_equal(p, "7000");
    assert_int_equal(tf_split_hostport("[::1]:0", h, sizeof h, p, sizeof p, err, sizeof err), 0);
    assert_string_equal(h, "::1");
    assert_int_equal(tf_split_hostport("nohost", h, sizeof h, p, sizeof p, err, sizeof err), -1);
    assert_int_equal(tf_split_hostport("a:99999", h, sizeof h, p, sizeof p, err, sizeof err), -1);
    assert_true(tf_addr_is_loopback("127.0.0.1"));
    assert_true(tf_addr_is_loopback("127.9.9.9"));
    assert_true(tf_addr_is_loopback("::1"));
    assert_true(tf_addr_is_loopback("localhost"));
    assert_false(tf_addr_is_loopback("0.0.0.0"));
    assert_false(tf_addr_is_loopback("::"));
    assert_false(tf_addr_is_loopback("10.0.0.1"));
    assert_false(tf_addr_is_loopback(""));
}

static void test_auth_macs(void **state)
{
    (void)state;
    uint8_t k1[TF_KEY_BYTES], k2[TF_KEY_BYTES], ns[TF_NONCE_BYTES], nc[TF_NONCE_BYTES];
    uint8_t mac[TF_MAC_BYTES];
    assert_int_equal(tf_secret_from_bytes("right", 5, k1), 0);
    assert_int_equal(tf_secret_from_bytes("wrong", 5, k2), 0);
    assert_int_equal(tf_secret_from_bytes("", 0, k2), -1);
    tf_secret_from_bytes("wrong", 5, k2);
    tf_auth_nonce(ns);
    tf_auth_nonce(nc);
    assert_memory_not_equal(ns, nc, TF_NONCE_BYTES);
    tf_auth_client_mac(k1, ns, nc, mac);
    assert_true(tf_auth_client_mac_ok(k1, ns, nc, mac));
    assert_false(tf_auth_client_mac_ok(k2, ns, nc, mac));
    assert_false(tf_auth_server_mac_ok(k1, ns, nc, mac)); /* no reflection */
    nc[0] ^= 1;
    assert_false(tf_auth_client_mac_ok(k1, ns, nc, mac));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip_every_type),
        cmocka_unit_test(test_max_fields),
        cmocka_unit_test(test_match_rules),
        cmocka_unit_test(test_decode_rejects_malformed),
        cmocka_unit_test(test_view_borrows_blobs),
        cmocka_unit_test(test_decode_shared_keeps_large_blobs_in_place),
        cmocka_unit_test(test_frame_parse),
        cmocka_unit_test(test_buf_trim),
        cmocka_unit_test(test_hostport_and_loopback),
        cmocka_unit_test(test_auth_macs),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
