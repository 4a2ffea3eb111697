/* fuzzseeds.c: writes the valid seeds of three fuzz corpora, so their replay in `make test`
 * reaches the accept paths and not only the refusals:
 *   CORPUS/seal/    records sealed under tests/fuzz/fuzz_seal.c's fixed key and handshake
 *                   (client to server), holding ordinary frames: one record, several records,
 *                   one frame split over records; and refused_*: a record cut short, one
 *                   with a tag altered, one replayed, a length out of bounds;
 *   CORPUS/result/  fuzz_result.c's header and a result tuple encoded by a real encoder
 *                   (tf_exr_encode_rect of a small gradient, its preview share) for a few
 *                   layouts and tasks: scanline half and float, a whole tile, an edge tile;
 *                   and refused_*: a result for another task, a preview one byte short, a
 *                   chunk whose zlib checksum is wrong (structurally fine: only the
 *                   --verify-chunks walk refuses it);
 *   CORPUS/paint/   fuzz_paint.c's header, a node list made by tf_paint_nodes_put and an
 *                   answer of the length tf_paint_task_values gives, every value in range: a
 *                   sampled node, one with its corners known, an exact node clipped by the
 *                   image's edge; and refused_*: a NaN, an alpha of 2, a sample count of 3,
 *                   the answer a value short, a node of size 3, a node with unknown flags.
 * Every seed is deterministic and small.  Usage: build/tools/fuzzseeds tests/corpus */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "farmproto.h"
#include "paintproto.h"
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

/* plain sealed in one record, twice over (the second copy: a replay), in *out (caller frees);
 * the record's length in *one.  0 or -1. */
static int record_twice(const tf_buf *plain, uint8_t **out, size_t *one)
{
    tf_seal tx = client_tx();
    tf_buf w;
    tf_buf_init(&w);
    *out = NULL;
    if (tf_seal_append(&tx, &w, tf_buf_head(plain), plain->len) == 0 &&
        (*out = malloc(2 * w.len)) != NULL) {
        *one = w.len;
        memcpy(*out, tf_buf_head(&w), w.len);
        memcpy(*out + w.len, tf_buf_head(&w), w.len);
    }
    tf_buf_free(&w);
    return *out ? 0 : -1;
}

/* The refused_* seal seeds: spoiled copies of plain's record. */
static int seal_refusals(const char *dir, const tf_buf *plain)
{
    uint8_t *p;
    size_t one;
    if (record_twice(plain, &p, &one))
        return -1;
    int rc = write_file(dir, "seal", "refused_replayed", p, 2 * one) ||
             write_file(dir, "seal", "refused_truncated", p, one - 1);
    p[one - 1] ^= 0x80; /* the tag's last byte */
    rc = rc || write_file(dir, "seal", "refused_tampered", p, one);
    p[0] = 0x11, p[1] = 0x00, p[2] = 0x01, p[3] = 0x00; /* 65553 = max + 17 */
    rc = rc || write_file(dir, "seal", "refused_length", p, one);
    free(p);
    return rc ? -1 : 0;
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
             seal_seed(dir, "two_records", &plain, plain.len - 9) ||
             seal_refusals(dir, &plain);
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
    tf_render_counts c = {.primary_rays = (uint64_t)r.w * (uint64_t)r.h};
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

enum spoil { SPOIL_NONE, SPOIL_PREVIEW, SPOIL_CHUNK };

/* Flip the last byte (zlib's checksum) of p's first compressed chunk; -1 if none is. */
static int spoil_chunk(tf_chunk_payload *p)
{
    size_t off = 0;
    for (size_t i = 0; i < p->nchunks; i++) {
        tf_chunk_rec c;
        tf_chunk_rec_get(p->index + i * TF_CHUNK_RECORD_BYTES, &c);
        off += (size_t)c.packed;
        if (c.packed < c.unpacked) {
            ((uint8_t *)p->chunks)[off - 1] ^= 0x01; /* the encoder's own buffer */
            return 0;
        }
    }
    return -1;
}

/* The result a worker sends for task r of layout l (a gradient, encoded), as tuple bytes,
 * spoiled as asked. */
static int result_bytes(const tf_exr_layout *l, tf_rect r, enum spoil s, uint8_t **out,
                        size_t *len)
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
    if (s == SPOIL_PREVIEW)
        p.preview_len--;
    rc = rc || (s == SPOIL_CHUNK && spoil_chunk(&p)) || tuple_bytes(r, &p, out, len);
    if (rc)
        fprintf(stderr, "fuzzseeds: cannot encode a result: %s\n", err);
    free(preview);
    free(px);
    tf_exr_encoder_free(e);
    return rc ? -1 : 0;
}

/* A result seed: the result of rectangle r, spoiled as asked, checked against task `task`. */
typedef struct result_spec {
    const char *name;
    tf_exr_layout l;
    tf_rect r, task;
    enum spoil spoil;
} result_spec;

static int result_seed(const char *dir, const result_spec *s)
{
    uint8_t *body;
    size_t len;
    if (result_bytes(&s->l, s->r, s->spoil, &body, &len))
        return -1;
    uint8_t *seed = malloc(15 + len);
    int rc = -1;
    if (seed) {
        put_header(seed, &s->l, s->task);
        memcpy(seed + 15, body, len);
        rc = write_file(dir, "result", s->name, seed, 15 + len);
    }
    free(seed);
    free(body);
    return rc;
}

