/* test_sun_strips.c: the sun's strips (render/sun_strips.h, render/sun_math.h).  Their table
 * bounds the surface from above and below as the query assumes (checked against the surface
 * itself at random points); a shadow ray the strips prove occluded is, and one whose walk ends
 * where they prove it clear gives tf_occluded's answer over the whole ray, for suns from every
 * heading (the axes and the diagonals too) and elevation, from points on, over, under and
 * beside the surface; the strips do prove most lit rays clear and many occluded ones occluded;
 * a table that lies changes answers (so the comparison can fail); and no strips are made where
 * they cannot help.  An occluder far down the strip is proved as cheaply as a near one. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>
#include "render/constants.h"
#include "render/sun_strips.h"
#include "render/trace.h"
#include "terrain/heightfield.h"
#include "test_terrains.h"

typedef struct rng { uint64_t s; } rng;
static double uni(rng *r) { return tf_hash_unit(r->s++); }
static double range(rng *r, double lo, double hi) { return lo + (hi - lo) * uni(r); }

static tf_vec3 sun_at(double az, double el)
{
    return v3(cos(az) * cos(el), sin(az) * cos(el), sin(el));
}

/* ---- the table ------------------------------------------------------------------------------ */

/* The bin that gives sink[b]: the last one whose sink is still sink[b] (-1: none). */
static int named_bin(const tf_sun_frame *f, const float *row, int b)
{
    if (!(row[TF_SUN_BIN * b + 1] > -INFINITY))
        return -1;
    int c = b;
    while (c + 1 < f->bins && row[TF_SUN_BIN * (c + 1) + 1] >= row[TF_SUN_BIN * b + 1])
        c++;
    return c;
}

/* At random points q of the square: in q's strip, the reach of q's bin b is at least
 * f(q) - climb * (bin b's start) and never grows toward the sun; and wherever the sink of a bin
 * b' <= b is given by bin b, it is at most f(q) - climb * (bin b's end) -- what the query's
 * proofs read off the table (a ray is lowest in a bin where it enters it, highest where it
 * leaves).  Sinks never grow toward the sun either, and the bin giving one lies inside the
 * square. */
static int check_sinks(const tf_sun_frame *f, const float *row, int bq, double x, double y,
                       double h)
{
    int checked = 0;
    assert_true(row[TF_SUN_BIN * (bq - 1) + 1] >= row[TF_SUN_BIN * bq + 1]);
    for (int b = bq; b >= 0 && named_bin(f, row, b) == bq; b--, checked++) {
        const double most = h - f->climb * (f->along0 + (bq + 1) * f->ds);
        if (!(row[TF_SUN_BIN * b + 1] <= most))
            fail_msg("sink[%d] = %.9g (bin %d) over the surface's %.9g at (%.9g, %.9g)", b,
                     (double)row[TF_SUN_BIN * b + 1], bq, most, x, y);
    }
    return checked;
}

/* Every bin that gives a sink lies inside the square: its corners do. */
static void check_named_inside(const tf_sun_strips *s, const tf_heightfield *hf)
{
    const tf_sun_frame *f = &s->frame;
    const double e = hf->cells * hf->cell, ux = f->a_s * hf->cell, uy = f->b_s * hf->cell;
    for (int k = 0; k < f->strips; k++)
        for (int b = 0; b < f->bins; b++) {
            const float *row = s->table + TF_SUN_BIN * (size_t)k * f->bins;
            const int at = named_bin(f, row, b);
            if (at >= 0) /* the query's halving finds what the walk along the row finds */
                assert_int_equal(tf_sun_sink_bin(f, row, b, row[TF_SUN_BIN * b + 1]), at);
            for (int c = 0; at >= 0 && c < 4; c++) {
                const double al = (f->along0 + (at + (c & 1)) * f->ds) * hf->cell;
                const double ac = (f->across0 + (k + (c >> 1)) / f->inv_w) * hf->cell;
                const double cx = ux * al - uy * ac, cy = uy * al + ux * ac;
                assert_true(cx >= 0 && cx <= e && cy >= 0 && cy <= e);
            }
        }
}

