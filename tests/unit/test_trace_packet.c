/* test_trace_packet.c: the packet tracer (common/render/trace_packet.c and its kernels) against
 * the single-ray tracer, on every ISA this CPU runs (portable forced too).  Every lane's hit --
 * hit or miss, t, p, n, ci, cj -- must be tf_trace's to the bit, and every occlusion
 * tf_occluded's: on random rays of every kind (from above, inside, from below, grazing,
 * axis-parallel along grid lines, vertical up and down, along cell diagonals), on adversarial
 * ones (zero components, outside the box, degenerate, NaN, empty intervals), on batches whose
 * lanes diverge wildly, on every batch size from 1 to past two packets (partial packets), on a
 * coherent camera row and its shadow rays.  Then tf_render_rect with packets on and off, every
 * ISA: memcmp-identical pixels. */
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
#include "render/trace_packet.h"
#include "render/render.h"
#include "render/render_internal.h"
#include "test_terrains.h"

static const char *const isas[] = {"portable", "avx2", "avx512"};
enum { ISAS = 3 };

/* ---- rays -------------------------------------------------------------------------------------- */

typedef struct rng { uint64_t s; } rng;
static double uni(rng *r) { return tf_hash_unit(r->s++); }
static double range(rng *r, double lo, double hi) { return lo + (hi - lo) * uni(r); }

typedef struct batch {
    int n;
    tf_vec3 o[512], d[512];
    double tmin[512], tmax[512];
} batch;

static void add(batch *b, tf_vec3 o, tf_vec3 d, double tmin, double tmax)
{
    assert_true(b->n < 512);
    b->o[b->n] = o, b->d[b->n] = d, b->tmin[b->n] = tmin, b->tmax[b->n] = tmax;
    b->n++;
}

enum { FROM_ABOVE, INSIDE, FROM_BELOW, GRAZING, AXIS_PARALLEL, VERTICAL, DIAGONAL, ODD, KINDS };

/* A ray of the given kind (test_trace.c's kinds, and ODD: zero components, outside the box,
 * degenerate); snapping to grid lines runs many rays along cell edges and through vertices. */
static void make_ray(const tf_heightfield *hf, rng *r, int kind, tf_vec3 *o, tf_vec3 *d)
{
    double e = hf->cells * hf->cell, lo = hf->hmin, hi = hf->hmax, span = hi - lo + 1;
    double snap = hf->cell * floor(range(r, 0, hf->cells + 1));
    double snap2 = hf->cell * floor(range(r, 0, hf->cells + 1));
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
    case GRAZING:
        *o = v3(-0.1 * e, range(r, 0, e), range(r, lo, hi));
        *d = v3(1, range(r, -0.5, 0.5), range(r, -0.02, 0.02));
        break;
    case AXIS_PARALLEL: {
        int along_x = uni(r) < 0.5;
        double across = uni(r) < 0.5 ? snap : range(r, 0, e), sgn = uni(r) < 0.5 ? 1 : -1;
        double z = range(r, lo - 0.2 * span, hi + 0.2 * span), dz = uni(r) < 0.2 ? 0 : range(r, -0.3, 0.3);
        *o = along_x ? v3(sgn > 0 ? -1 : e + 1, across, z) : v3(across, sgn > 0 ? -1 : e + 1, z);
        *d = along_x ? v3(sgn, 0, dz) : v3(0, sgn, dz);
        break;
    }
    case VERTICAL: {
        int up = uni(r) < 0.3;
        *o = v3(uni(r) < 0.3 ? snap : range(r, 0, e), uni(r) < 0.3 ? snap2 : range(r, 0, e),
                up ? lo - 1 : hi + 1);
        *d = v3(0, 0, up ? 1 : -range(r, 0.5, 2));
        break;
    }
    case DIAGONAL:
        *o = v3(snap, snap2, range(r, lo, hi + span));
        *d = v3(uni(r) < 0.5 ? 1 : -1, uni(r) < 0.5 ? 1 : -1, range(r, -0.5, 0.1));
        break;
    default: { /* ODD */
        static const tf_vec3 dirs[] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, -1}, {-1, 0, 0},
                                       {0, -1, 0}, {1, 1, 0}, {1e-300, 0, -1}, {1, -1e-17, -1e-3}};
        int k = (int)range(r, 0, sizeof dirs / sizeof dirs[0]);
        *o = uni(r) < 0.5 ? v3(range(r, -2 * e, 3 * e), range(r, -2 * e, 3 * e), range(r, lo - span, hi + span))
                          : v3(snap, snap2, range(r, lo, hi));
        *d = dirs[k];
        break;
    }
    }
}

