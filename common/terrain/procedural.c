/* procedural.c: the procedural terrain's levels, samples, heights and bounds (procedural.h). */
#include "terrain/procedural.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "log.h"
#include "terrain/heightfield.h"

#define TILE TF_TILE_CELLS
#define MiB (1024.0 * 1024.0)

/* Tile keys: level in the top 6 bits, then tile x and tile y in 29 bits each. */
static uint64_t tile_key(int level, int64_t tx, int64_t ty)
{
    return ((uint64_t)level << 58) | ((uint64_t)tx << 29) | (uint64_t)ty;
}

static int64_t level_cells(int level) { return (int64_t)TILE << level; }

/* World coordinate of grid line i of a level: one expression, so every tile agrees. */
static double grid_coord(const tf_procedural *p, int level, int64_t i)
{
    return (double)i * tf_proc_spacing(p, level);
}

/* Detail over a grid: the grid's height under each sample of tile (tx, ty) of a level. */
static void add_base(const tf_procedural *p, int level, int64_t tx, int64_t ty, float *samples)
{
    for (int b = 0; b < TF_TILE_SAMPLES; b++) {
        double y = grid_coord(p, level, ty * TILE + b);
        for (int a = 0; a < TF_TILE_SAMPLES; a++) {
            double x = grid_coord(p, level, tx * TILE + a);
            float *v = &samples[b * TF_TILE_SAMPLES + a];
            *v = (float)((double)*v + tf_heightfield_grid_height_at(p->base, x, y));
        }
    }
}

/* A row buffer per thread for the fills (tf_fractal_row_at: octave by octave over a row, the
 * lattice columns hashed once for the samples that share them; the same bits as a point),
 * freed when the thread ends. */
static __thread tf_fractal_rowbuf *fill_row; /* NULL: none yet, or none to be had */
static __thread int fill_row_tried;
static pthread_key_t fill_row_key;
static pthread_once_t fill_row_once = PTHREAD_ONCE_INIT;

static void free_fill_row(void *b)
{
    tf_fractal_rowbuf_free(b);
    free(b);
}

static void make_fill_row_key(void) { pthread_key_create(&fill_row_key, free_fill_row); }

/* This thread's row buffer, or NULL without memory (the fills then go point by point). */
static tf_fractal_rowbuf *row_buffer(void)
{
    if (!fill_row_tried) {
        fill_row_tried = 1;
        pthread_once(&fill_row_once, make_fill_row_key);
        tf_fractal_rowbuf *b = malloc(sizeof *b);
        if (b && tf_fractal_rowbuf_init(b, TF_TILE_SAMPLES) == 0) {
            fill_row = b;
            pthread_setspecific(fill_row_key, b);
        } else {
            free(b);
        }
    }
    return fill_row;
}

static uint64_t fill_tile(void *ctx, uint64_t key, float *samples)
{
    const tf_procedural *p = ctx;
    int level = (int)(key >> 58);
    int64_t tx = (int64_t)((key >> 29) & ((1u << 29) - 1)), ty = (int64_t)(key & ((1u << 29) - 1));
    tf_fractal_rowbuf *row = row_buffer();
    for (int b = 0; b < TF_TILE_SAMPLES; b++)
        tf_fractal_row_at(&p->level[level], &p->noise, grid_coord(p, level, ty * TILE + b),
                          tf_proc_spacing(p, level), tx * TILE, TF_TILE_SAMPLES,
                          p->height_scale * p->fade[level], samples + b * TF_TILE_SAMPLES, row);
    if (p->base)
        add_base(p, level, tx, ty, samples);
    return (uint64_t)TF_TILE_SAMPLES * TF_TILE_SAMPLES;
}

size_t tf_procedural_default_cache_bytes(void)
{
    long pages = sysconf(_SC_PHYS_PAGES), size = sysconf(_SC_PAGESIZE);
    double eighth = pages > 0 && size > 0 ? (double)pages * (double)size / 8 : 512 * MiB;
    return (size_t)fmin(eighth, 512 * MiB);
}