static void check_bound(height_fn fn, int k, double extent, tf_vec3 sun, uint64_t seed)
{
    tf_heightfield *hf = make_field(fn, k, extent);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun);
    assert_non_null(s);
    const tf_sun_frame *f = &s->frame;
    const double e = hf->cells * hf->cell;
    rng r = {seed};
    int sinks = 0;
    for (int i = 0; i < 20000; i++) {
        const double x = range(&r, 0, e), y = range(&r, 0, e);
        const double along = f->a_s * x + f->b_s * y, across = f->a_p * x + f->b_p * y;
        const int kq = (int)floor((across - f->across0) * f->inv_w);
        const int bq = (int)floor((along - f->along0) * f->inv_ds);
        assert_true(kq >= 0 && kq < f->strips && bq >= 1 && bq < f->bins);
        const float *row = s->table + TF_SUN_BIN * (size_t)kq * f->bins;
        const double h = tf_heightfield_height_at(hf, x, y);
        const double need = h - f->climb * (f->along0 + bq * f->ds);
        if (!(row[TF_SUN_BIN * bq] >= need))
            fail_msg("reach[%d][%d] = %.9g under the surface's %.9g at (%.9g, %.9g)", kq, bq,
                     (double)row[TF_SUN_BIN * bq], need, x, y);
        assert_true(row[TF_SUN_BIN * (bq - 1)] >= row[TF_SUN_BIN * bq]);
        sinks += check_sinks(f, row, bq, x, y, h);
    }
    assert_true(sinks > 100); /* the sink bound was checked, not skipped */
    check_named_inside(s, hf);
    tf_sun_strips_free(s);
    tf_heightfield_free(hf);
}

static void test_bound_hills(void **state)
{
    (void)state;
    check_bound(hills, 7, 150, sun_at(0.7, 0.3), 1);
    check_bound(hills, 7, 150, sun_at(M_PI, 0.1), 2); /* along -x: an axis */
}

static void test_bound_rough(void **state)
{
    (void)state;
    check_bound(rough, 6, 100, sun_at(-M_PI / 4, 0.5), 3); /* a diagonal */
    check_bound(rough, 6, 100, sun_at(M_PI / 2, 0.05), 4); /* along +y, low */
}

/* ---- shadow rays ------------------------------------------------------------------------------ */

typedef struct tally { int rays, lit, proved_lit, occluded, proved_under; } tally;

/* The point an occluded ray's record names when a neighbour asks (tf_sun_strips_named). */
static double named_point(const tf_sun_strips *s, tf_vec3 o)
{
    const tf_shadow_clear rec = tf_sun_strips_under_record(s, o), *plain = NULL;
    tf_shadow_clear named;
    assert_true(rec.t_under < 0);
    assert_ptr_equal(tf_sun_strips_named(s, plain, &named), NULL);
    const tf_shadow_clear *got = tf_sun_strips_named(s, &rec, &named);
    assert_ptr_equal(got, &named);
    assert_memory_equal(named.d, rec.d, sizeof rec.d);
    assert_ptr_equal(tf_sun_strips_named(s, got, &named), got); /* a named record is kept */
    return got->t_under;
}

/* One shadow ray: occluded where the strips prove it (the point its record names under the
 * surface), and the walk ended where they prove it clear answers as the whole ray. */
