/* erosion_role.h: what a networked worker may do in an erosion's tuple space
 * (common/erosion_tuples.h): read the scene, the plan and anyone's edges; take one patch; put
 * and take back edges, and hand in the final bands, tally or failure, of its own patch only.
 * Who owns which patch is recorded as patches are taken (tf_erosion_owners_take). */
#ifndef TF_EROSION_ROLE_H
#define TF_EROSION_ROLE_H

#include <stdint.h>

#include "linda/capability.h"

typedef struct tf_erosion_owners {
    int patches;
    uint64_t *conn; /* per patch: the connection that took it, 0 none yet */
} tf_erosion_owners;

/* The role over owners (which the guard reads); largest tuple max_tuple_bytes. */
void tf_erosion_role_init(ts_role *role, tf_erosion_owners *owners, size_t max_tuple_bytes);
/* A patch tuple (name "erode_patch") was taken by conn: it is conn's from now. */
void tf_erosion_owners_take(tf_erosion_owners *o, uint64_t conn, const tf_tuple *patch);
/* The patch conn owns, or -1. */
int tf_erosion_owners_patch(const tf_erosion_owners *o, uint64_t conn);

#endif
