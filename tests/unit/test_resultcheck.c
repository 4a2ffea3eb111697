/* test_resultcheck.c: the pixel checker (coordinator/render/resultcheck.c) against a result
 * whose bytes someone else can still write.  A forked worker's result reaches the coordinator
 * in the worker's shared outbox, and the tuple only references those bytes; under
 * --verify-chunks a lying child could let the checker pass good bytes and then rewrite them
 * before the writer copies them to the file.  Here the result's blobs lie in a buffer the test
 * owns (tf_tuple_decode_shared, as the outbox hands them over), and the test overwrites that
 * buffer with garbage right after submitting: the verdict must still be "passed", and the
 * tuple it hands back must hold the bytes that were checked, for a small result (checked on the
 * caller's thread) and a large one (on the checker's thread).  And garbage submitted as such
 * is refused, so the first two cannot pass by not looking.  A networked worker's result lies in
 * the receive buffer the server adopted, which nothing else writes: it is checked and handed
 * back where it lies, not copied. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "coordinator/render/resultcheck.h"
#include "farmproto.h"
#include "image/exrencode.h"

/* A result of task 7 from worker 3: rectangle r of layout l, its pixels varied (so that the
 * chunks compress to something garbage cannot imitate). */
static void pack_result(const tf_exr_layout *l, tf_rect r, tf_tuple *t)
{
    char err[256];
    tf_pixel *px = malloc(sizeof *px * (size_t)r.w * (size_t)r.h);
    assert_non_null(px);
    for (int i = 0; i < r.w * r.h; i++)
        px[i] = (tf_pixel){(float)(i % 97) * 0.01f, (float)(i % 13) * 0.1f, 0.25f, 1.0f,
                           (float)i, (float)(1 + i % 5)};
    tf_exr_encoder *enc = tf_exr_encoder_new(l, err, sizeof err);
    assert_non_null(enc);
    tf_chunk_payload p;
    assert_int_equal(tf_exr_encode_rect(enc, r, px, &p, err, sizeof err), 0);
    tf_render_counts c = {.primary_rays = 10, .shadow_rays = 5};
    assert_int_equal(tf_result_pack(t, 7, 3, &c, 1234, 99, &p), 0);
    tf_exr_encoder_free(enc);
    free(px);
}

/* t's encoding in a malloc'd buffer (*len bytes). */
static uint8_t *encoded(const tf_tuple *t, size_t *len)
{
    *len = tf_tuple_encoded_size(t);
    uint8_t *buf = malloc(*len);
    assert_non_null(buf);
    assert_int_equal(tf_tuple_encode(t, buf), *len);
    return buf;
}

/* Wait for the verdict on the one result submitted: 0 passed, 1 refused. */
static int verdict(tf_resultcheck *rc, tf_tuple *out, char *why, size_t len)
{
    int v;
    while ((v = tf_resultcheck_next(rc, out, why, len)) < 0)
        usleep(1000);
    return v;
}

/* Submit r's result with its blobs in a buffer of the test's, overwrite the buffer, and expect
 * the result to pass with the bytes it had. */
static void expect_checked_bytes_kept(const tf_exr_layout *l, tf_rect r)
{
    tf_tuple original, shared, back;
    pack_result(l, r, &original);
    size_t n;
    uint8_t *want = encoded(&original, &n);
    uint8_t *mem = malloc(n);
    assert_non_null(mem);
    memcpy(mem, want, n);
    tf_shared_bytes *owner = tf_shared_bytes_wrap(free, mem); /* lent, as an outbox's */
    assert_non_null(owner);
    char err[256];
    assert_int_equal(tf_tuple_decode_shared(mem, n, owner, 1, &shared, err, sizeof err), 0);

    tf_resultcheck *rc = tf_resultcheck_new(l, 1, err, sizeof err);
    assert_non_null(rc);
    assert_int_equal(tf_resultcheck_submit(rc, &shared), 0);
    memset(mem, 0xa5, n); /* the other process rewrites its outbox */
    tf_tuple_init(&back);
    assert_int_equal(verdict(rc, &back, err, sizeof err), 0);
    size_t m;
    uint8_t *got = encoded(&back, &m);
    assert_int_equal(m, n);
    assert_memory_equal(got, want, n);

    free(got);
    free(want);
    tf_tuple_clear(&back);
    tf_tuple_clear(&original);
    tf_resultcheck_free(rc);
    tf_shared_bytes_release(owner);
}

static const tf_exr_layout layout = {256, 256, 0, 0, 0, TF_PIXEL_HALF};

static void test_small_result_keeps_the_bytes_it_passed(void **state)
{
    (void)state;
    expect_checked_bytes_kept(&layout, (tf_rect){0, 0, 256, 16}); /* 48 KiB decoded: inline */
}

static void test_large_result_keeps_the_bytes_it_passed(void **state)
{
    (void)state;
    expect_checked_bytes_kept(&layout, (tf_rect){0, 0, 256, 128}); /* 384 KiB: the thread */
}

/* A result whose blobs lie in adopted memory (a receive buffer) passes with its blobs where
 * they were: the checker took the tuple, not a copy. */
static void test_received_result_is_not_copied(void **state)
{
    (void)state;
    tf_tuple original, shared, back;
    pack_result(&layout, (tf_rect){0, 0, 256, 128}, &original);
    size_t n;
    uint8_t *mem = encoded(&original, &n);
    tf_shared_bytes *owner = tf_shared_bytes_adopt(mem);
    assert_non_null(owner);
    char err[256];
    assert_int_equal(tf_tuple_decode_shared(mem, n, owner, 1, &shared, err, sizeof err), 0);
    tf_resultcheck *rc = tf_resultcheck_new(&layout, 1, err, sizeof err);
    assert_non_null(rc);
    assert_int_equal(tf_resultcheck_submit(rc, &shared), 0);
    tf_tuple_init(&back);
    assert_int_equal(verdict(rc, &back, err, sizeof err), 0);
    int blobs = 0;
    for (int i = 0; i < back.nfields; i++)
        if (back.f[i].type == TF_FIELD_BLOB && back.f[i].v.bytes.shared) {
            assert_ptr_equal(back.f[i].v.bytes.shared, owner);
            assert_true(back.f[i].v.bytes.ptr >= mem && back.f[i].v.bytes.ptr < mem + n);
            blobs++;
        }
    assert_true(blobs > 0);
    tf_tuple_clear(&back);
    tf_tuple_clear(&original);
    tf_resultcheck_free(rc);
    tf_shared_bytes_release(owner);
}

/* The same garbage, submitted as the result's bytes, is refused. */
static void test_garbage_is_refused(void **state)
{
    (void)state;
    tf_tuple t, back;
    pack_result(&layout, (tf_rect){0, 0, 256, 128}, &t);
    tf_result_msg msg;
    assert_int_equal(tf_result_unpack(&t, &msg), 0);
    memset((uint8_t *)msg.chunks, 0xa5, msg.chunks_len);
    char err[256], why[256];
    tf_resultcheck *rc = tf_resultcheck_new(&layout, 1, err, sizeof err);
    assert_non_null(rc);
    assert_int_equal(tf_resultcheck_submit(rc, &t), 0);
    tf_tuple_init(&back);
    assert_int_equal(verdict(rc, &back, why, sizeof why), 1);
    tf_tuple_clear(&back);
    tf_resultcheck_free(rc);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_small_result_keeps_the_bytes_it_passed),
        cmocka_unit_test(test_large_result_keeps_the_bytes_it_passed),
        cmocka_unit_test(test_received_result_is_not_copied),
        cmocka_unit_test(test_garbage_is_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