static void check_ray(const tf_heightfield *hf, const tf_sun_strips *s, tf_vec3 o, tf_vec3 sun,
                      tally *t)
{
    const int want = tf_occluded(hf, o, sun, 0.0, TF_FAR_AWAY);
    double at = -1;
    const int said = tf_sun_strips_shadow(s, o, &at);
    double named = -1; /* the query that names an occluded ray's point: the same answer */
    assert_int_equal(tf_sun_strips_say(&s->frame, s->table, s->h, o.x, o.y, o.z, 1, &named),
                     said);
    if (said == TF_SUN_UNDER) {
        assert_true(at == 0);
        at = named_point(s, o);
        assert_true(at == named && at > 0);
    } else if (said == TF_SUN_CLEAR_AFTER) {
        assert_true(named == at);
    }
    const int got = said == TF_SUN_UNDER ? 1
                    : tf_occluded(hf, o, sun, 0.0, said == TF_SUN_CLEAR_AFTER ? at : TF_FAR_AWAY);
    if (got != want)
        fail_msg("strips change the answer: o=(%.17g,%.17g,%.17g) sun=(%.17g,%.17g,%.17g) "
                 "said %d at %.17g: %d, the whole ray %d", o.x, o.y, o.z, sun.x, sun.y, sun.z,
                 said, at, got, want);
    if (said == TF_SUN_UNDER) { /* the point it names is under the surface */
        const tf_vec3 p = v3_add(o, v3_scale(sun, at));
        assert_true(p.z < tf_heightfield_height_at(hf, p.x, p.y));
    }
    t->rays++;
    t->lit += !want;
    t->proved_lit += !want && said == TF_SUN_CLEAR_AFTER;
    t->occluded += want;
    t->proved_under += said == TF_SUN_UNDER;
}

/* Many suns; for each, rays from points on the surface (lifted as a shadow ray is, or a hair
 * under it), above it, and outside the square. */
static tally shadow_rays(height_fn fn, int k, double extent, uint64_t seed)
{
    tf_heightfield *hf = make_field(fn, k, extent);
    const double e = hf->cells * hf->cell, relief = hf->hmax - hf->hmin + 1;
    rng r = {seed};
    tally t = {0, 0, 0, 0, 0};
    const double headings[] = {0, M_PI / 2, M_PI, -M_PI / 2, M_PI / 4, 3 * M_PI / 4, -1.0, 2.5};
    for (int n = 0; n < 24; n++) {
        const double az = n < 8 ? headings[n] : range(&r, -M_PI, M_PI);
        const double el = range(&r, 0.03, 1.3);
        const tf_vec3 sun = sun_at(az, el);
        tf_sun_strips *s = tf_sun_strips_build(hf, sun);
        assert_non_null(s);
        for (int i = 0; i < 600; i++) {
            const double x = range(&r, -0.02, 1.02) * e, y = range(&r, -0.02, 1.02) * e;
            const double ground = tf_heightfield_height_at(hf, fmin(fmax(x, 0), e),
                                                           fmin(fmax(y, 0), e));
            const double lift = i % 4 == 3 ? range(&r, -1e-3, 0.3) : range(&r, 1e-4, 2e-3);
            check_ray(hf, s, v3(x, y, ground + lift * relief), sun, &t);
        }
        tf_sun_strips_free(s);
    }
    tf_heightfield_free(hf);
    return t;
}

/* The rays of shadow_rays on field fn: answers checked; the strips must have proved at least
 * lit_share of the lit rays clear and, unless under_share is 0 (nothing asked), under_share of
 * the occluded ones occluded. */
static void rays_over(const char *name, height_fn fn, int k, double extent, uint64_t seed,
                      double lit_share, double under_share)
{
    tally t = shadow_rays(fn, k, extent, seed);
    print_message("%s: %d rays, %d lit (%d proved), %d occluded (%d proved)\n", name, t.rays,
                  t.lit, t.proved_lit, t.occluded, t.proved_under);
    assert_true(t.lit > t.rays / 10 && t.occluded > t.rays / 20);
    assert_true(t.proved_lit >= lit_share * t.lit);
    if (under_share > 0)
        assert_true(t.proved_under >= under_share * t.occluded);
}

/* The strips do the work for most lit rays and for many occluded ones; with 4-cell bins on a
 * 64-cell field they are coarse, and fewer occluded rays are proved there.  Over white noise a
 * bin's floor lies far below the surface between its peaks, so no occluded ray is expected to
 * be proved there (and none is asked): that field checks the answers and the lit rays. */
