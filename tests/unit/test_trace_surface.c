/* test_trace_surface.c: rays that start ON the terrain (shadow rays, cameras in valleys).
 *
 * The hierarchical walk starts such rays at level 0 instead of descending from the top
 * (trace.c, walk_hier: "Where to start").  That must not change any result: for rays leaving
 * surface points (exactly on the surface, lifted a hair along the normal as shade.c does,
 * and sunk a hair below it), in random and in low-sun directions, tf_trace must equal
 * tf_trace_flat bit for bit and tf_occluded must agree with both.  Terrains: smooth fBm-like
 * hills, white noise and terraces (ties with the max grids). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>
#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "render/trace.h"
#include "test_terrains.h"

typedef struct rng { uint64_t s; } rng;
static double uni(rng *r) { return tf_hash_unit(r->s++); }
static double range(rng *r, double lo, double hi) { return lo + (hi - lo) * uni(r); }

typedef struct tally { int rays, hits; } tally;

/* tf_trace == tf_trace_flat bit for bit, and tf_occluded agrees. */
static void check_ray(const tf_heightfield *hf, tf_vec3 o, tf_vec3 d, tally *tl)
{
    tf_hit a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    int ha = tf_trace(hf, o, d, 0.0, INFINITY, &a), hb = tf_trace_flat(hf, o, d, 0.0, INFINITY, &b);
    if (ha != hb || (ha && memcmp(&a, &b, sizeof a) != 0))
        fail_msg("trace/flat differ: o=(%.17g,%.17g,%.17g) d=(%.17g,%.17g,%.17g) hit %d/%d "
                 "t %.17g/%.17g", o.x, o.y, o.z, d.x, d.y, d.z, ha, hb, a.t, b.t);
    assert_int_equal(tf_occluded(hf, o, d, 0.0, INFINITY), ha);
    tl->rays++;
    tl->hits += ha;
}

/* A random surface point: a vertical ray's hit (so it lies on the traced triangles). */
static int surface_point(const tf_heightfield *hf, rng *r, tf_hit *h)
{
    double e = hf->cells * hf->cell;
    tf_vec3 o = v3(range(r, 0, e), range(r, 0, e), hf->hmax + 1);
    return tf_trace(hf, o, v3(0, 0, -1), 0.0, INFINITY, h);
}

static void surface_rays(height_fn f, int k, double extent, uint64_t seed)
{
    tf_heightfield *hf = make_field(f, k, extent);
    rng r = {seed};
    tally tl = {0, 0};
    const double lift = 0.01 * hf->cell + 1e-6 * (hf->hmax - hf->hmin); /* as shade.c */
    for (int i = 0; i < 1500; i++) {
        tf_hit h;
        if (!surface_point(hf, &r, &h))
            continue;
        /* a low sun (like default.scene's 14 degrees) or any upward direction */
        double az = range(&r, 0, 6.283185307179586);
        double el = i % 2 ? range(&r, 0.05, 0.4) : range(&r, 0.0, 1.5);
        tf_vec3 d = v3(sin(az) * cos(el), cos(az) * cos(el), sin(el));
        check_ray(hf, h.p, d, &tl);                                      /* on the surface */
        check_ray(hf, v3_add(h.p, v3_scale(h.n, lift)), d, &tl);         /* lifted (shadow) */
        check_ray(hf, v3_add(h.p, v3_scale(h.n, -lift)), d, &tl);        /* sunk a hair */
        check_ray(hf, v3_add(h.p, v3_scale(h.n, lift)), v3(d.x, d.y, -d.z), &tl); /* downwards */
    }
    /* both outcomes occur, so the comparison is not vacuous */
    assert_true(tl.rays > 4000);
    assert_true(tl.hits > tl.rays / 20);
    assert_true(tl.hits < tl.rays - tl.rays / 20);
    tf_heightfield_free(hf);
}

static void test_surface_rays_hills(void **state)
{
    (void)state;
    surface_rays(hills, 7, 100.0, 11);
}

static void test_surface_rays_rough(void **state)
{
    (void)state;
    surface_rays(rough, 6, 64.0, 22);
}

static void test_surface_rays_terraces(void **state)
{
    (void)state;
    surface_rays(terraces, 7, 100.0, 33);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_surface_rays_hills),
        cmocka_unit_test(test_surface_rays_rough),
        cmocka_unit_test(test_surface_rays_terraces),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
