/* png_write.h: streaming PNG output through libpng, one row at a time, so callers never hold a
 * whole image.  Used for the tone-mapped preview beside every render (8-bit sRGB) and for the
 * 16-bit grayscale height field that POV-Ray reads as a height_field. */
#ifndef TF_PNG_WRITE_H
#define TF_PNG_WRITE_H

#include <stddef.h>

typedef struct tf_png_writer tf_png_writer;

/* bit_depth 8 or 16; channels 1 (gray) or 3 (RGB).  Writes to path + ".tmp" and renames on
 * finish, so an existing file is never left half-written. */
tf_png_writer *tf_png_create(const char *path, int width, int height, int bit_depth, int channels,
                             char *err, size_t errlen);
/* Trade size for speed: no row filter and zlib `level` (0: stored, 1: fastest), for the progress
 * preview the coordinator rewrites every few seconds while a render runs.  Call before the
 * first row. */
void tf_png_fast(tf_png_writer *w, int level);
/* A tEXt chunk key = value (Latin-1, key 1..79 bytes), written after the pixels by
 * tf_png_finish.  0, or -1 with one line in err. */
int tf_png_text(tf_png_writer *w, const char *key, const char *value, char *err,
                size_t errlen);
/* One row of width * channels samples: uint8_t for depth 8, uint16_t (host order) for depth 16. */
int tf_png_write_row(tf_png_writer *w, const void *row, char *err, size_t errlen);
/* Finish, close, rename into place.  Frees w whatever happens. */
int tf_png_finish(tf_png_writer *w, char *err, size_t errlen);
/* Give up: close, remove the temporary file, free w. */
void tf_png_abort(tf_png_writer *w);

#endif
