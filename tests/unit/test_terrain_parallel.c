/* test_terrain_parallel.c: the whole terrain build is bit-identical whatever the thread count.
 *
 * Every generator (fbm, hetero, hybrid, ridged, midpoint, fault, subdivide), bare and with
 * thermal weathering, is built at 257^2 (and fbm and midpoint at 1025^2) with 1, 2, 3 and 7
 * threads; every height and every level of the max and min grids must equal the 1-thread
 * build's, compared with memcmp.  Odd counts (3, 7) split rows into uneven bands, so an
 * off-by-one at a band's edge shows as a wrong or missing row; and every row of a point
 * generator's build must be the row evaluator's own, whoever claimed it. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/fractal.h"
#include "terrain/heightfield.h"
#include "terrain/terrain_build.h"

static tf_terrain terrain(enum tf_generator g, int size_exp, int weathered)
{
    tf_terrain t;
    memset(&t, 0, sizeof t);
    t.generator = g;
    t.seed = 11;
    t.size_exp = size_exp;
    t.extent = 3000.0;
    t.height_scale = 400.0;
    t.feature_size = 900.0;
    t.octaves = 8.5;
    t.H = 0.8;
    t.lacunarity = 2.0;
    t.offset = g == TF_GEN_RIDGED ? 1.0 : 0.7;
    t.gain = 2.0;
    t.roughness = 0.75;
    t.envelope_tolerance = 1.0;
    t.faults = 60;
    t.fault_step = 0.05;
    t.wind_passes = 1;
    t.rain_passes = 1;
    t.erosion_k = 0.5;
    t.sub_M = 1.0;
    t.sub_E = 2.0;
    t.sub_W = 0.3;
    t.thermal_iterations = weathered ? 4 : 0;
    t.talus_deg = 30.0;
    return t;
}

static tf_heightfield *build(const tf_terrain *t, int threads)
{
    char err[256] = "";
    float *h = tf_terrain_heights(t, threads, NULL, err, sizeof err);
    if (!h)
        print_error("%s\n", err);
    assert_non_null(h);
    tf_heightfield *hf = tf_heightfield_wrap(h, t->size_exp, t->extent, threads);
    assert_non_null(hf);
    return hf;
}

/* Every sample and every grid level of a and b, byte for byte. */
static void assert_same_field(const tf_heightfield *a, const tf_heightfield *b)
{
    assert_int_equal(a->n, b->n);
    assert_int_equal(a->levels, b->levels);
    assert_memory_equal(a->h, b->h, (size_t)a->n * a->n * sizeof(float));
    for (int L = 0; L < a->levels; L++) {
        size_t side = (size_t)a->cells >> L;
        assert_memory_equal(a->maxgrid[L], b->maxgrid[L], side * side * sizeof(float));
        assert_memory_equal(a->mingrid[L], b->mingrid[L], side * side * sizeof(float));
    }
    assert_true(memcmp(&a->hmin, &b->hmin, sizeof a->hmin) == 0);
    assert_true(memcmp(&a->hmax, &b->hmax, sizeof a->hmax) == 0);
}

static void check_generator(enum tf_generator g, int size_exp, int weathered)
{
    tf_terrain t = terrain(g, size_exp, weathered);
    tf_heightfield *one = build(&t, 1);
    static const int counts[] = {2, 3, 7};
    for (size_t c = 0; c < sizeof counts / sizeof counts[0]; c++) {
        tf_heightfield *many = build(&t, counts[c]);
        assert_same_field(one, many);
        tf_heightfield_free(many);
    }
    tf_heightfield_free(one);
}

static const enum tf_generator all_gens[] = {TF_GEN_FBM,      TF_GEN_HETERO, TF_GEN_HYBRID,
                                             TF_GEN_RIDGED,   TF_GEN_MIDPOINT, TF_GEN_FAULT,
                                             TF_GEN_SUBDIVIDE};

static void test_every_generator_at_257(void **state)
{
    (void)state;
    for (size_t g = 0; g < sizeof all_gens / sizeof all_gens[0]; g++)
        check_generator(all_gens[g], 8, 0);
}

static void test_every_generator_weathered_at_257(void **state)
{
    (void)state;
    for (size_t g = 0; g < sizeof all_gens / sizeof all_gens[0]; g++)
        check_generator(all_gens[g], 8, 1);
}

