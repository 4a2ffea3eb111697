/* exrpart.c: see exrpart.h. */
#include "image/exrpart.h"

#include <string.h>

#include "image/pixel.h"

static const tf_exr_channel FLOAT_CHANNELS[] = {
    {"A", offsetof(tf_pixel, a), EXR_PIXEL_FLOAT}, {"B", offsetof(tf_pixel, b), EXR_PIXEL_FLOAT},
    {"G", offsetof(tf_pixel, g), EXR_PIXEL_FLOAT}, {"R", offsetof(tf_pixel, r), EXR_PIXEL_FLOAT},
    {"Z", offsetof(tf_pixel, z), EXR_PIXEL_FLOAT}, {"spp", offsetof(tf_pixel, spp), EXR_PIXEL_FLOAT},
};

static const tf_exr_channel HALF_CHANNELS[] = {
    {"A", offsetof(tf_pixel, a), EXR_PIXEL_HALF}, {"B", offsetof(tf_pixel, b), EXR_PIXEL_HALF},
    {"G", offsetof(tf_pixel, g), EXR_PIXEL_HALF}, {"R", offsetof(tf_pixel, r), EXR_PIXEL_HALF},
    {"Z", offsetof(tf_pixel, z), EXR_PIXEL_FLOAT}, {"spp", offsetof(tf_pixel, spp), EXR_PIXEL_FLOAT},
};

const tf_exr_channel *tf_exr_render_channels(int pixel, int *n)
{
    *n = 6;
    return pixel == TF_PIXEL_HALF ? HALF_CHANNELS : FLOAT_CHANNELS;
}

const tf_exr_channel *tf_exr_find_channel(const tf_exr_channel *map, int n, const char *name)
{
    for (int i = 0; i < n; i++)
        if (strcmp(map[i].name, name) == 0)
            return &map[i];
    return NULL;
}

exr_compression_t tf_exr_layout_compression(const tf_exr_layout *l)
{
    return l->tiled ? EXR_COMPRESSION_ZIP : EXR_COMPRESSION_ZIPS;
}

exr_result_t tf_exr_define_part(exr_context_t ctx, const tf_exr_layout *l,
                                const tf_exr_channel *channels, int nchannels)
{
    int part = 0;
    exr_result_t rv = exr_add_part(ctx, NULL, l->tiled ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE,
                                   &part);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr_simple(ctx, part, l->width, l->height,
                                                 tf_exr_layout_compression(l));
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_zip_compression_level(ctx, part, TF_EXR_ZIP_LEVEL);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_lineorder(ctx, part, EXR_LINEORDER_INCREASING_Y);
    if (rv == EXR_ERR_SUCCESS && l->tiled)
        rv = exr_set_tile_descriptor(ctx, part, (uint32_t)l->tile_w, (uint32_t)l->tile_h,
                                     EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN);
    for (int i = 0; i < nchannels && rv == EXR_ERR_SUCCESS; i++)
        rv = exr_add_channel(ctx, part, channels[i].name, channels[i].type,
                             EXR_PERCEPTUALLY_LINEAR, 1, 1);
    return rv;
}

/* Point each channel of enc at its float in the caller's pixels. */
static exr_result_t point_channels(exr_encode_pipeline_t *enc, const tf_exr_channel *channels,
                                   int nchannels, const uint8_t *origin, size_t pixel_bytes,
                                   size_t line_bytes)
{
    for (int i = 0; i < enc->channel_count; i++) {
        exr_coding_channel_info_t *ch = &enc->channels[i];
        const tf_exr_channel *m = tf_exr_find_channel(channels, nchannels, ch->channel_name);
        if (!m) /* cannot happen: the part declares exactly these channels */
            return EXR_ERR_INVALID_ARGUMENT;
        ch->encode_from_ptr = origin + m->offset;
        ch->user_pixel_stride = (int32_t)pixel_bytes;
        ch->user_line_stride = (int32_t)line_bytes;
        ch->user_bytes_per_element = 4;
        ch->user_data_type = EXR_PIXEL_FLOAT;
    }
    return EXR_ERR_SUCCESS;
}

exr_result_t tf_exr_begin_chunk(exr_context_t ctx, const tf_exr_layout *l,
                                const tf_chunk_ref *c, const tf_exr_channel *channels,
                                int nchannels, const uint8_t *origin, size_t pixel_bytes,
                                size_t line_bytes, exr_encode_pipeline_t *enc)
{
    exr_chunk_info_t cinfo;
    exr_result_t rv = l->tiled ? exr_write_tile_chunk_info(ctx, 0, c->cx, c->cy, 0, 0, &cinfo)
                               : exr_write_scanline_chunk_info(ctx, 0, c->cy, &cinfo);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_initialize(ctx, 0, &cinfo, enc);
    if (rv == EXR_ERR_SUCCESS)
        rv = point_channels(enc, channels, nchannels, origin, pixel_bytes, line_bytes);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_choose_default_routines(ctx, 0, enc);
    return rv;
}
