/* test_fractal.c: Musgrave's procedural terrains (common/terrain/fractal.c, fractal.h) and the terrain
 * point entry tf_terrain_point (terrain.h).
 *
 * Every generator must be deterministic and finite; the row evaluator the height-field builder
 * uses must give the same bits as evaluating each point alone, with its AVX-512 blend and
 * without; and each multifractal must show
 * the behaviour that defines it (Musgrave 2.3.2): hetero's detail grows with altitude, hybrid's
 * and ridged's octaves are weighted by the previous one, ridged is built on (offset - |N|)^2. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "terrain/fractal.h"
#include "terrain/noise.h"
#include "terrain/noise_row.h"

static double sample(uint64_t *counter, double lo, double hi)
{
    return lo + (hi - lo) * tf_hash_unit((*counter)++);
}

static tf_terrain terrain(enum tf_generator g, double octaves)
{
    tf_terrain t;
    memset(&t, 0, sizeof t);
    t.generator = g;
    t.seed = 99;
    t.size_exp = 6;
    t.extent = 1000.0;
    t.height_scale = 100.0;
    t.feature_size = 300.0;
    t.octaves = octaves;
    t.H = 0.8;
    t.lacunarity = 2.0;
    t.offset = g == TF_GEN_RIDGED ? 1.0 : 0.7;
    t.gain = 2.0;
    return t;
}

static const enum tf_generator point_gens[] = {TF_GEN_FBM, TF_GEN_HETERO, TF_GEN_HYBRID,
                                               TF_GEN_RIDGED};

static void test_generators_deterministic_finite_and_seeded(void **state)
{
    (void)state;
    for (size_t g = 0; g < 4; g++) {
        tf_terrain t = terrain(point_gens[g], 8.5);
        tf_terrain u = t;
        u.seed = 100;
        tf_noise a, b, other;
        tf_noise_init(&a, t.seed);
        tf_noise_init(&b, t.seed);
        tf_noise_init(&other, u.seed);
        uint64_t c = 1;
        int differ = 0;
        for (int k = 0; k < 2000; k++) {
            double x = sample(&c, -500, 1500), y = sample(&c, -500, 1500);
            double v1 = tf_terrain_point(&t, &a, x, y), v2 = tf_terrain_point(&t, &b, x, y);
            assert_true(isfinite(v1));
            assert_memory_equal(&v1, &v2, sizeof v1);
            differ += fabs(v1 - tf_terrain_point(&u, &other, x, y)) > 1e-6;
        }
        assert_true(differ > 1800);
    }
}

/* tf_fractal_row must equal point evaluation bit for bit: with scratch memory (the column
 * table path, and the per-sample path for octaves finer than the samples) and without. */
static void check_row_matches_points(const tf_terrain *t, double cell, int count)
{
    tf_fractal f;
    tf_noise nz;
    assert_int_equal(tf_fractal_prepare(&f, t), 0);
    tf_noise_init(&nz, t->seed);
    tf_fractal_rowbuf buf;
    assert_int_equal(tf_fractal_rowbuf_init(&buf, count), 0);
    float row[300], bare[300], points[300];
    assert_true(count <= 300);
    for (int j = 0; j < 5; j++) {
        double y = j * 37.3;
        tf_fractal_row(&f, &nz, y, cell, count, t->height_scale, row, &buf);
        tf_fractal_row(&f, &nz, y, cell, count, t->height_scale, bare, NULL);
        for (int i = 0; i < count; i++)
            points[i] = (float)(t->height_scale * tf_fractal_eval(&f, &nz, (double)i * cell, y));
        assert_memory_equal(row, points, count * sizeof(float));
        assert_memory_equal(bare, points, count * sizeof(float));
    }
    tf_fractal_rowbuf_free(&buf);
}

static void test_row_equals_points_bitwise(void **state)
{
    (void)state;
    for (size_t g = 0; g < 4; g++) {
        tf_terrain t = terrain(point_gens[g], 6.3);
        check_row_matches_points(&t, 1000.0 / 256, 257); /* lattice coarser than samples */
        t.octaves = 14;                                   /* finest octaves finer than samples */
        check_row_matches_points(&t, 1000.0 / 64, 65);
        t.lacunarity = 2.7183;
        t.H = 0.35;
        check_row_matches_points(&t, 3.0, 200);
    }
}

static void test_fbm_terrain_is_fbm_at_mapped_point(void **state)
{
    (void)state;
    tf_terrain t = terrain(TF_GEN_FBM, 7.25);
    tf_noise nz;
    tf_noise_init(&nz, t.seed);
    double ox, oy;
    tf_fractal_seed_offset(t.seed, &ox, &oy);
    uint64_t c = 5;
    for (int k = 0; k < 500; k++) {
        double x = sample(&c, 0, 1000), y = sample(&c, 0, 1000);
        double want = tf_fbm2(&nz, x / t.feature_size + ox, y / t.feature_size + oy, t.H,
                              t.lacunarity, t.octaves);
        assert_true(tf_terrain_point(&t, &nz, x, y) == want);
    }
}

