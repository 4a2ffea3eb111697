/* erosion_run.c: many erosion steps over a whole grid in one process, cache-blocked and on
 * every core (erosion_run.h).
 *
 * The grid is cut into tiles.  A round of k steps (k = the halo) loads each tile with k more
 * vertices on every side into a window small enough for the core's cache, runs the k steps
 * there (step s updates the tile grown by k - 1 - s, so the tile itself is exact after k
 * steps: a vertex's new state needs only its 4 neighbours' old ones, erosion.h), and stores
 * the tile into the next state.  Tiles read the old state and write the new, so they run in
 * any order on any thread; the halo's work is done twice (by the tile and by its neighbour),
 * the price of reading the grid from memory once per k steps instead of once per step.  The
 * farm's patches (coordinator/erosion/erosion_farm.c) do the same with tuples for the halo. */
#include "terrain/erosion_run.h"

#include <stdlib.h>
#include <string.h>

#include "terrain/gridgen.h"
#include "terrain/heightfield.h"
#include "clock.h"
#include "log.h"

typedef struct {
    const tf_erosion_model *m;
    const tf_erosion_state *old;
    tf_erosion_state *next;
    tf_erosion_window *windows; /* one per piece */
    tf_erosion_tally *tallies;  /* one per piece */
    int *failed;                /* one per piece */
    int tile_w, tile_h, tiles_x;
    int k, first_step;
} round_ctx;

/* k steps on one tile in window win; 0 or -1 (out of memory). */
static int run_tile(const round_ctx *rc, tf_erosion_window *win, int tile, tf_erosion_tally *t)
{
    int n = rc->m->n, k = rc->k;
    int ti = tile % rc->tiles_x, tj = tile / rc->tiles_x;
    int i0 = ti * rc->tile_w, j0 = tj * rc->tile_h;
    int i1 = i0 + rc->tile_w < n ? i0 + rc->tile_w : n;
    int j1 = j0 + rc->tile_h < n ? j0 + rc->tile_h : n;
    win->v.nx = i1 - i0 + 2 * k;
    win->v.ny = j1 - j0 + 2 * k;
    tf_erosion_window_load(win, rc->old, i0 - k, j0 - k);
    tf_erosion_rect own = {k, k + j1 - j0, k, k + i1 - i0};
    for (int s = 0; s < k; s++) {
        int grow = k - 1 - s;
        tf_erosion_rect r = {own.r0 - grow, own.r1 + grow, own.c0 - grow, own.c1 + grow};
        /* never update a ghost: clip to the grid */
        r.r0 = r.r0 + win->v.gj < 0 ? -win->v.gj : r.r0;
        r.c0 = r.c0 + win->v.gi < 0 ? -win->v.gi : r.c0;
        r.r1 = r.r1 + win->v.gj > n ? n - win->v.gj : r.r1;
        r.c1 = r.c1 + win->v.gi > n ? n - win->v.gi : r.c1;
        if (tf_erosion_step(rc->m, &win->v, r, own, rc->first_step + s, t) != 0)
            return -1;
    }
    tf_erosion_window_store(win, rc->next, own);
    return 0;
}

static void run_tiles(void *arg, int piece, int begin, int end)
{
    const round_ctx *rc = arg;
    for (int tile = begin; tile < end && !rc->failed[piece]; tile++)
        if (run_tile(rc, &rc->windows[piece], tile, &rc->tallies[piece]) != 0)
            rc->failed[piece] = 1;
}

/* Per-piece windows, tallies and flags for `pieces` pieces of tiles of the given size. */
static int round_alloc(round_ctx *rc, int pieces, int halo)
{
    rc->windows = calloc((size_t)pieces, sizeof *rc->windows);
    rc->tallies = calloc((size_t)pieces, sizeof *rc->tallies);
    rc->failed = calloc((size_t)pieces, sizeof *rc->failed);
    if (!rc->windows || !rc->tallies || !rc->failed)
        return -1;
    for (int p = 0; p < pieces; p++)
        if (tf_erosion_window_alloc(&rc->windows[p], rc->tile_w + 2 * halo,
                                    rc->tile_h + 2 * halo) != 0)
            return -1;
    return 0;
}

static void round_free(round_ctx *rc, int pieces)
{
    for (int p = 0; rc->windows && p < pieces; p++)
        tf_erosion_window_free(&rc->windows[p]);
    free(rc->windows);
    free(rc->tallies);
    free(rc->failed);
}

/* One round: k steps from first_step, old -> next; the pieces' tallies added to *tally. */
static int run_round(round_ctx *rc, int pieces, int threads, tf_erosion_tally *tally)
{
    int n = rc->m->n;
    int tiles = rc->tiles_x * ((n + rc->tile_h - 1) / rc->tile_h);
    memset(rc->tallies, 0, (size_t)pieces * sizeof *rc->tallies);
    tf_grid_parallel(tiles, threads, 1, run_tiles, rc);
    for (int p = 0; p < pieces; p++) {
        if (rc->failed[p])
            return -1;
        tally->rain += rc->tallies[p].rain;
        tally->evaporated += rc->tallies[p].evaporated;
        tally->out_water += rc->tallies[p].out_water;
        tally->out_load += rc->tallies[p].out_load;
    }
    return 0;
}

static void swap_states(tf_erosion_state *a, tf_erosion_state *b)
{
    tf_erosion_state t = *a;
    *a = *b;
    *b = t;
}

int tf_erosion_run(tf_erosion_state *st, const tf_erosion_model *m, const tf_erosion_run_opts *o,
                   tf_erosion_tally *tally, char *err, size_t errlen)
{
    int n = m->n;
    int halo = o->halo > 0 ? o->halo : TF_EROSION_DEFAULT_HALO;
    int threads = o->threads > 0 ? o->threads : tf_thread_count(0);
    round_ctx rc = {m, st, NULL, NULL, NULL, NULL,
                    o->tile_w > 0 ? o->tile_w : TF_EROSION_TILE_W,
                    o->tile_h > 0 ? o->tile_h : TF_EROSION_TILE_H, 0, 0, o->first_step};
    rc.tiles_x = (n + rc.tile_w - 1) / rc.tile_w;
    int tiles = rc.tiles_x * ((n + rc.tile_h - 1) / rc.tile_h);
    int pieces = tf_grid_pieces(tiles, threads, 1);
    tf_erosion_state next;
    int rcode = -1;
    if (tf_erosion_state_alloc(&next, n) != 0 || round_alloc(&rc, pieces, halo) != 0) {
        tf_seterr(err, errlen, "out of memory: erosion of a %dx%d grid", n, n);
        goto done;
    }
    memcpy(next.soft, st->soft, (size_t)n * (size_t)n * sizeof *next.soft);
    for (int done_steps = 0; done_steps < o->steps; done_steps += rc.k) {
        rc.k = o->steps - done_steps < halo ? o->steps - done_steps : halo;
        rc.first_step = o->first_step + done_steps;
        rc.old = st;
        rc.next = &next;
        if (run_round(&rc, pieces, threads, tally) != 0) {
            tf_seterr(err, errlen, "out of memory: erosion of a %dx%d grid", n, n);
            goto done;
        }
        swap_states(st, &next);
    }
    rcode = 0;
done:
    round_free(&rc, pieces);
    tf_erosion_state_free(&next);
    return rcode;
}
