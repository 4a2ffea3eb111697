/* test_trace.c: the grid tracer (common/render/trace.c).  Analytic hits on a flat plane, a tilted plane
 * and a single spike; vertical rays land on height_at; thousands of random rays of every kind give
 * bit-identical results from tf_trace and tf_trace_flat, agree with a brute-force test of every
 * triangle, and lie on the surface; rays aimed exactly at shared edges and vertices do not slip
 * through; tmin / tmax are respected; tf_occluded agrees with tf_trace. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <float.h>
#include <cmocka.h>
#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "render/trace.h"
#include "render/constants.h"
#include "render/trace_internal.h"
#include "render/trace_math.h"
#include "test_terrains.h"

#define assert_near(a, b, tol) assert_near_at((a), (b), (tol), __FILE__, __LINE__)
static void assert_near_at(double a, double b, double tol, const char *file, int line)
{
    if (!(fabs(a - b) <= tol)) {
        print_error("%.17g != %.17g (tolerance %g)\n", a, b, tol);
        _fail(file, line);
    }
}

/* Build with -DTRACE_SOAK=100 for a long soak of the random-ray comparisons. */
#ifndef TRACE_SOAK
#define TRACE_SOAK 1
#endif

/* ---- terrains -------------------------------------------------------------------------------- */

static double flat5(int i, int j, int n) { (void)i; (void)j; (void)n; return 5; }
static double tilted(int i, int j, int n) { (void)n; return 0.5 * i - 0.25 * j + 3; }
static double spike(int i, int j, int n) { return i == n / 2 && j == n / 2 ? 10 : 0; }
/* rough, hills, terraces and make_field: test_terrains.h */

/* ---- brute force: every triangle, textbook Moller-Trumbore --------------------------------- */

static double tri_hit(tf_vec3 o, tf_vec3 d, tf_vec3 a, tf_vec3 b, tf_vec3 c, double *bary_min)
{
    tf_vec3 e1 = v3_sub(b, a), e2 = v3_sub(c, a), p = v3_cross(d, e2);
    double det = v3_dot(e1, p);
    if (det == 0)
        return INFINITY;
    tf_vec3 s = v3_sub(o, a);
    double u = v3_dot(s, p) / det;
    tf_vec3 q = v3_cross(s, e1);
    double v = v3_dot(d, q) / det;
    double w = 1 - u - v;
    *bary_min = fmin(u, fmin(v, w));
    if (u < -1e-12 || v < -1e-12 || w < -1e-12)
        return INFINITY;
    return v3_dot(e2, q) / det;
}

static tf_vec3 vertex(const tf_heightfield *hf, int i, int j)
{
    return v3(i * hf->cell, j * hf->cell, hf->h[(size_t)j * hf->n + i]);
}

/* Smallest t in (tmin, tmax); *marginal set when a hit this close to it lies on a triangle's
 * border, where rounding may legitimately decide either way. */
static double brute_force(const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmin, double tmax,
                          int *marginal)
{
    double best = INFINITY, best_bary = 1;
    for (int cj = 0; cj < hf->cells; cj++)
        for (int ci = 0; ci < hf->cells; ci++) {
            tf_vec3 a = vertex(hf, ci, cj), b = vertex(hf, ci + 1, cj);
            tf_vec3 c = vertex(hf, ci + 1, cj + 1), dd = vertex(hf, ci, cj + 1);
            double bm1, bm2;
            double t1 = tri_hit(o, d, a, b, c, &bm1), t2 = tri_hit(o, d, a, c, dd, &bm2);
            if (t1 > tmin && t1 < tmax && t1 < best)
                best = t1, best_bary = bm1;
            if (t2 > tmin && t2 < tmax && t2 < best)
                best = t2, best_bary = bm2;
        }
    *marginal = best_bary < 1e-7;
    return best;
}

/* ---- ray generators ---------------------------------------------------------------------------- */

typedef struct rng { uint64_t s; } rng;
static double uni(rng *r) { return tf_hash_unit(r->s++); }
static double range(rng *r, double lo, double hi) { return lo + (hi - lo) * uni(r); }

