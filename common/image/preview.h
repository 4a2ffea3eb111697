/* preview.h: the tone-mapped sRGB PNG written beside every render.  It is made by streaming the
 * finished EXR back chunk by chunk, so the coordinator never holds the whole image. */
#ifndef TF_PREVIEW_H
#define TF_PREVIEW_H

#include <stddef.h>
#include <stdint.h>

/* Linear value -> 8-bit sRGB (exposure 1, clamp, sRGB transfer curve), by a table of where
 * each byte's values begin; the same byte as tf_srgb8_exact for every float. */
uint8_t tf_srgb8(float linear);
/* The same through the transfer curve itself (pow): what the table is made from. */
uint8_t tf_srgb8_exact(float linear);
/* Write png_path from the EXR at exr_path. */
int tf_preview_from_exr(const char *exr_path, const char *png_path, char *err, size_t errlen);

#endif
