/* exrencode.h: a worker's side of "workers encode, the coordinator moves bytes".  Turns a
 * task's rendered rectangle into the finished OpenEXR chunks of the output file (packed with
 * OpenEXRCore's encode pipeline, the file's compression and level: exrpart.h; its compress
 * step is exrzip.h's, on libdeflate) and into its
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
/* Pack with OpenEXRCore's own compress step (zlib) instead of exrzip.h's (libdeflate): the
 * same pixels, other bytes.  Only bench/bench_encode's baseline asks for it. */
void tf_exr_encoder_use_openexr_zlib(tf_exr_encoder *e, int on);
/* The preview share of rectangle r alone (tf_preview_span), into buf (grown as needed). */
int tf_preview_share(const tf_preview_grid *g, int width, int height, tf_rect r,
                     const tf_pixel *px, uint8_t **buf, size_t *cap, size_t *len);

#endif
