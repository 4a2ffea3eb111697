/* terrain_build.c: builds a scene's height field (tf_heightfield_build, heightfield.h) and its
 * bare heights (tf_terrain_heights, terrain_build.h).
 *
 * Point generators (fractal.c) are evaluated row by row by a small pool of pthreads, each
 * claiming the next unclaimed row from a shared counter.  A row's values depend only on its
 * index, never on which thread computed it, so the result is bit-identical for every thread
 * count.  Claiming rows one at a time balances the load both for generators whose cost varies
 * across the terrain and on a machine whose other load takes a core away from one thread
 * (thread t taking rows t, t + T, ..., as before, waited for the slowest).  Grid
 * generators (midpoint.c, fault.c, subdivide.c) own their parallelism; weathering.c likewise.
 * The sweeps after them (height_scale, the non-finite check) split rows with gridgen.h. */
#include "terrain/terrain_build.h"
#include "terrain/procedural.h"
#include "terrain/eroded.h"
#include "terrain/erosion_state.h"

#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/fractal.h"
#include "terrain/gridgen.h"
#include "terrain/heightfield.h"
#include "terrain/heightmap_file.h"
#include "terrain/noise.h"
#include "terrain/terrain.h"
#include "log.h"

/* More threads than this never help the row-by-row build on any machine we target, and the
 * bound keeps the thread array on the stack. */
#define MAX_BUILD_THREADS 256

typedef struct row_job {
    const tf_fractal *fractal;
    const tf_noise *noise;
    float *h;
    int n;
    double cell, scale;
    int *next; /* the first row no thread has claimed (atomic) */
} row_job;

/* Claim rows one at a time until none is left.  One job is shared by every thread. */
static void *run_rows(void *arg)
{
    const row_job *job = arg;
    /* Without scratch memory tf_fractal_row evaluates point by point: same bits, slower. */
    tf_fractal_rowbuf buf;
    int have_buf = tf_fractal_rowbuf_init(&buf, job->n) == 0;
    int j;
    while ((j = __atomic_fetch_add(job->next, 1, __ATOMIC_RELAXED)) < job->n)
        tf_fractal_row(job->fractal, job->noise, (double)j * job->cell, job->cell, job->n,
                       job->scale, job->h + (size_t)j * (size_t)job->n, have_buf ? &buf : NULL);
    if (have_buf)
        tf_fractal_rowbuf_free(&buf);
    return NULL;
}

/* Evaluate every sample of a point generator with `threads` threads.  The calling thread
 * works too and takes whatever rows are left, so a thread that cannot be created (or one the
 * machine's other load keeps off a core) only makes the build slower, never different. */
static void fill_point_generator(const tf_fractal *f, const tf_noise *nz, float *h, int n,
                                 double cell, double scale, int threads)
{
    int next = 0;
    row_job job = {f, nz, h, n, cell, scale, &next};
    pthread_t tids[MAX_BUILD_THREADS];
    int started[MAX_BUILD_THREADS];
    for (int t = 1; t < threads; t++)
        started[t] = pthread_create(&tids[t], NULL, run_rows, &job) == 0;
    run_rows(&job);
    for (int t = 1; t < threads; t++)
        if (started[t])
            pthread_join(tids[t], NULL);
}

static int resolve_threads(int threads, int n)
{
    if (threads <= 0)
        threads = tf_thread_count(threads);
    if (threads < 1)
        threads = 1;
    if (threads > MAX_BUILD_THREADS)
        threads = MAX_BUILD_THREADS;
    if (threads > n)
        threads = n;
    return threads;
}

static int run_grid_generator(float *h, const tf_terrain *t, int threads, char *err,
                              size_t errlen)
{
    switch (t->generator) {
    case TF_GEN_MIDPOINT:
        return tf_gen_midpoint(h, t->size_exp, t, threads, err, errlen);
    case TF_GEN_FAULT:
        return tf_gen_fault(h, t->size_exp, t, threads, err, errlen);
    case TF_GEN_SUBDIVIDE:
        return tf_gen_subdivide(h, t->size_exp, t, threads, err, errlen);
    default:
        tf_seterr(err, errlen, "terrain: unknown generator %d", (int)t->generator);
        return -1;
    }
}

