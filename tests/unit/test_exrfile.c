/* test_exrfile.c: the OpenEXR output and checkpoint (common/image/exrfile.h: exrwrite.c,
 * exrsink.c, exrread.c, exrstream.c, exrresume.c).
 *
 * Covers the bit-exact round trip, header attributes, that exrheader accepts the file, that
 * OpenEXRCore 3.1.5 really rebuilds the zero offset table of a killed render, torn final chunks
 * at every byte offset, resume (equal to an uninterrupted write) and its refusals (file bytes
 * untouched), and write errors (full device, file size limit). */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "scratch_dir.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <openexr.h>

#include "image/exrencode.h"
#include "image/exrfile.h"
#include "image/exrsink.h"

#define W 37
#define H 53 /* an odd height: with chunks of 16 rows, a last partial chunk of 5 */



static tf_exr_meta test_meta(int w, int h)
{
    tf_exr_meta m;
    memset(&m, 0, sizeof m);
    m.width = w;
    m.height = h;
    snprintf(m.scene_hash, sizeof m.scene_hash, "%s",
             "a1b2c3d4e5f60718293a4b5c6d7e8f90a1b2c3d4e5f60718293a4b5c6d7e8f90");
    snprintf(m.scene_name, sizeof m.scene_name, "alps.scene");
    snprintf(m.settings, sizeof m.settings, "aa=adaptive spp=4 seed=7");
    return m;
}

/* Random bit patterns: every float class appears (normals, denormals, zeros, inf, NaN). */
static tf_pixel *random_image(int w, int h, uint64_t seed)
{
    tf_pixel *px = malloc(sizeof *px * (size_t)w * (size_t)h);
    assert_non_null(px);
    uint32_t *u = (uint32_t *)px;
    uint64_t x = seed * 0x9e3779b97f4a7c15ULL + 1;
    for (size_t i = 0; i < (size_t)w * (size_t)h * 6; i++) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        u[i] = (uint32_t)(x >> 16);
        if (i % 5 == 0)
            u[i] &= 0x807fffffu; /* force a denormal (or zero) */
    }
    return px;
}

/* Smooth values: compress well, so chunks are small (the torn-chunk test walks every byte). */
static tf_pixel *smooth_image(int w, int h)
{
    tf_pixel *px = malloc(sizeof *px * (size_t)w * (size_t)h);
    assert_non_null(px);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            tf_pixel *p = &px[(size_t)y * (size_t)w + (size_t)x];
            p->r = (float)x / (float)w;
            p->g = (float)y / (float)h;
            p->b = 0.25f;
            p->a = 1.0f;
            p->z = 100.0f + (float)y;
            p->spp = 4.0f;
        }
    return px;
}

static uint64_t file_checksum(const char *path, long *size)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    uint64_t h = 1469598103934665603ULL;
    long n = 0;
    int ch;
    while ((ch = fgetc(f)) != EOF) {
        h = (h ^ (uint64_t)ch) * 1099511628211ULL;
        n++;
    }
    fclose(f);
    *size = n;
    return h;
}

static void write_file(const char *path, const tf_exr_meta *m, const tf_pixel *px, int rows,
                       int finish)
{
    char err[512] = "";
    tf_exr_writer *w = tf_exr_create(path, m, err, sizeof err);
    assert_non_null(w);
    int chunk = tf_exr_chunk_rows();
    for (int y = 0; y < rows; y += chunk) {
        int n = rows - y < chunk ? rows - y : chunk;
        assert_int_equal(tf_exr_write_rows(w, n, px + (size_t)y * (size_t)m->width, err,
                                           sizeof err), 0);
    }
    assert_int_equal(tf_exr_next_row(w), rows);
    if (finish) {
        assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);
    } else {
        /* Abandon is a kill: not one more byte may reach the file. */
        assert_int_equal(tf_exr_sync(w, err, sizeof err), 0);
        long before_size, after_size;
        uint64_t before = file_checksum(path, &before_size);
        tf_exr_abandon(w);
        assert_true(file_checksum(path, &after_size) == before);
        assert_int_equal(after_size, before_size);
    }
}

typedef struct collected {
    tf_pixel *px;
    int width, max_rows, rows_seen;
    int out_of_order;
} collected;

static int collect_row(void *user, int y, const tf_pixel *row)
{
    collected *c = user;
    if (y != c->rows_seen || y >= c->max_rows)
        c->out_of_order = 1;
    else
        memcpy(c->px + (size_t)y * (size_t)c->width, row, sizeof *row * (size_t)c->width);
    c->rows_seen++;
    return 0;
}

