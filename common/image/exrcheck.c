/* exrcheck.c: see exrcheck.h.  The reconstruction after inflating is OpenEXR's own for ZIP and
 * ZIPS (the delta predictor undone; the two halves of the byte split are read where they lie,
 * not interleaved); the value scan knows the channel types of exrpart.c: R G B A half or
 * float, Z and spp float. */
#include "image/exrcheck.h"
#include "growbuf.h"

#include <libdeflate.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "log.h"

int tf_exr_chunk_decodes(const uint8_t *packed, size_t packed_len, size_t unpacked,
                         uint8_t **scratch, size_t *cap)
{
    if (packed_len == 0 || packed_len > unpacked)
        return -1;
    if (packed_len == unpacked)
        return 0; /* stored raw */
    if (tf_growbuf(scratch, cap, unpacked))
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

/* OpenEXR's delta predictor undone in place: p[i] = p[i - 1] + p[i] - 128 for i >= 1, a
 * running byte sum.  With SSE2 (every x86-64), 16 bytes at once: their sum within the block by
 * four shifted adds, then the running total of the blocks before added to every lane (the
 * serial loop was half of the coordinator's check of a networked chunk, ~1 cycle a byte).  The
 * total is kept in a register and grows by each block's own last sum, which does not wait for
 * the total: the only chain from block to block is one add (reading the total back from the
 * stored block put a store and a load on that chain). */
#ifdef __SSE2__
static inline __m128i broadcast_last_byte(__m128i v)
{
    __m128i w = _mm_unpackhi_epi8(v, v);    /* word 7 = (byte 15, byte 15) */
    w = _mm_shufflehi_epi16(w, 0xff);       /* words 4-7 = word 7 */
    return _mm_shuffle_epi32(w, 0xff);      /* every dword = dword 3 */
}
#endif

void tf_exr_undo_delta(uint8_t *p, size_t n)
{
    size_t i = 1;
#ifdef __SSE2__
    if (n > 16) {
        const __m128i flip = _mm_set1_epi8((char)0x80); /* - 128 mod 256 */
        __m128i total = _mm_set1_epi8((char)p[0]);
        for (; i + 16 <= n; i += 16) {
            __m128i v = _mm_xor_si128(_mm_loadu_si128((const __m128i *)(p + i)), flip);
            v = _mm_add_epi8(v, _mm_slli_si128(v, 1));
            v = _mm_add_epi8(v, _mm_slli_si128(v, 2));
            v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
            v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
            _mm_storeu_si128((__m128i *)(p + i), _mm_add_epi8(v, total));
            total = _mm_add_epi8(total, broadcast_last_byte(v));
        }
    }
#endif
    for (; i < n; i++)
        p[i] = (uint8_t)(p[i - 1] + p[i] - 128);
}

/* The bytes of a chunk as the scan reads them: `split` after inflating (OpenEXR's byte split
 * left as it is: the even bytes of the chunk first, then the odd ones, so the scan needs no
 * interleaved copy), else raw. */
typedef struct chunk_bytes {
    const uint8_t *even, *odd; /* split: byte 2k is even[k], byte 2k+1 is odd[k] */
    const uint8_t *raw;
    int split;
} chunk_bytes;

/* Where byte o of the chunk is, and the step between bytes o, o + step, o + 2 step, ... (step
 * even) as a stride in memory. */
static const uint8_t *byte_at(const chunk_bytes *b, size_t o, size_t step, size_t *stride)
{
    if (!b->split) {
        *stride = step;
        return b->raw + o;
    }
    *stride = step / 2;
    return (o & 1) ? b->odd + o / 2 : b->even + o / 2;
}

/* The scans below look at SCAN_BLOCK values at a time with no early exit, which the compiler
 * turns into vector compares, and go value by value only in a block that holds a bad one (to
 * name it).  In a split chunk (every ZIP chunk that shrank) a half's high bytes lie one after
 * another and a float's two high bytes two apart; a raw chunk goes value by value. */
#define SCAN_BLOCK 64

static int block_has_bad_half(const uint8_t *hi)
{
    unsigned bad = 0;
    for (int k = 0; k < SCAN_BLOCK; k++)
        bad |= (hi[k] & 0x7c) == 0x7c;
    return bad != 0;
}

/* b3 and b2: the two high bytes of SCAN_BLOCK floats, each two bytes from the next.  Read as
 * 16-bit words whose low byte they are (little-endian), so the loop needs no byte shuffles. */
typedef uint16_t u16_unaligned __attribute__((aligned(1), may_alias));

static int block_has_bad_float(const uint8_t *b3, const uint8_t *b2)
{
    unsigned bad = 0;
#if __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    const u16_unaligned *w3 = (const u16_unaligned *)b3, *w2 = (const u16_unaligned *)b2;
    for (int k = 0; k < SCAN_BLOCK; k++)
        bad |= ((w3[k] & 0x7f) == 0x7f) & ((w2[k] & 0x80) == 0x80);
#else
    for (int k = 0; k < SCAN_BLOCK; k++)
        bad |= ((b3[2 * k] & 0x7f) == 0x7f) & ((b2[2 * k] & 0x80) == 0x80);
#endif
    return bad != 0;
}

/* Index of the first non-finite value among n little-endian halves or floats starting at
 * (even) byte o of the chunk, or -1: a half's exponent bits in its high byte, a float's in its
 * two high bytes. */
static long first_bad_half(const chunk_bytes *b, size_t o, size_t n)
{
    size_t s, i = 0;
    const uint8_t *hi = byte_at(b, o + 1, 2, &s);
    if (s == 1)
        while (i + SCAN_BLOCK <= n && !block_has_bad_half(hi + i))
            i += SCAN_BLOCK;
    for (; i < n; i++)
        if ((hi[i * s] & 0x7c) == 0x7c)
            return (long)i;
    return -1;
}

static long first_bad_float(const chunk_bytes *b, size_t o, size_t n)
{
    size_t s, i = 0;
    const uint8_t *b3 = byte_at(b, o + 3, 4, &s), *b2 = byte_at(b, o + 2, 4, &s);
    /* < n, not <= n: a block's words end one byte past its last float's high byte, which is
     * a byte of the float after it (the chunk's last float is always looked at alone) */
    if (s == 2)
        while (i + SCAN_BLOCK < n && !block_has_bad_float(b3 + 2 * i, b2 + 2 * i))
            i += SCAN_BLOCK;
    for (; i < n; i++)
        if ((b3[i * s] & 0x7f) == 0x7f && (b2[i * s] & 0x80))
            return (long)i;
    return -1;
}

/* Scan the line of w pixels at byte o; 0, or -1 with the channel and column of a bad value. */
static int scan_line(const chunk_bytes *b, size_t o, int w, int half, const char **channel,
                     long *col)
{
    static const char *const names[] = {"A", "B", "G", "R", "Z", "spp"};
    size_t colour = half ? 2 : 4;
    for (int ch = 0; ch < 6; ch++) {
        int is_half = half && ch < 4;
        *col = is_half ? first_bad_half(b, o, (size_t)w) : first_bad_float(b, o, (size_t)w);
        if (*col >= 0) {
            *channel = names[ch];
            return -1;
        }
        o += (size_t)w * (ch < 4 ? colour : 4);
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
    chunk_bytes b = {NULL, NULL, packed, 0};
    if (packed_len != n) {
        tf_exr_undo_delta(*scratch, n);
        b = (chunk_bytes){*scratch, *scratch + (n + 1) / 2, NULL, 1};
    }
    int half = l->pixel == TF_PIXEL_HALF;
    size_t line_bytes = (size_t)c->rect.w * (half ? 16 : 24);
    if (line_bytes * (size_t)c->rect.h != n)
        return tf_seterr(err, errlen, "chunk (%d, %d): %zu bytes for %dx%d pixels", c->cx,
                         c->cy, n, c->rect.w, c->rect.h);
    for (int y = 0; y < c->rect.h; y++) {
        const char *channel;
        long col;
        if (scan_line(&b, (size_t)y * line_bytes, c->rect.w, half, &channel, &col))
            return tf_seterr(err, errlen, "channel %s is not finite at pixel (%ld, %d)",
                             channel, c->rect.x + col, c->rect.y + y);
    }
    return 0;
}
