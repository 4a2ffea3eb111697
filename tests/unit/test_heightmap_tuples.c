/* test_heightmap_tuples.c: the height map's trip through the tuple space
 * (common/heightmap_tuples.c): descriptor and chunks round-trip through the space bit for bit;
 * a short, long, missing, reordered or damaged chunk, a lying descriptor (size, chunk count,
 * hash) and a malformed tuple are each one error line naming the coordinator, never a crash. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "heightmap_tuples.h"

#define FROM "10.0.0.1:7878"

static void hex_sha256(const uint8_t *d, size_t n, char out[65])
{
    uint8_t h[32];
    crypto_hash_sha256(h, d, n);
    for (int i = 0; i < 32; i++)
        sprintf(out + 2 * i, "%02x", h[i]);
}

/* 2.5 chunks of pseudo-random bytes */
static uint8_t *sample(size_t *n)
{
    *n = TF_HEIGHTMAP_CHUNK_BYTES * 2 + TF_HEIGHTMAP_CHUNK_BYTES / 2;
    uint8_t *d = malloc(*n);
    uint32_t x = 12345;
    for (size_t i = 0; i < *n; i++) {
        x = x * 1664525u + 1013904223u;
        d[i] = (uint8_t)(x >> 24);
    }
    return d;
}

/* Run the receiver over the chunks of data (optionally tampered with by `tamper`). */
typedef void (*tamper_fn)(int64_t index, uint8_t *chunk, size_t *n, int64_t *as_index);

static int receive(const uint8_t *data, size_t n, const char *sha, size_t announced,
                   tamper_fn tamper, char *err, size_t errlen, uint8_t **out, size_t *outlen)
{
    tf_tuple t;
    tf_heightmap_rx rx;
    assert_int_equal(tf_heightmap_desc_pack(&t, announced, sha), 0);
    int rc = tf_heightmap_rx_begin(&rx, FROM, &t, err, errlen);
    tf_tuple_clear(&t);
    int64_t chunks = (int64_t)((n + TF_HEIGHTMAP_CHUNK_BYTES - 1) / TF_HEIGHTMAP_CHUNK_BYTES);
    uint8_t *buf = malloc(TF_HEIGHTMAP_CHUNK_BYTES + 16);
    for (int64_t i = 0; rc == 0 && i < chunks; i++) {
        size_t off = (size_t)i * TF_HEIGHTMAP_CHUNK_BYTES;
        size_t len = n - off < TF_HEIGHTMAP_CHUNK_BYTES ? n - off : TF_HEIGHTMAP_CHUNK_BYTES;
        memcpy(buf, data + off, len);
        int64_t as = i;
        if (tamper)
            tamper(i, buf, &len, &as);
        if (as < 0)
            continue; /* dropped */
        assert_int_equal(tf_heightmap_chunk_pack(&t, as, buf, len), 0);
        rc = tf_heightmap_rx_chunk(&rx, &t, err, errlen);
        tf_tuple_clear(&t);
    }
    free(buf);
    if (rc == 0)
        rc = tf_heightmap_rx_finish(&rx, out, outlen, err, errlen);
    tf_heightmap_rx_free(&rx);
    return rc;
}

static void test_through_the_space(void **state)
{
    (void)state;
    size_t n;
    uint8_t *data = sample(&n);
    tf_scene s;
    memset(&s, 0, sizeof s);
    s.terrain.generator = TF_GEN_FILE;
    s.heightmap = data;
    s.heightmap_len = n;
    hex_sha256(data, n, s.terrain.file_sha256);
    ts_space *space = ts_space_new();
    assert_int_equal(tf_heightmap_tuples_put(space, &s), 0);
    /* take them back out of the space as a worker would read them */
    tf_tuple tmpl, got;
    tf_heightmap_rx rx;
    char err[256];
    tf_tuple_init(&tmpl);
    assert_int_equal(tf_tuple_pack(&tmpl, "sIIS", "heightmap"), 0);
    assert_int_equal(ts_space_rdp(space, &tmpl, &got), 1);
    assert_int_equal(tf_heightmap_rx_begin(&rx, FROM, &got, err, sizeof err), 0);
    assert_int_equal(rx.chunks, 3);
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    for (int64_t i = 0; i < rx.chunks; i++) {
        assert_int_equal(tf_tuple_pack(&tmpl, "siB", "heightmap_chunk", i), 0);
        assert_int_equal(ts_space_rdp(space, &tmpl, &got), 1);
        assert_int_equal(tf_heightmap_rx_chunk(&rx, &got, err, sizeof err), 0);
        tf_tuple_clear(&tmpl);
        tf_tuple_clear(&got);
    }
    uint8_t *out;
    size_t outlen;
    assert_int_equal(tf_heightmap_rx_finish(&rx, &out, &outlen, err, sizeof err), 0);
    assert_int_equal(outlen, n);
    assert_memory_equal(out, data, n);
    free(out);
    tf_heightmap_rx_free(&rx);
    ts_space_free(space);
    free(data);
}