/* Read the whole image back; returns rows_valid. */
static int read_back(const char *path, tf_pixel *out, int w, int h, tf_exr_meta *meta)
{
    char err[512] = "";
    collected c = {out, w, h, 0, 0};
    int rows = -1;
    assert_int_equal(tf_exr_read_rows(path, meta, &rows, collect_row, &c, err, sizeof err), 0);
    assert_int_equal(c.out_of_order, 0);
    assert_int_equal(c.rows_seen, rows);
    return rows;
}

static long file_size(const char *path)
{
    struct stat st;
    assert_int_equal(stat(path, &st), 0);
    return (long)st.st_size;
}

/* Where chunk `index` begins in the file (its y field), asked of OpenEXRCore. */
static long chunk_start(const char *path, int index)
{
    exr_context_t ctx = NULL;
    exr_chunk_info_t cinfo;
    assert_int_equal(exr_start_read(&ctx, path, NULL), EXR_ERR_SUCCESS);
    assert_int_equal(exr_read_scanline_chunk_info(ctx, 0, index * tf_exr_chunk_rows(), &cinfo),
                     EXR_ERR_SUCCESS);
    exr_finish(&ctx);
    return (long)cinfo.data_offset - 8; /* int32 y + int32 packed size precede the data */
}

/* ------------------------------------------------------------------------------------------ */

static void test_round_trip_is_bit_exact(void **state)
{
    (void)state;
    const char *path = scratch_path("round.exr");
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = random_image(W, H, 1);
    char err[512] = "";
    /* Two calls: 32 rows (two whole chunks), then the 21 remaining (a chunk and a partial). */
    tf_exr_writer *w = tf_exr_create(path, &m, err, sizeof err);
    assert_non_null(w);
    assert_int_equal(tf_exr_write_rows(w, 32, px, err, sizeof err), 0);
    assert_int_equal(tf_exr_write_rows(w, H - 32, px + 32 * W, err, sizeof err), 0);
    assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);

    tf_pixel *back = calloc((size_t)W * H, sizeof *back);
    tf_exr_meta got;
    assert_int_equal(read_back(path, back, W, H, &got), H);
    assert_memory_equal(back, px, sizeof *px * W * H);
    free(back);
    free(px);
}

/* ZIP encoding is deterministic: the same pixels written twice (in different row batches)
 * give the same file, byte for byte. */
static void test_same_pixels_give_same_bytes(void **state)
{
    (void)state;
    const char *a = scratch_path("same_a.exr");
    const char *b = scratch_path("same_b.exr");
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = random_image(W, H, 6);
    write_file(a, &m, px, H, 1); /* one chunk per call */
    char err[512] = "";
    tf_exr_writer *w = tf_exr_create(b, &m, err, sizeof err);
    assert_non_null(w);
    assert_int_equal(tf_exr_write_rows(w, H, px, err, sizeof err), 0); /* all in one call */
    assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);
    long sa, sb;
    assert_true(file_checksum(a, &sa) == file_checksum(b, &sb));
    assert_int_equal(sa, sb);
    free(px);
}

static void test_attributes_read_back(void **state)
{
    (void)state;
    const char *path = scratch_path("attrs.exr");
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = smooth_image(W, H);
    write_file(path, &m, px, H, 1);
    free(px);

    tf_exr_meta got;
    int rows = -1, complete = -1;
    char err[512] = "";
    assert_int_equal(tf_exr_probe(path, &got, &rows, &complete, err, sizeof err), 0);
    assert_int_equal(got.width, W);
    assert_int_equal(got.height, H);
    assert_string_equal(got.scene_hash, m.scene_hash);
    assert_string_equal(got.scene_name, m.scene_name);
    assert_string_equal(got.settings, m.settings);
    assert_int_equal(rows, H);
    assert_int_equal(complete, 1);

    /* The layout the brief asks for, straight from OpenEXRCore. */
    exr_context_t ctx = NULL;
    assert_int_equal(exr_start_read(&ctx, path, NULL), EXR_ERR_SUCCESS);
    int32_t len = 0;
    const char *version = NULL;
    assert_int_equal(exr_attr_get_string(ctx, 0, "terrafarm.version", &len, &version), 0);
    assert_string_equal(version, TF_VERSION);
    exr_compression_t comp;
    assert_int_equal(exr_get_compression(ctx, 0, &comp), 0);
    assert_true(comp == EXR_COMPRESSION_ZIPS || comp == EXR_COMPRESSION_ZIP);
    assert_int_equal(comp == EXR_COMPRESSION_ZIPS ? 1 : 16, tf_exr_chunk_rows());
    exr_lineorder_t lo;
    assert_int_equal(exr_get_lineorder(ctx, 0, &lo), 0);
    assert_int_equal(lo, EXR_LINEORDER_INCREASING_Y);
    int32_t spc = 0;
    assert_int_equal(exr_get_scanlines_per_chunk(ctx, 0, &spc), 0);
    assert_int_equal(spc, tf_exr_chunk_rows());
    const exr_attr_chlist_t *chl = NULL;
    assert_int_equal(exr_get_channels(ctx, 0, &chl), 0);
    const char *names[] = {"A", "B", "G", "R", "Z", "spp"};
    assert_int_equal(chl->num_channels, 6);
    for (int i = 0; i < 6; i++) {
        assert_string_equal(chl->entries[i].name.str, names[i]);
        assert_int_equal(chl->entries[i].pixel_type, EXR_PIXEL_FLOAT);
    }
    exr_finish(&ctx);
}