enum ray_kind { FROM_ABOVE, INSIDE, FROM_BELOW, GRAZING, AXIS_PARALLEL, VERTICAL, DIAGONAL, KINDS };

/* A ray of the given kind over hf; the snapping to grid lines makes many rays run exactly
 * along cell edges or through vertices. */
static void make_ray(const tf_heightfield *hf, rng *r, int kind, tf_vec3 *o, tf_vec3 *d)
{
    double e = hf->cells * hf->cell, lo = hf->hmin, hi = hf->hmax, span = hi - lo + 1;
    double snap = hf->cell * floor(range(r, 0, hf->cells + 1));
    switch (kind) {
    case FROM_ABOVE:
        *o = v3(range(r, -0.3 * e, 1.3 * e), range(r, -0.3 * e, 1.3 * e), hi + range(r, 0, 2 * span));
        *d = v3(range(r, -1, 1), range(r, -1, 1), range(r, -1, -0.05));
        break;
    case INSIDE:
        *o = v3(range(r, 0, e), range(r, 0, e), range(r, lo, hi));
        *d = v3(range(r, -1, 1), range(r, -1, 1), range(r, -1, 1));
        break;
    case FROM_BELOW:
        *o = v3(range(r, 0, e), range(r, 0, e), lo - range(r, 0, span));
        *d = v3(range(r, -1, 1), range(r, -1, 1), range(r, 0.05, 1));
        break;
    case GRAZING: /* from the side, nearly horizontal, through the height range */
        *o = v3(-0.1 * e, range(r, 0, e), range(r, lo, hi));
        *d = v3(1, range(r, -0.5, 0.5), range(r, -0.02, 0.02));
        break;
    case AXIS_PARALLEL: {
        int along_x = uni(r) < 0.5;
        double across = uni(r) < 0.5 ? snap : range(r, 0, e);
        double sgn = uni(r) < 0.5 ? 1 : -1;
        double z = range(r, lo - 0.2 * span, hi + 0.2 * span), dz = range(r, -0.3, 0.3);
        *o = along_x ? v3(sgn > 0 ? -1 : e + 1, across, z) : v3(across, sgn > 0 ? -1 : e + 1, z);
        *d = along_x ? v3(sgn, 0, dz) : v3(0, sgn, dz);
        break;
    }
    case VERTICAL: {
        double x = uni(r) < 0.3 ? snap : range(r, 0, e);
        double y = uni(r) < 0.3 ? hf->cell * floor(range(r, 0, hf->cells + 1)) : range(r, 0, e);
        int up = uni(r) < 0.3;
        *o = v3(x, y, up ? lo - 1 : hi + 1);
        *d = v3(0, 0, up ? 1 : -range(r, 0.5, 2));
        break;
    }
    default: { /* DIAGONAL: along the cell diagonals, through vertices */
        double sx = uni(r) < 0.5 ? 1 : -1, sy = uni(r) < 0.5 ? 1 : -1;
        *o = v3(snap, hf->cell * floor(range(r, 0, hf->cells + 1)), range(r, lo, hi + span));
        *d = v3(sx, sy, range(r, -0.5, 0.1));
        break;
    }
    }
}

/* ---- the random-ray comparison --------------------------------------------------------------- */

typedef struct tally { int rays, hits, marginal_skips; } tally;

/* tf_trace and tf_trace_flat agree bit for bit, tf_occluded agrees, hits lie on the surface,
 * and the brute force finds the same first hit. */