/* ---- the comparison ------------------------------------------------------------------------------ */

static int same_hit(const tf_hit *a, const tf_hit *b) { return memcmp(a, b, sizeof *a) == 0; }

/* The batch through the packets on the current ISA, ray by ray against tf_trace and
 * tf_occluded.  Returns the hits found. */
static int compare_now(const tf_heightfield *hf, const batch *b)
{
    static unsigned char found[512], occl[512];
    static tf_hit hits[512];
    memset(found, 7, sizeof found);
    memset(occl, 7, sizeof occl);
    tf_trace_packets(hf, b->n, b->o, b->d, b->tmin, b->tmax, found, hits);
    tf_occluded_packets(hf, b->n, b->o, b->d, b->tmin, b->tmax, occl);
    int nhits = 0;
    for (int i = 0; i < b->n; i++) {
        tf_hit h;
        int want = tf_trace(hf, b->o[i], b->d[i], b->tmin[i], b->tmax[i], &h);
        int want_occl = tf_occluded(hf, b->o[i], b->d[i], b->tmin[i], b->tmax[i]);
        if (found[i] != want || (want && !same_hit(&h, &hits[i])) || occl[i] != want_occl)
            fail_msg("%s: ray %d of %d o=(%.17g,%.17g,%.17g) d=(%.17g,%.17g,%.17g) (%g,%g): "
                     "packet %d t %.17g ci %d cj %d occl %d, single %d t %.17g ci %d cj %d occl %d",
                     tf_trace_packet_isa(), i, b->n, b->o[i].x, b->o[i].y, b->o[i].z, b->d[i].x,
                     b->d[i].y, b->d[i].z, b->tmin[i], b->tmax[i], found[i], hits[i].t,
                     hits[i].ci, hits[i].cj, occl[i], want, h.t, h.ci, h.cj, want_occl);
        nhits += want;
    }
    return nhits;
}

/* compare_now on every ISA this CPU runs; at least the portable one. */
static int compare_all(const tf_heightfield *hf, const batch *b)
{
    int nhits = 0, ran = 0;
    for (int k = 0; k < ISAS; k++) {
        if (tf_trace_packet_force_isa(isas[k]) != 0)
            continue;
        assert_string_equal(tf_trace_packet_isa(), isas[k]);
        nhits = compare_now(hf, b);
        ran++;
    }
    tf_trace_packet_force_isa(NULL);
    assert_true(ran >= 1);
    return nhits;
}

/* Batches of random rays, each mixing every kind so the lanes of a packet diverge, with
 * windows (0, inf), (0, finite) and (tmin > 0, inf). */
static void random_batches(tf_heightfield *hf, int batches, uint64_t seed)
{
    rng r = {seed};
    int hits = 0, rays = 0;
    for (int k = 0; k < batches; k++) {
        batch b = {0};
        int n = 1 + (int)range(&r, 0, 300);
        for (int i = 0; i < n; i++) {
            tf_vec3 o, d;
            make_ray(hf, &r, (int)range(&r, 0, KINDS), &o, &d);
            double w = uni(&r);
            add(&b, o, d, w < 0.2 ? range(&r, 0, 3) : 0, w > 0.8 ? range(&r, 0.5, 50) : INFINITY);
        }
        hits += compare_all(hf, &b);
        rays += n;
    }
    assert_true(hits > rays / 10);
    tf_heightfield_free(hf);
}

static void test_random_rough(void **state) { (void)state; random_batches(make_field(rough, 5, 32.0), 30, 1); }
static void test_random_hills(void **state) { (void)state; random_batches(make_field(hills, 6, 640.0), 30, 2); }
static void test_random_terraces(void **state) { (void)state; random_batches(make_field(terraces, 6, 64.0), 30, 3); }
static void test_random_odd_extent(void **state) { (void)state; random_batches(make_field(hills, 4, 7.3), 20, 4); }
static void test_random_tiny(void **state)
{
    (void)state;
    random_batches(make_field(rough, 1, 2.0), 10, 5);
    random_batches(make_field(hills, 2, 3.0), 10, 6);
}