/* n(L): the octaves of wavelength at least two samples of level L, at most the scene's. */
static double level_octaves(const tf_terrain *t, double spacing)
{
    double n = 1.0 + log(t->feature_size / (2.0 * spacing)) / log(t->lacunarity);
    return fmin(fmax(n, 1.0), t->octaves);
}

/* Levels go two past the one where every octave is in, so the last octave is drawn with four
 * samples to its wavelength and more. */
static int choose_max_level(const tf_terrain *t, double spacing0)
{
    int level = 0;
    while (level < TF_PROC_MAX_LEVELS && level_octaves(t, ldexp(spacing0, -level)) < t->octaves)
        level++;
    return level + 2 < TF_PROC_MAX_LEVELS ? level + 2 : TF_PROC_MAX_LEVELS;
}

static int prepare_levels(tf_procedural *p, const tf_terrain *t)
{
    if (tf_fractal_prepare(&p->fractal, t))
        return -1;
    tf_fractal_bound_plan(&p->full, &p->fractal);
    p->max_level = choose_max_level(t, p->spacing0);
    for (int level = 0; level <= p->max_level; level++) {
        tf_terrain at_level = *t;
        at_level.octaves = p->octaves[level] = level_octaves(t, tf_proc_spacing(p, level));
        tf_fractal_prepare(&p->level[level], &at_level);
        p->fade[level] = 1.0;
    }
    return 0;
}

static tf_procedural *finish(tf_procedural *p, const tf_terrain *t, size_t cache_bytes,
                             char *err, size_t errlen);

/* A zeroed terrain with an id no other in this process has; NULL with a message. */
static tf_procedural *alloc_terrain(char *err, size_t errlen)
{
    static uint64_t next_id;
    tf_procedural *p = calloc(1, sizeof *p);
    if (!p)
        tf_seterr(err, errlen, "procedural terrain: out of memory");
    else
        p->id = __atomic_add_fetch(&next_id, 1, __ATOMIC_RELAXED);
    return p;
}

tf_procedural *tf_procedural_new(const tf_terrain *t, size_t cache_bytes, char *err,
                                 size_t errlen)
{
    tf_procedural *p = alloc_terrain(err, errlen);
    if (!p)
        return NULL;
    p->extent = t->extent;
    p->height_scale = t->height_scale;
    p->spacing0 = t->extent / TILE;
    tf_noise_init(&p->noise, t->seed);
    if (prepare_levels(p, t)) {
        free(p);
        tf_seterr(err, errlen, "procedural terrain: needs a noise generator (fbm, hetero, "
                  "hybrid or ridged)");
        return NULL;
    }
    return finish(p, t, cache_bytes, err, errlen);
}

/* The bound of every height, and the cache budget; frees p and returns NULL if the bound
 * leaves a float. */
static tf_procedural *finish(tf_procedural *p, const tf_terrain *t, size_t cache_bytes,
                             char *err, size_t errlen)
{
    tf_interval all = tf_fractal_bound(&p->fractal, &p->full, &p->noise, 0, t->extent, 0,
                                       t->extent, 1.0, t->octaves);
    if (p->base) /* the grid, plus detail that may also be absent (fade 0) */
        all = (tf_interval){fmin(all.lo, 0.0), fmax(all.hi, 0.0)};
    double a = all.lo * p->height_scale, b = all.hi * p->height_scale;
    if (p->base) {
        a += p->base->hmin;
        b += p->base->hmax;
    }
    double slack = 1e-6 * fmax(fabs(a), fabs(b)) + 1e-30; /* float rounding of the samples */
    p->lo = fmin(a, b) - slack;
    p->hi = fmax(a, b) + slack;
    /* the bound holds every sample: finite and well inside a float, or refuse the scene now
     * (hetero's products can overflow: offset 10 over 30 octaves) */
    if (!(fabs(p->lo) < 1e30 && fabs(p->hi) < 1e30)) {
        free(p);
        tf_seterr(err, errlen, "procedural terrain: heights may reach %g, beyond what a sample "
                  "holds (lower height_scale, offset or octaves)", fmax(fabs(a), fabs(b)));
        return NULL;
    }
    p->cache_bytes = cache_bytes;
    return p;
}

