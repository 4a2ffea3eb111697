/* paint_raster.h: what the page draws, and the same drawing here (for the PNG the page can be
 * checked against, and the benchmark's PSNR).  web/paint.js implements exactly this.
 *
 * A view's picture is a run of display messages, applied in order to an RGB8 canvas that
 * starts black.  A message is a header of 5 little-endian uint32 -- kind, x, y, s, d -- then:
 *   kind 1 (LATTICE): the node's lattice at stride d (paintproto.h: tf_paint_axis on both
 *          axes, all points, corners included), 3 bytes sRGB each, row by row.  Each cell
 *          between neighbouring points is shaded bilinearly from its four corners: pixel
 *          (px, py) of cell [x0, x1] x [y0, y1] gets, per channel, with integer weights
 *          ax = 2 (px - x0) + 1, bx = 2 (x1 - x0) - ax (likewise ay, by in y),
 *          (c00 bx by + c10 ax by + c01 bx ay + c11 ax ay + D/2) / D,  D = 4 (x1-x0)(y1-y0),
 *          integer division.  Pixels px in [x0, x1), py in [y0, y1).
 *   kind 2 (EXACT): the node's pixels [x, min(x+s, W)) x [y, min(y+s, H)), 3 bytes each, row
 *          by row: the final render's pixel as the render's PNG preview shows it (the sRGB
 *          of its float value, image/preview.h tf_srgb8).
 * A later message over the same pixels wins; a region is only ever refined. */
#ifndef TF_PAINT_RASTER_H
#define TF_PAINT_RASTER_H

#include <stddef.h>
#include <stdint.h>

#define TF_PAINT_MSG_LATTICE 1
#define TF_PAINT_MSG_EXACT 2
#define TF_PAINT_MSG_HEADER 20

/* Apply the messages in msgs[0 .. len) to rgb (w * h * 3).  0, or -1 if they are malformed
 * (the canvas is then partly drawn). */
int tf_paint_raster_apply(uint8_t *rgb, int w, int h, const uint8_t *msgs, size_t len);

/* PSNR in dB of a against b (w * h * 3 bytes each); INFINITY when equal. */
double tf_paint_psnr(const uint8_t *a, const uint8_t *b, size_t n);

#endif
