/* livepreview.h: the image coming into focus, for the dashboard.  A small tone-mapped RGBA copy
 * of the render (at most max_side pixels on its longer side, so its size does not grow with
 * the image), drawn stamp by stamp as results arrive (each preview pixel takes the nearest
 * image pixel), with alpha 0 where nothing has been rendered yet.  Encoded to PNG on demand
 * (/api/preview.png) by the HTTP side from a copy; this module itself has no locks and is used
 * by the event loop only. */
#ifndef TF_LIVEPREVIEW_H
#define TF_LIVEPREVIEW_H

#include <stddef.h>
#include <stdint.h>

#include "image/pixel.h"

typedef struct tf_livepreview {
    int img_w, img_h;   /* the render */
    int w, h;           /* the preview */
    uint8_t *rgba;      /* w * h * 4 */
    uint64_t version;   /* grows with every change */
    int64_t stamps;     /* results drawn */
} tf_livepreview;

tf_livepreview *tf_livepreview_new(int img_w, int img_h, int max_side);
void tf_livepreview_free(tf_livepreview *lp);
/* Draw a finished rectangle from its wire pixels (farmproto.h: w*h*TF_PIXEL_WIRE_BYTES bytes,
 * checked by the caller). */
void tf_livepreview_put_wire(tf_livepreview *lp, tf_rect r, const uint8_t *wire);
/* Draw one decoded image row (rows read back from a resumed file). */
void tf_livepreview_put_row(tf_livepreview *lp, int y, const tf_pixel *row);

/* Encode w x h RGBA pixels as a PNG in memory (fast compression).  0 and a malloc'd buffer,
 * or -1. */
int tf_png_encode_rgba(const uint8_t *rgba, int w, int h, uint8_t **out, size_t *len);

#endif
