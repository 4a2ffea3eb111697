/* fault.c: Krten's fault-line terrain with his wind and rain erosion filters -- tf_gen_fault,
 * the TF_GEN_FAULT generator.
 *
 * Source: R. Krten, "Generating Realistic Terrain", Dr. Dobb's Journal, July 1994, Listings
 * Two (filter) and Four (fault, generate_line).
 *
 *  - generate_line: a line through two random points (x1, y1), (x2, y2) with |x2-x1| > 2 and
 *    |y2-y1| > 2 (rejection sampling, as in the listing); on each row y the intercept is
 *    xint = x1 + trunc((y - y1) * (x2 - x1) / (y2 - y1)), clamped to [0, n]; samples left of it
 *    move by +sign * step, the others by -sign * step.  Krten's "1/x-height reduction": fault f
 *    (0-based) has step fault_step / (f + 1).  (The listing's sign is 60/40 biased by
 *    `random(10) > 5`; ours is a fair coin.)  Integer intercepts, exactly as the listing.
 *
 *  - filter: the single-constant FIR ("low-pass") filter.  One directional sweep keeps
 *    acc = in[0] / (1 - k) and for each sample outputs (1 - k) * acc, then acc = k * acc + in[x]:
 *    exponential smoothing of the samples BEFORE x.  The two-pass filter (wind) averages the
 *    +x and +y sweeps, which leaves Krten's "landscape shift" downwind; the four-pass filter
 *    (rain) averages the sweeps in all four directions.  Every sweep reads the same input.
 *    We run wind_passes of the two-pass filter, then rain_passes of the four-pass filter, with
 *    k = erosion_k, after all the faults.
 *
 * The output is normalised to [0, 1] (min -> 0, max -> 1; a flat result is all 0).
 *
 * Parallel and deterministic: each random draw is a hash of (seed, fault, attempt, field); the
 * faults are summed row by row (rows in parallel) in fault order via a suffix sum of per-row
 * step changes, so a row costs O(n + faults) instead of O(n * faults); x sweeps run rows in
 * parallel and y sweeps run blocks of columns in parallel (walking rows in order, one
 * accumulator per column, which keeps memory access sequential).  Every output element is
 * computed by one fixed sequence of operations whatever the thread count. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/gridgen.h"
#include "terrain/terrain.h"
#include "log.h"

#define FAULT_KMAX 13
#define FAULT_MAX_LINES 100000 /* each costs O(1) per row: bounded work and memory */
#define FAULT_MAX_PASSES 10000
#define FAULT_MAX_ATTEMPTS 64  /* rejection sampling bound for the line end points */

typedef struct {
    int x1, y1, dx, dy; /* the line; dy != 0 */
    double up;          /* sign * step: added left of the line, subtracted right of it */
} fault_line;

/* Random integer in [0, n) from (seed, fault, attempt, field). */
static int fault_pick(uint64_t seed, int f, int attempt, int field, int n)
{
    uint64_t key = tf_grid_key(seed, TF_STREAM_FAULT, (uint32_t)f, (uint32_t)attempt,
                               (uint32_t)field);
    return (int)(tf_hash64(key) % (uint64_t)n);
}

/* Two coordinates more than `gap` apart (Krten's do-while loops), deterministic. */
static void fault_pair(uint64_t seed, int f, int field, int n, int gap, int *a, int *b)
{
    for (int attempt = 0; attempt < FAULT_MAX_ATTEMPTS; attempt++) {
        *a = fault_pick(seed, f, attempt, field, n);
        *b = fault_pick(seed, f, attempt, field + 1, n);
        if (abs(*b - *a) > gap)
            return;
    }
    *a = 0; /* astronomically unlikely: fall back to the full span */
    *b = n - 1;
}

static void fault_make_lines(fault_line *L, int count, int n, const tf_terrain *t)
{
    int gap = n - 2 < 2 ? n - 2 : 2; /* Krten's "> 2", relaxed for the 3x3 grid */
    for (int f = 0; f < count; f++) {
        int x1, x2, y1, y2;
        fault_pair(t->seed, f, 0, n, gap, &y1, &y2);
        fault_pair(t->seed, f, 2, n, gap, &x1, &x2);
        uint64_t key = tf_grid_key(t->seed, TF_STREAM_FAULT, (uint32_t)f, 0, 4);
        double sign = (tf_hash64(key) & 1) ? -1.0 : 1.0;
        L[f] = (fault_line){x1, y1, x2 - x1, y2 - y1, sign * t->fault_step / (double)(f + 1)};
    }
}

typedef struct {
    float *h;
    int n;
    const fault_line *lines;
    int count;
    double *scratch; /* (n + 1) doubles per piece: the per-row step changes */
} fault_sum_ctx;