/* The detail fBm over a grid of cell `cell`: first wavelength two cells, amplitude `detail`. */
static tf_terrain detail_terrain(const tf_terrain *t, double cell)
{
    tf_terrain d = *t;
    d.generator = TF_GEN_FBM;
    d.feature_size = 2 * cell;
    d.height_scale = t->detail;
    return d;
}

tf_procedural *tf_procedural_over(const tf_terrain *t, const struct tf_heightfield *grid,
                                  size_t cache_bytes, char *err, size_t errlen)
{
    tf_procedural *p = alloc_terrain(err, errlen);
    if (!p)
        return NULL;
    tf_terrain d = detail_terrain(t, grid->cell);
    d.extent = grid->extent;
    p->base = grid;
    p->extent = grid->extent;
    p->height_scale = d.height_scale;
    p->spacing0 = grid->extent / TILE;
    tf_noise_init(&p->noise, t->seed ^ 0x64657461696cULL); /* "detail" */
    prepare_levels(p, &d);
    for (int level = 0; level <= p->max_level; level++) {
        /* 1 + log2(2 cells / 2 spacings) octaves: below 1, that share of the first */
        double n = 1.0 + log(grid->cell / tf_proc_spacing(p, level)) / log(d.lacunarity);
        p->fade[level] = n <= 0 ? 0.0 : n >= 1 ? 1.0 : n;
    }
    return finish(p, &d, cache_bytes, err, errlen);
}

void tf_procedural_free(tf_procedural *p) { free(p); }

void tf_procedural_set_cache(tf_procedural *p, size_t bytes) { p->cache_bytes = bytes; }

/* ------------------------------------------------------------------------------ caches */

/* This thread's cache, of the terrain whose id it holds. */
static __thread tf_tilecache *thread_cache;
static __thread uint64_t thread_cache_owner;
static pthread_key_t cache_key;
static pthread_once_t cache_key_once = PTHREAD_ONCE_INIT;

static void free_thread_cache(void *c) { tf_tilecache_free(c); }
static void make_cache_key(void) { pthread_key_create(&cache_key, free_thread_cache); }

static tf_tilecache *cache_of(const tf_procedural *p)
{
    if (thread_cache && thread_cache_owner == p->id) {
        if (tf_tilecache_budget(thread_cache) != p->cache_bytes)
            tf_tilecache_set_budget(thread_cache, p->cache_bytes);
        return thread_cache;
    }
    pthread_once(&cache_key_once, make_cache_key);
    tf_tilecache_free(thread_cache);
    /* the fill reads p: the cache is dropped (above) before another terrain uses this thread */
    thread_cache = tf_tilecache_new(p->cache_bytes, fill_tile, (void *)p);
    if (!thread_cache) {
        fprintf(stderr, "terrafarm: out of memory for a terrain cache\n");
        abort();
    }
    thread_cache_owner = p->id;
    pthread_setspecific(cache_key, thread_cache);
    return thread_cache;
}

/* ------------------------------------------------------------------------------ levels */

tf_proc_view tf_proc_view_of(const tf_procedural *p, tf_vec3 eye, double pixel_angle)
{
    static uint64_t next_id;
    tf_proc_view v;
    v.id = __atomic_add_fetch(&next_id, 1, __ATOMIC_RELAXED);
    v.eye = eye;
    v.pixel_angle = pixel_angle > 0 ? pixel_angle : 1e-3;
    v.dz = eye.z > p->hi ? eye.z - p->hi : 0.0;
    v.min_dist = tf_proc_spacing(p, p->max_level) / v.pixel_angle;
    for (int level = 0; level <= p->max_level; level++) {
        double reach = p->spacing0 / (v.pixel_angle * ldexp(1.0, level));
        v.reach2[level] = reach * reach;
    }
    return v;
}

