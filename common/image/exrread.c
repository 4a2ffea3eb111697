/* exrread.c: reading an output back (exrfile.h, exrinternal.h): open it and check it is one
 * of ours, walk and verify its chunks, and probe how much of it is done.
 *
 * A chunk counts as done only if its header names the expected chunk (y, or tile indices), its
 * packed bytes lie inside the file, and it decodes (ZIP inflate checks its stream).  Chunks
 * are verified from the top; the first one that fails ends the valid prefix, so a torn final
 * chunk is dropped, never trusted. */
#include "image/exrinternal.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "image/exrpart.h"
#include "log.h"

void tf_exr_reader_close(tf_exr_reader *r)
{
    if (r->ctx)
        exr_finish(&r->ctx);
}

static int copy_string_attr(tf_exr_reader *r, const char *name, char *out, size_t outlen, char *err,
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

/* The tile size of a tiled part into l (one level, sides 1 .. TF_EXR_MAX_DIM).  0 or -1. */
static int check_tiles(tf_exr_reader *r, tf_exr_layout *l, char *err, size_t errlen)
{
    uint32_t tw = 0, th = 0;
    exr_tile_level_mode_t lm;
    exr_tile_round_mode_t rm;
    if (exr_get_tile_descriptor(r->ctx, 0, &tw, &th, &lm, &rm) != EXR_ERR_SUCCESS ||
        lm != EXR_TILE_ONE_LEVEL || tw < 1 || th < 1 || tw > TF_EXR_MAX_DIM ||
        th > TF_EXR_MAX_DIM)
        return tf_seterr(err, errlen, "%s: not a terrafarm render (tiles)", r->path);
    l->tile_w = (int)tw;
    l->tile_h = (int)th;
    return 0;
}

/* The pixel type of the channels (exrlayout.h): TF_PIXEL_HALF when R is half, else float. */
static int pixel_type_of(const exr_attr_chlist_t *chl)
{
    for (int i = 0; i < chl->num_channels; i++)
        if (!strcmp(chl->entries[i].name.str, "R") &&
            chl->entries[i].pixel_type == EXR_PIXEL_HALF)
            return TF_PIXEL_HALF;
    return TF_PIXEL_FLOAT;
}

/* Every channel one of the six of pixel type `pixel`, sampled 1:1 (r->channels set to them).
 * 0 or -1. */
static int check_channels(tf_exr_reader *r, const exr_attr_chlist_t *chl, int pixel,
                          char *err, size_t errlen)
{
    r->channels = tf_exr_render_channels(pixel, &r->nchannels);
    for (int i = 0; i < chl->num_channels; i++) {
        const exr_attr_chlist_entry_t *e = &chl->entries[i];
        const tf_exr_channel *m = tf_exr_find_channel(r->channels, r->nchannels, e->name.str);
        if (!m || e->pixel_type != m->type || e->x_sampling != 1 || e->y_sampling != 1)
            return tf_seterr(err, errlen, "%s: not a terrafarm render (channel %s)", r->path,
                             e->name.str);
    }
    return 0;
}

/* The layout found, as the reader's and its metadata's. */
static void keep_layout(tf_exr_reader *r, const tf_exr_layout *l)
{
    r->layout = *l;
    r->meta.width = l->width;
    r->meta.height = l->height;
    r->meta.tiled = l->tiled;
    r->meta.tile_w = l->tile_w;
    r->meta.tile_h = l->tile_h;
    r->meta.pixel = l->pixel;
    r->nchunks = tf_layout_chunk_count(l);
}

/* The part must be a single scanline ZIPS part or a one-level tiled ZIP part holding exactly
 * our six channels, of the types of one pixel type (exrpart.h). */
static int check_layout(tf_exr_reader *r, char *err, size_t errlen)
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
        chl->num_channels != 6)
        return tf_seterr(err, errlen, "%s: not a terrafarm render (unexpected EXR layout)",
                         r->path);
    int64_t w = (int64_t)dw.max.x + 1, h = (int64_t)dw.max.y + 1;
    if (w > TF_EXR_MAX_DIM || h > TF_EXR_MAX_DIM || !tf_exr_valid_size((int)w, (int)h))
        return tf_seterr(err, errlen, "%s: not a terrafarm render (size %" PRId64 "x%" PRId64 ")",
                         r->path, w, h);
    tf_exr_layout l = {(int)w, (int)h, storage == EXR_STORAGE_TILED, 0, 0, TF_PIXEL_FLOAT};
    if (l.tiled && check_tiles(r, &l, err, errlen))
        return -1;
    l.pixel = pixel_type_of(chl);
    if (comp != tf_exr_layout_compression(&l))
        return tf_seterr(err, errlen, "%s: not a terrafarm render (compression)", r->path);
    if (check_channels(r, chl, l.pixel, err, errlen))
        return -1;
    keep_layout(r, &l);
    return 0;
}

