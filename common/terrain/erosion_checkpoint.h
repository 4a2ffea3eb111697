/* erosion_checkpoint.h: an erosion's whole state kept in the erosion cache, so that a longer
 * erosion of the same terrain (the next frame of an erosion film: [animation] erosion_steps)
 * continues from the longest one already done instead of starting again.  Continuing is
 * exact: the state is integers and the rain falls by the global step number (erosion.h), so
 * S steps then S' - S more are bit for bit S' steps.  Kept only when enabled (a film turns it
 * on); a checkpoint that does not check out is not used. */
#ifndef TF_EROSION_CHECKPOINT_H
#define TF_EROSION_CHECKPOINT_H

#include "terrain/erosion_state.h"
#include "scene.h"

void tf_erosion_checkpoints_enable(int on);
int tf_erosion_checkpoints_enabled(void);

/* Keep st, t's erosion after `steps` steps, in dir. */
void tf_erosion_checkpoint_save(const tf_terrain *t, const char *dir, const tf_erosion_state *st,
                                int steps);
/* The longest checkpoint of t's erosion in dir with at most max_steps steps, loaded into st
 * (allocated, st->n x st->n; its soft field untouched): its step count, or 0 for none. */
int tf_erosion_checkpoint_find(const tf_terrain *t, const char *dir, int max_steps,
                               tf_erosion_state *st);

#endif
