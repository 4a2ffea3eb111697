/* heightmap_file.c: generator = file (see heightmap_file.h): from a decoded raster (raster.h)
 * to the terrain grid, in this order:
 *
 *   1. decode: PNG by its signature, OpenEXR by its magic number, anything else through GDAL;
 *   2. crop to crop_x, crop_y, crop_width, crop_height (width/height 0: to the raster's edge);
 *   3. world heights z = value * vertical_scale + vertical_offset (in double, stored as float,
 *      so a float raster with scale 1 and offset 0 keeps its bits).  Here and in 5 and 6, a
 *      key the scene leaves at its default (scale 1, offset 0, first_row auto, extent 0) takes
 *      what the file says of itself (raster.h's tf_raster_meta, which terrafarm heightfield
 *      writes), so its exports re-import with only `path`;
 *   4. nodata: `fill` gives each nodata sample the mean of its already-known 4-neighbours, in
 *      breadth-first layers growing from the data (deterministic, linear time); `sea` puts it
 *      one world unit below materials.sea_level, under the water.  A window with no data at
 *      all is an error;
 *   5. orientation: terrain row 0 is the south edge (world y = 0).  first_row = north (the
 *      map convention, and `auto` without the file's word or georeferencing) flips the rows;
 *      so does `auto` with a north-up geotransform (negative pixel height); first_row = south
 *      (what terrafarm heightfield writes in PNG and EXR, and records there) keeps them.  An
 *      east-to-west geotransform flips the columns;
 *   6. horizontal scale: a georeferenced raster's pixel size in metres: projected CRSs times
 *      their linear unit, geographic (degree) CRSs by the sphere of the ellipsoid's semi-major
 *      axis a: east = |dlon| * pi/180 * a * cos(latitude of the window's centre), north =
 *      |dlat| * pi/180 * a.  Without georeferencing a pixel is the file's recorded extent over
 *      its width - 1, else one world unit.  The terrain is
 *      square, so the window must cover a square (within 1%) in metres; `extent`, if set,
 *      overrides the side's size;
 *   7. resample onto n x n samples with a separable tent (triangle) filter of radius
 *      max(1, source pixels per sample): linear interpolation when enlarging, a weighted area
 *      average when shrinking (no aliasing from point sampling).  Where the grid lands on
 *      source pixels exactly (a 2^k+1 raster at size_exp k) the samples are the source's
 *      bits. */
#include "terrain/heightmap_file.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/raster.h"
#include "log.h"

#define SQUARE_TOLERANCE 0.01 /* relative difference of the window's sides in metres */

/* The crop window, checked against the raster. */
static int crop_window(const tf_terrain *t, const tf_raster *r, const char *name, int *x,
                       int *y, int *w, int *h, char *err, size_t errlen)
{
    *x = t->crop_x;
    *y = t->crop_y;
    *w = t->crop_width ? t->crop_width : r->width - t->crop_x;
    *h = t->crop_height ? t->crop_height : r->height - t->crop_y;
    if (*x >= r->width || *y >= r->height || *w < 1 || *h < 1 || *x + *w > r->width ||
        *y + *h > r->height)
        return tf_seterr(err, errlen, "%s: crop window x %d, y %d, %dx%d lies outside the %dx%d "
                         "raster", name, t->crop_x, t->crop_y, t->crop_width, t->crop_height,
                         r->width, r->height);
    if (*w < 2 || *h < 2)
        return tf_seterr(err, errlen, "%s: %dx%d pixels is too small for a terrain (at least "
                         "2x2)", name, *w, *h);
    return 0;
}

/* Step 4, fill: breadth-first layers from the known samples.  Layer L is the unknown samples
 * next to a sample of layer L-1 (layer 0: the data); each gets the mean of its neighbours
 * known before its layer, and only then is the layer stored, so the result does not depend
 * on the order within a layer.  Every sample joins one layer once: linear time, whatever the
 * shape of the holes.  -1 on out of memory. */
enum { UNKNOWN = 0, QUEUED = 1, KNOWN = 2 };

