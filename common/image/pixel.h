/* pixel.h: the pixel and the rectangle, the two types the renderer, the image files and the
 * farm's tuples all speak.  They live here, below the renderer, so that the OpenEXR writer and
 * the wire format need not include the renderer to name a pixel. */
#ifndef TF_PIXEL_H
#define TF_PIXEL_H

/* A rectangle of the image, in pixels: x, y of its top-left corner, w x h pixels. */
typedef struct tf_rect { int x, y, w, h; } tf_rect;

/* One output pixel: linear RGB, alpha (1 = terrain or water, 0 = sky), Z = distance along the
 * primary ray through the pixel centre region (camera to first hit; +inf-free: sky = 1e30f),
 * spp = number of distinct samples that went into this pixel. */
typedef struct tf_pixel { float r, g, b, a, z, spp; } tf_pixel;

#endif
