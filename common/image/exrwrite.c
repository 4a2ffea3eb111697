/* exrwrite.c: writing the render's OpenEXR output (exrfile.h): create it with its header,
 * append whole chunks in file order -- encoded here (tf_exr_write_rows, the single-channel
 * export) or packed by workers and written raw (tf_exr_write_chunk) -- flush, sync, finish
 * (the offset table), or abandon.  Every byte goes through the sink (exrsink.h).
 *
 * On-disk invariant of a file being written: header, then the offset table (all zero until
 * tf_exr_finish), then whole chunks in file order, each "int32 y, int32 packed size, packed
 * bytes" (tiles: "int32 tx, ty, level x, level y, packed size, packed bytes").  OpenEXRCore
 * 3.1.5 sees the zero offset table as invalid and rebuilds it by walking
 * those chunk headers (tests/unit/test_exrfile.c checks that it does), so a killed render is
 * readable up to its last whole chunk.
 *
 * Invariants of a writer, after every call that changes it (assert_writer_state asserts them
 * clause by clause in the `make asan` build), beside its sink's E1-E6 (exrsink.h):
 *   E7  chunks go out in file order, each once: 0 <= next_chunk <= nchunks;
 *   E8  OpenEXRCore writes only to our open descriptor: a live context implies sink.fd >= 0
 *       (the descriptor is opened before the context and closed after it ends). */
#include "image/exrinternal.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "image/exrpart.h"
#include "image/exrsink.h"
#include "image/exrzip.h"
#include "log.h"

/* Scanlines per chunk of a scanline file: ZIPS, one scanline per chunk, so that any rows:K task
 * is whole chunks a worker can encode alone, and a killed render loses no finished row to an
 * incomplete chunk. */
#define TF_EXR_CHUNK_ROWS 1

#ifndef TF_VERSION
#define TF_VERSION "unknown"
#endif

/* Channel layout.  EXR stores channels sorted by name (A B G R Z spp); we always address them
 * by name (exrpart.h), so the order in tf_pixel never matters. */
static const tf_exr_channel GRAY_CHANNELS[] = {{"Y", 0, EXR_PIXEL_FLOAT}};

tf_exr_layout tf_exr_meta_layout(const tf_exr_meta *m)
{
    tf_exr_layout l = {m->width, m->height, m->tiled, m->tile_w, m->tile_h, m->pixel};
    return l;
}

struct tf_exr_writer {
    exr_context_t ctx;
    tf_exr_sink sink;
    char *path;
    tf_exr_layout layout;
    int width, height;
    int64_t next_chunk;          /* file-order index of the next chunk to write */
    int64_t nchunks;
    const tf_exr_channel *channels;
    int nchannels;
    size_t pixel_bytes;          /* stride of one caller pixel */
    int broken;                  /* a chunk write failed: every later write/sync/finish fails */
    tf_exr_zip *zip;             /* packs the chunks this writer encodes itself (exrzip.h) */
};

/* E7 and the sink's E1-E6, one assert per clause; nothing with NDEBUG. */
static void assert_writer_state(const tf_exr_writer *w)
{
    assert(w->next_chunk >= 0 && "E7: next_chunk >= 0");
    assert(w->next_chunk <= w->nchunks && "E7: next_chunk <= nchunks");
    assert((!w->ctx || w->sink.fd >= 0) && "E8: a live context writes to an open descriptor");
    tf_exr_sink_check(&w->sink);
    (void)w;
}

int tf_exr_chunk_rows(void) { return TF_EXR_CHUNK_ROWS; }

int tf_exr_next_row(const tf_exr_writer *w)
{
    return w->next_chunk >= w->nchunks ? w->height
                                       : tf_layout_rows_in_chunks(&w->layout, w->next_chunk);
}

int64_t tf_exr_next_chunk(const tf_exr_writer *w) { return w->next_chunk; }

/* One line for a failed OpenEXRCore write step: the errno of the sink wins if it has one,
 * because "No space left on device" is what the user needs to read. */
static void writer_error(tf_exr_writer *w, char *err, size_t errlen, const char *what,
                         exr_result_t rv)
{
    if (w->sink.write_errno) {
        tf_seterr(err, errlen, "%s: %s: %s", w->path, what, strerror(w->sink.write_errno));
        return;
    }
    tf_exr_set_error(err, errlen, w->path, what, rv);
}