double tf_proc_lambda(const tf_procedural *p, const tf_proc_view *v, double d2)
{
    double d = sqrt(d2 + v->dz * v->dz);
    double footprint = v->pixel_angle * (d > v->min_dist ? d : v->min_dist);
    double lambda = log2(p->spacing0 / footprint);
    return lambda < 0 ? 0 : lambda > p->max_level ? p->max_level : lambda;
}

static double lambda_at(const tf_procedural *p, const tf_proc_view *v, double x, double y)
{
    double dx = x - v->eye.x, dy = y - v->eye.y;
    return tf_proc_lambda(p, v, dx * dx + dy * dy);
}

/* Squared horizontal distances from the eye to the nearest and farthest points of the box. */
static void box_distances(const tf_proc_view *v, double x0, double x1, double y0, double y1,
                          double *near2, double *far2)
{
    double nx = v->eye.x < x0 ? x0 - v->eye.x : v->eye.x > x1 ? v->eye.x - x1 : 0.0;
    double ny = v->eye.y < y0 ? y0 - v->eye.y : v->eye.y > y1 ? v->eye.y - y1 : 0.0;
    double fx = fmax(fabs(v->eye.x - x0), fabs(v->eye.x - x1));
    double fy = fmax(fabs(v->eye.y - y0), fabs(v->eye.y - y1));
    *near2 = nx * nx + ny * ny;
    *far2 = fx * fx + fy * fy;
}

/* floor(lambda) at squared horizontal distance d2: the last level whose reach covers it. */
static int level_at(const tf_procedural *p, const tf_proc_view *v, double d2)
{
    double dd2 = d2 + v->dz * v->dz;
    if (!(dd2 < v->reach2[1]))
        return 0;
    /* reach2[L] = reach2[0] / 4^L: start from the binary exponent of the ratio, then settle
     * on the table itself so rounding cannot disagree with it */
    int level = ilogb(v->reach2[0] / fmax(dd2, 1e-300)) / 2;
    level = level < 0 ? 0 : level > p->max_level ? p->max_level : level;
    while (level > 0 && !(dd2 <= v->reach2[level]))
        level--;
    while (level < p->max_level && dd2 <= v->reach2[level + 1])
        level++;
    return level;
}

double tf_proc_lambda_slope(const tf_procedural *p, const tf_proc_view *v, double x0,
                            double x1, double y0, double y1)
{
    (void)p;
    double near2, far2;
    box_distances(v, x0, x1, y0, y1, &near2, &far2);
    double d = sqrt(near2 + v->dz * v->dz);
    return 1.0 / (M_LN2 * fmax(d, v->min_dist));
}

void tf_proc_box_levels(const tf_procedural *p, const tf_proc_view *v, double x0, double x1,
                        double y0, double y1, int *level_lo, int *level_hi)
{
    double near2, far2;
    box_distances(v, x0, x1, y0, y1, &near2, &far2);
    /* lambda falls with distance; a hair of slack covers rounding against tf_proc_lambda */
    int lo = level_at(p, v, far2 * (1 + 1e-9) + 1e-300);
    int hi = level_at(p, v, near2 * (1 - 1e-9)) + 1;
    *level_lo = lo;
    *level_hi = hi > p->max_level ? p->max_level : hi;
}

/* ------------------------------------------------------------------------------ samples */

