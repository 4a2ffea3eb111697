/* exrcheck.h: what the coordinator may ask of a worker's packed chunk without trusting the
 * worker: does it decode, and to finite values only?  OpenEXR's ZIP and ZIPS chunks are a zlib
 * stream of the chunk's bytes after a byte split and a delta predictor; a chunk whose packed
 * size equals its unpacked size is stored raw (exrlayout.h, farmproto.h "THE RESULT FORMAT").
 * Once the stream inflates, checksum included, to exactly the unpacked size, the rest of
 * OpenEXR's decoding cannot fail, so "decodes" here is what every OpenEXR reader accepts.
 * The values are then those a reader gets: each line of the chunk holds, channel by channel in
 * name order (A B G R Z spp), the line's values of that channel (exrpart.c).  Per-pixel work:
 * the coordinator runs it off its event loop (coordinator/render/resultcheck.h). */
#ifndef TF_EXRCHECK_H
#define TF_EXRCHECK_H

#include <stddef.h>
#include <stdint.h>

#include "image/exrlayout.h"

/* Does this packed chunk decode to exactly `unpacked` bytes?  0 if it does, else -1.
 * *scratch (grown as needed, caller frees) holds the inflated bytes. */
int tf_exr_chunk_decodes(const uint8_t *packed, size_t packed_len, size_t unpacked,
                         uint8_t **scratch, size_t *cap);

/* Does chunk c of layout l, packed in packed_len bytes, decode, and hold only finite values in
 * every channel?  0, or -1 with a one-line reason ("does not decode", "channel R holds a NaN
 * at (x, y)").  *scratch as above: the check reads the inflated bytes where they lie. */
int tf_exr_chunk_check(const tf_exr_layout *l, const tf_chunk_ref *c, const uint8_t *packed,
                       size_t packed_len, uint8_t **scratch, size_t *cap, char *err,
                       size_t errlen);

/* OpenEXR's delta predictor undone in place (p[i] += p[i - 1] - 128, in order): what
 * tf_exr_chunk_check does after inflating, exposed for its test against the plain loop. */
void tf_exr_undo_delta(uint8_t *p, size_t n);

#endif