/* Sum all faults into rows [begin, end).  For row y, value(x) = sum_f (x < xint_f ? +up_f :
 * -up_f) = -sum_f up_f + sum_{f : xint_f > x} 2 up_f: a suffix sum over a per-row array. */
static void fault_sum_rows(void *arg, int piece, int begin, int end)
{
    fault_sum_ctx *c = arg;
    int n = c->n;
    double *add = c->scratch + (size_t)piece * (n + 1);
    for (int y = begin; y < end; y++) {
        memset(add, 0, (size_t)(n + 1) * sizeof *add);
        double base = 0.0;
        for (int f = 0; f < c->count; f++) {
            const fault_line *L = &c->lines[f];
            long long xint = L->x1 + ((long long)(y - L->y1) * L->dx) / L->dy;
            if (xint < 0) xint = 0;
            if (xint > n) xint = n;
            base -= L->up;
            add[xint] += 2.0 * L->up;
        }
        double run = base;
        for (int x = n; x-- > 0;) {
            run += add[x + 1];
            c->h[(size_t)y * n + x] = (float)run;
        }
    }
}

typedef struct {
    const float *in;
    float *out;
    int n;
    double k;
    int four;     /* 1: rain (four-pass), 0: wind (two-pass) */
    double *acc;  /* n column accumulators (y sweeps; each thread owns its column range) */
} filter_ctx;

/* x sweeps of rows [begin, end): out = forward (+ backward). */
static void filter_x_rows(void *arg, int piece, int begin, int end)
{
    (void)piece;
    filter_ctx *c = arg;
    int n = c->n;
    double k = c->k, g = 1.0 - c->k;
    for (int y = begin; y < end; y++) {
        const float *in = c->in + (size_t)y * n;
        float *out = c->out + (size_t)y * n;
        double acc = in[0] / g;
        for (int x = 0; x < n; x++) {
            out[x] = (float)(g * acc);
            acc = acc * k + in[x];
        }
        if (!c->four)
            continue;
        acc = in[n - 1] / g;
        for (int x = n - 1; x >= 0; x--) {
            out[x] = (float)((double)out[x] + g * acc);
            acc = acc * k + in[x];
        }
    }
}

/* y sweeps of columns [begin, end), walking rows in order; then the final average. */
static void filter_y_cols(void *arg, int piece, int begin, int end)
{
    (void)piece;
    filter_ctx *c = arg;
    int n = c->n;
    double k = c->k, g = 1.0 - c->k;
    double *acc = c->acc;
    for (int x = begin; x < end; x++)
        acc[x] = c->in[x] / g;
    for (int y = 0; y < n; y++) {
        const float *in = c->in + (size_t)y * n;
        float *out = c->out + (size_t)y * n;
        for (int x = begin; x < end; x++) {
            out[x] = (float)((double)out[x] + g * acc[x]);
            acc[x] = acc[x] * k + in[x];
        }
    }
    if (c->four) {
        for (int x = begin; x < end; x++)
            acc[x] = c->in[(size_t)(n - 1) * n + x] / g;
        for (int y = n - 1; y >= 0; y--) {
            const float *in = c->in + (size_t)y * n;
            float *out = c->out + (size_t)y * n;
            for (int x = begin; x < end; x++) {
                out[x] = (float)((double)out[x] + g * acc[x]);
                acc[x] = acc[x] * k + in[x];
            }
        }
    }
    double inv = c->four ? 0.25 : 0.5;
    for (int y = 0; y < n; y++) {
        float *out = c->out + (size_t)y * n;
        for (int x = begin; x < end; x++)
            out[x] = (float)((double)out[x] * inv);
    }
}

/* One application of Krten's filter from `in` to `out`. */
static void fault_filter(const float *in, float *out, int n, double k, int four, double *acc,
                         int threads)
{
    filter_ctx c = {in, out, n, k, four, acc};
    int min_rows = 1 + 16384 / n;
    tf_grid_parallel(n, threads, min_rows, filter_x_rows, &c);
    tf_grid_parallel(n, threads, 64, filter_y_cols, &c);
}

typedef struct {
    float *h;
    int n;
    float *rmin, *rmax;
    double lo, scale;
} norm_ctx;

static void norm_range_rows(void *arg, int piece, int begin, int end)
{
    (void)piece;
    norm_ctx *c = arg;
    for (int y = begin; y < end; y++) {
        const float *row = c->h + (size_t)y * c->n;
        float lo = row[0], hi = row[0];
        for (int x = 1; x < c->n; x++) {
            if (row[x] < lo) lo = row[x];
            if (row[x] > hi) hi = row[x];
        }
        c->rmin[y] = lo;
        c->rmax[y] = hi;
    }
}