/* Whole-grid sweeps after the generator, rows split over the threads (gridgen.h): each
 * sample is scaled alone, and the first non-finite sample is the first one found by the
 * lowest band that found one, so neither depends on the split. */
typedef struct sweep {
    float *h;
    int n;
    double scale;
    ptrdiff_t bad[TF_GRID_MAX_THREADS]; /* per band: first non-finite index, or -1 */
} sweep;

static void scale_rows(void *arg, int piece, int begin, int end)
{
    sweep *w = arg;
    (void)piece;
    for (size_t i = (size_t)begin * w->n; i < (size_t)end * w->n; i++)
        w->h[i] = (float)((double)w->h[i] * w->scale);
}

static void find_non_finite_rows(void *arg, int piece, int begin, int end)
{
    sweep *w = arg;
    w->bad[piece] = -1;
    for (size_t i = (size_t)begin * w->n; i < (size_t)end * w->n; i++)
        if (!isfinite(w->h[i])) {
            w->bad[piece] = (ptrdiff_t)i;
            return;
        }
}

/* Rows per band below which a sweep is not split (a row of 8193 is ~10 microseconds). */
#define SWEEP_MIN_ROWS 64

static void scale_heights(float *h, int n, double scale, int threads)
{
    sweep w = {.h = h, .n = n, .scale = scale};
    tf_grid_parallel(n, threads, SWEEP_MIN_ROWS, scale_rows, &w);
}

/* Index of the first non-finite height of the n x n grid, or -1. */
static ptrdiff_t first_non_finite(float *h, int n, int threads)
{
    sweep w = {.h = h, .n = n};
    tf_grid_parallel(n, threads, SWEEP_MIN_ROWS, find_non_finite_rows, &w);
    for (int p = 0; p < tf_grid_pieces(n, threads, SWEEP_MIN_ROWS); p++)
        if (w.bad[p] >= 0)
            return w.bad[p];
    return -1;
}

/* generator = file: the height map's samples, then thermal weathering if asked. */
static float *file_heights(const tf_terrain *t, int threads, double *extent, char *err,
                           size_t errlen)
{
    float *h = tf_heightmap_heights(t, extent, err, errlen);
    if (!h)
        return NULL;
    int n = (1 << t->size_exp) + 1;
    if (!(*extent > 0.0) || !isfinite(*extent)) {
        tf_seterr(err, errlen, "%s: the terrain's side comes out as %g; set extent",
                  t->file_name ? t->file_name : t->file_path, *extent);
        free(h);
        return NULL;
    }
    threads = resolve_threads(threads, n);
    if (t->thermal_iterations > 0 &&
        tf_weather_thermal(h, n, *extent / (double)(n - 1), t, threads, err, errlen) != 0) {
        free(h);
        return NULL;
    }
    return h;
}

/* The generator's samples into h (n x n, cell apart), scaled by height_scale. */
static int generate(const tf_terrain *t, const tf_fractal *fractal, int is_point, float *h,
                    int n, double cell, int threads, char *err, size_t errlen)
{
    if (is_point) {
        tf_noise noise;
        tf_noise_init(&noise, t->seed);
        fill_point_generator(fractal, &noise, h, n, cell, t->height_scale, threads);
        return 0;
    }
    if (run_grid_generator(h, t, threads, err, errlen) != 0)
        return -1;
    scale_heights(h, n, t->height_scale, threads);
    return 0;
}

/* Every height finite, or a message naming the first sample that is not. */
static int check_finite(const tf_terrain *t, float *h, int n, int threads, char *err,
                        size_t errlen)
{
    ptrdiff_t bad = first_non_finite(h, n, threads);
    if (bad < 0)
        return 0;
    return tf_seterr(err, errlen,
                     "terrain: %s generator produced a non-finite height at sample (%d, %d); "
                     "check H, lacunarity, offset, gain and height_scale",
                     tf_generator_name(t->generator), (int)(bad % n), (int)(bad / n));
}

