/* erosion_checkpoint.c: whole erosion states kept in the cache so that a longer erosion of the
 * same terrain continues from the last one (erosion_checkpoint.h).
 *
 * File <dir>/<lineage>.<steps>.state, lineage = SHA-256 of "terrafarm erosion lineage 1" and
 * the canonical [terrain] and [erosion] with fluvial_steps left out:
 *   magic "TFESTAT1" | lineage (32) | n (u32 LE) | steps (u32 LE) |
 *   bedrock, talus, silt, water, load (int32 LE), flow (float32): n*n each | SHA-256 (32)
 * The soft field is not stored: it is a function of the keys (tf_erosion_state_from_heights). */
#include "terrain/erosion_checkpoint.h"

#include <dirent.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cachefile.h"
#include "le_bytes.h"
#include "log.h"

#define MAGIC "TFESTAT1"
#define HEADER (8 + 32 + 4 + 4)
#define ARRAYS 6

static int enabled;

void tf_erosion_checkpoints_enable(int on) { enabled = on; }
int tf_erosion_checkpoints_enabled(void) { return enabled; }

static void lineage_hex(const tf_terrain *t, uint8_t key[32], char hex[65])
{
    static const char tag[] = "terrafarm erosion lineage 1\n";
    static tf_scene holder;
    tf_scene *s = malloc(sizeof *s);
    char *text = NULL;
    if (s) {
        *s = holder;
        s->terrain = *t;
        s->terrain.erosion.fluvial_steps = 1; /* present, and the same for every length */
        text = tf_scene_canonical_terrain(s);
        free(s);
    }
    crypto_hash_sha256_state h;
    crypto_hash_sha256_init(&h);
    crypto_hash_sha256_update(&h, (const uint8_t *)tag, sizeof tag - 1);
    crypto_hash_sha256_update(&h, (const uint8_t *)(text ? text : "oom"), text ? strlen(text) : 3);
    crypto_hash_sha256_final(&h, key);
    free(text);
    sodium_bin2hex(hex, 65, key, 32);
}

static size_t file_bytes(int n) { return HEADER + (size_t)ARRAYS * (size_t)n * n * 4 + 32; }

static void arrays(const tf_erosion_state *st, void *out[ARRAYS])
{
    out[0] = st->b;
    out[1] = st->t;
    out[2] = st->d;
    out[3] = st->w;
    out[4] = st->s;
    out[5] = st->flow;
}

void tf_erosion_checkpoint_save(const tf_terrain *t, const char *dir, const tf_erosion_state *st,
                                int steps)
{
    int n = st->n;
    size_t each = (size_t)n * (size_t)n * 4, len = file_bytes(n);
    uint8_t *b = malloc(len), key[32];
    char hex[65], path[600];
    if (!b)
        return; /* a checkpoint is an optimisation: without memory, none */
    memcpy(b, MAGIC, 8);
    lineage_hex(t, key, hex);
    memcpy(b + 8, key, 32);
    tf_le_put32(b + 40, (uint32_t)n);
    tf_le_put32(b + 44, (uint32_t)steps);
    void *a[ARRAYS];
    arrays(st, a);
    for (int k = 0; k < ARRAYS; k++)
        memcpy(b + HEADER + k * each, a[k], each);
    crypto_hash_sha256(b + len - 32, b, len - 32);
    snprintf(path, sizeof path, "%s/%s.%d.state", dir, hex, steps);
    tf_cachefile_write(dir, path, b, len);
    free(b);
}

/* Load one checkpoint file into st (allocated, n x n) if it checks out; 0 or -1. */
static int load(const char *path, const uint8_t key[32], int n, int steps, tf_erosion_state *st)
{
    size_t len = file_bytes(n), each = (size_t)n * (size_t)n * 4;
    uint8_t *b = malloc(len + 1), sum[32];
    FILE *f = fopen(path, "rb");
    size_t got = f && b ? fread(b, 1, len + 1, f) : 0;
    if (f)
        fclose(f);
    int ok = b && got == len && !memcmp(b, MAGIC, 8) && !memcmp(b + 8, key, 32) &&
             tf_le_get32(b + 40) == (uint32_t)n && tf_le_get32(b + 44) == (uint32_t)steps;
    if (ok) {
        crypto_hash_sha256(sum, b, len - 32);
        ok = !sodium_memcmp(sum, b + len - 32, 32);
    }
    if (!ok && b && got > 0)
        tf_warn("%s: not a checkpoint of this erosion, or damaged; not used", path);
    void *a[ARRAYS];
    arrays(st, a);
    for (int k = 0; ok && k < ARRAYS; k++)
        memcpy(a[k], b + HEADER + k * each, each);
    free(b);
    return ok ? 0 : -1;
}

/* The step counts of t's checkpoints in dir, at most max_steps, largest first: *count of them
 * (at most cap) into out. */
static int list_steps(const char *dir, const char *hex, int max_steps, int *out, int cap)
{
    DIR *d = opendir(dir);
    int count = 0;
    struct dirent *e;
    while (d && (e = readdir(d)) != NULL) {
        int steps, used = 0;
        if (strncmp(e->d_name, hex, 64) || sscanf(e->d_name + 64, ".%d.state%n", &steps,
                                                  &used) != 1 ||
            e->d_name[64 + used] != '\0' || steps < 1 || steps > max_steps)
            continue;
        int at = count < cap ? count++ : cap - 1;
        if (at == cap - 1 && count == cap && out[at] >= steps)
            continue;
        out[at] = steps;
        for (int i = at; i > 0 && out[i] > out[i - 1]; i--) { /* keep descending */
            int tmp = out[i];
            out[i] = out[i - 1];
            out[i - 1] = tmp;
        }
    }
    if (d)
        closedir(d);
    return count;
}

int tf_erosion_checkpoint_find(const tf_terrain *t, const char *dir, int max_steps,
                               tf_erosion_state *st)
{
    uint8_t key[32];
    char hex[65], path[600];
    int found[8];
    lineage_hex(t, key, hex);
    int count = list_steps(dir, hex, max_steps, found, 8);
    for (int i = 0; i < count; i++) {
        snprintf(path, sizeof path, "%s/%s.%d.state", dir, hex, found[i]);
        if (load(path, key, st->n, found[i], st) == 0)
            return found[i];
    }
    return 0;
}
