/* test_procedural.c: procedural terrain (terrain/procedural.h, fractal_bound.h, tilecache.h,
 * render/trace_procedural.h).  Interval bounds of the noise and of every generator hold at random
 * points of random boxes, for every octave count in their range; the tile cache evicts the least
 * recently used tile, keeps its budget and its counts, and its range pyramid is exact; the surface
 * is continuous where the level of detail changes and fades the finer level in from nothing; the
 * quad-tree's bound is never below the surface on random boxes; random rays find every hit a
 * brute-force dense march of the same surface finds, and only true ones, over a noise generator
 * and over a grid with detail added; and no hit depends on the cache's budget, nor on what the
 * tracer's node memo holds from another view; and rays traced in packets get the bits each gets
 * alone. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <pthread.h>
#include <cmocka.h>
#include "terrain/fractal_bound.h"
#include "terrain/heightfield.h"
#include "terrain/procedural.h"
#include "terrain/tilecache.h"
#include "render/trace_procedural.h"

/* Build with -DPROC_SOAK=10 for 10^5 rays in test_no_missed_hits. */
#ifndef PROC_SOAK
#define PROC_SOAK 1
#endif

static uint64_t rng = 0x2545f4914f6cdd1dULL;
static double uniform(double lo, double hi)
{
    rng = tf_hash64(rng);
    return lo + (hi - lo) * (double)(rng >> 11) * 0x1.0p-53;
}

static tf_terrain terrain_of(enum tf_generator g)
{
    tf_terrain t = {0};
    t.generator = g;
    t.seed = 11;
    t.extent = 1000;
    t.height_scale = 100;
    t.feature_size = 300;
    t.octaves = 8;
    t.H = 0.8;
    t.lacunarity = 2.0;
    t.offset = g == TF_GEN_RIDGED ? 1.0 : 0.7;
    t.gain = 2.0;
    t.procedural = 1;
    return t;
}

/* ---- bounds ---------------------------------------------------------------------------------- */

static void test_noise_bound_contains(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 3);
    for (int box = 0; box < 2000; box++) {
        double size = exp(uniform(log(0.01), log(8.0)));
        double x0 = uniform(-50, 50), y0 = uniform(-50, 50), height = size * uniform(0.2, 1);
        tf_interval b = tf_noise2_bound(&nz, x0, x0 + size, y0, y0 + height);
        assert_true(b.lo <= b.hi);
        for (int k = 0; k < 50; k++) {
            double x = x0 + size * uniform(0, 1), y = y0 + height * uniform(0, 1);
            double n = tf_noise2(&nz, x, y);
            if (!(n >= b.lo && n <= b.hi))
                fail_msg("noise %.17g outside [%.17g, %.17g] at (%g, %g)", n, b.lo, b.hi, x, y);
        }
    }
}

/* f's bound over random boxes holds for every octave count in [lo, hi]. */
static void bound_holds(enum tf_generator g)
{
    tf_terrain t = terrain_of(g);
    tf_noise nz;
    tf_noise_init(&nz, t.seed);
    tf_fractal f;
    tf_octaves full;
    assert_int_equal(tf_fractal_prepare(&f, &t), 0);
    tf_fractal_bound_plan(&full, &f);
    for (int box = 0; box < 600; box++) {
        double size = exp(uniform(log(0.05), log(2000.0)));
        double x0 = uniform(-200, 1000), y0 = uniform(-200, 1000);
        double lo = uniform(1, 8), hi = uniform(lo, 8.5);
        tf_interval b = tf_fractal_bound(&f, &full, &nz, x0, x0 + size, y0, y0 + size, lo, hi);
        for (int k = 0; k < 40; k++) {
            tf_terrain at = t;
            at.octaves = uniform(lo, hi);
            tf_fractal fk;
            tf_fractal_prepare(&fk, &at);
            double x = x0 + size * uniform(0, 1), y = y0 + size * uniform(0, 1);
            double v = tf_fractal_eval(&fk, &nz, x, y);
            if (!(v >= b.lo && v <= b.hi))
                fail_msg("generator %d: %.17g outside [%.17g, %.17g] (octaves %g in [%g, %g])",
                         (int)g, v, b.lo, b.hi, at.octaves, lo, hi);
        }
    }
}

