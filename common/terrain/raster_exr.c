/* raster_exr.c: an OpenEXR height map decoded from memory with OpenEXRCore.  See raster.h.
 *
 * The channel read is "Y" (what terrafarm heightfield writes), else "Z", else "R", else the
 * only channel; FLOAT and HALF samples are read as float (FLOAT bit for bit), UINT ones
 * converted.  NaN and infinite samples are nodata.  Scanline and tiled files both decode,
 * chunk by chunk; the data window's size is checked before anything is allocated.  String
 * attributes may say what the samples are (raster.h's TF_RASTER_KEY_*: terrafarm heightfield
 * records them). */
#include "terrain/raster.h"

#include <openexr.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

typedef struct exr_source {
    const uint8_t *data;
    size_t len;
} exr_source;

static int64_t read_at(exr_const_context_t ctx, void *user, void *buffer, uint64_t sz,
                       uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctx;
    (void)error_cb;
    const exr_source *src = user;
    if (offset >= src->len)
        return 0;
    uint64_t n = src->len - offset < sz ? src->len - offset : sz;
    memcpy(buffer, src->data + offset, (size_t)n);
    return (int64_t)n;
}

static int64_t query_size(exr_const_context_t ctx, void *user)
{
    (void)ctx;
    return (int64_t)((const exr_source *)user)->len;
}

static void quiet_errors(exr_const_context_t ctx, exr_result_t code, const char *msg)
{
    (void)ctx;
    (void)code;
    (void)msg; /* the one-line message is ours; OpenEXRCore would print to stderr */
}

/* Index of the channel to read, or -1. */
static int pick_channel(const exr_attr_chlist_t *ch)
{
    static const char *const preferred[] = {"Y", "Z", "R"};
    for (int p = 0; p < 3; p++)
        for (int c = 0; c < ch->num_channels; c++)
            if (strcmp(ch->entries[c].name.str, preferred[p]) == 0)
                return c;
    return ch->num_channels == 1 ? 0 : -1;
}

/* Decode one chunk's rows of the chosen channel into the raster. */
static exr_result_t decode_chunk(exr_context_t ctx, const exr_chunk_info_t *ci,
                                 const char *channel, const exr_attr_box2i_t *dw, tf_raster *r)
{
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    exr_result_t rv = exr_decoding_initialize(ctx, 0, ci, &dec);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    int x0 = ci->start_x - dw->min.x, y0 = ci->start_y - dw->min.y;
    if (x0 < 0 || y0 < 0 || x0 + ci->width > r->width || y0 + ci->height > r->height) {
        exr_decoding_destroy(ctx, &dec);
        return EXR_ERR_CORRUPT_CHUNK;
    }
    for (int c = 0; c < dec.channel_count; c++) {
        exr_coding_channel_info_t *chi = &dec.channels[c];
        if (strcmp(chi->channel_name, channel) == 0) {
            chi->decode_to_ptr = (uint8_t *)(r->v + (size_t)y0 * (size_t)r->width + x0);
            chi->user_pixel_stride = (int32_t)sizeof(float);
            chi->user_line_stride = (int32_t)(sizeof(float) * (size_t)r->width);
            chi->user_bytes_per_element = 4;
            chi->user_data_type = EXR_PIXEL_FLOAT;
        } else {
            chi->decode_to_ptr = NULL;
        }
    }
    rv = exr_decoding_choose_default_routines(ctx, 0, &dec);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_decoding_run(ctx, 0, &dec);
    exr_decoding_destroy(ctx, &dec);
    return rv;
}

static exr_result_t decode_all(exr_context_t ctx, exr_storage_t storage, const char *channel,
                               const exr_attr_box2i_t *dw, tf_raster *r)
{
    exr_result_t rv;
    if (storage == EXR_STORAGE_SCANLINE) {
        int32_t lines;
        if ((rv = exr_get_scanlines_per_chunk(ctx, 0, &lines)) != EXR_ERR_SUCCESS)
            return rv;
        if (lines < 1)
            return EXR_ERR_CORRUPT_CHUNK;
        for (int64_t y = dw->min.y; y <= dw->max.y; y += lines) {
            exr_chunk_info_t ci;
            if ((rv = exr_read_scanline_chunk_info(ctx, 0, (int)y, &ci)) != EXR_ERR_SUCCESS ||
                (rv = decode_chunk(ctx, &ci, channel, dw, r)) != EXR_ERR_SUCCESS)
                return rv;
        }
        return EXR_ERR_SUCCESS;
    }
    if (storage != EXR_STORAGE_TILED)
        return EXR_ERR_FEATURE_NOT_IMPLEMENTED; /* deep data is not a height map */
    uint32_t tw, th;
    exr_tile_level_mode_t lm;
    exr_tile_round_mode_t rm;
    if ((rv = exr_get_tile_descriptor(ctx, 0, &tw, &th, &lm, &rm)) != EXR_ERR_SUCCESS)
        return rv;
    if (tw < 1 || th < 1)
        return EXR_ERR_CORRUPT_CHUNK;
    int tiles_x = (int)((r->width + (int64_t)tw - 1) / tw);
    int tiles_y = (int)((r->height + (int64_t)th - 1) / th);
    for (int ty = 0; ty < tiles_y; ty++)
        for (int tx = 0; tx < tiles_x; tx++) {
            exr_chunk_info_t ci;
            if ((rv = exr_read_tile_chunk_info(ctx, 0, tx, ty, 0, 0, &ci)) != EXR_ERR_SUCCESS ||
                (rv = decode_chunk(ctx, &ci, channel, dw, r)) != EXR_ERR_SUCCESS)
                return rv;
        }
    return EXR_ERR_SUCCESS;
}