static void test_exrheader_parses_the_file(void **state)
{
    (void)state;
    if (system("command -v exrheader >/dev/null 2>&1") != 0) {
        print_message("exrheader not installed (package openexr): skipping\n");
        skip();
    }
    const char *path = scratch_path("hdr.exr");
    const char *out = scratch_path("hdr.txt");
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = smooth_image(W, H);
    write_file(path, &m, px, H, 1);
    free(px);
    char cmd[1024];
    snprintf(cmd, sizeof cmd, "exrheader '%s' >'%s' 2>&1", path, out);
    assert_int_equal(system(cmd), 0);
    FILE *f = fopen(out, "r");
    assert_non_null(f);
    char text[8192];
    size_t n = fread(text, 1, sizeof text - 1, f);
    text[n] = '\0';
    fclose(f);
    assert_non_null(strstr(text, "terrafarm.scene_hash"));
    assert_non_null(strstr(text, m.scene_hash));
    assert_non_null(strstr(text, "zip"));
    assert_non_null(strstr(text, "spp, 32-bit floating-point"));
}

static void quiet(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    (void)code;
    (void)msg;
}

/* A killed render leaves zeros in the offset table.  Prove that the table really is unusable
 * (reconstruction disabled: no chunk found) and that OpenEXRCore 3.1.5 rebuilds it from the
 * chunk headers when allowed to. */
static void test_core_rebuilds_zero_offset_table(void **state)
{
    (void)state;
    const char *path = scratch_path("killed.exr");
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = smooth_image(W, H);
    write_file(path, &m, px, 32, 0);
    free(px);

    exr_context_initializer_t strict = EXR_DEFAULT_CONTEXT_INITIALIZER;
    strict.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION |
                   EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE;
    strict.error_handler_fn = quiet;
    exr_context_t ctx = NULL;
    exr_chunk_info_t cinfo;
    assert_int_equal(exr_start_read(&ctx, path, &strict), EXR_ERR_SUCCESS);
    assert_int_not_equal(exr_read_scanline_chunk_info(ctx, 0, 0, &cinfo), EXR_ERR_SUCCESS);
    exr_finish(&ctx);

    assert_int_equal(exr_start_read(&ctx, path, NULL), EXR_ERR_SUCCESS);
    for (int y = 0; y < 32; y += tf_exr_chunk_rows()) {
        assert_int_equal(exr_read_scanline_chunk_info(ctx, 0, y, &cinfo), EXR_ERR_SUCCESS);
        assert_int_equal(cinfo.start_y, y);
        assert_true(cinfo.data_offset + cinfo.packed_size <= (uint64_t)file_size(path));
    }
    exr_finish(&ctx);
}

static void test_partial_file_probes_rows_done(void **state)
{
    (void)state;
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = random_image(W, H, 2);
    const int stops[] = {0, 16, 32, 48, H};
    for (size_t i = 0; i < sizeof stops / sizeof stops[0]; i++) {
        const char *path = scratch_path("partial.exr");
        write_file(path, &m, px, stops[i], 0);
        tf_exr_meta got;
        int rows = -1, complete = -1;
        char err[512] = "";
        assert_int_equal(tf_exr_probe(path, &got, &rows, &complete, err, sizeof err), 0);
        assert_int_equal(rows, stops[i]);
        /* OpenEXRCore 3.1.5 writes the offset table together with the last chunk, so a file
         * with every row is finished even if tf_exr_finish never ran. */
        assert_int_equal(complete, stops[i] == H);
        assert_string_equal(got.scene_hash, m.scene_hash);

        tf_pixel *back = calloc((size_t)W * H, sizeof *back);
        assert_int_equal(read_back(path, back, W, H, &got), stops[i]);
        if (stops[i] > 0)
            assert_memory_equal(back, px, sizeof *px * W * (size_t)stops[i]);
        free(back);
    }
    free(px);
}

/* Killed between the last chunk and its offset table (table still zero): every row is there
 * but the file is not complete; resume takes it over and finishing makes it whole. */
