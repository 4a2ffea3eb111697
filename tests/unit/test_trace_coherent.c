/* test_trace_coherent.c: camera rays helped by the ray below them (tf_trace_coherent,
 * common/render/trace.c "Coherence").  slope_max bounds the surface's slope and is its steepest
 * triangle; fans of rays from one origin (above the hills, outside the square, low and grazing,
 * under the surface, with a water plane's tmax) traced bottom-up, each with the record of the
 * one below (or of any other ray of the fan, or of another origin), give tf_trace's hit bit for
 * bit; and the walk does skip what a record vouches for: a record that lies hides a hit.
 * Shadow rays in rows (tf_occluded_coherent) give tf_occluded's answer with any record, and the
 * neighbour's record settles most occluded rays without a walk. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>
#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "render/trace.h"
#include "test_terrains.h"
#include "test_fans.h"

/* ---- slope_max ------------------------------------------------------------------------------ */

/* The steepest triangle by brute force, and no two points of the surface further apart in
 * height than slope_max times their horizontal distance. */
static void check_slope(height_fn f, int k, double extent)
{
    tf_heightfield *hf = make_field(f, k, extent);
    double steepest = 0;
    for (int j = 0; j < hf->cells; j++)
        for (int i = 0; i < hf->cells; i++) {
            const float *p = hf->h + (size_t)j * hf->n + i;
            double a = p[0], b = p[1], d = p[hf->n], c = p[hf->n + 1];
            double g1 = hypot(b - a, c - b) / hf->cell, g2 = hypot(c - d, d - a) / hf->cell;
            steepest = fmax(steepest, fmax(g1, g2));
        }
    assert_true(hf->slope_max >= steepest);
    assert_true(hf->slope_max <= steepest * (1 + 1e-6) + 1e-300);
    rng r = {77};
    double e = hf->cells * hf->cell;
    for (int i = 0; i < 20000; i++) {
        double x1 = range(&r, 0, e), y1 = range(&r, 0, e);
        double x2 = x1 + range(&r, -3, 3) * hf->cell, y2 = y1 + range(&r, -3, 3) * hf->cell;
        x2 = fmin(fmax(x2, 0), e), y2 = fmin(fmax(y2, 0), e);
        double dh = fabs(tf_heightfield_height_at(hf, x1, y1) -
                         tf_heightfield_height_at(hf, x2, y2));
        assert_true(dh <= hf->slope_max * hypot(x2 - x1, y2 - y1) + 1e-9);
    }
    tf_heightfield_free(hf);
}

static void test_slope_max_rough(void **state) { (void)state; check_slope(rough, 5, 100); }
static void test_slope_max_hills(void **state) { (void)state; check_slope(hills, 6, 1000); }
static void test_slope_max_terraces(void **state) { (void)state; check_slope(terraces, 6, 250); }

/* ---- fans of rays ---------------------------------------------------------------------------- */

typedef struct fan_tally { int rays, hits, vouching; } fan_tally;

/* The plain trace and the coherent one agree to the bit. */
static int check_one(const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmax,
                     const tf_ray_clear *lower, tf_ray_clear *mine)
{
    tf_hit a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    int ha = tf_trace(hf, o, d, 0.0, tmax, &a);
    int hb = tf_trace_coherent(hf, o, d, tmax, lower, &b, mine);
    if (ha != hb || (ha && memcmp(&a, &b, sizeof a) != 0))
        fail_msg("coherent trace differs: o=(%.17g,%.17g,%.17g) d=(%.17g,%.17g,%.17g) hit %d/%d "
                 "t %.17g/%.17g", o.x, o.y, o.z, d.x, d.y, d.z, ha, hb, a.t, b.t);
    return ha;
}