/* A generated (not file) terrain's heights, weathered: the grid's size, the generator, the
 * thermal weathering, the finite check. */
static float *generated_heights(const tf_terrain *t, int threads, char *err, size_t errlen)
{
    if (!(t->extent > 0.0) || !isfinite(t->extent) || !isfinite(t->height_scale)) {
        tf_seterr(err, errlen, "terrain: extent must be positive and height_scale finite");
        return NULL;
    }
    int n = (1 << t->size_exp) + 1;
    size_t count = (size_t)n * (size_t)n; /* at most 8193^2: no overflow */
    double cell = t->extent / (double)(n - 1);
    threads = resolve_threads(threads, n);
    tf_fractal fractal;
    int is_point = tf_fractal_prepare(&fractal, t) == 0;
    if (is_point && !(t->feature_size > 0.0 && isfinite(t->feature_size))) {
        tf_seterr(err, errlen, "terrain: feature_size must be positive");
        return NULL;
    }
    float *h = tf_alloc_heights(count * sizeof *h);
    if (!h) {
        tf_seterr(err, errlen, "out of memory: a %dx%d height field needs %zu MB", n, n,
                 (count * sizeof *h + (1u << 20) - 1) >> 20);
        return NULL;
    }
    if (generate(t, &fractal, is_point, h, n, cell, threads, err, errlen) != 0 ||
        (t->thermal_iterations > 0 &&
         tf_weather_thermal(h, n, cell, t, threads, err, errlen) != 0) ||
        check_finite(t, h, n, threads, err, errlen) != 0) {
        free(h);
        return NULL;
    }
    return h;
}

/* The generator's heights, then thermal weathering: everything but the erosion. */
static float *raw_heights(const tf_terrain *t, int threads, double *extent, char *err,
                          size_t errlen)
{
    double side = t->extent;
    if (!extent)
        extent = &side;
    if (t->size_exp < 1 || t->size_exp > TF_TERRAIN_MAX_SIZE_EXP) {
        tf_seterr(err, errlen, "terrain: size_exp %d out of range 1..%d", t->size_exp,
                 TF_TERRAIN_MAX_SIZE_EXP);
        return NULL;
    }
    if (t->generator == TF_GEN_FILE)
        return file_heights(t, threads, extent, err, errlen);
    *extent = t->extent;
    return generated_heights(t, threads, err, errlen);
}

int tf_terrain_erosion_start(const tf_terrain *t, double *extent, tf_erosion_model *m,
                             tf_erosion_state *st, char *err, size_t errlen)
{
    double side;
    float *raw = raw_heights(t, 0, extent ? extent : &side, err, errlen);
    if (!raw)
        return -1;
    int rc = tf_erosion_begin(t, raw, (1 << t->size_exp) + 1, m, st, err, errlen);
    free(raw);
    return rc;
}

int tf_terrain_eroded_bytes(const tf_terrain *t, int threads, uint8_t **bytes, size_t *len,
                            tf_erosion_report *rep, char *err, size_t errlen)
{
    double extent;
    float *raw = raw_heights(t, threads, &extent, err, errlen);
    if (!raw)
        return -1;
    int n = (1 << t->size_exp) + 1;
    int rc = tf_eroded_get(t, raw, n, extent, threads, bytes, len, rep, err, errlen);
    free(raw);
    return rc;
}

/* The eroded terrain's extent, from its blob's header (the blob is checked after). */
static double blob_extent(const uint8_t *b, size_t len, double fallback)
{
    double e;
    if (len < 52)
        return fallback;
    memcpy(&e, b + 44, sizeof e);
    return isfinite(e) && e > 0 ? e : fallback;
}

