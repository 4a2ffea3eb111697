/* test_directfile.c: files written front to back around the page cache (common/directfile.h).
 * Seeded pieces of 1 byte to 600 KB go through a tf_directfile; after every call W1-W3 hold,
 * and at the end the file is exactly the bytes handed over (no padding of the last block, no
 * piece lost at a buffer's edge).  Then the same when the direct path is left in the middle
 * (what a write refused with EINVAL does), a file shorter than a block, a full disk reported
 * with its errno, and a file that cannot be created. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "scratch_dir.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "directfile.h"

#define SOURCE_MAX (3 * 1024 * 1024 + 5777) /* 12 buffers, a block and a tail */

static uint8_t *source;

static uint64_t rng = 0x9e3779b97f4a7c15ULL;
static uint64_t next_random(void)
{
    rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
    return rng;
}

static int fill_source(void **state)
{
    source = malloc(SOURCE_MAX);
    if (!source)
        return -1;
    for (size_t i = 0; i < SOURCE_MAX; i++)
        source[i] = (uint8_t)(next_random() >> 32);
    return scratch_dir_make(state);
}

static int free_source(void **state)
{
    free(source);
    return scratch_dir_remove(state);
}

/* The file at path must be exactly source[0, len). */
static void assert_file_is_source(const char *path, size_t len)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    uint8_t *got = malloc(len + 1);
    assert_non_null(got);
    size_t n = fread(got, 1, len + 1, f);
    fclose(f);
    assert_int_equal(n, len);
    assert_memory_equal(got, source, len);
    free(got);
}

/* Write source[0, len) in seeded pieces; leave the direct path after `switch_at` bytes
 * (SIZE_MAX: never). */
static void write_pieces(tf_directfile *f, size_t len, size_t switch_at)
{
    size_t at = 0;
    while (at < len) {
        uint64_t r = next_random();
        size_t n = (r & 3) == 0 ? 1 + (size_t)(r >> 40) % 600000 : 1 + (size_t)(r >> 40) % 5000;
        n = n < len - at ? n : len - at;
        assert_int_equal(tf_directfile_write(f, source + at, n), 0);
        at += n;
        tf_directfile_check(f);
        if (at >= switch_at && f->direct) {
            tf_directfile_buffered(f);
            tf_directfile_check(f);
        }
    }
}

static void test_every_byte_reaches_the_file(void **state)
{
    (void)state;
    const char *path = scratch_path("direct.bin");
    tf_directfile f;
    assert_int_equal(tf_directfile_create(&f, path), 0);
    if (!f.direct)
        print_message("note: %s has no O_DIRECT: the buffered path was tested\n", scratch_dir);
    write_pieces(&f, SOURCE_MAX, SIZE_MAX);
    assert_true(f.len > 0); /* SOURCE_MAX is not a whole number of blocks: a tail is left */
    assert_int_equal(tf_directfile_close(&f), 0);
    assert_file_is_source(path, SOURCE_MAX);
}

static void test_leaving_the_direct_path_midway_loses_nothing(void **state)
{
    (void)state;
    const char *path = scratch_path("switch.bin");
    tf_directfile f;
    assert_int_equal(tf_directfile_create(&f, path), 0);
    write_pieces(&f, SOURCE_MAX, SOURCE_MAX / 3);
    assert_int_equal(f.direct, 0);
    assert_int_equal(tf_directfile_close(&f), 0);
    assert_file_is_source(path, SOURCE_MAX);
}

static void test_a_file_shorter_than_a_block(void **state)
{
    (void)state;
    const char *path = scratch_path("short.bin");
    tf_directfile f;
    assert_int_equal(tf_directfile_create(&f, path), 0);
    assert_int_equal(tf_directfile_write(&f, source, 10), 0);
    assert_int_equal(tf_directfile_write(&f, source + 10, 0), 0);
    assert_int_equal(tf_directfile_close(&f), 0);
    assert_file_is_source(path, 10);
    /* created again over it: truncated */
    assert_int_equal(tf_directfile_create(&f, path), 0);
    assert_int_equal(tf_directfile_write(&f, source, 3), 0);
    assert_int_equal(tf_directfile_close(&f), 0);
    assert_file_is_source(path, 3);
}

static void test_a_full_disk_is_reported(void **state)
{
    (void)state;
    tf_directfile f;
    /* /dev/full refuses O_DIRECT (EINVAL at open: the buffered path), then every write with
     * ENOSPC. */
    assert_int_equal(tf_directfile_create(&f, "/dev/full"), 0);
    assert_int_equal(tf_directfile_write(&f, source, 100), 0); /* buffered, not yet written */
    errno = 0;
    assert_int_equal(tf_directfile_write(&f, source, TF_DIRECTFILE_BUF), -1);
    assert_int_equal(errno, ENOSPC);
    tf_directfile_check(&f);
    assert_int_equal(f.len, 0);
    assert_int_equal(tf_directfile_write(&f, source, 1), -1); /* and stays failed */
    errno = 0;
    assert_int_equal(tf_directfile_close(&f), -1);
    assert_int_equal(errno, ENOSPC);
}

static void test_a_file_that_cannot_be_created(void **state)
{
    (void)state;
    tf_directfile f;
    errno = 0;
    assert_int_equal(tf_directfile_create(&f, scratch_path("no/such/dir.bin")), -1);
    assert_int_equal(errno, ENOENT);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_byte_reaches_the_file),
        cmocka_unit_test(test_leaving_the_direct_path_midway_loses_nothing),
        cmocka_unit_test(test_a_file_shorter_than_a_block),
        cmocka_unit_test(test_a_full_disk_is_reported),
        cmocka_unit_test(test_a_file_that_cannot_be_created),
    };
    return cmocka_run_group_tests(tests, fill_source, free_source);
}