/* tf_trace_coherent_among with lowers[0 .. n) gives tf_trace's hit too. */
static void check_among(const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, double tmax,
                        const tf_ray_clear *const *lowers, int n)
{
    tf_hit a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    int ha = tf_trace(hf, o, d, 0.0, tmax, &a);
    int hb = tf_trace_coherent_among(hf, o, d, tmax, lowers, n, &b, NULL);
    if (ha != hb || (ha && memcmp(&a, &b, sizeof a) != 0))
        fail_msg("coherent trace among %d records differs: o=(%.17g,%.17g,%.17g) "
                 "d=(%.17g,%.17g,%.17g) hit %d/%d", n, o.x, o.y, o.z, d.x, d.y, d.z, ha, hb);
}

/* A fan (test_fans.h) traced bottom-up, each ray with the record of the one below; then
 * again, each with the record of a random other ray of the fan (higher ones vouch for nothing,
 * which must not matter either), with a record from another origin, and among a list of
 * records (NULL, another origin's, any of the fan's, the one below), as render.c asks. */
static void fan(const tf_heightfield *hf, rng *r, const ray_fan *f, fan_tally *t)
{
    tf_ray_clear rec[FAN_ROWS];
    for (int i = 0; i < FAN_ROWS; i++) {
        t->hits += check_one(hf, f->o, f->d[i], f->tmax, i ? &rec[i - 1] : NULL, &rec[i]);
        t->vouching += rec[i].s_free > 0;
        t->rays++;
    }
    tf_vec3 elsewhere = v3_add(f->o, v3(hf->cell * 0.37, 0, 0));
    for (int i = 0; i < FAN_ROWS; i++) {
        tf_ray_clear mine, other;
        check_one(hf, f->o, f->d[i], f->tmax, &rec[(int)(uni(r) * FAN_ROWS) % FAN_ROWS], &mine);
        check_one(hf, elsewhere, f->d[(i + 1) % FAN_ROWS], f->tmax, &rec[i], &other);
        const tf_ray_clear *lowers[5] = {NULL, &other, &rec[(7 * i + 3) % FAN_ROWS],
                                         &rec[(5 * i + 1) % FAN_ROWS], i ? &rec[i - 1] : NULL};
        check_among(hf, f->o, f->d[i], f->tmax, lowers, 5);
    }
}

static void fans_over(height_fn f, int k, double extent, uint64_t seed)
{
    tf_heightfield *hf = make_field(f, k, extent);
    rng r = {seed};
    fan_tally t = {0, 0, 0};
    for (int n = 0; n < 600; n++) {
        ray_fan rays;
        make_fan(hf, &r, n, &rays);
        fan(hf, &r, &rays, &t);
    }
    assert_true(t.hits > t.rays / 5);
    assert_true(t.vouching > t.rays / 5); /* plenty of records that vouch for something */
    tf_heightfield_free(hf);
}

static void test_fans_rough(void **state) { (void)state; fans_over(rough, 5, 100, 1); }
static void test_fans_hills(void **state) { (void)state; fans_over(hills, 7, 1000, 2); }
static void test_fans_terraces(void **state) { (void)state; fans_over(terraces, 6, 300, 3); }

/* ---- the skip is real ------------------------------------------------------------------------ */

/* A record that claims the ray below stayed clear far beyond where this ray hits makes the walk
 * start past the hit: the coherent trace then misses what tf_trace finds.  (The renderer never
 * makes such a record; this shows that the records are what the walk goes by.) */
static void test_a_false_record_hides_a_hit(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 6, 1000);
    tf_vec3 o = v3(500, 100, hf->hmax + 50), d = v3(0, 1, -0.3);
    tf_hit hit;
    assert_true(tf_trace(hf, o, d, 0.0, INFINITY, &hit));
    tf_ray_clear lie = {{o.x, o.y, o.z}, 0, 1, -0.31, 0, 2 * hit.t};
    assert_int_equal(tf_trace_coherent(hf, o, d, INFINITY, &lie, NULL, NULL), 0);
    /* the same record from another origin is ignored */
    lie.o[2] += 1;
    assert_int_equal(tf_trace_coherent(hf, o, d, INFINITY, &lie, NULL, NULL), 1);
    tf_heightfield_free(hf);
}

