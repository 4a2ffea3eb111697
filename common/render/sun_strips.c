/* sun_strips.c: building the sun's strips (render/sun_strips.h; the bounds and their query are
 * in render/sun_math.h).
 *
 * Coordinates are in cells: grid vertex (i, j) is at along = ux i + uy j, across = -uy i + ux j
 * (u the sun's unit heading).  The build goes once over the blocks of `TF_SUN_BLOCK_LEVEL` of
 * the max/min grids (2x2 cells): a block's top and bottom bound the triangles over it, and the
 * block lies, by its corners, within an along and an across interval, widened by a margin far
 * above their rounding; every bin those intervals meet takes the block's top and bottom as
 * candidates.  So a bin's top bounds the surface over it from above and its floor from below
 * (a bin a block only seems to meet gets a larger top and a lower floor, never the wrong way).
 * Then each strip, from its far end back, turns tops into reach and floors into sink:
 *     reach[b] = max(reach[b + 1], top[b] - climb (along0 + b ds)),
 *     sink[b]  = max(sink[b + 1], floor[b] - climb (along0 + (b + 1) ds))  over bins wholly
 *                inside the square,
 * reach rounded up and sink down (a relative 1e-9 on the double, then to the next float).  A
 * height field with a NaN anywhere (a hole, slope_max NaN) gets no sinks: the under proof needs
 * a continuous surface.  One pass over 1/4 of the cells and one over the bins: ~15 ms and
 * 5.6 MB for 2049^2 samples, the table on huge pages where the system has them (a fresh
 * table's first touch, one fault and one zeroed 4 KB page at a time, was a fifth of the
 * build).  On several threads each takes a range of whole strips (every thread reads every
 * block, and scatters only into its own strips), so the table is the same bits for any number
 * of threads; a process that forks renderers builds it so once and keeps it with the terrain
 * (tf_sun_strips_keep), and its children share the one copy.  Strips 2.5 cells wide instead
 * of 4 bound the surface under a ray's line more tightly, so a lit ray is proved clear ~4%
 * sooner in time (bench/README.md section 27); narrower strips or shorter bins help a little
 * more but hold more memory than the comparison with Embree leaves (issue 23: 1/10 of its
 * memory; 2 x 4 cells would be 68.5 of the 68.4 MB allowed at 2049^2). */
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "render/sun_strips.h"

#define TF_SUN_STRIP_CELLS 2.5 /* strip width, cells */
#define TF_SUN_BIN_CELLS 4.0   /* bin length, cells */
#define TF_SUN_BLOCK_LEVEL 1   /* the max/min-grid level scattered into the bins */
#define TF_SUN_LOOK 16         /* bins ahead a ray tries one by one before halving the rest */

/* The frame: the sun's heading in cells, the strips' extent over the square. */
static int frame_of(const tf_heightfield *hf, tf_vec3 sun, tf_sun_frame *f, double *ux,
                    double *uy)
{
    const double run = sqrt(sun.x * sun.x + sun.y * sun.y);
    if (!(run > 1e-6) || !(sun.z > 0) || !isfinite(run) || !isfinite(sun.z))
        return 0; /* overhead, at or below the horizon: every ray is its own case */
    *ux = sun.x / run, *uy = sun.y / run;
    const double C = hf->cells, w = TF_SUN_STRIP_CELLS, ds = TF_SUN_BIN_CELLS;
    double al_lo = INFINITY, al_hi = -INFINITY, ac_lo = INFINITY, ac_hi = -INFINITY;
    for (int c = 0; c < 4; c++) {
        const double x = (c & 1) ? C : 0, y = (c & 2) ? C : 0;
        const double al = *ux * x + *uy * y, ac = -*uy * x + *ux * y;
        al_lo = fmin(al_lo, al), al_hi = fmax(al_hi, al);
        ac_lo = fmin(ac_lo, ac), ac_hi = fmax(ac_hi, ac);
    }
    *f = (tf_sun_frame){0};
    f->a_s = *ux / hf->cell, f->b_s = *uy / hf->cell;
    f->a_p = -*uy / hf->cell, f->b_p = *ux / hf->cell;
    /* a strip (a bin) of margin on either side: the query wants a ray a strip from the edge */
    f->along0 = al_lo - ds, f->across0 = ac_lo - w;
    f->ds = ds, f->inv_ds = 1 / ds, f->inv_w = 1 / w;
    f->strips = (int)((ac_hi - ac_lo) / w) + 4;
    f->bins = (int)((al_hi - al_lo) / ds) + 4;
    f->climb = sun.z * hf->cell / run;
    f->t_per_cell = hf->cell / run;
    f->dx = sun.x, f->dy = sun.y, f->cell = hf->cell, f->n = hf->n;
    f->eps = 1e-7 * (3 * hf->extent + 3 * (fabs(hf->hmin) + fabs(hf->hmax)));
    f->look = TF_SUN_LOOK;
    return 1;
}

