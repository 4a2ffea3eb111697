/* livepreview.h: the image coming into focus, for the dashboard.  A small RGBA copy of the
 * farm's progress preview (the sRGB grid of exrlayout.h, whose pixels each result carries for
 * its rectangle: the `preview` blob of farmproto.h), at most max_side pixels on its longer
 * side so its size does not grow with the image: each live pixel takes the nearest grid pixel.
 * It is drawn stamp by stamp from those blobs as results arrive -- the coordinator never
 * decodes a pixel on the render path -- with alpha 0 where nothing has been rendered yet.  In a
 * sequence it shows one frame at a time (tf_livepreview_frame).  Encoded to PNG on demand
 * (/api/preview.png) by the HTTP side from a copy; this module itself has no locks and is used
 * by the event loop only. */
#ifndef TF_LIVEPREVIEW_H
#define TF_LIVEPREVIEW_H

#include <stddef.h>
#include <stdint.h>

#include "image/exrlayout.h"
#include "image/pixel.h"

typedef struct tf_livepreview {
    int img_w, img_h;   /* the render */
    tf_preview_grid grid; /* the farm's preview grid of the render (results' preview blobs) */
    int w, h;           /* the live preview */
    int frame;          /* the frame shown (-1: a still, or none yet) */
    uint8_t *rgba;      /* w * h * 4 */
    uint64_t version;   /* grows with every change */
    int64_t stamps;     /* results drawn */
} tf_livepreview;

tf_livepreview *tf_livepreview_new(int img_w, int img_h, int max_side);
void tf_livepreview_free(tf_livepreview *lp);
/* Draw a finished rectangle from its share of the preview grid (tf_preview_span of r, row-major,
 * 3 bytes sRGB each: a result's `preview` blob).  0, or -1 (nothing drawn) if r is outside the
 * image or len is not that share's size. */
int tf_livepreview_put_share(tf_livepreview *lp, tf_rect r, const uint8_t *share, size_t len);
/* Show `frame` from now on: a different frame than the one shown starts from an empty image. */
void tf_livepreview_frame(tf_livepreview *lp, int frame);
/* Draw one decoded image row (rows read back from a resumed file: a one-time cost of --resume,
 * not the render path's). */
void tf_livepreview_put_row(tf_livepreview *lp, int y, const tf_pixel *row);

/* Encode w x h RGBA pixels as a PNG in memory (fast compression).  0 and a malloc'd buffer,
 * or -1. */
int tf_png_encode_rgba(const uint8_t *rgba, int w, int h, uint8_t **out, size_t *len);

#endif
