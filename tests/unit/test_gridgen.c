/* test_gridgen.c: unit tests of the whole-grid terrain generators (midpoint.c, fault.c,
 * subdivide.c, weathering.c, gridgen.c): Koh & Hearn's envelope bound, the roughness trend of
 * free diamond-square, determinism from the seed, bit-identical output for any thread count,
 * the smoothing of Krten's wind and rain filters, talus relaxation with conservation of
 * material, Ammeter's water parameter, and parameter validation.  Grids are small (k <= 9). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "terrain/gridgen.h"
#include "terrain/terrain.h"

static size_t side(int k) { return ((size_t)1 << k) + 1; }

static float *grid(int k)
{
    float *h = malloc(side(k) * side(k) * sizeof *h);
    assert_non_null(h);
    return h;
}

static tf_terrain base_terrain(void)
{
    tf_terrain t;
    memset(&t, 0, sizeof t);
    t.seed = 42;
    t.roughness = 0.8;
    t.faults = 200;
    t.fault_step = 1.0;
    t.erosion_k = 0.5;
    t.sub_M = 0.5;
    t.sub_E = 2.0;
    t.sub_W = 0.3;
    t.thermal_iterations = 50;
    t.talus_deg = 30.0;
    return t;
}

/* A 3x3 control grid: a pyramid with its apex in the middle, plus a tilt. */
static void pyramid_envelope(tf_terrain *t, double tol)
{
    static const double e[9] = {0.0, 0.1, 0.2, 0.1, 1.0, 0.3, 0.2, 0.3, 0.4};
    t->envelope_n = 3;
    memcpy(t->envelope, e, sizeof e);
    t->envelope_tolerance = tol;
}

/* Mean |h(i + lag, j) - h(i, j)| over the grid, x direction. */
static double mean_increment(const float *h, size_t n, size_t lag)
{
    double sum = 0.0;
    for (size_t j = 0; j < n; j++)
        for (size_t i = 0; i + lag < n; i++)
            sum += fabs((double)h[j * n + i + lag] - h[j * n + i]);
    return sum / (double)(n * (n - lag));
}

/* Mean absolute difference between 4-neighbours (both axes). */
static double neighbour_roughness(const float *h, size_t n)
{
    double sum = 0.0;
    for (size_t j = 0; j < n; j++)
        for (size_t i = 0; i < n; i++) {
            if (i + 1 < n) sum += fabs((double)h[j * n + i + 1] - h[j * n + i]);
            if (j + 1 < n) sum += fabs((double)h[(j + 1) * n + i] - h[j * n + i]);
        }
    return sum / (double)(2 * n * (n - 1));
}

/* Largest |difference| between 4-neighbours divided by the cell size: the steepest slope. */
static double max_slope(const float *h, size_t n, double cell)
{
    double m = 0.0;
    for (size_t j = 0; j < n; j++)
        for (size_t i = 0; i < n; i++) {
            if (i + 1 < n) m = fmax(m, fabs((double)h[j * n + i + 1] - h[j * n + i]));
            if (j + 1 < n) m = fmax(m, fabs((double)h[(j + 1) * n + i] - h[j * n + i]));
        }
    return m / cell;
}

static double grid_sum(const float *h, size_t count)
{
    double s = 0.0;
    for (size_t q = 0; q < count; q++)
        s += h[q];
    return s;
}

/* ---- Koh & Hearn envelope ---- */

static void test_envelope_plane_interpolation(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    pyramid_envelope(&t, 0.1);
    int n = 17; /* control points fall on multiples of 8 */
    for (int cj = 0; cj < 3; cj++)
        for (int ci = 0; ci < 3; ci++)
            assert_true(tf_envelope_at(&t, n, ci * 8, cj * 8) == t.envelope[cj * 3 + ci]);
    /* (2, 6) in the first control square, fx = 0.25 < fy = 0.75: triangle (0,0) (0,1) (1,1):
     * z00 + fy (z01 - z00) + fx (z11 - z01) = 0 + 0.75 * 0.1 + 0.25 * 0.9. */
    assert_true(fabs(tf_envelope_at(&t, n, 2, 6) - (0.075 + 0.225)) < 1e-15);
    /* (6, 2): fx = 0.75 >= fy: triangle (0,0) (1,0) (1,1): 0.75 * 0.1 + 0.25 * 0.9. */
    assert_true(fabs(tf_envelope_at(&t, n, 6, 2) - (0.075 + 0.225)) < 1e-15);
    /* General triangulation: a 4x4 control grid on a 9x9 height grid (not aligned). */
    t.envelope_n = 4;
    for (int q = 0; q < 16; q++)
        t.envelope[q] = 0.5 * (q % 4) + 0.25 * (q / 4); /* a plane: interpolation is exact */
    for (int j = 0; j < 9; j++)
        for (int i = 0; i < 9; i++)
            assert_true(fabs(tf_envelope_at(&t, 9, i, j) - (0.5 * 3 * i / 8.0 + 0.25 * 3 * j / 8.0)) <
                        1e-12);
}

