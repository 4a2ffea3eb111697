/* tilecache.h: a worker's evaluated terrain, in bounded memory (Musgrave A.7.2.3: each worker
 * keeps the part of the model it has evaluated, so that what its next tasks need is mostly
 * there).
 *
 * A tile is a square block of TF_TILE_SAMPLES^2 height samples, named by a 64-bit key the
 * caller chooses; its values are a pure function of the key (the caller's fill function), so
 * what the cache holds or evicts changes how fast a render goes, never its bits.  Tiles are
 * kept least recently used first out within a byte budget (never fewer than
 * TF_TILE_CACHE_MIN_TILES).
 *
 * One thread's: no locks (a farm worker is one process rendering on one thread; a program
 * rendering on several threads gives each its own cache, as procedural.c does).  Reads copy
 * what they need out, so a tile may be evicted by the very next read.
 *
 * Counters: per cache (tf_tilecache_totals) and per calling thread (tf_tilecache_thread_counts,
 * what one worker's task cost when one thread renders it). */
#ifndef TF_TILECACHE_H
#define TF_TILECACHE_H

#include <stddef.h>
#include <stdint.h>

#define TF_TILE_CELLS 32
#define TF_TILE_SAMPLES (TF_TILE_CELLS + 1)
#define TF_TILE_CACHE_MIN_TILES 128 /* about 0.9 MiB: what one ray may need across its levels, and more */
/* Bytes a tile costs in the budget (its samples and its bookkeeping). */
size_t tf_tilecache_tile_bytes(void);

typedef struct tf_tilecache tf_tilecache;

/* Fills the TF_TILE_SAMPLES^2 samples of tile `key`, row-major; returns the number of samples
 * it evaluated. */
typedef uint64_t (*tf_tile_fill_fn)(void *ctx, uint64_t key, float *samples);

typedef struct tf_tile_counts {
    uint64_t samples_evaluated; /* samples computed by fills */
    uint64_t hits;              /* reads that found their tile */
    uint64_t misses;            /* reads that filled it */
    uint64_t evictions;         /* tiles dropped for the budget */
} tf_tile_counts;

/* NULL when out of memory. */
tf_tilecache *tf_tilecache_new(size_t budget_bytes, tf_tile_fill_fn fill, void *ctx);
void tf_tilecache_free(tf_tilecache *c);
size_t tf_tilecache_budget(const tf_tilecache *c);
/* Change the budget (evicting down to it at once). */
void tf_tilecache_set_budget(tf_tilecache *c, size_t budget_bytes);

/* Copy samples (i, j) for i in [i0, i0 + w), j in [j0, j0 + h) of tile `key` into out (row
 * major, w per row); 0 <= i0, i0 + w <= TF_TILE_SAMPLES, likewise j.  A missing tile that
 * cannot be allocated is filled in a spare and not kept: slower, never wrong (and if even the
 * spare cannot be had, the process is out of memory: it aborts). */
void tf_tilecache_read(tf_tilecache *c, uint64_t key, int i0, int j0, int w, int h, float *out);

/* The range of tile `key`'s samples over its block (bi, bj) of 2^k x 2^k cells (k in 1..5;
 * the block's boundary samples included): a pyramid made once per fill. */
void tf_tilecache_range(tf_tilecache *c, uint64_t key, int k, int bi, int bj, float *lo,
                        float *hi);

tf_tile_counts tf_tilecache_totals(tf_tilecache *c);
/* What this thread's reads cost since the thread started (all caches together). */
tf_tile_counts tf_tilecache_thread_counts(void);

#endif
