/* exrfile.c: the render's OpenEXR output and checkpoint (see exrfile.h), on OpenEXRCore.
 *
 * Writing.  Every byte goes through sink_write(), a write-behind buffer and pwrite loop on our
 * own descriptor, so that
 * (1) tf_exr_sync can fsync it, (2) the first failing write (ENOSPC, EIO, ...) is remembered
 * with its errno and reported as one line naming the file, and (3) tf_exr_abandon can close the
 * file without OpenEXRCore writing another byte: it sets sink.abandoned, after which
 * sink_write refuses everything, exactly as if the process had been killed at that instant.
 *
 * On-disk invariant of a file being written: header, then the offset table (all zero until
 * tf_exr_finish), then whole chunks in file order, each "int32 y, int32 packed size, packed
 * bytes" (tiles: "int32 tx, ty, level x, level y, packed size, packed bytes").  OpenEXRCore
 * 3.1.5 sees the zero offset table as invalid and rebuilds it by walking
 * those chunk headers (tests/unit/test_exrfile.c checks that it does), so a killed render is
 * readable up to its last whole chunk.
 *
 * Reading and verification.  A chunk counts as done only if its header names the expected
 * chunk (y, or tile indices), its
 * packed bytes lie inside the file, and it decodes (ZIP inflate checks its stream).  Chunks
 * are verified from the top; the first one that fails ends the valid prefix, so a torn final
 * chunk is dropped, never trusted.
 *
 * Resume.  The valid prefix is copied raw (packed bytes, no recompression) into PATH.resume.tmp
 * under the same header, that file is fsynced, renamed over PATH, and the directory fsynced.
 * Until the rename PATH is the old partial file; after it, the new one: never less. */
#include "image/exrfile.h"

#include <openexr.h>

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>
#include "image/exrpart.h"
#include "log.h"

/* Scanlines per chunk of a scanline file: ZIPS, one scanline per chunk, so that any rows:K task
 * is whole chunks a worker can encode alone, and a killed render loses no finished row to an
 * incomplete chunk. */
#define TF_EXR_CHUNK_ROWS 1
#define TF_EXR_MAX_DIM 65536 /* refuse absurd sizes before allocating anything */

static const char ATTR_HASH[] = "terrafarm.scene_hash";
static const char ATTR_SCENE[] = "terrafarm.scene";
static const char ATTR_SETTINGS[] = "terrafarm.settings";
static const char ATTR_VERSION[] = "terrafarm.version";

#ifndef TF_VERSION
#define TF_VERSION "unknown"
#endif

/* ---------------------------------------------------------------------------------------------
 * Error text.  OpenEXRCore reports details through a callback on the failing thread; we keep
 * the last one per thread (never printed) and append it to our own one-line messages. */

static _Thread_local char last_exr_message[200];

static void remember_exr_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    snprintf(last_exr_message, sizeof last_exr_message, "%s (%s)", msg ? msg : "",
             exr_get_error_code_as_string(code));
}

static void set_error(char *err, size_t errlen, const char *path, const char *what,
                      exr_result_t rv)
{
    if (!err || errlen == 0)
        return;
    if (rv != EXR_ERR_SUCCESS && last_exr_message[0])
        tf_seterr(err, errlen, "%s: %s: %s", path, what, last_exr_message);
    else if (rv != EXR_ERR_SUCCESS)
        tf_seterr(err, errlen, "%s: %s: %s", path, what, exr_get_default_error_message(rv));
    else
        tf_seterr(err, errlen, "%s: %s", path, what);
}

/* ---------------------------------------------------------------------------------------------
 * The output stream: our descriptor, the first errno that hit it, and the abandon switch. */

#define SINK_IOV 64 /* pieces in one run (one pwritev) */

typedef struct tf_exr_sink {
    int fd;
    int write_errno;  /* first failure, 0 if none */
    int abandoned;    /* once set, nothing more reaches the file */
    /* Write-behind: OpenEXRCore writes each chunk as two writes (its small header, its
     * bytes), in increasing offsets.  Contiguous writes gather here as one run of pieces and
     * reach the file in one pwritev when the run is full, before any other write, and on
     * sink_flush (sync, finish, abandon, tf_exr_flush): two syscalls per chunk become one per
     * run.  Small pieces are copied into buf; with `hold` set (tf_exr_hold_chunks), large ones
     * are referenced where they lie, and the caller keeps them alive until the next flush.
     * The file is still always a prefix of what was written, so a kill leaves whole chunks
     * and at most one torn one. */
    uint8_t *buf;
    size_t len;        /* bytes of buf in use */
    uint64_t run_off;  /* file offset of the run's first byte */
    uint64_t run_len;  /* bytes in the run */
    struct iovec iov[SINK_IOV];
    int niov;
    int hold;          /* tf_exr_hold_chunks: the caller keeps its chunks alive to the flush */
    int referring;     /* set only around tf_exr_write_chunk's raw write of the caller's bytes */
    int held;          /* pieces of the run that are references */
} tf_exr_sink;

#define SINK_BUFFER (256 * 1024)
#define SINK_REF_MIN 4096 /* with hold: pieces this large are referenced, not copied */

