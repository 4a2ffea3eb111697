/* test_results.c: the result format of farmproto.h and its checks.  A worker's real encoder
 * (image/exrencode.c) packs a rectangle; the result tuple round-trips; tf_result_check accepts
 * it for its own task and refuses every structural lie (other chunk coordinates, another
 * task's rectangle, wrong unpacked or packed sizes, blob lengths that do not add up, a wrong
 * preview size); tf_exr_chunk_decodes refuses packed bytes that do not inflate to the chunk's
 * size; tf_exr_chunk_check finds a non-finite value at its exact channel and pixel, through
 * the ZIP filter, in scanline and tiled, half and float chunks; tf_result_counts_check refuses
 * counts beyond what a task can hold.  Also the layout's geometry (partial edge tiles, the
 * preview span partitioning the preview among tasks), and the other kinds of farm tuple
 * (scene, counter, hello, failed). */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "farmproto.h"
#include "image/exrcheck.h"
#include "image/exrencode.h"

#define W 100
#define H 45

static tf_pixel *image(int w, int h)
{
    tf_pixel *px = malloc(sizeof *px * (size_t)w * (size_t)h);
    assert_non_null(px);
    for (int i = 0; i < w * h; i++)
        px[i] = (tf_pixel){(float)(i % 97) * 0.01f, (float)(i % 13) * 0.1f, 0.25f, 1.0f,
                           (float)i, (float)(1 + i % 5)};
    return px;
}

/* Encode task rectangle r of layout l and pack it as task 7 of worker 3. */
static tf_exr_encoder *enc;
static void pack_rect(const tf_exr_layout *l, tf_rect r, tf_tuple *t)
{
    char err[256];
    tf_pixel *px = image(r.w, r.h);
    enc = tf_exr_encoder_new(l, err, sizeof err);
    assert_non_null(enc);
    tf_chunk_payload p;
    assert_int_equal(tf_exr_encode_rect(enc, r, px, &p, err, sizeof err), 0);
    tf_render_counts c = {.primary_rays = 10, .shadow_rays = 5, .external_rays = 2};
    assert_int_equal(tf_result_pack(t, 7, 3, &c, 1234, 99, &p), 0);
    free(px);
}

static void test_round_trip_and_check(void **state)
{
    (void)state;
    tf_exr_layout tiled = {W, H, 1, 16, 16, TF_PIXEL_HALF};
    tf_preview_grid g = tf_preview_grid_for(W, H);
    tf_rect r = {96, 32, 4, 13}; /* the partial corner tile */
    tf_tuple t;
    pack_rect(&tiled, r, &t);
    tf_result_msg m;
    char err[256];
    assert_int_equal(tf_result_unpack(&t, &m), 0);
    assert_int_equal(m.id, 7);
    assert_int_equal(m.worker, 3);
    assert_int_equal(m.spp_total, 99);
    assert_int_equal(m.nchunks, 1);
    assert_int_equal(tf_result_check(&m, &tiled, &g, r, err, sizeof err), 0);
    assert_int_equal(m.counts.pixels, 4 * 13);
    /* the same bytes answer no other task */
    tf_rect other = {80, 32, 16, 13};
    assert_int_equal(tf_result_check(&m, &tiled, &g, other, err, sizeof err), -1);
    assert_non_null(strstr(err, "chunk 0 is at (6, 2), the task's is at (5, 2)"));
    /* nor a file of another layout */
    tf_exr_layout floats = tiled;
    floats.pixel = TF_PIXEL_FLOAT;
    assert_int_equal(tf_result_check(&m, &floats, &g, r, err, sizeof err), -1);
    assert_non_null(strstr(err, "unpacked"));
    tf_tuple_clear(&t);
    tf_exr_encoder_free(enc);
}

