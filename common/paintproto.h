/* paintproto.h: Raypaint on the farm (Musgrave A.7.2.4), the tuples the paint coordinator and
 * its workers speak, and the geometry both sides (and the page, web/paint.js) derive from a
 * quad-tree node:
 *
 *   ("scene", text, width, height, hash, "paint")   farmproto.h's scene tuple; the layout
 *                                                   TF_PAINT_LAYOUT sends a networked worker
 *                                                   to the paint loop (worker/paint_worker.h)
 *   ("paint_view", gen:I, text:S, hash:S)           the scene of view `gen` (the camera, sun
 *                                                   and mist edited; the terrain never), rd
 *   ("paint_task", gen:I, id:I, nodes:B)            nodes to refine in view gen; gen < 0: stop
 *   ("paint_result", gen:I, id:I, worker:I, busy_ns:I, values:B)
 *
 * THE NODES.  A node is an aligned square of the image, x, y, size s (a power of two), over
 * the lattice of pixel corners (0..W, 0..H: corner (X, Y) is the sample render.c traces at the
 * top-left corner of pixel (X, Y), so it is the final render's own sample).  Its lattice at
 * stride d (d divides s) is every corner x + i*d < end, then end = min(x + s, W) itself, on
 * each axis (tf_paint_axis); the last cell of a node on the image's edge is narrower.
 * A record is 5 little-endian int32: x, y, s, d, flags.
 *   d >= 1   SAMPLE: one sample (r, g, b) per lattice point at stride d, row by row, leaving
 *            out the node's 4 corners when flags & TF_PAINT_CORNERS_KNOWN
 *   d == 0   EXACT: tf_render_rect of the node's pixels [x, end) x [y, endy): the final
 *            render's pixels, adaptive antialiasing and all; TF_PAINT_PIXEL_FLOATS per pixel
 * Values are little-endian float32, the nodes' one after another (tf_paint_task_values).
 *
 * A result is structurally valid for its task when it is exactly that long; the coordinator
 * then checks every value (tf_paint_values_check) before anything is drawn.  It never trusts
 * a worker's word for where a value goes: that comes from its own record of the task. */
#ifndef TF_PAINTPROTO_H
#define TF_PAINTPROTO_H

#include <stddef.h>
#include <stdint.h>

#include "linda/tuple.h"

#define TF_PAINT_LAYOUT "paint"
#define TF_TAG_PAINT_VIEW "paint_view"
#define TF_TAG_PAINT_TASK "paint_task"
#define TF_TAG_PAINT_RESULT "paint_result"
#define TF_PAINT_VIEW_FIELDS 4
#define TF_PAINT_TASK_FIELDS 4
#define TF_PAINT_RESULT_FIELDS 6

#define TF_PAINT_CORNERS_KNOWN 1
#define TF_PAINT_RECORD_BYTES 20
#define TF_PAINT_SAMPLE_FLOATS 3   /* r, g, b */
#define TF_PAINT_PIXEL_FLOATS 6    /* tf_pixel: r, g, b, a, z, spp */
#define TF_PAINT_MAX_NODES 4096    /* per task */
#define TF_PAINT_MAX_SIZE 1024     /* largest node side */
#define TF_PAINT_STOP (-1)         /* gen of the stop task, which every worker puts back */

typedef struct tf_paint_node {
    int x, y, s, d, flags;
} tf_paint_node;

/* The lattice positions of a node's axis [x, x + s] at stride d, clamped at limit (W or H):
 * writes them to pos (at most s/d + 1) and returns how many. */
int tf_paint_axis(int x, int s, int d, int limit, int *pos);
/* Why node n cannot be a node of a w x h image, or NULL. */
const char *tf_paint_node_problem(const tf_paint_node *n, int w, int h);
/* Floats the answer to node n carries (n valid for w x h). */
size_t tf_paint_node_values(const tf_paint_node *n, int w, int h);
/* ... and to a whole task. */
size_t tf_paint_task_values(const tf_paint_node *nodes, int count, int w, int h);
/* Is lattice point (i, j) of node n (indices on its axes, ni x nj points) one it skips? */
int tf_paint_point_skipped(const tf_paint_node *n, int i, int j, int ni, int nj);

void tf_paint_nodes_put(uint8_t *out, const tf_paint_node *nodes, int count);
/* Parse a task's node blob for a w x h image: the count, or -1 with why. */
int tf_paint_nodes_get(const uint8_t *blob, size_t len, int w, int h, tf_paint_node *nodes,
                       int max, const char **why);

int tf_paint_view_pack(tf_tuple *t, int64_t gen, const char *text, const char *hash);
int tf_paint_task_pack(tf_tuple *t, int64_t gen, int64_t id, const tf_paint_node *nodes,
                       int count);
int tf_paint_result_pack(tf_tuple *t, int64_t gen, int64_t id, int64_t worker, int64_t busy_ns,
                         const float *values, size_t nvalues);

/* A task as taken, a result as received: blobs borrowed from the tuple. */
typedef struct tf_paint_task_msg {
    int64_t gen, id;
    const uint8_t *nodes;
    size_t nodes_len;
} tf_paint_task_msg;
typedef struct tf_paint_result_msg {
    int64_t gen, id, worker, busy_ns;
    const uint8_t *values;
    size_t values_len;
} tf_paint_result_msg;
int tf_paint_task_unpack(const tf_tuple *t, tf_paint_task_msg *m);
int tf_paint_result_unpack(const tf_tuple *t, tf_paint_result_msg *m);

/* Every value of an answer to nodes: finite; colours 0 .. TF_PAINT_MAX_RADIANCE; an exact
 * pixel's alpha in [0, 1], z > 0, spp 4 .. the antialiasing's most for aa_depth.  Decodes the
 * little-endian floats into out.  0, or -1 with a one-line reason naming the node. */
#define TF_PAINT_MAX_RADIANCE 1e6f
int tf_paint_values_check(const uint8_t *values, size_t len, const tf_paint_node *nodes,
                          int count, int w, int h, int aa_depth, float *out, char *err,
                          size_t errlen);

#endif
