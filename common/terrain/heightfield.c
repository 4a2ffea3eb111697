/* heightfield.c: the height field's shape, its hierarchy of max/min grids, and the exact
 * two-triangle surface the tracer sees (common/terrain/heightfield.h).
 *
 * The heights themselves come from elsewhere (tf_heightfield_build in terrain_build.c generates
 * them from the scene, tests hand them in directly).  This file owns what is built on top of
 * them: maxgrid[L] / mingrid[L] for L = 0..k, the "A grid" of Musgrave 3.3.1 generalised into a
 * max mipmap (and its min twin, for rays travelling below the surface), which common/render/trace.c
 * walks.  Level 0 holds, per cell, the max/min of its four corner samples; level L holds the
 * max/min of the 2x2 block of level L-1 entries below it; level k is 1x1 (the whole field).
 *
 * Grids are filled by `threads` pthreads claiming chunks of rows.  Max and min are exact and
 * each entry is computed alone, so the result is bit-identical whatever the thread count. */
#include <errno.h>
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <string.h>
#include <unistd.h>
#include "terrain/heightfield.h"
#include "terrain/grid_height.h"
#include "terrain/procedural.h"

/* Largest supported k: (2^16 + 1)^2 floats is already 16 GiB of heights. */
#define TF_HF_MAX_K 16
/* Below this many entries a level is built by the calling thread alone. */
#define TF_HF_PARALLEL_MIN 65536
/* Rows a thread claims at a time (level 0 of 8193^2: 256 chunks of 32 rows, 1 MB each). */
#define TF_HF_CHUNK_ROWS 32

int tf_thread_count(int threads)
{
    if (threads > 0)
        return threads > 1024 ? 1024 : threads;
    long online = sysconf(_SC_NPROCESSORS_ONLN);
    if (online < 1)
        return 1;
    return online > 1024 ? 1024 : (int)online;
}

/* ---- building one level ------------------------------------------------------------------ */

/* One level's job, shared by its threads: rows of level `level` (reading the level below, or
 * the samples for level 0), claimed TF_HF_CHUNK_ROWS at a time from a shared counter. */
typedef struct grid_job {
    tf_heightfield *hf;
    int level;
    int rows;
    int *next_chunk;   /* the first chunk no thread has claimed (atomic) */
    double *row_slope; /* level 0: each row's steepest squared triangle gradient (x cell^2) */
} grid_job;

static inline float max4(float a, float b, float c, float d)
{
    float m = a > b ? a : b;
    float m2 = c > d ? c : d;
    return m > m2 ? m : m2;
}

static inline float min4(float a, float b, float c, float d)
{
    float m = a < b ? a : b;
    float m2 = c < d ? c : d;
    return m < m2 ? m : m2;
}

/* The larger of two squared gradients, NaN if either is: a NaN sample is a hole in the surface,
 * and the slope bound across a hole is none (render/trace.h's coherence, the sun's strips). */
static inline double steeper(double g1, double g2)
{
    return g1 > g2 || g1 != g1 ? g1 : g2;
}

/* The squared gradients (times cell^2) of the two triangles of the cell with corners
 * a = (i, j), b = (i+1, j), c = (i+1, j+1), d = (i, j+1): T1 = (a, b, c) rises b - a along x
 * and c - b along y, T2 = (a, c, d) rises c - d and d - a.  Differences of floats are exact in
 * double; a NaN corner makes one of them NaN. */
static inline void cell_slopes2(float a, float b, float c, float d, double *t1, double *t2)
{
    double t1x = (double)b - a, t1y = (double)c - b, t2x = (double)c - d, t2y = (double)d - a;
    *t1 = t1x * t1x + t1y * t1y, *t2 = t2x * t2x + t2y * t2y;
}