static void norm_apply_rows(void *arg, int piece, int begin, int end)
{
    (void)piece;
    norm_ctx *c = arg;
    for (size_t q = (size_t)begin * c->n; q < (size_t)end * c->n; q++)
        c->h[q] = (float)(((double)c->h[q] - c->lo) * c->scale);
}

/* Map [min, max] to [0, 1]; min and max are exact (order-independent), so is the result. */
static void fault_normalise(float *h, int n, float *rowbuf, int threads)
{
    norm_ctx c = {h, n, rowbuf, rowbuf + n, 0.0, 0.0};
    int min_rows = 1 + 16384 / n;
    tf_grid_parallel(n, threads, min_rows, norm_range_rows, &c);
    float lo = c.rmin[0], hi = c.rmax[0];
    for (int y = 1; y < n; y++) {
        if (c.rmin[y] < lo) lo = c.rmin[y];
        if (c.rmax[y] > hi) hi = c.rmax[y];
    }
    c.lo = lo;
    c.scale = hi > lo ? 1.0 / ((double)hi - (double)lo) : 0.0;
    tf_grid_parallel(n, threads, min_rows, norm_apply_rows, &c);
}

static int fault_validate(int k, const tf_terrain *t, char *err, size_t errlen)
{
    if (k < 1 || k > FAULT_KMAX) {
        tf_seterr(err, errlen, "fault: size exponent %d out of range 1..%d", k, FAULT_KMAX);
        return -1;
    }
    if (t->faults < 0 || t->faults > FAULT_MAX_LINES) {
        tf_seterr(err, errlen, "fault: faults %d out of range 0..%d", t->faults, FAULT_MAX_LINES);
        return -1;
    }
    if (!isfinite(t->fault_step) || fabs(t->fault_step) > 1e6) {
        tf_seterr(err, errlen, "fault: fault_step %g is not a finite number below 1e6",
                 t->fault_step);
        return -1;
    }
    if (t->wind_passes < 0 || t->wind_passes > FAULT_MAX_PASSES || t->rain_passes < 0 ||
        t->rain_passes > FAULT_MAX_PASSES) {
        tf_seterr(err, errlen, "fault: wind_passes %d / rain_passes %d out of range 0..%d",
                 t->wind_passes, t->rain_passes, FAULT_MAX_PASSES);
        return -1;
    }
    if (!(t->erosion_k >= 0.0 && t->erosion_k < 1.0)) {
        tf_seterr(err, errlen, "fault: erosion_k %g out of range [0, 1)", t->erosion_k);
        return -1;
    }
    return 0;
}

int tf_gen_fault(float *h, int k, const tf_terrain *t, int threads, char *err, size_t errlen)
{
    if (fault_validate(k, t, err, errlen) != 0)
        return -1;
    int n = (1 << k) + 1;
    int passes = t->wind_passes + t->rain_passes;
    fault_line *lines = malloc((size_t)(t->faults > 0 ? t->faults : 1) * sizeof *lines);
    double *acc = malloc((size_t)n * sizeof *acc);
    float *rowbuf = malloc((size_t)2 * n * sizeof *rowbuf);
    float *tmp = passes > 0 ? malloc((size_t)n * n * sizeof *tmp) : NULL;
    int sum_chunk = 1 + 16384 / (n + t->faults);
    int pieces = tf_grid_pieces(n, threads, sum_chunk);
    double *scratch = malloc((size_t)pieces * (n + 1) * sizeof *scratch);
    if (!lines || !acc || !rowbuf || (passes > 0 && !tmp) || !scratch) {
        tf_seterr(err, errlen, "fault: out of memory for a %dx%d grid", n, n);
        free(lines), free(acc), free(rowbuf), free(tmp), free(scratch);
        return -1;
    }

    fault_make_lines(lines, t->faults, n, t);
    fault_sum_ctx sc = {h, n, lines, t->faults, scratch};
    tf_grid_parallel(n, threads, sum_chunk, fault_sum_rows, &sc);
    free(scratch);

    /* Ping-pong between h and tmp; `cur` holds the latest heights. */
    float *cur = h, *other = tmp;
    for (int p = 0; p < passes; p++) {
        int four = p >= t->wind_passes;
        fault_filter(cur, other, n, t->erosion_k, four, acc, threads);
        float *swap = cur;
        cur = other;
        other = swap;
    }
    if (cur != h)
        memcpy(h, cur, (size_t)n * n * sizeof *h);

    fault_normalise(h, n, rowbuf, threads);
    free(lines), free(acc), free(rowbuf), free(tmp);
    return 0;
}
