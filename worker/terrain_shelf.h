/* terrain_shelf.h: the terrains a standing worker keeps between jobs, by terrain key
 * (farm_keys.h tf_farm_terrain_key), least recently used out beyond a byte budget.  A worker
 * sent to a job whose terrain it holds starts at once; the farm prefers to send it there
 * (coordinator/farm/scheduler.h). */
#ifndef TF_TERRAIN_SHELF_H
#define TF_TERRAIN_SHELF_H

#include <stddef.h>

#include "terrain/heightfield.h"

typedef struct tf_terrain_shelf tf_terrain_shelf;

tf_terrain_shelf *tf_terrain_shelf_new(size_t budget_bytes);
void tf_terrain_shelf_free(tf_terrain_shelf *sh);
/* The terrain kept under key (now the most recently used), or NULL. */
const tf_heightfield *tf_terrain_shelf_get(tf_terrain_shelf *sh, const char *key);
/* Keep hf (owned from now on) under key, dropping the least recently used others while the
 * total is over budget (the newest stays even alone over it). */
void tf_terrain_shelf_put(tf_terrain_shelf *sh, const char *key, tf_heightfield *hf);
/* The keys held, most recent first: up to max pointers into the shelf. */
int tf_terrain_shelf_keys(const tf_terrain_shelf *sh, const char **keys, int max);
/* An estimate of what hf holds in memory (samples, max/min grids, erosion maps). */
size_t tf_heightfield_bytes(const tf_heightfield *hf);

#endif