/* Every batch size from 1 to 40 (partial packets of every ISA), one kind per batch, and
 * single-kind batches of every kind (coherent lanes that take the same odd paths). */
static void test_sizes_and_kinds(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 5, 100.0);
    rng r = {11};
    for (int n = 1; n <= 40; n++)
        for (int kind = 0; kind < KINDS; kind++) {
            batch b = {0};
            for (int i = 0; i < n; i++) {
                tf_vec3 o, d;
                make_ray(hf, &r, kind, &o, &d);
                add(&b, o, d, 0, INFINITY);
            }
            compare_all(hf, &b);
        }
    tf_heightfield_free(hf);
}

/* Hand-made adversarial lanes in one packet with ordinary ones: NaN and infinite components,
 * a zero direction, an empty or reversed interval, rays exactly along the box's faces,
 * vertical rays on vertices, rays from far outside, grazing the highest peak. */
static void test_adversarial(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(terraces, 5, 32.0);
    const double e = hf->cells * hf->cell, c = hf->cell, top = hf->hmax, low = hf->hmin;
    batch b = {0};
    add(&b, v3(NAN, 1, top + 1), v3(0, 0, -1), 0, INFINITY);
    add(&b, v3(1, 1, top + 1), v3(INFINITY, 0, -1), 0, INFINITY);
    add(&b, v3(1, 1, top + 1), v3(0, 0, 0), 0, INFINITY);
    add(&b, v3(1, 1, top + 1), v3(0, 0, -1), 5, 5);
    add(&b, v3(1, 1, top + 1), v3(0, 0, -1), 7, 3);
    add(&b, v3(0, 0, top + 1), v3(1, 0, -0.01), 0, INFINITY);  /* along the face y = 0 */
    add(&b, v3(e, e, top + 1), v3(-1, 0, -0.01), 0, INFINITY); /* along y = e */
    add(&b, v3(0, e, top + 1), v3(0, -1, -0.02), 0, INFINITY); /* along x = 0 */
    add(&b, v3(0, 0, top + 1), v3(1, 1, -0.05), 0, INFINITY);  /* the diagonal */
    add(&b, v3(e, 0, top + 1), v3(-1, 1, -0.05), 0, INFINITY); /* the anti-diagonal */
    for (int k = 0; k <= hf->cells; k += 3) {
        add(&b, v3(k * c, k * c, top + 1), v3(0, 0, -1), 0, INFINITY);   /* down on vertices */
        add(&b, v3(k * c, (k / 2) * c, low - 1), v3(0, 0, 1), 0, INFINITY); /* up from below */
        add(&b, v3(-1e6, k * c, top + 1e3), v3(1e6, 0, -1e3), 0, INFINITY);   /* from far away */
        add(&b, v3(k * c, -5, hf->h[(size_t)k] + 1e-9), v3(0, 1, 0), 0, INFINITY); /* level */
        add(&b, v3(-1, k * c + 0.5 * c, top), v3(1, 0, -1e-12), 0, INFINITY); /* grazing the top */
    }
    add(&b, v3(e + 10, e + 10, top + 10), v3(1, 1, 1), 0, INFINITY); /* away from the box */
    add(&b, v3(e / 2, e / 2, top + 1), v3(0, 0, 1), 0, INFINITY);    /* up into the sky */
    compare_all(hf, &b);
    tf_heightfield_free(hf);
}

/* Rays from grid vertices along rational slopes (p, q) in every direction: their crossings of
 * x and y lines tie exactly at vertices all along the way, where the walk's x-before-y rule and
 * the re-entry search after a descent (fix_stale_axis, strict on one axis, not the other)
 * decide which cell comes first. */
