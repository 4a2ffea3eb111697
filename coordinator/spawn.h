/* spawn.h: fork a local worker (Musgrave's fork model of eval()).  The child inherits the
 * parsed scene and the height field copy-on-write, talks to the coordinator over one end of a
 * socketpair, and never returns. */
#ifndef TF_SPAWN_H
#define TF_SPAWN_H

#include <sys/types.h>

#include "terrain/heightfield.h"
#include "scene.h"
#include "linda/tsserver.h"

/* Fork worker number `index`; the parent's end of the socketpair is added to srv as a trusted
 * connection.  Returns the child's pid, or -1 with a message in err. */
pid_t tf_spawn_worker(ts_server *srv, const tf_scene *s, const tf_heightfield *hf,
                      const char *backend, int index, char *err, size_t errlen);

#endif