static void test_bound_fbm(void **state) { (void)state; bound_holds(TF_GEN_FBM); }
static void test_bound_hetero(void **state) { (void)state; bound_holds(TF_GEN_HETERO); }
static void test_bound_hybrid(void **state) { (void)state; bound_holds(TF_GEN_HYBRID); }
static void test_bound_ridged(void **state) { (void)state; bound_holds(TF_GEN_RIDGED); }

/* ---- the tile cache -------------------------------------------------------------------------- */

static uint64_t fills;
static uint64_t fill_by_key(void *ctx, uint64_t key, float *s)
{
    (void)ctx;
    fills++;
    for (int i = 0; i < TF_TILE_SAMPLES * TF_TILE_SAMPLES; i++)
        s[i] = (float)(key * 1000 + (uint64_t)i % 977);
    return 7; /* what the fill says it evaluated */
}

static float read_one(tf_tilecache *c, uint64_t key)
{
    float v;
    tf_tilecache_read(c, key, 3, 2, 1, 1, &v);
    return v;
}

static void test_tilecache_lru(void **state)
{
    (void)state;
    const int n = TF_TILE_CACHE_MIN_TILES;
    tf_tilecache *c = tf_tilecache_new(1, fill_by_key, NULL); /* the minimum: n tiles */
    fills = 0;
    tf_tile_counts t0 = tf_tilecache_thread_counts();
    for (int k = 0; k < n; k++)
        assert_true(read_one(c, (uint64_t)k) == (float)(k * 1000 + (2 * 33 + 3) % 977));
    read_one(c, 0);              /* 0 is now the most recent; 1 the least */
    read_one(c, (uint64_t)n);    /* evicts 1 */
    assert_int_equal(fills, n + 1);
    read_one(c, 0);              /* still there */
    assert_int_equal(fills, n + 1);
    read_one(c, 1);              /* gone: filled again, with the same values */
    assert_int_equal(fills, n + 2);
    assert_true(read_one(c, 1) == (float)(1000 + (2 * 33 + 3) % 977));
    tf_tile_counts a = tf_tilecache_totals(c), th = tf_tilecache_thread_counts();
    assert_int_equal(a.misses, n + 2);
    assert_int_equal(a.samples_evaluated, 7 * (n + 2));
    assert_int_equal(a.evictions, 2);
    assert_int_equal(a.hits, 3);
    assert_int_equal(th.misses - t0.misses, a.misses);
    assert_int_equal(th.evictions - t0.evictions, a.evictions);
    tf_tilecache_set_budget(c, 2 * (size_t)n * tf_tilecache_tile_bytes());
    for (int k = 0; k < 2 * n; k++) /* 3n tiles read into room for 2n: n more evicted */
        read_one(c, 1000 + (uint64_t)k);
    assert_int_equal(tf_tilecache_totals(c).evictions, 2 + n);
    tf_tilecache_free(c);
}

static uint64_t fill_noise(void *ctx, uint64_t key, float *s)
{
    (void)ctx;
    for (int i = 0; i < TF_TILE_SAMPLES * TF_TILE_SAMPLES; i++)
        s[i] = (float)tf_hash_unit(key * 4096 + (uint64_t)i);
    return 1;
}

static void test_tile_range_pyramid(void **state)
{
    (void)state;
    tf_tilecache *c = tf_tilecache_new(1 << 20, fill_noise, NULL);
    float all[TF_TILE_SAMPLES * TF_TILE_SAMPLES];
    tf_tilecache_read(c, 5, 0, 0, TF_TILE_SAMPLES, TF_TILE_SAMPLES, all);
    for (int k = 1; k <= 5; k++) {
        int side = TF_TILE_CELLS >> k, cells = 1 << k;
        for (int bj = 0; bj < side; bj++)
            for (int bi = 0; bi < side; bi++) {
                float lo, hi, want_lo = INFINITY, want_hi = -INFINITY;
                tf_tilecache_range(c, 5, k, bi, bj, &lo, &hi);
                for (int j = bj * cells; j <= (bj + 1) * cells; j++)
                    for (int i = bi * cells; i <= (bi + 1) * cells; i++) {
                        want_lo = fminf(want_lo, all[j * TF_TILE_SAMPLES + i]);
                        want_hi = fmaxf(want_hi, all[j * TF_TILE_SAMPLES + i]);
                    }
                assert_true(lo == want_lo && hi == want_hi);
            }
    }
    tf_tilecache_free(c);
}

