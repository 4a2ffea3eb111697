/* fuzzseeds.c: writes the valid seeds of two fuzz corpora, so their replay in `make test`
 * reaches the accept paths and not only the refusals:
 *   CORPUS/seal/    records sealed under tests/fuzz/fuzz_seal.c's fixed key and handshake
 *                   (client to server), holding ordinary frames: one record, several records,
 *                   one frame split over records;
 *   CORPUS/result/  fuzz_result.c's header and a result tuple encoded by a real encoder
 *                   (tf_exr_encode_rect of a small gradient, its preview share) for a few
 *                   layouts and tasks: scanline half and float, a whole tile, an edge tile.
 * Every seed is deterministic and small.  Usage: build/tools/fuzzseeds tests/corpus */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "farmproto.h"
#include "image/exrencode.h"
#include "linda/seal.h"

/* DIR/SUB made if it is not there; 0 or -1. */
static int make_dir(const char *dir, const char *sub)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, sub);
    if (mkdir(path, 0755) == 0 || errno == EEXIST)
        return 0;
    fprintf(stderr, "fuzzseeds: cannot create %s: %s\n", path, strerror(errno));
    return -1;
}

static int write_file(const char *dir, const char *sub, const char *name, const uint8_t *p,
                      size_t n)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/%s/%s", dir, sub, name);
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(p, 1, n, f) == n;
    if (f && fclose(f) != 0)
        ok = 0;
    if (!ok)
        fprintf(stderr, "fuzzseeds: cannot write %s\n", path);
    return ok ? 0 : -1;
}

/* The client's sending state under fuzz_seal.c's key and nonces. */
static tf_seal client_tx(void)
{
    uint8_t key[TF_KEY_BYTES], ns[TF_NONCE_BYTES], nc[TF_NONCE_BYTES];
    tf_seal tx, rx;
    memset(key, 0x4b, sizeof key);
    memset(ns, 0x53, sizeof ns);
    memset(nc, 0x43, sizeof nc);
    tf_seal_init(key, ns, nc, 1, &tx, &rx);
    return tx;
}

/* A seal seed: the frames of `plain`, sealed in pieces of `piece` bytes. */
static int seal_seed(const char *dir, const char *name, const tf_buf *plain, size_t piece)
{
    tf_seal tx = client_tx();
    tf_buf wire;
    tf_buf_init(&wire);
    int rc = 0;
    for (size_t off = 0; off < plain->len && rc == 0; off += piece) {
        size_t n = plain->len - off < piece ? plain->len - off : piece;
        rc = tf_seal_append(&tx, &wire, tf_buf_head(plain) + off, n);
    }
    if (rc == 0)
        rc = write_file(dir, "seal", name, tf_buf_head(&wire), wire.len);
    tf_buf_free(&wire);
    return rc;
}

static int seal_seeds(const char *dir)
{
    tf_buf plain;
    tf_tuple t;
    tf_buf_init(&plain);
    tf_tuple_init(&t);
    int rc = tf_tuple_pack(&t, "sii", "task", (int64_t)7, (int64_t)-1) ||
             tf_frame_append_tuple(&plain, TF_OP_OUT, 1, &t) ||
             tf_frame_append_raw(&plain, TF_OP_PING, 2, NULL, 0);
    if (rc == 0)
        rc = seal_seed(dir, "one_record", &plain, plain.len) ||
             seal_seed(dir, "records_of_7", &plain, 7) ||
             seal_seed(dir, "two_records", &plain, plain.len - 9);
    tf_tuple_clear(&t);
    tf_buf_free(&plain);
    return rc ? -1 : 0;
}

/* fuzz_result.c's header: layout l and task rectangle r. */
static void put_header(uint8_t *h, const tf_exr_layout *l, tf_rect r)
{
    int v[] = {l->width - 1, l->height - 1, r.x, r.y, r.w, r.h};
    uint8_t *at[] = {h, h + 2, h + 7, h + 9, h + 11, h + 13};
    for (int i = 0; i < 6; i++) {
        at[i][0] = (uint8_t)v[i];
        at[i][1] = (uint8_t)(v[i] >> 8);
    }
    h[4] = (uint8_t)((l->tiled ? 1 : 0) | (l->pixel == TF_PIXEL_HALF ? 2 : 0));
    h[5] = (uint8_t)(l->tile_w - 1);
    h[6] = (uint8_t)(l->tile_h - 1);
}