static void check_ray(const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmin, double tmax,
                      int brute, tally *tl)
{
    tf_hit a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    int ha = tf_trace(hf, o, d, tmin, tmax, &a), hb = tf_trace_flat(hf, o, d, tmin, tmax, &b);
    if (ha != hb || (ha && memcmp(&a, &b, sizeof a) != 0))
        fail_msg("trace/flat differ: o=(%.17g,%.17g,%.17g) d=(%.17g,%.17g,%.17g) hit %d/%d "
                 "t %.17g/%.17g cell (%d,%d)/(%d,%d)", o.x, o.y, o.z, d.x, d.y, d.z, ha, hb,
                 a.t, b.t, a.ci, a.cj, b.ci, b.cj);
    assert_int_equal(tf_occluded(hf, o, d, tmin, tmax), ha);
    tl->rays++;
    double scale = hf->hmax - hf->hmin + 1;
    if (ha) {
        tl->hits++;
        assert_true(a.t > tmin && a.t < tmax);
        assert_near(a.p.z, tf_heightfield_height_at(hf, a.p.x, a.p.y), 1e-7 * scale);
        assert_near(a.p.x, o.x + a.t * d.x, 0);
        assert_true(a.n.z > 0);
        assert_near(v3_len(a.n), 1, 1e-12);
        /* the reported cell contains the hit point (up to rounding) */
        assert_true(a.p.x >= a.ci * hf->cell - 1e-6 && a.p.x <= (a.ci + 1) * hf->cell + 1e-6);
        assert_true(a.p.y >= a.cj * hf->cell - 1e-6 && a.p.y <= (a.cj + 1) * hf->cell + 1e-6);
    }
    if (brute) {
        int marginal;
        double tb = brute_force(hf, o, d, tmin, tmax, &marginal);
        double tt = ha ? a.t : INFINITY;
        int same = (isinf(tb) && isinf(tt)) || fabs(tb - tt) <= 1e-7 * (1 + fabs(tb));
        if (!same && marginal)
            tl->marginal_skips++;
        else if (!same)
            fail_msg("brute force disagrees: o=(%.17g,%.17g,%.17g) d=(%.17g,%.17g,%.17g) "
                     "trace %.17g brute %.17g", o.x, o.y, o.z, d.x, d.y, d.z, tt, tb);
    }
}

static void random_rays(tf_heightfield *hf, int per_kind, int brute_every, uint64_t seed)
{
    rng r = {seed};
    tally tl = {0, 0, 0};
    for (int kind = 0; kind < KINDS; kind++) {
        int hits_before = tl.hits;
        for (int i = 0; i < per_kind * TRACE_SOAK; i++) {
            tf_vec3 o, d;
            make_ray(hf, &r, kind, &o, &d);
            check_ray(hf, o, d, 0, INFINITY, i % brute_every == 0, &tl);
        }
        /* every kind of ray does meet the terrain sometimes */
        assert_true(tl.hits > hits_before);
    }
    assert_true(tl.marginal_skips * 100 <= tl.rays); /* border cases are rare */
    tf_heightfield_free(hf);
}

static void test_random_rays_rough(void **state)
{
    (void)state;
    random_rays(make_field(rough, 5, 32.0), 400, 4, 1);
}

static void test_random_rays_hills(void **state)
{
    (void)state;
    random_rays(make_field(hills, 6, 640.0), 400, 8, 2);
}

static void test_random_rays_terraces(void **state)
{
    (void)state;
    random_rays(make_field(terraces, 6, 64.0), 400, 8, 3);
}

/* Off-centre placement and an extent that is not a power of two. */
static void test_random_rays_odd_extent(void **state)
{
    (void)state;
    random_rays(make_field(hills, 4, 7.3), 300, 3, 4);
}

/* ---- analytic cases ---------------------------------------------------------------------------- */

