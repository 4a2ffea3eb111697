/* exrencode.h: a worker's side of "workers encode, the coordinator moves bytes".  Turns a
 * task's rendered rectangle into the finished OpenEXR chunks of the output file (packed with
 * OpenEXRCore's encode pipeline, the file's compression and zlib level: exrpart.h) and into its
 * share of the progress preview, as the result tuple carries them (farmproto.h).
 *
 * The encoder owns an OpenEXRCore write context whose header is the output's part (same
 * layout), written to a sink that discards it: the context only serves chunk geometry and the
 * encode pipeline; each pipeline's write step is replaced by a copy of the packed bytes into
 * the payload.  One encoder per worker, reused for every task (not thread safe). */
#ifndef TF_EXRENCODE_H
#define TF_EXRENCODE_H

#include <stddef.h>

#include "image/exrlayout.h"
#include "image/pixel.h"

typedef struct tf_exr_encoder tf_exr_encoder;

tf_exr_encoder *tf_exr_encoder_new(const tf_exr_layout *l, char *err, size_t errlen);
void tf_exr_encoder_free(tf_exr_encoder *e);
/* Encode rectangle r (px: r.w * r.h pixels, row-major) into *out, whose buffers belong to the
 * encoder and stay valid until the next call.  0, or -1 with a message (r is not whole chunks
 * of the layout, or OpenEXRCore failed). */
int tf_exr_encode_rect(tf_exr_encoder *e, tf_rect r, const tf_pixel *px, tf_chunk_payload *out,
                       char *err, size_t errlen);
/* The preview share of rectangle r alone (tf_preview_span), into buf (grown as needed). */
int tf_preview_share(const tf_preview_grid *g, int width, int height, tf_rect r,
                     const tf_pixel *px, uint8_t **buf, size_t *cap, size_t *len);

/* Does this packed chunk decode to exactly `unpacked` bytes?  (ZIP/ZIPS: a chunk stored raw has
 * packed == unpacked; otherwise its zlib stream must inflate, checksum included, to exactly
 * unpacked bytes -- the rest of OpenEXR's ZIP decoding, the predictor and byte reordering,
 * cannot fail.)  For --verify-chunks: this is per-pixel work.  0 if it decodes, else -1.
 * *scratch (grown as needed, caller frees) holds the inflated bytes. */
int tf_exr_chunk_decodes(const uint8_t *packed, size_t packed_len, size_t unpacked,
                         uint8_t **scratch, size_t *cap);

#endif