#define SCAN_HALF {12, 6, 0, 0, 0, TF_PIXEL_HALF}
#define SCAN_FLOAT {5, 4, 0, 0, 0, TF_PIXEL_FLOAT}
#define TILED {10, 7, 1, 4, 4, TF_PIXEL_HALF}
static const result_spec RESULTS[] = {
    {"scanline_half_rows", SCAN_HALF, {0, 2, 12, 3}, {0, 2, 12, 3}, SPOIL_NONE},
    {"scanline_float_all", SCAN_FLOAT, {0, 0, 5, 4}, {0, 0, 5, 4}, SPOIL_NONE},
    {"tiled_whole_tile", TILED, {4, 0, 4, 4}, {4, 0, 4, 4}, SPOIL_NONE},
    {"tiled_edge_tile", TILED, {8, 4, 2, 3}, {8, 4, 2, 3}, SPOIL_NONE},
    {"refused_other_task", SCAN_HALF, {0, 2, 12, 3}, {0, 2, 12, 2}, SPOIL_NONE},
    {"refused_short_preview", SCAN_FLOAT, {0, 0, 5, 4}, {0, 0, 5, 4}, SPOIL_PREVIEW},
    {"refused_chunk_checksum", SCAN_FLOAT, {0, 0, 5, 4}, {0, 0, 5, 4}, SPOIL_CHUNK},
};

static int result_seeds(const char *dir)
{
    for (size_t i = 0; i < sizeof RESULTS / sizeof RESULTS[0]; i++)
        if (result_seed(dir, &RESULTS[i]))
            return -1;
    return 0;
}

/* ---- paint: fuzz_paint.c's input */

enum paint_spoil { PAINT_FINE, PAINT_NAN, PAINT_ALPHA, PAINT_SPP, PAINT_SHORT, PAINT_SIZE,
                   PAINT_FLAGS };

typedef struct paint_spec {
    const char *name;
    enum paint_spoil spoil;
} paint_spec;

/* A value in range for field f of a node's record (exact: a pixel's six floats). */
static float paint_value(size_t i, int exact)
{
    const size_t f = i % (exact ? TF_PAINT_PIXEL_FLOATS : TF_PAINT_SAMPLE_FLOATS);
    if (exact && f == 3)
        return 1.0f;                          /* alpha */
    if (exact && f == 4)
        return 100.0f + (float)(i % 7);       /* depth */
    if (exact && f == 5)
        return 4.0f + (float)(i % 3);         /* samples, aa_depth 3 allows 4 .. 81 */
    return 0.25f + 0.01f * (float)(i % 50);   /* a colour */
}

static int paint_seed(const char *dir, const paint_spec *spec)
{
    const int w = 64, h = 48, aa_depth = 3;
    tf_paint_node nodes[3] = {{0, 0, 16, 4, 0},
                              {16, 0, 16, 8, TF_PAINT_CORNERS_KNOWN},
                              {32, 32, 32, 0, 0}}; /* exact, 32 x 16 inside the image */
    const int count = 3;
    size_t nvalues = tf_paint_task_values(nodes, count, w, h);
    float *v = malloc(nvalues * sizeof *v);
    if (!v)
        return -1;
    size_t at = 0;
    for (int k = 0; k < count; k++) {
        size_t n = tf_paint_node_values(&nodes[k], w, h);
        for (size_t i = 0; i < n; i++)
            v[at + i] = paint_value(i, nodes[k].d == 0);
        at += n;
    }
    const size_t exact_at = nvalues - tf_paint_node_values(&nodes[2], w, h);
    if (spec->spoil == PAINT_NAN)
        v[5] = NAN;
    if (spec->spoil == PAINT_ALPHA)
        v[exact_at + 3] = 2.0f;
    if (spec->spoil == PAINT_SPP)
        v[exact_at + 5] = 3.0f;
    if (spec->spoil == PAINT_SHORT)
        nvalues--;
    uint8_t blob[3 * TF_PAINT_RECORD_BYTES];
    tf_paint_nodes_put(blob, nodes, count);
    if (spec->spoil == PAINT_SIZE)
        blob[8] = 3; /* the first node's s, little-endian */
    if (spec->spoil == PAINT_FLAGS)
        blob[TF_PAINT_RECORD_BYTES + 16] |= 4; /* the second node's flags */
    const size_t len = 7 + sizeof blob + nvalues * sizeof *v;
    uint8_t *seed = malloc(len);
    int rc = -1;
    if (seed) {
        const uint8_t head[7] = {(w - 1) & 255, (w - 1) >> 8, (h - 1) & 255, (h - 1) >> 8,
                                 aa_depth, sizeof blob & 255, sizeof blob >> 8};
        memcpy(seed, head, sizeof head);
        memcpy(seed + 7, blob, sizeof blob);
        memcpy(seed + 7 + sizeof blob, v, nvalues * sizeof *v); /* little-endian floats */
        rc = write_file(dir, "paint", spec->name, seed, len);
    }
    free(seed);
    free(v);
    return rc;
}

static const paint_spec PAINTS[] = {
    {"three_nodes", PAINT_FINE},         {"refused_nan", PAINT_NAN},
    {"refused_alpha", PAINT_ALPHA},      {"refused_sample_count", PAINT_SPP},
    {"refused_short", PAINT_SHORT},      {"refused_node_size", PAINT_SIZE},
    {"refused_node_flags", PAINT_FLAGS},
};

static int paint_seeds(const char *dir)
{
    for (size_t i = 0; i < sizeof PAINTS / sizeof PAINTS[0]; i++)
        if (paint_seed(dir, &PAINTS[i]))
            return -1;
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s CORPUS_DIR   (writes CORPUS_DIR/seal/, /result/ and "
                        "/paint/)\n", argv[0]);
        return 2;
    }
    if (make_dir(argv[1], "seal") || make_dir(argv[1], "result") || make_dir(argv[1], "paint"))
        return 1;
    return seal_seeds(argv[1]) || result_seeds(argv[1]) || paint_seeds(argv[1]) ? 1 : 0;
}
