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
    int workers, px, py, halo;
    double edge_bytes_per_step; /* edges traded through the space, per time step */
} tf_erosion_farm_report;

/* t's eroded terrain's blob (*bytes malloc'd): from the cache, or eroded now on `workers`
 * forked workers with edges traded every `halo` steps (<= 0: 8).  0, or -1 with one line in
 * err (a worker that fails or dies fails the erosion; none is left behind). */
int tf_erosion_farm(const tf_terrain *t, int workers, int halo, uint8_t **bytes, size_t *len,
                    tf_erosion_report *rep, tf_erosion_farm_report *fr, char *err,
                    size_t errlen);

#endif