static int sink_pwrite(tf_exr_sink *s, const uint8_t *p, uint64_t sz, uint64_t offset)
{
    uint64_t done = 0;
    while (done < sz) {
        ssize_t n = pwrite(s->fd, p + done, (size_t)(sz - done), (off_t)(offset + done));
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0) {
            if (!s->write_errno)
                s->write_errno = n < 0 ? errno : EIO;
            return -1;
        }
        done += (uint64_t)n;
    }
    return 0;
}

/* Write the run out (pwritev, resumed after a short write).  0, or -1 with write_errno set. */
static int sink_flush(tf_exr_sink *s)
{
    if (s->write_errno) { /* nothing more reaches the file: drop the run and its references */
        s->niov = s->held = 0;
        s->len = 0;
        s->run_len = 0;
        return -1;
    }
    struct iovec *v = s->iov;
    int n = s->niov;
    uint64_t off = s->run_off;
    int rc = 0;
    while (n > 0) {
        ssize_t k = pwritev(s->fd, v, n, (off_t)off);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0) {
            if (!s->write_errno)
                s->write_errno = k < 0 ? errno : EIO;
            rc = -1;
            break;
        }
        off += (uint64_t)k;
        while (n > 0 && (size_t)k >= v->iov_len) {
            k -= (ssize_t)v->iov_len;
            v++;
            n--;
        }
        if (n > 0) {
            v->iov_base = (uint8_t *)v->iov_base + k;
            v->iov_len -= (size_t)k;
        }
    }
    s->niov = 0;
    s->held = 0;
    s->len = 0;
    s->run_len = 0;
    return rc;
}

/* Add a piece to the run (which has room for it: the caller checked). */
static void sink_add(tf_exr_sink *s, const void *p, size_t sz, uint64_t offset)
{
    if (s->run_len == 0)
        s->run_off = offset;
    struct iovec *last = s->niov > 0 ? &s->iov[s->niov - 1] : NULL;
    if (last && (const uint8_t *)last->iov_base + last->iov_len == (const uint8_t *)p)
        last->iov_len += sz; /* the buffer's tail, grown by a copy just made */
    else
        s->iov[s->niov++] = (struct iovec){(void *)p, sz};
    s->run_len += sz;
}

static int64_t sink_write(exr_const_context_t ctxt, void *userdata, const void *buffer,
                          uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctxt;
    (void)error_cb;
    tf_exr_sink *s = userdata;
    if (s->abandoned || s->write_errno)
        return -1;
    if (sz > (uint64_t)INT64_MAX || offset > (uint64_t)INT64_MAX - sz) {
        s->write_errno = EFBIG;
        return -1;
    }
    if (sz == 0)
        return 0;
    if (!s->buf)
        s->buf = malloc(SINK_BUFFER); /* without it, every write goes straight through */
    /* Only the caller's packed bytes, never OpenEXRCore's own buffers (the header, the offset
     * table at finish, the encoder's output), which it may free before the flush. */
    int refer = s->referring && sz >= SINK_REF_MIN;
    int fits = refer ? 1 : s->buf && s->len + sz <= SINK_BUFFER;
    if (s->run_len > 0 && (offset != s->run_off + s->run_len || s->niov == SINK_IOV || !fits))
        if (sink_flush(s))
            return -1;
    if (refer) {
        sink_add(s, buffer, (size_t)sz, offset);
        s->held++;
        return (int64_t)sz;
    }
    if (s->buf && s->len + sz <= SINK_BUFFER) {
        memcpy(s->buf + s->len, buffer, (size_t)sz);
        sink_add(s, s->buf + s->len, (size_t)sz, offset);
        s->len += (size_t)sz;
        return (int64_t)sz;
    }
    return sink_pwrite(s, buffer, sz, offset) ? -1 : (int64_t)sz;
}

/* ---------------------------------------------------------------------------------------------
 * Channel layout.  EXR stores channels sorted by name (A B G R Z spp); we always address them
 * by name (exrpart.h), so the order in tf_pixel never matters. */

static const tf_exr_channel GRAY_CHANNELS[] = {{"Y", 0, EXR_PIXEL_FLOAT}};

tf_exr_layout tf_exr_meta_layout(const tf_exr_meta *m)
{
    tf_exr_layout l = {m->width, m->height, m->tiled, m->tile_w, m->tile_h, m->pixel};
    return l;
}

/* ---------------------------------------------------------------------------------------------
 * Writer. */

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
};

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
    set_error(err, errlen, w->path, what, rv);
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
            sink_flush(&w->sink);
        w->sink.abandoned = 1;
    }
    if (w->ctx)
        exr_finish(&w->ctx);
    if (w->sink.fd >= 0)
        close(w->sink.fd);
    free(w->sink.buf);
    free(w->path);
    free(w);
}

static int valid_size(int width, int height)
{
    return width > 0 && height > 0 && width <= TF_EXR_MAX_DIM && height <= TF_EXR_MAX_DIM;
}

/* Open `path` (truncating) and start an OpenEXRCore write context on it with one scanline
 * part of the given channels.  The header is not written yet. */