static void queue_unknown_neighbours(uint32_t i, int w, int h, uint8_t *state, uint32_t *next,
                                     size_t *nn)
{
    int x = (int)(i % (uint32_t)w), y = (int)(i / (uint32_t)w);
    uint32_t nb[4];
    int m = 0;
    if (x > 0) nb[m++] = i - 1;
    if (x < w - 1) nb[m++] = i + 1;
    if (y > 0) nb[m++] = i - (uint32_t)w;
    if (y < h - 1) nb[m++] = i + (uint32_t)w;
    for (int k = 0; k < m; k++)
        if (state[nb[k]] == UNKNOWN) {
            state[nb[k]] = QUEUED;
            next[(*nn)++] = nb[k];
        }
}

static int fill_nodata(float *z, int w, int h)
{
    size_t count = (size_t)w * (size_t)h;
    uint32_t *layer = malloc(count * sizeof *layer), *next = malloc(count * sizeof *next);
    float *layer_v = malloc(count * sizeof *layer_v);
    uint8_t *state = malloc(count);
    int rc = -1;
    if (!layer || !next || !layer_v || !state)
        goto out;
    size_t nl = 0;
    for (size_t i = 0; i < count; i++)
        state[i] = isnan(z[i]) ? UNKNOWN : KNOWN;
    for (size_t i = 0; i < count; i++)
        if (state[i] == KNOWN)
            queue_unknown_neighbours((uint32_t)i, w, h, state, layer, &nl);
    while (nl > 0) {
        for (size_t k = 0; k < nl; k++) {
            uint32_t i = layer[k];
            int x = (int)(i % (uint32_t)w), y = (int)(i / (uint32_t)w);
            double sum = 0;
            int m = 0;
            if (x > 0 && state[i - 1] == KNOWN) sum += z[i - 1], m++;
            if (x < w - 1 && state[i + 1] == KNOWN) sum += z[i + 1], m++;
            if (y > 0 && state[i - (uint32_t)w] == KNOWN) sum += z[i - (uint32_t)w], m++;
            if (y < h - 1 && state[i + (uint32_t)w] == KNOWN) sum += z[i + (uint32_t)w], m++;
            layer_v[k] = (float)(sum / m); /* m >= 1: queued next to a known sample */
        }
        for (size_t k = 0; k < nl; k++) {
            z[layer[k]] = layer_v[k];
            state[layer[k]] = KNOWN;
        }
        size_t nn = 0;
        for (size_t k = 0; k < nl; k++)
            queue_unknown_neighbours(layer[k], w, h, state, next, &nn);
        uint32_t *t = layer;
        layer = next;
        next = t;
        nl = nn;
    }
    rc = 0;
out:
    free(layer);
    free(next);
    free(layer_v);
    free(state);
    return rc;
}

/* Step 3's scale and offset: each the scene's key where it is given (differs from its default,
 * 1 and 0), else what the file says, else the default. */
static void vertical(const tf_terrain *t, const tf_raster_meta *m, double *scale,
                     double *offset)
{
    *scale = t->vertical_scale != 1.0 || !m->has_scale ? t->vertical_scale : m->vertical_scale;
    *offset = t->vertical_offset != 0.0 || !m->has_offset ? t->vertical_offset
                                                          : m->vertical_offset;
}

/* Step 5: 1 if the raster's first row is the south edge: the scene's first_row, else the
 * file's own word, else a south-up geotransform. */
static int south_first(const tf_terrain *t, const tf_raster *r)
{
    if (t->first_row != TF_FIRST_ROW_AUTO)
        return t->first_row == TF_FIRST_ROW_SOUTH;
    if (r->meta.first_row != TF_RASTER_ROWS_UNSAID)
        return r->meta.first_row == TF_RASTER_ROWS_SOUTH_FIRST;
    return r->has_georef && r->gt[5] > 0;
}

