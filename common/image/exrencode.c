/* exrencode.c: see exrencode.h. */
#include "image/exrencode.h"
#include "growbuf.h"

#include <openexr.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "image/exrpart.h"
#include "image/exrzip.h"
#include "image/preview.h"
#include "log.h"

struct tf_exr_encoder {
    exr_context_t ctx;
    tf_exr_zip *zip; /* packs the chunks (libdeflate: exrzip.h) */
    tf_exr_layout layout;
    tf_preview_grid grid;
    const tf_exr_channel *channels;
    int nchannels;
    /* the payload being built */
    uint8_t *index, *chunks, *preview;
    size_t index_cap, chunks_cap, preview_cap;
    size_t nchunks, chunks_len;
    int failed;                 /* out of memory in the capture step */
    int openexr_zlib;           /* tf_exr_encoder_use_openexr_zlib: the benchmark's baseline */
    char last_error[200];
};

static void note_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    (void)code;
    (void)msg; /* reported through the return codes; details are not worth a global */
}

/* The encoder's context writes its header nowhere. */
static int64_t discard_write(exr_const_context_t ctxt, void *userdata, const void *buffer,
                             uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctxt, (void)userdata, (void)buffer, (void)offset, (void)error_cb;
    return (int64_t)sz;
}

/* The pipeline's compress step: the encoder's own packer. */
static exr_result_t zip_chunk(exr_encode_pipeline_t *enc)
{
    tf_exr_encoder *e = enc->encoding_user_data;
    return tf_exr_zip_compress(e->zip, enc);
}

/* The pipeline's last step: instead of writing the chunk to a file, append it to the payload. */
static exr_result_t capture_chunk(exr_encode_pipeline_t *enc)
{
    tf_exr_encoder *e = enc->encoding_user_data;
    const tf_exr_layout *l = &e->layout;
    size_t n = enc->compressed_bytes;
    if (tf_growbuf(&e->index, &e->index_cap, (e->nchunks + 1) * TF_CHUNK_RECORD_BYTES) ||
        tf_growbuf(&e->chunks, &e->chunks_cap, e->chunks_len + n)) {
        e->failed = 1;
        return EXR_ERR_OUT_OF_MEMORY;
    }
    memcpy(e->chunks + e->chunks_len, enc->compressed_buffer, n);
    e->chunks_len += n;
    tf_chunk_rec rec;
    /* OpenEXRCore's tile chunk info holds tile indices in start_x / start_y */
    rec.cx = l->tiled ? enc->chunk.start_x : 0;
    rec.cy = enc->chunk.start_y;
    rec.packed = (int64_t)n;
    rec.unpacked = (int64_t)enc->chunk.unpacked_size;
    tf_chunk_rec_put(e->index + e->nchunks * TF_CHUNK_RECORD_BYTES, &rec);
    e->nchunks++;
    return EXR_ERR_SUCCESS;
}

