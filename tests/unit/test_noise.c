/* test_noise.c: gradient noise and fBm (common/terrain/noise.c, noise.h).
 *
 * Checks the properties everything downstream relies on: the range [-1, 1], zeros at lattice
 * points, determinism per seed and variety across seeds, continuity with a bounded gradient,
 * fractional octaves, the exact gradients of noise and fBm, and that fBm's roughness follows
 * H: the structure function S(lag) = E[(f(x + lag) - f(x))^2] of fBm grows as lag^(2H)
 * between its crossover scales. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "terrain/noise.h"

/* A deterministic stream of doubles in [lo, hi) for sampling (tf_hash_unit of a counter). */
static double sample(uint64_t *counter, double lo, double hi)
{
    return lo + (hi - lo) * tf_hash_unit((*counter)++);
}

/* Largest |noise| found by random sampling plus a local hill climb from the best points. */
static double max_abs_noise2(const tf_noise *nz, int points)
{
    uint64_t c = 1;
    double best = 0.0;
    for (int k = 0; k < points; k++) {
        double x = sample(&c, -300, 300), y = sample(&c, -300, 300);
        double v = fabs(tf_noise2(nz, x, y));
        /* Climb: try steps in 8 directions, halving the step when nothing improves. */
        for (double step = 0.05; step > 1e-6;) {
            int moved = 0;
            for (int d = 0; d < 8; d++) {
                double a = d * 0.78539816339744831;
                double nx = x + step * cos(a), ny = y + step * sin(a);
                double nv = fabs(tf_noise2(nz, nx, ny));
                if (nv > v) { v = nv; x = nx; y = ny; moved = 1; }
            }
            if (!moved) step *= 0.5;
        }
        if (v > best) best = v;
    }
    return best;
}

static void test_noise2_range_within_unit(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 42);
    uint64_t c = 7;
    for (int k = 0; k < 200000; k++) {
        double v = tf_noise2(&nz, sample(&c, -1000, 1000), sample(&c, -1000, 1000));
        assert_true(v >= -1.0 && v <= 1.0);
    }
    double m = max_abs_noise2(&nz, 400);
    assert_true(m <= 1.0);
    assert_true(m > 0.6); /* the range is really used, not squashed */
}

static void test_noise3_range_within_unit(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 43);
    uint64_t c = 9;
    double m = 0.0;
    for (int k = 0; k < 300000; k++) {
        double v = tf_noise3(&nz, sample(&c, -500, 500), sample(&c, -500, 500),
                             sample(&c, -500, 500));
        assert_true(v >= -1.0 && v <= 1.0);
        if (fabs(v) > m) m = fabs(v);
    }
    assert_true(m > 0.5);
}

static void test_noise_zero_at_lattice_points(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 5);
    for (int j = -40; j <= 40; j++)
        for (int i = -40; i <= 40; i++) {
            assert_true(tf_noise2(&nz, i, j) == 0.0);
            assert_true(tf_noise3(&nz, i, j, (i * 7 + j) % 13) == 0.0);
        }
    /* ... and not zero half-way between them (in general). */
    int nonzero = 0;
    for (int i = 0; i < 100; i++)
        nonzero += tf_noise2(&nz, i + 0.5, 0.37) != 0.0;
    assert_true(nonzero > 90);
}

static void test_noise_permutation_is_valid(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 123456789);
    int seen[256] = {0};
    for (int i = 0; i < 256; i++) {
        assert_true(nz.perm[i] < 256);
        seen[nz.perm[i]]++;
        assert_int_equal(nz.perm[256 + i], nz.perm[i]);
    }
    for (int i = 0; i < 256; i++)
        assert_int_equal(seen[i], 1);
}

static void test_noise_deterministic_per_seed(void **state)
{
    (void)state;
    tf_noise a, b, other;
    tf_noise_init(&a, 2024);
    tf_noise_init(&b, 2024);
    tf_noise_init(&other, 2025);
    assert_memory_equal(a.perm, b.perm, sizeof a.perm);
    assert_memory_not_equal(a.perm, other.perm, sizeof a.perm);
    uint64_t c = 3;
    int differ = 0;
    for (int k = 0; k < 1000; k++) {
        double x = sample(&c, -50, 50), y = sample(&c, -50, 50), z = sample(&c, -50, 50);
        double va = tf_noise2(&a, x, y), vb = tf_noise2(&b, x, y);
        assert_memory_equal(&va, &vb, sizeof va);
        double wa = tf_noise3(&a, x, y, z), wb = tf_noise3(&b, x, y, z);
        assert_memory_equal(&wa, &wb, sizeof wa);
        differ += fabs(va - tf_noise2(&other, x, y)) > 1e-3;
    }
    assert_true(differ > 900);
}

