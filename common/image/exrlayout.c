/* exrlayout.c: see exrlayout.h. */
#include "image/exrlayout.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "le_bytes.h"
#include "log.h"

#define MAX_DIM 65536

int tf_exr_layout_check(const tf_exr_layout *l, char *err, size_t errlen)
{
    if (l->width < 1 || l->height < 1 || l->width > MAX_DIM || l->height > MAX_DIM)
        return tf_seterr(err, errlen, "bad image size %dx%d", l->width, l->height);
    if (l->pixel != TF_PIXEL_HALF && l->pixel != TF_PIXEL_FLOAT)
        return tf_seterr(err, errlen, "bad pixel type %d", l->pixel);
    if (l->tiled && (l->tile_w < 1 || l->tile_h < 1 || l->tile_w > MAX_DIM ||
                     l->tile_h > MAX_DIM))
        return tf_seterr(err, errlen, "bad tile size %dx%d", l->tile_w, l->tile_h);
    return 0;
}

const char *tf_pixel_type_name(int pixel) { return pixel == TF_PIXEL_HALF ? "half" : "float"; }

int tf_pixel_type_parse(const char *s, int *pixel)
{
    if (!strcmp(s, "half"))
        *pixel = TF_PIXEL_HALF;
    else if (!strcmp(s, "float"))
        *pixel = TF_PIXEL_FLOAT;
    else
        return -1;
    return 0;
}

void tf_exr_layout_format(const tf_exr_layout *l, char *buf, size_t len)
{
    if (l->tiled)
        snprintf(buf, len, "tiled %dx%d %s", l->tile_w, l->tile_h, tf_pixel_type_name(l->pixel));
    else
        snprintf(buf, len, "scanline %s", tf_pixel_type_name(l->pixel));
}

int tf_exr_layout_parse(const char *s, int width, int height, tf_exr_layout *l)
{
    memset(l, 0, sizeof *l);
    l->width = width;
    l->height = height;
    char kind[16], pix[16];
    int tw = 0, th = 0, n = 0;
    if (sscanf(s, "tiled %dx%d %15s%n", &tw, &th, pix, &n) == 3 && s[n] == '\0') {
        l->tiled = 1;
        l->tile_w = tw;
        l->tile_h = th;
    } else if (sscanf(s, "%15s %15s%n", kind, pix, &n) == 2 && s[n] == '\0' &&
               !strcmp(kind, "scanline")) {
        l->tiled = 0;
    } else {
        return -1;
    }
    if (tf_pixel_type_parse(pix, &l->pixel))
        return -1;
    return tf_exr_layout_check(l, NULL, 0);
}

int tf_layout_pixel_bytes(const tf_exr_layout *l) { return l->pixel == TF_PIXEL_HALF ? 16 : 24; }

int tf_layout_chunks_x(const tf_exr_layout *l)
{
    return l->tiled ? (l->width + l->tile_w - 1) / l->tile_w : 1;
}

int tf_layout_chunks_y(const tf_exr_layout *l)
{
    return l->tiled ? (l->height + l->tile_h - 1) / l->tile_h : l->height;
}

int64_t tf_layout_chunk_count(const tf_exr_layout *l)
{
    return (int64_t)tf_layout_chunks_x(l) * tf_layout_chunks_y(l);
}

tf_chunk_ref tf_layout_chunk(const tf_exr_layout *l, int64_t index)
{
    tf_chunk_ref c;
    int nx = tf_layout_chunks_x(l);
    c.cx = (int)(index % nx);
    c.cy = (int)(index / nx);
    if (l->tiled) {
        c.rect.x = c.cx * l->tile_w;
        c.rect.y = c.cy * l->tile_h;
        c.rect.w = l->width - c.rect.x < l->tile_w ? l->width - c.rect.x : l->tile_w;
        c.rect.h = l->height - c.rect.y < l->tile_h ? l->height - c.rect.y : l->tile_h;
    } else {
        c.rect = (tf_rect){0, c.cy, l->width, 1};
    }
    c.unpacked = (uint64_t)c.rect.w * (uint64_t)c.rect.h * (uint64_t)tf_layout_pixel_bytes(l);
    return c;
}