static void test_vertex_ties(void **state)
{
    (void)state;
    height_fn fields[] = {terraces, hills, rough};
    for (int f = 0; f < 3; f++) {
        tf_heightfield *hf = make_field(fields[f], 6, 64.0);
        const double c = hf->cell, top = hf->hmax, low = hf->hmin;
        rng r = {40 + (uint64_t)f};
        batch b = {0};
        for (int p = -3; p <= 3; p++)
            for (int q = -3; q <= 3; q++) {
                if (!p && !q)
                    continue;
                for (int k = 0; k < 9; k++) {
                    int i = (int)range(&r, 0, hf->cells + 1), j = (int)range(&r, 0, hf->cells + 1);
                    double z = k < 6 ? top + range(&r, 0, 3) : low + range(&r, 0, top - low);
                    double dz = k % 3 == 0 ? -(top - low) / (64.0 * c) : range(&r, -0.2, 0.02);
                    add(&b, v3(i * c, j * c, z), v3(p * c, q * c, dz * c), 0, INFINITY);
                }
            }
        compare_all(hf, &b);
        tf_heightfield_free(hf);
    }
}

/* A camera's row of rays (coherent, as tf_render_rect traces them), then shadow rays from
 * every hit toward a low sun, starting a hair above the hit as the shader does. */
static void test_camera_row_and_shadows(void **state)
{
    (void)state;
    tf_heightfield *hf = make_field(hills, 7, 1000.0);
    tf_vec3 eye = v3(30, 40, hf->hmax + 2);
    for (int row = 0; row < 12; row++) {
        batch prim = {0}, shad = {0};
        for (int x = 0; x < 300; x++)
            add(&prim, eye, v3_norm(v3(1, 0.2 + x / 300.0, -0.02 - row * 0.01)), 0, INFINITY);
        compare_all(hf, &prim);
        tf_vec3 sun = v3_norm(v3(-0.6, 0.5, 0.12 + 0.02 * row));
        for (int i = 0; i < prim.n; i++) {
            tf_hit h;
            if (tf_trace(hf, prim.o[i], prim.d[i], 0, INFINITY, &h))
                add(&shad, v3_add(h.p, v3_scale(h.n, 0.01 * hf->cell)), sun, 0, 1e30);
        }
        assert_true(shad.n > 0);
        compare_all(hf, &shad);
    }
    tf_heightfield_free(hf);
}

/* ---- the image -------------------------------------------------------------------------------------- */

#define IW 53
#define IH 31

static void fill_scene(tf_scene *s, int smooth)
{
    memset(s, 0, sizeof *s);
    s->width = IW;
    s->height = IH;
    s->camera.kind = TF_CAMERA_PINHOLE;
    s->camera.position = v3(500, -250, 420);
    s->camera.look_at = v3(500, 600, 300);
    s->camera.up = v3(0, 0, 1);
    s->camera.fov_deg = 55;
    s->sun.azimuth_deg = 250;
    s->sun.elevation_deg = 12; /* low: long shadows */
    s->sun.color = v3(1, 0.95, 0.85);
    s->sun.intensity = 3;
    s->sky.zenith = v3(0.15, 0.3, 0.7);
    s->sky.horizon = v3(0.55, 0.65, 0.8);
    s->sky.intensity = 0.8;
    s->terrain.seed = 1234;
    s->terrain.smooth = smooth;
    s->materials.sea_level = 60;
    s->materials.tree_line = 200;
    s->materials.snow_line = 330;
    s->materials.snow_jitter = 20;
    s->materials.rock_slope_deg = 35;
    s->materials.bump = 0.4;
    s->mist.enabled = 1;
    s->mist.density = 0.0008;
    s->mist.falloff = 150;
    s->mist.color = v3(0.6, 0.7, 0.85);
    s->mist.extinction = v3(1, 1.6, 3);
    s->antialias.threshold = 0.05;
    s->antialias.max_depth = 2;
}

/* Hills, a ridge and a sea, over [0, 1000]^2. */
static tf_heightfield *image_terrain(void)
{
    enum { K = 6, SIDE = (1 << K) + 1 };
    static float h[SIDE * SIDE];
    for (int j = 0; j < SIDE; j++)
        for (int i = 0; i < SIDE; i++) {
            double x = i * 1000.0 / (SIDE - 1), y = j * 1000.0 / (SIDE - 1);
            h[j * SIDE + i] = (float)(160 + 110 * sin(x * 0.011) * cos(y * 0.008) + 0.25 * y -
                                      90 * exp(-((x - 200) * (x - 200) + (y - 150) * (y - 150)) / 40000.0));
        }
    return tf_heightfield_from_heights(h, K, 1000.0, 1);
}

