/* raster.c: what the three height map decoders share (raster.h): the size limits every one
 * checks before allocating, freeing a raster, and the choice of decoder from a file's first
 * bytes.  The decoders and this file know nothing of scenes or terrain grids; heightmap_file.c
 * is the one caller, above them. */
#include "terrain/raster.h"

#include <stdlib.h>
#include <string.h>

#include "log.h"

void tf_raster_free(tf_raster *r)
{
    free(r->v);
    r->v = NULL;
}

int tf_raster_check_size(long long width, long long height, const char *name, char *err,
                         size_t errlen)
{
    if (width < 1 || height < 1)
        return tf_seterr(err, errlen, "%s: empty raster (%lldx%lld pixels)", name, width,
                         height);
    if (width > TF_RASTER_MAX_SIDE || height > TF_RASTER_MAX_SIDE ||
        (unsigned long long)width * (unsigned long long)height > TF_RASTER_MAX_PIXELS)
        return tf_seterr(err, errlen, "%s: too large: %lldx%lld pixels (at most %d on a side and "
                         "%zu in all; crop or shrink it with gdal_translate first)", name, width,
                         height, TF_RASTER_MAX_SIDE, TF_RASTER_MAX_PIXELS);
    return 0;
}

int tf_raster_decode(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                     char *err, size_t errlen)
{
    static const uint8_t png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    static const uint8_t exr_magic[4] = {0x76, 0x2f, 0x31, 0x01};
    memset(r, 0, sizeof *r);
    if (len == 0)
        return tf_seterr(err, errlen, "%s: empty file", name);
    if (len >= 8 && memcmp(data, png_sig, 8) == 0)
        return tf_raster_read_png(data, len, name, r, err, errlen);
    if (len >= 4 && memcmp(data, exr_magic, 4) == 0)
        return tf_raster_read_exr(data, len, name, r, err, errlen);
    return tf_raster_read_gdal(data, len, name, r, err, errlen);
}

