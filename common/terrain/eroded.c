/* eroded.c: an eroded terrain's blob, its key and its cache (eroded.h). */
#include "terrain/eroded.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <sodium.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cachefile.h"
#include "terrain/erosion_checkpoint.h"
#include "terrain/erosion_run.h"
#include "terrain/erosion_state.h"
#include "terrain/heightfield.h"
#include "clock.h"
#include "le_bytes.h"
#include "log.h"

#define MAGIC "TFERODE1"
#define HEADER_BYTES (8 + 32 + 4 + 8 + 4)
#define MAPS 4 /* heights, water, silt, flow */

static char cache_dir[400];

void tf_eroded_set_cache_dir(const char *dir)
{
    snprintf(cache_dir, sizeof cache_dir, "%s", dir ? dir : "");
}

void tf_eroded_cache_beside(const char *output)
{
    const char *slash = strrchr(output, '/');
    if (slash)
        snprintf(cache_dir, sizeof cache_dir, "%.*s/.terrafarm-cache", (int)(slash - output),
                 output);
    else
        snprintf(cache_dir, sizeof cache_dir, ".terrafarm-cache");
}

const char *tf_eroded_cache_dir(void)
{
    const char *env = getenv("TF_EROSION_CACHE");
    if (env && *env)
        return strcmp(env, "off") ? env : NULL;
    return cache_dir[0] ? cache_dir : NULL;
}

void tf_eroded_key(const tf_terrain *t, uint8_t key[32])
{
    static tf_scene holder; /* only its terrain is read; zero elsewhere */
    static const char tag[] = "terrafarm eroded terrain 1\n";
    tf_scene *s = malloc(sizeof *s);
    char *text = NULL;
    if (s) {
        *s = holder;
        s->terrain = *t;
        text = tf_scene_canonical_terrain(s);
        free(s);
    }
    if (sodium_init() < 0)
        (void)0; /* hashing needs no entropy */
    crypto_hash_sha256_state h;
    crypto_hash_sha256_init(&h);
    crypto_hash_sha256_update(&h, (const uint8_t *)tag, sizeof tag - 1);
    if (text)
        crypto_hash_sha256_update(&h, (const uint8_t *)text, strlen(text));
    else /* out of memory: a key no real terrain has */
        crypto_hash_sha256_update(&h, (const uint8_t *)"oom", 3);
    crypto_hash_sha256_final(&h, key);
    free(text);
}

void tf_eroded_maps_free(tf_eroded_maps *m)
{
    free(m->water);
    free(m->silt);
    free(m->flow);
    memset(m, 0, sizeof *m);
}

static size_t blob_bytes(int n)
{
    return HEADER_BYTES + (size_t)MAPS * (size_t)n * (size_t)n * 4 + 32;
}

/* The blob of an eroded state (floats are stored as the machine's IEEE single, little-endian
 * on every machine terrafarm builds for). */
uint8_t *tf_eroded_encode(const tf_terrain *t, const tf_erosion_state *st,
                          const tf_erosion_model *m, double extent, size_t *len)
{
    int n = m->n;
    size_t count = (size_t)n * (size_t)n, total = blob_bytes(n);
    uint8_t *b = malloc(total);
    float *row = malloc(count * sizeof *row);
    if (!b || !row) {
        free(b);
        free(row);
        return NULL;
    }
    memcpy(b, MAGIC, 8);
    tf_eroded_key(t, b + 8);
    tf_le_put32(b + 40, (uint32_t)n);
    memcpy(b + 44, &extent, 8);
    tf_le_put32(b + 52, (uint32_t)m->steps);
    uint8_t *at = b + HEADER_BYTES;
    tf_erosion_heights(st, m, row);
    memcpy(at, row, count * 4);
    for (size_t i = 0; i < count; i++)
        row[i] = (float)(st->w[i] * m->q);
    memcpy(at + count * 4, row, count * 4);
    for (size_t i = 0; i < count; i++)
        row[i] = (float)(st->d[i] * m->q);
    memcpy(at + 2 * count * 4, row, count * 4);
    for (size_t i = 0; i < count; i++)
        row[i] = (float)(st->flow[i] * m->q);
    memcpy(at + 3 * count * 4, row, count * 4);
    free(row);
    crypto_hash_sha256(b + total - 32, b, total - 32);
    *len = total;
    return b;
}