/* Step 6: metres per pixel east and north. */
static int pixel_size(const tf_raster *r, int wy, int wh, const char *name, double *dx,
                      double *dy, char *err, size_t errlen)
{
    *dx = *dy = 1.0;
    if (!r->has_georef && r->meta.extent > 0)
        *dx = *dy = r->meta.extent / (r->width - 1);
    if (!r->has_georef)
        return 0;
    if (r->gt[2] != 0 || r->gt[4] != 0)
        return tf_seterr(err, errlen, "%s: rotated or sheared georeferencing; warp it north-up "
                         "first (gdalwarp)", name);
    if (!(r->gt[1] != 0) || !(r->gt[5] != 0) || !isfinite(r->gt[1]) || !isfinite(r->gt[5]))
        return tf_seterr(err, errlen, "%s: georeferencing has a zero or non-finite pixel size",
                         name);
    if (r->geographic) {
        double lat = r->gt[3] + ((double)wy + wh / 2.0) * r->gt[5];
        if (!(fabs(lat) < 89.9))
            return tf_seterr(err, errlen, "%s: window centre at latitude %.3f: too near a pole "
                             "for a geographic raster; reproject it first (gdalwarp)", name, lat);
        double rad = M_PI / 180.0 * r->semi_major;
        *dx = fabs(r->gt[1]) * rad * cos(lat * M_PI / 180.0);
        *dy = fabs(r->gt[5]) * rad;
    } else {
        *dx = fabs(r->gt[1]) * r->unit_m;
        *dy = fabs(r->gt[5]) * r->unit_m;
    }
    return 0;
}

/* Step 7, one line: src has len samples at stride ss; dst gets n at stride ds. */
static void resample_line(const double *src, int len, size_t ss, double *dst, int n, size_t ds)
{
    double step = (double)(len - 1) / (double)(n - 1);
    double radius = step > 1.0 ? step : 1.0;
    for (int i = 0; i < n; i++) {
        double p = (double)i * (double)(len - 1) / (double)(n - 1);
        int k0 = (int)ceil(p - radius), k1 = (int)floor(p + radius);
        if (k0 < 0) k0 = 0;
        if (k1 > len - 1) k1 = len - 1;
        double sum = 0, wsum = 0;
        for (int k = k0; k <= k1; k++) {
            double w = 1.0 - fabs((double)k - p) / radius;
            if (w <= 0)
                continue;
            sum += w * src[(size_t)k * ss];
            wsum += w;
        }
        dst[(size_t)i * ds] = sum / wsum;
    }
}

/* Steps 2 and 3: the w x h window at (wx, wy) as world heights (NAN: nodata), still in the
 * file's row order; *valid gets how many are data.  NULL with a message in err. */
static float *window_heights(const tf_terrain *t, const tf_raster *r, const char *name, int wx,
                             int wy, int w, int h, size_t *valid, char *err, size_t errlen)
{
    float *win = malloc((size_t)w * (size_t)h * sizeof *win);
    if (!win)
        return tf_seterr(err, errlen, "%s: out of memory", name), NULL;
    double vscale, voffset;
    vertical(t, &r->meta, &vscale, &voffset);
    *valid = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float v = r->v[(size_t)(wy + y) * (size_t)r->width + (size_t)(wx + x)];
            float zz = isnan(v) ? NAN : (float)((double)v * vscale + voffset);
            if (!isnan(zz) && !isfinite(zz)) {
                free(win);
                return tf_seterr(err, errlen, "%s: value %g at pixel (%d, %d) times "
                                 "vertical_scale is not a finite float", name, (double)v,
                                 wx + x, wy + y), NULL;
            }
            *valid += !isnan(zz);
            win[(size_t)y * (size_t)w + (size_t)x] = zz;
        }
    return win;
}

/* Step 4: the window's nodata samples given heights (valid of its w x h are data; none is an
 * error, its message naming the crop window if there is one).  0 or -1. */
static int fill_window(const tf_terrain *t, const char *name, float *win, int w, int h,
                       int cropped, size_t valid, char *err, size_t errlen)
{
    size_t count = (size_t)w * (size_t)h;
    if (valid == 0)
        return tf_seterr(err, errlen, "%s: no data: all %dx%d samples%s are nodata", name, w, h,
                         cropped ? " of the crop window" : "");
    if (valid == count)
        return 0;
    if (t->nodata == TF_NODATA_SEA) {
        float sea = (float)(t->file_sea_level - 1.0);
        for (size_t i = 0; i < count; i++)
            if (isnan(win[i]))
                win[i] = sea;
        return 0;
    }
    if (fill_nodata(win, w, h) != 0)
        return tf_seterr(err, errlen, "%s: out of memory filling nodata", name);
    return 0;
}