/* Where the blocks of one level reach, from a block's corner cell (i, j): along and across
 * spans [ux i + uy j + al_lo, .. + al_hi] and [-uy i + ux j + ac_lo, .. + ac_hi] measured from
 * the frame's along0 and across0 (so a span times inv_ds or inv_w is in bins or strips), each
 * already widened by the margin. */
typedef struct block_reach {
    double ux, uy, B;
    double al_lo, al_hi, ac_lo, ac_hi;
} block_reach;

static block_reach block_reach_of(const tf_sun_frame *f, int cells, double ux, double uy, int L)
{
    const double B = (double)(1 << L), mu = 1e-9 * cells + 1e-9;
    /* a block's along and across spans from its corner (i, j): the corners' offsets */
    const double al_off[4] = {0, ux * B, uy * B, (ux + uy) * B};
    const double ac_off[4] = {0, -uy * B, ux * B, (ux - uy) * B};
    double al_min = 0, al_max = 0, ac_min = 0, ac_max = 0;
    for (int c = 1; c < 4; c++) {
        al_min = fmin(al_min, al_off[c]), al_max = fmax(al_max, al_off[c]);
        ac_min = fmin(ac_min, ac_off[c]), ac_max = fmax(ac_max, ac_off[c]);
    }
    return (block_reach){ux, uy, B, al_min - mu - f->along0, al_max + mu - f->along0,
                         ac_min - mu - f->across0, ac_max + mu - f->across0};
}

/* Block (bi, bj), bounded by top and bottom: every bin it meets takes its top, and its floor
 * negated (so both are raised with one max, which the compiler does on the pair at once;
 * strip_bounds negates the floors back). */
static inline void scatter_block(const tf_sun_frame *f, const block_reach *r, int bi, int bj,
                                 float top, float bottom, int k_lo, int k_hi, float *table)
{
    const double i = bi * r->B, j = bj * r->B;
    const double al = r->ux * i + r->uy * j, ac = -r->uy * i + r->ux * j;
    const int b0 = (int)((al + r->al_lo) * f->inv_ds), b1 = (int)((al + r->al_hi) * f->inv_ds);
    int k0 = (int)((ac + r->ac_lo) * f->inv_w), k1 = (int)((ac + r->ac_hi) * f->inv_w);
    k0 = k0 > k_lo ? k0 : k_lo, k1 = k1 < k_hi ? k1 : k_hi; /* this thread's strips only */
    /* a block the grids could not bound (a NaN height) bounds its bins by nothing: they then
     * prove neither clear nor under */
    const float hi = isnan(top) ? INFINITY : top, neg_lo = isnan(bottom) ? INFINITY : -bottom;
    for (int k = k0; k <= k1; k++) {
        float *t = &table[TF_SUN_BIN * ((size_t)k * (size_t)f->bins + (size_t)b0)];
        for (int b = 0; b <= b1 - b0; b++) {
            t[2 * b] = hi > t[2 * b] ? hi : t[2 * b];
            t[2 * b + 1] = neg_lo > t[2 * b + 1] ? neg_lo : t[2 * b + 1];
        }
    }
}