static void test_flat_plane(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(flat5, 4, 16.0);
    tf_hit h;
    assert_true(tf_trace(hf, v3(10.3, 7.1, 20), v3(0.3, -0.2, -1), 0, INFINITY, &h));
    assert_near(h.t, 15, 1e-12);
    assert_near(h.p.x, 14.8, 1e-12);
    assert_near(h.p.y, 4.1, 1e-12);
    assert_near(h.p.z, 5, 1e-12);
    assert_near(h.n.z, 1, 1e-15);
    assert_int_equal(h.ci, 14);
    assert_int_equal(h.cj, 4);
    /* from below, the underside */
    assert_true(tf_trace(hf, v3(3.3, 2.2, -1), v3(0.1, 0.1, 2), 0, INFINITY, &h));
    assert_near(h.t, 3, 1e-12);
    /* tmax just short of / past the hit */
    assert_false(tf_trace(hf, v3(10.3, 7.1, 20), v3(0.3, -0.2, -1), 0, 14.9, &h));
    assert_true(tf_trace(hf, v3(10.3, 7.1, 20), v3(0.3, -0.2, -1), 0, 15.1, &h));
    assert_false(tf_trace(hf, v3(10.3, 7.1, 20), v3(0.3, -0.2, -1), 15.1, INFINITY, &h));
    /* rays that miss: upward, parallel above, beside the square, pointing away, zero dir */
    assert_false(tf_trace(hf, v3(8, 8, 6), v3(0.2, 0.1, 1), 0, INFINITY, &h));
    assert_false(tf_trace(hf, v3(-4, 8, 6), v3(1, 0, 0), 0, INFINITY, &h));
    assert_false(tf_trace(hf, v3(20, 8, 6), v3(0, 1, -1), 0, INFINITY, &h));
    assert_false(tf_trace(hf, v3(-4, 8, 6), v3(-1, 0, -1), 0, INFINITY, &h));
    assert_false(tf_trace(hf, v3(8, 8, 6), v3(0, 0, 0), 0, INFINITY, &h));
    /* a ray from outside the square that comes down inside it */
    assert_true(tf_trace(hf, v3(-4, -4, 9), v3(1, 1, -0.5), 0, INFINITY, &h));
    assert_near(h.t, 8, 1e-12);
    tf_heightfield_free(hf);
}

static void test_tilted_plane(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(tilted, 4, 16.0); /* z = 0.5 x - 0.25 y + 3, cell = 1 */
    rng r = {77};
    tf_vec3 n_expect = v3_norm(v3(-0.5, 0.25, 1));
    for (int s = 0; s < 300; s++) {
        tf_vec3 o = v3(range(&r, 0, 16), range(&r, 0, 16), range(&r, 12, 30));
        tf_vec3 d = v3(range(&r, -1, 1), range(&r, -1, 1), range(&r, -1, -0.2));
        double t = (0.5 * o.x - 0.25 * o.y + 3 - o.z) / (d.z - 0.5 * d.x + 0.25 * d.y);
        tf_vec3 p = v3_add(o, v3_scale(d, t));
        tf_hit h;
        int inside = p.x >= 0 && p.x <= 16 && p.y >= 0 && p.y <= 16;
        int hit = tf_trace(hf, o, d, 0, INFINITY, &h);
        if (!inside)
            continue; /* it may or may not clip the plane's edge elsewhere */
        assert_true(hit);
        assert_near(h.t, t, 1e-9 * t);
        assert_near(h.n.x, n_expect.x, 1e-12);
        assert_near(h.n.y, n_expect.y, 1e-12);
        assert_near(h.n.z, n_expect.z, 1e-12);
    }
    tf_heightfield_free(hf);
}

static void test_spike(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(spike, 4, 16.0); /* apex (8, 8, 10), zero elsewhere */
    tf_hit h;
    /* straight down onto the apex, and up into it from below */
    assert_true(tf_trace(hf, v3(8, 8, 30), v3(0, 0, -1), 0, INFINITY, &h));
    assert_near(h.t, 20, 1e-12);
    assert_true(tf_trace(hf, v3(8, 8, -5), v3(0, 0, 1), 0, INFINITY, &h));
    assert_near(h.t, 15, 1e-12);
    /* aimed exactly at the apex from the -x side: the face only meets the ray there */
    assert_true(tf_trace(hf, v3(0, 8, 20), v3(8, 0, -10), 0, INFINITY, &h));
    assert_near(h.t, 1, 1e-12);
    assert_true(tf_trace_flat(hf, v3(0, 8, 20), v3(8, 0, -10), 0, INFINITY, &h));
    assert_near(h.t, 1, 1e-12);
    /* and from the diagonal direction (through the vertices on the way) */
    assert_true(tf_trace(hf, v3(2, 2, 25), v3(6, 6, -15), 0, INFINITY, &h));
    assert_near(h.t, 1, 1e-12);
    /* horizontal just above the apex misses, just below hits the front face */
    assert_false(tf_trace(hf, v3(0, 8, 10 + 1e-9), v3(1, 0, 0), 0, INFINITY, &h));
    assert_true(tf_trace(hf, v3(0, 8.25, 7), v3(1, 0, 0), 0, INFINITY, &h));
    assert_near(h.p.x, 7.95, 1e-12); /* cell (7, 8), lower triangle: z = 10 (u - v) */
    /* along the grid line y = 8 at half height: in at x = 7.5, out (underside) at x = 8.5 */
    assert_true(tf_trace(hf, v3(0, 8, 5), v3(1, 0, 0), 0, INFINITY, &h));
    assert_near(h.t, 7.5, 1e-12);
    assert_true(tf_trace(hf, v3(0, 8, 5), v3(1, 0, 0), 7.6, INFINITY, &h));
    assert_near(h.t, 8.5, 1e-12);
    assert_false(tf_trace(hf, v3(0, 8, 5), v3(1, 0, 0), 8.6, INFINITY, &h));
    assert_false(tf_trace(hf, v3(0, 8, 5), v3(1, 0, 0), 0, 7.4, &h));
    assert_int_equal(tf_occluded(hf, v3(0, 8, 5), v3(1, 0, 0), 0, 7.6), 1);
    assert_int_equal(tf_occluded(hf, v3(0, 8, 5), v3(1, 0, 0), 0, 7.4), 0);
    tf_heightfield_free(hf);
}

