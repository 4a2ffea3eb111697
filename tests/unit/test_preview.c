/* test_preview.c: the sRGB PNG preview (common/image/preview.c): the tone curve's fixed points
 * and monotonicity, its table against the curve at every float, and a PNG streamed from an EXR
 * read back with libpng (size, format, pixels, black rows for a partial render, clear error for
 * a missing EXR). */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "scratch_dir.h"

#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "image/exrfile.h"
#include "image/preview.h"

#define W 37
#define H 53



static tf_pixel test_pixel(int x, int y)
{
    tf_pixel p = {(float)x / (W - 1), (float)y / (H - 1), 0.18f, 1.0f, 10.0f, 4.0f};
    if (x == 3 && y == 4)
        p.r = 7.5f; /* over-exposed: clamps */
    if (x == 5 && y == 6)
        p.g = -0.5f; /* negative: black */
    return p;
}

/* Write a W x H EXR with rows [0, rows) rendered. */
static void write_exr(const char *path, int rows)
{
    tf_exr_meta m;
    memset(&m, 0, sizeof m);
    m.width = W;
    m.height = H;
    snprintf(m.scene_hash, sizeof m.scene_hash, "%064d", 7);
    snprintf(m.scene_name, sizeof m.scene_name, "test.scene");
    tf_pixel *px = malloc(sizeof *px * W * H);
    assert_non_null(px);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            px[y * W + x] = test_pixel(x, y);
    char err[512] = "";
    tf_exr_writer *w = tf_exr_create(path, &m, err, sizeof err);
    assert_non_null(w);
    if (rows > 0)
        assert_int_equal(tf_exr_write_rows(w, rows, px, err, sizeof err), 0);
    if (rows == H)
        assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);
    else
        tf_exr_abandon(w);
    free(px);
}

/* Read an 8-bit RGB PNG with libpng into a malloc'd buffer; checks the format on the way. */
static uint8_t *read_png(const char *path, int *width, int *height)
{
    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    assert_true(png_image_begin_read_from_file(&img, path));
    assert_int_equal(img.format & PNG_FORMAT_FLAG_COLOR, PNG_FORMAT_FLAG_COLOR);
    assert_int_equal(img.format & (PNG_FORMAT_FLAG_ALPHA | PNG_FORMAT_FLAG_LINEAR), 0);
    *width = (int)img.width;
    *height = (int)img.height;
    img.format = PNG_FORMAT_RGB;
    uint8_t *buf = malloc(PNG_IMAGE_SIZE(img));
    assert_non_null(buf);
    assert_true(png_image_finish_read(&img, NULL, buf, 0, NULL));
    return buf;
}

static void test_srgb8_fixed_points(void **state)
{
    (void)state;
    assert_int_equal(tf_srgb8(0.0f), 0);
    assert_int_equal(tf_srgb8(-1.0f), 0);
    assert_int_equal(tf_srgb8(NAN), 0);
    assert_int_equal(tf_srgb8(1.0f), 255);
    assert_int_equal(tf_srgb8(2.0f), 255);
    assert_int_equal(tf_srgb8(INFINITY), 255);
    assert_int_equal(tf_srgb8(0.5f), 188);       /* 0.7354 * 255 = 187.5 */
    assert_int_equal(tf_srgb8(0.18f), 118);      /* middle grey: 0.4614 * 255 = 117.7 */
    assert_int_equal(tf_srgb8(0.0031308f), 10);  /* end of the linear toe: 0.04045 * 255 */
    assert_int_equal(tf_srgb8(0.001f), 3);       /* on the toe: 12.92 * 0.001 * 255 = 3.3 */
}

/* The table (tf_srgb8) gives the transfer curve's byte (tf_srgb8_exact) for every float from
 * 2^-14 to 1, and the curve's byte never decreases from one float to the next there, which is
 * what the table's construction assumes; below 2^-14 (byte 0: 12.92 * 2^-14 * 255 < 0.5) one
 * float in 4096.  ~1.2e8 floats; off by one at any byte's first float, or at any float the
 * table mishandles, it fails.  (The curve was also found non-decreasing at every float in
 * (0, 1): bench/README.md section 42.) */
