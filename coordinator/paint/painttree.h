/* painttree.h: Raypaint's quad-tree (Musgrave A.7.2.4), the policy of what to trace next, as
 * plain data and pure functions: no sockets, no threads, no clock (tests/unit/test_painttree.c).
 *
 * The image is covered by root nodes of side `root`.  A node whose four corner samples are
 * known is a *cell*, waiting in a priority queue.  Taking a cell of side s > leaf makes a
 * SAMPLE node: its lattice at stride d = max(s >> levels, leaf) is traced, and each of its
 * (s/d)^2 sub-squares becomes a cell.  A cell of the leaf's side first has its lattice traced at
 * the fine stride (a cheap sharper picture: a quarter of a ray a pixel at stride 2) and waits
 * again, ranked by its fine cells' widest contrast; then it becomes an EXACT node: its pixels
 * rendered as `terrafarm render` renders them.  A root starts as a SAMPLE node with no corners
 * known.  So every part of the image goes coarse -> finer -> exact, and once every pixel is
 * exact the painted image is the render (paintproto.h says why).
 *
 * Which cell first: every root before anything else (the first complete coarse image); then
 * the cells that meet the area of interest (where the person pointed); then the rest; within
 * a tier, by what a ray buys: the widest per-channel range of the cell's corners' display
 * levels (the antialiasing's own measure, render.c), plus a floor so flat cells are not left to
 * the very end, times its side squared, over the rays its next node costs -- so the cheap
 * passes that sharpen most come before the exact ones that settle what is nearly right.  A task is the best cells, batched up to about
 * `task_rays` rays (the granularity, measured in bench/paint_progress.sh); the roots go in
 * tasks of their own, so the coarse picture never waits for finer work.
 *
 * What the page draws comes out of tf_paint_tree_apply as display messages (paint_raster.h).
 *
 * Invariants (tf_paint_tree_check):
 *   P1  every pixel is covered by exactly one of: a queued cell, a node of a task out, or
 *       the exact pixels: their pixel counts add up to the image's;
 *   P2  the queue is a max-heap on its keys;
 *   P3  a queued cell's side is a power of two between 1 and root, and it lies in the image. */
#ifndef TF_PAINTTREE_H
#define TF_PAINTTREE_H

#include <stddef.h>
#include <stdint.h>

#include "image/pixel.h"
#include "paintproto.h"

typedef struct tf_paint_params {
    int root;        /* side of a root node, a power of two (64) */
    int levels;      /* quad-tree levels a SAMPLE node descends (2) */
    int leaf;        /* a cell this side or smaller is rendered exactly (16) */
    int task_rays;   /* about this many rays per task (16384) */
    int fine;        /* a leaf-sized cell's lattice is traced at this stride before it is
                        rendered exactly (2; = leaf: no such pass) */
} tf_paint_params;

void tf_paint_params_default(tf_paint_params *p);
/* Why p cannot paint, or NULL. */
const char *tf_paint_params_problem(const tf_paint_params *p);

/* A growing byte buffer: the display messages of applied results. */
typedef struct tf_paint_bytes {
    uint8_t *p;
    size_t len, cap;
} tf_paint_bytes;
int tf_paint_bytes_add(tf_paint_bytes *b, const void *data, size_t n);
void tf_paint_bytes_free(tf_paint_bytes *b);

typedef struct tf_paint_tree tf_paint_tree;

/* NULL on out of memory. */
tf_paint_tree *tf_paint_tree_new(int w, int h, const tf_paint_params *p);
void tf_paint_tree_free(tf_paint_tree *t);
/* A new view: nothing known, every root queued.  0, or -1 on out of memory. */
int tf_paint_tree_reset(tf_paint_tree *t);
/* The area of interest (w == 0: none); requeues every cell with its new key. */
void tf_paint_tree_set_interest(tf_paint_tree *t, tf_rect area);
/* The next task's nodes (at most max): how many, 0 when no cell waits. */
int tf_paint_tree_next(tf_paint_tree *t, tf_paint_node *nodes, int max);
/* A task that will not come back: its cells wait again. */
void tf_paint_tree_requeue(tf_paint_tree *t, const tf_paint_node *nodes, int count);
/* Store a task's checked values (tf_paint_values_check) and append what changed on screen to
 * out.  0, or -1 on out of memory. */
int tf_paint_tree_apply(tf_paint_tree *t, const tf_paint_node *nodes, int count,
                        const float *values, tf_paint_bytes *out);

typedef struct tf_paint_counts {
    int64_t exact_pixels, pixels;  /* painted exactly, in the image */
    int64_t samples;               /* corner samples traced for this view */
    int64_t queued;                /* cells waiting */
    int64_t roots_left;            /* roots not yet traced: 0 = a complete coarse image */
} tf_paint_counts;
void tf_paint_tree_counts(const tf_paint_tree *t, tf_paint_counts *c);
/* Every pixel exact: the final render's pixels, row-major (else NULL). */
const tf_pixel *tf_paint_tree_pixels(const tf_paint_tree *t);
/* P1-P3, one assert per clause; returns 1 (call it inside assert()). */
int tf_paint_tree_check(const tf_paint_tree *t);

#endif