/* A vertical ray down onto (x, y) lands at height_at(x, y): the tracer and height_at agree on
 * the triangles, including exactly on edges, diagonals and vertices. */
static void test_vertical_rays_land_on_height_at(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(rough, 5, 32.0); /* cell = 1 */
    rng r = {5};
    for (int s = 0; s < 2000; s++) {
        double x = range(&r, 0, 32), y = range(&r, 0, 32);
        switch (s % 4) {
        case 1: x = floor(x); break;               /* on a column line */
        case 2: x = floor(x); y = floor(y); break; /* on a vertex */
        case 3: y = floor(y) + (x - floor(x)); break; /* on a diagonal */
        }
        tf_hit a, b;
        assert_true(tf_trace(hf, v3(x, y, 100), v3(0, 0, -1), 0, INFINITY, &a));
        assert_true(tf_trace_flat(hf, v3(x, y, 100), v3(0, 0, -1), 0, INFINITY, &b));
        assert_true(a.t == b.t);
        double z = tf_heightfield_height_at(hf, x, y);
        assert_near(a.p.z, z, 1e-12);
        assert_true(a.p.x == x && a.p.y == y);
    }
    tf_heightfield_free(hf);
}

/* Rays aimed exactly at points of shared edges, diagonals and vertices, from every direction.
 * Each starts above the terrain over the square and is below the surface just past its target,
 * so it crosses the surface no later than that: nothing may slip between triangles.  (Targets
 * where the ray only touches a ridge or crease are tangent cases and are skipped.) */
static void test_watertight_at_edges_and_vertices(void **state)
{
    (void)state;
    height_fn fields[] = {rough, hills, terraces};
    for (int f = 0; f < 3; f++) {
        tf_heightfield *hf = make_field(fields[f], 4, f == 1 ? 160.0 : 16.0);
        rng r = {100 + (uint64_t)f};
        const double c = hf->cell, e = hf->cells * c;
        int tested = 0, tangent = 0;
        for (int s = 0; s < 4000; s++) {
            int i = (int)range(&r, 1, hf->cells - 1), j = (int)range(&r, 1, hf->cells - 1);
            tf_vec3 target;
            switch (s % 4) {
            case 0: target = vertex(hf, i, j); break;
            case 1: target = v3_lerp(vertex(hf, i, j), vertex(hf, i + 1, j), 0.5); break;
            case 2: target = v3_lerp(vertex(hf, i, j), vertex(hf, i, j + 1), 0.25); break;
            default: target = v3_lerp(vertex(hf, i, j), vertex(hf, i + 1, j + 1), 0.5); break;
            }
            /* From a random point above the terrain over the square; one in five from a point
             * exactly along a grid axis or diagonal through the target. */
            tf_vec3 o = v3(range(&r, 0, e), range(&r, 0, e), hf->hmax + range(&r, 0.1, 2) * c);
            if (s % 5 == 0) {
                static const double ox[8] = {1, 1, 0, -1, -1, -1, 0, 1};
                static const double oy[8] = {0, 1, 1, 1, 0, -1, -1, -1};
                int oct = (int)range(&r, 0, 8);
                double m = floor(range(&r, 1, 4)) * c;
                o.x = target.x + m * ox[oct];
                o.y = target.y + m * oy[oct];
            }
            if (o.x < 0 || o.x > e || o.y < 0 || o.y > e)
                continue;
            tf_vec3 d = v3_sub(target, o);
            tf_vec3 past = v3_add(o, v3_scale(d, 1 + 1e-6));
            if (!(past.z < tf_heightfield_height_at(hf, past.x, past.y) - 1e-9)) {
                tangent++;
                continue;
            }
            tested++;
            tf_hit a, b;
            int ha = tf_trace(hf, o, d, 0, INFINITY, &a);
            int hb = tf_trace_flat(hf, o, d, 0, INFINITY, &b);
            if (!ha || a.t > 1 + 1e-6)
                fail_msg("slipped through: field %d target (%.17g,%.17g,%.17g) o=(%.17g,%.17g,%.17g) "
                         "hit %d t %.17g", f, target.x, target.y, target.z, o.x, o.y, o.z, ha, a.t);
            assert_true(hb && a.t == b.t && a.ci == b.ci && a.cj == b.cj);
        }
        assert_true(tested > 1000 && tangent < tested);
        tf_heightfield_free(hf);
    }
}