/* Every block of level L raises the tops and lowers the floors of the bins it meets in strips
 * k_lo..k_hi (table: top, negated floor in a bin's first two floats, from -INFINITY, until
 * strip_bounds makes them reach and sink). */
static void scatter_blocks(const tf_heightfield *hf, const tf_sun_frame *f, double ux, double uy,
                           int k_lo, int k_hi, float *table)
{
    const int L = TF_SUN_BLOCK_LEVEL < hf->levels ? TF_SUN_BLOCK_LEVEL : hf->levels - 1;
    const int side = hf->cells >> L;
    const block_reach r = block_reach_of(f, hf->cells, ux, uy, L);
    const float *mx = hf->maxgrid[L], *mn = hf->mingrid[L];
    for (int bj = 0; bj < side; bj++)
        for (int bi = 0; bi < side; bi++) {
            const size_t at = (size_t)bj * (size_t)side + (size_t)bi;
            scatter_block(f, &r, bi, bj, mx[at], mn[at], k_lo, k_hi, table);
        }
}

/* A double rounded up (down) to a float: the nearest float, stepped one ulp where it lies on
 * the wrong side (nextafterf, spelled on the bits: this runs for every bin). */
static float float_step(float r, int up)
{
    uint32_t bits;
    memcpy(&bits, &r, sizeof bits);
    if (r == 0)
        bits = up ? 0x00000001u : 0x80000001u; /* the least denormal, either sign */
    else
        bits = (r > 0) == (up != 0) ? bits + 1 : bits - 1; /* away from or toward zero */
    memcpy(&r, &bits, sizeof r);
    return r;
}

static float float_up(double v)
{
    const float r = (float)v;
    return r < v ? float_step(r, 1) : r;
}

static float float_down(double v)
{
    const float r = (float)v;
    return r > v ? float_step(r, 0) : r;
}

/* A strip's two edges in the square's cell coordinates: a point at run `al` along edge e is
 * (x0[e] + ux al, y0[e] + uy al). */
typedef struct strip_edges {
    double x0[2], y0[2], ux, uy, lo, hi; /* lo, hi: the square shrunk by a margin */
} strip_edges;

static strip_edges edges_of(const tf_sun_frame *f, int cells, double ux, double uy, int k)
{
    strip_edges e = {.ux = ux, .uy = uy};
    const double w = 1 / f->inv_w, m = 1e-6 * cells + 1e-9;
    for (int c = 0; c < 2; c++) {
        const double ac = f->across0 + (k + c) * w;
        e.x0[c] = -uy * ac, e.y0[c] = ux * ac;
    }
    e.lo = m, e.hi = cells - m;
    return e;
}

/* Does bin b of the strip lie wholly inside the square (its corners do, by a margin far above
 * their rounding; the square is convex)? */
static int bin_inside(const tf_sun_frame *f, const strip_edges *e, int b)
{
    for (int c = 0; c < 4; c++) {
        const double al = f->along0 + (b + (c & 1)) * f->ds;
        const double i = e->x0[c >> 1] + e->ux * al, j = e->y0[c >> 1] + e->uy * al;
        if (!(i >= e->lo && i <= e->hi && j >= e->lo && j <= e->hi))
            return 0;
    }
    return 1;
}

/* The strip's bins that lie inside the square: [*first, *last], empty where *first > *last.
 * Along each edge of the strip the points inside the square form one interval (it is convex),
 * so the bins inside do too: found from either end, the ones between are not asked. */
static void bins_inside(const tf_sun_frame *f, const strip_edges *e, int *first, int *last)
{
    int b = 0, c = f->bins - 1;
    while (b <= c && !bin_inside(f, e, b))
        b++;
    while (c >= b && !bin_inside(f, e, c))
        c--;
    *first = b, *last = c;
}

