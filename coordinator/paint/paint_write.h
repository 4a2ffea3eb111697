/* paint_write.h: a painted view on disk.  Once every pixel of a view is exact, its pixels are
 * the render's (paintproto.h), and `terrafarm paint -o FILE` writes them as `terrafarm render`
 * would: an OpenEXR scanline file of the same channels and pixel type, written beside the
 * output and renamed over it when whole and durable, so the path never holds less than a
 * complete image (or what was there before). */
#ifndef TF_PAINT_WRITE_H
#define TF_PAINT_WRITE_H

#include <stdint.h>

#include "image/pixel.h"
#include "scene.h"

/* Write the w x h pixels of view gen of scene s (the view's scene: its hash goes in the
 * header) to path.  0, or -1 (one line logged). */
int tf_paint_write(const char *path, const tf_scene *view, int64_t gen, const tf_pixel *px,
                   int pixel_type);

#endif