/* Any ray that starts above the terrain over the square and ends below it over the square
 * hits: here along grid lines and diagonals, where cells meet. */
static void test_no_leak_along_grid_lines(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(rough, 4, 16.0);
    for (int j = 0; j <= hf->cells; j++)
        for (int q = 0; q < 8; q++) {
            double x0 = q * 2.0 + 0.5, slope = -(q + 1) * 3.0;
            tf_vec3 dirs[4] = {v3(1, 0, slope / 16), v3(-1, 0, slope / 16), v3(1, 1, slope / 16),
                               v3(1, -1, slope / 16)};
            for (int k = 0; k < 4; k++) {
                tf_vec3 o = v3(k == 1 ? 16 - x0 : x0, j, hf->hmax + 0.5);
                double t_end = (hf->hmin - 0.5 - o.z) / dirs[k].z;
                tf_vec3 end = v3_add(o, v3_scale(dirs[k], t_end));
                if (end.x < 0 || end.x > 16 || end.y < 0 || end.y > 16)
                    continue;
                tf_hit a;
                assert_true(tf_trace(hf, o, dirs[k], 0, t_end, &a));
                assert_true(tf_trace_flat(hf, o, dirs[k], 0, t_end, &a));
            }
        }
    tf_heightfield_free(hf);
}

/* tmin / tmax on random rays: the hit with a window starting just past the first hit is the
 * next one, and a window ending before the first hit sees nothing. */
static void test_tmin_tmax_windows(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 5, 320.0);
    rng r = {9};
    tally tl = {0, 0, 0};
    int second_hits = 0;
    for (int s = 0; s < 500; s++) {
        tf_vec3 o, d;
        make_ray(hf, &r, s % 2 ? GRAZING : INSIDE, &o, &d);
        tf_hit h;
        if (!tf_trace(hf, o, d, 0, INFINITY, &h))
            continue;
        check_ray(hf, o, d, 0, h.t * (1 - 1e-9), 1, &tl);
        assert_false(tf_trace(hf, o, d, 0, h.t * (1 - 1e-9), NULL));
        assert_false(tf_occluded(hf, o, d, 0, h.t * (1 - 1e-9)));
        double after = h.t * (1 + 1e-9) + 1e-9;
        tf_hit g;
        check_ray(hf, o, d, after, INFINITY, 1, &tl);
        if (tf_trace(hf, o, d, after, INFINITY, &g)) {
            assert_true(g.t > after);
            second_hits++;
        }
        /* a window around the hit still finds it */
        tf_hit w;
        assert_true(tf_trace(hf, o, d, h.t * 0.5, h.t * 1.5 + 1, &w));
        assert_true(w.t == h.t);
    }
    assert_true(second_hits > 10);
    tf_heightfield_free(hf);
}