/* Among several records the walk goes by the first that vouches: a record from another origin
 * is passed over, a false one after it hides the hit; a true one before the false one is the
 * one taken, and the hit is tf_trace's. */
static void test_among_the_first_record_that_vouches_is_taken(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 6, 1000);
    tf_vec3 o = v3(500, 100, hf->hmax + 50), d = v3(0, 1, -0.3);
    tf_hit want, got;
    assert_true(tf_trace(hf, o, d, 0.0, INFINITY, &want));
    tf_ray_clear lie = {{o.x, o.y, o.z}, 0, 1, -0.31, 0, 2 * want.t}, elsewhere = lie, below;
    elsewhere.o[2] += 1;
    const tf_ray_clear *lies[3] = {NULL, &elsewhere, &lie};
    assert_int_equal(tf_trace_coherent_among(hf, o, d, INFINITY, lies, 3, NULL, NULL), 0);
    assert_int_equal(tf_trace_coherent_among(hf, o, d, INFINITY, lies, 2, NULL, NULL), 1);
    assert_true(tf_trace_coherent(hf, o, v3(0, 1, -0.35), INFINITY, NULL, NULL, &below));
    assert_true(below.s_free > 0);
    const tf_ray_clear *truth_first[2] = {&below, &lie};
    assert_true(tf_trace_coherent_among(hf, o, d, INFINITY, truth_first, 2, &got, NULL));
    assert_memory_equal(&got, &want, sizeof want);
    tf_heightfield_free(hf);
}

/* A height field with a hole (a column of NaN samples, which no loader lets through, but the
 * grids take what they are given) between a plain at 0 and a plateau at 100: every finite
 * triangle is flat, so a slope bound taken over those alone would be ~0, and the surface is not
 * continuous across the hole.  A ray passing through the hole goes under the plateau without
 * crossing it and misses; its record must not vouch for a steeper ray that meets the
 * plateau's underside.  slope_max bounds nothing there, and the coherent trace is tf_trace. */
static double plain_hole_plateau(int i, int j, int n)
{
    (void)j, (void)n;
    return i == 31 ? NAN : i < 31 ? 0.0 : 100.0;
}

static void test_a_hole_in_the_field_vouches_for_nothing(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(plain_hole_plateau, 6, 64); /* cell 1 */
    assert_false(hf->slope_max < INFINITY);
    const tf_vec3 o = v3(5, 32.5, 99.5), low = v3(1, 0, -0.001), high = v3(1, 0, 0.01);
    tf_ray_clear below;
    tf_hit hit, want;
    assert_false(tf_trace_coherent(hf, o, low, INFINITY, NULL, &hit, &below));
    assert_true(tf_trace(hf, o, high, 0.0, INFINITY, &want)); /* the underside, at x = 55 */
    assert_true(tf_trace_coherent(hf, o, high, INFINITY, &below, &hit, NULL));
    assert_memory_equal(&hit.t, &want.t, sizeof hit.t);
    tf_heightfield_free(hf);
}

/* A hit before the lower ray even enters the square is found by the prefix walk: without it
 * the walk would start where the lower ray vouches, past the hill (test_fans.h). */
static void test_the_prefix_finds_a_hit_before_the_lower_ray_enters(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(edge_hill, 7, 1000);
    tf_vec3 o, lower, upper;
    prefix_rays(&o, &lower, &upper);
    tf_hit below, plain, helped;
    tf_ray_clear rec;
    assert_true(tf_trace_coherent(hf, o, lower, INFINITY, NULL, &below, &rec));
    assert_true(rec.s_free > rec.s_in);
    assert_true(tf_trace(hf, o, upper, 0.0, INFINITY, &plain));
    assert_true(plain.t * hypot(upper.x, upper.y) < rec.s_in); /* before the lower one enters */
    assert_true(tf_trace_coherent(hf, o, upper, INFINITY, &rec, &helped, NULL));
    assert_memory_equal(&helped, &plain, sizeof plain);
    tf_heightfield_free(hf);
}