static void test_rays_hills(void **state) { (void)state; rays_over("hills", hills, 7, 150, 5, 0.5, 0.1); }
static void test_rays_rough(void **state) { (void)state; rays_over("rough", rough, 6, 100, 6, 0.25, 0.0); }
static void test_rays_terraces(void **state)
{
    (void)state;
    rays_over("terraces", terraces, 6, 300, 7, 0.5, 0.05);
}

/* A wall across the far side of a flat field (rows j >= 200 of 256 cells raised by 100, the
 * sun low over it, heading +y): a ray from the flat ground 150+ cells short of the wall is
 * under the surface only there, 37 or more bins past its start, and the strips prove it with
 * no walk (the sink's suffix maximum reaches any distance; the old look ahead was 16 bins). */
static double far_wall(int i, int j, int n)
{
    (void)i, (void)n;
    return j >= 200 ? 100.0 : 0.0;
}

static void test_a_far_wall_is_proved_without_a_walk(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(far_wall, 8, 256); /* cell 1 */
    const tf_vec3 sun = sun_at(M_PI / 2, 0.1);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun);
    assert_non_null(s);
    rng r = {12};
    for (int i = 0; i < 200; i++) {
        const tf_vec3 o = v3(range(&r, 20, 236), range(&r, 10, 50), 0.01);
        assert_true(tf_occluded(hf, o, sun, 0.0, TF_FAR_AWAY));
        double t = -1;
        assert_int_equal(tf_sun_strips_shadow(s, o, &t), TF_SUN_UNDER);
        t = named_point(s, o);
        const tf_vec3 p = v3_add(o, v3_scale(sun, t));
        assert_true(p.y >= 200 && p.z < tf_heightfield_height_at(hf, p.x, p.y));
    }
    tf_sun_strips_free(s);
    tf_heightfield_free(hf);
}

/* A spike on a flat field, 1.5 cells beside a lit ray's line but in its strip, 140 cells on
 * (35 bins, past the 16 the query tries one by one): the ray is under the strip's reach until
 * past the spike, and is proved clear from the first bin after it, found by halving (reach
 * never grows away from the sun). */
static double spike(int i, int j, int n)
{
    (void)n;
    return i == 128 && j == 160 ? 30.0 : 0.0;
}

static void test_a_ray_clear_past_the_look_ahead_is_proved_clear(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(spike, 8, 256); /* cell 1 */
    const tf_vec3 sun = sun_at(M_PI / 2, 0.1);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun);
    assert_non_null(s);
    const tf_sun_frame *f = &s->frame;
    for (double y = 10; y < 20; y += 0.37) {
        const tf_vec3 o = v3(126.5, y, 0.01);
        assert_false(tf_occluded(hf, o, sun, 0.0, TF_FAR_AWAY));
        double t = -1;
        assert_int_equal(tf_sun_strips_shadow(s, o, &t), TF_SUN_CLEAR_AFTER);
        const tf_vec3 p = v3_add(o, v3_scale(sun, t));
        assert_true(p.y > 160 && p.y < 160 + 2 * f->ds / f->b_s); /* just past the spike */
        assert_false(tf_occluded(hf, o, sun, 0.0, t));
    }
    tf_sun_strips_free(s);
    tf_heightfield_free(hf);
}

/* Tables that lie change answers: reaches lowered prove occluded rays clear, sinks raised
 * prove lit rays occluded. */
static int answers_changed(const tf_heightfield *hf, const tf_sun_strips *s, tf_vec3 sun)
{
    const double e = hf->cells * hf->cell;
    rng r = {9};
    int changed = 0;
    for (int i = 0; i < 3000; i++) {
        const double x = range(&r, 0, e), y = range(&r, 0, e);
        const tf_vec3 o = v3(x, y, tf_heightfield_height_at(hf, x, y) + 0.01);
        double t;
        const int said = tf_sun_strips_shadow(s, o, &t);
        const int got = said == TF_SUN_UNDER ? 1
                        : tf_occluded(hf, o, sun, 0.0, said == TF_SUN_CLEAR_AFTER ? t : TF_FAR_AWAY);
        changed += got != tf_occluded(hf, o, sun, 0.0, TF_FAR_AWAY);
    }
    return changed;
}

