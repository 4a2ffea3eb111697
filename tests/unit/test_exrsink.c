/* test_exrsink.c: the output stream under OpenEXRCore (common/image/exrsink.h), on its direct
 * path.  A seeded sequence of writes shaped like a render's (a header, small chunk headers,
 * large chunk bytes referenced with hold, a jump back to write the offset table, flushes) goes
 * through a sink opened O_DIRECT; after every flush the file must hold exactly what a model
 * says was handed over, and at the end every byte.  Then the same with blocks the kernel
 * refuses (256 bytes, under a disk's 512-byte sector: EINVAL), which must fall back to
 * buffered writes mid-run and lose nothing. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "scratch_dir.h"

#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "image/exrsink.h"

#define FILE_MAX (6 * 1024 * 1024)

/* What should be in the file: model[0, model_len) (holes read as zeros). */
static uint8_t *model, *source;
static size_t model_len;

static uint64_t rng = 0x243f6a8885a308d3ULL;
static uint64_t next_random(void)
{
    rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
    return rng;
}

static void fill_source(void)
{
    source = malloc(FILE_MAX);
    model = calloc(1, FILE_MAX);
    assert_non_null(source);
    assert_non_null(model);
    for (size_t i = 0; i < FILE_MAX; i++)
        source[i] = (uint8_t)(next_random() >> 32);
}

static tf_exr_sink *open_sink(const char *path, int direct)
{
    static tf_exr_sink s; /* large (its iovec array): static, not on the stack */
    tf_exr_sink_init(&s);
    s.fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    assert_true(s.fd >= 0);
    if (direct)
        tf_exr_sink_go_direct(&s, path);
    return &s;
}

/* Hand [off, off+len) of the source to the sink at off, as the writer does (large pieces by
 * reference with hold on), and into the model. */
static void put(tf_exr_sink *s, size_t off, size_t len)
{
    assert_true(off + len <= FILE_MAX);
    s->referring = s->hold;
    assert_int_equal(tf_exr_sink_write(NULL, s, source + off, len, off, NULL), (int64_t)len);
    s->referring = 0;
    memcpy(model + off, source + off, len);
    if (off + len > model_len)
        model_len = off + len;
}

/* The file has between model_len - short_by_under and model_len bytes, each the model's. */
static void file_is_model_prefix(const char *path, size_t short_by_under, const char *when)
{
    struct stat st;
    assert_int_equal(stat(path, &st), 0);
    size_t have = (size_t)st.st_size;
    if (have > model_len || model_len - have >= short_by_under)
        fail_msg("%s: file has %zu bytes, the model %zu", when, have, model_len);
    uint8_t *got = malloc(have + 1);
    int fd = open(path, O_RDONLY);
    assert_true(fd >= 0);
    assert_int_equal(pread(fd, got, have, 0), (ssize_t)have);
    close(fd);
    for (size_t i = 0; i < have; i++)
        if (got[i] != model[i])
            fail_msg("%s: byte %zu of %zu is %u, not %u", when, i, have, got[i], model[i]);
    free(got);
}

/* The file holds exactly model[0, model_len). */
static void file_matches_model(const char *path, const char *when)
{
    file_is_model_prefix(path, 1, when);
}

/* After tf_exr_sink_emit: the file is the model but for at most its last part block (under
 * s->align bytes), still staged. */
static void file_matches_model_but_tail(const tf_exr_sink *s, const char *path, const char *when)
{
    file_is_model_prefix(path, s->dfd >= 0 ? s->align : 1, when);
}

/* A render's shape of writes: header, a gap for the table, chunks of a small header and large
 * bytes, a flush or an emit every few chunks (after an emit the caller's bytes are scribbled
 * over, as a freed result's would be), then the table written back in the gap. */
static void render_like_writes(tf_exr_sink *s, const char *path)
{
    memset(model, 0, FILE_MAX);
    model_len = 0;
    size_t header = 300 + next_random() % 700, table = 8 * (50 + next_random() % 400);
    put(s, 0, header);
    assert_int_equal(tf_exr_sink_flush(s), 0); /* tf_exr_create writes the header at once */
    file_matches_model(path, "after the header");
    size_t end = header + table;
    for (int chunk = 0; end < FILE_MAX - 400 * 1024; chunk++) {
        size_t bytes = next_random() % 4 ? 1 + next_random() % (300 * 1024)
                                         : 1 + next_random() % 3000;
        put(s, end, 8);
        put(s, end + 8, bytes);
        end += 8 + bytes;
        char when[64];
        if (next_random() % 5 == 0) {
            assert_int_equal(tf_exr_sink_flush(s), 0);
            snprintf(when, sizeof when, "after the flush at chunk %d", chunk);
            file_matches_model(path, when);
        } else if (next_random() % 4 == 0) {
            assert_int_equal(tf_exr_sink_emit(s), 0);
            assert_int_equal(s->held, 0);
            for (size_t i = 0; i < end; i++) /* the caller's chunks are free to go: */
                source[i] = (uint8_t)(source[i] * 5 + 1); /* new bytes, still all different */
            snprintf(when, sizeof when, "after the emit at chunk %d", chunk);
            file_matches_model_but_tail(s, path, when);
        }
    }
    put(s, header, table); /* the offset table, at finish */
    assert_int_equal(tf_exr_sink_flush(s), 0);
    file_matches_model(path, "after the table");
}

/* The direct path writes what was handed over, byte for byte, after every flush. */
static void test_direct_sink_writes_every_byte(void **state)
{
    (void)state;
    const char *path = scratch_path("direct.bin");
    tf_exr_sink *s = open_sink(path, 1);
    if (s->dfd < 0)
        print_message("no O_DIRECT under %s: the buffered path is what is tested\n", path);
    for (int hold = 0; hold <= 1; hold++) {
        assert_int_equal(ftruncate(s->fd, 0), 0);
        s->hold = hold;
        render_like_writes(s, path);
    }
    int stayed_direct = s->dfd >= 0;
    assert_int_equal(tf_exr_sink_close(s), 0);
    if (stayed_direct)
        print_message("direct path used throughout\n");
}

/* A direct write the kernel refuses with EINVAL (here: blocks of 256 bytes, offsets no disk
 * sector divides) leaves the direct path for buffered writes in the middle of a run, and
 * loses nothing. */
static void test_refused_direct_write_falls_back(void **state)
{
    (void)state;
    const char *path = scratch_path("fallback.bin");
    tf_exr_sink *s = open_sink(path, 1);
    if (s->dfd < 0) {
        print_message("no O_DIRECT under %s: skipping\n", path);
        tf_exr_sink_close(s);
        skip();
    }
    s->align = 256;
    s->hold = 1;
    render_like_writes(s, path);
    int left = s->dfd < 0;
    assert_int_equal(tf_exr_sink_close(s), 0);
    if (!left) /* a file system that takes any alignment (tmpfs): nothing was refused */
        print_message("256-byte direct writes were accepted here; fallback not exercised\n");
    else
        print_message("the direct path was left after EINVAL, as it should\n");
}

int main(void)
{
    fill_source();
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_direct_sink_writes_every_byte),
        cmocka_unit_test(test_refused_direct_write_falls_back),
    };
    int rc = cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
    free(source);
    free(model);
    return rc;
}