/* Rewrite one index record or blob of a packed result and expect a refusal naming `words`. */
static void expect_refused(const tf_exr_layout *l, tf_rect r, int field, size_t at,
                           const void *bytes, size_t n, size_t new_len, const char *words)
{
    tf_tuple t;
    pack_rect(l, r, &t);
    tf_field *f = &t.f[field];
    if (new_len != (size_t)-1)
        f->v.bytes.len = (uint32_t)new_len;
    if (bytes)
        memcpy(f->v.bytes.ptr + at, bytes, n);
    tf_result_msg m;
    char err[256] = "";
    tf_preview_grid g = tf_preview_grid_for(l->width, l->height);
    int rc = tf_result_unpack(&t, &m);
    if (rc == 0)
        rc = tf_result_check(&m, l, &g, r, err, sizeof err);
    assert_int_equal(rc, -1);
    if (words && !strstr(err, words))
        fail_msg("refusal '%s' does not say '%s'", err, words);
    tf_tuple_clear(&t);
    tf_exr_encoder_free(enc);
}

static void test_lies_refused(void **state)
{
    (void)state;
    tf_exr_layout rows = {W, H, 0, 0, 0, TF_PIXEL_HALF};
    tf_rect r = {0, 7, W, 3}; /* rows 7..9: three chunks */
    int32_t y = 8;
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD, 4, &y, 4, (size_t)-1, "chunk 0 is at (0, 8)");
    int64_t big = 1 << 20, zero = 0;
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD, 16, &big, 8, (size_t)-1, "unpacked bytes");
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD, 8, &big, 8, (size_t)-1, "packed bytes");
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD, 8, &zero, 8, (size_t)-1, "packed bytes");
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD, 0, NULL, 0, 2 * TF_CHUNK_RECORD_BYTES, "2 chunks, the task has 3");
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD, 0, NULL, 0, 2 * TF_CHUNK_RECORD_BYTES + 5, NULL); /* not records */
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD + 1, 0, NULL, 0, 10, "add up");
    expect_refused(&rows, r, TF_RESULT_INDEX_FIELD + 2, 0, NULL, 0, 3, "preview");
    /* a task that is not whole chunks of the file */
    tf_rect half = {0, 7, W / 2, 3};
    tf_tuple t;
    pack_rect(&rows, r, &t);
    tf_result_msg m;
    char err[256];
    tf_preview_grid g = tf_preview_grid_for(W, H);
    assert_int_equal(tf_result_unpack(&t, &m), 0);
    assert_int_equal(tf_result_check(&m, &rows, &g, half, err, sizeof err), -1);
    tf_tuple_clear(&t);
    tf_exr_encoder_free(enc);
}

static void test_chunk_decodes(void **state)
{
    (void)state;
    tf_exr_layout tiled = {W, H, 1, 32, 16, TF_PIXEL_FLOAT};
    tf_rect r = {32, 16, 32, 16};
    tf_tuple t;
    pack_rect(&tiled, r, &t);
    tf_result_msg m;
    assert_int_equal(tf_result_unpack(&t, &m), 0);
    tf_chunk_rec c;
    tf_chunk_rec_get(m.index, &c);
    uint8_t *scratch = NULL;
    size_t cap = 0;
    assert_int_equal(tf_exr_chunk_decodes(m.chunks, (size_t)c.packed, (size_t)c.unpacked,
                                          &scratch, &cap), 0);
    assert_true(c.packed < c.unpacked); /* these pixels compress */
    uint8_t *bad = malloc((size_t)c.packed);
    memcpy(bad, m.chunks, (size_t)c.packed);
    bad[c.packed / 2] ^= 0x5a; /* zlib's checksum catches a flipped byte */
    assert_int_equal(tf_exr_chunk_decodes(bad, (size_t)c.packed, (size_t)c.unpacked, &scratch,
                                          &cap), -1);
    memset(bad, 0, (size_t)c.packed);
    assert_int_equal(tf_exr_chunk_decodes(bad, (size_t)c.packed, (size_t)c.unpacked, &scratch,
                                          &cap), -1);
    /* a stream that inflates to fewer bytes than the chunk's */
    assert_int_equal(tf_exr_chunk_decodes(m.chunks, (size_t)c.packed, (size_t)c.unpacked - 4,
                                          &scratch, &cap), -1);
    free(bad);
    free(scratch);
    tf_tuple_clear(&t);
    tf_exr_encoder_free(enc);
}

/* Encode r of layout l with one bad value at pixel (bx, by) of channel ch (0 A, 1 B, 2 G, 3 R,
 * 4 Z, 5 spp) and check that the chunk holding it is refused naming them, the others pass. */
