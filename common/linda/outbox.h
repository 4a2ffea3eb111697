/* outbox.h: memory a forked worker shares with its coordinator, where it leaves its large
 * results for the coordinator to keep in place (proto.h, OUT_SHARED).
 *
 * The coordinator maps an outbox (shared, anonymous, pages committed as they are written)
 * before it forks the worker, so both processes see the same pages; after the fork it marks
 * its mapping not to be inherited by the workers it forks later.  The outbox is a ring of
 * records: a 64-byte header, whose first word is the record's state, then a payload.  To put a
 * large tuple the worker reserves a record (tf_outbox_reserve), encodes the tuple into its
 * payload and sends OUT_SHARED with the payload's offset and length.  The server decodes the
 * tuple where it lies: the stored tuple's large blobs (a result's chunks) stay in the record,
 * through a reference that also holds the outbox (tf_outbox_lend).  The last reference gone
 * (the chunks written), the record's state says free, and the worker reclaims free records in
 * ring order before it reserves again.  With no room (the oldest record still held), the tuple
 * travels through the socket as before.  Neither side waits for the other.
 *
 * Trust.  The coordinator keeps bytes in memory its child can write.  A forked worker runs this
 * program (its connection is a trusted one, ts_server_add_fd) and never writes a record from
 * its OUT_SHARED to the record's release.  The server checks the offset and length it is
 * given, decodes as it decodes any OUT body, and copies every length it later relies on;
 * networked workers never have an outbox.
 *
 * INVARIANTS of the worker's side (tf_outbox_check, in debug builds):
 *   O1. Its records lie in [0, size), 64-byte aligned, each at least a header and a payload.
 *   O2. They are in ring order: each starts where the one before it ends, or at 0 (a wrap),
 *       and at most one wrap lies between the oldest and the newest.
 *   O3. The newest does not reach into the oldest: records never overlap. */
#ifndef TF_OUTBOX_H
#define TF_OUTBOX_H

#include <stddef.h>
#include <stdint.h>

#include "linda/tuple.h"

/* A tuple whose encoding is at least this large goes through the outbox (smaller ones cost
 * less as bytes on the socket). */
#define TF_OUTBOX_MIN (32 * 1024)
/* An outbox's size: room for the results a worker has waiting for their rows (a 3840-pixel row
 * of 128-pixel stamps is 30 results of ~110 KB), small enough that the coordinator's mapping
 * of it stays warm: 64 MB was 0.93x the CPU of copying each result out, 8 MB 0.89x
 * (bench/README.md section 19). */
#define TF_OUTBOX_BYTES ((size_t)8 * 1024 * 1024)
/* A record's header: its state word, then padding to keep payloads on cache lines. */
#define TF_OUTBOX_HEADER 64

typedef struct tf_outbox tf_outbox;

/* Map a new outbox of TF_OUTBOX_BYTES (one reference, the caller's).  NULL with a one-line
 * reason in err. */
tf_outbox *tf_outbox_create(char *err, size_t errlen);
/* In the parent after the fork: the children it forks later do not inherit this outbox. */
void tf_outbox_keep_from_later_forks(const tf_outbox *ob);
/* Drop one reference; the last unmaps it.  Thread-safe; NULL does nothing. */
void tf_outbox_unref(tf_outbox *ob);
uint8_t *tf_outbox_base(const tf_outbox *ob);
size_t tf_outbox_size(const tf_outbox *ob);

/* ---- the worker's side (one thread) ---- */
/* A record with a payload of n bytes: the payload's offset, after reclaiming the records the
 * coordinator has released; -1 when there is no room now. */
int64_t tf_outbox_reserve(tf_outbox *ob, size_t n);
/* O1-O3, one assert a clause; returns 1 (for use inside assert). */
int tf_outbox_check(const tf_outbox *ob);

/* ---- the coordinator's side ---- */
/* Is [off, off + len) a payload a record may hold (its header before it, all inside)?  0, or
 * -1 with a one-line reason in err. */
int tf_outbox_payload_ok(const tf_outbox *ob, uint64_t off, uint64_t len, char *err,
                         size_t errlen);
/* A reference to the record whose payload starts at off (checked above), holding the outbox:
 * with its last release the record is marked free for the worker.  NULL without memory. */
tf_shared_bytes *tf_outbox_lend(tf_outbox *ob, uint64_t off);

#endif