/* The header's terrafarm.* attributes into r->meta: each must be a string. */
static int read_attributes(exr_context_t ctx, const char *name, tf_raster *r, char *err,
                           size_t errlen)
{
    int32_t n = 0;
    if (exr_get_attribute_count(ctx, 0, &n) != EXR_ERR_SUCCESS)
        return 0;
    for (int32_t i = 0; i < n; i++) {
        const exr_attribute_t *a = NULL;
        if (exr_get_attribute_by_index(ctx, 0, EXR_ATTR_LIST_FILE_ORDER, i, &a) !=
                EXR_ERR_SUCCESS || !a || !tf_raster_meta_key(a->name))
            continue;
        if (a->type != EXR_ATTR_STRING || !a->string)
            return tf_seterr(err, errlen, "%s: %s: not a string attribute", name, a->name);
        if (tf_raster_meta_item(r, a->name, a->string->str ? a->string->str : "", name, err,
                                errlen) != 0)
            return -1;
    }
    return 0;
}

/* What the header says of the pixels: the data window, the storage and the channel read. */
typedef struct exr_shape {
    exr_attr_box2i_t dw;
    exr_storage_t storage;
    const char *channel;
} exr_shape;

/* The part's data window, storage and height channel, its terrafarm.* attributes into r. */
static int read_header(exr_context_t ctx, const char *name, tf_raster *r, exr_shape *sh,
                       char *err, size_t errlen)
{
    const exr_attr_chlist_t *chlist = NULL;
    if (exr_get_data_window(ctx, 0, &sh->dw) != EXR_ERR_SUCCESS ||
        exr_get_channels(ctx, 0, &chlist) != EXR_ERR_SUCCESS || !chlist ||
        exr_get_storage(ctx, 0, &sh->storage) != EXR_ERR_SUCCESS)
        return tf_seterr(err, errlen, "%s: OpenEXR header lacks a data window or channels",
                         name);
    if (read_attributes(ctx, name, r, err, errlen) != 0)
        return -1;
    int c = pick_channel(chlist);
    if (c < 0)
        return tf_seterr(err, errlen,
                         "%s: OpenEXR file has %d channels and none is named Y, Z or R", name,
                         chlist->num_channels);
    sh->channel = chlist->entries[c].name.str;
    return 0;
}

/* r sized to the data window (within the raster limits), every sample nodata until a chunk
 * fills it. */
static int size_raster(const exr_attr_box2i_t *dw, const char *name, tf_raster *r, char *err,
                       size_t errlen)
{
    if (tf_raster_check_size((long long)dw->max.x - dw->min.x + 1,
                             (long long)dw->max.y - dw->min.y + 1, name, err, errlen) != 0)
        return -1;
    r->width = dw->max.x - dw->min.x + 1;
    r->height = dw->max.y - dw->min.y + 1;
    size_t count = (size_t)r->width * (size_t)r->height;
    r->v = malloc(count * sizeof *r->v);
    if (!r->v)
        return tf_seterr(err, errlen, "%s: out of memory for a %dx%d height map", name,
                         r->width, r->height);
    for (size_t i = 0; i < count; i++)
        r->v[i] = NAN; /* a chunk the file lacks stays nodata */
    return 0;
}

/* Every chunk of the part decoded into r; what is not finite becomes nodata. */
static int read_pixels(exr_context_t ctx, const exr_shape *sh, const char *name, tf_raster *r,
                       char *err, size_t errlen)
{
    exr_result_t rv = decode_all(ctx, sh->storage, sh->channel, &sh->dw, r);
    if (rv != EXR_ERR_SUCCESS)
        return tf_seterr(err, errlen,
                         "%s: OpenEXR pixels do not decode (%s): corrupt or truncated", name,
                         exr_get_default_error_message(rv));
    size_t count = (size_t)r->width * (size_t)r->height;
    for (size_t i = 0; i < count; i++)
        if (!isfinite(r->v[i]))
            r->v[i] = NAN;
    return 0;
}

int tf_raster_read_exr(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                       char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    exr_source src = {data, len};
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.user_data = &src;
    init.read_fn = read_at;
    init.size_fn = query_size;
    init.error_handler_fn = quiet_errors;
    init.flags = EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE;
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_read(&ctx, name, &init);
    if (rv != EXR_ERR_SUCCESS) {
        tf_seterr(err, errlen, "%s: not a readable OpenEXR file: %s", name,
                  exr_get_default_error_message(rv));
        exr_finish(&ctx);
        return -1;
    }
    exr_shape sh;
    int rc = -1;
    if (read_header(ctx, name, r, &sh, err, errlen) == 0 &&
        size_raster(&sh.dw, name, r, err, errlen) == 0 &&
        read_pixels(ctx, &sh, name, r, err, errlen) == 0)
        rc = 0;
    if (rc != 0) {
        free(r->v);
        r->v = NULL;
    }
    exr_finish(&ctx);
    return rc;
}