static void expect_bad_value(const tf_exr_layout *l, tf_rect r, int bx, int by, int ch,
                             float value, const char *name)
{
    char err[256], want[64];
    tf_pixel *px = image(r.w, r.h);
    float *v[6];
    tf_pixel *p = &px[(by - r.y) * r.w + (bx - r.x)];
    v[0] = &p->a, v[1] = &p->b, v[2] = &p->g, v[3] = &p->r, v[4] = &p->z, v[5] = &p->spp;
    *v[ch] = value;
    tf_exr_encoder *e = tf_exr_encoder_new(l, err, sizeof err);
    assert_non_null(e);
    tf_chunk_payload pay;
    assert_int_equal(tf_exr_encode_rect(e, r, px, &pay, err, sizeof err), 0);
    uint8_t *scratch = NULL;
    size_t cap = 0, off = 0;
    int refused = 0;
    snprintf(want, sizeof want, "channel %s is not finite at pixel (%d, %d)", name, bx, by);
    for (size_t i = 0; i < pay.nchunks; i++) {
        tf_chunk_rec rec;
        tf_chunk_rec_get(pay.index + i * TF_CHUNK_RECORD_BYTES, &rec);
        tf_chunk_ref c = tf_layout_chunk(l, tf_layout_chunk_index(l, rec.cx, rec.cy));
        int holds = by >= c.rect.y && by < c.rect.y + c.rect.h;
        err[0] = '\0';
        assert_int_equal(tf_exr_chunk_check(l, &c, pay.chunks + off, (size_t)rec.packed,
                                            &scratch, &cap, err, sizeof err), holds ? -1 : 0);
        if (holds) {
            assert_string_equal(err, want);
            refused++;
        }
        off += (size_t)rec.packed;
    }
    assert_int_equal(refused, 1);
    free(scratch);
    free(px);
    tf_exr_encoder_free(e);
}

static void test_chunk_check(void **state)
{
    (void)state;
    tf_exr_layout rows = {W, H, 0, 0, 0, TF_PIXEL_HALF};
    tf_exr_layout tiled_half = {W, H, 1, 32, 16, TF_PIXEL_HALF};
    tf_exr_layout tiled_float = {W, H, 1, 32, 16, TF_PIXEL_FLOAT};
    expect_bad_value(&rows, (tf_rect){0, 3, W, 4}, 57, 5, 3, NAN, "R");
    expect_bad_value(&rows, (tf_rect){0, 3, W, 4}, 99, 6, 0, INFINITY, "A");
    expect_bad_value(&rows, (tf_rect){0, 3, W, 4}, 0, 3, 5, -INFINITY, "spp");
    expect_bad_value(&tiled_half, (tf_rect){32, 16, 32, 16}, 40, 30, 2, 1e6f, "G"); /* > half */
    expect_bad_value(&tiled_half, (tf_rect){96, 32, 4, 13}, 99, 44, 4, NAN, "Z");
    expect_bad_value(&tiled_float, (tf_rect){32, 16, 32, 16}, 63, 16, 1, NAN, "B");
    /* lines wider than the scan's blocks of 64 values: the last value of a block, one past
     * it, and a line's (and a chunk's) last float */
    tf_exr_layout rows_float = {W, H, 0, 0, 0, TF_PIXEL_FLOAT};
    expect_bad_value(&rows, (tf_rect){0, 3, W, 4}, 63, 4, 4, NAN, "Z");
    expect_bad_value(&rows, (tf_rect){0, 3, W, 4}, 64, 4, 1, INFINITY, "B");
    expect_bad_value(&rows_float, (tf_rect){0, 3, W, 4}, 63, 5, 2, -INFINITY, "G");
    expect_bad_value(&rows_float, (tf_rect){0, 3, W, 4}, 5, 3, 3, NAN, "R");
    expect_bad_value(&rows_float, (tf_rect){0, 3, W, 4}, W - 1, 6, 5, NAN, "spp");
    /* a line of exactly one block whose chunk fills its scratch buffer (4096 bytes): the scan
     * reads nothing past the chunk's last byte (AddressSanitizer checks in make asan) */
    tf_exr_layout tiled_64 = {W, H, 1, 64, 4, TF_PIXEL_HALF};
    expect_bad_value(&tiled_64, (tf_rect){0, 8, 64, 4}, 63, 11, 5, NAN, "spp");
    /* raw (packed = unpacked) chunks are scanned as they are */
    tf_chunk_ref c = tf_layout_chunk(&rows, 0);
    uint8_t *raw = calloc(1, (size_t)c.unpacked), *scratch = NULL;
    size_t cap = 0;
    char err[256];
    assert_int_equal(tf_exr_chunk_check(&rows, &c, raw, (size_t)c.unpacked, &scratch, &cap, err,
                                        sizeof err), 0);
    raw[2 * W * 3 + 2 * 7 + 1] = 0x7e; /* R (the 4th channel) of pixel 7: a NaN half */
    assert_int_equal(tf_exr_chunk_check(&rows, &c, raw, (size_t)c.unpacked, &scratch, &cap, err,
                                        sizeof err), -1);
    assert_string_equal(err, "channel R is not finite at pixel (7, 0)");
    free(raw);
    free(scratch);
}

