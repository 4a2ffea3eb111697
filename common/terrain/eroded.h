/* eroded.h: an eroded terrain as one self-checking blob of bytes, computed once and then
 * reused: stored in a cache directory under the hash of everything that determines it, and
 * carried to networked workers through the tuple space (heightmap_tuples.h) instead of being
 * eroded again on every machine.
 *
 * The key is SHA-256 of "terrafarm eroded terrain 1" and the canonical text of the scene's
 * [terrain] and [erosion] sections (which include the height map's SHA-256 for generator =
 * file): a change to any of them is another key, so a stale entry is never found.  The blob:
 *
 *   magic "TFERODE1" | key (32 bytes) | n (u32 LE) | extent (f64 LE) | steps (u32 LE) |
 *   heights, water, silt, flow: n*n float32 LE each | SHA-256 of everything before (32 bytes)
 *
 * heights are world heights of the ground, water and silt world depths, flow the decaying sum
 * of the water leaving each vertex per step (erosion.h) in world metres.  A blob is accepted
 * only whole: the right length for its n, its own checksum, the key the reader computes from
 * its own scene, and only values an erosion writes (finite heights; finite depths and flows
 * >= 0: whoever sends a blob can also checksum it); anything else is one line naming where it
 * came from. */
#ifndef TF_ERODED_H
#define TF_ERODED_H

#include <stddef.h>
#include <stdint.h>

#include "terrain/erosion.h"
#include "scene.h"

/* The key of t's eroded terrain. */
void tf_eroded_key(const tf_terrain *t, uint8_t key[32]);

/* The maps an eroded terrain carries besides its heights (n * n floats each, malloc'd). */
typedef struct tf_eroded_maps {
    float *water, *silt, *flow;
} tf_eroded_maps;
void tf_eroded_maps_free(tf_eroded_maps *m);

/* What producing one cost: computed now (seconds, vertex-steps, exact balances) or read. */
typedef struct tf_erosion_report {
    int from_cache;           /* 1: read from the cache, nothing computed */
    char cache_path[512];     /* the entry read or written ("" without a cache) */
    double seconds;           /* erosion time (0 from the cache) */
    double vertex_steps;
    const char *isa;
    int threads;
    tf_erosion_tally tally;
    int64_t solid_before, solid_after; /* bedrock + talus + silt + load, quanta */
    double quantum;
} tf_erosion_report;

/* The cache directory (created on first write, mode 0700), or NULL for no cache.  The
 * environment's TF_EROSION_CACHE (a directory, or "off") overrides what a command sets. */
void tf_eroded_set_cache_dir(const char *dir);
const char *tf_eroded_cache_dir(void);
/* The cache directory .terrafarm-cache beside the file `output` (what render and heightfield
 * use). */
void tf_eroded_cache_beside(const char *output);
/* Where t's entry is (or would be) in the cache: 0, or -1 without a cache. */
int tf_eroded_cache_path(const tf_terrain *t, char *out, size_t len);

/* The blob of t's eroded terrain: from the cache when an entry checks out, else the raw
 * heights raw (n x n, the generator's, after thermal weathering) eroded with `threads` threads
 * and stored.  *bytes is malloc'd.  rep (may be NULL) says which.  0, or -1 with one line. */
int tf_eroded_get(const tf_terrain *t, const float *raw, int n, double extent, int threads,
                  uint8_t **bytes, size_t *len, tf_erosion_report *rep, char *err, size_t errlen);

/* Check a blob against t (from names it in messages) and copy out its heights (h: n * n
 * floats, the caller's) and, if maps is not NULL, its maps.  0, or -1 with one line. */
int tf_eroded_parse(const tf_terrain *t, int n, const uint8_t *bytes, size_t len,
                    const char *from, float *h, tf_eroded_maps *maps, char *err, size_t errlen);

/* The pieces of tf_eroded_get, for drivers that erode elsewhere (the farm): the cache's
 * entry for t if it checks out (else NULL; rep->cache_path names where it would be), storing
 * a blob, the blob of a finished state, and the log line of an erosion done. */
struct tf_erosion_state;
uint8_t *tf_eroded_from_cache(const tf_terrain *t, int n, size_t *len, tf_erosion_report *rep);
void tf_eroded_to_cache(const tf_terrain *t, const uint8_t *b, size_t len,
                        tf_erosion_report *rep);
uint8_t *tf_eroded_encode(const tf_terrain *t, const struct tf_erosion_state *st,
                          const tf_erosion_model *m, double extent, size_t *len);
void tf_eroded_log(const tf_terrain *t, int n, const tf_erosion_report *rep, const char *how);

/* Largest blob: 8193^2 vertices, 4 arrays. */
#define TF_ERODED_MAX_BYTES ((size_t)1100 << 20)

#endif