/* ---- the surface ----------------------------------------------------------------------------- */

static tf_procedural *make(enum tf_generator g)
{
    char err[256];
    tf_terrain t = terrain_of(g);
    tf_procedural *p = tf_procedural_new(&t, 64 << 20, err, sizeof err);
    if (!p)
        fail_msg("%s", err);
    return p;
}

/* Detail over a 65^2 grid of rolling hills (15.6 m cells) on the same square. */
static tf_heightfield *hills;
static tf_procedural *make_over(void)
{
    enum { K = 6, N = (1 << K) + 1 };
    static float h[N * N];
    for (int j = 0; j < N; j++)
        for (int i = 0; i < N; i++)
            h[j * N + i] = (float)(40 * sin(i * 0.31) * cos(j * 0.23) + 0.5 * ((i * 7 + j * 3) % 5));
    hills = tf_heightfield_from_heights(h, K, 1000, 1);
    char err[256];
    tf_terrain t = terrain_of(TF_GEN_MIDPOINT);
    t.detail = 3;
    tf_procedural *p = tf_procedural_over(&t, hills, 64 << 20, err, sizeof err);
    if (!p)
        fail_msg("%s", err);
    return p;
}

static void free_over(tf_procedural *p)
{
    tf_procedural_free(p);
    tf_heightfield_free(hills);
    hills = NULL;
}

/* Eye over the middle; a coarse pixel so that every level appears within the square. */
static tf_proc_view view_of(const tf_procedural *p)
{
    return tf_proc_view_of(p, (tf_vec3){500, 500, 150}, 0.004);
}

/* Distance along +x from the eye where lambda falls through `target` (bisection). */
static double crossing(const tf_procedural *p, const tf_proc_view *v, double target)
{
    double near = 0, far = 5000;
    for (int it = 0; it < 200; it++) {
        double mid = 0.5 * (near + far);
        if (tf_proc_lambda(p, v, mid * mid) >= target)
            near = mid;
        else
            far = mid;
    }
    return near;
}

/* Wherever lambda crosses a whole or a half level along the x axis from the eye, h is
 * continuous; at a whole level L it is level L's own height (the finer level fades in from
 * nothing as the eye approaches). */
static void test_continuous_across_levels(void **state)
{
    (void)state;
    tf_procedural *p = make(TF_GEN_HYBRID);
    /* an eye at the west edge, and pixels coarse enough that every level is in the square */
    tf_proc_view v = tf_proc_view_of(p, (tf_vec3){20, 500, 150}, 0.03);
    const double y = 500, relief = 100, step = 1e-9; /* along the eye's own y */
    int crossings = 0;
    for (double target = 1; target < p->max_level; target += 0.5) {
        double at = crossing(p, &v, target);
        if (!(at > 1 && at < 950))
            continue;
        double in = tf_proc_height(p, &v, 20 + at - step, y);
        double out = tf_proc_height(p, &v, 20 + at + step, y);
        if (!(fabs(in - out) <= 1e-6 * relief))
            fail_msg("lambda %g: h jumps %.3g there", target, in - out);
        if (target == floor(target) &&
            !(fabs(tf_proc_height(p, &v, 20 + at, y) -
                   tf_proc_level_height(p, (int)target, 20 + at, y)) <= 1e-6 * relief))
            fail_msg("lambda %g: h is not level %g's own height there", target, target);
        crossings++;
    }
    assert_true(crossings >= 10);
    tf_procedural_free(p);
}