static void test_all_rows_without_offset_table_is_not_complete(void **state)
{
    (void)state;
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = random_image(W, H, 5);
    const char *path = scratch_path("notable.exr");
    write_file(path, &m, px, H, 0);
    int c = tf_exr_chunk_rows();
    int nchunks = (H + c - 1) / c;
    long table = chunk_start(path, 0) - 8L * nchunks;
    int fd = open(path, O_WRONLY);
    assert_true(fd >= 0);
    uint8_t *zeros = calloc((size_t)nchunks, 8);
    assert_non_null(zeros);
    assert_int_equal(pwrite(fd, zeros, 8 * (size_t)nchunks, table), (ssize_t)(8 * nchunks));
    free(zeros);
    close(fd);

    tf_exr_meta got;
    int rows = -1, complete = -1;
    char err[512] = "";
    assert_int_equal(tf_exr_probe(path, &got, &rows, &complete, err, sizeof err), 0);
    assert_int_equal(rows, H);
    assert_int_equal(complete, 0);

    tf_exr_writer *w = tf_exr_resume(path, &m, &rows, err, sizeof err);
    assert_non_null(w);
    assert_int_equal(rows, H);
    assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);
    assert_int_equal(tf_exr_probe(path, &got, &rows, &complete, err, sizeof err), 0);
    assert_int_equal(complete, 1);
    tf_pixel *back = calloc((size_t)W * H, sizeof *back);
    assert_int_equal(read_back(path, back, W, H, &got), H);
    assert_memory_equal(back, px, sizeof *px * W * H);
    free(back);
    free(px);
}

/* Cut the file at every byte of chunk `last` (from its header to its end): the chunk must be
 * dropped each time, never crash, and rows_done fall back to the chunk before it. */
static void check_torn_at_every_offset(const char *path, int last, int expect_rows)
{
    long start = chunk_start(path, last);
    long end = file_size(path);
    assert_true(start > 0 && start < end);
    for (long len = end - 1; len >= start; len--) {
        assert_int_equal(truncate(path, len), 0);
        tf_exr_meta got;
        int rows = -1, complete = -1;
        char err[512] = "";
        int rc = tf_exr_probe(path, &got, &rows, &complete, err, sizeof err);
        if (rc != 0 || rows != expect_rows || complete != 0)
            fail_msg("cut at %ld (chunk %ld..%ld): rc %d rows %d complete %d %s", len, start,
                     end, rc, rows, complete, err);
    }
}

static void test_torn_last_chunk_dropped_at_every_offset(void **state)
{
    (void)state;
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = smooth_image(W, H);
    const char *path = scratch_path("torn.exr");
    /* A finished file (valid offset table) whose last chunk is cut... */
    int c = tf_exr_chunk_rows(), last = (H + c - 1) / c - 1;
    write_file(path, &m, px, H, 1);
    check_torn_at_every_offset(path, last, last * c);
    /* ...and a killed one (zero offset table) cut inside its last chunk. */
    int killed = 48 / c; /* chunks written before the kill */
    write_file(path, &m, px, killed * c, 0);
    check_torn_at_every_offset(path, killed - 1, (killed - 1) * c);
    free(px);
}

static void test_resume_equals_uninterrupted_write(void **state)
{
    (void)state;
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = random_image(W, H, 3);
    const char *whole = scratch_path("whole.exr");
    const char *part = scratch_path("resumed.exr");
    write_file(whole, &m, px, H, 1);
    /* Killed while writing the third chunk: cut 10 bytes into it. */
    int c = tf_exr_chunk_rows();
    write_file(part, &m, px, 3 * c, 0);
    assert_int_equal(truncate(part, chunk_start(part, 2) + 10), 0);

    char err[512] = "";
    int rows = -1;
    tf_exr_writer *w = tf_exr_resume(part, &m, &rows, err, sizeof err);
    assert_non_null(w);
    assert_int_equal(rows, 2 * c);
    assert_int_equal(tf_exr_next_row(w), 2 * c);
    char tmp[400];
    snprintf(tmp, sizeof tmp, "%s.resume.tmp", part);
    assert_int_equal(access(tmp, F_OK), -1); /* renamed into place already */
    {   /* At this instant PATH must be a valid partial render with the copied rows. */
        tf_exr_meta got;
        int r2 = -1, complete = -1;
        assert_int_equal(tf_exr_probe(part, &got, &r2, &complete, err, sizeof err), 0);
        assert_int_equal(r2, 2 * c);
    }
    assert_int_equal(tf_exr_write_rows(w, H - 2 * c, px + 2 * c * W, err, sizeof err), 0);
    assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);

    tf_pixel *a = calloc((size_t)W * H, sizeof *a), *b = calloc((size_t)W * H, sizeof *b);
    tf_exr_meta ma, mb;
    assert_int_equal(read_back(whole, a, W, H, &ma), H);
    assert_int_equal(read_back(part, b, W, H, &mb), H);
    assert_memory_equal(a, b, sizeof *a * W * H);
    assert_memory_equal(a, px, sizeof *a * W * H);
    /* Raw chunk copies under the same header: the files are identical byte for byte. */
    long sa, sb;
    assert_true(file_checksum(whole, &sa) == file_checksum(part, &sb));
    assert_int_equal(sa, sb);
    free(a);
    free(b);
    free(px);
}