/* Straightforward 2D gradient noise written from the definition (libm floor, explicit corner
 * loop, the same 16 unit gradients) to cross-check the optimised kernel. */
static double reference_noise2(const tf_noise *nz, double x, double y)
{
    static const double c1 = 0.92387953251128674, s1 = 0.38268343236508977,
                        h1 = 0.70710678118654752;
    const double g[16][2] = {{1, 0},   {c1, s1},   {h1, h1},   {s1, c1},   {0, 1},   {-s1, c1},
                             {-h1, h1}, {-c1, s1}, {-1, 0},    {-c1, -s1}, {-h1, -h1}, {-s1, -c1},
                             {0, -1},  {s1, -c1},  {h1, -h1},  {c1, -s1}};
    double x0 = floor(x), y0 = floor(y);
    double sum = 0.0;
    for (int cy = 0; cy <= 1; cy++)
        for (int cx = 0; cx <= 1; cx++) {
            int X = ((int)x0 + cx) & 255, Y = ((int)y0 + cy) & 255;
            int hash = nz->perm[nz->perm[X] + Y] & 15;
            double dx = x - (x0 + cx), dy = y - (y0 + cy);
            double fx = x - x0, fy = y - y0;
            double wx = fx * fx * fx * (fx * (fx * 6 - 15) + 10);
            double wy = fy * fy * fy * (fy * (fy * 6 - 15) + 10);
            double w = (cx ? wx : 1 - wx) * (cy ? wy : 1 - wy);
            sum += w * (g[hash][0] * dx + g[hash][1] * dy);
        }
    return sum * 1.41421;
}

static void test_noise2_matches_reference_definition(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 1);
    uint64_t c = 17;
    for (int k = 0; k < 20000; k++) {
        double x = sample(&c, -600, 600), y = sample(&c, -600, 600);
        assert_true(fabs(tf_noise2(&nz, x, y) - reference_noise2(&nz, x, y)) < 1e-13);
    }
}

/* Golden bits for seed 1, computed once on x86-64: every machine must reproduce them exactly
 * (no FMA, no libm in the noise kernel).  If this fails after an intentional change of the
 * noise, every terrain and image changes too: update the values deliberately. */
static void test_noise_golden_bits(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 1);
    assert_int_equal(nz.perm[0], 226);
    assert_int_equal(nz.perm[1], 196);
    assert_int_equal(nz.perm[255], 152);
    assert_true(tf_noise2(&nz, 3.25, -7.6) == 0x1.6f3912ea73e41p-2);
    assert_true(tf_noise3(&nz, 3.25, -7.6, 0.4) == -0x1.df72d784e0effp-4);
    assert_true(tf_fbm2(&nz, 0.3, 0.7, 0.5, 2.0, 6.5) == 0x1.c74eab5809579p-2);
    /* The lattice has period 256. */
    assert_true(tf_noise2(&nz, 3.25 + 256.0, -7.6) == tf_noise2(&nz, 3.25, -7.6));
}

static void test_noise_continuous_bounded_gradient(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 77);
    uint64_t c = 11;
    const double h = 1e-5;
    double max_slope2 = 0.0, max_slope3 = 0.0;
    for (int k = 0; k < 100000; k++) {
        double x = sample(&c, -100, 100), y = sample(&c, -100, 100), z = sample(&c, -100, 100);
        double d2 = fabs(tf_noise2(&nz, x + h, y) - tf_noise2(&nz, x, y)) / h;
        double d2y = fabs(tf_noise2(&nz, x, y + h) - tf_noise2(&nz, x, y)) / h;
        double d3 = fabs(tf_noise3(&nz, x, y, z + h) - tf_noise3(&nz, x, y, z)) / h;
        if (d2 > max_slope2) max_slope2 = d2;
        if (d2y > max_slope2) max_slope2 = d2y;
        if (d3 > max_slope3) max_slope3 = d3;
    }
    /* Each corner term g.d has slope <= |g| and the fade's slope is <= 15/8, so the partial
     * derivatives are bounded by a small constant; a jump (discontinuity) would show up as a
     * slope of order 1/h = 1e5. */
    assert_true(max_slope2 < 4.0);
    assert_true(max_slope3 < 4.0);
    assert_true(max_slope2 > 0.5); /* and it does vary */
}

