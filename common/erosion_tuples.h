/* erosion_tuples.h: an erosion on the farm (Musgrave A.7.3): the grid cut into px x py patches,
 * one per worker, each exchanging its edges with its 8 neighbours through the tuple space every
 * `halo` steps, and the tuples both sides speak:
 *
 *   ("erode_patch", job:I, patch:I)                     dealt once per patch; a worker in's one
 *   ("erode_edge", job:I, patch:I, round:I, side:I, data:B)
 *        the patch's state after `round` rounds, on the `halo` rows or columns along one side
 *        (0 south: its first rows, 1 north: its last, 2 west: its first columns, 3 east)
 *   ("erode_final", job:I, patch:I, row:I, rows:I, data:B)  its final state, a band of rows
 *   ("erode_tally", job:I, patch:I, rain:I, evaporated:I, out_water:I, out_load:I)
 *   ("erode_failed", job:I, patch:I, why:S)
 *
 * State travels as six arrays one after the other (bedrock, talus, silt, water, load, flow;
 * erosion.h), each row-major over the block, 4 bytes an element.  Rounds: round r runs steps
 * r*halo .. min((r+1)*halo, steps) - 1; before it (r > 0) a patch refills its halo from its
 * neighbours' edges of round r - 1 (erosion.h: k steps need k vertices around), so the
 * result is the single-process result, bit for bit, for any patch shape.  A block that
 * arrives is checked before use: its size, and that every value is one the model can produce
 * (no negative water, load or layers; altitudes and flow in range): a broken or hostile
 * worker's block is refused with one line, never folded into the terrain. */
#ifndef TF_EROSION_TUPLES_H
#define TF_EROSION_TUPLES_H

#include <stddef.h>
#include <stdint.h>

#include "linda/tuple.h"
#include "terrain/erosion_state.h"

#define TF_EROSION_FIELDS 6 /* b, t, d, w, s, flow */

/* An erosion's space also holds the scene tuple (farmproto.h) for networked workers, with this
 * in place of an output layout, and ("erode_plan", job, n, px, py, halo, steps): a worker that
 * reads the one goes on to the other instead of rendering. */
#define TF_EROSION_LAYOUT "erosion"

typedef struct tf_erosion_plan {
    int64_t job;
    int n;        /* grid side */
    int px, py;   /* patches across, up */
    int halo;     /* steps per round (<= every patch's side) */
    int steps;
} tf_erosion_plan;

/* A plan for `workers` patches (px x py as square as the count allows) and the halo wanted,
 * shrunk to the smallest patch side.  0, or -1 if the grid is too small for that many. */
int tf_erosion_plan_make(tf_erosion_plan *p, int64_t job, int n, int workers, int halo,
                         int steps);
int tf_erosion_plan_rounds(const tf_erosion_plan *p);
/* Bytes of edges all patches put in one round (each edge toward a neighbour, once). */
double tf_erosion_plan_edge_bytes(const tf_erosion_plan *p);
/* Patch `patch`'s rectangle of the grid: [i0, i1) x [j0, j1). */
void tf_erosion_patch_rect(const tf_erosion_plan *p, int patch, int *i0, int *i1, int *j0,
                           int *j1);

/* A block of state: rows x cols elements of each of the six arrays. */
size_t tf_erosion_block_bytes(int rows, int cols);
/* Copy the window rectangle r of v into data (tf_erosion_block_bytes long), and back. */
void tf_erosion_block_pack(const tf_erosion_view *v, tf_erosion_rect r, uint8_t *data);
void tf_erosion_block_unpack(tf_erosion_view *v, tf_erosion_rect r, const uint8_t *data);
/* Check a received block of rows x cols: its length and every value's range.  0, or -1 with
 * one line naming `from` and what is wrong. */
int tf_erosion_block_check(const uint8_t *data, size_t len, int rows, int cols,
                           const char *from, char *err, size_t errlen);

#endif
