/* heightmap_tuples.c: see heightmap_tuples.h. */
#include "heightmap_tuples.h"

#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "terrain/eroded.h"

/* The tuple names and the words for messages of one kind of blob. */
typedef struct blob_kind {
    const char *desc, *chunk, *what;
    size_t max_bytes;
} blob_kind;

static const blob_kind HEIGHTMAP = {"heightmap", "heightmap_chunk", "height map",
                                    TF_HEIGHTMAP_MAX_BYTES};
static const blob_kind ERODED = {"eroded", "eroded_chunk", "eroded terrain", TF_ERODED_MAX_BYTES};

static int64_t chunk_count(size_t len)
{
    return (int64_t)((len + TF_HEIGHTMAP_CHUNK_BYTES - 1) / TF_HEIGHTMAP_CHUNK_BYTES);
}

int tf_heightmap_desc_pack(tf_tuple *t, size_t len, const char *sha256_hex)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siis", "heightmap", (int64_t)len, chunk_count(len), sha256_hex);
}

int tf_heightmap_chunk_pack(tf_tuple *t, int64_t index, const uint8_t *data, size_t n)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "sib", "heightmap_chunk", index, (const void *)data, n);
}

static void sha256_hex(const uint8_t *data, size_t len, char out[65])
{
    static const char hex[] = "0123456789abcdef";
    uint8_t h[32];
    if (sodium_init() < 0)
        (void)0; /* hashing needs no entropy */
    crypto_hash_sha256(h, data, len);
    for (int i = 0; i < 32; i++) {
        out[2 * i] = hex[h[i] >> 4];
        out[2 * i + 1] = hex[h[i] & 15];
    }
    out[64] = '\0';
}

static int put_blob(ts_space *space, const blob_kind *k, const uint8_t *data, size_t len,
                    const char *sha256_hex)
{
    tf_tuple t;
    tf_tuple_init(&t);
    if (tf_tuple_pack(&t, "siis", k->desc, (int64_t)len, chunk_count(len), sha256_hex) ||
        ts_space_out(space, &t))
        return -1;
    for (int64_t i = 0; i < chunk_count(len); i++) {
        size_t off = (size_t)i * TF_HEIGHTMAP_CHUNK_BYTES;
        size_t n = len - off < TF_HEIGHTMAP_CHUNK_BYTES ? len - off : TF_HEIGHTMAP_CHUNK_BYTES;
        tf_tuple_init(&t);
        if (tf_tuple_pack(&t, "sib", k->chunk, i, (const void *)(data + off), n) ||
            ts_space_out(space, &t))
            return -1;
    }
    return 0;
}

int tf_heightmap_tuples_put(ts_space *space, const tf_scene *s)
{
    if (s->terrain.generator == TF_GEN_FILE && !s->heightmap)
        return -1; /* tf_scene_load always attaches it: a programming error */
    if (s->terrain.generator == TF_GEN_FILE &&
        put_blob(space, &HEIGHTMAP, s->heightmap, s->heightmap_len, s->terrain.file_sha256))
        return -1;
    if (!s->eroded)
        return 0;
    char hex[65];
    sha256_hex(s->eroded, s->eroded_len, hex);
    return put_blob(space, &ERODED, s->eroded, s->eroded_len, hex);
}

static int is_sha256_hex(const char *s)
{
    return strlen(s) == 64 && strspn(s, "0123456789abcdef") == 64;
}

static int rx_begin(tf_heightmap_rx *rx, const blob_kind *k, const char *from,
                    const tf_tuple *desc, char *err, size_t errlen)
{
    memset(rx, 0, sizeof *rx);
    rx->from = from;
    rx->kind = k;
    int64_t len, chunks;
    const char *sha;
    const char *name = tf_tuple_name(desc);
    if (desc->nfields != 4 || !name || strcmp(name, k->desc) ||
        tf_tuple_get_int(desc, 1, &len) || tf_tuple_get_int(desc, 2, &chunks) ||
        tf_tuple_get_string(desc, 3, &sha) || !is_sha256_hex(sha))
        return tf_seterr(err, errlen, "%s: malformed %s descriptor", from, k->what);
    if (len < 1 || (uint64_t)len > k->max_bytes)
        return tf_seterr(err, errlen, "%s: %s of %lld bytes (at most %zu MiB)", from, k->what,
                         (long long)len, k->max_bytes >> 20);
    if (chunks != chunk_count((size_t)len))
        return tf_seterr(err, errlen, "%s: %s of %lld bytes announced in %lld chunks, "
                         "not %lld", from, k->what, (long long)len, (long long)chunks,
                         (long long)chunk_count((size_t)len));
    rx->buf = malloc((size_t)len);
    if (!rx->buf)
        return tf_seterr(err, errlen, "%s: out of memory for a %lld-byte %s", from,
                         (long long)len, k->what);
    rx->len = (size_t)len;
    rx->chunks = chunks;
    memcpy(rx->sha256, sha, 65);
    return 0;
}

int tf_heightmap_rx_begin(tf_heightmap_rx *rx, const char *from, const tf_tuple *desc,
                          char *err, size_t errlen)
{
    return rx_begin(rx, &HEIGHTMAP, from, desc, err, errlen);
}

