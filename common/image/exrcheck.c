/* exrcheck.c: see exrcheck.h.  The reconstruction after inflating is OpenEXR's own for ZIP and
 * ZIPS (the delta predictor undone, then the two halves of the byte split interleaved); the
 * value scan knows the channel types of exrpart.c: R G B A half or float, Z and spp float. */
#include "image/exrcheck.h"
#include "growbuf.h"

#include <libdeflate.h>
#include <string.h>

#include "log.h"

int tf_exr_chunk_decodes(const uint8_t *packed, size_t packed_len, size_t unpacked,
                         uint8_t **scratch, size_t *cap)
{
    if (packed_len == 0 || packed_len > unpacked)
        return -1;
    if (packed_len == unpacked)
        return 0; /* stored raw */
    if (tf_growbuf(scratch, cap, 2 * unpacked + 1))
        return -1;
    /* libdeflate inflates ~2x as fast as zlib (bench/README.md section 15); with no room for
     * more, a stream of another length, or a bad checksum, is refused */
    struct libdeflate_decompressor *d = libdeflate_alloc_decompressor();
    if (!d)
        return -1;
    enum libdeflate_result rc =
        libdeflate_zlib_decompress(d, packed, packed_len, *scratch, unpacked, NULL);
    libdeflate_free_decompressor(d);
    return rc == LIBDEFLATE_SUCCESS ? 0 : -1;
}

/* in: n inflated bytes; out: the chunk's bytes as a reader sees them. */
static void undo_zip_filter(uint8_t *in, size_t n, uint8_t *out)
{
    for (size_t i = 1; i < n; i++)
        in[i] = (uint8_t)(in[i - 1] + in[i] - 128);
    const uint8_t *lo = in, *hi = in + (n + 1) / 2;
    for (size_t i = 0; i < n; i++)
        out[i] = (i & 1) ? *hi++ : *lo++;
}

/* Index of the first non-finite value among n little-endian halves or floats, or -1. */
static long first_bad_half(const uint8_t *p, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if ((p[2 * i + 1] & 0x7c) == 0x7c)
            return (long)i;
    return -1;
}

static long first_bad_float(const uint8_t *p, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if ((p[4 * i + 3] & 0x7f) == 0x7f && (p[4 * i + 2] & 0x80))
            return (long)i;
    return -1;
}

/* Scan one decoded line of w pixels; 0, or -1 with the channel and column of a bad value. */
static int scan_line(const uint8_t *line, int w, int half, const char **channel, long *col)
{
    static const char *const names[] = {"A", "B", "G", "R", "Z", "spp"};
    size_t colour = half ? 2 : 4;
    for (int ch = 0; ch < 6; ch++) {
        int is_half = half && ch < 4;
        *col = is_half ? first_bad_half(line, (size_t)w) : first_bad_float(line, (size_t)w);
        if (*col >= 0) {
            *channel = names[ch];
            return -1;
        }
        line += (size_t)w * (ch < 4 ? colour : 4);
    }
    return 0;
}

int tf_exr_chunk_check(const tf_exr_layout *l, const tf_chunk_ref *c, const uint8_t *packed,
                       size_t packed_len, uint8_t **scratch, size_t *cap, char *err,
                       size_t errlen)
{
    size_t n = (size_t)c->unpacked;
    if (tf_exr_chunk_decodes(packed, packed_len, n, scratch, cap))
        return tf_seterr(err, errlen, "chunk (%d, %d) does not decode", c->cx, c->cy);
    const uint8_t *data = packed;
    if (packed_len != n) {
        undo_zip_filter(*scratch, n, *scratch + n);
        data = *scratch + n;
    }
    int half = l->pixel == TF_PIXEL_HALF;
    size_t line_bytes = (size_t)c->rect.w * (half ? 16 : 24);
    if (line_bytes * (size_t)c->rect.h != n)
        return tf_seterr(err, errlen, "chunk (%d, %d): %zu bytes for %dx%d pixels", c->cx,
                         c->cy, n, c->rect.w, c->rect.h);
    for (int y = 0; y < c->rect.h; y++) {
        const char *channel;
        long col;
        if (scan_line(data + (size_t)y * line_bytes, c->rect.w, half, &channel, &col))
            return tf_seterr(err, errlen, "channel %s is not finite at pixel (%ld, %d)",
                             channel, c->rect.x + col, c->rect.y + y);
    }
    return 0;
}
