/* raster_png.c: a grayscale PNG height map (8 or 16 bits per sample; terrafarm heightfield
 * writes 16-bit ones) decoded from memory with libpng.  See raster.h.
 *
 * The PNG's codes are the raster's values (0..65535 for 16 bits); the scene's vertical_scale
 * and vertical_offset turn them into heights.  A grayscale+alpha PNG's transparent samples
 * (alpha 0) are nodata.  Text chunks may say what the samples are (raster.h's
 * TF_RASTER_KEY_*: terrafarm heightfield records them).  Colour and palette images are
 * refused: a height map is one channel.
 * libpng reports errors by longjmp: every allocation that can outlive it is made before
 * setjmp or freed after it. */
#include "terrain/raster.h"

#include <png.h>
#include <math.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

typedef struct png_source {
    const uint8_t *data;
    size_t len, pos;
    char message[160]; /* libpng's own error text */
} png_source;

static void read_bytes(png_structp png, png_bytep out, size_t n)
{
    png_source *src = png_get_io_ptr(png);
    if (n > src->len - src->pos) {
        snprintf(src->message, sizeof src->message, "truncated (file ends inside the image)");
        png_longjmp(png, 1);
    }
    memcpy(out, src->data + src->pos, n);
    src->pos += n;
}

static void on_error(png_structp png, png_const_charp msg)
{
    png_source *src = png_get_error_ptr(png);
    if (!src->message[0])
        snprintf(src->message, sizeof src->message, "%s", msg);
    png_longjmp(png, 1);
}

static void on_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg; /* benign (unknown chunks, ...): the pixels are what matter */
}

/* The file's text chunks (tEXt, zTXt, iTXt, before or after the pixels) into r->meta. */
static int read_text(png_structp png, png_infop info, const char *name, tf_raster *r,
                     char *err, size_t errlen)
{
    png_textp text = NULL;
    int n = 0;
    png_get_text(png, info, &text, &n);
    for (int i = 0; i < n; i++)
        if (tf_raster_meta_item(r, text[i].key, text[i].text ? text[i].text : "", name, err,
                                errlen) != 0)
            return -1;
    return 0;
}

/* The IHDR's size, checked before libpng (which refuses sizes above its own limit with a
 * vaguer message): signature, chunk length, "IHDR", width, height, all big-endian.  0, or -1
 * with err. */
static int check_ihdr_size(const uint8_t *data, size_t len, const char *name, char *err,
                           size_t errlen)
{
    if (len < 24 || memcmp(data + 12, "IHDR", 4) != 0)
        return 0; /* libpng says what is wrong */
    unsigned long long w = (unsigned long long)data[16] << 24 | data[17] << 16 |
                           data[18] << 8 | data[19];
    unsigned long long h = (unsigned long long)data[20] << 24 | data[21] << 16 |
                           data[22] << 8 | data[23];
    return tf_raster_check_size((long long)w, (long long)h, name, err, errlen);
}

/* After png_read_info: a grayscale (+alpha) image of a size a raster may have, not
 * interlaced, its 1-, 2- and 4-bit samples read as bytes.  0, or -1 with err. */
static int check_format(png_structp png, png_infop info, const char *name, char *err,
                        size_t errlen)
{
    png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    int type = png_get_color_type(png, info);
    if (type != PNG_COLOR_TYPE_GRAY && type != PNG_COLOR_TYPE_GRAY_ALPHA)
        return tf_seterr(err, errlen,
                         "%s: a colour PNG; a height map must be grayscale (one channel)", name);
    if (tf_raster_check_size(w, h, name, err, errlen) != 0)
        return -1;
    if (png_get_bit_depth(png, info) < 8)
        png_set_expand_gray_1_2_4_to_8(png);
    if (png_get_interlace_type(png, info) != PNG_INTERLACE_NONE)
        return tf_seterr(err, errlen, "%s: an interlaced PNG; save it without interlacing", name);
    png_read_update_info(png, info);
    return 0;
}

/* One row's samples as values: PNG samples are big-endian; a transparent one is nodata. */
static void decode_row(const uint8_t *row, float *out, png_uint_32 w, int channels, int bytes)
{
    for (png_uint_32 x = 0; x < w; x++) {
        const uint8_t *s = row + (size_t)x * (size_t)channels * (size_t)bytes;
        unsigned v, a;
        if (bytes == 2) {
            v = (unsigned)s[0] << 8 | s[1];
            a = channels == 2 ? ((unsigned)s[2] << 8 | s[3]) : 1;
        } else {
            v = s[0];
            a = channels == 2 ? s[1] : 1;
        }
        out[x] = a == 0 ? NAN : (float)v;
    }
}

int tf_raster_read_png(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                       char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    if (check_ihdr_size(data, len, name, err, errlen) != 0)
        return -1;
    png_source src = {data, len, 0, ""};
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &src, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!info) {
        png_destroy_read_struct(&png, NULL, NULL);
        return tf_seterr(err, errlen, "%s: out of memory", name);
    }
    /* volatile: modified between setjmp and a longjmp back to it (the helpers below call
     * libpng, whose errors come back here) */
    float *volatile values = NULL;
    uint8_t *volatile row = NULL;
    int rc = -1;
    if (setjmp(png_jmpbuf(png))) {
        tf_seterr(err, errlen, "%s: not a readable PNG: %s", name,
                  src.message[0] ? src.message : "corrupt");
        goto out;
    }
    png_set_read_fn(png, &src, read_bytes);
    png_read_info(png, info);
    if (check_format(png, info, name, err, errlen) != 0)
        goto out;
    png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    int channels = png_get_color_type(png, info) == PNG_COLOR_TYPE_GRAY_ALPHA ? 2 : 1;
    int bytes = png_get_bit_depth(png, info) == 16 ? 2 : 1;
    size_t rowbytes = png_get_rowbytes(png, info);
    if (rowbytes != (size_t)w * (size_t)channels * (size_t)bytes) {
        tf_seterr(err, errlen, "%s: unexpected PNG row layout", name);
        goto out;
    }
    values = malloc((size_t)w * h * sizeof(float));
    row = malloc(rowbytes);
    if (!values || !row) {
        tf_seterr(err, errlen, "%s: out of memory for a %ux%u height map", name, (unsigned)w,
                  (unsigned)h);
        goto out;
    }
    for (png_uint_32 y = 0; y < h; y++) {
        png_read_row(png, row, NULL);
        decode_row(row, values + (size_t)y * w, w, channels, bytes);
    }
    png_read_end(png, info);
    if (read_text(png, info, name, r, err, errlen) != 0)
        goto out;
    r->width = (int)w;
    r->height = (int)h;
    r->v = values;
    values = NULL;
    rc = 0;
out:
    png_destroy_read_struct(&png, &info, NULL);
    free(values);
    free(row);
    return rc;
}
