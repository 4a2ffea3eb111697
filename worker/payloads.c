/* payloads.c: see payloads.h. */
#include "worker/payloads.h"
#include "growbuf.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "image/exrencode.h"
#include "image/exrfile.h"
#include "image/preview.h"
#include "log.h"

typedef struct rec_chunk {
    uint8_t *packed;
    size_t len;
    tf_rect rect;
    int64_t spp_total;
} rec_chunk;

struct tf_payloads {
    tf_exr_layout layout;
    rec_chunk *chunks;         /* in file order */
    int64_t nchunks;
    uint8_t *rgb;              /* width * height * 3: the recording, tone-mapped */
    uint64_t packed_total;
};

typedef struct loader {
    tf_payloads *p;
    char err[256];
} loader;

static int keep_chunk(void *user, const tf_chunk_ref *c, const uint8_t *packed, size_t len,
                      const tf_pixel *px)
{
    loader *ld = user;
    tf_payloads *p = ld->p;
    int64_t i = tf_layout_chunk_index(&p->layout, c->cx, c->cy);
    if (i < 0 || i >= p->nchunks)
        return -1;
    rec_chunk *rc = &p->chunks[i];
    rc->packed = malloc(len);
    if (!rc->packed) {
        snprintf(ld->err, sizeof ld->err, "out of memory");
        return -1;
    }
    memcpy(rc->packed, packed, len);
    rc->len = len;
    rc->rect = c->rect;
    double spp = 0;
    int w = p->layout.width;
    for (int y = 0; y < c->rect.h; y++)
        for (int x = 0; x < c->rect.w; x++) {
            const tf_pixel *q = &px[(size_t)y * (size_t)c->rect.w + (size_t)x];
            uint8_t *o = p->rgb + (((size_t)(c->rect.y + y) * (size_t)w) + (size_t)(c->rect.x + x)) * 3;
            o[0] = tf_srgb8(q->r);
            o[1] = tf_srgb8(q->g);
            o[2] = tf_srgb8(q->b);
            spp += q->spp;
        }
    rc->spp_total = (int64_t)spp;
    p->packed_total += len;
    return 0;
}

tf_payloads *tf_payloads_load(const char *path, char *err, size_t errlen)
{
    tf_exr_meta meta;
    int rows = 0, complete = 0;
    if (tf_exr_probe(path, &meta, &rows, &complete, err, errlen) != 0) {
        if (err && errlen && !err[0])
            tf_seterr(err, errlen, "%s: no such file", path);
        return NULL;
    }
    if (!complete) {
        tf_seterr(err, errlen, "%s: a recording must be a finished render (%d of %d rows)", path,
                  rows, meta.height);
        return NULL;
    }
    tf_payloads *p = calloc(1, sizeof *p);
    if (!p) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    p->layout = tf_exr_meta_layout(&meta);
    p->nchunks = tf_layout_chunk_count(&p->layout);
    p->chunks = calloc((size_t)p->nchunks, sizeof *p->chunks);
    p->rgb = malloc((size_t)meta.width * (size_t)meta.height * 3);
    if (!p->chunks || !p->rgb) {
        tf_payloads_free(p);
        tf_seterr(err, errlen, "out of memory for the recording %s", path);
        return NULL;
    }
    loader ld = {p, ""};
    int64_t valid = 0;
    char e[512];
    if (tf_exr_read_packed_chunks(path, &meta, &valid, keep_chunk, &ld, e, sizeof e) ||
        valid != p->nchunks) {
        tf_seterr(err, errlen, "%s: cannot load the recording: %s", path, ld.err[0] ? ld.err : e);
        tf_payloads_free(p);
        return NULL;
    }
    return p;
}

void tf_payloads_free(tf_payloads *p)
{
    if (!p)
        return;
    for (int64_t i = 0; p->chunks && i < p->nchunks; i++)
        free(p->chunks[i].packed);
    free(p->chunks);
    free(p->rgb);
    free(p);
}