static void test_a_lying_table_changes_answers(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 7, 150);
    const tf_vec3 sun = sun_at(0.4, 0.15);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun);
    assert_non_null(s);
    assert_int_equal(answers_changed(hf, s, sun), 0);
    const size_t n = (size_t)s->frame.strips * s->frame.bins;
    for (size_t i = 0; i < n; i++)
        s->table[TF_SUN_BIN * i] -= 2.0f;
    assert_true(answers_changed(hf, s, sun) > 0);
    for (size_t i = 0; i < n; i++)
        s->table[TF_SUN_BIN * i] += 2.0f, s->table[TF_SUN_BIN * i + 1] += 2.0f;
    assert_true(answers_changed(hf, s, sun) > 0);
    tf_sun_strips_free(s);
    tf_heightfield_free(hf);
}

/* A height field with a NaN sample (a hole no loader lets through, but the grids take what
 * they are given): the strips prove nothing about the bins over it, so every answer is still
 * the walk's. */
static void test_a_nan_height_proves_nothing_there(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 6, 150);
    const int mid = hf->n / 2;
    for (int j = mid - 3; j <= mid + 3; j++)
        for (int i = mid - 3; i <= mid + 3; i++)
            hf->h[(size_t)j * hf->n + i] = NAN;
    tf_heightfield *holed = tf_heightfield_wrap(hf->h, 6, 150, 1); /* grids over the hole */
    assert_non_null(holed);
    hf->h = NULL;
    tf_heightfield_free(hf);
    rng r = {11};
    tally t = {0, 0, 0, 0, 0};
    const double e = holed->cells * holed->cell;
    for (int n = 0; n < 12; n++) {
        const tf_vec3 sun = sun_at(range(&r, -M_PI, M_PI), range(&r, 0.05, 0.6));
        tf_sun_strips *s = tf_sun_strips_build(holed, sun);
        assert_non_null(s);
        for (int i = 0; i < 800; i++) {
            const double x = range(&r, 0, e), y = range(&r, 0, e);
            const double z = tf_heightfield_height_at(holed, x, y);
            if (isnan(z))
                continue;
            check_ray(holed, s, v3(x, y, z + range(&r, 1e-3, 3)), sun, &t);
        }
        tf_sun_strips_free(s);
    }
    assert_true(t.rays > 5000);
    tf_heightfield_free(holed);
}

/* No strips where they cannot help; NULL strips prove nothing. */
static void test_no_strips(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 5, 100);
    assert_null(tf_sun_strips_build(hf, v3(0, 0, 1)));         /* overhead */
    assert_null(tf_sun_strips_build(hf, sun_at(1.0, 0.0)));    /* on the horizon */
    assert_null(tf_sun_strips_build(hf, sun_at(1.0, -0.2)));   /* below it */
    assert_null(tf_sun_strips_build(hf, v3(NAN, 0.5, 0.5)));
    double t;
    assert_int_equal(tf_sun_strips_shadow(NULL, v3(1, 1, 1), &t), TF_SUN_UNKNOWN);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun_at(1.0, 0.3));
    assert_non_null(s);
    assert_int_equal(tf_sun_strips_shadow(s, v3(NAN, 1, 1), &t), TF_SUN_UNKNOWN);
    assert_int_equal(tf_sun_strips_shadow(s, v3(1e12, 1, 1), &t), TF_SUN_UNKNOWN); /* far off */
    assert_int_equal(tf_sun_strips_shadow(s, v3(50, 50, NAN), &t), TF_SUN_UNKNOWN);
    assert_true(tf_sun_strips_bytes(s) > 0);
    tf_sun_strips_free(s);
    tf_sun_strips_free(NULL);
    tf_heightfield_free(hf);
}

/* ---- built on threads, kept with the terrain ---------------------------------------------- */