static void test_noise_out_of_range_is_zero(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 1);
    assert_true(tf_noise2(&nz, NAN, 0.5) == 0.0);
    assert_true(tf_noise2(&nz, 0.5, INFINITY) == 0.0);
    assert_true(tf_noise3(&nz, 0.5, 0.5, -INFINITY) == 0.0);
    assert_true(tf_noise2(&nz, 1e300, 0.5) == 0.0);
    assert_true(tf_fbm2(&nz, 0.3, 0.3, 0.5, 2.0, NAN) == tf_fbm2(&nz, 0.3, 0.3, 0.5, 2.0, 1.0));
}

static void test_fbm_fractional_octaves(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 9);
    const double H = 0.7, lac = 2.0;
    uint64_t c = 13;
    for (int k = 0; k < 1000; k++) {
        double x = sample(&c, -20, 20), y = sample(&c, -20, 20);
        double f3 = tf_fbm2(&nz, x, y, H, lac, 3.0);
        double f4 = tf_fbm2(&nz, x, y, H, lac, 4.0);
        double f35 = tf_fbm2(&nz, x, y, H, lac, 3.5);
        /* The 4th octave alone: N(p * 8) * 8^-H; half of it for octaves = 3.5. */
        double fourth = tf_noise2(&nz, x * 8.0, y * 8.0) * pow(8.0, -H);
        assert_true(fabs((f4 - f3) - fourth) < 1e-12);
        assert_true(fabs((f35 - f3) - 0.5 * fourth) < 1e-12);
        /* Continuous in `octaves`: 3.0001 is nearly 3. */
        assert_true(fabs(tf_fbm2(&nz, x, y, H, lac, 3.0001) - f3) < 1e-3);
        /* fBm of one octave is the noise itself. */
        assert_true(tf_fbm2(&nz, x, y, H, lac, 1.0) == tf_noise2(&nz, x, y));
        double g3 = tf_fbm3(&nz, x, y, 0.5, H, lac, 3.0);
        double g4 = tf_fbm3(&nz, x, y, 0.5, H, lac, 4.0);
        double fourth3 = tf_noise3(&nz, x * 8.0, y * 8.0, 4.0) * pow(8.0, -H);
        assert_true(fabs((g4 - g3) - fourth3) < 1e-12);
    }
}

/* The largest error of an exact gradient (gx, gy) of f at (x, y) against f's central
 * differences at step h, relative to 1 + |gradient|. */
typedef double (*field2)(const tf_noise *nz, double x, double y, double *gx, double *gy);

static double noise2_field(const tf_noise *nz, double x, double y, double *gx, double *gy)
{
    return tf_noise2_gradient(nz, x, y, gx, gy);
}

static double fbm2_field(const tf_noise *nz, double x, double y, double *gx, double *gy)
{
    return tf_fbm2_gradient(nz, x, y, 0.8, 2.0, 3.6, gx, gy);
}

static double gradient_error(const tf_noise *nz, field2 f, double x, double y, double h)
{
    double gx, gy, unused_x, unused_y;
    f(nz, x, y, &gx, &gy);
    double cx = (f(nz, x + h, y, &unused_x, &unused_y) - f(nz, x - h, y, &unused_x, &unused_y)) /
                (2 * h);
    double cy = (f(nz, x, y + h, &unused_x, &unused_y) - f(nz, x, y - h, &unused_x, &unused_y)) /
                (2 * h);
    return fmax(fabs(gx - cx), fabs(gy - cy)) / (1.0 + hypot(gx, gy));
}

/* tf_noise2_gradient and tf_fbm2_gradient: the value is tf_noise2's / tf_fbm2's to the bit,
 * and the gradient is the derivative: central differences agree to their own error (h^2
 * times the third derivative, ~1e-9 here); a gradient off by a term (the fade's slope, a
 * column's y derivative, an octave's frequency) misses by 0.01 or more. */