/* The rewind of --verify: a partial file cut back to its first K chunks through the resume
 * path (chunks after K dropped although they are whole), then rewritten with other pixels and
 * finished, reads back as those pixels, byte for byte the same file as one written straight. */
/* The coordinator's path: chunks packed elsewhere (a worker's encoder), written raw with
 * tf_exr_hold_chunks on, from a buffer that is scribbled over right after each flush.  The
 * file must equal one written by tf_exr_write_rows byte for byte, large chunks must be held
 * (referenced) until the flush and never after it, and a refused chunk must leave nothing
 * held once flushed. */
static void test_held_chunks_reach_the_file_before_their_memory_goes(void **state)
{
    (void)state;
    const char *a = scratch_path("held_a.exr");
    const char *b = scratch_path("held_b.exr");
    tf_exr_meta m = test_meta(W * 8, H); /* random rows of 296 float pixels: chunks of ~7 KB */
    tf_pixel *px = random_image(m.width, H, 9);
    write_file(a, &m, px, H, 1);
    char err[512] = "";
    tf_exr_layout l = tf_exr_meta_layout(&m);
    tf_exr_encoder *enc = tf_exr_encoder_new(&l, err, sizeof err);
    assert_non_null(enc);
    tf_exr_writer *w = tf_exr_create(b, &m, err, sizeof err);
    assert_non_null(w);
    tf_exr_hold_chunks(w, 1);
    uint8_t *copy = NULL;
    int held_any = 0;
    for (int y = 0; y < H; y += tf_exr_chunk_rows()) {
        int rows = H - y < tf_exr_chunk_rows() ? H - y : tf_exr_chunk_rows();
        tf_rect r = {0, y, m.width, rows};
        tf_chunk_payload p;
        assert_int_equal(tf_exr_encode_rect(enc, r, px + (size_t)y * m.width, &p, err, sizeof err), 0);
        copy = realloc(copy, p.chunks_len);
        assert_non_null(copy);
        memcpy(copy, p.chunks, p.chunks_len);
        size_t off = 0;
        for (size_t i = 0; i < p.nchunks; i++) {
            tf_chunk_rec c;
            tf_chunk_rec_get(p.index + i * TF_CHUNK_RECORD_BYTES, &c);
            assert_int_equal(tf_exr_write_chunk(w, c.cx, c.cy, copy + off, (size_t)c.packed, err,
                                                sizeof err), 0);
            off += (size_t)c.packed;
        }
        held_any |= tf_exr_holds_references(w);
        assert_int_equal(tf_exr_flush(w, err, sizeof err), 0);
        assert_false(tf_exr_holds_references(w));
        memset(copy, 0xa5, p.chunks_len); /* what a freed result would hold */
    }
    assert_true(held_any);
    assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);
    long sa, sb;
    assert_true(file_checksum(a, &sa) == file_checksum(b, &sb));
    assert_int_equal(sa, sb);

    /* A chunk out of order is refused; the held one before it still goes out at the flush. */
    w = tf_exr_create(b, &m, err, sizeof err);
    assert_non_null(w);
    tf_exr_hold_chunks(w, 1);
    tf_chunk_payload p;
    tf_rect r0 = {0, 0, m.width, tf_exr_chunk_rows()};
    assert_int_equal(tf_exr_encode_rect(enc, r0, px, &p, err, sizeof err), 0);
    copy = realloc(copy, p.chunks_len);
    memcpy(copy, p.chunks, p.chunks_len);
    tf_chunk_rec c;
    tf_chunk_rec_get(p.index, &c);
    assert_int_equal(tf_exr_write_chunk(w, c.cx, c.cy, copy, (size_t)c.packed, err, sizeof err), 0);
    assert_true(tf_exr_holds_references(w));
    assert_int_equal(tf_exr_write_chunk(w, c.cx, c.cy + 32, copy, (size_t)c.packed, err,
                                        sizeof err), -1);
    assert_int_equal(tf_exr_flush(w, err, sizeof err), 0);
    assert_false(tf_exr_holds_references(w));
    tf_exr_abandon(w);
    free(copy);
    tf_exr_encoder_free(enc);
    free(px);
}