static void assert_inside_envelope(const tf_terrain *t, int k, int threads)
{
    size_t n = side(k);
    float *h = grid(k);
    char err[256] = "";
    assert_int_equal(tf_gen_midpoint(h, k, t, threads, err, sizeof err), 0);
    double maxdev = 0.0;
    for (size_t j = 0; j < n; j++)
        for (size_t i = 0; i < n; i++) {
            double c = tf_envelope_at(t, (int)n, (int)i, (int)j);
            double d = fabs((double)h[j * n + i] - c);
            assert_true(d <= t->envelope_tolerance);
            maxdev = fmax(maxdev, d);
        }
    /* Not a copy of the envelope: the fractal detail uses a fair part of the band. */
    assert_true(maxdev > 0.1 * t->envelope_tolerance);
    free(h);
}

static void test_midpoint_stays_inside_envelope(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    pyramid_envelope(&t, 0.05);
    assert_inside_envelope(&t, 8, 1);
    t.roughness = 0.0; /* no decay: the band limit must do the work */
    t.seed = 7;
    assert_inside_envelope(&t, 8, 2);
    pyramid_envelope(&t, 1e-4); /* a tight band, close to float resolution of the heights */
    assert_inside_envelope(&t, 7, 1);
    t.envelope_n = 5; /* a 5x5 envelope over a grid that does not align with 3x3 */
    for (int q = 0; q < 25; q++)
        t.envelope[q] = tf_grid_unit(tf_hash64((uint64_t)q));
    t.envelope_tolerance = 0.2;
    assert_inside_envelope(&t, 6, 3);
}

static void test_midpoint_roughness_trend(void **state)
{
    (void)state;
    int k = 9;
    size_t n = side(k);
    float *smooth = grid(k), *rough = grid(k);
    char err[256] = "";
    tf_terrain t = base_terrain();
    t.roughness = 1.0;
    assert_int_equal(tf_gen_midpoint(smooth, k, &t, 1, err, sizeof err), 0);
    t.roughness = 0.3;
    assert_int_equal(tf_gen_midpoint(rough, k, &t, 1, err, sizeof err), 0);
    double s1 = mean_increment(smooth, n, 1), s64 = mean_increment(smooth, n, 64);
    double r1 = mean_increment(rough, n, 1), r64 = mean_increment(rough, n, 64);
    /* Higher roughness (H) means smaller small-lag increments, absolutely and relative to the
     * large-lag ones (fBm: increment ~ lag^H, so the ratio is ~ 64^-H). */
    assert_true(s1 < r1);
    assert_true(s1 / s64 < 0.5 * (r1 / r64));
    free(smooth);
    free(rough);
}

static void test_midpoint_small_grid_is_subsample(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    char err[256] = "";
    for (int env = 0; env < 2; env++) {
        if (env)
            pyramid_envelope(&t, 0.1);
        float *small = grid(6), *big = grid(8);
        assert_int_equal(tf_gen_midpoint(small, 6, &t, 1, err, sizeof err), 0);
        assert_int_equal(tf_gen_midpoint(big, 8, &t, 2, err, sizeof err), 0);
        for (size_t j = 0; j < side(6); j++)
            for (size_t i = 0; i < side(6); i++)
                assert_true(small[j * side(6) + i] == big[4 * j * side(8) + 4 * i]);
        free(small);
        free(big);
    }
}

/* ---- determinism ---- */

typedef int (*gen_fn)(float *, int, const tf_terrain *, int, char *, size_t);

static void assert_thread_invariant(gen_fn gen, const tf_terrain *t, int k)
{
    static const int threads[] = {2, 3, 7};
    size_t count = side(k) * side(k);
    float *ref = grid(k), *h = grid(k);
    char err[256] = "";
    assert_int_equal(gen(ref, k, t, 1, err, sizeof err), 0);
    for (size_t q = 0; q < sizeof threads / sizeof threads[0]; q++) {
        memset(h, 0xff, count * sizeof *h);
        assert_int_equal(gen(h, k, t, threads[q], err, sizeof err), 0);
        assert_memory_equal(ref, h, count * sizeof *h);
    }
    free(ref);
    free(h);
}

