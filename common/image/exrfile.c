/* exrfile.c: the render's OpenEXR output and checkpoint (see exrfile.h), on OpenEXRCore.
 *
 * Writing.  Every byte goes through sink_write(), a pwrite loop on our own descriptor, so that
 * (1) tf_exr_sync can fsync it, (2) the first failing write (ENOSPC, EIO, ...) is remembered
 * with its errno and reported as one line naming the file, and (3) tf_exr_abandon can close the
 * file without OpenEXRCore writing another byte: it sets sink.abandoned, after which
 * sink_write refuses everything, exactly as if the process had been killed at that instant.
 *
 * On-disk invariant of a file being written: header, then the offset table (all zero until
 * tf_exr_finish), then whole chunks in increasing y, each "int32 y, int32 packed size, packed
 * bytes".  OpenEXRCore 3.1.5 sees the zero offset table as invalid and rebuilds it by walking
 * those chunk headers (tests/unit/test_exrfile.c checks that it does), so a killed render is
 * readable up to its last whole chunk.
 *
 * Reading and verification.  A chunk counts as done only if its header is the expected y, its
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
#include <unistd.h>
#include "log.h"

/* Scanlines per chunk: ZIPS, one scanline per chunk.  The coordinator then holds one row, not
 * sixteen, between the workers and the disk (its memory stays flat as images grow wider), and
 * a killed render loses no finished row to an incomplete chunk. */
#define TF_EXR_CHUNK_ROWS 1
#define TF_EXR_COMPRESSION EXR_COMPRESSION_ZIPS
/* zlib level 1, not zlib's default 6: the coordinator shares the cores with the workers, and
 * on float pixels level 6 buys 1.4% of file size for 13% more of the coordinator's CPU
 * (alps.scene 1920x640: 17.97 -> 18.22 MB, coordinator 1.05 -> 0.92 CPU-s).  Any level reads
 * back the same; a resumed file may mix levels. */
#define TF_EXR_ZIP_LEVEL 1
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

typedef struct tf_exr_sink {
    int fd;
    int write_errno;  /* first failure, 0 if none */
    int abandoned;    /* once set, nothing more reaches the file */
} tf_exr_sink;

static int64_t sink_write(exr_const_context_t ctxt, void *userdata, const void *buffer,
                          uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctxt;
    (void)error_cb;
    tf_exr_sink *s = userdata;
    if (s->abandoned)
        return -1;
    if (sz > (uint64_t)INT64_MAX || offset > (uint64_t)INT64_MAX - sz) {
        s->write_errno = s->write_errno ? s->write_errno : EFBIG;
        return -1;
    }
    const uint8_t *p = buffer;
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
    return (int64_t)sz;
}

/* ---------------------------------------------------------------------------------------------
 * Channel layout.  EXR stores channels sorted by name (A B G R Z spp); we always address them
 * by name, so the order in tf_pixel never matters. */

typedef struct channel_map {
    const char *name;
    size_t offset; /* byte offset of the float inside one caller pixel */
} channel_map;

static const channel_map PIXEL_CHANNELS[] = {
    {"A", offsetof(tf_pixel, a)}, {"B", offsetof(tf_pixel, b)}, {"G", offsetof(tf_pixel, g)},
    {"R", offsetof(tf_pixel, r)}, {"Z", offsetof(tf_pixel, z)}, {"spp", offsetof(tf_pixel, spp)},
};
#define N_PIXEL_CHANNELS (int)(sizeof PIXEL_CHANNELS / sizeof PIXEL_CHANNELS[0])

static const channel_map GRAY_CHANNELS[] = {{"Y", 0}};

static const channel_map *find_channel(const channel_map *map, int n, const char *name)
{
    for (int i = 0; i < n; i++)
        if (strcmp(map[i].name, name) == 0)
            return &map[i];
    return NULL;
}

/* ---------------------------------------------------------------------------------------------
 * Writer. */

struct tf_exr_writer {
    exr_context_t ctx;
    tf_exr_sink sink;
    char *path;
    int width, height;
    int next_row;                /* first row not yet written; chunk aligned until the end */
    const channel_map *channels;
    int nchannels;
    size_t pixel_bytes;          /* stride of one caller pixel */
    int broken;                  /* a chunk write failed: every later write/sync/finish fails */
};

