/* exrzip.c: see exrzip.h.  The byte split and predictor are OpenEXR's (its internal_zip.c);
 * exrcheck.c undoes them. */
#include "image/exrzip.h"
#include "growbuf.h"

#include <libdeflate.h>
#include <stdlib.h>
#include <string.h>

struct tf_exr_zip {
    struct libdeflate_compressor *deflate;
    uint8_t *filtered, *packed; /* the split and predicted bytes; the packed chunk */
    size_t filtered_cap, packed_cap;
};

tf_exr_zip *tf_exr_zip_new(int level)
{
    tf_exr_zip *z = calloc(1, sizeof *z);
    if (z)
        z->deflate = libdeflate_alloc_compressor(level);
    if (z && !z->deflate) {
        free(z);
        return NULL;
    }
    return z;
}

void tf_exr_zip_free(tf_exr_zip *z)
{
    if (!z)
        return;
    libdeflate_free_compressor(z->deflate);
    free(z->filtered);
    free(z->packed);
    free(z);
}

/* OpenEXR's filter: the even bytes, then the odd ones (into split); then each byte as its
 * difference from the one before, plus 128 (into out).  Two plain loops over separate buffers,
 * which the compiler turns into vector code (one pass carrying the previous byte in place could
 * not be: bench/README.md section 42). */
static void split_and_predict(const uint8_t *restrict in, size_t n, uint8_t *restrict split,
                              uint8_t *restrict out)
{
    const size_t half = n / 2, first_odd = (n + 1) / 2;
    for (size_t i = 0; i < half; i++) {
        split[i] = in[2 * i];
        split[first_odd + i] = in[2 * i + 1];
    }
    if (n & 1)
        split[half] = in[n - 1];
    out[0] = split[0];
    for (size_t i = 1; i < n; i++)
        out[i] = (uint8_t)(split[i] - split[i - 1] + 128);
}

const uint8_t *tf_exr_zip_pack(tf_exr_zip *z, const uint8_t *in, size_t n, size_t *len)
{
    if (tf_growbuf(&z->filtered, &z->filtered_cap, n ? n : 1) ||
        tf_growbuf(&z->packed, &z->packed_cap, n ? n : 1))
        return NULL;
    *len = 0;
    if (n == 0)
        return z->packed;
    split_and_predict(in, n, z->packed, z->filtered); /* packed: scratch until compressed into */
    /* room for n - 1 bytes: a stream that does not shrink the chunk does not fit (0) */
    *len = libdeflate_zlib_compress(z->deflate, z->filtered, n, z->packed, n - 1);
    if (*len == 0) {
        memcpy(z->packed, in, n);
        *len = n;
    }
    return z->packed;
}

exr_result_t tf_exr_zip_compress(tf_exr_zip *z, exr_encode_pipeline_t *enc)
{
    size_t len;
    const uint8_t *p = tf_exr_zip_pack(z, enc->packed_buffer, enc->packed_bytes, &len);
    if (!p)
        return EXR_ERR_OUT_OF_MEMORY;
    enc->compressed_buffer = (void *)p;
    enc->compressed_bytes = len;
    enc->compressed_alloc_size = z->packed_cap;
    return EXR_ERR_SUCCESS;
}

void tf_exr_zip_release(exr_encode_pipeline_t *enc)
{
    enc->compressed_buffer = NULL;
    enc->compressed_alloc_size = 0;
}