int tf_payloads_fit(const tf_payloads *p, const tf_exr_layout *l, char *err, size_t errlen)
{
    const tf_exr_layout *r = &p->layout;
    char a[64], b[64];
    tf_exr_layout_format(r, a, sizeof a);
    tf_exr_layout_format(l, b, sizeof b);
    if (r->tiled != l->tiled || r->pixel != l->pixel ||
        (r->tiled && (r->tile_w != l->tile_w || r->tile_h != l->tile_h)) ||
        (!r->tiled && r->width != l->width))
        return tf_seterr(err, errlen, "the recording is '%s' %dx%d, the render '%s' %dx%d: its "
                         "chunks cannot stand in (record a render of the same --tasks, --pixel%s)",
                         a, r->width, r->height, b, l->width, l->height,
                         r->tiled ? "" : " and width");
    return 0;
}

int tf_payloads_for(const tf_payloads *p, const tf_exr_layout *l, tf_rect r, tf_payload_buf *b,
                    tf_chunk_payload *out, int64_t *spp_total, char *err, size_t errlen)
{
    int64_t first;
    int count;
    if (tf_layout_rect_chunks(l, r, &first, &count))
        return tf_seterr(err, errlen, "task %dx%d at %d,%d is not whole chunks", r.w, r.h, r.x,
                         r.y);
    int nx = tf_layout_chunks_x(l), ny = tf_layout_chunks_y(l);
    int rx = tf_layout_chunks_x(&p->layout), ry = tf_layout_chunks_y(&p->layout);
    size_t len = 0;
    *spp_total = 0;
    if (tf_growbuf(&b->index, &b->index_cap, (size_t)count * TF_CHUNK_RECORD_BYTES))
        return tf_seterr(err, errlen, "out of memory");
    for (int i = 0; i < count; i++) {
        tf_chunk_ref c = tf_layout_chunk(l, first + i);
        int64_t ri = tf_layout_chunk_index(&p->layout, (int)((int64_t)c.cx * rx / nx),
                                           (int)((int64_t)c.cy * ry / ny));
        const rec_chunk *rc = &p->chunks[ri];
        if (rc->rect.w != c.rect.w || rc->rect.h != c.rect.h)
            return tf_seterr(err, errlen, "no recorded chunk of %dx%d for chunk (%d, %d) (size "
                             "the render in whole tiles of the recording)", c.rect.w, c.rect.h,
                             c.cx, c.cy);
        if (tf_growbuf(&b->chunks, &b->chunks_cap, len + rc->len))
            return tf_seterr(err, errlen, "out of memory");
        memcpy(b->chunks + len, rc->packed, rc->len);
        len += rc->len;
        tf_chunk_rec rec = {c.cx, c.cy, (int64_t)rc->len, (int64_t)c.unpacked};
        tf_chunk_rec_put(b->index + (size_t)i * TF_CHUNK_RECORD_BYTES, &rec);
        *spp_total += rc->spp_total;
    }
    /* the preview share, sampled from the recording at the same relative place */
    tf_preview_grid g = tf_preview_grid_for(l->width, l->height);
    int i0, i1, j0, j1;
    tf_preview_span(&g, l->width, l->height, r, &i0, &i1, &j0, &j1);
    size_t plen = (size_t)(i1 - i0) * (size_t)(j1 - j0) * 3;
    if (tf_growbuf(&b->preview, &b->preview_cap, plen ? plen : 1))
        return tf_seterr(err, errlen, "out of memory");
    uint8_t *o = b->preview;
    for (int j = j0; j < j1; j++) {
        int64_t sy = (int64_t)tf_preview_source(&g, j, l->height) * p->layout.height / l->height;
        for (int i = i0; i < i1; i++) {
            int64_t sx = (int64_t)tf_preview_source(&g, i, l->width) * p->layout.width / l->width;
            memcpy(o, p->rgb + ((size_t)sy * (size_t)p->layout.width + (size_t)sx) * 3, 3);
            o += 3;
        }
    }
    out->index = b->index;
    out->nchunks = (size_t)count;
    out->chunks = b->chunks;
    out->chunks_len = len;
    out->preview = b->preview;
    out->preview_len = plen;
    return 0;
}

void tf_payload_buf_free(tf_payload_buf *b)
{
    free(b->index);
    free(b->chunks);
    free(b->preview);
    memset(b, 0, sizeof *b);
}