/* One strip's bins, from its far end back: tops into reach (rounded up), floors into sink
 * (rounded down; only bins inside the square count, and none where `holes`). */
static void strip_bounds(const tf_sun_frame *f, int cells, double ux, double uy, int holes,
                         int k, float *row)
{
    const strip_edges e = edges_of(f, cells, ux, uy, k);
    int first, last;
    bins_inside(f, &e, &first, &last);
    if (holes)
        first = last + 1;
    double reach = -INFINITY;
    float sink = -INFINITY;
    for (int b = f->bins - 1; b >= 0; b--) {
        float *bin = row + TF_SUN_BIN * (size_t)b;
        if (bin[0] > -INFINITY) {
            const double top = bin[0], rise = f->climb * (f->along0 + b * f->ds);
            const double v = (top - rise) + 1e-9 * (fabs(top) + fabs(rise));
            reach = v > reach ? v : reach;
        }
        const double bottom = -bin[1], rise = f->climb * (f->along0 + (b + 1) * f->ds);
        if (b >= first && b <= last && isfinite(bottom)) {
            const float g = float_down((bottom - rise) - 1e-9 * (fabs(bottom) + fabs(rise)));
            sink = g > sink ? g : sink;
        }
        bin[0] = float_up(reach), bin[1] = sink;
    }
}

/* The part of a build one thread does: strips k_lo..k_hi, whole (their bins cleared, every
 * block's share scattered into them, their bounds from the far end back).  No two parts write
 * the same bin, and a bin's value is a max over the same blocks whichever thread computes it:
 * the table does not depend on the number of threads. */
typedef struct strips_part {
    const tf_heightfield *hf;
    const tf_sun_frame *f;
    double ux, uy;
    int holes, k_lo, k_hi;
    float *table;
} strips_part;

static void *build_part(void *arg)
{
    const strips_part *p = arg;
    const tf_sun_frame *f = p->f;
    const size_t bins = (size_t)f->bins;
    for (size_t i = (size_t)p->k_lo * bins; i < (size_t)(p->k_hi + 1) * bins; i++)
        p->table[TF_SUN_BIN * i] = -INFINITY, p->table[TF_SUN_BIN * i + 1] = -INFINITY;
    scatter_blocks(p->hf, f, p->ux, p->uy, p->k_lo, p->k_hi, p->table);
    for (int k = p->k_lo; k <= p->k_hi; k++)
        strip_bounds(f, p->hf->cells, p->ux, p->uy, p->holes, k,
                     p->table + TF_SUN_BIN * (size_t)k * bins);
    return NULL;
}

#define TF_SUN_MAX_THREADS 64

/* parts[0] on this thread, the others on threads of their own (one that cannot start: here). */
static void run_parts(strips_part *parts, int n)
{
    pthread_t tids[TF_SUN_MAX_THREADS];
    int started[TF_SUN_MAX_THREADS] = {0};
    for (int t = 1; t < n; t++)
        started[t] = pthread_create(&tids[t], NULL, build_part, &parts[t]) == 0;
    build_part(&parts[0]);
    for (int t = 1; t < n; t++)
        if (started[t])
            pthread_join(tids[t], NULL);
        else
            build_part(&parts[t]);
}
#define TF_SUN_PARALLEL_MIN_CELLS (1 << 20) /* below ~1 M cells a thread costs more than it saves */