static void test_resume_prefix_takes_back_whole_chunks(void **state)
{
    (void)state;
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *good = random_image(W, H, 5), *lies = random_image(W, H, 6);
    int c = tf_exr_chunk_rows();
    const char *whole = scratch_path("honest.exr");
    const char *part = scratch_path("rewound.exr");
    write_file(whole, &m, good, H, 1);
    /* 2 chunks of good rows, then 3 chunks of lies, all whole */
    tf_pixel *mixed = malloc(sizeof *mixed * W * H);
    memcpy(mixed, good, sizeof *mixed * W * 2 * c);
    memcpy(mixed + 2 * c * W, lies + 2 * c * W, sizeof *mixed * W * 3 * c);
    write_file(part, &m, mixed, 5 * c, 0);

    char err[512] = "";
    int rows = -1;
    tf_exr_writer *w = tf_exr_resume_prefix(part, &m, 2, &rows, err, sizeof err);
    assert_non_null(w);
    assert_int_equal(rows, 2 * c);
    assert_int_equal(tf_exr_next_chunk(w), 2);
    tf_exr_meta got;
    int r2 = -1, complete = -1;
    assert_int_equal(tf_exr_probe(part, &got, &r2, &complete, err, sizeof err), 0);
    assert_int_equal(r2, 2 * c); /* on disk at once, before anything else is written */
    assert_int_equal(tf_exr_write_rows(w, H - 2 * c, good + 2 * c * W, err, sizeof err), 0);
    assert_int_equal(tf_exr_finish(w, err, sizeof err), 0);
    long sa, sb;
    assert_true(file_checksum(whole, &sa) == file_checksum(part, &sb));
    assert_int_equal(sa, sb);
    /* keep 0: back to a header and no rows */
    write_file(part, &m, mixed, 3 * c, 0);
    w = tf_exr_resume_prefix(part, &m, 0, &rows, err, sizeof err);
    assert_non_null(w);
    assert_int_equal(rows, 0);
    tf_exr_abandon(w);
    free(mixed);
    free(good);
    free(lies);
}

static void expect_refusal(const char *path, const tf_exr_meta *want, const char *words)
{
    long size_before, size_after;
    uint64_t before = file_checksum(path, &size_before);
    char err[512] = "";
    int rows = -1;
    assert_null(tf_exr_resume(path, want, &rows, err, sizeof err));
    if (!strstr(err, words) || !strstr(err, path))
        fail_msg("expected \"%s\" naming the file, got: %s", words, err);
    assert_null(strchr(err, '\n'));
    uint64_t after = file_checksum(path, &size_after);
    assert_true(before == after);
    assert_int_equal(size_before, size_after);
    char tmp[400];
    snprintf(tmp, sizeof tmp, "%s.resume.tmp", path);
    assert_int_equal(access(tmp, F_OK), -1);
}

static void test_resume_refuses_changes_and_touches_nothing(void **state)
{
    (void)state;
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = smooth_image(W, H);
    const char *path = scratch_path("refuse.exr");
    write_file(path, &m, px, 32, 0);
    free(px);

    tf_exr_meta changed = m;
    changed.scene_hash[0] = 'f';
    expect_refusal(path, &changed, "scene changed since the partial render (hash a1b2c3d4");
    changed = m;
    changed.width = W + 1;
    expect_refusal(path, &changed, "image size changed since the partial render (37x53 vs 38x53)");
    changed = m;
    snprintf(changed.settings, sizeof changed.settings, "aa=adaptive spp=16 seed=7");
    expect_refusal(path, &changed, "render settings changed");

    char err[512] = "";
    int rows = -1;
    assert_null(tf_exr_resume(scratch_path("absent.exr"), &m, &rows, err, sizeof err));
    assert_non_null(strstr(err, "absent.exr"));
}

static void test_probe_missing_and_foreign_files(void **state)
{
    (void)state;
    tf_exr_meta got;
    int rows, complete;
    char err[512] = "";
    assert_int_equal(tf_exr_probe(scratch_path("nothing.exr"), &got, &rows, &complete, err,
                                  sizeof err), 1);
    const char *junk = scratch_path("junk.exr");
    FILE *f = fopen(junk, "wb");
    assert_non_null(f);
    fputs("this is not an EXR file at all", f);
    fclose(f);
    assert_int_equal(tf_exr_probe(junk, &got, &rows, &complete, err, sizeof err), -1);
    assert_non_null(strstr(err, junk));
    assert_null(strchr(err, '\n'));
    /* A plain EXR without our attributes (the height field export) is not resumable. */
    const char *gray = scratch_path("gray.exr");
    float data[4 * 3] = {0};
    assert_int_equal(tf_exr_write_gray(gray, 4, 3, data, err, sizeof err), 0);
    assert_int_equal(tf_exr_probe(gray, &got, &rows, &complete, err, sizeof err), -1);
    assert_non_null(strstr(err, "not a terrafarm render"));
}