static tf_exr_writer *writer_open(const char *path, const tf_exr_layout *layout,
                                  const tf_exr_channel *channels, int nchannels,
                                  size_t pixel_bytes, char *err, size_t errlen)
{
    int width = layout->width, height = layout->height;
    if (!valid_size(width, height) || tf_exr_layout_check(layout, NULL, 0)) {
        tf_seterr(err, errlen, "%s: bad image size %dx%d", path, width, height);
        return NULL;
    }
    tf_exr_writer *w = calloc(1, sizeof *w);
    if (!w || !(w->path = strdup(path))) {
        free(w);
        tf_seterr(err, errlen, "%s: out of memory", path);
        return NULL;
    }
    w->sink.fd = -1;
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
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = remember_exr_error;
    init.user_data = &w->sink;
    init.write_fn = sink_write;
    last_exr_message[0] = '\0';
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
    const char *names[] = {ATTR_HASH, ATTR_SCENE, ATTR_SETTINGS, ATTR_VERSION};
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
    if (rv == EXR_ERR_SUCCESS && sink_flush(&w->sink)) /* a file that cannot take it: now */
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

/* Encode and write chunk c from `rows`, which holds the caller rows [y0, ...) as width caller
 * pixels each. */
static int encode_chunk(tf_exr_writer *w, const tf_chunk_ref *c, const uint8_t *rows, int y0,
                        char *err, size_t errlen)
{
    exr_chunk_info_t cinfo;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    exr_result_t rv = w->layout.tiled
                          ? exr_write_tile_chunk_info(w->ctx, 0, c->cx, c->cy, 0, 0, &cinfo)
                          : exr_write_scanline_chunk_info(w->ctx, 0, c->cy, &cinfo);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_initialize(w->ctx, 0, &cinfo, &enc);
    if (rv == EXR_ERR_SUCCESS) {
        size_t line = (size_t)w->width * w->pixel_bytes;
        const uint8_t *origin = rows + (size_t)(c->rect.y - y0) * line +
                                (size_t)c->rect.x * w->pixel_bytes;
        for (int i = 0; i < enc.channel_count; i++) {
            exr_coding_channel_info_t *ch = &enc.channels[i];
            const tf_exr_channel *m = tf_exr_find_channel(w->channels, w->nchannels,
                                                          ch->channel_name);
            if (!m) { /* cannot happen: we declared exactly these channels */
                rv = EXR_ERR_INVALID_ARGUMENT;
                break;
            }
            ch->encode_from_ptr = origin + m->offset;
            ch->user_pixel_stride = (int32_t)w->pixel_bytes;
            ch->user_line_stride = (int32_t)line;
            ch->user_bytes_per_element = 4;
            ch->user_data_type = EXR_PIXEL_FLOAT;
        }
    }
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_choose_default_routines(w->ctx, 0, &enc);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_run(w->ctx, 0, &enc);
    exr_encoding_destroy(w->ctx, &enc);
    if (rv != EXR_ERR_SUCCESS) {
        chunk_failed(w, c, rv, err, errlen);
        return -1;
    }
    w->next_chunk++;
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
    if (sink_flush(&w->sink)) {
        tf_seterr(err, errlen, "%s: cannot write rows %d..%d: %s", w->path, y0, end - 1,
                  strerror(w->sink.write_errno));
        w->broken = 1;
        w->next_chunk = first_chunk; /* none of this call's rows counts as written */
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
    last_exr_message[0] = '\0';
    w->sink.referring = w->sink.hold;
    exr_result_t rv = w->layout.tiled
                          ? exr_write_tile_chunk(w->ctx, 0, cx, cy, 0, 0, packed, len)
                          : exr_write_scanline_chunk(w->ctx, 0, cy, packed, len);
    w->sink.referring = 0;
    if (rv != EXR_ERR_SUCCESS || w->sink.write_errno) {
        chunk_failed(w, &c, rv, err, errlen);
        return -1;
    }
    w->next_chunk++;
    return 0;
}

int tf_exr_flush(tf_exr_writer *w, char *err, size_t errlen)
{
    /* Even when refusing new chunks (a failed chunk write), the whole chunks handed over
     * before it go out, and no reference to the caller's memory outlives this call. */
    int refused = writer_refuses(w, err, errlen);
    if (sink_flush(&w->sink) && !refused) {
        tf_seterr(err, errlen, "%s: cannot write: %s", w->path, strerror(w->sink.write_errno));
        return -1;
    }
    return refused ? -1 : 0;
}

void tf_exr_hold_chunks(tf_exr_writer *w, int on)
{
    if (!on && w->sink.held)
        sink_flush(&w->sink); /* a failure is remembered and reported by the next call */
    w->sink.hold = on;
}

int tf_exr_holds_references(const tf_exr_writer *w) { return w->sink.held > 0; }

int tf_exr_sync(tf_exr_writer *w, char *err, size_t errlen)
{
    if (writer_refuses(w, err, errlen))
        return -1;
    if (sink_flush(&w->sink)) {
        tf_seterr(err, errlen, "%s: cannot write: %s", w->path, strerror(w->sink.write_errno));
        return -1;
    }
    if (fsync(w->sink.fd) != 0) {
        tf_seterr(err, errlen, "%s: fsync failed: %s", w->path, strerror(errno));
        return -1;
    }
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
    last_exr_message[0] = '\0';
    exr_result_t rv = exr_finish(&w->ctx); /* writes the offset table through sink_write */
    if (rv == EXR_ERR_SUCCESS)
        sink_flush(&w->sink);
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
    if (close(w->sink.fd) != 0 && rc == 0) {
        tf_seterr(err, errlen, "%s: close failed: %s", w->path, strerror(errno));
        rc = -1;
    }
    w->sink.fd = -1;
    writer_free(w, 1);
    return rc;
}

void tf_exr_abandon(tf_exr_writer *w)
{
    writer_free(w, 1);
}

int tf_exr_write_gray(const char *path, int width, int height, const float *data, char *err,
                      size_t errlen)
{
    return tf_exr_write_gray_attrs(path, width, height, data, NULL, err, errlen);
}

int tf_exr_write_gray_attrs(const char *path, int width, int height, const float *data,
                            const char *const *attrs, char *err, size_t errlen)
{
    tf_exr_layout layout = {width, height, 0, 0, 0, TF_PIXEL_FLOAT};
    tf_exr_writer *w = writer_open(path, &layout, GRAY_CHANNELS, 1, sizeof(float), err, errlen);
    if (!w)
        return -1;
    exr_result_t rv = exr_attr_set_string(w->ctx, 0, ATTR_VERSION, TF_VERSION);
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

/* ---------------------------------------------------------------------------------------------
 * Reader: open, check it is one of ours, walk and verify chunks. */

typedef struct exr_reader {
    exr_context_t ctx;
    const char *path;
    int64_t file_size;
    tf_exr_meta meta;
    tf_exr_layout layout;
    const tf_exr_channel *channels;
    int nchannels;
    int64_t nchunks;
} exr_reader;

static void reader_close(exr_reader *r)
{
    if (r->ctx)
        exr_finish(&r->ctx);
}

static int copy_string_attr(exr_reader *r, const char *name, char *out, size_t outlen, char *err,
                            size_t errlen)
{
    int32_t len = 0;
    const char *s = NULL;
    exr_result_t rv = exr_attr_get_string(r->ctx, 0, name, &len, &s);
    if (rv != EXR_ERR_SUCCESS || !s || len < 0 || (size_t)len >= outlen) {
        tf_seterr(err, errlen, "%s: not a terrafarm render (attribute %s %s)", r->path, name,
                 rv != EXR_ERR_SUCCESS ? "missing" : "too long");
        return -1;
    }
    memcpy(out, s, (size_t)len);
    out[len] = '\0';
    return 0;
}

/* The part must be a single scanline ZIPS part or a one-level tiled ZIP part holding exactly
 * our six channels, of the types of one pixel type (exrpart.h). */
static int check_layout(exr_reader *r, char *err, size_t errlen)
{
    exr_storage_t storage;
    exr_compression_t comp;
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *chl = NULL;
    int nparts = 0;
    if (exr_get_count(r->ctx, &nparts) != EXR_ERR_SUCCESS || nparts != 1 ||
        exr_get_storage(r->ctx, 0, &storage) != EXR_ERR_SUCCESS ||
        (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) ||
        exr_get_compression(r->ctx, 0, &comp) != EXR_ERR_SUCCESS ||
        exr_get_data_window(r->ctx, 0, &dw) != EXR_ERR_SUCCESS || dw.min.x != 0 ||
        dw.min.y != 0 || exr_get_channels(r->ctx, 0, &chl) != EXR_ERR_SUCCESS ||
        chl->num_channels != 6) {
        tf_seterr(err, errlen, "%s: not a terrafarm render (unexpected EXR layout)", r->path);
        return -1;
    }
    int64_t w = (int64_t)dw.max.x + 1, h = (int64_t)dw.max.y + 1;
    if (w > TF_EXR_MAX_DIM || h > TF_EXR_MAX_DIM || !valid_size((int)w, (int)h)) {
        tf_seterr(err, errlen, "%s: not a terrafarm render (size %" PRId64 "x%" PRId64 ")",
                 r->path, w, h);
        return -1;
    }
    tf_exr_layout l = {(int)w, (int)h, storage == EXR_STORAGE_TILED, 0, 0, TF_PIXEL_FLOAT};
    if (l.tiled) {
        uint32_t tw = 0, th = 0;
        exr_tile_level_mode_t lm;
        exr_tile_round_mode_t rm;
        if (exr_get_tile_descriptor(r->ctx, 0, &tw, &th, &lm, &rm) != EXR_ERR_SUCCESS ||
            lm != EXR_TILE_ONE_LEVEL || tw < 1 || th < 1 || tw > TF_EXR_MAX_DIM ||
            th > TF_EXR_MAX_DIM) {
            tf_seterr(err, errlen, "%s: not a terrafarm render (tiles)", r->path);
            return -1;
        }
        l.tile_w = (int)tw;
        l.tile_h = (int)th;
    }
    for (int i = 0; i < chl->num_channels; i++)
        if (!strcmp(chl->entries[i].name.str, "R") &&
            chl->entries[i].pixel_type == EXR_PIXEL_HALF)
            l.pixel = TF_PIXEL_HALF;
    if (comp != tf_exr_layout_compression(&l)) {
        tf_seterr(err, errlen, "%s: not a terrafarm render (compression)", r->path);
        return -1;
    }
    r->channels = tf_exr_render_channels(l.pixel, &r->nchannels);
    for (int i = 0; i < chl->num_channels; i++) {
        const exr_attr_chlist_entry_t *e = &chl->entries[i];
        const tf_exr_channel *m = tf_exr_find_channel(r->channels, r->nchannels, e->name.str);
        if (!m || e->pixel_type != m->type || e->x_sampling != 1 || e->y_sampling != 1) {
            tf_seterr(err, errlen, "%s: not a terrafarm render (channel %s)", r->path,
                     e->name.str);
            return -1;
        }
    }
    r->layout = l;
    r->meta.width = l.width;
    r->meta.height = l.height;
    r->meta.tiled = l.tiled;
    r->meta.tile_w = l.tile_w;
    r->meta.tile_h = l.tile_h;
    r->meta.pixel = l.pixel;
    r->nchunks = tf_layout_chunk_count(&l);
    return 0;
}

/* Returns 1 if path does not exist, 0 when open and checked, -1 with a message otherwise. */
static int reader_open(exr_reader *r, const char *path, char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    r->path = path;
    struct stat st;
    if (stat(path, &st) != 0) {
        if (errno == ENOENT)
            return 1;
        tf_seterr(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    if (!S_ISREG(st.st_mode)) {
        tf_seterr(err, errlen, "%s: not a regular file", path);
        return -1;
    }
    r->file_size = (int64_t)st.st_size;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = remember_exr_error;
    init.flags = EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE;
    last_exr_message[0] = '\0';
    exr_result_t rv = exr_start_read(&r->ctx, path, &init);
    if (rv != EXR_ERR_SUCCESS) {
        set_error(err, errlen, path, "not a readable OpenEXR file", rv);
        reader_close(r);
        return -1;
    }
    if (check_layout(r, err, errlen) != 0 ||
        copy_string_attr(r, ATTR_HASH, r->meta.scene_hash, sizeof r->meta.scene_hash, err,
                         errlen) != 0 ||
        copy_string_attr(r, ATTR_SCENE, r->meta.scene_name, sizeof r->meta.scene_name, err,
                         errlen) != 0 ||
        copy_string_attr(r, ATTR_SETTINGS, r->meta.settings, sizeof r->meta.settings, err,
                         errlen) != 0) {
        reader_close(r);
        return -1;
    }
    return 0;
}

static exr_result_t chunk_info(exr_context_t ctx, const tf_exr_layout *l, const tf_chunk_ref *c,
                               exr_chunk_info_t *cinfo)
{
    return l->tiled ? exr_read_tile_chunk_info(ctx, 0, c->cx, c->cy, 0, 0, cinfo)
                    : exr_read_scanline_chunk_info(ctx, 0, c->cy, cinfo);
}

/* Locate chunk c and check its header against the file: the right chunk and size, packed
 * bytes entirely inside the file.  Returns 0 if plausible. */
static int locate_chunk(exr_reader *r, const tf_chunk_ref *c, exr_chunk_info_t *cinfo)
{
    if (chunk_info(r->ctx, &r->layout, c, cinfo) != EXR_ERR_SUCCESS)
        return -1;
    /* tile chunk infos hold tile indices in start_x / start_y, scanline ones the first row */
    int sx = r->layout.tiled ? c->cx : 0, sy = c->cy;
    if (cinfo->start_x != sx || cinfo->start_y != sy || cinfo->height != c->rect.h ||
        cinfo->width != c->rect.w)
        return -1;
    if (cinfo->packed_size == 0 || cinfo->data_offset > (uint64_t)r->file_size ||
        cinfo->packed_size > (uint64_t)r->file_size - cinfo->data_offset)
        return -1;
    return 0;
}

/* Decode the located chunk into out (rect.w * rect.h pixels).  Returns 0 if it decoded. */
static int decode_chunk(exr_reader *r, const exr_chunk_info_t *cinfo, const tf_chunk_ref *c,
                        tf_pixel *out)
{
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    exr_result_t rv = exr_decoding_initialize(r->ctx, 0, cinfo, &dec);
    if (rv == EXR_ERR_SUCCESS) {
        for (int i = 0; i < dec.channel_count; i++) {
            exr_coding_channel_info_t *ch = &dec.channels[i];
            const tf_exr_channel *m = tf_exr_find_channel(r->channels, r->nchannels,
                                                          ch->channel_name);
            ch->decode_to_ptr = m ? (uint8_t *)out + m->offset : NULL;
            ch->user_pixel_stride = (int32_t)sizeof(tf_pixel);
            ch->user_line_stride = (int32_t)(sizeof(tf_pixel) * (size_t)c->rect.w);
            ch->user_bytes_per_element = 4;
            ch->user_data_type = EXR_PIXEL_FLOAT;
        }
        rv = exr_decoding_choose_default_routines(r->ctx, 0, &dec);
    }
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_decoding_run(r->ctx, 0, &dec);
    exr_decoding_destroy(r->ctx, &dec);
    return rv == EXR_ERR_SUCCESS ? 0 : -1;
}

/* Called for each verified chunk in order with its decoded pixels; nonzero stops the walk. */
typedef int (*chunk_fn)(void *user, exr_reader *r, const exr_chunk_info_t *cinfo,
                        const tf_chunk_ref *c, const tf_pixel *px);

/* Verify chunks from the first, at most `limit` of them; returns the number of leading whole,
 * decodable chunks, or -1 if fn failed or memory ran out (message in err). */
static int64_t walk_chunks_upto(exr_reader *r, int64_t limit, chunk_fn fn, void *user, char *err,
                                size_t errlen)
{
    tf_chunk_ref c0 = tf_layout_chunk(&r->layout, 0); /* the largest chunk */
    tf_pixel *px = malloc((size_t)c0.rect.w * (size_t)c0.rect.h * sizeof *px);
    if (!px) {
        tf_seterr(err, errlen, "%s: out of memory", r->path);
        return -1;
    }
    int64_t good = 0;
    for (; good < r->nchunks && good < limit; good++) {
        exr_chunk_info_t cinfo;
        tf_chunk_ref c = tf_layout_chunk(&r->layout, good);
        if (locate_chunk(r, &c, &cinfo) != 0 || decode_chunk(r, &cinfo, &c, px) != 0)
            break;
        if (fn && fn(user, r, &cinfo, &c, px) != 0) {
            good = -1;
            break;
        }
    }
    free(px);
    return good;
}

static int64_t walk_chunks(exr_reader *r, chunk_fn fn, void *user, char *err, size_t errlen)
{
    return walk_chunks_upto(r, INT64_MAX, fn, user, err, errlen);
}

/* Was the file finished (offset table written by exr_finish)?  Asked of a second context
 * with chunk reconstruction disabled, so only a real offset table can answer yes.  With
 * whole_file set, the last chunk must also end exactly at the end of the file. */
static int offset_table_valid_ext(const char *path, const tf_exr_layout *l, int whole_file)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = remember_exr_error;
    init.flags = EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE |
                 EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    exr_context_t ctx = NULL;
    exr_chunk_info_t cinfo;
    struct stat st;
    tf_chunk_ref last = tf_layout_chunk(l, tf_layout_chunk_count(l) - 1);
    int ok = stat(path, &st) == 0 && exr_start_read(&ctx, path, &init) == EXR_ERR_SUCCESS &&
             chunk_info(ctx, l, &last, &cinfo) == EXR_ERR_SUCCESS &&
             (!whole_file || cinfo.data_offset + cinfo.packed_size == (uint64_t)st.st_size);
    if (ctx)
        exr_finish(&ctx);
    return ok;
}

/* A finished file whose last chunk lies wholly inside it: every chunk was written before the
 * offset table (exr_finish), so it is complete without decoding each chunk -- which for a
 * large image would cost seconds on every new render over an old output. */
static int finished_and_whole(const char *path, const tf_exr_layout *l)
{
    return offset_table_valid_ext(path, l, 1);
}

int tf_exr_probe_chunks(const char *path, tf_exr_meta *meta, int64_t *chunks_done,
                        int *complete, char *err, size_t errlen)
{
    exr_reader r;
    int rc = reader_open(&r, path, err, errlen);
    if (rc != 0)
        return rc;
    if (finished_and_whole(path, &r.layout)) {
        *meta = r.meta;
        *chunks_done = r.nchunks;
        *complete = 1;
        reader_close(&r);
        return 0;
    }
    int64_t good = walk_chunks(&r, NULL, NULL, err, errlen);
    if (good >= 0) {
        *meta = r.meta;
        *chunks_done = good;
        *complete = good == r.nchunks && offset_table_valid_ext(path, &r.layout, 0);
    }
    reader_close(&r);
    return good < 0 ? -1 : 0;
}

int tf_exr_probe(const char *path, tf_exr_meta *meta, int *rows_done, int *complete, char *err,
                 size_t errlen)
{
    int64_t chunks = 0;
    int rc = tf_exr_probe_chunks(path, meta, &chunks, complete, err, errlen);
    if (rc == 0) {
        tf_exr_layout l = tf_exr_meta_layout(meta);
        *rows_done = tf_layout_rows_in_chunks(&l, chunks);
    }
    return rc;
}

/* ---------------------------------------------------------------------------------------------
 * Streaming chunks and rows back. */

typedef struct chunk_stream {
    tf_exr_chunk_fn fn;
    void *user;
} chunk_stream;

static int stream_chunk(void *user, exr_reader *r, const exr_chunk_info_t *cinfo,
                        const tf_chunk_ref *c, const tf_pixel *px)
{
    (void)r;
    (void)cinfo;
    chunk_stream *s = user;
    return s->fn(s->user, c->rect, px);
}

int tf_exr_read_chunks(const char *path, tf_exr_meta *meta, int64_t *chunks_valid,
                       tf_exr_chunk_fn fn, void *user, char *err, size_t errlen)
{
    exr_reader r;
    if (errlen > 0)
        err[0] = '\0'; /* so a stop by fn can be told from our own failures below */
    int rc = reader_open(&r, path, err, errlen);
    if (rc == 1)
        tf_seterr(err, errlen, "%s: no such file", path);
    if (rc != 0)
        return -1;
    *meta = r.meta; /* filled before the first chunk arrives, so fn may size things from it */
    chunk_stream s = {fn, user};
    int64_t good = walk_chunks(&r, stream_chunk, &s, err, errlen);
    if (good < 0 && errlen > 0 && !err[0])
        tf_seterr(err, errlen, "%s: reading stopped by the chunk consumer", path);
    if (good >= 0)
        *chunks_valid = good;
    reader_close(&r);
    return good < 0 ? -1 : 0;
}

typedef struct packed_stream {
    tf_exr_packed_fn fn;
    void *user;
    uint8_t *buf;
    size_t cap;
    char *err;
    size_t errlen;
} packed_stream;

static int stream_packed(void *user, exr_reader *r, const exr_chunk_info_t *cinfo,
                         const tf_chunk_ref *c, const tf_pixel *px)
{
    packed_stream *s = user;
    if (cinfo->packed_size > s->cap) {
        uint8_t *p = realloc(s->buf, (size_t)cinfo->packed_size);
        if (!p)
            return tf_seterr(s->err, s->errlen, "%s: out of memory", r->path);
        s->buf = p;
        s->cap = (size_t)cinfo->packed_size;
    }
    exr_result_t rv = exr_read_chunk(r->ctx, 0, cinfo, s->buf);
    if (rv != EXR_ERR_SUCCESS) {
        set_error(s->err, s->errlen, r->path, "cannot read a verified chunk", rv);
        return -1;
    }
    return s->fn(s->user, c, s->buf, (size_t)cinfo->packed_size, px);
}

int tf_exr_read_packed_chunks(const char *path, tf_exr_meta *meta, int64_t *chunks_valid,
                              tf_exr_packed_fn fn, void *user, char *err, size_t errlen)
{
    exr_reader r;
    if (errlen > 0)
        err[0] = '\0';
    int rc = reader_open(&r, path, err, errlen);
    if (rc == 1)
        tf_seterr(err, errlen, "%s: no such file", path);
    if (rc != 0)
        return -1;
    *meta = r.meta;
    packed_stream s = {fn, user, NULL, 0, err, errlen};
    int64_t good = walk_chunks(&r, stream_packed, &s, err, errlen);
    if (good < 0 && errlen > 0 && !err[0])
        tf_seterr(err, errlen, "%s: reading stopped by the chunk consumer", path);
    if (good >= 0)
        *chunks_valid = good;
    free(s.buf);
    reader_close(&r);
    return good < 0 ? -1 : 0;
}

/* Rows from chunks: a band of one chunk row (a tile row, or one scanline) is assembled, then
 * handed on row by row once its last chunk arrived. */
typedef struct row_stream {
    tf_exr_row_fn fn;
    void *user;
    const tf_exr_meta *meta;
    tf_pixel *band;
    int band_y, band_h;
    int failed_alloc;
} row_stream;

static int band_chunk(void *user, tf_rect rect, const tf_pixel *px)
{
    row_stream *s = user;
    int width = s->meta->width;
    if (!s->band) {
        int bh = s->meta->tiled ? s->meta->tile_h : 1;
        s->band = malloc((size_t)width * (size_t)bh * sizeof *s->band);
        if (!s->band) {
            s->failed_alloc = 1;
            return -1;
        }
    }
    s->band_y = rect.y;
    s->band_h = rect.h;
    for (int y = 0; y < rect.h; y++)
        memcpy(s->band + (size_t)y * (size_t)width + rect.x, px + (size_t)y * (size_t)rect.w,
               (size_t)rect.w * sizeof *px);
    if (rect.x + rect.w < width)
        return 0; /* the band is not complete yet */
    for (int y = 0; y < rect.h; y++)
        if (s->fn(s->user, rect.y + y, s->band + (size_t)y * (size_t)width) != 0)
            return -1;
    return 0;
}

int tf_exr_read_rows(const char *path, tf_exr_meta *meta, int *rows_valid, tf_exr_row_fn fn,
                     void *user, char *err, size_t errlen)
{
    row_stream s = {fn, user, meta, NULL, 0, 0, 0};
    int64_t chunks = 0;
    int rc = tf_exr_read_chunks(path, meta, &chunks, band_chunk, &s, err, errlen);
    if (rc != 0 && s.failed_alloc)
        tf_seterr(err, errlen, "%s: out of memory", path);
    if (rc == 0) {
        tf_exr_layout l = tf_exr_meta_layout(meta);
        *rows_valid = tf_layout_rows_in_chunks(&l, chunks);
    }
    free(s.band);
    return rc;
}

/* ---------------------------------------------------------------------------------------------
 * Resume. */

/* Names what differs between the file's meta and the expected one; 0 if nothing does. */
static int describe_meta_change(const char *path, const tf_exr_meta *have,
                                const tf_exr_meta *want, char *err, size_t errlen)
{
    if (have->width != want->width || have->height != want->height) {
        tf_seterr(err, errlen, "%s: image size changed since the partial render (%dx%d vs %dx%d)",
                 path, have->width, have->height, want->width, want->height);
        return 1;
    }
    if (strcmp(have->scene_hash, want->scene_hash) != 0) {
        tf_seterr(err, errlen, "%s: scene changed since the partial render (hash %.12s... vs "
                 "%.12s...)", path, have->scene_hash, want->scene_hash);
        return 1;
    }
    if (strcmp(have->settings, want->settings) != 0) {
        tf_seterr(err, errlen, "%s: render settings changed since the partial render "
                 "('%.80s' vs '%.80s')", path, have->settings, want->settings);
        return 1;
    }
    tf_exr_layout a = tf_exr_meta_layout(have), b = tf_exr_meta_layout(want);
    if (a.tiled != b.tiled || a.pixel != b.pixel ||
        (a.tiled && (a.tile_w != b.tile_w || a.tile_h != b.tile_h))) {
        char la[64], lb[64];
        tf_exr_layout_format(&a, la, sizeof la);
        tf_exr_layout_format(&b, lb, sizeof lb);
        tf_seterr(err, errlen, "%s: the file's layout changed since the partial render ('%s' "
                  "vs '%s')", path, la, lb);
        return 1;
    }
    return 0;
}

typedef struct raw_copy {
    tf_exr_writer *w;
    void *buf;
    size_t cap;
    char *err;
    size_t errlen;
} raw_copy;

/* Copy one verified chunk's packed bytes into the new file, untouched. */
static int copy_chunk_raw(void *user, exr_reader *r, const exr_chunk_info_t *cinfo,
                          const tf_chunk_ref *c, const tf_pixel *px)
{
    (void)px;
    raw_copy *rc = user;
    if (cinfo->packed_size > rc->cap) {
        void *p = realloc(rc->buf, (size_t)cinfo->packed_size);
        if (!p) {
            snprintf(rc->err, rc->errlen, "%s: out of memory", r->path);
            return -1;
        }
        rc->buf = p;
        rc->cap = (size_t)cinfo->packed_size;
    }
    exr_result_t rv = exr_read_chunk(r->ctx, 0, cinfo, rc->buf);
    if (rv != EXR_ERR_SUCCESS) {
        set_error(rc->err, rc->errlen, r->path, "cannot read a verified chunk", rv);
        return -1;
    }
    return tf_exr_write_chunk(rc->w, c->cx, c->cy, rc->buf, (size_t)cinfo->packed_size, rc->err,
                              rc->errlen);
}

static int fsync_parent_dir(const char *path, char *err, size_t errlen)
{
    char *dir = strdup(path);
    if (!dir) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        return -1;
    }
    char *slash = strrchr(dir, '/');
    const char *d = slash ? (slash == dir ? "/" : (*slash = '\0', dir)) : ".";
    int fd = open(d, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    int rc = 0;
    if (fd < 0 || fsync(fd) != 0) {
        tf_seterr(err, errlen, "%s: cannot sync directory %s: %s", path, d, strerror(errno));
        rc = -1;
    }
    if (fd >= 0)
        close(fd);
    free(dir);
    return rc;
}

tf_exr_writer *tf_exr_resume(const char *path, const tf_exr_meta *expect, int *rows_done,
                             char *err, size_t errlen)
{
    return tf_exr_resume_prefix(path, expect, INT64_MAX, rows_done, err, errlen);
}

tf_exr_writer *tf_exr_resume_prefix(const char *path, const tf_exr_meta *expect,
                                    int64_t keep_chunks, int *rows_done, char *err, size_t errlen)
{
    exr_reader r;
    int rc = reader_open(&r, path, err, errlen);
    if (rc == 1)
        tf_seterr(err, errlen, "%s: no partial render to resume", path);
    if (rc != 0)
        return NULL;
    if (describe_meta_change(path, &r.meta, expect, err, errlen)) {
        reader_close(&r);
        return NULL;
    }
    size_t plen = strlen(path);
    char *tmp = malloc(plen + sizeof ".resume.tmp");
    if (!tmp) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        reader_close(&r);
        return NULL;
    }
    memcpy(tmp, path, plen);
    memcpy(tmp + plen, ".resume.tmp", sizeof ".resume.tmp");

    tf_exr_writer *w = pixel_writer_create(tmp, &r.meta, err, errlen);
    raw_copy copy = {w, NULL, 0, err, errlen};
    int64_t good = w ? walk_chunks_upto(&r, keep_chunks, copy_chunk_raw, &copy, err, errlen) : -1;
    free(copy.buf);
    reader_close(&r);
    if (good < 0 || tf_exr_sync(w, err, errlen) != 0) {
        writer_free(w, 1);
        unlink(tmp); /* PATH itself was never touched */
        free(tmp);
        return NULL;
    }
    if (rename(tmp, path) != 0) {
        tf_seterr(err, errlen, "%s: cannot rename %s over it: %s", path, tmp, strerror(errno));
        writer_free(w, 1);
        unlink(tmp);
        free(tmp);
        return NULL;
    }
    /* From here PATH is the new file (a valid partial render); the writer keeps its fd. */
    free(w->path);
    w->path = tmp;
    memcpy(tmp, path, plen + 1);
    if (fsync_parent_dir(path, err, errlen) != 0) {
        writer_free(w, 1);
        return NULL;
    }
    *rows_done = tf_exr_next_row(w);
    return w;
}