/* A plain beside a ramp of slope 1 (slope_max 1), rising from the row y = 59.  The lower ray
 * runs along the plain, over it to the square's edge; the upper one, from the same origin,
 * turns 0.05 rad toward the ramp and climbs 0.0375 per unit of run faster: less than the ramp
 * can rise under it for that turn (slope_max |u - lu| ~ 0.05), so it meets the ramp at a run of
 * ~89, well inside what the lower ray went clear over.  The proof must not vouch for it (C1's
 * D < 0); a slope term half as large would (D > 0), and the walk would skip the hit. */
static double plain_then_ramp(int i, int j, int n)
{
    (void)i, (void)n;
    return j > 59 ? j - 59.0 : 0.0;
}

static void test_a_steep_side_keeps_a_diverging_ray_unvouched(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(plain_then_ramp, 7, 128); /* cell 1 */
    const tf_vec3 o = v3(2, 58, 0.2), lower = v3(1, 0, -0.001);
    const double turn = 0.05, climb = -0.001 + 0.0375;
    const tf_vec3 upper = v3(cos(turn), sin(turn), climb);
    tf_ray_clear rec;
    tf_hit want, got;
    assert_false(tf_trace_coherent(hf, o, lower, INFINITY, NULL, &got, &rec));
    assert_true(rec.s_free > 120); /* clear to the square's edge */
    assert_true(tf_trace(hf, o, upper, 0.0, INFINITY, &want));
    assert_true(want.t * hypot(upper.x, upper.y) < 100); /* on the ramp, inside that run */
    assert_true(tf_trace_coherent(hf, o, upper, INFINITY, &rec, &got, NULL));
    assert_memory_equal(&got, &want, sizeof want);
    tf_heightfield_free(hf);
}

/* ---- shadow rays ----------------------------------------------------------------------------- */

/* Parallel rays toward a sun from points on (or, some, a hair under, or beside) the surface,
 * in rows, each with the record of the one before it, or a record that points anywhere: always
 * tf_occluded's answer; and the neighbour's record does the work for most occluded rays (their
 * record then holds one of the probed parameters rather than a walk's hit). */
static void shadow_rows(height_fn f, int k, double extent, uint64_t seed)
{
    tf_heightfield *hf = make_field(f, k, extent);
    rng r = {seed};
    const double e = hf->cells * hf->cell;
    int occluded = 0, by_probe = 0, rays = 0;
    for (int n = 0; n < 300; n++) {
        double az = range(&r, 0, 2 * M_PI), el = range(&r, 0.05, 0.8);
        tf_vec3 sun = v3(cos(az) * cos(el), sin(az) * cos(el), sin(el));
        double x = range(&r, -0.05, 1.05) * e, y = range(&r, 0, e), lift = range(&r, -0.002, 0.02);
        double dx = range(&r, -1, 1) * 0.5 * hf->cell, dy = range(&r, -1, 1) * 0.5 * hf->cell;
        tf_shadow_clear prev = {{0}, 0, {0}};
        tf_ray_dir sun_ray;
        assert_true(tf_ray_dir_init(&sun_ray, hf, sun));
        for (int i = 0; i < 40; i++, x += dx, y += dy) {
            double z = tf_heightfield_height_at(hf, x, y) + lift * (hf->hmax - hf->hmin + 1);
            tf_vec3 o = v3(x, y, z);
            tf_shadow_clear mine, any = {{sun.x, sun.y, sun.z}, range(&r, -1, 2) * e, {0}};
            int want = tf_occluded(hf, o, sun, 0.0, INFINITY);
            assert_int_equal(tf_occluded_coherent(&sun_ray, o, INFINITY, &prev, &mine), want);
            assert_int_equal(tf_occluded_coherent(&sun_ray, o, INFINITY, &any, NULL), want);
            assert_int_equal(tf_occluded_coherent(&sun_ray, o, INFINITY, NULL, NULL), want);
            double step = hf->cell / hypot(sun.x, sun.y);
            if (want && prev.t_under > 0)
                by_probe += mine.t_under == prev.t_under || mine.t_under == prev.t_under + step ||
                            mine.t_under == prev.t_under + 3 * step;
            occluded += want;
            rays++;
            assert_true(want ? mine.t_under > 0 : mine.t_under == 0);
            prev = mine;
        }
    }
    assert_true(occluded > rays / 10);
    assert_true(by_probe > occluded / 5);
    tf_heightfield_free(hf);
}