static void test_bound_never_below(void **state)
{
    (void)state;
    enum tf_generator gens[] = {TF_GEN_FBM, TF_GEN_HETERO, TF_GEN_HYBRID, TF_GEN_RIDGED, 0};
    for (int g = 0; g < 5; g++) {
        tf_procedural *p = g < 4 ? make(gens[g]) : make_over(); /* 4: detail over a grid */
        tf_proc_view v = view_of(p);
        for (int box = 0; box < 300; box++) {
            double size = exp(uniform(log(0.2), log(600.0)));
            double x0 = uniform(0, 1000 - size), y0 = uniform(0, 1000 - size);
            tf_interval b = tf_proc_bound(p, &v, x0, x0 + size, y0, y0 + size);
            for (int k = 0; k < 30; k++) {
                double x = x0 + size * uniform(0, 1), y = y0 + size * uniform(0, 1);
                double h = tf_proc_height(p, &v, x, y);
                if (!(h >= b.lo && h <= b.hi))
                    fail_msg("generator %d: h %.9g outside its bound [%.9g, %.9g]", g, h, b.lo,
                             b.hi);
            }
        }
        if (g < 4)
            tf_procedural_free(p);
        else
            free_over(p);
    }
}

/* ---- tracing --------------------------------------------------------------------------------- */

/* A random ray from above the surface, aimed down or across. */
static void random_ray(const tf_procedural *p, const tf_proc_view *v, tf_vec3 *o, tf_vec3 *d)
{
    double x = uniform(100, 900), y = uniform(100, 900);
    *o = (tf_vec3){x, y, tf_proc_height(p, v, x, y) + uniform(0.3, 30)};
    double a = uniform(0, 2 * M_PI);
    *d = v3_norm((tf_vec3){cos(a), sin(a), uniform(-0.7, 0.15)});
}

static double gap_at(const tf_procedural *p, const tf_proc_view *v, tf_vec3 o, tf_vec3 d,
                     double t)
{
    return o.z + t * d.z - tf_proc_height(p, v, o.x + t * d.x, o.y + t * d.y);
}

/* The first t in steps of dt where the ray is at or below the surface, or -1. */
static double brute_force(const tf_procedural *p, const tf_proc_view *v, tf_vec3 o, tf_vec3 d,
                          double tmax, double dt)
{
    for (double t = 0; t <= tmax; t += dt)
        if (gap_at(p, v, o, d, t) <= 0)
            return t;
    return -1;
}

static void no_missed_hits(tf_procedural *p)
{
    tf_proc_view v = view_of(p);
    const double tmax = 40, dt = 0.05;
    int hits = 0;
    for (int k = 0; k < 10000 * PROC_SOAK; k++) {
        tf_vec3 o, d;
        random_ray(p, &v, &o, &d);
        tf_hit hit;
        int found = tf_proc_trace(p, &v, o, d, 0, tmax, &hit);
        double tb = brute_force(p, &v, o, d, tmax, dt);
        if (tb >= 0 && !(found && hit.t <= tb + 1e-9))
            fail_msg("ray %d: the dense march crosses at t = %.9g, the tracer %s %.9g", k, tb,
                     found ? "hits only at" : "misses", found ? hit.t : 0.0);
        if (found) {
            double g = gap_at(p, &v, o, d, hit.t);
            if (!(fabs(g) <= 1e-3 * tf_proc_spacing(p, 0)))
                fail_msg("ray %d: a hit %.9g above the surface at t = %.9g", k, g, hit.t);
            if (!(hit.n.z > 0 && fabs(v3_len(hit.n) - 1) < 1e-9))
                fail_msg("ray %d: normal (%g, %g, %g)", k, hit.n.x, hit.n.y, hit.n.z);
            hits++;
            assert_true(tf_proc_occluded(p, &v, o, d, 0, tmax));
        } else {
            assert_false(tf_proc_occluded(p, &v, o, d, 0, tmax));
        }
    }
    assert_true(hits > 1000 * PROC_SOAK); /* the rays do meet the ground */
}

static void test_no_missed_hits(void **state)
{
    (void)state;
    tf_procedural *p = make(TF_GEN_HYBRID);
    no_missed_hits(p);
    tf_procedural_free(p);
}

static void test_no_missed_hits_detail_over_grid(void **state)
{
    (void)state;
    tf_procedural *p = make_over();
    no_missed_hits(p);
    /* the detail is there: level 6 (1 m spacing) differs from the grid by metres somewhere */
    double most = 0;
    for (int k = 0; k < 200; k++) {
        double x = uniform(0, 1000), y = uniform(0, 1000);
        most = fmax(most, fabs(tf_proc_level_height(p, 6, x, y) -
                               tf_heightfield_grid_height_at(hills, x, y)));
    }
    assert_true(most > 1.0);
    free_over(p);
}