float *tf_terrain_heights_maps(const tf_terrain *t, int threads, double *extent,
                               tf_eroded_maps *maps, tf_erosion_report *rep, char *err,
                               size_t errlen)
{
    double side = t->extent;
    if (!extent)
        extent = &side;
    if (t->erosion.fluvial_steps <= 0)
        return raw_heights(t, threads, extent, err, errlen);
    if (t->size_exp < 1 || t->size_exp > TF_TERRAIN_MAX_SIZE_EXP)
        return raw_heights(t, threads, extent, err, errlen); /* says what is wrong */
    uint8_t *owned = NULL;
    const uint8_t *b = t->eroded_bytes;
    size_t len = t->eroded_len;
    const char *from = t->eroded_from ? t->eroded_from : "eroded terrain";
    if (!b) {
        if (tf_terrain_eroded_bytes(t, threads, &owned, &len, rep, err, errlen) != 0)
            return NULL;
        b = owned;
        from = "erosion cache";
    }
    int n = (1 << t->size_exp) + 1;
    float *h = tf_alloc_heights((size_t)n * (size_t)n * sizeof *h);
    if (!h)
        tf_seterr(err, errlen, "out of memory: a %dx%d height field", n, n);
    else if (tf_eroded_parse(t, n, b, len, from, h, maps, err, errlen) != 0) {
        free(h);
        h = NULL;
    }
    *extent = blob_extent(b, len, t->extent);
    free(owned);
    return h;
}

float *tf_terrain_heights(const tf_terrain *t, int threads, double *extent, char *err,
                          size_t errlen)
{
    return tf_terrain_heights_maps(t, threads, extent, NULL, NULL, err, errlen);
}

/* The procedural terrain as a height field without samples (heightfield.h). */
static tf_heightfield *procedural_build(const tf_scene *s, char *err, size_t errlen)
{
    tf_heightfield *hf = calloc(1, sizeof *hf);
    if (!hf) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    hf->proc = tf_procedural_new(&s->terrain, tf_procedural_default_cache_bytes(), err, errlen);
    if (!hf->proc) {
        free(hf);
        return NULL;
    }
    hf->extent = s->terrain.extent;
    hf->cell = hf->extent / (double)(1 << s->terrain.size_exp); /* the grid's look */
    hf->hmin = (float)hf->proc->lo;
    hf->hmax = (float)hf->proc->hi;
    return hf;
}

/* Procedural detail over the grid hf (procedural.h, tf_procedural_over). */
static tf_heightfield *detail_over(tf_heightfield *hf, const tf_scene *s, char *err,
                                   size_t errlen)
{
    hf->proc = tf_procedural_over(&s->terrain, hf, tf_procedural_default_cache_bytes(), err,
                                  errlen);
    if (!hf->proc) {
        tf_heightfield_free(hf);
        return NULL;
    }
    hf->hmin = (float)hf->proc->lo;
    hf->hmax = (float)hf->proc->hi;
    return hf;
}

static int noise_generator(enum tf_generator g)
{
    return g == TF_GEN_FBM || g == TF_GEN_HETERO || g == TF_GEN_HYBRID || g == TF_GEN_RIDGED;
}

tf_heightfield *tf_heightfield_build(const tf_scene *s, int threads, char *err, size_t errlen)
{
    if (s->terrain.procedural && noise_generator(s->terrain.generator))
        return procedural_build(s, err, errlen);
    double extent;
    tf_eroded_maps maps = {0};
    float *h = tf_terrain_heights_maps(&s->terrain, threads, &extent, &maps, NULL, err, errlen);
    if (!h)
        return NULL;
    /* tf_heightfield_wrap owns h from here, and frees it if it fails. */
    tf_heightfield *hf = tf_heightfield_wrap(h, s->terrain.size_exp, extent, threads);
    if (!hf) {
        int n = (1 << s->terrain.size_exp) + 1;
        tf_eroded_maps_free(&maps);
        tf_seterr(err, errlen, "out of memory: max/min grids of a %dx%d height field", n, n);
        return NULL;
    }
    hf->water = maps.water;
    hf->silt = maps.silt;
    hf->flow = maps.flow;
    return s->terrain.procedural ? detail_over(hf, s, err, errlen) : hf;
}
