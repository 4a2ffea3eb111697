/* paint_worker.h: a worker of Raypaint (Musgrave A.7.2.4; common/paintproto.h): take a task of
 * quad-tree nodes, trace the samples or render the pixels they ask for in the view the task
 * names, put the values back, until the stop task.  Forked paint workers run it with the
 * terrain inherited; networked ones (`terrafarm worker --connect` to a `terrafarm paint`) after
 * reading the scene tuple, whose layout is TF_PAINT_LAYOUT.
 *
 * A view's scene comes from its ("paint_view", gen, ...) tuple and must describe this worker's
 * terrain (the camera, sun and mist may change, the terrain never): a view that does not is
 * refused and the worker leaves.  Every sample is the final render's own (render.h: a function
 * of its lattice point), so a painted node is exactly what `terrafarm render` makes there.
 * This loop renders with the C renderer only: --backend opencl does not apply to painting. */
#ifndef TF_PAINT_WORKER_H
#define TF_PAINT_WORKER_H

#include "linda/tsclient.h"
#include "paintproto.h"
#include "render/render.h"
#include "scene.h"
#include "terrain/heightfield.h"

/* Join, then serve paint tasks until the stop task: 0; TF_WORKER_EXIT_LOST (worker.h) when the
 * coordinator was lost; 1 on a refusal or a view this worker cannot paint (one line logged). */
int tf_paint_worker_loop(ts_client *c, const tf_scene *s, const tf_heightfield *hf,
                         const char *kind);

/* The values of one task's nodes for renderer r (tf_paint_task_values floats into out). */
void tf_paint_render_nodes(const tf_renderer *r, const tf_paint_node *nodes, int count, int w,
                           int h, float *out);

#endif
