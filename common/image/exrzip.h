/* exrzip.h: OpenEXR's ZIP and ZIPS chunk compression, done with libdeflate instead of the zlib
 * that OpenEXRCore 3.1 calls.  The chunk's bytes are split into their even and odd bytes, a
 * delta predictor runs over the result, and that is deflated as a zlib stream; a chunk that
 * would not shrink is stored raw (its packed size equal to its unpacked size), as exrcheck.h
 * and every OpenEXR reader expect.  The stream is a standard zlib stream, so any reader
 * decodes it; libdeflate's level 1 packs it ~2x faster than zlib's and ~3% smaller (the
 * workers' encoding was 6.5% of a render's CPU: bench/README.md section 15).
 *
 * A tf_exr_zip is one thread's: its compressor and the buffers it packs into.  The encode
 * pipeline borrows its output buffer (tf_exr_zip_compress) until tf_exr_zip_release, which must
 * come before exr_encoding_destroy so that OpenEXRCore does not free what it does not own. */
#ifndef TF_EXRZIP_H
#define TF_EXRZIP_H

#include <openexr.h>
#include <stddef.h>
#include <stdint.h>

typedef struct tf_exr_zip tf_exr_zip;

/* A packer at `level` (libdeflate's 1..12); NULL when out of memory. */
tf_exr_zip *tf_exr_zip_new(int level);
void tf_exr_zip_free(tf_exr_zip *z);

/* Pack n bytes of `in` as a ZIP / ZIPS chunk.  Returns the packed bytes (n when stored raw) in
 * a buffer of z's, valid until the next call; *len gets their count.  NULL when out of memory. */
const uint8_t *tf_exr_zip_pack(tf_exr_zip *z, const uint8_t *in, size_t n, size_t *len);

/* The encode pipeline's compress step for a ZIP or ZIPS part (enc->compress_fn calls it with
 * its own tf_exr_zip): enc->packed_buffer packed, enc->compressed_buffer pointing into z. */
exr_result_t tf_exr_zip_compress(tf_exr_zip *z, exr_encode_pipeline_t *enc);

/* Hand the buffer tf_exr_zip_compress lent back to z before exr_encoding_destroy(enc). */
void tf_exr_zip_release(exr_encode_pipeline_t *enc);

#endif