static void short_last(int64_t i, uint8_t *c, size_t *n, int64_t *as) { (void)c; (void)as; if (i == 2) *n -= 1; }
static void long_first(int64_t i, uint8_t *c, size_t *n, int64_t *as) { (void)c; (void)as; if (i == 0) *n += 1; }
static void drop_middle(int64_t i, uint8_t *c, size_t *n, int64_t *as) { (void)c; (void)n; if (i == 1) *as = -1; }
static void swap_index(int64_t i, uint8_t *c, size_t *n, int64_t *as) { (void)c; (void)n; if (i == 1) *as = 2; }
static void flip_bit(int64_t i, uint8_t *c, size_t *n, int64_t *as) { (void)n; (void)as; if (i == 1) c[100] ^= 4; }
static void drop_last(int64_t i, uint8_t *c, size_t *n, int64_t *as) { (void)c; (void)n; if (i == 2) *as = -1; }

static void expect(const uint8_t *d, size_t n, const char *sha, size_t announced, tamper_fn f,
                   const char *words)
{
    char err[256] = "";
    uint8_t *out = NULL;
    size_t outlen;
    if (receive(d, n, sha, announced, f, err, sizeof err, &out, &outlen) == 0)
        fail_msg("accepted, expected \"%s\"", words);
    if (strncmp(err, FROM ": ", strlen(FROM) + 2) != 0 || !strstr(err, words) ||
        strchr(err, '\n'))
        fail_msg("got \"%s\", expected \"" FROM ": ...%s...\"", err, words);
}

static void test_hostile_transfers(void **state)
{
    (void)state;
    size_t n;
    uint8_t *data = sample(&n);
    char sha[65];
    hex_sha256(data, n, sha);
    uint8_t *out;
    size_t outlen;
    char err[256];
    assert_int_equal(receive(data, n, sha, n, NULL, err, sizeof err, &out, &outlen), 0);
    free(out);
    expect(data, n, sha, n, short_last, "chunk 2 has 4194303 bytes, expected 4194304");
    expect(data, n, sha, n, long_first, "chunk 0 has 8388609 bytes, expected 8388608");
    expect(data, n, sha, n, drop_middle, "chunk 2 where chunk 1 of 3 was expected");
    expect(data, n, sha, n, swap_index, "chunk 2 where chunk 1 of 3 was expected");
    expect(data, n, sha, n, flip_bit, "damaged in transfer");
    expect(data, n, sha, n, drop_last, "incomplete (2 of 3 chunks)");
    expect(data, n, sha, n + 1, NULL, "chunk 2 has 4194304 bytes, expected 4194305");
    expect(data, n, sha, TF_HEIGHTMAP_MAX_BYTES + 1, NULL, "at most 512 MiB");
    expect(data, n, sha, 0, NULL, "height map of 0 bytes");
    char bad[65];
    memcpy(bad, sha, 65);
    bad[0] = bad[0] == 'a' ? 'b' : 'a';
    expect(data, n, bad, n, NULL, "damaged in transfer");
    /* malformed tuples: wrong chunk count, wrong types, wrong name */
    tf_tuple t;
    tf_heightmap_rx rx;
    tf_tuple_init(&t);
    assert_int_equal(tf_tuple_pack(&t, "siis", "heightmap", (int64_t)n, (int64_t)99, sha), 0);
    assert_int_equal(tf_heightmap_rx_begin(&rx, FROM, &t, err, sizeof err), -1);
    assert_non_null(strstr(err, "announced in 99 chunks, not 3"));
    tf_tuple_clear(&t);
    assert_int_equal(tf_tuple_pack(&t, "sisi", "heightmap", (int64_t)n, sha, (int64_t)3), 0);
    assert_int_equal(tf_heightmap_rx_begin(&rx, FROM, &t, err, sizeof err), -1);
    assert_string_equal(err, FROM ": malformed height map descriptor");
    tf_tuple_clear(&t);
    assert_int_equal(tf_tuple_pack(&t, "siis", "heightmap", (int64_t)n, (int64_t)3, "xyz"), 0);
    assert_int_equal(tf_heightmap_rx_begin(&rx, FROM, &t, err, sizeof err), -1);
    tf_tuple_clear(&t);
    assert_int_equal(tf_heightmap_desc_pack(&t, n, sha), 0);
    assert_int_equal(tf_heightmap_rx_begin(&rx, FROM, &t, err, sizeof err), 0);
    tf_tuple_clear(&t);
    assert_int_equal(tf_tuple_pack(&t, "sis", "heightmap_chunk", (int64_t)0, "text"), 0);
    assert_int_equal(tf_heightmap_rx_chunk(&rx, &t, err, sizeof err), -1);
    assert_string_equal(err, FROM ": malformed height map chunk 0");
    tf_tuple_clear(&t);
    tf_heightmap_rx_free(&rx);
    free(data);
}

int main(void)
{
    if (sodium_init() < 0)
        return 1;
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_through_the_space),
        cmocka_unit_test(test_hostile_transfers),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