void tf_proc_samples(const tf_procedural *p, int level, int64_t i0, int64_t j0, int w, int h,
                     float *out)
{
    int64_t last = ((int64_t)1 << level) - 1;
    int64_t tx = i0 / TILE < last ? i0 / TILE : last, ty = j0 / TILE < last ? j0 / TILE : last;
    tf_tilecache_read(cache_of(p), tile_key(level, tx, ty), (int)(i0 - tx * TILE),
                      (int)(j0 - ty * TILE), w, h, out);
}

void tf_proc_range(const tf_procedural *p, int level, int k, int64_t ci, int64_t cj, float *lo,
                   float *hi)
{
    int64_t tx = ci / TILE, ty = cj / TILE;
    tf_tilecache_range(cache_of(p), tile_key(level, tx, ty), k, (int)(ci - tx * TILE) >> k,
                       (int)(cj - ty * TILE) >> k, lo, hi);
}

/* The cell of level L under coordinate c (clamped to the square) and the fraction across it. */
static int64_t cell_of(const tf_procedural *p, int level, double c, double *fraction)
{
    double g = c / tf_proc_spacing(p, level);
    int64_t cells = level_cells(level);
    int64_t i = g <= 0 ? 0 : g >= (double)cells ? cells - 1 : (int64_t)g;
    double f = g - (double)i;
    *fraction = f < 0 ? 0 : f > 1 ? 1 : f;
    return i;
}

double tf_proc_level_height(const tf_procedural *p, int level, double x, double y)
{
    double fx, fy;
    int64_t i = cell_of(p, level, x, &fx), j = cell_of(p, level, y, &fy);
    float c[4];
    tf_proc_samples(p, level, i, j, 2, 2, c);
    return (1 - fy) * ((1 - fx) * c[0] + fx * c[1]) + fy * ((1 - fx) * c[2] + fx * c[3]);
}

double tf_proc_height(const tf_procedural *p, const tf_proc_view *v, double x, double y)
{
    double lambda = lambda_at(p, v, x, y);
    int level = (int)lambda;
    double w = lambda - level;
    double h = tf_proc_level_height(p, level, x, y);
    if (w > 0 && level < p->max_level)
        h += w * (tf_proc_level_height(p, level + 1, x, y) - h);
    return h;
}

/* ------------------------------------------------------------------------------ bounds */

tf_interval tf_proc_bound(const tf_procedural *p, const tf_proc_view *v, double x0, double x1,
                          double y0, double y1)
{
    int lo, hi;
    tf_proc_box_levels(p, v, x0, x1, y0, y1, &lo, &hi);
    return tf_proc_bound_levels(p, x0, x1, y0, y1, lo, hi);
}

tf_interval tf_proc_bound_levels(const tf_procedural *p, double x0, double x1, double y0,
                                 double y1, int lo, int hi)
{
    double pad = tf_proc_spacing(p, lo);
    tf_interval b = tf_fractal_bound(&p->fractal, &p->full, &p->noise, x0 - pad, x1 + pad, y0 - pad,
                                     y1 + pad, p->octaves[lo], p->octaves[hi]);
    double f_lo = fmin(p->fade[lo], p->fade[hi]), f_hi = fmax(p->fade[lo], p->fade[hi]);
    if (f_lo < 1) /* a fading first octave: anything between none and all of it */
        b = (tf_interval){fmin(b.lo * f_lo, b.lo * f_hi), fmax(b.hi * f_lo, b.hi * f_hi)};
    double a = b.lo * p->height_scale, c = b.hi * p->height_scale;
    if (p->base) {
        float glo, ghi;
        tf_heightfield_range(p->base, x0 - pad, x1 + pad, y0 - pad, y1 + pad, &glo, &ghi);
        a += glo;
        c += ghi;
    }
    /* samples are rounded to float: widen by more than half an ulp of the largest */
    double slack = 1e-6 * fmax(fabs(a), fabs(c)) + 1e-30;
    return (tf_interval){fmax(fmin(a, c) - slack, p->lo), fmin(fmax(a, c) + slack, p->hi)};
}