tf_sun_strips *tf_sun_strips_build_threads(const tf_heightfield *hf, tf_vec3 sun, int threads)
{
    tf_sun_frame f;
    double ux, uy;
    if (!hf || hf->proc || !hf->maxgrid || hf->cells < 2 || !frame_of(hf, sun, &f, &ux, &uy))
        return NULL;
    const size_t n = (size_t)f.strips * (size_t)f.bins;
    tf_sun_strips *s = malloc(sizeof *s);
    float *a = tf_alloc_heights(TF_SUN_BIN * n * sizeof *a);
    if (!s || !a) {
        free(s), free(a);
        return NULL;
    }
    /* a hole (slope_max NaN: heightfield.h) breaks the under proof's continuous surface; the
     * grids cannot say, their min of four samples keeps or drops a NaN by its place */
    const int holes = !(hf->slope_max >= 0 && hf->slope_max < INFINITY);
    threads = tf_thread_count(threads);
    if ((double)hf->cells * hf->cells < TF_SUN_PARALLEL_MIN_CELLS)
        threads = 1;
    threads = threads < f.strips ? threads : f.strips;
    threads = threads < TF_SUN_MAX_THREADS ? threads : TF_SUN_MAX_THREADS;
    strips_part parts[TF_SUN_MAX_THREADS];
    for (int t = 0; t < threads; t++)
        parts[t] = (strips_part){hf, &f, ux, uy, holes, (int)((int64_t)f.strips * t / threads),
                                 (int)((int64_t)f.strips * (t + 1) / threads) - 1, a};
    run_parts(parts, threads);
    s->frame = f;
    s->table = a;
    s->h = hf->h;
    s->sun = sun;
    return s;
}

tf_sun_strips *tf_sun_strips_build(const tf_heightfield *hf, tf_vec3 sun)
{
    return tf_sun_strips_build_threads(hf, sun, 1);
}

/* ---------------------------------------------------------------- strips kept with the terrain */

static void free_kept(void *s) { tf_sun_strips_free(s); }

int tf_sun_strips_keep(tf_heightfield *hf, tf_vec3 sun, int threads)
{
    if (!hf || hf->derived)
        return -1;
    tf_sun_strips *s = tf_sun_strips_build_threads(hf, sun, threads);
    if (!s)
        return -1;
    hf->derived = s;
    hf->derived_free = free_kept;
    return 0;
}

size_t tf_sun_strips_kept_bytes(const tf_heightfield *hf)
{
    return hf && hf->derived_free == free_kept ? tf_sun_strips_bytes(hf->derived) : 0;
}

const tf_sun_strips *tf_sun_strips_kept(const tf_heightfield *hf, tf_vec3 sun)
{
    const tf_sun_strips *s = hf && hf->derived_free == free_kept ? hf->derived : NULL;
    /* kept for this very sun (the same bits): a sequence whose sun moves builds its own */
    return s && s->h == hf->h && memcmp(&s->sun, &sun, sizeof sun) == 0 ? s : NULL;
}

void tf_sun_strips_free(tf_sun_strips *s)
{
    if (s)
        free(s->table);
    free(s);
}

int tf_sun_strips_shadow(const tf_sun_strips *s, tf_vec3 o, double *t)
{
    return s ? tf_sun_strips_say(&s->frame, s->table, s->h, o.x, o.y, o.z, 0, t) : TF_SUN_UNKNOWN;
}

tf_shadow_clear tf_sun_strips_under_record(const tf_sun_strips *s, tf_vec3 o)
{
    return (tf_shadow_clear){{s->sun.x, s->sun.y, s->sun.z}, -1, {o.x, o.y, o.z}};
}

const tf_shadow_clear *tf_sun_strips_named(const tf_sun_strips *s, const tf_shadow_clear *near,
                                           tf_shadow_clear *named)
{
    if (!s || !near || !(near->t_under < 0))
        return near;
    double t = 0;
    *named = *near;
    const int said = tf_sun_strips_say(&s->frame, s->table, s->h, near->o[0], near->o[1],
                                       near->o[2], 1, &t);
    named->t_under = said == TF_SUN_UNDER && t > 0 ? t : 0;
    return named;
}

size_t tf_sun_strips_table_bytes(const tf_sun_strips *s)
{
    return TF_SUN_BIN * (size_t)s->frame.strips * (size_t)s->frame.bins * sizeof(float);
}

size_t tf_sun_strips_bytes(const tf_sun_strips *s)
{
    return s ? sizeof *s + tf_sun_strips_table_bytes(s) : 0;
}
