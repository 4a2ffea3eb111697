/* worker_role.h: the role of every worker connection to the coordinator's tuple space (the
 * farm's use of linda/capability.h).  A worker, forked or networked, holding the secret or
 * not, can only render:
 *
 *   rd  ("scene", ...)            read the scene (any number of times: reconnections), and
 *   rd  ("heightmap"...)          a generator = file scene's height map (heightmap_tuples.h)
 *   in  ("next_worker", ?n)       once: take a worker id, bound to the connection there and
 *                                 then (the supervisor puts the counter back itself)
 *   out ("hello", id, ...)        once, with its own id
 *   in  ("task", ...)             only while it holds no other task (no hoarding)
 *   out ("task", ...)             put back a task it holds (it is excluded from it); the
 *                                 supervisor deals its own copy, the worker's is not stored;
 *                                 the stop task only as it was dealt, once it was dealt
 *   out ("result", ...)           only for a task it holds, under its own id, with exactly the
 *                                 task's size and finite values; the first result wins
 *   out ("failed", ...)           only for a task it holds, under its own id
 *
 * Everything else (taking results or the scene, putting scenes, tasks or counters, reading
 * tasks) is refused.  The supervisor is in-process and privileged. */
#ifndef TF_WORKER_ROLE_H
#define TF_WORKER_ROLE_H

#include <stddef.h>

#include "coordinator/render/supervisor.h"
#include "coordinator/render/tasks.h"
#include "linda/capability.h"

/* Fill role for the workers of this render (guard context: sup).  The largest tuple a worker
 * may send follows the largest task's result. */
void tf_worker_role_init(ts_role *role, tf_supervisor *sup, const tf_tasks *tasks);

#endif
