/* paint_role.h: Raypaint's dealer and doorman -- the leases of the tasks dealt in the current
 * view, the paint worker role (what any worker, forked or networked, may do in the space) with
 * its admission guard, the server's hooks, and what happens to a result.
 *
 * The rules, the farm's own (coordinator/render/worker_role.c) in paint's words:
 *   - a worker may read the scene, its height map or eroded terrain, and the views; take one
 *     worker id and announce itself once; take any paint task; put back only the stop task;
 *   - a result is admitted only from the connection holding that task's lease in the current
 *     view; one for a task never dealt, or held by another connection, or answered already,
 *     is REFUSEd (a forged result); one of an earlier view, or of a lease taken back, is
 *     DISCARDed (stale: never stored, never drawn);
 *   - a result's values are checked before anything is drawn (tf_paint_values_check): a result
 *     that fails is refused, its cells dealt again, and its sender's connection closed;
 *   - a lease held past TF_PAINT_LEASE_S is taken back (its cells dealt again, its late result
 *     discarded), so a worker that says nothing useful cannot hold the picture still.
 * Invariants (tf_paint_role_check): L1 every lease is of the current view; L2 a lease's conn is
 * 0 (its task is still in the space) or a connection; L3 workers counts the hellos of the
 * connections still open. */
#ifndef TF_PAINT_ROLE_H
#define TF_PAINT_ROLE_H

#include <stddef.h>
#include <stdint.h>

#include "coordinator/paint/painttree.h"
#include "linda/capability.h"
#include "linda/tsserver.h"
#include "linda/tuplespace.h"

#define TF_PAINT_LEASE_S 30.0

typedef struct tf_paint_lease {
    int64_t id;
    uint64_t conn;        /* 0: its task is in the space */
    int answered;         /* its result is in the space */
    double taken_s;
    int count;
    tf_paint_node *nodes;
} tf_paint_lease;

typedef struct tf_paint_role {
    ts_role role;
    ts_space *space;
    ts_server *srv;           /* set once the server exists */
    tf_paint_tree *tree;      /* set by tf_paint_role_new_view */
    int w, h;
    int64_t gen, next_id, next_worker;
    tf_paint_lease *leases;
    int nleases, cap;
    uint64_t *hellos;         /* connections that said hello */
    int workers, hellos_cap;
    int64_t results, stale, refused, expired;
} tf_paint_role;

void tf_paint_role_init(tf_paint_role *r, ts_space *space, int w, int h,
                        const tf_paint_params *p);
void tf_paint_role_free(tf_paint_role *r);
ts_server_hooks tf_paint_role_hooks(tf_paint_role *r);
/* View gen begins: the old view's tasks still in the space are taken out, every lease
 * forgotten (their results will be stale). */
void tf_paint_role_new_view(tf_paint_role *r, int64_t gen, tf_paint_tree *tree);
/* Deal the tree's best cells while fewer than the watermark (2 per worker, plus 1) are out;
 * take back expired leases.  The watermark keeps the dealt work small, so a new area of
 * interest or a new view is served soon. */
void tf_paint_role_deal(tf_paint_role *r, tf_paint_tree *tree);
/* A result taken from the space: checked, applied to the tree (its display messages into
 * msgs), the lease closed: 1; or dropped (stale) or refused: 0.  values is scratch. */
int tf_paint_role_take_result(tf_paint_role *r, tf_paint_tree *tree, const tf_tuple *t,
                              int aa_depth, float **values, size_t *cap, tf_paint_bytes *msgs);
/* L1-L3, one assert per clause; returns 1. */
int tf_paint_role_check(const tf_paint_role *r);

#endif
