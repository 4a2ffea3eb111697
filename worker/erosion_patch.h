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

/* A networked worker whose coordinator runs an erosion (its scene tuple said so:
 * TF_EROSION_LAYOUT): read the plan, check it fits the scene s, derive the initial state,
 * serve one patch.  The exit status, 0 or 1. */
int tf_erosion_networked(ts_client *c, const tf_scene *s, const char *from, int heartbeat_ms);

#endif