/* The first value of a blob's map k (0 heights, 1 water, 2 silt, 3 flow) that no erosion
 * produces: not finite, or below 0 where the map is a depth or a flow.  Its index, or -1. */
static ptrdiff_t first_impossible(const uint8_t *at, size_t count, int k)
{
    for (size_t i = 0; i < count; i++) {
        float v;
        memcpy(&v, at + (size_t)k * count * 4 + i * 4, 4);
        if (!isfinite(v) || (k > 0 && !(v >= 0.0f)))
            return (ptrdiff_t)i;
    }
    return -1;
}

/* Every value of the blob's maps is one tf_eroded_encode can write (finite heights; finite
 * depths and flows >= 0): the checksum only says the bytes arrived as they were sent, and a
 * coordinator that sends a networked worker its eroded terrain may send anything.  0, or -1
 * with one line naming `from`, the map and the vertex. */
static int check_values(const uint8_t *at, int n, const char *from, char *err, size_t errlen)
{
    static const char *const names[MAPS] = {"a height", "a water depth", "a silt depth",
                                            "a flow"};
    const size_t count = (size_t)n * (size_t)n;
    for (int k = 0; k < MAPS; k++) {
        ptrdiff_t i = first_impossible(at, count, k);
        if (i >= 0) {
            float v;
            memcpy(&v, at + (size_t)k * count * 4 + (size_t)i * 4, 4);
            return tf_seterr(err, errlen, "%s: eroded terrain holds %s of %g at vertex (%d, %d), "
                             "which no erosion produces", from, names[k], (double)v,
                             (int)(i % n), (int)(i / n));
        }
    }
    return 0;
}

int tf_eroded_parse(const tf_terrain *t, int n, const uint8_t *bytes, size_t len,
                    const char *from, float *h, tf_eroded_maps *maps, char *err, size_t errlen)
{
    uint8_t key[32], sum[32];
    if (len != blob_bytes(n) || memcmp(bytes, MAGIC, 8) || tf_le_get32(bytes + 40) != (uint32_t)n)
        return tf_seterr(err, errlen, "%s: not an eroded %dx%d terrain (%zu bytes)", from, n, n,
                         len);
    crypto_hash_sha256(sum, bytes, len - 32);
    if (sodium_memcmp(sum, bytes + len - 32, 32))
        return tf_seterr(err, errlen, "%s: eroded terrain damaged: its checksum does not match",
                         from);
    tf_eroded_key(t, key);
    if (memcmp(key, bytes + 8, 32))
        return tf_seterr(err, errlen, "%s: eroded terrain of another scene or other [erosion] "
                         "settings", from);
    size_t count = (size_t)n * (size_t)n;
    const uint8_t *at = bytes + HEADER_BYTES;
    if (check_values(at, n, from, err, errlen))
        return -1;
    memcpy(h, at, count * 4);
    if (!maps)
        return 0;
    maps->water = malloc(count * 4);
    maps->silt = malloc(count * 4);
    maps->flow = malloc(count * 4);
    if (!maps->water || !maps->silt || !maps->flow) {
        tf_eroded_maps_free(maps);
        return tf_seterr(err, errlen, "out of memory for the maps of a %dx%d terrain", n, n);
    }
    memcpy(maps->water, at + count * 4, count * 4);
    memcpy(maps->silt, at + 2 * count * 4, count * 4);
    memcpy(maps->flow, at + 3 * count * 4, count * 4);
    return 0;
}

static void entry_path(char *out, size_t len, const char *dir, const tf_terrain *t)
{
    uint8_t key[32];
    char hex[65];
    tf_eroded_key(t, key);
    sodium_bin2hex(hex, sizeof hex, key, sizeof key);
    snprintf(out, len, "%s/%s.eroded", dir, hex);
}

/* The cache entry's bytes if it exists and parses for t; NULL otherwise (a bad entry is
 * logged and will be overwritten). */
static uint8_t *cache_read(const tf_terrain *t, int n, const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    size_t want = blob_bytes(n);
    uint8_t *b = malloc(want + 1);
    size_t got = b ? fread(b, 1, want + 1, f) : 0;
    fclose(f);
    char err[600];
    float *h = malloc((size_t)n * (size_t)n * 4);
    if (b && h && tf_eroded_parse(t, n, b, got, path, h, NULL, err, sizeof err) == 0) {
        free(h);
        *len = got;
        return b;
    }
    if (b && h)
        tf_warn("%s; eroding again", err);
    free(h);
    free(b);
    return NULL;
}