/* Occlusion walks skip a cell's triangle tests where the ray is above both their planes by the
 * margin (trace.c, "The plane test"): rays that skim a surface -- down a tilted plane at a
 * hair's slope into it, and over rough ground from points on it, the way shadow rays leave --
 * are occluded exactly where tf_trace (which tests every cell) finds a hit. */
static void test_occlusion_skims_a_surface_like_a_trace(void **state)
{
    (void)state;
    tf_heightfield *plane = make_field(tilted, 5, 32.0), *ground = make_field(rough, 5, 320.0);
    rng r = {33};
    int hits = 0, rays = 0;
    for (int s = 0; s < 4000; s++) {
        tf_heightfield *hf = s % 2 ? plane : ground;
        const double e = hf->cells * hf->cell, span = hf->hmax - hf->hmin + 1;
        const double x = range(&r, 0.05, 0.95) * e, y = range(&r, 0.05, 0.95) * e;
        const double az = range(&r, 0, 2 * M_PI), dx = cos(az), dy = sin(az);
        /* the surface's slope along the heading, from two nearby heights */
        const double step = 1e-3 * hf->cell;
        const double slope = (tf_heightfield_height_at(hf, x + step * dx, y + step * dy) -
                              tf_heightfield_height_at(hf, x, y)) / step;
        const double lift = (s % 5) * 1e-9 * span * range(&r, 0, 1);
        const double skim = slope + (s % 3 - 1) * range(&r, 0, 1) * pow(10, -range(&r, 2, 9));
        const tf_vec3 o = v3(x, y, tf_heightfield_height_at(hf, x, y) + lift);
        const tf_vec3 d = v3(dx, dy, skim);
        const int want = tf_trace(hf, o, d, 0, INFINITY, NULL);
        assert_int_equal(tf_occluded(hf, o, d, 0, INFINITY), want);
        hits += want, rays++;
    }
    assert_true(hits > rays / 5 && hits < rays * 4 / 5);
    tf_heightfield_free(plane);
    tf_heightfield_free(ground);
}

/* The box as tf_clip_slab (trace_math.h) gives it, slab by slab as setup_ray clips: 0 where
 * the ray misses it (or the window is empty). */
static int box_by_clip_slab(const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmin,
                            double tmax, double *t_square, double *t0, double *t1)
{
    const double top = hf->cells * hf->cell;
    const double zpad = tf_box_zpad(hf->hmin, hf->hmax, o.z);
    *t0 = tmin, *t1 = tmax;
    if (!(tmin < tmax) || !tf_clip_slab(o.x, d.x, 0, top, t0, t1) || !tf_clip_slab(o.y, d.y, 0, top, t0, t1))
        return 0;
    *t_square = *t0;
    return tf_clip_slab(o.z, d.z, hf->hmin - zpad, hf->hmax + zpad, t0, t1) && isfinite(*t0) &&
           isfinite(*t1);
}

/* Two walk contexts alike bit for bit (every field a walk reads). */
static void assert_same_ctx(const tf_ray_ctx *a, const tf_ray_ctx *b)
{
    const double da[] = {a->o[0], a->o[1], a->o[2], a->d[0], a->d[1], a->d[2], a->inv_dx,
                         a->inv_dy, a->tmin, a->tmax, a->t0, a->t1, a->t_square, a->margin,
                         a->tie_tol, a->inv_cell, a->shx, a->shy, a->shz};
    const double db[] = {b->o[0], b->o[1], b->o[2], b->d[0], b->d[1], b->d[2], b->inv_dx,
                         b->inv_dy, b->tmin, b->tmax, b->t0, b->t1, b->t_square, b->margin,
                         b->tie_tol, b->inv_cell, b->shx, b->shy, b->shz};
    for (size_t i = 0; i < sizeof da / sizeof da[0]; i++)
        if (memcmp(&da[i], &db[i], sizeof da[i]) != 0)
            fail_msg("field %zu: %.17g != %.17g", i, da[i], db[i]);
    const int ia[] = {a->sx, a->sy, a->ci, a->cj, a->kx, a->ky, a->kz};
    const int ib[] = {b->sx, b->sy, b->ci, b->cj, b->kx, b->ky, b->kz};
    assert_memory_equal(ia, ib, sizeof ia);
    assert_ptr_equal(a->hf, b->hf);
}

