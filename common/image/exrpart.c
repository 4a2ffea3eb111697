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