static void test_counts_bounded(void **state)
{
    (void)state;
    tf_rect r = {0, 0, 10, 4};
    tf_result_msg m = {0};
    char err[256];
    uint64_t side = (1u << 3) + 1, spp = 40 * side * side;
    m.counts = (tf_render_counts){.primary_rays = spp + 11 * 5, .shadow_rays = spp,
                                  .external_rays = spp, .pixels = 40};
    m.spp_total = (int64_t)spp;
    assert_int_equal(tf_result_counts_check(&m, r, 3, err, sizeof err), 0);
    m.counts.primary_rays++;
    assert_int_equal(tf_result_counts_check(&m, r, 3, err, sizeof err), -1);
    m.counts.primary_rays = 1ull << 62;
    assert_int_equal(tf_result_counts_check(&m, r, 3, err, sizeof err), -1);
    m.counts.primary_rays = 100;
    m.counts.shadow_rays = 101;
    m.counts.external_rays = 0;
    assert_int_equal(tf_result_counts_check(&m, r, 3, err, sizeof err), -1);
    m.counts.shadow_rays = 100;
    m.spp_total = (int64_t)spp + 1;
    assert_int_equal(tf_result_counts_check(&m, r, 3, err, sizeof err), -1);
    m.spp_total = -1;
    assert_int_equal(tf_result_counts_check(&m, r, 3, err, sizeof err), -1);
}

static void test_geometry(void **state)
{
    (void)state;
    tf_exr_layout l = {W, H, 1, 37, 23, TF_PIXEL_HALF};
    assert_int_equal(tf_layout_chunks_x(&l), 3);
    assert_int_equal(tf_layout_chunks_y(&l), 2);
    tf_chunk_ref c = tf_layout_chunk(&l, 5);
    assert_int_equal(c.cx, 2);
    assert_int_equal(c.cy, 1);
    assert_int_equal(c.rect.w, W - 74);
    assert_int_equal(c.rect.h, H - 23);
    assert_int_equal(c.unpacked, (uint64_t)(W - 74) * (H - 23) * 16);
    assert_int_equal(tf_layout_rows_in_chunks(&l, 4), 23);
    assert_int_equal(tf_layout_rows_in_chunks(&l, 6), H);
    /* every preview pixel belongs to exactly one tile, for several image sizes */
    int sizes[][2] = {{W, H}, {2049, 1000}, {5000, 3}, {1, 1}, {1025, 1025}};
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        int w = sizes[k][0], h = sizes[k][1];
        tf_exr_layout t = {w, h, 1, 37, 23, TF_PIXEL_HALF};
        tf_preview_grid g = tf_preview_grid_for(w, h);
        assert_true(g.pw <= TF_PREVIEW_MAX_SIDE && g.ph <= TF_PREVIEW_MAX_SIDE);
        int *owner = calloc((size_t)g.pw * (size_t)g.ph, sizeof *owner);
        for (int64_t i = 0; i < tf_layout_chunk_count(&t); i++) {
            tf_chunk_ref ch = tf_layout_chunk(&t, i);
            int i0, i1, j0, j1;
            tf_preview_span(&g, w, h, ch.rect, &i0, &i1, &j0, &j1);
            for (int j = j0; j < j1; j++)
                for (int x = i0; x < i1; x++) {
                    owner[j * g.pw + x]++;
                    int sx = tf_preview_source(&g, x, w), sy = tf_preview_source(&g, j, h);
                    assert_true(sx >= ch.rect.x && sx < ch.rect.x + ch.rect.w);
                    assert_true(sy >= ch.rect.y && sy < ch.rect.y + ch.rect.h);
                }
        }
        for (int i = 0; i < g.pw * g.ph; i++)
            assert_int_equal(owner[i], 1);
        free(owner);
    }
}