static void test_write_rows_rejects_misaligned_rows(void **state)
{
    (void)state;
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = smooth_image(W, H);
    char err[512] = "";
    tf_exr_writer *w = tf_exr_create(scratch_path("align.exr"), &m, err, sizeof err);
    assert_non_null(w);
    if (tf_exr_chunk_rows() > 1) { /* a part of a chunk is refused */
        assert_int_equal(tf_exr_write_rows(w, tf_exr_chunk_rows() - 1, px, err, sizeof err), -1);
        assert_non_null(strstr(err, "whole chunks"));
    }
    assert_int_equal(tf_exr_write_rows(w, H + 16, px, err, sizeof err), -1);
    assert_int_equal(tf_exr_next_row(w), 0);
    assert_int_equal(tf_exr_finish(w, err, sizeof err), -1); /* rows missing */
    assert_non_null(strstr(err, "only 0 of 53 rows"));
    free(px);
}

static void test_full_device_gives_clear_error(void **state)
{
    (void)state;
    if (access("/dev/full", W_OK) != 0) {
        print_message("/dev/full not writable: skipping\n");
        skip();
    }
    tf_exr_meta m = test_meta(W, H);
    char err[512] = "";
    tf_exr_writer *w = tf_exr_create("/dev/full", &m, err, sizeof err);
    assert_null(w);
    if (!strstr(err, "/dev/full") || !strstr(err, strerror(ENOSPC)))
        fail_msg("unclear error: %s", err);
    assert_null(strchr(err, '\n'));
}

/* A write that fails mid-render (file size limit hit after the header): the chunk write fails
 * with the errno in the message, and later calls keep failing instead of writing on. */
static void test_mid_render_write_error_is_reported(void **state)
{
    (void)state;
    const char *path = scratch_path("limited.exr");
    tf_exr_meta m = test_meta(W, H);
    tf_pixel *px = random_image(W, H, 4);
    struct rlimit old;
    assert_int_equal(getrlimit(RLIMIT_FSIZE, &old), 0);
    void (*old_handler)(int) = signal(SIGXFSZ, SIG_IGN);
    char err[512] = "";
    tf_exr_writer *w = tf_exr_create(path, &m, err, sizeof err);
    assert_non_null(w);
    struct rlimit lim = old;
    lim.rlim_cur = (rlim_t)file_size(path) + 1000; /* header fits, a random chunk does not */
    assert_int_equal(setrlimit(RLIMIT_FSIZE, &lim), 0);
    int rc = tf_exr_write_rows(w, 16, px, err, sizeof err);
    int rc2 = tf_exr_sync(w, err + 256, sizeof err - 256);
    assert_int_equal(setrlimit(RLIMIT_FSIZE, &old), 0);
    signal(SIGXFSZ, old_handler);
    assert_int_equal(rc, -1);
    if (!strstr(err, path) || !strstr(err, strerror(EFBIG)))
        fail_msg("unclear error: %s", err);
    assert_int_equal(rc2, -1);
    /* The limit is gone now, but the writer must not carry on past a lost chunk. */
    assert_int_equal(tf_exr_write_rows(w, 16, px, err, sizeof err), -1);
    assert_non_null(strstr(err, "earlier write failed"));
    assert_int_equal(tf_exr_next_row(w), 0);
    tf_exr_abandon(w);
    free(px);
}

/* Decode a gray file with OpenEXRCore directly (it is not a terrafarm render). */
static void test_write_gray_round_trip(void **state)
{
    (void)state;
    const int gw = 19, gh = 21;
    float data[19 * 21], back[19 * 21];
    for (int i = 0; i < gw * gh; i++)
        data[i] = (float)i * 0.37f - 11.0f;
    data[5] = 1.0e-40f; /* a denormal */
    const char *path = scratch_path("height.exr");
    char err[512] = "";
    assert_int_equal(tf_exr_write_gray(path, gw, gh, data, err, sizeof err), 0);

    exr_context_t ctx = NULL;
    assert_int_equal(exr_start_read(&ctx, path, NULL), EXR_ERR_SUCCESS);
    const exr_attr_chlist_t *chl = NULL;
    assert_int_equal(exr_get_channels(ctx, 0, &chl), 0);
    assert_int_equal(chl->num_channels, 1);
    assert_string_equal(chl->entries[0].name.str, "Y");
    memset(back, 0xff, sizeof back);
    for (int y = 0; y < gh; y += tf_exr_chunk_rows()) {
        exr_chunk_info_t cinfo;
        exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
        assert_int_equal(exr_read_scanline_chunk_info(ctx, 0, y, &cinfo), 0);
        assert_int_equal(exr_decoding_initialize(ctx, 0, &cinfo, &dec), 0);
        dec.channels[0].decode_to_ptr = (uint8_t *)(back + y * gw);
        dec.channels[0].user_pixel_stride = 4;
        dec.channels[0].user_line_stride = 4 * gw;
        dec.channels[0].user_bytes_per_element = 4;
        dec.channels[0].user_data_type = EXR_PIXEL_FLOAT;
        assert_int_equal(exr_decoding_choose_default_routines(ctx, 0, &dec), 0);
        assert_int_equal(exr_decoding_run(ctx, 0, &dec), 0);
        exr_decoding_destroy(ctx, &dec);
    }
    exr_finish(&ctx);
    assert_memory_equal(back, data, sizeof data);
}