static void test_fbm_and_midpoint_at_1025(void **state)
{
    (void)state;
    check_generator(TF_GEN_FBM, 10, 0);
    check_generator(TF_GEN_RIDGED, 10, 1);
    check_generator(TF_GEN_MIDPOINT, 10, 0);
}

/* Grids wrapped around the same heights: every level whatever the thread count (the levels
 * above TF_HF_PARALLEL_MIN entries are split by threads, the small ones are not). */
static void test_grids_of_given_heights(void **state)
{
    (void)state;
    int k = 10, n = (1 << k) + 1;
    float *h = malloc((size_t)n * n * sizeof *h);
    assert_non_null(h);
    uint64_t x = 99;
    for (size_t i = 0; i < (size_t)n * n; i++) {
        x = x * 6364136223846793005ULL + 1442695040888963407ULL;
        h[i] = (float)(int32_t)(x >> 40) * 0x1p-12f;
    }
    tf_heightfield *one = tf_heightfield_from_heights(h, k, 100.0, 1);
    assert_non_null(one);
    static const int counts[] = {2, 3, 7, 64};
    for (size_t c = 0; c < sizeof counts / sizeof counts[0]; c++) {
        tf_heightfield *many = tf_heightfield_from_heights(h, k, 100.0, counts[c]);
        assert_non_null(many);
        assert_same_field(one, many);
        tf_heightfield_free(many);
    }
    tf_heightfield_free(one);
    free(h);
}

/* Each row of a point generator's build, on any thread count, is the row evaluator's for that
 * row's y: a reference that does not go through the build's sharing of rows. */
static void test_rows_are_the_row_evaluators(void **state)
{
    (void)state;
    tf_terrain t = terrain(TF_GEN_RIDGED, 8, 0);
    int n = 257;
    double cell = t.extent / (n - 1);
    tf_fractal f;
    tf_noise nz;
    assert_int_equal(tf_fractal_prepare(&f, &t), 0);
    tf_noise_init(&nz, t.seed);
    float row[257];
    static const int counts[] = {1, 2, 3, 7};
    for (size_t c = 0; c < 4; c++) {
        char err[256];
        float *h = tf_terrain_heights(&t, counts[c], NULL, err, sizeof err);
        assert_non_null(h);
        for (int j = 0; j < n; j++) {
            tf_fractal_row(&f, &nz, (double)j * cell, cell, n, t.height_scale, row, NULL);
            assert_memory_equal(h + (size_t)j * n, row, sizeof row);
        }
        free(h);
    }
}

/* A build that overflows float names the same first bad sample whatever the thread count
 * (the check splits rows over the threads). */
static void test_non_finite_report_is_the_same(void **state)
{
    (void)state;
    static const enum tf_generator gens[] = {TF_GEN_FBM, TF_GEN_MIDPOINT};
    for (size_t g = 0; g < 2; g++) {
        tf_terrain t = terrain(gens[g], 9, 0);
        char one[256] = "", many[256] = "";
        t.height_scale = 1.0;
        float *h = tf_terrain_heights(&t, 1, NULL, one, sizeof one);
        assert_non_null(h);
        float top = 0.0f;
        for (size_t i = 0; i < (size_t)513 * 513; i++)
            top = fabsf(h[i]) > top ? fabsf(h[i]) : top;
        free(h);
        t.height_scale = 3.4e38 / (0.9 * top); /* only the highest tenth overflows */
        assert_null(tf_terrain_heights(&t, 1, NULL, one, sizeof one));
        assert_non_null(strstr(one, "non-finite"));
        static const int counts[] = {2, 3, 7};
        for (size_t c = 0; c < 3; c++) {
            assert_null(tf_terrain_heights(&t, counts[c], NULL, many, sizeof many));
            assert_string_equal(one, many);
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_generator_at_257),
        cmocka_unit_test(test_every_generator_weathered_at_257),
        cmocka_unit_test(test_fbm_and_midpoint_at_1025),
        cmocka_unit_test(test_grids_of_given_heights),
        cmocka_unit_test(test_rows_are_the_row_evaluators),
        cmocka_unit_test(test_non_finite_report_is_the_same),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
