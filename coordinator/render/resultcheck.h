/* resultcheck.h: the check of a result's pixels, off the event loop.  A worker the coordinator
 * did not fork sends bytes nobody has looked at: its chunks may be structurally perfect
 * (farmproto.h, tf_result_check) yet not decode, or decode to NaN and infinity.  Such a result
 * must never reach the file, or a render could end with exit 0 and an image no OpenEXR reader
 * accepts.  The supervisor hands each such result here after its structural check; a thread
 * of its own inflates every chunk and scans its values (image/exrcheck.h) and posts a verdict,
 * which the supervisor collects on its next step.  A small result (at most 64 KiB decoded) is
 * checked at once on the caller's thread instead: cheaper than the hand-off, and its verdict
 * waits the same way.  Forked workers run this program's own
 * encoder on its own pixels (which the worker loop checks for non-finite values before
 * encoding), so their results skip it unless --verify-chunks asks for everyone's.
 *
 * The queue is unbounded in count but not in bytes: what waits here is what the watermark
 * already allows to be outstanding. */
#ifndef TF_RESULTCHECK_H
#define TF_RESULTCHECK_H

#include <stddef.h>
#include <stdint.h>

#include "image/exrlayout.h"
#include "linda/tuple.h"

typedef struct tf_resultcheck tf_resultcheck;

/* A checker with `threads` (>= 1) threads for results of an output of layout l (each result
 * is a task's rectangle, already structurally checked); they start with the first result, so
 * the process stays one thread until then (the coordinator forks its workers meanwhile). */
tf_resultcheck *tf_resultcheck_new(const tf_exr_layout *l, int threads, char *err,
                                   size_t errlen);
/* Stop the threads and drop whatever is queued or decided.  NULL is fine. */
void tf_resultcheck_free(tf_resultcheck *rc);
/* Queue a result tuple for checking; its contents move into the queue (the caller's tuple is
 * left empty), except bytes it only references (tf_tuple_decode_shared), which are copied
 * first: a forked worker's outbox stays writable by that worker, and the tuple a verdict hands
 * back must hold the very bytes that were checked (--verify-chunks against a lying child).
 * 0, or -1 when out of memory or no thread could start (the tuple is then left to the
 * caller). */
int tf_resultcheck_submit(tf_resultcheck *rc, tf_tuple *result);
/* A decided result: 0 (it passed) or 1 (refused, *why says why), its tuple moved into
 * *result; -1 when nothing is decided yet. */
int tf_resultcheck_next(tf_resultcheck *rc, tf_tuple *result, char *why, size_t len);
/* Results queued or being checked, not yet collected. */
size_t tf_resultcheck_pending(tf_resultcheck *rc);
/* CPU seconds the checks have taken (the threads' CPU clocks; for a small result checked on the
 * caller's thread, the check's wall time), and the pixels they checked. */
void tf_resultcheck_totals(tf_resultcheck *rc, double *cpu_s, uint64_t *pixels);

#endif