static void test_srgb8_table_is_the_curve_at_every_float(void **state)
{
    (void)state;
    const uint32_t one = 0x3f800000u, low = 0x38800000u; /* 1.0f, 2^-14 */
    for (uint32_t bits = 1; bits < low; bits += 4096) {
        float f;
        memcpy(&f, &bits, sizeof f);
        assert_int_equal(tf_srgb8_exact(f), 0);
        assert_int_equal(tf_srgb8(f), 0);
    }
    int prev = 0;
    uint32_t changes = 0;
    for (uint32_t bits = low; bits < one; bits++) {
        float f;
        memcpy(&f, &bits, sizeof f);
        const int exact = tf_srgb8_exact(f), table = tf_srgb8(f);
        if (exact != table)
            fail_msg("tf_srgb8(%a) = %d, the curve gives %d", (double)f, table, exact);
        if (exact < prev)
            fail_msg("the curve decreases at %a: %d after %d", (double)f, exact, prev);
        changes += exact != prev;
        prev = exact;
    }
    assert_int_equal(changes, 255); /* every byte, each from one float on */
}

static void test_srgb8_is_monotonic_and_reaches_every_code(void **state)
{
    (void)state;
    int prev = 0, seen[256] = {0};
    for (int i = 0; i <= 100000; i++) {
        int v = tf_srgb8((float)i / 100000.0f);
        assert_true(v >= prev);
        prev = v;
        seen[v] = 1;
    }
    for (int v = 0; v < 256; v++)
        if (!seen[v])
            fail_msg("code %d never produced", v);
}

static void test_preview_png_has_size_and_pixels(void **state)
{
    (void)state;
    const char *exr = scratch_path("img.exr");
    const char *png = scratch_path("img.png");
    write_exr(exr, H);
    char err[512] = "";
    assert_int_equal(tf_preview_from_exr(exr, png, err, sizeof err), 0);
    int w = 0, h = 0;
    uint8_t *rgb = read_png(png, &w, &h);
    assert_int_equal(w, W);
    assert_int_equal(h, H);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            tf_pixel p = test_pixel(x, y);
            const uint8_t *q = rgb + 3 * (y * W + x);
            if (q[0] != tf_srgb8(p.r) || q[1] != tf_srgb8(p.g) || q[2] != tf_srgb8(p.b))
                fail_msg("pixel %d,%d is %d,%d,%d", x, y, q[0], q[1], q[2]);
        }
    assert_int_equal(rgb[3 * (4 * W + 3)], 255); /* the over-exposed pixel */
    assert_int_equal(rgb[3 * (6 * W + 5) + 1], 0);
    free(rgb);
}

static void test_preview_of_partial_render_is_full_size_with_black_rest(void **state)
{
    (void)state;
    const char *exr = scratch_path("part.exr");
    const char *png = scratch_path("part.png");
    write_exr(exr, 32);
    char err[512] = "";
    assert_int_equal(tf_preview_from_exr(exr, png, err, sizeof err), 0);
    int w = 0, h = 0;
    uint8_t *rgb = read_png(png, &w, &h);
    assert_int_equal(w, W);
    assert_int_equal(h, H);
    assert_int_equal(rgb[3 * (31 * W + 0) + 2], tf_srgb8(0.18f)); /* last rendered row */
    for (int i = 3 * 32 * W; i < 3 * W * H; i++)
        assert_int_equal(rgb[i], 0);
    free(rgb);
}

static void test_preview_of_missing_exr_fails_clearly(void **state)
{
    (void)state;
    const char *png = scratch_path("none.png");
    char err[512] = "";
    assert_int_equal(tf_preview_from_exr(scratch_path("none.exr"), png, err, sizeof err), -1);
    assert_non_null(strstr(err, "none.exr"));
    assert_null(strchr(err, '\n'));
    assert_int_equal(access(png, F_OK), -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_srgb8_fixed_points),
        cmocka_unit_test(test_srgb8_is_monotonic_and_reaches_every_code),
        cmocka_unit_test(test_srgb8_table_is_the_curve_at_every_float),
        cmocka_unit_test(test_preview_png_has_size_and_pixels),
        cmocka_unit_test(test_preview_of_partial_render_is_full_size_with_black_rest),
        cmocka_unit_test(test_preview_of_missing_exr_fails_clearly),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