/* Level 0: a cell's four corner samples; and the row's steepest triangle. */
static void build_level0_rows(tf_heightfield *hf, double *row_slope, int row_begin, int row_end)
{
    const int n = hf->n, cells = hf->cells;
    float *mx = hf->maxgrid[0], *mn = hf->mingrid[0];
    for (int cj = row_begin; cj < row_end; cj++) {
        const float *lo = hf->h + (size_t)cj * n;
        const float *hi = lo + n;
        float *mxrow = mx + (size_t)cj * cells, *mnrow = mn + (size_t)cj * cells;
        double steepest = 0;
        int holes = 0; /* a NaN slope seen (branch-free: the loop is hot, 8193^2 cells) */
        for (int ci = 0; ci < cells; ci++) {
            mxrow[ci] = max4(lo[ci], lo[ci + 1], hi[ci], hi[ci + 1]);
            mnrow[ci] = min4(lo[ci], lo[ci + 1], hi[ci], hi[ci + 1]);
            double t1, t2;
            cell_slopes2(lo[ci], lo[ci + 1], hi[ci + 1], hi[ci], &t1, &t2);
            const double g = t1 > t2 ? t1 : t2;
            steepest = g > steepest ? g : steepest;
            holes |= t1 + t2 != t1 + t2;
        }
        row_slope[cj] = holes ? NAN : steepest;
    }
}

/* Level L > 0: the 2x2 block of level L-1 below each entry. */
static void build_level_rows(tf_heightfield *hf, int level, int row_begin, int row_end)
{
    const int side = hf->cells >> level, below = side * 2;
    const float *bmx = hf->maxgrid[level - 1], *bmn = hf->mingrid[level - 1];
    float *mx = hf->maxgrid[level], *mn = hf->mingrid[level];
    for (int bj = row_begin; bj < row_end; bj++) {
        const size_t r0 = (size_t)(2 * bj) * below, r1 = r0 + below;
        for (int bi = 0; bi < side; bi++) {
            const size_t c = (size_t)2 * bi;
            mx[(size_t)bj * side + bi] = max4(bmx[r0 + c], bmx[r0 + c + 1], bmx[r1 + c], bmx[r1 + c + 1]);
            mn[(size_t)bj * side + bi] = min4(bmn[r0 + c], bmn[r0 + c + 1], bmn[r1 + c], bmn[r1 + c + 1]);
        }
    }
}

static void build_rows(const grid_job *job, int row_begin, int row_end)
{
    tf_heightfield *hf = job->hf;
    const int level = job->level;
    if (level == 0)
        build_level0_rows(hf, job->row_slope, row_begin, row_end);
    else
        build_level_rows(hf, level, row_begin, row_end);
}

static void *run_job(void *arg)
{
    grid_job *job = arg;
    int c;
    while ((c = __atomic_fetch_add(job->next_chunk, 1, __ATOMIC_RELAXED)) <
           (job->rows + TF_HF_CHUNK_ROWS - 1) / TF_HF_CHUNK_ROWS) {
        int begin = c * TF_HF_CHUNK_ROWS, end = begin + TF_HF_CHUNK_ROWS;
        build_rows(job, begin, end < job->rows ? end : job->rows);
    }
    return NULL;
}

/* Build one level with up to `threads` threads, the caller one of them.  Threads claim chunks
 * of rows as they go, so one that the machine's other load slows down holds up no band of its
 * own; one that cannot be created only leaves more chunks to the others.  Every entry is the
 * same max/min whoever computes it. */
static void build_level(tf_heightfield *hf, int level, double *row_slope, int threads)
{
    const int rows = hf->cells >> level;
    const size_t entries = (size_t)rows * rows;
    const int chunks = (rows + TF_HF_CHUNK_ROWS - 1) / TF_HF_CHUNK_ROWS;
    int next_chunk = 0;
    grid_job job = {hf, level, rows, &next_chunk, row_slope};
    if (threads > chunks)
        threads = chunks;
    if (threads <= 1 || entries < TF_HF_PARALLEL_MIN) {
        build_rows(&job, 0, rows);
        return;
    }
    pthread_t tids[threads];
    int started[threads];
    for (int t = 1; t < threads; t++)
        started[t] = pthread_create(&tids[t], NULL, run_job, &job) == 0;
    run_job(&job);
    for (int t = 1; t < threads; t++)
        if (started[t])
            pthread_join(tids[t], NULL);
}

