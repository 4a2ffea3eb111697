/* fuzz_result.c: libFuzzer harness for the checks a worker's result passes before the
 * coordinator writes its chunks (coordinator/render/supervisor.c refuse_result): tf_result_unpack
 * (common/farmproto.c), the structural tf_result_check against the task, the counts bound
 * (tf_result_counts_check), and the pixel check of coordinator/render/resultcheck.c:
 * tf_exr_chunk_check on every chunk (common/image/exrcheck.c: inflate, undo the ZIP filter,
 * scan every value).
 *
 * Input: a 15-byte header, then a result tuple's encoding (tuple.h) as a worker sends it:
 *   u16 width-1, u16 height-1 (little-endian, 1..65536), u8 flags (bit 0 tiled, bit 1 half),
 *   u8 tile_w-1, u8 tile_h-1, u16 x, u16 y, u16 w, u16 h (the task's rectangle)
 * Besides "no crash, leak or hang" it checks: every refusal is one non-empty line; a tuple that
 * unpacks re-packs (tf_result_pack) to the very bytes it came from; an accepted result counts
 * w * h pixels, its chunks' packed sizes add up to the chunks blob, and the pixel check's
 * chunk walk stays inside it, each refusal one line.  Seeds (tests/corpus/result/, made by
 * tests/tools/fuzzseeds.c) are real results encoded by tf_exr_encode_rect, so the replay
 * reaches the accept path, and refused_* ones (another task, a short preview, a chunk that
 * does not inflate) for the refusals. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "farmproto.h"
#include "image/exrcheck.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define HEADER 15

static int u16(const uint8_t *p) { return p[0] | p[1] << 8; }

static void parse_header(const uint8_t *p, tf_exr_layout *l, tf_rect *r)
{
    memset(l, 0, sizeof *l);
    l->width = u16(p) + 1;
    l->height = u16(p + 2) + 1;
    l->tiled = p[4] & 1;
    l->pixel = p[4] & 2 ? TF_PIXEL_HALF : TF_PIXEL_FLOAT;
    l->tile_w = p[5] + 1;
    l->tile_h = p[6] + 1;
    *r = (tf_rect){u16(p + 7), u16(p + 9), u16(p + 11), u16(p + 13)};
}

/* Only a one-line, non-empty reason may explain a refusal. */
static void check_reason(const char *err)
{
    if (err[0] == '\0' || strchr(err, '\n'))
        abort();
}

/* An unpacked result re-packs to the tuple it came from, byte for byte. */
static void check_repack(const tf_result_msg *m, const uint8_t *enc, size_t len)
{
    tf_chunk_payload p = {m->index, m->nchunks, m->chunks, m->chunks_len, m->preview,
                          m->preview_len};
    tf_tuple t;
    if (tf_result_pack(&t, m->id, m->worker, &m->counts, m->busy_ns, m->spp_total, &p))
        abort();
    uint8_t *re = malloc(len ? len : 1);
    if (!re || tf_tuple_encoded_size(&t) != len || tf_tuple_encode(&t, re) != len ||
        memcmp(re, enc, len) != 0)
        abort();
    free(re);
    tf_tuple_clear(&t);
}

/* The pixel check's walk over an accepted result, as coordinator/render/resultcheck.c does it. */
static void walk_chunks(const tf_result_msg *m, const tf_exr_layout *l)
{
    uint8_t *scratch = NULL;
    size_t cap = 0, off = 0;
    char err[256];
    for (size_t i = 0; i < m->nchunks; i++) {
        tf_chunk_rec c;
        tf_chunk_rec_get(m->index + i * TF_CHUNK_RECORD_BYTES, &c);
        if ((uint64_t)c.packed > m->chunks_len - off)
            abort(); /* accepted, yet the chunk runs past the blob */
        int64_t index = tf_layout_chunk_index(l, c.cx, c.cy);
        if (index < 0)
            abort(); /* accepted, yet not one of the output's chunks */
        tf_chunk_ref ref = tf_layout_chunk(l, index);
        err[0] = '\0';
        if (tf_exr_chunk_check(l, &ref, m->chunks + off, (size_t)c.packed, &scratch, &cap, err,
                               sizeof err))
            check_reason(err);
        off += (size_t)c.packed;
    }
    if (off != m->chunks_len)
        abort();
    free(scratch);
}

/* The structural check of m against the task r of layout l. */
static void check_against_task(tf_result_msg *m, const tf_exr_layout *l, tf_rect r)
{
    char err[256] = "";
    if (tf_exr_layout_check(l, err, sizeof err)) {
        check_reason(err);
        return;
    }
    tf_preview_grid g = tf_preview_grid_for(l->width, l->height);
    if (tf_result_check(m, l, &g, r, err, sizeof err)) {
        check_reason(err);
        return;
    }
    if (m->counts.pixels != (uint64_t)r.w * (uint64_t)r.h)
        abort();
    if (tf_result_counts_check(m, r, 3, err, sizeof err))
        check_reason(err);
    walk_chunks(m, l);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < HEADER)
        return 0;
    tf_exr_layout l;
    tf_rect r;
    parse_header(data, &l, &r);
    const uint8_t *enc = data + HEADER;
    size_t len = size - HEADER;
    char err[160] = "";
    tf_tuple t;
    if (tf_tuple_decode(enc, len, &t, 0, err, sizeof err)) {
        check_reason(err);
        return 0;
    }
    tf_result_msg m;
    if (tf_result_unpack(&t, &m) == 0) {
        check_repack(&m, enc, len);
        check_against_task(&m, &l, r);
    }
    tf_tuple_clear(&t);
    return 0;
}
