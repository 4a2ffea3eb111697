/* raster.h: a height map raster as decoded from a file's bytes: a plain struct of values and
 * what the file says about them, before anything makes it a terrain grid (that is the
 * caller's business; the decoders know nothing of scenes or terrains).
 *
 * Three decoders, chosen by tf_raster_decode (raster.c) from the first bytes: 16-bit (or
 * 8-bit) grayscale PNG with libpng (raster_png.c), OpenEXR with OpenEXRCore (raster_exr.c),
 * and everything else -- GeoTIFF above all -- through GDAL (raster_gdal.c), which also reads
 * the georeferencing.
 * Every decoder works on bytes in memory, never on a path, so a networked worker that received
 * the bytes from the coordinator decodes exactly what the coordinator decoded.
 *
 * Hostile input: every decoder checks the declared size against TF_RASTER_MAX_SIDE and
 * TF_RASTER_MAX_PIXELS before allocating, and reports one line "NAME: what is wrong". */
#ifndef TF_RASTER_H
#define TF_RASTER_H

#include <stddef.h>
#include <stdint.h>

#define TF_RASTER_MAX_SIDE 65536
#define TF_RASTER_MAX_PIXELS ((size_t)1 << 27) /* 512 MiB of floats */

/* What a file may say about its own samples (terrafarm heightfield records it: EXR string
 * attributes, PNG text chunks, GDAL metadata items), under these names: */
#define TF_RASTER_KEY_FIRST_ROW "terrafarm.first_row"             /* "north" or "south" */
#define TF_RASTER_KEY_EXTENT "terrafarm.extent"                   /* first to last column */
#define TF_RASTER_KEY_VERTICAL_SCALE "terrafarm.vertical_scale"   /* height = value * scale */
#define TF_RASTER_KEY_VERTICAL_OFFSET "terrafarm.vertical_offset" /*          + offset */
#define TF_RASTER_MAX_EXTENT 1e9 /* the scene's own limits on extent and the vertical keys */
#define TF_RASTER_MAX_VERTICAL 1e9

enum tf_raster_rows {
    TF_RASTER_ROWS_UNSAID,
    TF_RASTER_ROWS_NORTH_FIRST,
    TF_RASTER_ROWS_SOUTH_FIRST,
};

typedef struct tf_raster_meta {
    int first_row;         /* enum tf_raster_rows */
    double extent;         /* world distance from the first column to the last; 0: unsaid */
    int has_scale, has_offset;
    double vertical_scale, vertical_offset;
} tf_raster_meta;

typedef struct tf_raster {
    int width, height;
    float *v;          /* width * height values, row-major, first row first; NaN = nodata */
    /* georeferencing (GDAL only): pixel (c, r)'s corner is at
     * (gt[0] + c * gt[1] + r * gt[2], gt[3] + c * gt[4] + r * gt[5]) */
    int has_georef;
    double gt[6];
    int geographic;    /* coordinates are degrees of longitude and latitude */
    double semi_major; /* geographic: the ellipsoid's semi-major axis in metres */
    double unit_m;     /* projected: metres per coordinate unit (1 for metres, 0.3048 feet) */
    tf_raster_meta meta; /* what the file says of itself (all decoders) */
} tf_raster;

/* The decoder the first bytes call for (PNG signature, OpenEXR magic number, else GDAL). */
int tf_raster_decode(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                     char *err, size_t errlen);
/* Each returns 0 and fills r (r->v malloc'd), or -1 with one line in err naming `name`. */
int tf_raster_read_png(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                       char *err, size_t errlen);
int tf_raster_read_exr(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                       char *err, size_t errlen);
int tf_raster_read_gdal(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                        char *err, size_t errlen);
void tf_raster_free(tf_raster *r);

/* 1 if key is one of the TF_RASTER_KEY_* names, else 0. */
int tf_raster_meta_key(const char *key);
/* A decoder's text item key = value: a TF_RASTER_KEY_* one is parsed into r->meta, any other
 * ignored.  0, or -1 with "NAME: KEY: what is wrong" in err (a malformed or out-of-range
 * value). */
int tf_raster_meta_item(tf_raster *r, const char *key, const char *value, const char *name,
                        char *err, size_t errlen);

/* 0 if width x height is within the limits, else -1 with "NAME: ... too large" in err. */
int tf_raster_check_size(long long width, long long height, const char *name, char *err,
                         size_t errlen);

#endif