/* Steps 5 and 6's size: the w x h window at row wy must cover a square (within
 * SQUARE_TOLERANCE); *side gets its side (in metres, or pixels without georeferencing). */
static int square_side(const tf_raster *r, const char *name, int wy, int w, int h,
                       double *side, char *err, size_t errlen)
{
    double dx, dy;
    if (pixel_size(r, wy, h, name, &dx, &dy, err, errlen) != 0)
        return -1;
    double side_x = (w - 1) * dx, side_y = (h - 1) * dy;
    if (fabs(side_x - side_y) > SQUARE_TOLERANCE * fmax(side_x, side_y)) {
        int wide = side_x > side_y;
        return tf_seterr(err, errlen, "%s: the window covers %.6g x %.6g %s (%dx%d pixels), not "
                         "a square as the terrain is: crop it, e.g. %s = %ld", name, side_x,
                         side_y, r->has_georef ? "metres" : "pixels", w, h,
                         wide ? "crop_width" : "crop_height",
                         wide ? lround(side_y / dx) + 1 : lround(side_x / dy) + 1);
    }
    *side = side_x;
    return 0;
}

/* Steps 5 and 7: the w x h window (file row order) turned south first and west first, then
 * resampled onto n x n samples: rows to n columns, then columns to n rows.  NULL when out of
 * memory. */
static float *resample_window(const float *win, int w, int h, int south, int flip_x, int n)
{
    double *z = malloc((size_t)w * (size_t)h * sizeof *z);
    double *tmp = malloc((size_t)h * (size_t)n * sizeof *tmp);
    double *col = malloc((size_t)n * sizeof *col);
    float *out = malloc((size_t)n * (size_t)n * sizeof *out);
    if (z && tmp && col && out) {
        for (int y = 0; y < h; y++) {
            int sy = south ? y : h - 1 - y; /* z row y is world row y (south first) */
            for (int x = 0; x < w; x++)
                z[(size_t)y * (size_t)w + (size_t)x] =
                    win[(size_t)sy * (size_t)w + (size_t)(flip_x ? w - 1 - x : x)];
        }
        for (int y = 0; y < h; y++)
            resample_line(z + (size_t)y * (size_t)w, w, 1, tmp + (size_t)y * (size_t)n, n, 1);
        for (int i = 0; i < n; i++) {
            resample_line(tmp + i, h, (size_t)n, col, n, 1);
            for (int j = 0; j < n; j++)
                out[(size_t)j * (size_t)n + (size_t)i] = (float)col[j];
        }
    } else {
        free(out);
        out = NULL;
    }
    free(z);
    free(tmp);
    free(col);
    return out;
}

float *tf_heightmap_heights(const tf_terrain *t, double *extent, char *err, size_t errlen)
{
    const char *name = t->file_name ? t->file_name : t->file_path;
    if (!t->file_bytes)
        return tf_seterr(err, errlen, "%s: height map not loaded", name), NULL;
    tf_raster r;
    if (tf_raster_decode(t->file_bytes, t->file_len, name, &r, err, errlen) != 0)
        return NULL;
    float *win = NULL, *out = NULL;
    int wx, wy, w, h;
    size_t valid = 0;
    double side = 0;
    if (crop_window(t, &r, name, &wx, &wy, &w, &h, err, errlen) != 0 ||
        !(win = window_heights(t, &r, name, wx, wy, w, h, &valid, err, errlen)) ||
        fill_window(t, name, win, w, h, wx || wy || w != r.width || h != r.height, valid, err,
                    errlen) != 0 ||
        square_side(&r, name, wy, w, h, &side, err, errlen) != 0)
        goto out;
    const int n = (1 << t->size_exp) + 1;
    out = resample_window(win, w, h, south_first(t, &r), r.has_georef && r.gt[1] < 0, n);
    if (!out) {
        tf_seterr(err, errlen, "%s: out of memory resampling to %dx%d", name, n, n);
        goto out;
    }
    *extent = t->extent > 0 ? t->extent : side;
out:
    free(win);
    tf_raster_free(&r);
    return out;
}
