/* erosion_farm.h: erode a terrain on forked workers, one patch each, that trade their edges
 * through the tuple space (Musgrave A.7.3; common/erosion_tuples.h has the protocol).  The
 * result is the same blob, bit for bit, as eroding in one process (terrain/eroded.h), and goes
 * into the same cache. */
#ifndef TF_EROSION_FARM_H
#define TF_EROSION_FARM_H

#include <stddef.h>
#include <stdint.h>

#include "erosion_tuples.h"
#include "terrain/eroded.h"
#include "scene.h"

typedef struct tf_erosion_farm_report {
    int workers, remote, px, py, halo;
    double edge_bytes_per_step; /* edges traded through the space, per time step */
} tf_erosion_farm_report;

typedef struct tf_erosion_farm_opts {
    int forked;             /* workers forked here, one patch each */
    int remote;             /* networked workers expected (terrafarm worker --connect) */
    int halo;               /* steps per round; <= 0: 8 */
    const char *listen;     /* where networked workers connect (remote > 0) */
    const uint8_t *key;     /* their secret (tf_secret_load), or NULL on loopback */
} tf_erosion_farm_opts;

/* s's eroded terrain's blob (*bytes malloc'd): from the cache, or eroded now on o->forked
 * forked workers and o->remote networked ones, edges traded every o->halo steps.  The
 * networked workers read the scene and derive the initial state themselves; the plan's grid
 * is s->terrain's.  0, or -1 with one line in err (a worker that fails, dies or leaves with its
 * patch fails the erosion; no forked worker is left behind). */
int tf_erosion_farm(const tf_scene *s, const tf_erosion_farm_opts *o, uint8_t **bytes,
                    size_t *len, tf_erosion_report *rep, tf_erosion_farm_report *fr, char *err,
                    size_t errlen);

#endif