/* The setup's box is tf_clip_slab's, bit for bit, and a shared direction's setup (tf_ray_dir:
 * no division where a product proves the box's exit beyond tmax) is tf_trace_setup's, field
 * for field: rays of every kind, windows starting below, at and above
 * 0, and tmax at each exit of the box, an ulp either side of it, and a hair beyond it, where a
 * loose proof would keep tmax in place of the exit. */
static void test_shared_direction_setup_is_the_rays_own(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 5, 320.0);
    const double top = hf->cells * hf->cell;
    rng r = {21};
    int compared = 0, beyond = 0;
    for (int s = 0; s < 3000; s++) {
        tf_vec3 o, d;
        make_ray(hf, &r, s % KINDS, &o, &d);
        if (s % 3 == 0) /* from inside the box, where the shortcut applies */
            o = v3(range(&r, 0, top), range(&r, 0, top), range(&r, hf->hmin, hf->hmax));
        tf_ray_dir dir;
        assert_true(tf_ray_dir_init(&dir, hf, d));
        const double pad = 1e-9 * (fabs(hf->hmin) + fabs(hf->hmax) + fabs(o.z) +
                                   (hf->hmax - hf->hmin)) + DBL_MIN; /* tf_box_zpad */
        const double ov[3] = {o.x, o.y, o.z}, dv[3] = {d.x, d.y, d.z};
        const double lo[3] = {0, 0, hf->hmin - pad}, hi[3] = {top, top, hf->hmax + pad};
        for (int a = 0; a < 3; a++) {
            if (dv[a] == 0)
                continue;
            const double exit = ((dv[a] > 0 ? hi[a] : lo[a]) - ov[a]) / dv[a];
            const double tmaxes[] = {exit, nextafter(exit, INFINITY), nextafter(exit, 0),
                                     exit * (1 + 1e-13), exit * (1 + 1e-10), exit * 0.5,
                                     exit * 2, TF_FAR_AWAY, INFINITY};
            const double tmins[] = {0, -1, 0.25 * exit};
            for (size_t i = 0; i < sizeof tmaxes / sizeof tmaxes[0]; i++)
                for (size_t j = 0; j < sizeof tmins / sizeof tmins[0]; j++) {
                    tf_ray_ctx want, got;
                    double ts, t0, t1;
                    const int w = tf_trace_setup(&want, hf, o, d, tmins[j], tmaxes[i]);
                    assert_int_equal(box_by_clip_slab(hf, o, d, tmins[j], tmaxes[i], &ts, &t0,
                                                      &t1), w);
                    assert_int_equal(tf_trace_setup_dir(&got, &dir, o, tmins[j], tmaxes[i]), w);
                    if (w) {
                        assert_memory_equal(&want.t_square, &ts, sizeof ts);
                        assert_memory_equal(&want.t0, &t0, sizeof t0);
                        assert_memory_equal(&want.t1, &t1, sizeof t1);
                        assert_same_ctx(&got, &want), compared++;
                    }
                    beyond += w && exit > 0 && tmaxes[i] > exit && tmaxes[i] < exit * 1.01;
                }
        }
    }
    assert_true(compared > 20000);
    assert_true(beyond > 2000);
    tf_heightfield_free(hf);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_flat_plane),
        cmocka_unit_test(test_tilted_plane),
        cmocka_unit_test(test_spike),
        cmocka_unit_test(test_vertical_rays_land_on_height_at),
        cmocka_unit_test(test_watertight_at_edges_and_vertices),
        cmocka_unit_test(test_no_leak_along_grid_lines),
        cmocka_unit_test(test_tmin_tmax_windows),
        cmocka_unit_test(test_shared_direction_setup_is_the_rays_own),
        cmocka_unit_test(test_occlusion_skims_a_surface_like_a_trace),
        cmocka_unit_test(test_random_rays_rough),
        cmocka_unit_test(test_random_rays_hills),
        cmocka_unit_test(test_random_rays_terraces),
        cmocka_unit_test(test_random_rays_odd_extent),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
