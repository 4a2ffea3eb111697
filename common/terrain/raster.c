/* raster.c: what the three height map decoders share (raster.h): the size limits every one
 * checks before allocating, freeing a raster, and the choice of decoder from a file's first
 * bytes.  The decoders and this file know nothing of scenes or terrain grids; heightmap_file.c
 * is the one caller, above them. */
#include "terrain/raster.h"

#include <errno.h>
#include <math.h>
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

/* A whole decimal number in [lo, hi] (lo excluded if open_lo), or -1 with the key named. */
static int parse_number(const char *key, const char *value, double lo, int open_lo, double hi,
                        const char *name, double *out, char *err, size_t errlen)
{
    char *end, shown[48];
    errno = 0;
    double v = strtod(value, &end);
    if (end == value || *end != '\0' || errno == ERANGE || !isfinite(v) || v > hi || v < lo ||
        (open_lo && v == lo))
        return tf_seterr(err, errlen, "%s: %s: '%s' is not a number in %s%g, %g]", name, key,
                         tf_printable(value, shown, sizeof shown), open_lo ? "(" : "[", lo, hi);
    *out = v;
    return 0;
}

static int parse_first_row(const char *value, const char *name, int *out, char *err,
                           size_t errlen)
{
    char shown[48];
    if (strcmp(value, "north") == 0 || strcmp(value, "south") == 0) {
        *out = value[0] == 'n' ? TF_RASTER_ROWS_NORTH_FIRST : TF_RASTER_ROWS_SOUTH_FIRST;
        return 0;
    }
    return tf_seterr(err, errlen, "%s: %s: '%s' is neither north nor south", name,
                     TF_RASTER_KEY_FIRST_ROW, tf_printable(value, shown, sizeof shown));
}

int tf_raster_meta_key(const char *key)
{
    return strcmp(key, TF_RASTER_KEY_FIRST_ROW) == 0 || strcmp(key, TF_RASTER_KEY_EXTENT) == 0 ||
           strcmp(key, TF_RASTER_KEY_VERTICAL_SCALE) == 0 ||
           strcmp(key, TF_RASTER_KEY_VERTICAL_OFFSET) == 0;
}

int tf_raster_meta_item(tf_raster *r, const char *key, const char *value, const char *name,
                        char *err, size_t errlen)
{
    tf_raster_meta *m = &r->meta;
    const double vmax = TF_RASTER_MAX_VERTICAL;
    if (strcmp(key, TF_RASTER_KEY_FIRST_ROW) == 0)
        return parse_first_row(value, name, &m->first_row, err, errlen);
    if (strcmp(key, TF_RASTER_KEY_EXTENT) == 0)
        return parse_number(key, value, 0, 1, TF_RASTER_MAX_EXTENT, name, &m->extent, err,
                            errlen);
    if (strcmp(key, TF_RASTER_KEY_VERTICAL_SCALE) == 0)
        return m->has_scale = 1, parse_number(key, value, -vmax, 0, vmax, name,
                                              &m->vertical_scale, err, errlen);
    if (strcmp(key, TF_RASTER_KEY_VERTICAL_OFFSET) == 0)
        return m->has_offset = 1, parse_number(key, value, -vmax, 0, vmax, name,
                                               &m->vertical_offset, err, errlen);
    return 0;
}