/* A small gradient over rectangle r (the encoder's input). */
static tf_pixel *gradient(tf_rect r)
{
    tf_pixel *px = calloc((size_t)r.w * (size_t)r.h, sizeof *px);
    for (int j = 0; px && j < r.h; j++)
        for (int i = 0; i < r.w; i++)
            px[(size_t)j * (size_t)r.w + (size_t)i] =
                (tf_pixel){(float)(r.x + i) / 16, (float)(r.y + j) / 16, 0.5f, 1, 100, 4};
    return px;
}

/* The encoding of the result tuple of payload p for task r, in *out (caller frees); 0 or -1. */
static int tuple_bytes(tf_rect r, const tf_chunk_payload *p, uint8_t **out, size_t *len)
{
    tf_render_counts c = {(uint64_t)r.w * (uint64_t)r.h, 0, 0, 0};
    tf_tuple t;
    tf_tuple_init(&t);
    int rc = tf_result_pack(&t, 3, 1, &c, 1000, 4 * (int64_t)c.primary_rays, p);
    *len = rc ? 0 : tf_tuple_encoded_size(&t);
    *out = rc ? NULL : malloc(*len);
    if (*out)
        tf_tuple_encode(&t, *out);
    tf_tuple_clear(&t);
    return *out ? 0 : -1;
}

/* The result a worker sends for task r of layout l (a gradient, encoded), as tuple bytes. */
static int result_bytes(const tf_exr_layout *l, tf_rect r, uint8_t **out, size_t *len)
{
    char err[256] = "out of memory";
    tf_exr_encoder *e = tf_exr_encoder_new(l, err, sizeof err);
    tf_pixel *px = gradient(r);
    tf_chunk_payload p;
    uint8_t *preview = NULL;
    size_t cap = 0;
    tf_preview_grid g = tf_preview_grid_for(l->width, l->height);
    int rc = !e || !px || tf_exr_encode_rect(e, r, px, &p, err, sizeof err) ||
             tf_preview_share(&g, l->width, l->height, r, px, &preview, &cap, &p.preview_len);
    p.preview = preview;
    rc = rc || tuple_bytes(r, &p, out, len);
    if (rc)
        fprintf(stderr, "fuzzseeds: cannot encode a result: %s\n", err);
    free(preview);
    free(px);
    tf_exr_encoder_free(e);
    return rc ? -1 : 0;
}

static int result_seed(const char *dir, const char *name, tf_exr_layout l, tf_rect r)
{
    uint8_t *body;
    size_t len;
    if (result_bytes(&l, r, &body, &len))
        return -1;
    uint8_t *seed = malloc(15 + len);
    int rc = -1;
    if (seed) {
        put_header(seed, &l, r);
        memcpy(seed + 15, body, len);
        rc = write_file(dir, "result", name, seed, 15 + len);
    }
    free(seed);
    free(body);
    return rc;
}

static int result_seeds(const char *dir)
{
    tf_exr_layout scan_half = {12, 6, 0, 0, 0, TF_PIXEL_HALF};
    tf_exr_layout scan_float = {5, 4, 0, 0, 0, TF_PIXEL_FLOAT};
    tf_exr_layout tiled = {10, 7, 1, 4, 4, TF_PIXEL_HALF};
    return result_seed(dir, "scanline_half_rows", scan_half, (tf_rect){0, 2, 12, 3}) ||
           result_seed(dir, "scanline_float_all", scan_float, (tf_rect){0, 0, 5, 4}) ||
           result_seed(dir, "tiled_whole_tile", tiled, (tf_rect){4, 0, 4, 4}) ||
           result_seed(dir, "tiled_edge_tile", tiled, (tf_rect){8, 4, 2, 3})
               ? -1
               : 0;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s CORPUS_DIR   (writes CORPUS_DIR/seal/ and /result/)\n",
                argv[0]);
        return 2;
    }
    if (make_dir(argv[1], "seal") || make_dir(argv[1], "result"))
        return 1;
    return seal_seeds(argv[1]) || result_seeds(argv[1]) ? 1 : 0;
}