/* The same rays give the same bits with the smallest cache (TF_TILE_CACHE_MIN_TILES) as with 64 MiB. */
static void test_hits_independent_of_cache(void **state)
{
    (void)state;
    tf_procedural *p = make(TF_GEN_RIDGED);
    tf_proc_view v = view_of(p);
    enum { RAYS = 3000 };
    static tf_hit big[RAYS];
    static int found[RAYS];
    uint64_t seed = rng;
    for (int k = 0; k < RAYS; k++) {
        tf_vec3 o, d;
        random_ray(p, &v, &o, &d);
        found[k] = tf_proc_trace(p, &v, o, d, 0, 200, &big[k]);
    }
    tf_procedural_set_cache(p, 1);
    tf_tile_counts before = tf_tilecache_thread_counts();
    rng = seed;
    for (int k = 0; k < RAYS; k++) {
        tf_vec3 o, d;
        tf_hit h;
        random_ray(p, &v, &o, &d);
        assert_int_equal(tf_proc_trace(p, &v, o, d, 0, 200, &h), found[k]);
        if (found[k])
            assert_memory_equal(&h, &big[k], sizeof h);
    }
    assert_true(tf_tilecache_thread_counts().evictions > before.evictions);
    tf_procedural_free(p);
}

/* Rays traced by a thread of its own, whose node memo starts empty. */
typedef struct ray_batch {
    const tf_procedural *p;
    const tf_proc_view *v;
    int n;
    const tf_vec3 *o, *d;
    tf_hit *hit;
    int *found;
} ray_batch;

static void *trace_batch(void *arg)
{
    ray_batch *b = arg;
    for (int k = 0; k < b->n; k++)
        b->found[k] = tf_proc_trace(b->p, b->v, b->o[k], b->d[k], 0, 200, &b->hit[k]);
    return NULL;
}

static void trace_in_fresh_thread(ray_batch *b)
{
    pthread_t t;
    assert_int_equal(pthread_create(&t, NULL, trace_batch, b), 0);
    assert_int_equal(pthread_join(t, NULL), 0);
}

/* A node's levels depend on the view: two views traced in turn by one thread (each node
 * remembered for one, then asked for by the other) give the bits each gives alone. */
static void test_node_memo_keyed_by_view(void **state)
{
    (void)state;
    tf_procedural *p = make(TF_GEN_FBM);
    tf_proc_view va = view_of(p), vb = tf_proc_view_of(p, (tf_vec3){300, 700, 120}, 0.002);
    enum { RAYS = 1500 };
    static tf_vec3 o[RAYS], d[RAYS];
    static tf_hit ha[RAYS], hb[RAYS];
    static int fa[RAYS], fb[RAYS];
    for (int k = 0; k < RAYS; k++)
        random_ray(p, &va, &o[k], &d[k]);
    trace_in_fresh_thread(&(ray_batch){p, &va, RAYS, o, d, ha, fa});
    trace_in_fresh_thread(&(ray_batch){p, &vb, RAYS, o, d, hb, fb});
    int differ = 0;
    for (int k = 0; k < RAYS; k++) {
        tf_hit h;
        assert_int_equal(tf_proc_trace(p, &va, o[k], d[k], 0, 200, &h), fa[k]);
        if (fa[k])
            assert_memory_equal(&h, &ha[k], sizeof h);
        assert_int_equal(tf_proc_trace(p, &vb, o[k], d[k], 0, 200, &h), fb[k]);
        if (fb[k])
            assert_memory_equal(&h, &hb[k], sizeof h);
        differ += fa[k] != fb[k] || (fa[k] && ha[k].t != hb[k].t);
    }
    assert_true(differ > RAYS / 10); /* the views do see different surfaces */
    tf_procedural_free(p);
}

/* n rays for the packet test, of every kind a packet must take as single rays take them:
 * random ones of every heading, rows of a camera's (one eye, neighbouring directions), shadow
 * rays toward one sun from points on the surface, vertical rays, rays along an axis (d.x or
 * d.y zero, of either sign), rays from below the surface. */