static void test_seed_offset_keeps_origin_off_lattice(void **state)
{
    (void)state;
    for (uint64_t seed = 0; seed < 200; seed++) {
        double ox, oy;
        tf_fractal_seed_offset(seed, &ox, &oy);
        double fx = ox - floor(ox), fy = oy - floor(oy);
        assert_true(fx >= 0.1 && fx <= 0.9 && fy >= 0.1 && fy <= 0.9);
        assert_true(ox >= 16 && ox < 241 && oy >= 16 && oy < 241);
    }
    tf_terrain t = terrain(TF_GEN_FBM, 8);
    tf_noise nz;
    tf_noise_init(&nz, t.seed);
    assert_true(tf_terrain_point(&t, &nz, 0.0, 0.0) != 0.0);
}

static void test_one_octave_is_the_basis(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 4);
    uint64_t c = 8;
    for (int k = 0; k < 500; k++) {
        double x = sample(&c, -9, 9), y = sample(&c, -9, 9);
        double n = tf_noise2(&nz, x, y);
        assert_true(tf_hetero2(&nz, x, y, 0.8, 2.0, 1.0, 0.7) == n + 0.7);
        assert_true(tf_hybrid2(&nz, x, y, 0.8, 2.0, 1.0, 0.7, 2.0) == 0.5 * (n + 0.7));
        double r = 1.0 - fabs(n);
        assert_true(tf_ridged2(&nz, x, y, 0.8, 2.0, 1.0, 1.0, 2.0) == r * r);
    }
}

/* Second octave by hand: the weighting that defines each multifractal. */
static void test_second_octave_weighting(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 6);
    const double H = 0.9, lac = 2.0, w1 = pow(2.0, -H), off = 0.8, gain = 1.5;
    uint64_t c = 21;
    for (int k = 0; k < 500; k++) {
        double x = sample(&c, -9, 9), y = sample(&c, -9, 9);
        double n0 = tf_noise2(&nz, x, y), n1 = tf_noise2(&nz, 2 * x, 2 * y);
        double a0 = n0 + off;
        assert_true(fabs(tf_hetero2(&nz, x, y, H, lac, 2.0, off) - (a0 + a0 * (n1 + off) * w1)) <
                    1e-12);
        double s0 = 0.5 * (n0 + off), wt = fmin(1.0, fmax(0.0, s0 * gain));
        assert_true(fabs(tf_hybrid2(&nz, x, y, H, lac, 2.0, off, gain) -
                         (s0 + w1 * wt * 0.5 * (n1 + off))) < 1e-12);
        double r0 = (1 - fabs(n0)) * (1 - fabs(n0)), r1 = (1 - fabs(n1)) * (1 - fabs(n1));
        double rw = fmin(1.0, fmax(0.0, r0 * gain));
        assert_true(fabs(tf_ridged2(&nz, x, y, H, lac, 2.0, 1.0, gain) - (r0 + w1 * rw * r1)) <
                    1e-12);
    }
}

/* Hetero, "statistics by altitude": the detail added by octaves 5..10 is proportional to the
 * altitude reached by octave 4, so it is much larger on high ground than near sea level. */
static void test_hetero_detail_grows_with_altitude(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 12);
    double low_sum = 0, high_sum = 0;
    int low_n = 0, high_n = 0;
    uint64_t c = 3;
    for (int k = 0; k < 20000; k++) {
        double x = sample(&c, 0, 50), y = sample(&c, 0, 50);
        double coarse = tf_hetero2(&nz, x, y, 0.5, 2.0, 4.0, 0.3);
        double detail = fabs(tf_hetero2(&nz, x, y, 0.5, 2.0, 10.0, 0.3) - coarse);
        if (fabs(coarse) < 0.1) { low_sum += detail; low_n++; }
        if (coarse > 0.8) { high_sum += detail; high_n++; }
    }
    assert_true(low_n > 100 && high_n > 100);
    assert_true(high_sum / high_n > 4.0 * (low_sum / low_n));
}

/* Ridged and hybrid weight each octave by the previous one, clamped to [0, 1]: ridged is never
 * negative and never exceeds the unweighted sum of offset^2 * amp; where an octave's signal is
 * zero, the next octave adds nothing. */
