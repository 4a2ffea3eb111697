/* test_exrzip.c: the ZIP / ZIPS chunk packer on libdeflate (common/image/exrzip.h).
 *
 * A packed chunk must be what OpenEXR writes for ZIP: a zlib stream of the bytes after the byte
 * split and the delta predictor, or the bytes themselves when that would not be smaller.  The
 * tests undo a packed chunk here with zlib and OpenEXR's inverse filter, written out again so
 * that a mistake in exrzip.c is not mirrored, and ask exrcheck (the coordinator's check of a
 * worker's chunk) whether it decodes.  Whole files written through the packer are read back by
 * OpenEXRCore in test_exrfile and by exrcmp in every end-to-end render.  exrcheck's vector undo
 * of the predictor is checked against the plain loop. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "image/exrcheck.h"
#include "image/exrpart.h"
#include "image/exrzip.h"

/* OpenEXR's reader: inflate, undo the predictor, interleave the two halves.  0 when `packed`
 * unpacks to exactly the n bytes of `want`. */
static int unpacks_to(const uint8_t *packed, size_t len, const uint8_t *want, size_t n)
{
    if (len == n)
        return memcmp(packed, want, n) == 0 ? 0 : -1; /* stored raw */
    uint8_t *t = malloc(n + 1), *out = malloc(n);
    uLongf got = (uLongf)n + 1;
    int ok = t && out && uncompress(t, &got, packed, (uLong)len) == Z_OK && got == n;
    for (size_t i = 1; ok && i < n; i++)
        t[i] = (uint8_t)(t[i - 1] + t[i] - 128);
    size_t half = (n + 1) / 2;
    for (size_t i = 0; ok && i < n; i++)
        out[i] = i % 2 ? t[half + i / 2] : t[i / 2];
    ok = ok && memcmp(out, want, n) == 0;
    free(t);
    free(out);
    return ok ? 0 : -1;
}

/* Bytes like a chunk's: slowly varying 16-bit values, low byte first. */
static void smooth(uint8_t *p, size_t n, unsigned seed)
{
    for (size_t i = 0; i < n; i++)
        p[i] = i % 2 ? (uint8_t)(0x3c + (i / 512) % 3) : (uint8_t)(seed + i / 7);
}

static void noise(uint8_t *p, size_t n, unsigned seed)
{
    uint64_t x = 0x9e3779b97f4a7c15u ^ seed;
    for (size_t i = 0; i < n; i++) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        p[i] = (uint8_t)(x >> 24);
    }
}

static void test_round_trip_every_length(void **state)
{
    (void)state;
    static const size_t lengths[] = {2, 3, 4, 17, 64, 1000, 1001, 4096, 65537, 262144};
    tf_exr_zip *z = tf_exr_zip_new(TF_EXR_ZIP_LEVEL);
    assert_non_null(z);
    for (size_t k = 0; k < sizeof lengths / sizeof lengths[0]; k++) {
        size_t n = lengths[k], len = 0;
        uint8_t *in = malloc(n);
        smooth(in, n, (unsigned)k);
        const uint8_t *packed = tf_exr_zip_pack(z, in, n, &len);
        assert_non_null(packed);
        assert_true(len > 0 && len <= n);
        if (n >= 1000)
            assert_true(len < n / 4); /* it does compress what compresses */
        assert_int_equal(unpacks_to(packed, len, in, n), 0);
        free(in);
    }
    tf_exr_zip_free(z);
}

/* Noise does not shrink: stored raw, so a reader sees packed size == unpacked size. */
static void test_incompressible_is_stored_raw(void **state)
{
    (void)state;
    tf_exr_zip *z = tf_exr_zip_new(TF_EXR_ZIP_LEVEL);
    for (size_t n = 1; n <= 40000; n = n * 3 + 1) {
        uint8_t *in = malloc(n);
        noise(in, n, (unsigned)n);
        size_t len = 0;
        const uint8_t *packed = tf_exr_zip_pack(z, in, n, &len);
        assert_int_equal(len, n);
        assert_memory_equal(packed, in, n);
        free(in);
    }
    tf_exr_zip_free(z);
}

/* What the coordinator asks of a networked worker's chunk (exrcheck.h) holds for ours. */
static void test_exrcheck_accepts_packed_chunks(void **state)
{
    (void)state;
    tf_exr_zip *z = tf_exr_zip_new(TF_EXR_ZIP_LEVEL);
    uint8_t *scratch = NULL;
    size_t cap = 0, n = 128 * 16 * 16;
    uint8_t *in = malloc(n);
    smooth(in, n, 5);
    size_t len = 0;
    const uint8_t *packed = tf_exr_zip_pack(z, in, n, &len);
    assert_true(len < n);
    assert_int_equal(tf_exr_chunk_decodes(packed, len, n, &scratch, &cap), 0);
    assert_int_equal(tf_exr_chunk_decodes(packed, len, n - 1, &scratch, &cap), -1);
    free(in);
    free(scratch);
    tf_exr_zip_free(z);
}

/* The same bytes pack to the same stream, however often and after whatever came before: the
 * file's bytes depend on its pixels alone (README, "The decomposition invariant"). */
static void test_packing_is_deterministic(void **state)
{
    (void)state;
    tf_exr_zip *a = tf_exr_zip_new(TF_EXR_ZIP_LEVEL), *b = tf_exr_zip_new(TF_EXR_ZIP_LEVEL);
    size_t n = 50000, la = 0, lb = 0;
    uint8_t *in = malloc(n), *other = malloc(3 * n);
    smooth(in, n, 9);
    noise(other, 3 * n, 1);
    size_t ignored;
    assert_non_null(tf_exr_zip_pack(b, other, 3 * n, &ignored)); /* b has packed before */
    const uint8_t *pa = tf_exr_zip_pack(a, in, n, &la);
    const uint8_t *pb = tf_exr_zip_pack(b, in, n, &lb);
    assert_int_equal(la, lb);
    assert_memory_equal(pa, pb, la);
    free(in);
    free(other);
    tf_exr_zip_free(a);
    tf_exr_zip_free(b);
}

/* exrcheck's vector undo of the predictor is the plain loop, byte for byte: every length from
 * 0 to 200 (whole blocks of 16, tails, the block boundary after the first byte), every byte
 * value, and a long run whose sums wrap many times. */
static void test_undo_delta_matches_the_loop(void **state)
{
    (void)state;
    enum { MAX = 4096 };
    static uint8_t a[MAX], b[MAX];
    uint32_t x = 12345;
    for (size_t n = 0; n <= MAX; n = n < 200 ? n + 1 : n * 2 + 7) {
        size_t len = n < MAX ? n : MAX;
        for (size_t i = 0; i < len; i++)
            a[i] = b[i] = (uint8_t)((x = x * 1103515245u + 12345u) >> 16);
        tf_exr_undo_delta(a, len);
        for (size_t i = 1; i < len; i++)
            b[i] = (uint8_t)(b[i - 1] + b[i] - 128);
        assert_memory_equal(a, b, len ? len : 1);
    }
    for (int v = 0; v < 256; v++) {
        memset(a, v, 64), memset(b, v, 64);
        tf_exr_undo_delta(a, 64);
        for (size_t i = 1; i < 64; i++)
            b[i] = (uint8_t)(b[i - 1] + b[i] - 128);
        assert_memory_equal(a, b, 64);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip_every_length),
        cmocka_unit_test(test_incompressible_is_stored_raw),
        cmocka_unit_test(test_exrcheck_accepts_packed_chunks),
        cmocka_unit_test(test_packing_is_deterministic),
        cmocka_unit_test(test_undo_delta_matches_the_loop),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
