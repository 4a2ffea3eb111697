/* test_sun_strips.c: the sun's strips (render/sun_strips.h, render/sun_math.h).  Their table
 * bounds the surface as the query assumes (checked against the surface itself at random points
 * of every bin); a shadow ray whose walk ends where the strips say gives tf_occluded's answer
 * over the whole ray, for suns from every heading (the axes and the diagonals too) and
 * elevation, from points on, over, under and beside the surface; the strips do prove most lit
 * rays clear; a table that lies changes answers (so the comparison can fail); and no strips are
 * made where they cannot help. */
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

/* At random points q of the square: in q's strip, the entry of q's bin b is at least
 * f(q) - climb * (bin b's start), and the entries never grow toward the sun -- what the
 * query's proof reads off the table (a ray is lowest in a bin where it enters it). */
static void check_bound(height_fn fn, int k, double extent, tf_vec3 sun, uint64_t seed)
{
    tf_heightfield *hf = make_field(fn, k, extent);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun);
    assert_non_null(s);
    const tf_sun_frame *f = &s->frame;
    const double e = hf->cells * hf->cell;
    rng r = {seed};
    for (int i = 0; i < 20000; i++) {
        const double x = range(&r, 0, e), y = range(&r, 0, e);
        const double along = f->a_s * x + f->b_s * y, across = f->a_p * x + f->b_p * y;
        const int kq = (int)floor((across - f->across0) * f->inv_w);
        const int bq = (int)floor((along - f->along0) * f->inv_ds);
        assert_true(kq >= 0 && kq < f->strips && bq >= 1 && bq < f->bins);
        const float *row = s->reach + (size_t)kq * f->bins;
        const double need = tf_heightfield_height_at(hf, x, y) - f->climb * (f->along0 + bq * f->ds);
        if (!(row[bq] >= need))
            fail_msg("reach[%d][%d] = %.9g under the surface's %.9g at (%.9g, %.9g)", kq, bq,
                     (double)row[bq], need, x, y);
        assert_true(row[bq - 1] >= row[bq]);
    }
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

typedef struct tally { int rays, lit, proved_lit; } tally;

/* One shadow ray: the walk ended where the strips say answers as the whole ray. */
static void check_ray(const tf_heightfield *hf, const tf_sun_strips *s, tf_vec3 o, tf_vec3 sun,
                      tally *t)
{
    const int want = tf_occluded(hf, o, sun, 0.0, TF_FAR_AWAY);
    const double tmax = tf_sun_strips_tmax(s, o);
    const int got = tf_occluded(hf, o, sun, 0.0, tmax);
    if (got != want)
        fail_msg("strips change the answer: o=(%.17g,%.17g,%.17g) sun=(%.17g,%.17g,%.17g) "
                 "tmax %.17g: %d, the whole ray %d", o.x, o.y, o.z, sun.x, sun.y, sun.z, tmax,
                 got, want);
    t->rays++;
    t->lit += !want;
    t->proved_lit += !want && tmax < TF_FAR_AWAY;
}

/* Many suns; for each, rays from points on the surface (lifted as a shadow ray is, or a hair
 * under it), above it, and outside the square. */
static tally shadow_rays(height_fn fn, int k, double extent, uint64_t seed)
{
    tf_heightfield *hf = make_field(fn, k, extent);
    const double e = hf->cells * hf->cell, relief = hf->hmax - hf->hmin + 1;
    rng r = {seed};
    tally t = {0, 0, 0};
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

static void test_rays_hills(void **state)
{
    (void)state;
    tally t = shadow_rays(hills, 7, 150, 5);
    assert_true(t.lit > t.rays / 4);
    assert_true(t.proved_lit > t.lit / 2); /* the strips do the work for most lit rays */
}

static void test_rays_rough(void **state)
{
    (void)state;
    tally t = shadow_rays(rough, 6, 100, 6);
    assert_true(t.lit > t.rays / 10);
    assert_true(t.proved_lit > t.lit / 4);
}

static void test_rays_terraces(void **state)
{
    (void)state;
    tally t = shadow_rays(terraces, 6, 300, 7);
    assert_true(t.proved_lit > t.lit / 2);
}

/* A table lowered by a little proves rays clear that are not: the answers change. */
static void test_a_lying_table_changes_answers(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 7, 150);
    const tf_vec3 sun = sun_at(0.4, 0.15);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun);
    assert_non_null(s);
    const size_t n = (size_t)s->frame.strips * s->frame.bins;
    for (size_t i = 0; i < n; i++)
        s->reach[i] -= 2.0f;
    const double e = hf->cells * hf->cell;
    rng r = {9};
    int changed = 0;
    for (int i = 0; i < 3000; i++) {
        const double x = range(&r, 0, e), y = range(&r, 0, e);
        const tf_vec3 o = v3(x, y, tf_heightfield_height_at(hf, x, y) + 0.01);
        changed += tf_occluded(hf, o, sun, 0.0, tf_sun_strips_tmax(s, o)) !=
                   tf_occluded(hf, o, sun, 0.0, TF_FAR_AWAY);
    }
    assert_true(changed > 0);
    tf_sun_strips_free(s);
    tf_heightfield_free(hf);
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
    assert_true(tf_sun_strips_tmax(NULL, v3(1, 1, 1)) == TF_FAR_AWAY);
    tf_sun_strips *s = tf_sun_strips_build(hf, sun_at(1.0, 0.3));
    assert_non_null(s);
    assert_true(tf_sun_strips_tmax(s, v3(NAN, 1, 1)) == TF_FAR_AWAY);
    assert_true(tf_sun_strips_tmax(s, v3(1e12, 1, 1)) == TF_FAR_AWAY); /* far outside */
    assert_true(tf_sun_strips_bytes(s) > 0);
    tf_sun_strips_free(s);
    tf_sun_strips_free(NULL);
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
        cmocka_unit_test(test_a_lying_table_changes_answers),
        cmocka_unit_test(test_no_strips),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
