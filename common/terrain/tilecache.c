/* tilecache.c: the byte-budgeted LRU cache of terrain tiles (tilecache.h).
 *
 * Layout: a chained hash table of tiles by key, and a doubly linked LRU list through the same
 * tiles (head: most recently read).  Invariants, asserted in debug builds by check_cache:
 *   C1. Every tile is in exactly one hash chain, the one of its key, and in the LRU list once.
 *   C2. ntiles counts them, and ntiles <= max_tiles after every public call.
 *   C3. Keys are unique. */
#include "terrain/tilecache.h"

#include <assert.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SAMPLES_PER_TILE (TF_TILE_SAMPLES * TF_TILE_SAMPLES)
#define MAX_BUCKETS (1u << 22)
/* The range pyramid: blocks of 2^k x 2^k cells for k = 1..5 (16^2 + 8^2 + 4^2 + 2^2 + 1). */
#define PYRAMID_ENTRIES 341
#define RECENT_SLOTS 64

typedef struct tile {
    uint64_t key;
    struct tile *chain;       /* next in the hash bucket */
    struct tile *newer, *older; /* LRU list */
    float s[SAMPLES_PER_TILE];
    float lo[PYRAMID_ENTRIES], hi[PYRAMID_ENTRIES]; /* each block's sample range */
} tile;

/* Index of block (bi, bj) of 2^k cells in the pyramid. */
static int pyramid_at(int k, int bi, int bj)
{
    static const int offset[6] = {0, 0, 256, 320, 336, 340};
    int side = TF_TILE_CELLS >> k;
    return offset[k] + bj * side + bi;
}

static void build_pyramid(tile *t)
{
    for (int bj = 0; bj < 16; bj++)
        for (int bi = 0; bi < 16; bi++) {
            float lo = INFINITY, hi = -INFINITY;
            for (int b = 0; b < 3; b++)
                for (int a = 0; a < 3; a++) {
                    float v = t->s[(2 * bj + b) * TF_TILE_SAMPLES + 2 * bi + a];
                    lo = v < lo ? v : lo;
                    hi = v > hi ? v : hi;
                }
            t->lo[pyramid_at(1, bi, bj)] = lo;
            t->hi[pyramid_at(1, bi, bj)] = hi;
        }
    for (int k = 2; k <= 5; k++)
        for (int bj = 0; bj < (TF_TILE_CELLS >> k); bj++)
            for (int bi = 0; bi < (TF_TILE_CELLS >> k); bi++) {
                float lo = INFINITY, hi = -INFINITY;
                for (int c = 0; c < 4; c++) {
                    int at = pyramid_at(k - 1, 2 * bi + (c & 1), 2 * bj + (c >> 1));
                    lo = t->lo[at] < lo ? t->lo[at] : lo;
                    hi = t->hi[at] > hi ? t->hi[at] : hi;
                }
                t->lo[pyramid_at(k, bi, bj)] = lo;
                t->hi[pyramid_at(k, bi, bj)] = hi;
            }
}

struct tf_tilecache {
    tf_tile_fill_fn fill;
    void *ctx;
    size_t budget, max_tiles, ntiles;
    tile **buckets;
    size_t nbuckets; /* a power of two */
    tile *newest, *oldest;
    tf_tile_counts totals;
    tile *recent[RECENT_SLOTS]; /* by key hash: tiles read lately, skipping the chains */
};

static __thread tf_tile_counts thread_counts;

size_t tf_tilecache_tile_bytes(void) { return sizeof(tile) + sizeof(tile *); }

static size_t tiles_for(size_t budget)
{
    size_t n = budget / tf_tilecache_tile_bytes();
    return n < TF_TILE_CACHE_MIN_TILES ? TF_TILE_CACHE_MIN_TILES : n;
}

static size_t buckets_for(size_t max_tiles)
{
    size_t n = 1024;
    while (n < 2 * max_tiles && n < MAX_BUCKETS)
        n <<= 1;
    return n;
}

static size_t bucket_of(const tf_tilecache *c, uint64_t key)
{
    key ^= key >> 31;
    key *= 0x9e3779b97f4a7c15ULL;
    return (size_t)(key >> 32) & (c->nbuckets - 1);
}

#ifndef NDEBUG
/* O(tiles): checked while the cache is small (the unit tests' budgets), skipped beyond. */
static void check_cache(const tf_tilecache *c)
{
    if (c->ntiles > 256)
        return;
    size_t listed = 0, chained = 0;
    for (const tile *t = c->newest; t; t = t->older, listed++)
        assert((t->older ? t->older->newer == t : c->oldest == t) && "C1: LRU list links");
    for (size_t b = 0; b < c->nbuckets; b++)
        for (const tile *t = c->buckets[b]; t; t = t->chain, chained++) {
            assert(bucket_of(c, t->key) == b && "C1: a tile sits in its key's chain");
            for (const tile *u = t->chain; u; u = u->chain)
                assert(u->key != t->key && "C3: keys are unique");
        }
    assert(listed == c->ntiles && chained == c->ntiles && "C2: ntiles counts the tiles");
    assert(c->ntiles <= c->max_tiles && "C2: within the budget");
}
#else
#define check_cache(c) ((void)0)
#endif

tf_tilecache *tf_tilecache_new(size_t budget_bytes, tf_tile_fill_fn fill, void *ctx)
{
    tf_tilecache *c = calloc(1, sizeof *c);
    if (!c)
        return NULL;
    c->fill = fill;
    c->ctx = ctx;
    c->budget = budget_bytes;
    c->max_tiles = tiles_for(budget_bytes);
    c->nbuckets = buckets_for(c->max_tiles);
    c->buckets = calloc(c->nbuckets, sizeof *c->buckets);
    if (!c->buckets) {
        free(c);
        return NULL;
    }
    return c;
}

