/* erosion_patch.h: a worker's part in an erosion on the farm: one patch of the grid, its halo
 * refilled from its neighbours' edges every round (common/erosion_tuples.h). */
#ifndef TF_EROSION_PATCH_H
#define TF_EROSION_PATCH_H

#include "erosion_tuples.h"
#include "linda/tsclient.h"
#include "terrain/erosion.h"
#include "terrain/erosion_state.h"

/* Take one ("erode_patch", plan->job, ?) from c, erode it through every round from the
 * initial state init (the whole grid, as every worker derives it from the scene), and hand in
 * its final state and tally.  On failure says why (one line, naming `from`), puts
 * ("erode_failed", ...) for the coordinator, and returns 1; 0 on success. */
int tf_erosion_patch_serve(ts_client *c, const tf_erosion_plan *plan, const tf_erosion_model *m,
                           const tf_erosion_state *init, const char *from);

/* A networked worker whose coordinator turns out to run an erosion (its space holds an
 * ("erode_plan", ...)): read the scene, check the plan fits it, derive the initial state,
 * serve one patch.  -1 when c's space is not an erosion's (the caller renders instead);
 * else the exit status, 0 or 1. */
int tf_erosion_networked(ts_client *c, const char *from, int heartbeat_ms);

#endif