static void test_ridged_bounds_and_weighting(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 13);
    const double H = 1.0, lac = 2.0;
    double bound = 0;
    for (int i = 0; i < 8; i++)
        bound += pow(pow(2.0, i), -H);
    uint64_t c = 4;
    double smallest = 1e9, largest = -1e9;
    for (int k = 0; k < 20000; k++) {
        double x = sample(&c, -100, 100), y = sample(&c, -100, 100);
        double r = tf_ridged2(&nz, x, y, H, lac, 8.0, 1.0, 2.0);
        assert_true(r >= 0.0 && r <= bound);
        smallest = fmin(smallest, r);
        largest = fmax(largest, r);
    }
    assert_true(largest - smallest > 0.5); /* and it does span a range */
    /* gain 0: every octave after the first is weighted by 0 -> only the basis remains. */
    double x = 1.37, y = -2.71, n = tf_noise2(&nz, x, y);
    assert_true(tf_ridged2(&nz, x, y, H, lac, 8.0, 1.0, 0.0) == (1 - fabs(n)) * (1 - fabs(n)));
    assert_true(tf_hybrid2(&nz, x, y, H, lac, 8.0, 0.7, 0.0) == 0.5 * (n + 0.7));
}

/* Samples first .. first + count - 1 with the row's vector blend (noise_row.h) and without:
 * the same bits as points. */
static void check_row_at_every_isa(const tf_terrain *t, double cell, int64_t first, int count)
{
    tf_fractal f;
    tf_noise nz;
    assert_int_equal(tf_fractal_prepare(&f, t), 0);
    tf_noise_init(&nz, t->seed);
    tf_fractal_rowbuf buf;
    assert_int_equal(tf_fractal_rowbuf_init(&buf, count), 0);
    float row[300], points[300];
    assert_true(count <= 300);
    static const char *isas[] = {"avx512", "portable"};
    for (size_t a = 0; a < 2; a++) {
        if (tf_noise_row_force_isa(isas[a]) != 0)
            continue; /* this CPU has no AVX-512 */
        for (int j = 0; j < 3; j++) {
            double y = j * 41.9 - 30.0;
            tf_fractal_row_at(&f, &nz, y, cell, first, count, t->height_scale, row, &buf);
            for (int i = 0; i < count; i++)
                points[i] = (float)(t->height_scale *
                                    tf_fractal_eval(&f, &nz, (double)(first + i) * cell, y));
            assert_memory_equal(row, points, count * sizeof(float));
        }
    }
    assert_int_equal(tf_noise_row_force_isa(NULL), 0);
    tf_fractal_rowbuf_free(&buf);
}

/* The vector blend's cases: columns picked by permutes (samples denser than the lattice) and by
 * gathers (about one column per sample), rows across x = 0 and wholly negative, odd lengths
 * that leave a scalar tail. */
static void test_row_blend_kernels_agree(void **state)
{
    (void)state;
    for (size_t g = 0; g < 4; g++) {
        tf_terrain t = terrain(point_gens[g], 6.3);
        tf_fractal f;
        assert_int_equal(tf_fractal_prepare(&f, &t), 0);
        int64_t origin = -(int64_t)(f.ox * t.feature_size / 3.0); /* x = 0 near sample -origin */
        check_row_at_every_isa(&t, 3.0, origin - 150, 299);
        check_row_at_every_isa(&t, 3.0, origin - 100000, 173);
        t.octaves = 1.0;
        check_row_at_every_isa(&t, 0.95 * t.feature_size, 0, 201);
        check_row_at_every_isa(&t, 0.95 * t.feature_size, origin / 95 - 40, 97);
    }
    assert_int_equal(tf_noise_row_force_isa("no such isa"), -1);
}

static void test_prepare_rejects_grid_generators(void **state)
{
    (void)state;
    tf_fractal f;
    tf_terrain t = terrain(TF_GEN_MIDPOINT, 8);
    assert_int_equal(tf_fractal_prepare(&f, &t), -1);
    t.generator = TF_GEN_FAULT;
    assert_int_equal(tf_fractal_prepare(&f, &t), -1);
    t.generator = TF_GEN_RIDGED;
    assert_int_equal(tf_fractal_prepare(&f, &t), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_generators_deterministic_finite_and_seeded),
        cmocka_unit_test(test_row_equals_points_bitwise),
        cmocka_unit_test(test_row_blend_kernels_agree),
        cmocka_unit_test(test_fbm_terrain_is_fbm_at_mapped_point),
        cmocka_unit_test(test_seed_offset_keeps_origin_off_lattice),
        cmocka_unit_test(test_one_octave_is_the_basis),
        cmocka_unit_test(test_second_octave_weighting),
        cmocka_unit_test(test_hetero_detail_grows_with_altitude),
        cmocka_unit_test(test_ridged_bounds_and_weighting),
        cmocka_unit_test(test_prepare_rejects_grid_generators),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