static void test_generators_identical_for_any_thread_count(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    t.wind_passes = 1;
    t.rain_passes = 2;
    assert_thread_invariant(tf_gen_midpoint, &t, 9);
    assert_thread_invariant(tf_gen_fault, &t, 9);
    assert_thread_invariant(tf_gen_subdivide, &t, 9);
    pyramid_envelope(&t, 0.1);
    assert_thread_invariant(tf_gen_midpoint, &t, 9);
}

static void test_thermal_identical_for_any_thread_count(void **state)
{
    (void)state;
    int k = 8;
    size_t n = side(k), count = n * n;
    tf_terrain t = base_terrain();
    float *src = grid(k), *ref = grid(k), *h = grid(k);
    char err[256] = "";
    assert_int_equal(tf_gen_midpoint(src, k, &t, 1, err, sizeof err), 0);
    for (size_t q = 0; q < count; q++)
        src[q] *= 400.0f; /* world heights over cells of 1: many slopes beyond the talus */
    memcpy(ref, src, count * sizeof *src);
    assert_int_equal(tf_weather_thermal(ref, (int)n, 1.0, &t, 1, err, sizeof err), 0);
    static const int threads[] = {2, 3, 7};
    for (size_t q = 0; q < 3; q++) {
        memcpy(h, src, count * sizeof *src);
        assert_int_equal(tf_weather_thermal(h, (int)n, 1.0, &t, threads[q], err, sizeof err), 0);
        assert_memory_equal(ref, h, count * sizeof *h);
    }
    free(src);
    free(ref);
    free(h);
}

static void assert_seed_determines(gen_fn gen, tf_terrain t, int k)
{
    size_t count = side(k) * side(k);
    float *a = grid(k), *b = grid(k);
    char err[256] = "";
    assert_int_equal(gen(a, k, &t, 1, err, sizeof err), 0);
    assert_int_equal(gen(b, k, &t, 1, err, sizeof err), 0);
    assert_memory_equal(a, b, count * sizeof *a);
    t.seed += 1;
    assert_int_equal(gen(b, k, &t, 1, err, sizeof err), 0);
    size_t differ = 0;
    for (size_t q = 0; q < count; q++)
        differ += a[q] != b[q];
    assert_true(differ > count / 2);
    free(a);
    free(b);
}

static void test_fault_deterministic_per_seed(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    t.wind_passes = 1;
    t.rain_passes = 1;
    assert_seed_determines(tf_gen_fault, t, 7);
    /* Normalised to [0, 1], using the whole range. */
    int k = 7;
    size_t count = side(k) * side(k);
    float *h = grid(k);
    char err[256] = "";
    assert_int_equal(tf_gen_fault(h, k, &t, 1, err, sizeof err), 0);
    float lo = h[0], hi = h[0];
    for (size_t q = 0; q < count; q++) {
        lo = fminf(lo, h[q]);
        hi = fmaxf(hi, h[q]);
    }
    assert_true(lo == 0.0f);
    assert_true(hi == 1.0f);
    free(h);
}

static void test_subdivide_deterministic_per_seed(void **state)
{
    (void)state;
    assert_seed_determines(tf_gen_subdivide, base_terrain(), 7);
}

/* ---- Krten's filters ---- */

static double fault_roughness(int wind, int rain, double k_coef)
{
    int k = 8;
    tf_terrain t = base_terrain();
    t.wind_passes = wind;
    t.rain_passes = rain;
    t.erosion_k = k_coef;
    float *h = grid(k);
    char err[256] = "";
    assert_int_equal(tf_gen_fault(h, k, &t, 2, err, sizeof err), 0);
    double r = neighbour_roughness(h, side(k)); /* output is normalised: range 1 */
    free(h);
    return r;
}

static void test_wind_and_rain_filters_smooth(void **state)
{
    (void)state;
    double raw = fault_roughness(0, 0, 0.5);
    double wind = fault_roughness(1, 0, 0.5);
    double wind3 = fault_roughness(3, 0, 0.5);
    double rain = fault_roughness(0, 1, 0.5);
    double rain3 = fault_roughness(0, 3, 0.5);
    double strong = fault_roughness(0, 1, 0.9);
    assert_true(wind < raw);
    assert_true(wind3 < wind);
    assert_true(rain < raw);
    assert_true(rain3 < rain);
    assert_true(strong < rain); /* a larger coefficient smooths more */
}

/* ---- thermal weathering ---- */

