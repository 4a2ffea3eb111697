/* worker.h: the worker loop (Musgrave Appendix A): take a task tuple, render its rectangle,
 * put the result back, until the stop tuple appears.  Forked workers run it in a child of the
 * coordinator over a socketpair, with the scene and height field inherited copy-on-write;
 * networked workers (`terrafarm worker`) run it after fetching the scene from the tuple space
 * (tf_worker_fetch_scene) and building the terrain themselves. */
#ifndef TF_WORKER_H
#define TF_WORKER_H

#include "terrain/heightfield.h"
#include "farmproto.h"
#include "scene.h"
#include "linda/tsclient.h"
#include "render/render.h"
#include "image/exrlayout.h"

/* Heartbeat interval (farmproto.h: a quarter of the shortest lease a coordinator accepts). */
#define TF_WORKER_HEARTBEAT_MS TF_HEARTBEAT_MS

/* Exit status of a worker that could not start at all (e.g. no OpenCL device): the coordinator
 * does not restart it. */
#define TF_WORKER_EXIT_NOSTART 3
/* tf_worker_loop lost its coordinator (connection closed, reset, a refused request): a
 * networked worker reconnects (worker/networked.c); a forked one is restarted. */
#define TF_WORKER_EXIT_LOST 4

/* What a worker does with a task: the real worker's C or OpenCL backend traces rays; a test
 * may render anything.  The loop around it -- take, check, render, encode, put the result
 * back -- is tf_worker_serve's.  (The simulated workers, worker/simulate.c, speak the same
 * protocol from one event loop, without this loop.) */
typedef struct tf_worker_step {
    void *ctx;
    /* Render rect of `frame` (-1 for a still scene, else a frame of its animation) into
     * px[rect.w * rect.h]; fill *counts and *busy_ns (the time it took).  0, or -1 with one
     * line in err (reported to the coordinator as a task failure). */
    int (*render)(void *ctx, int frame, tf_rect rect, tf_pixel *px, tf_render_counts *counts,
                  int64_t *busy_ns, char *err, size_t errlen);
    /* The image a task's rectangle must lie in (0: not checked beyond its size). */
    int image_w, image_h;
} tf_worker_step;

/* Join the render: take a worker id (Linda's counter idiom) and announce ("hello", id, kind,
 * host, pid, backend).  0, or -1 (the client's error says why). */
int tf_worker_join(ts_client *c, const char *kind, const char *backend, int64_t *id);
/* The same, and the hello leaves with the first take of a task in one round trip (ts_out_in):
 * when the coordinator sees the hello, this worker is already waiting for a task.  Returns once
 * the first task tuple is in *first (to hand to tf_worker_serve_from). */
int tf_worker_join_take(ts_client *c, const char *kind, const char *backend, int64_t *id,
                        tf_tuple *first);

/* How tf_worker_serve ended. */
enum { TF_SERVE_STOPPED = 0, TF_SERVE_LOST = 1, TF_SERVE_UNDELIVERED = 2 };

/* Take tasks and answer them with step until the stop tuple: TF_SERVE_STOPPED; or the
 * coordinator was lost while waiting for a task (TF_SERVE_LOST) or while delivering a result
 * (TF_SERVE_UNDELIVERED).  Logs nothing about those two: the caller knows whether the render
 * was ending anyway. */
int tf_worker_serve(ts_client *c, int64_t id, const tf_exr_layout *layout,
                    const tf_worker_step *step);
/* The same, starting with the task in *first (taken when joining; moved out, *first left
 * empty), or with a take when first is NULL. */
int tf_worker_serve_from(ts_client *c, int64_t id, const tf_exr_layout *layout,
                         const tf_worker_step *step, tf_tuple *first);

/* The real worker: join, build the backend, serve until told to stop.  kind is "forked" or
 * "networked".  Returns an exit status (0 when the render finished; TF_WORKER_EXIT_NOSTART
 * when the backend cannot start; TF_WORKER_EXIT_LOST when the connection was lost); prints one
 * line on failure.  Closes nothing: the caller
 * owns c. */
int tf_worker_loop(ts_client *c, const tf_scene *s, const tf_heightfield *hf, const char *kind,
                   const char *backend);

/* rd the ("scene", ...) tuple for the output's layout, which every result is encoded for.  0, or
 * -1 with a message. */
int tf_worker_fetch_layout(ts_client *c, tf_exr_layout *l, char *err, size_t errlen);

/* rd the ("scene", ...) tuple, parse it and apply the render's image size.  NULL with a message
 * on failure (including a scene whose hash differs from the coordinator's). */
tf_scene *tf_worker_fetch_scene(ts_client *c, const char *coordinator, char *err, size_t errlen);
/* What a coordinator's space is doing, from its scene tuple's layout. */
enum { TF_SPACE_RENDER = 0, TF_SPACE_EROSION = 1, TF_SPACE_PAINT = 2 };
/* The same, and *kind (if not NULL) says what the space does: a render; an erosion
 * (common/erosion_tuples.h: its layout is TF_EROSION_LAYOUT), whose eroded terrain is then not
 * read (that space is computing it); or Raypaint (common/paintproto.h: TF_PAINT_LAYOUT). */
tf_scene *tf_worker_fetch_scene_ex(ts_client *c, const char *coordinator, int *kind,
                                   char *err, size_t errlen);

#endif
