/* worker.h: the worker loop (Musgrave Appendix A): take a task tuple, render its rectangle,
 * put the result back, until the stop tuple appears.  Forked workers run it in a child of the
 * coordinator over a socketpair, with the scene and height field inherited copy-on-write;
 * networked workers (`terrafarm worker`) run it after fetching the scene from the tuple space
 * (tf_worker_fetch_scene) and building the terrain themselves. */
#ifndef TF_WORKER_H
#define TF_WORKER_H

#include "terrain/heightfield.h"
#include "scene.h"
#include "linda/tsclient.h"

/* Heartbeat interval: well under the coordinator's default 15 s silence timeout. */
#define TF_WORKER_HEARTBEAT_MS 2000

/* Exit status of a worker that could not start at all (e.g. no OpenCL device): the coordinator
 * does not restart it. */
#define TF_WORKER_EXIT_NOSTART 3

/* Serve tasks until told to stop.  kind is "forked" or "networked".  Returns an exit status
 * (0 when the render finished); prints one line on failure.  Closes nothing: the caller owns c. */
int tf_worker_loop(ts_client *c, const tf_scene *s, const tf_heightfield *hf, const char *kind,
                   const char *backend);

/* rd the ("scene", ...) tuple, parse it and apply the render's image size.  NULL with a message
 * on failure (including a scene whose hash differs from the coordinator's). */
tf_scene *tf_worker_fetch_scene(ts_client *c, const char *coordinator, char *err, size_t errlen);

#endif
