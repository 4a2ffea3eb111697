/* erosion.h: Musgrave's fluvial erosion (dissertation 2.4.1) with dry creep (2.4.3) and layered
 * ground (2.4.4), as a synchronous stencil on a grid of integers: the model, its state, and the
 * one time step every driver (erosion_run.c in one process, the farm's patches) repeats.
 *
 * The state of a vertex (all in quanta of q metres, int32, so every transfer is exact):
 *   b  bedrock altitude          t  talus thickness (crept material)   d  silt thickness (deposit)
 *   w  water depth               s  suspended sediment
 * Ground a = b + t + d; water surface H = a + w.  Plus two floats: `flow`, a decaying sum of the
 * water leaving the vertex (the river map), and `soft`, the bedrock's softness multiplier (a
 * fixed fractal field, 1 without hardness_noise).
 *
 * One step, the choice the seed leaves open written down (docs/erosion.md has the derivation):
 *  E1. Every edge between 4-neighbours P and Q carries at most one transfer, from the vertex
 *      with the higher water surface (the sender x) to the other (y), computed from the step's
 *      old state of x and y alone:
 *        water     DW  = trunc(min(w_x, (H_x - H_y) / 2) / 4)       (at most w_x / 4 per edge)
 *        capacity  C   = K_c DW
 *        from the load  SUS = trunc(min(s_x / 4, C))                (at most s_x / 4 per edge)
 *        eroded    ERO = trunc(min(k_x (C - s_x / 4), (a_x - a_y) / 8))  when C > s_x / 4
 *      k_x is K_s times the softness of x's top layer: silt, else talus, else bedrock
 *      (soft * the strata factor of its altitude).  Dry creep moves
 *        CREEP = trunc(c_d (a_P - a_Q)) from P to Q (negative: Q to P) between inner vertices.
 *  E2. Every vertex then adds what its four edges bring and subtracts what they take: water;
 *      its load loses SUS and gains the SUS + ERO sent to it; its ground loses ERO and creep
 *      (silt first, then talus, then bedrock) and gains creep as talus; then K_d of the load
 *      that stayed settles as silt: dep = trunc(K_d (s - sent)).
 *  E3. Rain (on rain steps) and evaporation change w; the grid's outer ring is the outlet:
 *      the water and load that reach it leave the grid (counted), its ground never changes.
 * Because an edge's transfer is one integer computed from the same two old states whichever
 * end computes it, what one vertex loses its neighbour gains exactly: bedrock + talus + silt +
 * load summed over the grid plus the load that left is constant to the last quantum, and water
 * changes only by rain, evaporation and outflow (tf_erosion_tally).  A vertex's new state is a
 * function of its own and its 4 neighbours' old states: k steps need a halo of k vertices,
 * whatever cut the grid into pieces, and the result is bit-identical for any tiling, thread
 * count or farm of patches.  The float arithmetic is IEEE single without fused multiply-add,
 * the same bits on every kernel (erosion_kernel.h: AVX-512, AVX2, portable). */
#ifndef TF_EROSION_H
#define TF_EROSION_H

#include <stddef.h>
#include <stdint.h>

#include "scene.h"

/* Ghost vertices (outside the grid) are this high, dry and unloaded: nothing flows to them. */
#define TF_EROSION_GHOST_ALT (1 << 30)
/* Initial ground spans at most 2^25 quanta: room for water, deposits and differences in int32. */
#define TF_EROSION_RANGE_BITS 25

/* The constants of one erosion, derived from the scene's [erosion] keys and the initial
 * heights' range (tf_erosion_model_init); what the kernel reads. */
typedef struct tf_erosion_model {
    int n;                    /* the grid is n x n vertices */
    double q;                 /* metres per quantum */
    double base;              /* world height of ground 0 */
    float kc, kd, ks;         /* capacity, deposition, bedrock softness */
    float k_silt, k_talus;    /* softness of silt and talus (K_s times their multipliers) */
    float creep;              /* c_d */
    float evaporation;
    float flow_decay;         /* flow = flow * decay + water out (per step) */
    float rain_altitude;      /* rain multiplier 1 + rain_altitude * a / range_units */
    float inv_range_units;
    float inv_strata_units;   /* 1 / strata thickness in quanta (0: no strata) */
    float strata_contrast;
    double rain_units;        /* quanta of rain per rain event before the altitude factor */
    int rain_interval;
    double rain_noise;
    uint64_t seed;
    int steps;
} tf_erosion_model;