/* Erode raw (n x n) by t's [erosion] keys; the blob, or NULL with one line in err. */
static uint8_t *erode(const tf_terrain *t, const float *raw, int n, double extent, int threads,
                      size_t *len, tf_erosion_report *rep, char *err, size_t errlen)
{
    tf_erosion_model m;
    tf_erosion_state st;
    if (tf_erosion_begin(t, raw, n, &m, &st, err, errlen) != 0)
        return NULL;
    rep->solid_before = tf_erosion_solid(&st, n);
    const char *dir = tf_eroded_cache_dir();
    int done = dir && tf_erosion_checkpoints_enabled()
                   ? tf_erosion_checkpoint_find(t, dir, m.steps, &st) : 0;
    if (done > 0)
        tf_info("erosion: continuing from the checkpoint after %d steps", done);
    tf_erosion_run_opts o = {done, m.steps - done, threads, 0, 0, 0};
    double t0 = tf_now_s();
    uint8_t *b = NULL;
    if (tf_erosion_run(&st, &m, &o, &rep->tally, err, errlen) == 0) {
        if (dir && tf_erosion_checkpoints_enabled())
            tf_erosion_checkpoint_save(t, dir, &st, m.steps);
        rep->seconds = tf_now_s() - t0;
        rep->vertex_steps = (double)n * (double)n * (double)(m.steps - done);
        rep->solid_after = tf_erosion_solid(&st, n);
        rep->quantum = m.q;
        rep->isa = tf_erosion_isa();
        rep->threads = threads > 0 ? threads : tf_thread_count(0);
        b = tf_eroded_encode(t, &st, &m, extent, len);
        if (!b)
            tf_seterr(err, errlen, "out of memory: the eroded %dx%d terrain", n, n);
    }
    tf_erosion_state_free(&st);
    return b;
}

int tf_eroded_cache_path(const tf_terrain *t, char *out, size_t len)
{
    const char *dir = tf_eroded_cache_dir();
    if (!dir)
        return -1;
    entry_path(out, len, dir, t);
    return 0;
}

uint8_t *tf_eroded_from_cache(const tf_terrain *t, int n, size_t *len, tf_erosion_report *rep)
{
    const char *dir = tf_eroded_cache_dir();
    if (!dir)
        return NULL;
    entry_path(rep->cache_path, sizeof rep->cache_path, dir, t);
    uint8_t *b = cache_read(t, n, rep->cache_path, len);
    if (b) {
        rep->from_cache = 1;
        tf_info("erosion: reused %s", rep->cache_path);
    }
    return b;
}

void tf_eroded_to_cache(const tf_terrain *t, const uint8_t *b, size_t len,
                        tf_erosion_report *rep)
{
    const char *dir = tf_eroded_cache_dir();
    if (!dir)
        return;
    entry_path(rep->cache_path, sizeof rep->cache_path, dir, t);
    tf_cachefile_write(dir, rep->cache_path, b, len);
}

void tf_eroded_log(const tf_terrain *t, int n, const tf_erosion_report *rep, const char *how)
{
    tf_info("erosion: %d steps on %dx%d in %.2f s (%.3f G vertex-steps/s, %s, %s)",
            t->erosion.fluvial_steps, n, n, rep->seconds,
            rep->vertex_steps / (rep->seconds > 0 ? rep->seconds : 1e-9) * 1e-9, rep->isa, how);
}

int tf_eroded_get(const tf_terrain *t, const float *raw, int n, double extent, int threads,
                  uint8_t **bytes, size_t *len, tf_erosion_report *rep, char *err, size_t errlen)
{
    tf_erosion_report local;
    rep = rep ? rep : &local;
    memset(rep, 0, sizeof *rep);
    *bytes = tf_eroded_from_cache(t, n, len, rep);
    if (*bytes)
        return 0;
    *bytes = erode(t, raw, n, extent, threads, len, rep, err, errlen);
    if (!*bytes)
        return -1;
    char how[32];
    snprintf(how, sizeof how, "%d threads", rep->threads);
    tf_eroded_log(t, n, rep, how);
    tf_eroded_to_cache(t, *bytes, *len, rep);
    return 0;
}