/* Returns 1 if path does not exist, 0 when open and checked, -1 with a message otherwise. */
int tf_exr_reader_open(tf_exr_reader *r, const char *path, char *err, size_t errlen)
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
    init.error_handler_fn = tf_exr_remember_error;
    init.flags = EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE;
    tf_exr_clear_error();
    exr_result_t rv = exr_start_read(&r->ctx, path, &init);
    if (rv != EXR_ERR_SUCCESS) {
        tf_exr_set_error(err, errlen, path, "not a readable OpenEXR file", rv);
        tf_exr_reader_close(r);
        return -1;
    }
    if (check_layout(r, err, errlen) != 0 ||
        copy_string_attr(r, TF_EXR_ATTR_HASH, r->meta.scene_hash, sizeof r->meta.scene_hash, err,
                         errlen) != 0 ||
        copy_string_attr(r, TF_EXR_ATTR_SCENE, r->meta.scene_name, sizeof r->meta.scene_name, err,
                         errlen) != 0 ||
        copy_string_attr(r, TF_EXR_ATTR_SETTINGS, r->meta.settings, sizeof r->meta.settings, err,
                         errlen) != 0) {
        tf_exr_reader_close(r);
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
static int locate_chunk(tf_exr_reader *r, const tf_chunk_ref *c, exr_chunk_info_t *cinfo)
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
static int decode_chunk(tf_exr_reader *r, const exr_chunk_info_t *cinfo, const tf_chunk_ref *c,
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


/* Verify chunks from the first, at most `limit` of them; returns the number of leading whole,
 * decodable chunks, or -1 if fn failed or memory ran out (message in err). */
int64_t tf_exr_walk_chunks_upto(tf_exr_reader *r, int64_t limit, tf_exr_visit_fn fn,
                                void *user, char *err, size_t errlen)
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

int64_t tf_exr_walk_chunks(tf_exr_reader *r, tf_exr_visit_fn fn, void *user, char *err,
                           size_t errlen)
{
    return tf_exr_walk_chunks_upto(r, INT64_MAX, fn, user, err, errlen);
}

typedef struct packed_walk {
    tf_exr_packed_fn fn;
    void *user;
    uint8_t *buf;
    size_t cap;
    char *err;
    size_t errlen;
} packed_walk;

/* Read a verified chunk's packed bytes and hand them on with its pixels. */
static int visit_packed(void *user, tf_exr_reader *r, const exr_chunk_info_t *cinfo,
                        const tf_chunk_ref *c, const tf_pixel *px)
{
    packed_walk *s = user;
    if (cinfo->packed_size > s->cap) {
        uint8_t *p = realloc(s->buf, (size_t)cinfo->packed_size);
        if (!p)
            return tf_seterr(s->err, s->errlen, "%s: out of memory", r->path);
        s->buf = p;
        s->cap = (size_t)cinfo->packed_size;
    }
    exr_result_t rv = exr_read_chunk(r->ctx, 0, cinfo, s->buf);
    if (rv != EXR_ERR_SUCCESS) {
        tf_exr_set_error(s->err, s->errlen, r->path, "cannot read a verified chunk", rv);
        return -1;
    }
    return s->fn(s->user, c, s->buf, (size_t)cinfo->packed_size, px);
}

int64_t tf_exr_walk_packed(tf_exr_reader *r, int64_t limit, tf_exr_packed_fn fn, void *user,
                           char *err, size_t errlen)
{
    packed_walk s = {fn, user, NULL, 0, err, errlen};
    int64_t good = tf_exr_walk_chunks_upto(r, limit, visit_packed, &s, err, errlen);
    free(s.buf);
    return good;
}

/* Was the file finished (offset table written by exr_finish)?  Asked of a second context
 * with chunk reconstruction disabled, so only a real offset table can answer yes.  With
 * whole_file set, the last chunk must also end exactly at the end of the file. */
static int offset_table_valid_ext(const char *path, const tf_exr_layout *l, int whole_file)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = tf_exr_remember_error;
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
    tf_exr_reader r;
    int rc = tf_exr_reader_open(&r, path, err, errlen);
    if (rc != 0)
        return rc;
    if (finished_and_whole(path, &r.layout)) {
        *meta = r.meta;
        *chunks_done = r.nchunks;
        *complete = 1;
        tf_exr_reader_close(&r);
        return 0;
    }
    int64_t good = tf_exr_walk_chunks(&r, NULL, NULL, err, errlen);
    if (good >= 0) {
        *meta = r.meta;
        *chunks_done = good;
        *complete = good == r.nchunks && offset_table_valid_ext(path, &r.layout, 0);
    }
    tf_exr_reader_close(&r);
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