/* slope_max from the rows' squared gradients (times cell^2): rounded up by far more than the
 * few roundings of sqrt and the division, so it bounds the true gradients; NaN where a row
 * holds a hole. */
static double steepest_slope(const double *row_slope, int rows, double cell)
{
    double g2 = 0;
    for (int r = 0; r < rows; r++)
        g2 = steeper(row_slope[r], g2);
    return sqrt(g2) / cell * (1 + 1e-9) + DBL_MIN;
}

/* ---- construction and destruction ---------------------------------------------------------- */

static void free_grids(tf_heightfield *hf)
{
    if (hf->maxgrid)
        for (int L = 0; L < hf->levels; L++)
            free(hf->maxgrid[L]);
    if (hf->mingrid)
        for (int L = 0; L < hf->levels; L++)
            free(hf->mingrid[L]);
    free(hf->maxgrid);
    free(hf->mingrid);
}

void tf_heightfield_free(tf_heightfield *hf)
{
    if (!hf)
        return;
    if (hf->derived_free)
        hf->derived_free(hf->derived);
    free_grids(hf);
    free(hf->h);
    free(hf->water);
    free(hf->silt);
    free(hf->flow);
    tf_procedural_free(hf->proc);
    free(hf);
}

void tf_heightfield_set_cache(tf_heightfield *hf, size_t bytes)
{
    if (hf && hf->proc)
        tf_procedural_set_cache(hf->proc, bytes);
}

/* A max/min level or the heights: large ones on 2 MB boundaries and marked for transparent
 * huge pages, so the tracer's walk over them misses the TLB less, a fork (the coordinator's
 * local workers share the height field copy-on-write) copies one page-table entry per 2 MB
 * instead of 512, and the builder's first touch of the fresh memory takes one page fault per
 * 2 MB instead of 512 (measured on the 2-core VM: 8193^2 heights 1.6 s instead of 2.0 s, the
 * grids 2.0 s instead of 2.7 s, both mostly the kernel zeroing pages).  Same bytes either way. */
#define HUGE_PAGE ((size_t)2 << 20)
float *tf_alloc_heights(size_t bytes)
{
    if (bytes < 2 * HUGE_PAGE)
        return malloc(bytes);
    void *p = NULL;
    size_t rounded = (bytes + HUGE_PAGE - 1) & ~(HUGE_PAGE - 1);
    if (posix_memalign(&p, HUGE_PAGE, rounded) != 0)
        return NULL;
    madvise(p, rounded, MADV_HUGEPAGE); /* advice: without THP it is ordinary memory */
    return p;
}

/* Allocate every level (calloc: a partial failure frees cleanly). */
static int alloc_grids(tf_heightfield *hf)
{
    hf->maxgrid = calloc((size_t)hf->levels, sizeof *hf->maxgrid);
    hf->mingrid = calloc((size_t)hf->levels, sizeof *hf->mingrid);
    if (!hf->maxgrid || !hf->mingrid)
        return -1;
    for (int L = 0; L < hf->levels; L++) {
        size_t side = (size_t)hf->cells >> L;
        hf->maxgrid[L] = tf_alloc_heights(side * side * sizeof(float));
        hf->mingrid[L] = tf_alloc_heights(side * side * sizeof(float));
        if (!hf->maxgrid[L] || !hf->mingrid[L])
            return -1;
    }
    return 0;
}