int64_t tf_layout_chunk_index(const tf_exr_layout *l, int cx, int cy)
{
    int nx = tf_layout_chunks_x(l), ny = tf_layout_chunks_y(l);
    if (cx < 0 || cy < 0 || cx >= nx || cy >= ny)
        return -1;
    return (int64_t)cy * nx + cx;
}

int tf_layout_rows_in_chunks(const tf_exr_layout *l, int64_t chunks)
{
    int64_t full_rows = chunks / tf_layout_chunks_x(l); /* complete chunk rows */
    int64_t rows = l->tiled ? full_rows * l->tile_h : full_rows;
    return rows < l->height ? (int)rows : l->height;
}

int tf_layout_rect_chunks(const tf_exr_layout *l, tf_rect r, int64_t *first, int *count)
{
    if (r.w < 1 || r.h < 1 || r.x < 0 || r.y < 0 || r.x > l->width - r.w ||
        r.y > l->height - r.h)
        return -1;
    if (!l->tiled) {
        if (r.x != 0 || r.w != l->width || r.h > TF_CHUNKS_PER_TASK_MAX)
            return -1;
        *first = r.y;
        *count = r.h;
        return 0;
    }
    if (r.x % l->tile_w || r.y % l->tile_h)
        return -1;
    tf_chunk_ref c = tf_layout_chunk(l, tf_layout_chunk_index(l, r.x / l->tile_w,
                                                              r.y / l->tile_h));
    if (c.rect.w != r.w || c.rect.h != r.h)
        return -1;
    *first = tf_layout_chunk_index(l, c.cx, c.cy);
    *count = 1;
    return 0;
}

tf_preview_grid tf_preview_grid_for(int width, int height)
{
    tf_preview_grid g;
    int side = width > height ? width : height;
    g.factor = (side + TF_PREVIEW_MAX_SIDE - 1) / TF_PREVIEW_MAX_SIDE;
    if (g.factor < 1)
        g.factor = 1;
    g.pw = (width + g.factor - 1) / g.factor;
    g.ph = (height + g.factor - 1) / g.factor;
    return g;
}

/* The first preview index whose source pixel is >= a, along a side of `size` pixels with n
 * preview pixels.  Sources grow with the index; clamping to size-1 only affects the last one,
 * and size-1 >= a whenever a < size. */
static int first_source_at(const tf_preview_grid *g, int a, int size, int n)
{
    if (a >= size)
        return n;
    int64_t num = (int64_t)a - g->factor / 2;
    int64_t i = num <= 0 ? 0 : (num + g->factor - 1) / g->factor;
    return i < n ? (int)i : n;
}

void tf_preview_span(const tf_preview_grid *g, int width, int height, tf_rect r, int *i0,
                     int *i1, int *j0, int *j1)
{
    *i0 = first_source_at(g, r.x, width, g->pw);
    *i1 = first_source_at(g, r.x + r.w, width, g->pw);
    *j0 = first_source_at(g, r.y, height, g->ph);
    *j1 = first_source_at(g, r.y + r.h, height, g->ph);
}

void tf_chunk_rec_put(uint8_t *rec, const tf_chunk_rec *c)
{
    tf_le_put32(rec, (uint32_t)c->cx);
    tf_le_put32(rec + 4, (uint32_t)c->cy);
    tf_le_put64(rec + 8, (uint64_t)c->packed);
    tf_le_put64(rec + 16, (uint64_t)c->unpacked);
}

void tf_chunk_rec_get(const uint8_t *rec, tf_chunk_rec *c)
{
    c->cx = (int32_t)tf_le_get32(rec);
    c->cy = (int32_t)tf_le_get32(rec + 4);
    c->packed = (int64_t)tf_le_get64(rec + 8);
    c->unpacked = (int64_t)tf_le_get64(rec + 16);
}