static void test_thermal_relaxes_towards_talus_and_conserves(void **state)
{
    (void)state;
    int k = 5;
    size_t n = side(k), count = n * n;
    double cell = 2.0;
    tf_terrain t = base_terrain();
    t.talus_deg = 30.0;
    double talus = tan(30.0 * M_PI / 180.0);
    float *h = grid(k);
    char err[256] = "";
    /* Rough terrain: midpoint with low H, scaled so slopes reach many times the talus. */
    t.roughness = 0.3;
    assert_int_equal(tf_gen_midpoint(h, k, &t, 1, err, sizeof err), 0);
    for (size_t q = 0; q < count; q++)
        h[q] *= 20.0f;
    double before = max_slope(h, n, cell), sum0 = grid_sum(h, count);
    assert_true(before > 4.0 * talus);

    t.thermal_iterations = 20;
    assert_int_equal(tf_weather_thermal(h, (int)n, cell, &t, 1, err, sizeof err), 0);
    double mid = max_slope(h, n, cell);
    t.thermal_iterations = 5000;
    assert_int_equal(tf_weather_thermal(h, (int)n, cell, &t, 1, err, sizeof err), 0);
    double after = max_slope(h, n, cell), sum1 = grid_sum(h, count);
    print_message("slope before %g after 20: %g after 5020: %g talus %g\n", before, mid, after, talus);
    assert_true(mid < before);
    assert_true(after < mid);
    assert_true(after < 1.02 * talus); /* asymptotically the talus slope */
    assert_true(after > 0.9 * talus);  /* ... from above: stable slopes are not flattened */
    /* Material is conserved to float rounding: ~1e-7 relative per sample and step. */
    assert_true(fabs(sum1 - sum0) <= 1e-5 * (fabs(sum0) + count));
    free(h);
}

static void test_thermal_leaves_stable_slopes_alone(void **state)
{
    (void)state;
    size_t n = 33;
    float *h = malloc(n * n * sizeof *h), *orig = malloc(n * n * sizeof *h);
    assert_non_null(h);
    assert_non_null(orig);
    for (size_t j = 0; j < n; j++)
        for (size_t i = 0; i < n; i++)
            h[j * n + i] = (float)(0.3 * i + 0.2 * j); /* slopes 0.3 and 0.2 < tan 30 = 0.577 */
    memcpy(orig, h, n * n * sizeof *h);
    tf_terrain t = base_terrain();
    char err[256] = "";
    assert_int_equal(tf_weather_thermal(h, (int)n, 1.0, &t, 2, err, sizeof err), 0);
    assert_memory_equal(orig, h, n * n * sizeof *h);
    free(h);
    free(orig);
}

/* ---- Ammeter & Mikhailyuk water ---- */

static double water_fraction(double W, double *lo, double *hi)
{
    int k = 7;
    size_t count = side(k) * side(k);
    tf_terrain t = base_terrain();
    t.sub_W = W;
    float *h = grid(k);
    char err[256] = "";
    assert_int_equal(tf_gen_subdivide(h, k, &t, 1, err, sizeof err), 0);
    size_t wet = 0;
    *lo = *hi = h[0];
    for (size_t q = 0; q < count; q++) {
        wet += h[q] < 0.0f;
        *lo = fmin(*lo, h[q]);
        *hi = fmax(*hi, h[q]);
    }
    free(h);
    return (double)wet / (double)count;
}

static void test_subdivide_water_parameter(void **state)
{
    (void)state;
    double lo, hi;
    /* W = 0: every displacement (R - 0) * ... >= 0 and corners >= 0: no water at all. */
    assert_true(water_fraction(0.0, &lo, &hi) == 0.0);
    assert_true(lo >= 0.0);
    /* W = 1: every displacement <= 0 and corners <= 0: nothing above sea level. */
    water_fraction(1.0, &lo, &hi);
    assert_true(hi <= 0.0);
    /* In between, more W, more water. */
    double w2 = water_fraction(0.2, &lo, &hi), w5 = water_fraction(0.5, &lo, &hi),
           w8 = water_fraction(0.8, &lo, &hi);
    assert_true(w2 < w5);
    assert_true(w5 < w8);
}

static void test_subdivide_formula_first_level(void **state)
{
    (void)state;
    /* k = 1: corners (level 0) and the level-1 points, checked against the formula. */
    tf_terrain t = base_terrain();
    float h[9];
    char err[256] = "";
    assert_int_equal(tf_gen_subdivide(h, 1, &t, 1, err, sizeof err), 0);
    double A = ((double)h[0] + h[2]) * 0.5; /* bottom edge midpoint (1, 0) */
    double R = tf_grid_unit(tf_grid_key(t.seed, TF_STREAM_SUBDIVIDE, 1, 1u << 12, 0));
    double H = A + (R - t.sub_W) * (1 + A) * (1 + A) * t.sub_M / pow(1.0, t.sub_E);
    assert_true(h[1] == (float)H);
    A = ((double)h[0] + h[2] + h[6] + h[8]) * 0.25; /* the centre */
    R = tf_grid_unit(tf_grid_key(t.seed, TF_STREAM_SUBDIVIDE, 1, 1u << 12, 1u << 12));
    assert_true(h[4] == (float)(A + (R - t.sub_W) * (1 + A) * (1 + A) * t.sub_M));
}