tf_heightfield *tf_heightfield_wrap(float *h, int k, double extent, int threads)
{
    if (!h || k < 0 || k > TF_HF_MAX_K || !(extent > 0) || extent > 1e300) {
        free(h);
        return NULL;
    }
    tf_heightfield *hf = calloc(1, sizeof *hf);
    if (!hf) {
        free(h);
        return NULL;
    }
    hf->k = k;
    hf->cells = 1 << k;
    hf->n = hf->cells + 1;
    hf->extent = extent;
    hf->cell = extent / hf->cells;
    hf->h = h;
    hf->levels = k + 1;
    if (alloc_grids(hf) != 0) {
        tf_heightfield_free(hf);
        return NULL;
    }
    double *row_slope = malloc((size_t)hf->cells * sizeof *row_slope);
    if (!row_slope) {
        tf_heightfield_free(hf);
        return NULL;
    }
    threads = tf_thread_count(threads);
    for (int L = 0; L < hf->levels; L++)
        build_level(hf, L, row_slope, threads);
    hf->slope_max = steepest_slope(row_slope, hf->cells, hf->cell);
    free(row_slope);
    /* The top level is 1x1: the range of every sample. */
    hf->hmax = hf->maxgrid[hf->levels - 1][0];
    hf->hmin = hf->mingrid[hf->levels - 1][0];
    return hf;
}

tf_heightfield *tf_heightfield_from_heights(const float *h, int k, double extent, int threads)
{
    if (!h || k < 0 || k > TF_HF_MAX_K)
        return NULL;
    size_t n = ((size_t)1 << k) + 1;
    float *copy = tf_alloc_heights(n * n * sizeof(float));
    if (!copy)
        return NULL;
    memcpy(copy, h, n * n * sizeof(float));
    return tf_heightfield_wrap(copy, k, extent, threads);
}

/* ---- the surface ----------------------------------------------------------------------------- */

/* World coordinate v clamped into [0, cells * cell] (a NaN to 0). */
static double into_square(const tf_heightfield *hf, double v)
{
    const double top = (double)hf->cells * hf->cell;
    return v > 0 ? (v < top ? v : top) : 0;
}

/* Clamp world coordinate v into the square and split it into a cell index in [0, cells-1] and
 * a fraction in [0, 1].  The cell satisfies i*cell <= v <= (i+1)*cell, the same test the tracer
 * uses to pick a ray's first cell. */
static int split_coord(const tf_heightfield *hf, double v, double *frac)
{
    return tf_grid_cell_of(into_square(hf, v), hf->cell, hf->cells, frac);
}

double tf_heightfield_height_at(const tf_heightfield *hf, double x, double y)
{
    if (hf->proc) /* its finest level: what a view sees up close */
        return tf_proc_level_height(hf->proc, hf->proc->max_level, x, y);
    return tf_heightfield_grid_height_at(hf, x, y);
}

void tf_heightfield_range(const tf_heightfield *hf, double x0, double x1, double y0, double y1,
                          float *lo, float *hi)
{
    double u;
    int i0 = split_coord(hf, x0, &u), i1 = split_coord(hf, x1, &u);
    int j0 = split_coord(hf, y0, &u), j1 = split_coord(hf, y1, &u);
    int L = 0;
    while (L + 1 < hf->levels && ((i1 >> L) - (i0 >> L) > 2 || (j1 >> L) - (j0 >> L) > 2))
        L++;
    int side = hf->cells >> L;
    *lo = INFINITY;
    *hi = -INFINITY;
    for (int bj = j0 >> L; bj <= j1 >> L; bj++)
        for (int bi = i0 >> L; bi <= i1 >> L; bi++) {
            size_t at = (size_t)bj * (size_t)side + (size_t)bi;
            *lo = hf->mingrid[L][at] < *lo ? hf->mingrid[L][at] : *lo;
            *hi = hf->maxgrid[L][at] > *hi ? hf->maxgrid[L][at] : *hi;
        }
}

double tf_heightfield_grid_height_at(const tf_heightfield *hf, double x, double y)
{
    return tf_grid_height(hf->h, hf->n, hf->cell, into_square(hf, x), into_square(hf, y));
}
