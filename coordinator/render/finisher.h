/* finisher.h: finishing a sequence's frames off the event loop.  When a frame's last row is
 * queued, its row writer still has to compress and write what is queued, write the offset
 * table, fsync, and complete the PNG preview: tens of milliseconds for a small frame, more for
 * a large one.  Done in the coordinator's event-loop thread, that would leave every worker
 * waiting for a reply at each frame boundary, which is exactly what a sequence must not do;
 * so each finished frame's writer is handed to a thread of its own (tf_rowwriter_finish), and
 * the event loop collects the outcome (tf_finisher_reap) between iterations. */
#ifndef TF_FINISHER_H
#define TF_FINISHER_H

#include <stddef.h>

#include "coordinator/render/rowwriter.h"

typedef struct tf_finisher tf_finisher;

tf_finisher *tf_finisher_new(void);
/* Finish w (now the finisher's) in a thread; `what` names it in messages.  0, or -1 with a
 * message (then w has been finished in this thread instead, and err holds its error if any). */
int tf_finisher_add(tf_finisher *f, tf_rowwriter *w, const char *what, char *err, size_t errlen);
/* Collect the finishes that are done.  0, or -1 with the first failure's message. */
int tf_finisher_reap(tf_finisher *f, char *err, size_t errlen);
/* Wait for every finish.  0, or -1 with the first failure's message. */
int tf_finisher_wait(tf_finisher *f, char *err, size_t errlen);
/* Wait for every finish, then free. */
void tf_finisher_free(tf_finisher *f);

#endif
