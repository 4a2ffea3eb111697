/* paint_raster.c: the page's drawing, done here (paint_raster.h). */
#include "coordinator/paint/paint_raster.h"

#include <math.h>
#include <string.h>

#include "le_bytes.h"
#include "paintproto.h"

/* Shade one cell [x0, x1] x [y0, y1] from its corners' colours. */
static void shade_cell(uint8_t *rgb, int w, int x0, int x1, int y0, int y1, const uint8_t *c00,
                       const uint8_t *c10, const uint8_t *c01, const uint8_t *c11)
{
    uint32_t D = 4u * (uint32_t)(x1 - x0) * (uint32_t)(y1 - y0);
    for (int py = y0; py < y1; py++) {
        uint32_t ay = 2u * (uint32_t)(py - y0) + 1, by = 2u * (uint32_t)(y1 - y0) - ay;
        uint8_t *row = rgb + ((size_t)py * (size_t)w + (size_t)x0) * 3;
        for (int px = x0; px < x1; px++, row += 3) {
            uint32_t ax = 2u * (uint32_t)(px - x0) + 1, bx = 2u * (uint32_t)(x1 - x0) - ax;
            for (int ch = 0; ch < 3; ch++)
                row[ch] = (uint8_t)((c00[ch] * bx * by + c10[ch] * ax * by + c01[ch] * bx * ay +
                                     c11[ch] * ax * ay + D / 2) / D);
        }
    }
}

/* A LATTICE message's body: the cells between its points.  Bytes it used, or 0 if short. */
static size_t draw_lattice(uint8_t *rgb, int w, int h, const tf_paint_node *n,
                           const uint8_t *body, size_t len)
{
    int xs[TF_PAINT_MAX_SIZE + 1], ys[TF_PAINT_MAX_SIZE + 1];
    int ni = tf_paint_axis(n->x, n->s, n->d, w, xs), nj = tf_paint_axis(n->y, n->s, n->d, h, ys);
    size_t need = (size_t)ni * (size_t)nj * 3;
    if (len < need)
        return 0;
    for (int j = 0; j + 1 < nj; j++)
        for (int i = 0; i + 1 < ni; i++) {
            const uint8_t *c00 = body + ((size_t)j * (size_t)ni + (size_t)i) * 3;
            shade_cell(rgb, w, xs[i], xs[i + 1], ys[j], ys[j + 1], c00, c00 + 3,
                       c00 + (size_t)ni * 3, c00 + (size_t)ni * 3 + 3);
        }
    return need;
}

static size_t draw_exact(uint8_t *rgb, int w, int h, const tf_paint_node *n,
                         const uint8_t *body, size_t len)
{
    int pw = (n->x + n->s < w ? n->x + n->s : w) - n->x;
    int ph = (n->y + n->s < h ? n->y + n->s : h) - n->y;
    size_t need = (size_t)pw * (size_t)ph * 3;
    if (len < need)
        return 0;
    for (int row = 0; row < ph; row++)
        memcpy(rgb + ((size_t)(n->y + row) * (size_t)w + (size_t)n->x) * 3,
               body + (size_t)row * (size_t)pw * 3, (size_t)pw * 3);
    return need;
}

int tf_paint_raster_apply(uint8_t *rgb, int w, int h, const uint8_t *msgs, size_t len)
{
    size_t at = 0;
    while (at < len) {
        if (len - at < TF_PAINT_MSG_HEADER)
            return -1;
        const uint8_t *m = msgs + at;
        uint32_t kind = tf_le_get32(m);
        tf_paint_node n = {(int)tf_le_get32(m + 4), (int)tf_le_get32(m + 8), (int)tf_le_get32(m + 12),
                           (int)tf_le_get32(m + 16), 0};
        if ((kind != TF_PAINT_MSG_LATTICE && kind != TF_PAINT_MSG_EXACT) ||
            (kind == TF_PAINT_MSG_LATTICE) != (n.d > 0) || tf_paint_node_problem(&n, w, h))
            return -1;
        at += TF_PAINT_MSG_HEADER;
        size_t used = kind == TF_PAINT_MSG_LATTICE ? draw_lattice(rgb, w, h, &n, msgs + at, len - at)
                                                   : draw_exact(rgb, w, h, &n, msgs + at, len - at);
        if (used == 0)
            return -1;
        at += used;
    }
    return 0;
}

double tf_paint_psnr(const uint8_t *a, const uint8_t *b, size_t n)
{
    double sum = 0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)a[i] - (double)b[i];
        sum += d * d;
    }
    if (sum == 0 || n == 0)
        return INFINITY;
    return 10.0 * log10(255.0 * 255.0 / (sum / (double)n));
}