/* Release everything; `abandon` stops OpenEXRCore from touching the file on its way out. */
static void writer_free(tf_exr_writer *w, int abandon)
{
    if (!w)
        return;
    if (abandon) {
        /* what was handed to the sink counts as written (as after a write() that returned);
         * nothing after this instant reaches the file */
        if (w->sink.fd >= 0)
            tf_exr_sink_flush(&w->sink);
        w->sink.abandoned = 1;
        assert_writer_state(w);
    }
    if (w->ctx)
        exr_finish(&w->ctx);
    tf_exr_sink_close(&w->sink);
    tf_exr_zip_free(w->zip);
    free(w->path);
    free(w);
}

/* Open `path` (truncating) and start an OpenEXRCore write context on it with one scanline
 * part of the given channels.  The header is not written yet. */
static tf_exr_writer *writer_open(const char *path, const tf_exr_layout *layout,
                                  const tf_exr_channel *channels, int nchannels,
                                  size_t pixel_bytes, char *err, size_t errlen)
{
    int width = layout->width, height = layout->height;
    if (!tf_exr_valid_size(width, height) || tf_exr_layout_check(layout, NULL, 0)) {
        tf_seterr(err, errlen, "%s: bad image size %dx%d", path, width, height);
        return NULL;
    }
    tf_exr_writer *w = calloc(1, sizeof *w);
    if (!w || !(w->path = strdup(path))) {
        free(w);
        tf_seterr(err, errlen, "%s: out of memory", path);
        return NULL;
    }
    tf_exr_sink_init(&w->sink);
    w->layout = *layout;
    w->width = width;
    w->height = height;
    w->nchunks = tf_layout_chunk_count(layout);
    w->channels = channels;
    w->nchannels = nchannels;
    w->pixel_bytes = pixel_bytes;
    w->sink.fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (w->sink.fd < 0) {
        tf_seterr(err, errlen, "%s: cannot create: %s", path, strerror(errno));
        writer_free(w, 1);
        return NULL;
    }
    tf_exr_sink_go_direct(&w->sink, path);
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = tf_exr_remember_error;
    init.user_data = &w->sink;
    init.write_fn = tf_exr_sink_write;
    tf_exr_clear_error();
    exr_result_t rv = exr_start_write(&w->ctx, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = tf_exr_define_part(w->ctx, layout, channels, nchannels);
    if (rv != EXR_ERR_SUCCESS) {
        writer_error(w, err, errlen, "cannot set up the EXR header", rv);
        writer_free(w, 1);
        return NULL;
    }
    return w;
}

static int set_string_attrs(tf_exr_writer *w, const tf_exr_meta *meta, char *err, size_t errlen)
{
    const char *names[] = {TF_EXR_ATTR_HASH, TF_EXR_ATTR_SCENE, TF_EXR_ATTR_SETTINGS,
                           TF_EXR_ATTR_VERSION};
    const char *values[] = {meta->scene_hash, meta->scene_name, meta->settings, TF_VERSION};
    for (int i = 0; i < 4; i++) {
        exr_result_t rv = exr_attr_set_string(w->ctx, 0, names[i], values[i]);
        if (rv != EXR_ERR_SUCCESS) {
            writer_error(w, err, errlen, "cannot set a header attribute", rv);
            return -1;
        }
    }
    return 0;
}

static int write_header(tf_exr_writer *w, char *err, size_t errlen)
{
    exr_result_t rv = exr_write_header(w->ctx);
    if (rv == EXR_ERR_SUCCESS && tf_exr_sink_flush(&w->sink)) /* a file that cannot take it: now */
        rv = EXR_ERR_WRITE_IO;
    if (rv != EXR_ERR_SUCCESS) {
        writer_error(w, err, errlen, "cannot write the EXR header", rv);
        return -1;
    }
    return 0;
}

/* A terrafarm writer: the six pixel channels and the terrafarm attributes, header written. */
static tf_exr_writer *pixel_writer_create(const char *path, const tf_exr_meta *meta, char *err,
                                          size_t errlen)
{
    tf_exr_layout layout = tf_exr_meta_layout(meta);
    int n;
    const tf_exr_channel *channels = tf_exr_render_channels(meta->pixel, &n);
    tf_exr_writer *w = writer_open(path, &layout, channels, n, sizeof(tf_pixel), err, errlen);
    if (!w)
        return NULL;
    if (set_string_attrs(w, meta, err, errlen) != 0 || write_header(w, err, errlen) != 0) {
        writer_free(w, 1);
        return NULL;
    }
    return w;
}

tf_exr_writer *tf_exr_create(const char *path, const tf_exr_meta *meta, char *err, size_t errlen)
{
    return pixel_writer_create(path, meta, err, errlen);
}

static int writer_refuses(tf_exr_writer *w, char *err, size_t errlen)
{
    if (w->broken || w->sink.write_errno) {
        tf_seterr(err, errlen, "%s: an earlier write failed%s%s", w->path,
                  w->sink.write_errno ? ": " : "",
                  w->sink.write_errno ? strerror(w->sink.write_errno) : "");
        return 1;
    }
    return 0;
}

static void chunk_failed(tf_exr_writer *w, const tf_chunk_ref *c, exr_result_t rv, char *err,
                         size_t errlen)
{
    char what[96];
    if (w->layout.tiled)
        snprintf(what, sizeof what, "cannot write tile (%d, %d)", c->cx, c->cy);
    else
        snprintf(what, sizeof what, "cannot write row %d", c->cy);
    writer_error(w, err, errlen, what, rv);
    w->broken = 1; /* OpenEXRCore's chunk state is unknown now: write nothing more */
}

/* The pipeline's compress step: the writer's packer, lent as the pipeline's user data. */
static exr_result_t zip_chunk(exr_encode_pipeline_t *enc)
{
    return tf_exr_zip_compress(enc->encoding_user_data, enc);
}

/* Encode and write chunk c from `rows`, which holds the caller rows [y0, ...) as width caller
 * pixels each. */
static int encode_chunk(tf_exr_writer *w, const tf_chunk_ref *c, const uint8_t *rows, int y0,
                        char *err, size_t errlen)
{
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    size_t line = (size_t)w->width * w->pixel_bytes;
    const uint8_t *origin = rows + (size_t)(c->rect.y - y0) * line +
                            (size_t)c->rect.x * w->pixel_bytes;
    exr_result_t rv = tf_exr_begin_chunk(w->ctx, &w->layout, c, w->channels, w->nchannels,
                                         origin, w->pixel_bytes, line, &enc);
    if (rv == EXR_ERR_SUCCESS && !w->zip && !(w->zip = tf_exr_zip_new(TF_EXR_ZIP_LEVEL)))
        rv = EXR_ERR_OUT_OF_MEMORY;
    if (rv == EXR_ERR_SUCCESS) {
        enc.encoding_user_data = w->zip; /* OpenEXR's own write step reads the context only */
        enc.compress_fn = zip_chunk;
        rv = exr_encoding_run(w->ctx, 0, &enc);
    }
    if (enc.compress_fn == zip_chunk)
        tf_exr_zip_release(&enc); /* the packed bytes are the packer's, not OpenEXRCore's */
    exr_encoding_destroy(w->ctx, &enc);
    if (rv != EXR_ERR_SUCCESS) {
        chunk_failed(w, c, rv, err, errlen);
        return -1;
    }
    w->next_chunk++;
    assert_writer_state(w);
    return 0;
}

/* Write nrows caller rows starting at the next row; shared by pixel and gray writers. */
static int write_rows_raw(tf_exr_writer *w, int nrows, const void *px, char *err, size_t errlen)
{
    if (writer_refuses(w, err, errlen))
        return -1;
    int y0 = tf_exr_next_row(w), nx = tf_layout_chunks_x(&w->layout);
    int unit = w->layout.tiled ? w->layout.tile_h : TF_EXR_CHUNK_ROWS;
    if (nrows <= 0 || nrows > w->height - y0 || w->next_chunk % nx != 0 ||
        (nrows % unit != 0 && y0 + nrows != w->height)) {
        tf_seterr(err, errlen, "%s: cannot write %d rows at row %d of %d (whole chunk rows of %d "
                  "only)", w->path, nrows, y0, w->height, unit);
        return -1;
    }
    int end = y0 + nrows;
    int64_t first_chunk = w->next_chunk;
    while (w->next_chunk < w->nchunks) {
        tf_chunk_ref c = tf_layout_chunk(&w->layout, w->next_chunk);
        if (c.rect.y >= end)
            break;
        if (encode_chunk(w, &c, px, y0, err, errlen) != 0)
            return -1;
    }
    /* this path (tests, the height-field export) reports a failed write at the call that
     * made it; the coordinator's raw chunk writes learn of it at the next flush or sync */
    if (tf_exr_sink_flush(&w->sink)) {
        tf_seterr(err, errlen, "%s: cannot write rows %d..%d: %s", w->path, y0, end - 1,
                  strerror(w->sink.write_errno));
        w->broken = 1;
        w->next_chunk = first_chunk; /* none of this call's rows counts as written */
        assert_writer_state(w);
        return -1;
    }
    return 0;
}

int tf_exr_write_rows(tf_exr_writer *w, int nrows, const tf_pixel *px, char *err, size_t errlen)
{
    return write_rows_raw(w, nrows, px, err, errlen);
}

int tf_exr_write_chunk(tf_exr_writer *w, int cx, int cy, const void *packed, size_t len,
                       char *err, size_t errlen)
{
    if (writer_refuses(w, err, errlen))
        return -1;
    int64_t index = tf_layout_chunk_index(&w->layout, cx, cy);
    if (index < 0 || index != w->next_chunk || len == 0 || len > INT32_MAX) {
        tf_seterr(err, errlen, "%s: chunk (%d, %d) of %zu bytes is not the next chunk to write "
                  "(index %lld)", w->path, cx, cy, len, (long long)w->next_chunk);
        return -1;
    }
    tf_chunk_ref c = tf_layout_chunk(&w->layout, index);
    tf_exr_clear_error();
    w->sink.referring = w->sink.hold;
    exr_result_t rv = w->layout.tiled
                          ? exr_write_tile_chunk(w->ctx, 0, cx, cy, 0, 0, packed, len)
                          : exr_write_scanline_chunk(w->ctx, 0, cy, packed, len);
    w->sink.referring = 0;
    assert_writer_state(w);
    if (rv != EXR_ERR_SUCCESS || w->sink.write_errno) {
        chunk_failed(w, &c, rv, err, errlen);
        return -1;
    }
    w->next_chunk++;
    assert_writer_state(w);
    return 0;
}

int tf_exr_flush(tf_exr_writer *w, char *err, size_t errlen)
{
    /* Even when refusing new chunks (a failed chunk write), the whole chunks handed over
     * before it go out, and no reference to the caller's memory outlives this call. */
    int refused = writer_refuses(w, err, errlen);
    if (tf_exr_sink_emit(&w->sink) && !refused) {
        tf_seterr(err, errlen, "%s: cannot write: %s", w->path, strerror(w->sink.write_errno));
        return -1;
    }
    return refused ? -1 : 0;
}

void tf_exr_hold_chunks(tf_exr_writer *w, int on)
{
    if (!on && w->sink.held)
        tf_exr_sink_flush(&w->sink); /* a failure is remembered and reported by the next call */
    w->sink.hold = on;
    assert_writer_state(w);
}

int tf_exr_holds_references(const tf_exr_writer *w) { return w->sink.held > 0; }

/* After a sync every byte written is on disk and its page-cache pages are clean: let them go.
 * Nothing reads the output back while it is written (a resume reads it before), so keeping
 * them only pushes a long render's or a sequence's gigabytes into other programs' cache; and
 * freed pages are reused for the next writes, which on a virtual machine are otherwise fresh
 * guest memory whose first touch traps to the host (bench/README.md section 12: 70-88 ->
 * 18-24 ms of CPU to write 32 MB in a test program; the coordinator's 0.84x on alps.scene at
 * 3840x1280).  Advice only: its failure changes nothing. */
static void drop_cached_pages(const tf_exr_writer *w)
{
    (void)posix_fadvise(w->sink.fd, 0, 0, POSIX_FADV_DONTNEED);
}

int tf_exr_sync(tf_exr_writer *w, char *err, size_t errlen)
{
    if (writer_refuses(w, err, errlen))
        return -1;
    if (tf_exr_sink_flush(&w->sink)) {
        tf_seterr(err, errlen, "%s: cannot write: %s", w->path, strerror(w->sink.write_errno));
        return -1;
    }
    if (fsync(w->sink.fd) != 0) {
        tf_seterr(err, errlen, "%s: fsync failed: %s", w->path, strerror(errno));
        return -1;
    }
    drop_cached_pages(w);
    return 0;
}

int tf_exr_finish(tf_exr_writer *w, char *err, size_t errlen)
{
    if (w->broken || w->next_chunk != w->nchunks) {
        tf_seterr(err, errlen, "%s: cannot finish: only %d of %d rows written", w->path,
                  w->broken ? 0 : tf_exr_next_row(w), w->height);
        writer_free(w, 1);
        return -1;
    }
    tf_exr_clear_error();
    exr_result_t rv = exr_finish(&w->ctx); /* writes the offset table through sink_write */
    if (rv == EXR_ERR_SUCCESS)
        tf_exr_sink_flush(&w->sink);
    if (rv != EXR_ERR_SUCCESS || w->sink.write_errno) {
        writer_error(w, err, errlen, "cannot finish the EXR file", rv);
        writer_free(w, 1);
        return -1;
    }
    int rc = 0;
    if (fsync(w->sink.fd) != 0) {
        tf_seterr(err, errlen, "%s: fsync failed: %s", w->path, strerror(errno));
        rc = -1;
    }
    if (tf_exr_sink_close(&w->sink) != 0 && rc == 0) {
        tf_seterr(err, errlen, "%s: close failed: %s", w->path, strerror(errno));
        rc = -1;
    }
    writer_free(w, 1);
    return rc;
}

void tf_exr_abandon(tf_exr_writer *w)
{
    writer_free(w, 1);
}

void tf_exr_writer_take_path(tf_exr_writer *w, char *path)
{
    free(w->path);
    w->path = path;
}

int tf_exr_write_gray(const char *path, int width, int height, const float *data, char *err,
                      size_t errlen)
{
    return tf_exr_write_gray_attrs(path, width, height, data, NULL, err, errlen);
}

/* FLOAT channels (sorted by name) over interleaved pixels of nchannels floats. */
static int write_floats(const char *path, int width, int height, const tf_exr_channel *channels,
                        int nchannels, const float *data, const char *const *attrs, char *err,
                        size_t errlen)
{
    tf_exr_layout layout = {width, height, 0, 0, 0, TF_PIXEL_FLOAT};
    tf_exr_writer *w = writer_open(path, &layout, channels, nchannels,
                                   (size_t)nchannels * sizeof(float), err, errlen);
    if (!w)
        return -1;
    exr_result_t rv = exr_attr_set_string(w->ctx, 0, TF_EXR_ATTR_VERSION, TF_VERSION);
    for (int i = 0; attrs && attrs[i] && rv == EXR_ERR_SUCCESS; i += 2)
        rv = exr_attr_set_string(w->ctx, 0, attrs[i], attrs[i + 1]);
    if (rv != EXR_ERR_SUCCESS)
        writer_error(w, err, errlen, "cannot set a header attribute", rv);
    if (rv != EXR_ERR_SUCCESS || write_header(w, err, errlen) != 0 ||
        write_rows_raw(w, height, data, err, errlen) != 0) {
        writer_free(w, 1);
        return -1;
    }
    return tf_exr_finish(w, err, errlen);
}

int tf_exr_write_gray_attrs(const char *path, int width, int height, const float *data,
                            const char *const *attrs, char *err, size_t errlen)
{
    return write_floats(path, width, height, GRAY_CHANNELS, 1, data, attrs, err, errlen);
}

int tf_exr_write_planes(const char *path, int width, int height, const char *const *names,
                        const float *const *planes, int nplanes, const char *const *attrs,
                        char *err, size_t errlen)
{
    size_t count = (size_t)width * (size_t)height;
    tf_exr_channel *ch = calloc((size_t)nplanes, sizeof *ch);
    float *px = malloc(count * (size_t)nplanes * sizeof *px);
    int rc = -1;
    if (!ch || !px)
        tf_seterr(err, errlen, "%s: out of memory", path);
    for (int c = 0; ch && px && c < nplanes; c++) {
        ch[c] = (tf_exr_channel){names[c], (size_t)c * sizeof(float), EXR_PIXEL_FLOAT};
        for (size_t i = 0; i < count; i++)
            px[i * (size_t)nplanes + (size_t)c] = planes[c][i];
    }
    if (ch && px)
        rc = write_floats(path, width, height, ch, nplanes, px, attrs, err, errlen);
    free(px);
    free(ch);
    return rc;
}