/* A window onto state arrays: row-major with `stride`, origin at global vertex (gi, gj). */
typedef struct tf_erosion_view {
    int32_t *b, *t, *d, *w, *s;
    float *flow, *soft;
    size_t stride;
    int gi, gj;      /* global coordinates of element 0 */
    int nx, ny;      /* size of the window */
    /* the kernel's rolling row buffers, TF_EROSION_ROWS(nx) int32s of any content, kept by the
     * window across steps (erosion_state.h); NULL: each step allocates its own */
    int32_t *rows;
} tf_erosion_view;

/* Exact integer bookkeeping of one step (or a sum of steps) over the vertices a piece owns. */
typedef struct tf_erosion_tally {
    int64_t rain, evaporated, out_water, out_load;
} tf_erosion_tally;

/* Derive the model from the keys and the heights' range.  0, or -1 with one line in err. */
int tf_erosion_model_init(tf_erosion_model *m, const tf_erosion_keys *k, uint64_t seed, int n,
                          float hmin, float hmax, char *err, size_t errlen);

/* Quanta of rain per vertex-multiplier on step `step` (0 on dry steps): the same number for
 * every piece of the grid (a function of the model and the step only). */
float tf_erosion_rain_now(const tf_erosion_model *m, int step);

/* The kernel works up to 16 vertices at a time: it reads, and rewrites unchanged, up to this
 * many elements past the end of a rectangle's row, so a window's arrays need that much room
 * after each row's last needed vertex (a stride of nx + TF_EROSION_PAD, and as many spare
 * elements after the last row). */
#define TF_EROSION_PAD 16

/* The kernel's row buffers for a window nx wide: two rows of derived values (3 arrays each) and
 * three of edges (4 arrays each), each array up to nx + 3 * TF_EROSION_PAD long.  While every
 * step allocated and freed its own (77 KiB at 1049 wide), its speed was left to malloc: of two
 * farm workers with patches of one size, the first forked computed 12-18% slower than the
 * other, whatever patch or core it had.  Kept by the window, both run as fast as the faster
 * one did (bench/README.md section 39; why malloc's blocks cost that much was not found). */
#define TF_EROSION_ROW_ARRAYS 18
#define TF_EROSION_ROWS(nx) (TF_EROSION_ROW_ARRAYS * ((size_t)(nx) + 3 * TF_EROSION_PAD))

/* One time step on the vertices [r0, r1) x [c0, c1) of view v (window coordinates), in place.
 * Needs the old state of one more vertex on every side of the rectangle (inside the window;
 * ghosts beyond the grid's edge).  Counts into tally only the vertices inside the rectangle
 * own (window coordinates; may be empty).  `step` is the global step number (for rain).
 * 0, or -1 when out of memory for the edge buffers (the window is then unchanged). */
typedef struct tf_erosion_rect {
    int r0, r1, c0, c1;
} tf_erosion_rect;
int tf_erosion_step(const tf_erosion_model *m, const tf_erosion_view *v, tf_erosion_rect rect,
                     tf_erosion_rect own, int step, tf_erosion_tally *tally);

/* Which kernel tf_erosion_step uses: "avx512", "avx2" or "portable", the best the CPU runs
 * (TF_EROSION_ISA=avx2 or portable caps it; all give the same bits). */
const char *tf_erosion_isa(void);
/* Tests and benchmarks: 1 forces the portable kernel, 0 the best, -1 back to the variable. */
void tf_erosion_force_portable(int portable);
/* Tests and benchmarks: use the kernel named isa (NULL: back to the variable); -1 if this CPU
 * cannot run it (nothing changes). */
int tf_erosion_force_isa(const char *isa);

#endif