static void test_noise_gradient_is_exact(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 5);
    uint64_t c = 17;
    double worst_noise = 0.0, worst_fbm = 0.0;
    for (int k = 0; k < 20000; k++) {
        double x = sample(&c, -60, 60), y = sample(&c, -60, 60), gx, gy;
        assert_true(tf_noise2_gradient(&nz, x, y, &gx, &gy) == tf_noise2(&nz, x, y));
        assert_true(tf_fbm2_gradient(&nz, x, y, 0.8, 2.0, 3.6, &gx, &gy) ==
                    tf_fbm2(&nz, x, y, 0.8, 2.0, 3.6));
        worst_noise = fmax(worst_noise, gradient_error(&nz, noise2_field, x, y, 1e-5));
        worst_fbm = fmax(worst_fbm, gradient_error(&nz, fbm2_field, x, y, 1e-6));
    }
    print_message("exact gradient against central differences: noise %.2g, fbm %.2g\n",
                  worst_noise, worst_fbm);
    assert_true(worst_noise < 1e-6);
    assert_true(worst_fbm < 1e-6);
    /* At a lattice point the noise is 0 and its gradient is the corner's own, scaled. */
    double gx, gy;
    assert_true(tf_noise2_gradient(&nz, 7.0, -3.0, &gx, &gy) == 0.0);
    assert_true(fabs(hypot(gx, gy) - TF_NOISE2_SCALE) < 1e-12);
    /* Out of range: 0, and so is the gradient. */
    assert_true(tf_noise2_gradient(&nz, NAN, 0.5, &gx, &gy) == 0.0 && gx == 0.0 && gy == 0.0);
    assert_true(tf_noise2_gradient(&nz, 0.5, 1e300, &gx, &gy) == 0.0 && gx == 0.0 && gy == 0.0);
}

/* Least-squares slope of log S(lag) against log lag, lags 2^-lo_exp .. 2^-hi_exp. */
static double structure_slope(const tf_noise *nz, double H, int lo_exp, int hi_exp)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int m = 0;
    for (int e = lo_exp; e >= hi_exp; e--) {
        double lag = ldexp(1.0, -e);
        double sum = 0.0;
        uint64_t c = 1000;
        const int pairs = 6000;
        for (int k = 0; k < pairs; k++) {
            double x = sample(&c, 0, 200), y = sample(&c, 0, 200);
            double d = tf_fbm2(nz, x + lag, y, H, 2.0, 14.0) - tf_fbm2(nz, x, y, H, 2.0, 14.0);
            sum += d * d;
        }
        double lx = log(lag), ly = log(sum / pairs);
        sx += lx; sy += ly; sxx += lx * lx; sxy += lx * ly; m++;
    }
    return (m * sxy - sx * sy) / (m * sxx - sx * sx);
}

static void test_fbm_roughness_follows_H(void **state)
{
    (void)state;
    tf_noise nz;
    tf_noise_init(&nz, 31);
    /* Lags 2^-10 .. 2^-3: well inside the fractal range (base scale 1, finest 2^-13). */
    double s_rough = structure_slope(&nz, 0.3, 10, 3);
    double s_smooth = structure_slope(&nz, 0.8, 10, 3);
    print_message("structure-function slope: H=0.3 -> %.3f (2H=0.6), H=0.8 -> %.3f (2H=1.6)\n",
                  s_rough, s_smooth);
    assert_true(fabs(s_rough - 0.6) < 0.15);
    assert_true(fabs(s_smooth - 1.6) < 0.15);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_noise2_range_within_unit),
        cmocka_unit_test(test_noise3_range_within_unit),
        cmocka_unit_test(test_noise_zero_at_lattice_points),
        cmocka_unit_test(test_noise_permutation_is_valid),
        cmocka_unit_test(test_noise_deterministic_per_seed),
        cmocka_unit_test(test_noise2_matches_reference_definition),
        cmocka_unit_test(test_noise_golden_bits),
        cmocka_unit_test(test_noise_continuous_bounded_gradient),
        cmocka_unit_test(test_noise_out_of_range_is_zero),
        cmocka_unit_test(test_fbm_fractional_octaves),
        cmocka_unit_test(test_noise_gradient_is_exact),
        cmocka_unit_test(test_fbm_roughness_follows_H),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