static void test_shadow_rows_hills(void **state) { (void)state; shadow_rows(hills, 7, 150, 5); }
static void test_shadow_rows_rough(void **state) { (void)state; shadow_rows(rough, 5, 100, 6); }
static void test_shadow_rows_terraces(void **state)
{
    (void)state;
    shadow_rows(terraces, 6, 300, 7);
}

/* A shadow ray the strips prove clear past a few bins is walked flat, a longer one through the
 * hierarchy (trace.c walk_occlusion): either walk, over any span, says tf_occluded's answer and
 * records tf_trace's first hit, bit for bit.  Rays leave the surface toward a low sun, with
 * ends a few cells off, some tens of cells off, past the flat walk's 64 cells, and none. */
static void occlusion_spans(height_fn f, int k, double extent, uint64_t seed, int far_hits)
{
    tf_heightfield *hf = make_field(f, k, extent);
    rng r = {seed};
    const double e = hf->cells * hf->cell;
    int hits_near = 0, hits_far = 0;
    for (int n = 0; n < 60; n++) {
        double az = range(&r, 0, 2 * M_PI), el = range(&r, 0.03, 0.5);
        tf_vec3 sun = v3(cos(az) * cos(el), sin(az) * cos(el), sin(el));
        const double t_cell = hf->cell / hypot(sun.x, sun.y); /* t per cell of run */
        const double ends[4] = {range(&r, 1, 8) * t_cell, range(&r, 10, 40) * t_cell,
                                range(&r, 70, 200) * t_cell, INFINITY};
        tf_ray_dir sun_ray;
        assert_true(tf_ray_dir_init(&sun_ray, hf, sun));
        for (int i = 0; i < 100; i++) {
            const double x = range(&r, 0, e), y = range(&r, 0, e);
            const double lift = range(&r, 0, 0.004) * (hf->hmax - hf->hmin + 1);
            const tf_vec3 o = v3(x, y, tf_heightfield_height_at(hf, x, y) + lift);
            for (int c = 0; c < 4; c++) {
                tf_shadow_clear mine;
                tf_hit want;
                int hit = tf_trace(hf, o, sun, 0.0, ends[c], &want);
                assert_int_equal(tf_occluded(hf, o, sun, 0.0, ends[c]), hit);
                assert_int_equal(tf_occluded_coherent(&sun_ray, o, ends[c], NULL, &mine), hit);
                if (hit) {
                    assert_memory_equal(&mine.t_under, &want.t, sizeof want.t);
                    hits_near += want.t < 40 * t_cell;
                    hits_far += want.t > 70 * t_cell;
                }
            }
        }
    }
    assert_true(hits_near > 200); /* both walks were asked, and found hits */
    assert_true(hits_far >= far_hits);
    tf_heightfield_free(hf);
}

static void test_occlusion_finds_the_first_hit_over_any_span_hills(void **state)
{
    (void)state;
    occlusion_spans(hills, 8, 150, 11, 20);
}

static void test_occlusion_finds_the_first_hit_over_any_span_terraces(void **state)
{
    (void)state;
    occlusion_spans(terraces, 8, 200, 12, 20);
}

static void test_occlusion_finds_the_first_hit_over_any_span_rough(void **state)
{
    (void)state;
    occlusion_spans(rough, 7, 100, 13, 0); /* its hits are all near */
}

