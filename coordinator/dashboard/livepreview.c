/* livepreview.c: see livepreview.h. */
#include "coordinator/dashboard/livepreview.h"

#include <png.h>
#include <setjmp.h>
#include <stdlib.h>
#include <string.h>

#include "image/preview.h"

tf_livepreview *tf_livepreview_new(int img_w, int img_h, int max_side)
{
    if (img_w < 1 || img_h < 1 || max_side < 1)
        return NULL;
    tf_livepreview *lp = calloc(1, sizeof *lp);
    if (!lp)
        return NULL;
    lp->img_w = img_w;
    lp->img_h = img_h;
    lp->frame = -1;
    lp->grid = tf_preview_grid_for(img_w, img_h);
    int gw = lp->grid.pw, gh = lp->grid.ph;
    double scale = gw >= gh ? (double)max_side / gw : (double)max_side / gh;
    if (scale > 1)
        scale = 1;
    lp->w = (int)(gw * scale + 0.5);
    lp->h = (int)(gh * scale + 0.5);
    if (lp->w < 1)
        lp->w = 1;
    if (lp->h < 1)
        lp->h = 1;
    lp->rgba = calloc((size_t)lp->w * (size_t)lp->h, 4);
    if (!lp->rgba) {
        free(lp);
        return NULL;
    }
    return lp;
}

void tf_livepreview_free(tf_livepreview *lp)
{
    if (lp)
        free(lp->rgba);
    free(lp);
}

/* The grid column (row) sampled by live column (row) p: the nearest to its centre. */
static int source_of(int p, int img, int preview)
{
    return (int)(((2 * (int64_t)p + 1) * img) / (2 * (int64_t)preview));
}

/* The live indices [*lo, *hi) whose source lies in [a, a + n) of the grid. */
static void preview_span(int a, int n, int img, int preview, int *lo, int *hi)
{
    int p = (int)((int64_t)a * preview / img) - 1;
    if (p < 0)
        p = 0;
    while (p < preview && source_of(p, img, preview) < a)
        p++;
    *lo = p;
    while (p < preview && source_of(p, img, preview) < a + n)
        p++;
    *hi = p;
}

static void set_rgb(tf_livepreview *lp, int px, int py, const uint8_t *rgb)
{
    uint8_t *d = lp->rgba + ((size_t)py * lp->w + px) * 4;
    d[0] = rgb[0];
    d[1] = rgb[1];
    d[2] = rgb[2];
    d[3] = 255;
}

int tf_livepreview_put_share(tf_livepreview *lp, tf_rect r, const uint8_t *share, size_t len)
{
    if (r.x < 0 || r.y < 0 || r.w < 1 || r.h < 1 || r.x > lp->img_w - r.w ||
        r.y > lp->img_h - r.h)
        return -1;
    int i0, i1, j0, j1; /* the grid pixels the share holds */
    tf_preview_span(&lp->grid, lp->img_w, lp->img_h, r, &i0, &i1, &j0, &j1);
    size_t line = (size_t)(i1 - i0) * 3;
    if (len != line * (size_t)(j1 - j0))
        return -1;
    int x0, x1, y0, y1; /* the live pixels whose grid source lies in it */
    preview_span(i0, i1 - i0, lp->grid.pw, lp->w, &x0, &x1);
    preview_span(j0, j1 - j0, lp->grid.ph, lp->h, &y0, &y1);
    for (int py = y0; py < y1; py++) {
        const uint8_t *src = share + (size_t)(source_of(py, lp->grid.ph, lp->h) - j0) * line;
        for (int px = x0; px < x1; px++)
            set_rgb(lp, px, py, src + (size_t)(source_of(px, lp->grid.pw, lp->w) - i0) * 3);
    }
    lp->stamps++;
    lp->version++;
    return 0;
}

void tf_livepreview_frame(tf_livepreview *lp, int frame)
{
    if (frame == lp->frame)
        return;
    memset(lp->rgba, 0, (size_t)lp->w * (size_t)lp->h * 4);
    lp->frame = frame;
    lp->stamps = 0;
    lp->version++;
}

void tf_livepreview_put_row(tf_livepreview *lp, int y, const tf_pixel *row)
{
    if (y < 0 || y >= lp->img_h)
        return;
    /* the live rows whose grid row shows image row y */
    for (int py = 0; py < lp->h; py++) {
        int j = source_of(py, lp->grid.ph, lp->h);
        if (tf_preview_source(&lp->grid, j, lp->img_h) != y)
            continue;
        for (int px = 0; px < lp->w; px++) {
            int i = source_of(px, lp->grid.pw, lp->w);
            const tf_pixel *v = &row[tf_preview_source(&lp->grid, i, lp->img_w)];
            uint8_t rgb[3] = {tf_srgb8(v->r), tf_srgb8(v->g), tf_srgb8(v->b)};
            set_rgb(lp, px, py, rgb);
        }
    }
    lp->version++;
}

/* ---- PNG in memory -------------------------------------------------------------------------- */

typedef struct membuf {
    uint8_t *data;
    size_t len, cap;
    int failed;
} membuf;

static void mem_write(png_structp png, png_bytep data, png_size_t n)
{
    membuf *m = png_get_io_ptr(png);
    if (m->failed)
        return;
    if (m->len + n > m->cap) {
        size_t cap = m->cap ? m->cap : 65536;
        while (cap < m->len + n)
            cap *= 2;
        uint8_t *d = realloc(m->data, cap);
        if (!d) {
            m->failed = 1;
            return;
        }
        m->data = d;
        m->cap = cap;
    }
    memcpy(m->data + m->len, data, n);
    m->len += n;
}

static void mem_flush(png_structp png) { (void)png; }

/* Apart from the caller so that nothing live across the setjmp changes. */
static int encode(png_structp png, png_infop info, const uint8_t *rgba, int w, int h, membuf *m)
{
    if (setjmp(png_jmpbuf(png)))
        return -1;
    png_set_write_fn(png, m, mem_write, mem_flush);
    png_set_compression_level(png, 1);
    png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, 8, PNG_COLOR_TYPE_RGBA,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (int y = 0; y < h; y++)
        png_write_row(png, (png_const_bytep)(rgba + (size_t)y * w * 4));
    png_write_end(png, info);
    return m->failed ? -1 : 0;
}

int tf_png_encode_rgba(const uint8_t *rgba, int w, int h, uint8_t **out, size_t *len)
{
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    membuf m = {NULL, 0, 0, 0};
    int rc = info ? encode(png, info, rgba, w, h, &m) : -1;
    png_destroy_write_struct(&png, info ? &info : NULL);
    if (rc) {
        free(m.data);
        return -1;
    }
    *out = m.data;
    *len = m.len;
    return 0;
}
