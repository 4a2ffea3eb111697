/* erosion_run.h: run erosion steps over a whole grid state in one process, in cache-sized
 * tiles with a halo, on several threads; bit-identical for every tile shape, halo and thread
 * count (erosion.h says why).  The farm's patches are the same idea across processes. */
#ifndef TF_EROSION_RUN_H
#define TF_EROSION_RUN_H

#include "terrain/erosion.h"
#include "terrain/erosion_state.h"

/* A tile and its halo's window, (192 + 24) x (96 + 24) vertices of 28 bytes: 726 KiB, inside a
 * 1 MiB L2.  Against halo 8 and 256 x 64 tiles: 30% less copying a step for 3% more halo
 * work; measured the best of halos 8-16 and tiles 128-512 wide on an AMD EPYC (+7 to +13%). */
#define TF_EROSION_DEFAULT_HALO 12
#define TF_EROSION_TILE_W 192
#define TF_EROSION_TILE_H 96

typedef struct tf_erosion_run_opts {
    int first_step;  /* global number of the first step (rain falls on multiples of its interval) */
    int steps;
    int threads;     /* <= 0: all online CPUs */
    int halo;        /* steps per round; <= 0: TF_EROSION_DEFAULT_HALO */
    int tile_w, tile_h; /* <= 0: the defaults */
} tf_erosion_run_opts;

/* Run o->steps steps on st in place; what rained, evaporated and left is added to *tally.
 * 0, or -1 with one line in err (out of memory; st is then left at a whole round's state). */
int tf_erosion_run(tf_erosion_state *st, const tf_erosion_model *m, const tf_erosion_run_opts *o,
                   tf_erosion_tally *tally, char *err, size_t errlen);

#endif