static void render_image(const tf_renderer *r, int packets, const char *isa, tf_pixel *out,
                         tf_render_counts *counts)
{
    tf_render_coherence_force(0); /* coherent samples are traced one at a time, not in packets */
    tf_trace_packets_force(packets);
    if (isa)
        assert_int_equal(tf_trace_packet_force_isa(isa), 0);
    tf_render_rect(r, (tf_rect){0, 0, IW, IH}, out, counts);
    tf_render_rect(r, (tf_rect){3, 5, 17, 9}, out + IW * IH, counts); /* an odd stamp too */
    tf_trace_packets_force(-1);
    tf_render_coherence_force(-1);
    tf_trace_packet_force_isa(NULL);
}

static void test_image_packets_on_off(void **state)
{
    (void)state;
    tf_heightfield *hf = image_terrain();
    for (int smooth = 0; smooth < 2; smooth++) {
        tf_scene s;
        fill_scene(&s, smooth);
        char err[256];
        tf_renderer *r = tf_renderer_new(&s, hf, err, sizeof err);
        assert_non_null(r);
        static tf_pixel off[IW * IH + 17 * 9], on[IW * IH + 17 * 9];
        tf_render_counts c_off = {0};
        render_image(r, 0, NULL, off, &c_off);
        assert_true(c_off.shadow_rays > 0);
        int ran = 0;
        for (int k = 0; k < ISAS; k++) {
            if (tf_trace_packet_force_isa(isas[k]) != 0)
                continue;
            tf_trace_packet_force_isa(NULL);
            tf_render_counts c_on = {0};
            memset(on, 0xa5, sizeof on);
            render_image(r, 1, isas[k], on, &c_on);
            if (memcmp(on, off, sizeof on) != 0)
                fail_msg("smooth %d, %s: the pixels differ with packets on", smooth, isas[k]);
            assert_memory_equal(&c_on, &c_off, sizeof c_on);
            ran++;
        }
        assert_true(ran >= 1);
        tf_renderer_free(r);
    }
    tf_heightfield_free(hf);
}

/* TF_TRACE_ISA caps the ISA; an unknown name or an ISA the CPU lacks is refused by the force. */
static void test_isa_switches(void **state)
{
    (void)state;
    assert_int_equal(tf_trace_packet_force_isa("portable"), 0);
    assert_string_equal(tf_trace_packet_isa(), "portable");
    assert_int_equal(tf_trace_packet_lanes(), 2);
    assert_int_equal(tf_trace_packet_force_isa("sse9"), -1);
    tf_trace_packet_force_isa(NULL);
    setenv("TF_TRACE_ISA", "portable", 1);
    assert_string_equal(tf_trace_packet_isa(), "portable");
    unsetenv("TF_TRACE_ISA");
    setenv("TF_TRACE_PACKETS", "0", 1);
    assert_false(tf_trace_packets_enabled());
    tf_trace_packets_force(1);
    assert_true(tf_trace_packets_enabled());
    tf_trace_packets_force(-1);
    setenv("TF_TRACE_PACKETS", "1", 1);
    assert_true(tf_trace_packets_enabled());
    unsetenv("TF_TRACE_PACKETS"); /* on with the AVX-512 kernel only, the one measured faster */
    assert_int_equal(tf_trace_packets_enabled(), !strcmp(tf_trace_packet_isa(), "avx512"));
    setenv("TF_TRACE_ISA", "avx2", 1);
    assert_false(tf_trace_packets_enabled());
    unsetenv("TF_TRACE_ISA");
    printf("packet ISA here: %s, %d lanes\n", tf_trace_packet_isa(), tf_trace_packet_lanes());
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_isa_switches),
        cmocka_unit_test(test_adversarial),
        cmocka_unit_test(test_sizes_and_kinds),
        cmocka_unit_test(test_vertex_ties),
        cmocka_unit_test(test_camera_row_and_shadows),
        cmocka_unit_test(test_random_rough),
        cmocka_unit_test(test_random_hills),
        cmocka_unit_test(test_random_terraces),
        cmocka_unit_test(test_random_odd_extent),
        cmocka_unit_test(test_random_tiny),
        cmocka_unit_test(test_image_packets_on_off),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