/* The scene, counter, hello and failed tuples round-trip through their packers, match their
 * templates, and are refused by the other kinds' parsers. */
static void test_other_kinds_round_trip(void **state)
{
    (void)state;
    tf_tuple t, tmpl;
    tf_scene_msg sc = {"[image]\n", 64, 48, "abc", "scanline half"}, sc2;
    assert_int_equal(tf_scene_tuple_pack(&t, &sc), 0);
    assert_int_equal(tf_scene_tuple_template(&tmpl), 0);
    assert_true(tf_tuple_match(&tmpl, &t));
    assert_int_equal(tf_scene_tuple_unpack(&t, &sc2), 0);
    assert_string_equal(sc2.text, sc.text);
    assert_int_equal(sc2.width, 64);
    assert_int_equal(sc2.height, 48);
    assert_string_equal(sc2.hash, "abc");
    assert_string_equal(sc2.layout, "scanline half");
    int64_t n;
    assert_int_equal(tf_next_worker_unpack(&t, &n), -1);
    tf_tuple_clear(&t);
    tf_tuple_clear(&tmpl);
    sc.width = 65537; /* larger than any image */
    assert_int_equal(tf_scene_tuple_pack(&t, &sc), 0);
    assert_int_equal(tf_scene_tuple_unpack(&t, &sc2), -1);
    tf_tuple_clear(&t);

    assert_int_equal(tf_next_worker_pack(&t, 5), 0);
    assert_int_equal(tf_next_worker_template(&tmpl), 0);
    assert_true(tf_tuple_match(&tmpl, &t));
    assert_int_equal(tf_next_worker_unpack(&t, &n), 0);
    assert_int_equal(n, 5);
    tf_tuple_clear(&t);
    tf_tuple_clear(&tmpl);

    tf_hello_msg h = {3, "forked", "host", 99, "c"}, h2;
    assert_int_equal(tf_hello_pack(&t, &h), 0);
    assert_int_equal(tf_hello_unpack(&t, &h2), 0);
    assert_int_equal(h2.worker, 3);
    assert_int_equal(h2.pid, 99);
    assert_string_equal(h2.kind, "forked");
    assert_string_equal(h2.host, "host");
    assert_string_equal(h2.backend, "c");
    tf_failed_msg f;
    assert_int_equal(tf_failed_unpack(&t, &f), -1);
    tf_tuple_clear(&t);

    assert_int_equal(tf_failed_pack(&t, 12, 3, "no memory"), 0);
    assert_int_equal(tf_failed_template(&tmpl, 12, -1), 0);
    assert_true(tf_tuple_match(&tmpl, &t));
    tf_tuple_clear(&tmpl);
    assert_int_equal(tf_failed_template(&tmpl, 13, 3), 0);
    assert_false(tf_tuple_match(&tmpl, &t));
    assert_int_equal(tf_failed_unpack(&t, &f), 0);
    assert_int_equal(f.id, 12);
    assert_int_equal(f.worker, 3);
    assert_string_equal(f.message, "no memory");
    tf_tuple_clear(&t);
    tf_tuple_clear(&tmpl);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip_and_check),
        cmocka_unit_test(test_lies_refused),
        cmocka_unit_test(test_chunk_decodes),
        cmocka_unit_test(test_chunk_check),
        cmocka_unit_test(test_counts_bounded),
        cmocka_unit_test(test_geometry),
        cmocka_unit_test(test_other_kinds_round_trip),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