void tf_tilecache_free(tf_tilecache *c)
{
    if (!c)
        return;
    for (tile *t = c->newest, *next; t; t = next) {
        next = t->older;
        free(t);
    }
    free(c->buckets);
    free(c);
}

size_t tf_tilecache_budget(const tf_tilecache *c) { return c->budget; }

static void unlink_lru(tf_tilecache *c, tile *t)
{
    if (t->newer)
        t->newer->older = t->older;
    else
        c->newest = t->older;
    if (t->older)
        t->older->newer = t->newer;
    else
        c->oldest = t->newer;
    t->newer = t->older = NULL;
}

static void push_newest(tf_tilecache *c, tile *t)
{
    t->older = c->newest;
    t->newer = NULL;
    if (c->newest)
        c->newest->newer = t;
    c->newest = t;
    if (!c->oldest)
        c->oldest = t;
}

static void unchain(tf_tilecache *c, tile *t)
{
    tile **p = &c->buckets[bucket_of(c, t->key)];
    while (*p != t)
        p = &(*p)->chain;
    *p = t->chain;
}

static size_t recent_slot(uint64_t key)
{
    return (size_t)((key * 0x9e3779b97f4a7c15ULL) >> 58) & (RECENT_SLOTS - 1);
}

static void evict_down_to(tf_tilecache *c, size_t keep)
{
    while (c->ntiles > keep) {
        tile *t = c->oldest;
        if (c->recent[recent_slot(t->key)] == t)
            c->recent[recent_slot(t->key)] = NULL;
        unlink_lru(c, t);
        unchain(c, t);
        free(t);
        c->ntiles--;
        c->totals.evictions++;
        thread_counts.evictions++;
    }
}

void tf_tilecache_set_budget(tf_tilecache *c, size_t budget_bytes)
{
    c->budget = budget_bytes;
    c->max_tiles = tiles_for(budget_bytes);
    evict_down_to(c, c->max_tiles);
    check_cache(c);
}

static tile *find(tf_tilecache *c, uint64_t key)
{
    for (tile *t = c->buckets[bucket_of(c, key)]; t; t = t->chain)
        if (t->key == key)
            return t;
    return NULL;
}

static void copy_out(const float *s, int i0, int j0, int w, int h, float *out)
{
    for (int j = 0; j < h; j++)
        memcpy(out + (size_t)j * (size_t)w, s + (size_t)(j0 + j) * TF_TILE_SAMPLES + i0,
               (size_t)w * sizeof *out);
}

/* The tile, most recently used now, or NULL. */
static tile *touch(tf_tilecache *c, uint64_t key)
{
    tile **slot = &c->recent[recent_slot(key)];
    tile *t = *slot && (*slot)->key == key ? *slot : find(c, key);
    if (t && c->newest != t) {
        unlink_lru(c, t);
        push_newest(c, t);
    }
    if (t)
        *slot = t;
    return t;
}

/* Keep freshly filled t. */
static void keep(tf_tilecache *c, tile *t)
{
    evict_down_to(c, c->max_tiles - 1);
    size_t b = bucket_of(c, t->key);
    t->chain = c->buckets[b];
    c->buckets[b] = t;
    push_newest(c, t);
    c->recent[recent_slot(t->key)] = t;
    c->ntiles++;
}

static void count_fill(tf_tilecache *c, uint64_t evaluated)
{
    c->totals.misses++;
    c->totals.samples_evaluated += evaluated;
    thread_counts.misses++;
    thread_counts.samples_evaluated += evaluated;
}

/* Fill tile t (its key set) and its pyramid; count it. */
static void fill(tf_tilecache *c, tile *t)
{
    uint64_t n = c->fill(c->ctx, t->key, t->s);
    build_pyramid(t);
    count_fill(c, n);
}

static __thread tile *spare_tile; /* per thread, for the out-of-memory path */

/* Tile `key`: found, or filled and kept; or, when no memory is left for one more, filled in
 * a spare that the next call reuses. */
static const tile *get_tile(tf_tilecache *c, uint64_t key)
{
    tile *t = touch(c, key);
    if (t) {
        c->totals.hits++;
        thread_counts.hits++;
        return t;
    }
    tile *fresh = malloc(sizeof *fresh);
    if (!fresh && !spare_tile)
        spare_tile = malloc(sizeof *spare_tile);
    t = fresh ? fresh : spare_tile;
    if (!t) {
        fprintf(stderr, "terrafarm: out of memory for one terrain tile\n");
        abort();
    }
    t->key = key;
    fill(c, t);
    if (fresh)
        keep(c, fresh);
    check_cache(c);
    return t;
}


void tf_tilecache_read(tf_tilecache *c, uint64_t key, int i0, int j0, int w, int h, float *out)
{
    assert(i0 >= 0 && j0 >= 0 && w >= 0 && h >= 0 && i0 + w <= TF_TILE_SAMPLES &&
           j0 + h <= TF_TILE_SAMPLES);
    copy_out(get_tile(c, key)->s, i0, j0, w, h, out);
}

void tf_tilecache_range(tf_tilecache *c, uint64_t key, int k, int bi, int bj, float *lo,
                        float *hi)
{
    assert(k >= 1 && k <= 5 && bi >= 0 && bj >= 0 && bi < (TF_TILE_CELLS >> k) &&
           bj < (TF_TILE_CELLS >> k));
    const tile *t = get_tile(c, key);
    int at = pyramid_at(k, bi, bj);
    *lo = t->lo[at];
    *hi = t->hi[at];
}

tf_tile_counts tf_tilecache_totals(tf_tilecache *c) { return c->totals; }

tf_tile_counts tf_tilecache_thread_counts(void) { return thread_counts; }
