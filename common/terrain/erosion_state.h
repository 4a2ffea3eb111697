/* erosion_state.h: a whole grid's erosion state (erosion.h's seven arrays, n x n, row-major),
 * how it is made from world heights and turned back into them and into maps, and how a
 * rectangle of it is copied into and out of a window with ghosts beyond the grid's edge: what
 * every driver of the erosion (erosion_run.c, the farm's patches) shares. */
#ifndef TF_EROSION_STATE_H
#define TF_EROSION_STATE_H

#include <stddef.h>
#include <stdint.h>

#include "terrain/erosion.h"

typedef struct tf_erosion_state {
    int n;
    int32_t *b, *t, *d, *w, *s;
    float *flow, *soft;
} tf_erosion_state;

/* All seven arrays zeroed (soft too).  0, or -1 on out of memory (nothing allocated). */
int tf_erosion_state_alloc(tf_erosion_state *st, int n);
void tf_erosion_state_free(tf_erosion_state *st);

/* The state of the heights h (n x n world heights): bedrock only, dry, unloaded; the bedrock
 * softness field from the keys.  0, or -1 on out of memory. */
int tf_erosion_state_from_heights(tf_erosion_state *st, const tf_erosion_model *m,
                                  const tf_erosion_keys *k, const float *h);
/* Both for t's erosion of the heights h (n x n): the model (its quantum from h's range) and
 * the initial state.  0, or -1 with one line in err. */
int tf_erosion_begin(const tf_terrain *t, const float *h, int n, tf_erosion_model *m,
                     tf_erosion_state *st, char *err, size_t errlen);
/* World heights of the ground (bedrock + talus + silt) into h (n x n). */
void tf_erosion_heights(const tf_erosion_state *st, const tf_erosion_model *m, float *h);
/* Sums over the grid, exact: bedrock + talus + silt + load, and water (quanta). */
int64_t tf_erosion_solid(const tf_erosion_state *st, int n);
int64_t tf_erosion_water(const tf_erosion_state *st, int n);

/* A window of nx x ny vertices with its own arrays (stride nx + TF_EROSION_PAD, spare room
 * after the last row), for a piece of the grid and its halo, and the kernel's row buffers for
 * all its steps (v.rows: erosion.h, TF_EROSION_ROWS). */
typedef struct tf_erosion_window {
    tf_erosion_view v;
    void *mem;
} tf_erosion_window;
int tf_erosion_window_alloc(tf_erosion_window *win, int nx, int ny);
void tf_erosion_window_free(tf_erosion_window *win);

/* Fill window win, placed at global (gi, gj), from the grid state st: vertices off the grid
 * become ghosts (TF_EROSION_GHOST_ALT high, dry).  Sets win->v.gi, gj. */
void tf_erosion_window_load(tf_erosion_window *win, const tf_erosion_state *st, int gi, int gj);
/* Copy the window's rectangle r (window coordinates, on the grid) into st. */
void tf_erosion_window_store(const tf_erosion_window *win, tf_erosion_state *st,
                             tf_erosion_rect r);

#endif