/* Shadow rays aimed at grid vertices, so that they pass cell corners exactly: where the walk
 * meets a corner it also tests the cells sharing it (trace.c, "Rounding"), the flat walk with
 * the entry crossings it carries from the cells before.  Each direction's heading crosses
 * corners on its way (diagonals, and 2:1 slopes every other column); rays end before, at and
 * past the vertex.  tf_occluded_coherent says tf_occluded's answer and records tf_trace's
 * first hit, bit for bit. */
static void test_occlusion_through_corners(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(rough, 5, 32.0); /* cell 1: corners on whole numbers */
    const double headings[][2] = {{1, 1}, {-1, 1}, {1, -1}, {-1, -1}, {2, 1}, {-1, 2}};
    rng r = {41};
    int hits = 0, compared = 0;
    for (size_t h = 0; h < sizeof headings / sizeof headings[0]; h++)
        for (int e = 0; e < 4; e++) {
            const double run = hypot(headings[h][0], headings[h][1]), el = 0.05 + 0.2 * e;
            const tf_vec3 sun = v3(headings[h][0] / run * cos(el), headings[h][1] / run * cos(el),
                                   sin(el)); /* unit; the diagonals' |x| and |y| equal */
            tf_ray_dir sun_ray;
            assert_true(tf_ray_dir_init(&sun_ray, hf, sun));
            for (int i = 0; i < 300; i++) {
                const int vi = 4 + (int)range(&r, 0, 24), vj = 4 + (int)range(&r, 0, 24);
                const tf_vec3 v = v3(vi, vj, hf->h[(size_t)vj * hf->n + vi] + range(&r, -0.5, 0.5));
                const double s = range(&r, 1, 4) * hf->cell / hypot(sun.x, sun.y);
                const tf_vec3 o = v3_sub(v, v3_scale(sun, s)); /* o + s sun is the vertex */
                const double ends[] = {s, nextafter(s, 0), nextafter(s, INFINITY), 2 * s, INFINITY};
                for (size_t c = 0; c < sizeof ends / sizeof ends[0]; c++) {
                    tf_shadow_clear mine;
                    tf_hit want;
                    const int hit = tf_trace(hf, o, sun, 0.0, ends[c], &want);
                    assert_int_equal(tf_occluded(hf, o, sun, 0.0, ends[c]), hit);
                    assert_int_equal(tf_occluded_coherent(&sun_ray, o, ends[c], NULL, &mine), hit);
                    if (hit)
                        assert_memory_equal(&mine.t_under, &want.t, sizeof want.t), hits++;
                    compared++;
                }
            }
        }
    assert_true(hits > compared / 4 && hits < compared * 3 / 4); /* both answers, often */
    tf_heightfield_free(hf);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_slope_max_rough),
        cmocka_unit_test(test_slope_max_hills),
        cmocka_unit_test(test_slope_max_terraces),
        cmocka_unit_test(test_fans_rough),
        cmocka_unit_test(test_fans_hills),
        cmocka_unit_test(test_fans_terraces),
        cmocka_unit_test(test_a_false_record_hides_a_hit),
        cmocka_unit_test(test_among_the_first_record_that_vouches_is_taken),
        cmocka_unit_test(test_the_prefix_finds_a_hit_before_the_lower_ray_enters),
        cmocka_unit_test(test_a_steep_side_keeps_a_diverging_ray_unvouched),
        cmocka_unit_test(test_a_hole_in_the_field_vouches_for_nothing),
        cmocka_unit_test(test_shadow_rows_hills),
        cmocka_unit_test(test_shadow_rows_rough),
        cmocka_unit_test(test_shadow_rows_terraces),
        cmocka_unit_test(test_occlusion_finds_the_first_hit_over_any_span_hills),
        cmocka_unit_test(test_occlusion_through_corners),
        cmocka_unit_test(test_occlusion_finds_the_first_hit_over_any_span_terraces),
        cmocka_unit_test(test_occlusion_finds_the_first_hit_over_any_span_rough),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
