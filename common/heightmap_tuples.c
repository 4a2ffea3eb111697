/* heightmap_tuples.c: see heightmap_tuples.h. */
#include "heightmap_tuples.h"

#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

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

int tf_heightmap_tuples_put(ts_space *space, const tf_scene *s)
{
    if (s->terrain.generator != TF_GEN_FILE)
        return 0;
    if (!s->heightmap)
        return -1; /* tf_scene_load always attaches it: a programming error */
    tf_tuple t;
    if (tf_heightmap_desc_pack(&t, s->heightmap_len, s->terrain.file_sha256) ||
        ts_space_out(space, &t))
        return -1;
    for (int64_t i = 0; i < chunk_count(s->heightmap_len); i++) {
        size_t off = (size_t)i * TF_HEIGHTMAP_CHUNK_BYTES;
        size_t n = s->heightmap_len - off < TF_HEIGHTMAP_CHUNK_BYTES ? s->heightmap_len - off
                                                                      : TF_HEIGHTMAP_CHUNK_BYTES;
        if (tf_heightmap_chunk_pack(&t, i, s->heightmap + off, n) || ts_space_out(space, &t))
            return -1;
    }
    return 0;
}

static int is_sha256_hex(const char *s)
{
    return strlen(s) == 64 && strspn(s, "0123456789abcdef") == 64;
}

int tf_heightmap_rx_begin(tf_heightmap_rx *rx, const char *from, const tf_tuple *desc,
                          char *err, size_t errlen)
{
    memset(rx, 0, sizeof *rx);
    rx->from = from;
    int64_t len, chunks;
    const char *sha;
    const char *name = tf_tuple_name(desc);
    if (desc->nfields != 4 || !name || strcmp(name, "heightmap") ||
        tf_tuple_get_int(desc, 1, &len) || tf_tuple_get_int(desc, 2, &chunks) ||
        tf_tuple_get_string(desc, 3, &sha) || !is_sha256_hex(sha))
        return tf_seterr(err, errlen, "%s: malformed height map descriptor", from);
    if (len < 1 || (uint64_t)len > TF_HEIGHTMAP_MAX_BYTES)
        return tf_seterr(err, errlen, "%s: height map of %lld bytes (at most %zu MiB)", from,
                         (long long)len, TF_HEIGHTMAP_MAX_BYTES >> 20);
    if (chunks != chunk_count((size_t)len))
        return tf_seterr(err, errlen, "%s: height map of %lld bytes announced in %lld chunks, "
                         "not %lld", from, (long long)len, (long long)chunks,
                         (long long)chunk_count((size_t)len));
    rx->buf = malloc((size_t)len);
    if (!rx->buf)
        return tf_seterr(err, errlen, "%s: out of memory for a %lld-byte height map", from,
                         (long long)len);
    rx->len = (size_t)len;
    rx->chunks = chunks;
    memcpy(rx->sha256, sha, 65);
    return 0;
}

int tf_heightmap_rx_chunk(tf_heightmap_rx *rx, const tf_tuple *chunk, char *err, size_t errlen)
{
    int64_t index;
    const uint8_t *data;
    size_t n;
    const char *name = tf_tuple_name(chunk);
    if (chunk->nfields != 3 || !name || strcmp(name, "heightmap_chunk") ||
        tf_tuple_get_int(chunk, 1, &index) || tf_tuple_get_blob(chunk, 2, &data, &n))
        return tf_seterr(err, errlen, "%s: malformed height map chunk %lld", rx->from,
                         (long long)rx->next);
    if (index != rx->next || rx->next >= rx->chunks)
        return tf_seterr(err, errlen, "%s: height map chunk %lld where chunk %lld of %lld was "
                         "expected", rx->from, (long long)index, (long long)rx->next,
                         (long long)rx->chunks);
    size_t want = rx->len - rx->got < TF_HEIGHTMAP_CHUNK_BYTES ? rx->len - rx->got
                                                               : TF_HEIGHTMAP_CHUNK_BYTES;
    if (n != want)
        return tf_seterr(err, errlen, "%s: height map chunk %lld has %zu bytes, expected %zu",
                         rx->from, (long long)index, n, want);
    memcpy(rx->buf + rx->got, data, n);
    rx->got += n;
    rx->next++;
    return 0;
}

int tf_heightmap_rx_finish(tf_heightmap_rx *rx, uint8_t **data, size_t *len, char *err,
                           size_t errlen)
{
    if (rx->next != rx->chunks || rx->got != rx->len)
        return tf_seterr(err, errlen, "%s: height map incomplete (%lld of %lld chunks)", rx->from,
                         (long long)rx->next, (long long)rx->chunks);
    static const char hex[] = "0123456789abcdef";
    uint8_t h[32];
    char got[65];
    if (sodium_init() < 0)
        (void)0; /* hashing needs no entropy */
    crypto_hash_sha256(h, rx->buf, rx->len);
    for (int i = 0; i < 32; i++) {
        got[2 * i] = hex[h[i] >> 4];
        got[2 * i + 1] = hex[h[i] & 15];
    }
    got[64] = '\0';
    if (strcmp(got, rx->sha256))
        return tf_seterr(err, errlen, "%s: height map damaged in transfer: SHA-256 %.16s..., "
                         "announced %.16s...", rx->from, got, rx->sha256);
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

int tf_heightmap_fetch(ts_client *c, tf_scene *s, const char *coordinator, char *err,
                       size_t errlen)
{
    if (s->terrain.generator != TF_GEN_FILE)
        return 0;
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    tf_heightmap_rx rx = {0};
    int rc = -1;
    if (tf_tuple_pack(&tmpl, "sIIS", "heightmap") || ts_rd(c, &tmpl, &got)) {
        tf_seterr(err, errlen, "%s: cannot read the height map: %s", coordinator,
                  ts_client_error(c));
        goto out;
    }
    if (tf_heightmap_rx_begin(&rx, coordinator, &got, err, errlen))
        goto out;
    for (int64_t i = 0; i < rx.chunks; i++) {
        tf_tuple_clear(&tmpl);
        tf_tuple_clear(&got);
        if (tf_tuple_pack(&tmpl, "siB", "heightmap_chunk", i) || ts_rd(c, &tmpl, &got)) {
            tf_seterr(err, errlen, "%s: cannot read height map chunk %lld: %s", coordinator,
                      (long long)i, ts_client_error(c));
            goto out;
        }
        if (tf_heightmap_rx_chunk(&rx, &got, err, errlen))
            goto out;
    }
    uint8_t *data;
    size_t len;
    if (tf_heightmap_rx_finish(&rx, &data, &len, err, errlen))
        goto out;
    char name[300];
    snprintf(name, sizeof name, "%s (from %s)", s->terrain.file_path, coordinator);
    rc = tf_scene_attach_heightmap(s, data, len, name, err, errlen);
out:
    tf_heightmap_rx_free(&rx);
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return rc;
}