tf_exr_encoder *tf_exr_encoder_new(const tf_exr_layout *l, char *err, size_t errlen)
{
    if (tf_exr_layout_check(l, err, errlen))
        return NULL;
    tf_exr_encoder *e = calloc(1, sizeof *e);
    if (e)
        e->zip = tf_exr_zip_new(TF_EXR_ZIP_LEVEL);
    if (!e || !e->zip) {
        free(e);
        tf_seterr(err, errlen, "out of memory for the chunk encoder");
        return NULL;
    }
    e->layout = *l;
    e->grid = tf_preview_grid_for(l->width, l->height);
    e->channels = tf_exr_render_channels(l->pixel, &e->nchannels);
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = note_error;
    init.write_fn = discard_write;
    init.user_data = e;
    exr_result_t rv = exr_start_write(&e->ctx, "<chunk encoder>", EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = tf_exr_define_part(e->ctx, l, e->channels, e->nchannels);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_write_header(e->ctx);
    if (rv != EXR_ERR_SUCCESS) {
        tf_seterr(err, errlen, "cannot set up the chunk encoder: %s",
                  exr_get_default_error_message(rv));
        tf_exr_encoder_free(e);
        return NULL;
    }
    return e;
}

void tf_exr_encoder_free(tf_exr_encoder *e)
{
    if (!e)
        return;
    if (e->ctx)
        exr_finish(&e->ctx); /* its "file" is the discarding sink */
    tf_exr_zip_free(e->zip);
    free(e->index);
    free(e->chunks);
    free(e->preview);
    free(e);
}

void tf_exr_encoder_use_openexr_zlib(tf_exr_encoder *e, int on) { e->openexr_zlib = on; }

/* Encode the chunk c of rectangle r (whose pixels px start at r's top-left). */
static exr_result_t encode_chunk(tf_exr_encoder *e, tf_rect r, const tf_pixel *px,
                                 const tf_chunk_ref *c)
{
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    const tf_pixel *origin = px + (size_t)(c->rect.y - r.y) * (size_t)r.w + (c->rect.x - r.x);
    exr_result_t rv = tf_exr_begin_chunk(e->ctx, &e->layout, c, e->channels, e->nchannels,
                                         (const uint8_t *)origin, sizeof(tf_pixel),
                                         sizeof(tf_pixel) * (size_t)r.w, &enc);
    if (rv == EXR_ERR_SUCCESS) {
        enc.encoding_user_data = e;
        enc.yield_until_ready_fn = NULL; /* no file order to wait for: nothing is written here */
        if (!e->openexr_zlib)
            enc.compress_fn = zip_chunk;
        enc.write_fn = capture_chunk;
        rv = exr_encoding_run(e->ctx, 0, &enc);
    }
    if (enc.compress_fn == zip_chunk)
        tf_exr_zip_release(&enc); /* ours; OpenEXRCore frees the buffer of its own step */
    exr_encoding_destroy(e->ctx, &enc);
    return rv;
}

int tf_preview_share(const tf_preview_grid *g, int width, int height, tf_rect r,
                     const tf_pixel *px, uint8_t **buf, size_t *cap, size_t *len)
{
    int i0, i1, j0, j1;
    tf_preview_span(g, width, height, r, &i0, &i1, &j0, &j1);
    size_t n = (size_t)(i1 - i0) * (size_t)(j1 - j0) * 3;
    if (tf_growbuf(buf, cap, n ? n : 1))
        return -1;
    uint8_t *o = *buf;
    for (int j = j0; j < j1; j++) {
        const tf_pixel *row = px + (size_t)(tf_preview_source(g, j, height) - r.y) * (size_t)r.w;
        for (int i = i0; i < i1; i++) {
            const tf_pixel *p = row + (tf_preview_source(g, i, width) - r.x);
            *o++ = tf_srgb8(p->r);
            *o++ = tf_srgb8(p->g);
            *o++ = tf_srgb8(p->b);
        }
    }
    *len = n;
    return 0;
}

int tf_exr_encode_rect(tf_exr_encoder *e, tf_rect r, const tf_pixel *px, tf_chunk_payload *out,
                       char *err, size_t errlen)
{
    int64_t first;
    int count;
    if (tf_layout_rect_chunks(&e->layout, r, &first, &count))
        return tf_seterr(err, errlen, "task %dx%d at %d,%d is not whole chunks of the output",
                         r.w, r.h, r.x, r.y);
    e->nchunks = 0;
    e->chunks_len = 0;
    e->failed = 0;
    for (int i = 0; i < count; i++) {
        tf_chunk_ref c = tf_layout_chunk(&e->layout, first + i);
        exr_result_t rv = encode_chunk(e, r, px, &c);
        if (rv != EXR_ERR_SUCCESS)
            return tf_seterr(err, errlen, "cannot encode chunk (%d, %d): %s", c.cx, c.cy,
                             e->failed ? "out of memory" : exr_get_default_error_message(rv));
    }
    size_t plen = 0;
    if (tf_preview_share(&e->grid, e->layout.width, e->layout.height, r, px, &e->preview,
                         &e->preview_cap, &plen))
        return tf_seterr(err, errlen, "out of memory for the preview");
    out->index = e->index;
    out->nchunks = e->nchunks;
    out->chunks = e->chunks;
    out->chunks_len = e->chunks_len;
    out->preview = e->preview;
    out->preview_len = plen;
    return 0;
}