/* ---- validation ---- */

static void assert_rejects(gen_fn gen, const tf_terrain *t, int k, const char *word)
{
    float h[25];
    char err[256] = "";
    assert_int_equal(gen(h, k, t, 1, err, sizeof err), -1);
    assert_non_null(strstr(err, word));
    assert_null(strchr(err, '\n'));
}

static void test_invalid_parameters_rejected(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    assert_rejects(tf_gen_midpoint, &t, 14, "size exponent");
    assert_rejects(tf_gen_midpoint, &t, 0, "size exponent");
    tf_terrain e = t;
    e.envelope_n = 1;
    assert_rejects(tf_gen_midpoint, &e, 2, "envelope_n");
    e.envelope_n = TF_ENVELOPE_MAX + 1;
    assert_rejects(tf_gen_midpoint, &e, 2, "envelope_n");
    pyramid_envelope(&e, 0.0);
    assert_rejects(tf_gen_midpoint, &e, 2, "envelope_tolerance");
    pyramid_envelope(&e, 0.1);
    e.envelope[4] = NAN;
    assert_rejects(tf_gen_midpoint, &e, 2, "envelope value");
    e = t;
    e.roughness = -1.0;
    assert_rejects(tf_gen_midpoint, &e, 2, "roughness");
    e = t;
    e.erosion_k = 1.0;
    assert_rejects(tf_gen_fault, &e, 2, "erosion_k");
    e = t;
    e.faults = -3;
    assert_rejects(tf_gen_fault, &e, 2, "faults");
    e = t;
    e.sub_E = 1.0;
    assert_rejects(tf_gen_subdivide, &e, 2, "E =");
    e = t;
    e.sub_W = 1.5;
    assert_rejects(tf_gen_subdivide, &e, 2, "W =");
    e = t;
    e.sub_M = 0.0;
    assert_rejects(tf_gen_subdivide, &e, 2, "M =");
}

static void test_subdivide_overflow_reported(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    t.sub_M = 1e6;
    t.sub_E = 1.01;
    t.sub_W = 0.0;
    float *h = grid(8);
    char err[256] = "";
    assert_int_equal(tf_gen_subdivide(h, 8, &t, 3, err, sizeof err), -1);
    assert_non_null(strstr(err, "overflow"));
    free(h);
}

static void test_thermal_invalid_parameters_rejected(void **state)
{
    (void)state;
    tf_terrain t = base_terrain();
    float h[16] = {0};
    char err[256] = "";
    assert_int_equal(tf_weather_thermal(h, 4, 0.0, &t, 1, err, sizeof err), -1);
    assert_non_null(strstr(err, "cell"));
    t.talus_deg = 90.0;
    assert_int_equal(tf_weather_thermal(h, 4, 1.0, &t, 1, err, sizeof err), -1);
    assert_non_null(strstr(err, "talus"));
    t.talus_deg = 30.0;
    assert_int_equal(tf_weather_thermal(h, 1, 1.0, &t, 1, err, sizeof err), -1);
    assert_non_null(strstr(err, "side"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_envelope_plane_interpolation),
        cmocka_unit_test(test_midpoint_stays_inside_envelope),
        cmocka_unit_test(test_midpoint_roughness_trend),
        cmocka_unit_test(test_midpoint_small_grid_is_subsample),
        cmocka_unit_test(test_generators_identical_for_any_thread_count),
        cmocka_unit_test(test_thermal_identical_for_any_thread_count),
        cmocka_unit_test(test_fault_deterministic_per_seed),
        cmocka_unit_test(test_subdivide_deterministic_per_seed),
        cmocka_unit_test(test_wind_and_rain_filters_smooth),
        cmocka_unit_test(test_thermal_relaxes_towards_talus_and_conserves),
        cmocka_unit_test(test_thermal_leaves_stable_slopes_alone),
        cmocka_unit_test(test_subdivide_water_parameter),
        cmocka_unit_test(test_subdivide_formula_first_level),
        cmocka_unit_test(test_invalid_parameters_rejected),
        cmocka_unit_test(test_subdivide_overflow_reported),
        cmocka_unit_test(test_thermal_invalid_parameters_rejected),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