static void packet_rays(const tf_procedural *p, const tf_proc_view *v, int n, tf_vec3 *o,
                        tf_vec3 *d)
{
    const tf_vec3 eye = {500, 500, 150}, sun = v3_norm((tf_vec3){0.6, -0.3, 0.35});
    for (int k = 0; k < n; k++) {
        double x = uniform(100, 900), y = uniform(100, 900), h = tf_proc_height(p, v, x, y);
        switch (k % 6) {
        case 0:
            random_ray(p, v, &o[k], &d[k]);
            break;
        case 1: /* a camera row: the eye, directions a hair apart */
            o[k] = eye;
            d[k] = v3_norm((tf_vec3){cos(0.001 * k), sin(0.001 * k), -0.2});
            break;
        case 2:
            o[k] = (tf_vec3){x, y, h + 0.01};
            d[k] = sun;
            break;
        case 3:
            o[k] = (tf_vec3){x, y, h + uniform(0.1, 50)};
            d[k] = (tf_vec3){0, 0, -1};
            break;
        case 4: /* along an axis, signed zeros too */
            o[k] = (tf_vec3){x, y, h + uniform(0.1, 5)};
            d[k] = k % 4 < 2 ? (tf_vec3){k % 8 < 4 ? 0.0 : -0.0, 1, -0.05}
                             : (tf_vec3){-1, k % 8 < 4 ? 0.0 : -0.0, -0.05};
            break;
        default:
            o[k] = (tf_vec3){x, y, h - uniform(0.1, 5)};
            d[k] = v3_norm((tf_vec3){uniform(-1, 1), uniform(-1, 1), uniform(-0.2, 0.6)});
        }
    }
}

/* Packets give every ray the bits tf_proc_trace and tf_proc_occluded give it alone. */
static void test_packets_match_single_rays(void **state)
{
    (void)state;
    enum { RAYS = 1200 };
    static tf_vec3 o[RAYS], d[RAYS];
    static double tmin[RAYS], tmax[RAYS];
    static tf_hit hits[RAYS];
    static unsigned char found[RAYS], occluded[RAYS];
    for (int g = 0; g < 2; g++) {
        tf_procedural *p = make(g ? TF_GEN_RIDGED : TF_GEN_FBM);
        tf_proc_view v = view_of(p);
        packet_rays(p, &v, RAYS, o, d);
        for (int k = 0; k < RAYS; k++)
            tmin[k] = 0, tmax[k] = k % 7 ? 400 : uniform(1, 40);
        tf_proc_trace_packet(p, &v, RAYS, o, d, tmin, tmax, found, hits);
        tf_proc_occluded_packet(p, &v, RAYS, o, d, tmin, tmax, occluded);
        int hit = 0;
        for (int k = 0; k < RAYS; k++) {
            tf_hit h;
            int single = tf_proc_trace(p, &v, o[k], d[k], tmin[k], tmax[k], &h);
            assert_int_equal(found[k], single);
            if (single)
                assert_memory_equal(&hits[k], &h, sizeof h);
            assert_int_equal(occluded[k], tf_proc_occluded(p, &v, o[k], d[k], tmin[k], tmax[k]));
            hit += single;
        }
        assert_true(hit > RAYS / 4 && hit < RAYS); /* both kinds of answer were asked */
        tf_procedural_free(p);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_noise_bound_contains),
        cmocka_unit_test(test_bound_fbm),
        cmocka_unit_test(test_bound_hetero),
        cmocka_unit_test(test_bound_hybrid),
        cmocka_unit_test(test_bound_ridged),
        cmocka_unit_test(test_tilecache_lru),
        cmocka_unit_test(test_tile_range_pyramid),
        cmocka_unit_test(test_continuous_across_levels),
        cmocka_unit_test(test_bound_never_below),
        cmocka_unit_test(test_no_missed_hits),
        cmocka_unit_test(test_no_missed_hits_detail_over_grid),
        cmocka_unit_test(test_hits_independent_of_cache),
        cmocka_unit_test(test_node_memo_keyed_by_view),
        cmocka_unit_test(test_packets_match_single_rays),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
