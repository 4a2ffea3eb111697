/* outbox.h: memory a forked worker shares with its coordinator, through which it hands over a
 * large tuple without the socket's copies (proto.h, OUT_SHARED).
 *
 * The coordinator maps an outbox (shared, anonymous, reserved lazily) before it forks the
 * worker, so both processes see the same pages at the same address; after the fork it marks
 * its mapping not to be inherited by the workers forked later (each sees only its own).  To put
 * a large tuple, the worker encodes it at the start of the outbox and sends an OUT_SHARED frame
 * with its length; the server copies those bytes out before it answers, and the worker writes
 * the outbox again only after that answer.  The bytes are the peer's: the server decodes its
 * own copy, so a worker that scribbles on the outbox meanwhile spoils only its own tuple.  The
 * area cannot shrink under the server (it is anonymous memory, not a file). */
#ifndef TF_OUTBOX_H
#define TF_OUTBOX_H

#include <stddef.h>
#include <stdint.h>

/* A tuple whose encoding is at least this large goes through the outbox (smaller ones cost
 * less as bytes on the socket than as one more frame's worth of bookkeeping). */
#define TF_OUTBOX_MIN (32 * 1024)
/* An outbox's size: room for the largest frame body (pages are committed only as written). */
#define TF_OUTBOX_BYTES ((size_t)64 * 1024 * 1024)

typedef struct tf_outbox {
    uint8_t *base; /* NULL: none */
    size_t size;
} tf_outbox;

/* Map a new outbox of TF_OUTBOX_BYTES.  0, or -1 with a one-line reason in err. */
int tf_outbox_create(tf_outbox *ob, char *err, size_t errlen);
/* In the parent after the fork: later children do not inherit this outbox. */
void tf_outbox_keep_from_later_forks(const tf_outbox *ob);
/* Unmap (a NULL base does nothing) and reset to none. */
void tf_outbox_release(tf_outbox *ob);

#endif
