/* exrstream.c: streaming a (possibly partial) output's verified chunks back (exrfile.h): as
 * decoded rectangles, with their packed bytes, or assembled into rows. */
#include "image/exrinternal.h"

#include <stdlib.h>
#include <string.h>

#include "log.h"

typedef struct chunk_stream {
    tf_exr_chunk_fn fn;
    void *user;
} chunk_stream;

static int stream_chunk(void *user, tf_exr_reader *r, const exr_chunk_info_t *cinfo,
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
    tf_exr_reader r;
    if (errlen > 0)
        err[0] = '\0'; /* so a stop by fn can be told from our own failures below */
    int rc = tf_exr_reader_open(&r, path, err, errlen);
    if (rc == 1)
        tf_seterr(err, errlen, "%s: no such file", path);
    if (rc != 0)
        return -1;
    *meta = r.meta; /* filled before the first chunk arrives, so fn may size things from it */
    chunk_stream s = {fn, user};
    int64_t good = tf_exr_walk_chunks(&r, stream_chunk, &s, err, errlen);
    if (good < 0 && errlen > 0 && !err[0])
        tf_seterr(err, errlen, "%s: reading stopped by the chunk consumer", path);
    if (good >= 0)
        *chunks_valid = good;
    tf_exr_reader_close(&r);
    return good < 0 ? -1 : 0;
}

int tf_exr_read_packed_chunks(const char *path, tf_exr_meta *meta, int64_t *chunks_valid,
                              tf_exr_packed_fn fn, void *user, char *err, size_t errlen)
{
    tf_exr_reader r;
    if (errlen > 0)
        err[0] = '\0';
    int rc = tf_exr_reader_open(&r, path, err, errlen);
    if (rc == 1)
        tf_seterr(err, errlen, "%s: no such file", path);
    if (rc != 0)
        return -1;
    *meta = r.meta;
    int64_t good = tf_exr_walk_packed(&r, INT64_MAX, fn, user, err, errlen);
    if (good < 0 && errlen > 0 && !err[0])
        tf_seterr(err, errlen, "%s: reading stopped by the chunk consumer", path);
    if (good >= 0)
        *chunks_valid = good;
    tf_exr_reader_close(&r);
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