int tf_exr_chunk_rows(void) { return TF_EXR_CHUNK_ROWS; }

int tf_exr_next_row(const tf_exr_writer *w) { return w->next_row; }

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
    if (abandon)
        w->sink.abandoned = 1;
    if (w->ctx)
        exr_finish(&w->ctx);
    if (w->sink.fd >= 0)
        close(w->sink.fd);
    free(w->path);
    free(w);
}

static int valid_size(int width, int height)
{
    return width > 0 && height > 0 && width <= TF_EXR_MAX_DIM && height <= TF_EXR_MAX_DIM;
}

/* Open `path` (truncating) and start an OpenEXRCore write context on it with one scanline
 * part of the given channels.  The header is not written yet. */
static tf_exr_writer *writer_open(const char *path, int width, int height,
                                  const channel_map *channels, int nchannels, size_t pixel_bytes,
                                  char *err, size_t errlen)
{
    if (!valid_size(width, height)) {
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
    w->width = width;
    w->height = height;
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
    int part = 0;
    exr_result_t rv = exr_start_write(&w->ctx, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_add_part(w->ctx, NULL, EXR_STORAGE_SCANLINE, &part);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr_simple(w->ctx, part, width, height,
                                                 TF_EXR_COMPRESSION);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_zip_compression_level(w->ctx, part, TF_EXR_ZIP_LEVEL);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_lineorder(w->ctx, part, EXR_LINEORDER_INCREASING_Y);
    for (int i = 0; i < nchannels && rv == EXR_ERR_SUCCESS; i++)
        rv = exr_add_channel(w->ctx, part, channels[i].name, EXR_PIXEL_FLOAT,
                             EXR_PERCEPTUALLY_LINEAR, 1, 1);
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
    tf_exr_writer *w = writer_open(path, meta->width, meta->height, PIXEL_CHANNELS,
                                   N_PIXEL_CHANNELS, sizeof(tf_pixel), err, errlen);
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

/* Encode and write the chunk starting at row y (chunk aligned) from `rows`, which holds the
 * chunk's rows as width * nrows caller pixels. */
static int write_chunk(tf_exr_writer *w, int y, const uint8_t *rows, char *err, size_t errlen)
{
    exr_chunk_info_t cinfo;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    exr_result_t rv = exr_write_scanline_chunk_info(w->ctx, 0, y, &cinfo);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_initialize(w->ctx, 0, &cinfo, &enc);
    if (rv == EXR_ERR_SUCCESS) {
        size_t line = (size_t)w->width * w->pixel_bytes;
        for (int c = 0; c < enc.channel_count; c++) {
            exr_coding_channel_info_t *ch = &enc.channels[c];
            const channel_map *m = find_channel(w->channels, w->nchannels, ch->channel_name);
            if (!m) { /* cannot happen: we declared exactly these channels */
                rv = EXR_ERR_INVALID_ARGUMENT;
                break;
            }
            ch->encode_from_ptr = rows + m->offset;
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
        char what[64];
        snprintf(what, sizeof what, "cannot write rows %d..%d", y,
                 y + TF_EXR_CHUNK_ROWS > w->height ? w->height - 1 : y + TF_EXR_CHUNK_ROWS - 1);
        writer_error(w, err, errlen, what, rv);
        return -1;
    }
    return 0;
}

/* Write nrows caller rows starting at w->next_row; shared by pixel and gray writers. */
static int write_rows_raw(tf_exr_writer *w, int nrows, const void *px, char *err, size_t errlen)
{
    if (w->broken || w->sink.write_errno) {
        tf_seterr(err, errlen, "%s: an earlier write failed%s%s", w->path,
                 w->sink.write_errno ? ": " : "",
                 w->sink.write_errno ? strerror(w->sink.write_errno) : "");
        return -1;
    }
    if (nrows <= 0 || nrows > w->height - w->next_row ||
        (nrows % TF_EXR_CHUNK_ROWS != 0 && w->next_row + nrows != w->height)) {
        tf_seterr(err, errlen, "%s: cannot write %d rows at row %d of %d (whole chunks of %d only)",
                 w->path, nrows, w->next_row, w->height, TF_EXR_CHUNK_ROWS);
        return -1;
    }
    int end = w->next_row + nrows; /* <= height: no overflow */
    const uint8_t *rows = px;
    size_t chunk_bytes = (size_t)w->width * w->pixel_bytes * TF_EXR_CHUNK_ROWS;
    for (int y = w->next_row; y < end; y += TF_EXR_CHUNK_ROWS, rows += chunk_bytes) {
        if (write_chunk(w, y, rows, err, errlen) != 0) {
            w->broken = 1; /* OpenEXRCore's chunk state is unknown now: write nothing more */
            return -1;
        }
        w->next_row = y + TF_EXR_CHUNK_ROWS < end ? y + TF_EXR_CHUNK_ROWS : end;
    }
    return 0;
}

int tf_exr_write_rows(tf_exr_writer *w, int nrows, const tf_pixel *px, char *err, size_t errlen)
{
    return write_rows_raw(w, nrows, px, err, errlen);
}

int tf_exr_sync(tf_exr_writer *w, char *err, size_t errlen)
{
    if (w->broken || w->sink.write_errno) {
        tf_seterr(err, errlen, "%s: an earlier write failed%s%s", w->path,
                 w->sink.write_errno ? ": " : "",
                 w->sink.write_errno ? strerror(w->sink.write_errno) : "");
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
    if (w->broken || w->next_row != w->height) {
        tf_seterr(err, errlen, "%s: cannot finish: only %d of %d rows written", w->path,
                 w->next_row, w->height);
        writer_free(w, 1);
        return -1;
    }
    last_exr_message[0] = '\0';
    exr_result_t rv = exr_finish(&w->ctx); /* writes the offset table through sink_write */
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
    tf_exr_writer *w = writer_open(path, width, height, GRAY_CHANNELS, 1, sizeof(float), err,
                                   errlen);
    if (!w)
        return -1;
    exr_result_t rv = exr_attr_set_string(w->ctx, 0, ATTR_VERSION, TF_VERSION);
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
    int nchunks;
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

/* The part must be a single ZIP scanline part holding exactly our six FLOAT channels. */
static int check_layout(exr_reader *r, char *err, size_t errlen)
{
    exr_storage_t storage;
    exr_compression_t comp;
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *chl = NULL;
    int nparts = 0;
    if (exr_get_count(r->ctx, &nparts) != EXR_ERR_SUCCESS || nparts != 1 ||
        exr_get_storage(r->ctx, 0, &storage) != EXR_ERR_SUCCESS ||
        storage != EXR_STORAGE_SCANLINE ||
        exr_get_compression(r->ctx, 0, &comp) != EXR_ERR_SUCCESS || comp != TF_EXR_COMPRESSION ||
        exr_get_data_window(r->ctx, 0, &dw) != EXR_ERR_SUCCESS || dw.min.x != 0 ||
        dw.min.y != 0 || exr_get_channels(r->ctx, 0, &chl) != EXR_ERR_SUCCESS ||
        chl->num_channels != N_PIXEL_CHANNELS) {
        tf_seterr(err, errlen, "%s: not a terrafarm render (unexpected EXR layout)", r->path);
        return -1;
    }
    for (int i = 0; i < chl->num_channels; i++) {
        const exr_attr_chlist_entry_t *e = &chl->entries[i];
        if (!find_channel(PIXEL_CHANNELS, N_PIXEL_CHANNELS, e->name.str) ||
            e->pixel_type != EXR_PIXEL_FLOAT || e->x_sampling != 1 || e->y_sampling != 1) {
            tf_seterr(err, errlen, "%s: not a terrafarm render (channel %s)", r->path,
                     e->name.str);
            return -1;
        }
    }
    int64_t w = (int64_t)dw.max.x + 1, h = (int64_t)dw.max.y + 1;
    if (w > TF_EXR_MAX_DIM || h > TF_EXR_MAX_DIM || !valid_size((int)w, (int)h)) {
        tf_seterr(err, errlen, "%s: not a terrafarm render (size %" PRId64 "x%" PRId64 ")",
                 r->path, w, h);
        return -1;
    }
    r->meta.width = (int)w;
    r->meta.height = (int)h;
    r->nchunks = (r->meta.height + TF_EXR_CHUNK_ROWS - 1) / TF_EXR_CHUNK_ROWS;
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

/* Locate chunk `index` and check its header against the file: right y, right row count, packed
 * bytes entirely inside the file.  Returns 0 if plausible. */
static int locate_chunk(exr_reader *r, int index, exr_chunk_info_t *cinfo)
{
    int y = index * TF_EXR_CHUNK_ROWS;
    if (exr_read_scanline_chunk_info(r->ctx, 0, y, cinfo) != EXR_ERR_SUCCESS)
        return -1;
    int rows = r->meta.height - y < TF_EXR_CHUNK_ROWS ? r->meta.height - y : TF_EXR_CHUNK_ROWS;
    if (cinfo->start_y != y || cinfo->height != rows || cinfo->width != r->meta.width)
        return -1;
    if (cinfo->packed_size == 0 || cinfo->data_offset > (uint64_t)r->file_size ||
        cinfo->packed_size > (uint64_t)r->file_size - cinfo->data_offset)
        return -1;
    return 0;
}

/* Decode the located chunk into out (width * rows pixels).  Returns 0 if it decoded. */
static int decode_chunk(exr_reader *r, const exr_chunk_info_t *cinfo, tf_pixel *out)
{
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    exr_result_t rv = exr_decoding_initialize(r->ctx, 0, cinfo, &dec);
    if (rv == EXR_ERR_SUCCESS) {
        for (int c = 0; c < dec.channel_count; c++) {
            exr_coding_channel_info_t *ch = &dec.channels[c];
            const channel_map *m = find_channel(PIXEL_CHANNELS, N_PIXEL_CHANNELS,
                                                ch->channel_name);
            ch->decode_to_ptr = m ? (uint8_t *)out + m->offset : NULL;
            ch->user_pixel_stride = (int32_t)sizeof(tf_pixel);
            ch->user_line_stride = (int32_t)(sizeof(tf_pixel) * (size_t)r->meta.width);
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
                        const tf_pixel *px);

/* Verify chunks from the top; returns the number of leading whole, decodable chunks, or -1 if
 * fn failed or memory ran out (message in err). */
static int walk_chunks(exr_reader *r, chunk_fn fn, void *user, char *err, size_t errlen)
{
    size_t n = (size_t)r->meta.width * TF_EXR_CHUNK_ROWS;
    tf_pixel *px = malloc(n * sizeof *px);
    if (!px) {
        tf_seterr(err, errlen, "%s: out of memory", r->path);
        return -1;
    }
    int good = 0;
    for (; good < r->nchunks; good++) {
        exr_chunk_info_t cinfo;
        if (locate_chunk(r, good, &cinfo) != 0 || decode_chunk(r, &cinfo, px) != 0)
            break;
        if (fn && fn(user, r, &cinfo, px) != 0) {
            good = -1;
            break;
        }
    }
    free(px);
    return good;
}

static int rows_in_chunks(const exr_reader *r, int chunks)
{
    int rows = chunks * TF_EXR_CHUNK_ROWS;
    return rows < r->meta.height ? rows : r->meta.height;
}

/* Was the file finished (offset table written by exr_finish)?  Asked of a second context
 * with chunk reconstruction disabled, so only a real offset table can answer yes.  With
 * whole_file set, the last chunk must also end exactly at the end of the file. */
static int offset_table_valid_ext(const char *path, int nchunks, int whole_file)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = remember_exr_error;
    init.flags = EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE |
                 EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    exr_context_t ctx = NULL;
    exr_chunk_info_t cinfo;
    struct stat st;
    int ok = stat(path, &st) == 0 && exr_start_read(&ctx, path, &init) == EXR_ERR_SUCCESS &&
             exr_read_scanline_chunk_info(ctx, 0, (nchunks - 1) * TF_EXR_CHUNK_ROWS, &cinfo) ==
                 EXR_ERR_SUCCESS &&
             (!whole_file || cinfo.data_offset + cinfo.packed_size == (uint64_t)st.st_size);
    if (ctx)
        exr_finish(&ctx);
    return ok;
}

static int offset_table_valid(const char *path, int nchunks)
{
    return offset_table_valid_ext(path, nchunks, 0);
}

/* A finished file whose last chunk lies wholly inside it: every chunk was written before the
 * offset table (exr_finish), so it is complete without decoding each chunk -- which for a
 * large image would cost seconds on every new render over an old output. */
static int finished_and_whole(const char *path, int nchunks)
{
    return offset_table_valid_ext(path, nchunks, 1);
}

int tf_exr_probe(const char *path, tf_exr_meta *meta, int *rows_done, int *complete, char *err,
                 size_t errlen)
{
    exr_reader r;
    int rc = reader_open(&r, path, err, errlen);
    if (rc != 0)
        return rc;
    if (finished_and_whole(path, r.nchunks)) {
        *meta = r.meta;
        *rows_done = r.meta.height;
        *complete = 1;
        reader_close(&r);
        return 0;
    }
    int good = walk_chunks(&r, NULL, NULL, err, errlen);
    if (good >= 0) {
        *meta = r.meta;
        *rows_done = rows_in_chunks(&r, good);
        *complete = good == r.nchunks && offset_table_valid(path, r.nchunks);
    }
    reader_close(&r);
    return good < 0 ? -1 : 0;
}

/* ---------------------------------------------------------------------------------------------
 * Streaming rows back. */

typedef struct row_stream {
    tf_exr_row_fn fn;
    void *user;
} row_stream;

static int stream_chunk_rows(void *user, exr_reader *r, const exr_chunk_info_t *cinfo,
                             const tf_pixel *px)
{
    row_stream *s = user;
    for (int i = 0; i < cinfo->height; i++)
        if (s->fn(s->user, cinfo->start_y + i, px + (size_t)i * (size_t)r->meta.width) != 0)
            return -1;
    return 0;
}

int tf_exr_read_rows(const char *path, tf_exr_meta *meta, int *rows_valid, tf_exr_row_fn fn,
                     void *user, char *err, size_t errlen)
{
    exr_reader r;
    if (errlen > 0)
        err[0] = '\0'; /* so a stop by fn can be told from our own failures below */
    int rc = reader_open(&r, path, err, errlen);
    if (rc == 1)
        tf_seterr(err, errlen, "%s: no such file", path);
    if (rc != 0)
        return -1;
    *meta = r.meta; /* filled before the first row arrives, so fn may size things from it */
    row_stream s = {fn, user};
    int good = walk_chunks(&r, stream_chunk_rows, &s, err, errlen);
    if (good < 0 && errlen > 0 && !err[0])
        tf_seterr(err, errlen, "%s: reading stopped by the row consumer", path);
    if (good >= 0)
        *rows_valid = rows_in_chunks(&r, good);
    reader_close(&r);
    return good < 0 ? -1 : 0;
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
                          const tf_pixel *px)
{
    (void)px;
    raw_copy *c = user;
    if (cinfo->packed_size > c->cap) {
        void *p = realloc(c->buf, (size_t)cinfo->packed_size);
        if (!p) {
            snprintf(c->err, c->errlen, "%s: out of memory", r->path);
            return -1;
        }
        c->buf = p;
        c->cap = (size_t)cinfo->packed_size;
    }
    exr_result_t rv = exr_read_chunk(r->ctx, 0, cinfo, c->buf);
    if (rv != EXR_ERR_SUCCESS) {
        set_error(c->err, c->errlen, r->path, "cannot read a verified chunk", rv);
        return -1;
    }
    rv = exr_write_scanline_chunk(c->w->ctx, 0, cinfo->start_y, c->buf, cinfo->packed_size);
    if (rv != EXR_ERR_SUCCESS) {
        writer_error(c->w, c->err, c->errlen, "cannot copy a chunk", rv);
        return -1;
    }
    c->w->next_row = cinfo->start_y + cinfo->height;
    return 0;
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
    int good = w ? walk_chunks(&r, copy_chunk_raw, &copy, err, errlen) : -1;
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
    *rows_done = w->next_row;
    return w;
}