int tf_heightmap_rx_chunk(tf_heightmap_rx *rx, const tf_tuple *chunk, char *err, size_t errlen)
{
    const blob_kind *k = rx->kind;
    int64_t index;
    const uint8_t *data;
    size_t n;
    const char *name = tf_tuple_name(chunk);
    if (chunk->nfields != 3 || !name || strcmp(name, k->chunk) ||
        tf_tuple_get_int(chunk, 1, &index) || tf_tuple_get_blob(chunk, 2, &data, &n))
        return tf_seterr(err, errlen, "%s: malformed %s chunk %lld", rx->from, k->what,
                         (long long)rx->next);
    if (index != rx->next || rx->next >= rx->chunks)
        return tf_seterr(err, errlen, "%s: %s chunk %lld where chunk %lld of %lld was "
                         "expected", rx->from, k->what, (long long)index, (long long)rx->next,
                         (long long)rx->chunks);
    size_t want = rx->len - rx->got < TF_HEIGHTMAP_CHUNK_BYTES ? rx->len - rx->got
                                                               : TF_HEIGHTMAP_CHUNK_BYTES;
    if (n != want)
        return tf_seterr(err, errlen, "%s: %s chunk %lld has %zu bytes, expected %zu",
                         rx->from, k->what, (long long)index, n, want);
    memcpy(rx->buf + rx->got, data, n);
    rx->got += n;
    rx->next++;
    return 0;
}

int tf_heightmap_rx_finish(tf_heightmap_rx *rx, uint8_t **data, size_t *len, char *err,
                           size_t errlen)
{
    const blob_kind *k = rx->kind;
    if (rx->next != rx->chunks || rx->got != rx->len)
        return tf_seterr(err, errlen, "%s: %s incomplete (%lld of %lld chunks)", rx->from,
                         k->what, (long long)rx->next, (long long)rx->chunks);
    char got[65];
    sha256_hex(rx->buf, rx->len, got);
    if (strcmp(got, rx->sha256))
        return tf_seterr(err, errlen, "%s: %s damaged in transfer: SHA-256 %.16s..., "
                         "announced %.16s...", rx->from, k->what, got, rx->sha256);
    *data = rx->buf;
    *len = rx->len;
    rx->buf = NULL;
    return 0;
}

void tf_heightmap_rx_free(tf_heightmap_rx *rx)
{
    free(rx->buf);
    rx->buf = NULL;
}

/* Read one blob of kind k from the space (rd: it stays for the next worker).  0 and *data
 * (malloc'd), or -1 with one line naming `from`. */
static int fetch_blob(ts_client *c, const blob_kind *k, const char *from, uint8_t **data,
                      size_t *len, char *err, size_t errlen)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    tf_heightmap_rx rx = {0};
    int rc = -1;
    if (tf_tuple_pack(&tmpl, "sIIS", k->desc) || ts_rd(c, &tmpl, &got)) {
        tf_seterr(err, errlen, "%s: cannot read the %s: %s", from, k->what, ts_client_error(c));
        goto out;
    }
    if (rx_begin(&rx, k, from, &got, err, errlen))
        goto out;
    for (int64_t i = 0; i < rx.chunks; i++) {
        tf_tuple_clear(&tmpl);
        tf_tuple_clear(&got);
        if (tf_tuple_pack(&tmpl, "siB", k->chunk, i) || ts_rd(c, &tmpl, &got)) {
            tf_seterr(err, errlen, "%s: cannot read %s chunk %lld: %s", from, k->what,
                      (long long)i, ts_client_error(c));
            goto out;
        }
        if (tf_heightmap_rx_chunk(&rx, &got, err, errlen))
            goto out;
    }
    rc = tf_heightmap_rx_finish(&rx, data, len, err, errlen);
out:
    tf_heightmap_rx_free(&rx);
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return rc;
}

int tf_heightmap_fetch(ts_client *c, tf_scene *s, const char *coordinator, char *err,
                       size_t errlen)
{
    uint8_t *data;
    size_t len;
    if (s->terrain.generator == TF_GEN_FILE) {
        if (fetch_blob(c, &HEIGHTMAP, coordinator, &data, &len, err, errlen))
            return -1;
        char name[300];
        snprintf(name, sizeof name, "%s (from %s)", s->terrain.file_path, coordinator);
        if (tf_scene_attach_heightmap(s, data, len, name, err, errlen))
            return -1;
    }
    return 0;
}

int tf_eroded_fetch(ts_client *c, tf_scene *s, const char *coordinator, char *err,
                    size_t errlen)
{
    uint8_t *data;
    size_t len;
    if (s->terrain.erosion.fluvial_steps <= 0)
        return 0;
    if (fetch_blob(c, &ERODED, coordinator, &data, &len, err, errlen))
        return -1;
    char name[300];
    snprintf(name, sizeof name, "the eroded terrain from %s", coordinator);
    if (tf_scene_attach_eroded(s, data, len, name) != 0)
        return tf_seterr(err, errlen, "out of memory");
    return 0;
}