static int same_table(const tf_sun_strips *a, const tf_sun_strips *b)
{
    return a && b && a->frame.strips == b->frame.strips && a->frame.bins == b->frame.bins &&
           memcmp(a->table, b->table, tf_sun_strips_table_bytes(a)) == 0;
}

/* The table does not depend on how many threads built it: each builds whole strips, and a bin
 * is the same max over the same blocks whoever computes it.  2^10 cells a side (the threaded
 * path starts at 2^20 cells), suns from every side, a field with a hole too. */
static void test_threads_build_the_same_table(void **state)
{
    (void)state;
    tf_heightfield *fields[2] = {make_field(rough, 10, 2000), make_field(hills, 10, 2000)};
    const int mid = fields[1]->n / 2;
    fields[1]->h[(size_t)mid * fields[1]->n + mid] = NAN;
    tf_heightfield *holed = tf_heightfield_wrap(fields[1]->h, 10, 2000, 2);
    assert_non_null(holed);
    fields[1]->h = NULL;
    tf_heightfield_free(fields[1]);
    fields[1] = holed;
    const double headings[] = {0.0, 0.3, M_PI / 2, 2.5, M_PI, -2.2, -M_PI / 4};
    for (int f = 0; f < 2; f++)
        for (size_t h = 0; h < sizeof headings / sizeof headings[0]; h++) {
            const tf_vec3 sun = sun_at(headings[h], 0.1 + 0.1 * (double)h);
            tf_sun_strips *one = tf_sun_strips_build(fields[f], sun);
            assert_non_null(one);
            const int threads[] = {2, 3, 7};
            for (int t = 0; t < 3; t++) {
                tf_sun_strips *many = tf_sun_strips_build_threads(fields[f], sun, threads[t]);
                if (!same_table(one, many))
                    fail_msg("field %d, heading %.2f: %d threads built another table",
                             f, headings[h], threads[t]);
                tf_sun_strips_free(many);
            }
            tf_sun_strips_free(one);
        }
    tf_heightfield_free(fields[0]);
    tf_heightfield_free(fields[1]);
}

/* Kept strips are given for their very sun only, and go with the height field (make asan
 * would see a leak); a field keeps one table. */
static void test_kept_strips_serve_their_sun_only(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 6, 150);
    const tf_vec3 sun = sun_at(0.7, 0.3), other = sun_at(0.7, 0.31);
    assert_null(tf_sun_strips_kept(hf, sun));
    assert_int_equal(tf_sun_strips_keep(hf, sun, 0), 0);
    const tf_sun_strips *kept = tf_sun_strips_kept(hf, sun);
    assert_non_null(kept);
    tf_sun_strips *own = tf_sun_strips_build(hf, sun);
    assert_true(same_table(kept, own));
    tf_sun_strips_free(own);
    assert_null(tf_sun_strips_kept(hf, other));
    assert_int_equal(tf_sun_strips_keep(hf, other, 0), -1); /* one table a field */
    assert_int_equal(tf_sun_strips_keep(hf, v3(0, 0, 1), 0), -1);
    tf_heightfield *flat = make_field(hills, 5, 100);
    assert_int_equal(tf_sun_strips_keep(flat, v3(0, 0, 1), 0), -1); /* overhead: none help */
    assert_null(flat->derived);
    tf_heightfield_free(flat);
    tf_heightfield_free(hf);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bound_hills),
        cmocka_unit_test(test_bound_rough),
        cmocka_unit_test(test_rays_hills),
        cmocka_unit_test(test_rays_rough),
        cmocka_unit_test(test_rays_terraces),
        cmocka_unit_test(test_a_far_wall_is_proved_without_a_walk),
        cmocka_unit_test(test_a_ray_clear_past_the_look_ahead_is_proved_clear),
        cmocka_unit_test(test_a_lying_table_changes_answers),
        cmocka_unit_test(test_a_nan_height_proves_nothing_there),
        cmocka_unit_test(test_no_strips),
        cmocka_unit_test(test_threads_build_the_same_table),
        cmocka_unit_test(test_kept_strips_serve_their_sun_only),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
