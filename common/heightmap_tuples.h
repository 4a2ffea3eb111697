/* heightmap_tuples.h: a generator = file scene's height map, carried from the coordinator to
 * networked workers through the tuple space (not a shared disk), in bounded chunks:
 *
 *   ("heightmap", bytes:I, chunks:I, sha256:S)   one descriptor: the file's size, the number of
 *                                                chunks, its SHA-256 in hex
 *   ("heightmap_chunk", index:I, data:B)         chunks 0 .. chunks-1, each
 *                                                TF_HEIGHTMAP_CHUNK_BYTES but the last
 *
 * The coordinator puts them once, beside the ("scene", ...) tuple (farmproto.h); a worker rd's
 * them (they stay for the next worker).  A chunk is far below a frame's 64 MiB cap.  What a
 * worker receives is checked as it comes: the descriptor's size against
 * TF_HEIGHTMAP_MAX_BYTES before anything is allocated, each chunk's index and exact length,
 * and the SHA-256 of the whole; then the bytes are attached to the scene
 * (tf_scene_attach_heightmap), so the scene hash the worker compares with the coordinator's
 * covers them too.  Anything wrong is one line naming the coordinator. */
#ifndef TF_HEIGHTMAP_TUPLES_H
#define TF_HEIGHTMAP_TUPLES_H

#include <stddef.h>
#include <stdint.h>

#include "linda/tsclient.h"
#include "linda/tuple.h"
#include "linda/tuplespace.h"
#include "scene.h"

#define TF_HEIGHTMAP_CHUNK_BYTES ((size_t)8 << 20)

/* Coordinator: put the descriptor and chunks of s's height map (generator = file), and of
 * its eroded terrain when one is attached (the same two tuples named "eroded" and
 * "eroded_chunk": terrain/eroded.h; a worker never erodes again).  0, or -1 on out of
 * memory. */
int tf_heightmap_tuples_put(ts_space *space, const tf_scene *s);

/* Worker: if s is a generator = file scene, read its height map from the coordinator's space
 * (c), check it, and attach it to s.  0, or -1 with one line in err naming `coordinator`. */
int tf_heightmap_fetch(ts_client *c, tf_scene *s, const char *coordinator, char *err,
                       size_t errlen);
/* Worker: if s has [erosion], the same for its eroded terrain (checked against the scene when
 * the terrain is built).  Not in an erosion's own space (common/erosion_tuples.h), which is
 * computing it. */
int tf_eroded_fetch(ts_client *c, tf_scene *s, const char *coordinator, char *err,
                    size_t errlen);

/* The receiving side's checks, one tuple at a time (what tf_heightmap_fetch runs; separate for
 * the unit tests).  begin takes the descriptor, chunk each chunk in order, finish checks the
 * hash and hands over the bytes (*data, malloc'd, *len).  Each returns 0 or -1 with err set
 * ("FROM: ..."); after -1, or instead of finish, call tf_heightmap_rx_free. */
typedef struct tf_heightmap_rx {
    const char *from;
    const struct blob_kind *kind;
    size_t len, got;
    int64_t chunks, next;
    char sha256[65];
    uint8_t *buf;
} tf_heightmap_rx;
int tf_heightmap_rx_begin(tf_heightmap_rx *rx, const char *from, const tf_tuple *desc,
                          char *err, size_t errlen);
int tf_heightmap_rx_chunk(tf_heightmap_rx *rx, const tf_tuple *chunk, char *err, size_t errlen);
int tf_heightmap_rx_finish(tf_heightmap_rx *rx, uint8_t **data, size_t *len, char *err,
                           size_t errlen);
void tf_heightmap_rx_free(tf_heightmap_rx *rx);

/* The sending side's tuples (used by tf_heightmap_tuples_put, and by the tests to forge). */
int tf_heightmap_desc_pack(tf_tuple *t, size_t len, const char *sha256_hex);
int tf_heightmap_chunk_pack(tf_tuple *t, int64_t index, const uint8_t *data, size_t n);

#endif
