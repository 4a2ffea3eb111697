/* idmap.h: a hash map from nonzero 64-bit ids (the server's connection ids, worker ids) to
 * 64-bit values, for the supervisor's per-request lookups (which worker a connection is, which
 * lease it holds) and the dashboard's per-snapshot ones (a worker's record), that were linear
 * scans: with a thousand workers they were a tenth of the coordinator's time.
 * Open addressing with linear probing and backward-shift deletion (no tombstones); it grows at
 * half full.  Not thread-safe: the event loop is its only user. */
#ifndef TF_IDMAP_H
#define TF_IDMAP_H

#include <stddef.h>
#include <stdint.h>

typedef struct tf_idmap {
    uint64_t *keys; /* 0: empty */
    int64_t *vals;
    size_t cap;     /* 0 or a power of two */
    size_t n;
} tf_idmap;

/* Set key's value (key != 0).  0, or -1 out of memory (the map is unchanged). */
int tf_idmap_put(tf_idmap *m, uint64_t key, int64_t val);
/* 1 and *val if key is there, else 0. */
int tf_idmap_get(const tf_idmap *m, uint64_t key, int64_t *val);
/* Remove key if it is there. */
void tf_idmap_del(tf_idmap *m, uint64_t key);
void tf_idmap_free(tf_idmap *m);

#endif
