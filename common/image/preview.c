/* preview.c: the 8-bit sRGB PNG preview beside every render (see preview.h).
 *
 * The finished EXR is streamed back row by row through tf_exr_read_rows and each row is tone
 * mapped and handed to png_write.h at once: memory is one row of bytes, never the image.  If
 * the EXR is a partial render, the rows it does not have yet come out black, so the preview
 * always has the image's full size. */
#include "image/preview.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "image/exrfile.h"
#include "image/png_write.h"
#include "log.h"

/* Exposure applied before clamping; 1 keeps linear radiance 1.0 at full white. */
#define TF_PREVIEW_EXPOSURE 1.0

/* Linear -> sRGB-encoded value in [0, 1] (IEC 61966-2-1 transfer curve). */
static double srgb_encode(double v)
{
    return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

uint8_t tf_srgb8_exact(float linear)
{
    double v = (double)linear * TF_PREVIEW_EXPOSURE;
    if (!(v > 0.0)) /* also catches NaN: a broken sample shows as black, never as garbage */
        return 0;
    if (v >= 1.0)
        return 255;
    return (uint8_t)(srgb_encode(v) * 255.0 + 0.5);
}

/* tf_srgb8 without pow.  tf_srgb8_exact never decreases from one float to the next (checked at
 * every float in (0, 1) once, bench/README.md section 42, and from 2^-14 up, where its byte
 * leaves 0, by tests/unit/test_preview.c), so the floats it maps to byte k begin
 * at srgb_start[k], and a value's byte is the last k whose start is at or below it.  The starts
 * are found with tf_srgb8_exact itself, bisecting the positive floats' bit patterns (ordered as
 * the floats are), once a process: ~7,600 calls, against three a pixel of every preview. */
static float srgb_start[256]; /* srgb_start[0] = 0 */
static pthread_once_t srgb_once = PTHREAD_ONCE_INIT;

static float float_of_bits(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static void find_srgb_starts(void)
{
    const uint32_t one = 0x3f800000u; /* 1.0f, which maps to 255 */
    uint32_t below = 0;               /* +0.0f: maps below every k >= 1 */
    for (int k = 1; k < 256; k++) {
        uint32_t lo = below, hi = one; /* tf_srgb8_exact(lo) < k <= tf_srgb8_exact(hi) */
        while (hi - lo > 1) {
            uint32_t mid = lo + (hi - lo) / 2;
            if (tf_srgb8_exact(float_of_bits(mid)) >= k)
                hi = mid;
            else
                lo = mid;
        }
        srgb_start[k] = float_of_bits(hi);
        below = lo;
    }
}

uint8_t tf_srgb8(float linear)
{
    double v = (double)linear * TF_PREVIEW_EXPOSURE;
    if (!(v > 0.0))
        return 0;
    if (v >= 1.0)
        return 255;
    pthread_once(&srgb_once, find_srgb_starts);
    unsigned k = 0;
    for (unsigned step = 128; step > 0; step >>= 1)
        if (srgb_start[k + step] <= linear)
            k += step;
    return (uint8_t)k;
}

typedef struct preview_state {
    const char *png_path;
    const tf_exr_meta *meta; /* filled by tf_exr_read_rows before the first row */
    tf_png_writer *png;
    uint8_t *rgb;            /* one output row, width * 3 bytes */
    int rows_written;
    char err[512];
} preview_state;

static int open_png(preview_state *s)
{
    int w = s->meta->width;
    s->rgb = calloc((size_t)w, 3);
    if (!s->rgb) {
        snprintf(s->err, sizeof s->err, "%s: out of memory", s->png_path);
        return -1;
    }
    s->png = tf_png_create(s->png_path, w, s->meta->height, 8, 3, s->err, sizeof s->err);
    return s->png ? 0 : -1;
}

static int put_row(void *user, int y, const tf_pixel *row)
{
    preview_state *s = user;
    (void)y; /* rows arrive in order, starting at 0 */
    if (!s->png && open_png(s) != 0)
        return -1;
    for (int x = 0; x < s->meta->width; x++) {
        s->rgb[3 * x + 0] = tf_srgb8(row[x].r);
        s->rgb[3 * x + 1] = tf_srgb8(row[x].g);
        s->rgb[3 * x + 2] = tf_srgb8(row[x].b);
    }
    if (tf_png_write_row(s->png, s->rgb, s->err, sizeof s->err) != 0)
        return -1;
    s->rows_written++;
    return 0;
}

/* Rows the partial render does not have yet: black. */
static int pad_missing_rows(preview_state *s)
{
    if (!s->png && open_png(s) != 0)
        return -1;
    memset(s->rgb, 0, (size_t)s->meta->width * 3);
    while (s->rows_written < s->meta->height) {
        if (tf_png_write_row(s->png, s->rgb, s->err, sizeof s->err) != 0)
            return -1;
        s->rows_written++;
    }
    return 0;
}

int tf_preview_from_exr(const char *exr_path, const char *png_path, char *err, size_t errlen)
{
    tf_exr_meta meta;
    preview_state s;
    memset(&s, 0, sizeof s);
    s.png_path = png_path;
    s.meta = &meta;
    int rows_valid = 0;
    int rc = tf_exr_read_rows(exr_path, &meta, &rows_valid, put_row, &s, err, errlen);
    if (rc != 0 && s.err[0]) /* the PNG side failed: its message says more */
        tf_seterr(err, errlen, "%s", s.err);
    if (rc == 0 && pad_missing_rows(&s) != 0) {
        tf_seterr(err, errlen, "%s", s.err);
        rc = -1;
    }
    if (rc == 0) {
        tf_png_writer *png = s.png;
        s.png = NULL;
        if (tf_png_finish(png, err, errlen) != 0)
            rc = -1;
    }
    if (s.png)
        tf_png_abort(s.png);
    free(s.rgb);
    return rc;
}