#ifndef NDEBUG
/* tf_exr_sink_check on s in a child: 1 if it aborted with `clause` on stderr, 0 if it
 * returned. */
static int sink_check_aborts_naming(const tf_exr_sink *s, const char *clause)
{
    int fds[2];
    assert_int_equal(pipe(fds), 0);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        dup2(fds[1], 2);
        tf_exr_sink_check(s);
        _exit(0);
    }
    close(fds[1]);
    char text[1024] = "";
    size_t n = 0;
    ssize_t k;
    while (n + 1 < sizeof text && (k = read(fds[0], text + n, sizeof text - 1 - n)) > 0)
        n += (size_t)k;
    text[n] = '\0';
    close(fds[0]);
    int status;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    if (!WIFSIGNALED(status))
        return 0;
    assert_int_equal(WTERMSIG(status), SIGABRT);
    if (!strstr(text, clause))
        fail_msg("the assertion does not name '%s': %s", clause, text);
    return 1;
}
#endif

/* The sink's invariants (exrsink.h E1-E6, D1-D3) are asserted clause by clause, each failure
 * naming its clause: a run on a closed descriptor fails E1, a run_len that is not its pieces'
 * sum E4, a reference without hold E6, staged bytes without a direct descriptor D1, a stage off
 * its block D2, a whole block left staged D3; a consistent sink passes.  Asserts are on in
 * `make asan`. */
static void test_sink_invariants_name_their_clause(void **state)
{
    (void)state;
#ifdef NDEBUG
    skip(); /* release builds define NDEBUG: nothing to check */
#else
    static tf_exr_sink s; /* large (its iovec array): static, not on the stack */
    tf_exr_sink_init(&s);
    s.fd = 2;
    s.niov = 1;
    s.iov[0].iov_len = 10;
    s.run_len = 10;
    assert_int_equal(sink_check_aborts_naming(&s, ""), 0);
    s.fd = -1;
    assert_true(sink_check_aborts_naming(&s, "E1: a run waits only on an open descriptor"));
    s.fd = 2;
    s.run_len = 11;
    assert_true(sink_check_aborts_naming(&s, "E4: run_len is the sum of the pieces' lengths"));
    s.run_len = 10;
    s.held = 1;
    assert_true(sink_check_aborts_naming(&s, "E6: references only with hold"));
    s.held = 0;
    static uint8_t stage[SINK_ALIGN];
    s.dfd = -1;
    s.stage = stage;
    s.stage_len = 100;
    assert_true(sink_check_aborts_naming(&s, "D1: staging only with a direct descriptor"));
    s.dfd = 3;
    assert_true(sink_check_aborts_naming(&s, "D2: a direct descriptor has its block size"));
    s.align = SINK_ALIGN;
    assert_int_equal(sink_check_aborts_naming(&s, ""), 0);
    s.stage_off = 100;
    assert_true(sink_check_aborts_naming(&s, "D2: the stage starts on a block"));
    s.stage_off = SINK_ALIGN;
    s.stage_len = SINK_ALIGN;
    assert_true(sink_check_aborts_naming(&s, "D3: less than a block staged between calls"));
#endif
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip_is_bit_exact),
        cmocka_unit_test(test_same_pixels_give_same_bytes),
        cmocka_unit_test(test_attributes_read_back),
        cmocka_unit_test(test_exrheader_parses_the_file),
        cmocka_unit_test(test_core_rebuilds_zero_offset_table),
        cmocka_unit_test(test_partial_file_probes_rows_done),
        cmocka_unit_test(test_all_rows_without_offset_table_is_not_complete),
        cmocka_unit_test(test_torn_last_chunk_dropped_at_every_offset),
        cmocka_unit_test(test_resume_equals_uninterrupted_write),
        cmocka_unit_test(test_resume_prefix_takes_back_whole_chunks),
        cmocka_unit_test(test_held_chunks_reach_the_file_before_their_memory_goes),
        cmocka_unit_test(test_resume_refuses_changes_and_touches_nothing),
        cmocka_unit_test(test_probe_missing_and_foreign_files),
        cmocka_unit_test(test_write_rows_rejects_misaligned_rows),
        cmocka_unit_test(test_full_device_gives_clear_error),
        cmocka_unit_test(test_mid_render_write_error_is_reported),
        cmocka_unit_test(test_write_gray_round_trip),
        cmocka_unit_test(test_sink_invariants_name_their_clause),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
