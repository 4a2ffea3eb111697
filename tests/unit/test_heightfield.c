/* test_heightfield.c: the height field structure (common/terrain/heightfield.c): the max/min mipmap
 * against brute force, its independence of the thread count, the two-triangle height_at,
 * ownership and argument checks, tf_thread_count. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include "terrain/heightfield.h"
#include "terrain/noise.h"

/* |a - b| <= tol, printing both values when not. */
#define assert_near(a, b, tol) assert_near_at((a), (b), (tol), __FILE__, __LINE__)
static void assert_near_at(double a, double b, double tol, const char *file, int line)
{
    if (!(fabs(a - b) <= tol)) {
        print_error("%.17g != %.17g (tolerance %g)\n", a, b, tol);
        _fail(file, line);
    }
}

/* Random heights in [-50, 50), deterministic from seed; caller frees. */
static float *random_heights(int k, uint64_t seed)
{
    size_t n = ((size_t)1 << k) + 1;
    float *h = malloc(n * n * sizeof *h);
    assert_non_null(h);
    for (size_t i = 0; i < n * n; i++)
        h[i] = (float)(tf_hash_unit(seed * 1000003u + i) * 100.0 - 50.0);
    return h;
}

/* Max and min of samples [i0, i1] x [j0, j1] by brute force. */
static void sample_range(const tf_heightfield *hf, int i0, int i1, int j0, int j1, float *mx,
                         float *mn)
{
    *mx = -INFINITY;
    *mn = INFINITY;
    for (int j = j0; j <= j1; j++)
        for (int i = i0; i <= i1; i++) {
            float v = hf->h[(size_t)j * hf->n + i];
            if (v > *mx)
                *mx = v;
            if (v < *mn)
                *mn = v;
        }
}

static void check_grids_brute_force(int k, int threads)
{
    float *h = random_heights(k, 7 + (uint64_t)k);
    tf_heightfield *hf = tf_heightfield_from_heights(h, k, 100.0, threads);
    free(h);
    assert_non_null(hf);
    assert_int_equal(hf->n, (1 << k) + 1);
    assert_int_equal(hf->cells, 1 << k);
    assert_int_equal(hf->levels, k + 1);
    assert_true(hf->cell == 100.0 / (1 << k));
    for (int L = 0; L < hf->levels; L++) {
        int side = hf->cells >> L, span = 1 << L;
        for (int bj = 0; bj < side; bj++)
            for (int bi = 0; bi < side; bi++) {
                float mx, mn;
                /* A level-L block covers cells [bi*span, (bi+1)*span), i.e. samples up to
                 * (bi+1)*span inclusive. */
                sample_range(hf, bi * span, (bi + 1) * span, bj * span, (bj + 1) * span, &mx, &mn);
                assert_true(hf->maxgrid[L][(size_t)bj * side + bi] == mx);
                assert_true(hf->mingrid[L][(size_t)bj * side + bi] == mn);
            }
    }
    float mx, mn;
    sample_range(hf, 0, hf->cells, 0, hf->cells, &mx, &mn);
    assert_true(hf->hmax == mx);
    assert_true(hf->hmin == mn);
    tf_heightfield_free(hf);
}

static void test_grids_match_brute_force(void **state)
{
    (void)state;
    check_grids_brute_force(0, 1);
    check_grids_brute_force(1, 1);
    check_grids_brute_force(5, 1);
    check_grids_brute_force(6, 3);
}

/* k = 9 has 512^2 level-0 entries, enough for the threaded path. */
static void test_grids_identical_for_any_thread_count(void **state)
{
    (void)state;
    const int k = 9;
    float *h = random_heights(k, 99);
    tf_heightfield *one = tf_heightfield_from_heights(h, k, 1000.0, 1);
    tf_heightfield *many = tf_heightfield_from_heights(h, k, 1000.0, 5);
    tf_heightfield *all = tf_heightfield_from_heights(h, k, 1000.0, 0);
    free(h);
    assert_non_null(one);
    assert_non_null(many);
    assert_non_null(all);
    for (int L = 0; L < one->levels; L++) {
        size_t side = (size_t)one->cells >> L, bytes = side * side * sizeof(float);
        assert_memory_equal(one->maxgrid[L], many->maxgrid[L], bytes);
        assert_memory_equal(one->mingrid[L], many->mingrid[L], bytes);
        assert_memory_equal(one->maxgrid[L], all->maxgrid[L], bytes);
        assert_memory_equal(one->mingrid[L], all->mingrid[L], bytes);
    }
    /* Level 0 spot check against the corners (the threaded bands must cover every row). */
    for (int cj = 0; cj < one->cells; cj += 37)
        for (int ci = 0; ci < one->cells; ci += 41) {
            float mx, mn;
            sample_range(one, ci, ci + 1, cj, cj + 1, &mx, &mn);
            assert_true(many->maxgrid[0][(size_t)cj * one->cells + ci] == mx);
            assert_true(many->mingrid[0][(size_t)cj * one->cells + ci] == mn);
        }
    tf_heightfield_free(one);
    tf_heightfield_free(many);
    tf_heightfield_free(all);
}

static void test_height_at_samples_and_triangles(void **state)
{
    (void)state;
    const int k = 3;
    float *h = random_heights(k, 3);
    tf_heightfield *hf = tf_heightfield_from_heights(h, k, 8.0, 1); /* cell = 1 */
    free(h);
    assert_non_null(hf);
    const int n = hf->n;
    /* Exactly the samples at grid points. */
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++)
            assert_true(tf_heightfield_height_at(hf, i, j) == (double)hf->h[j * n + i]);
    /* Cell (2, 5): the lower-right triangle below the diagonal, upper-left above it. */
    double ha = hf->h[5 * n + 2], hb = hf->h[5 * n + 3], hc = hf->h[6 * n + 3], hd = hf->h[6 * n + 2];
    assert_near(tf_heightfield_height_at(hf, 2.75, 5.25),
                        ha + (hb - ha) * 0.75 + (hc - hb) * 0.25, 1e-12);
    assert_near(tf_heightfield_height_at(hf, 2.25, 5.75),
                        ha + (hc - hd) * 0.25 + (hd - ha) * 0.75, 1e-12);
    /* On the diagonal both triangles give the average along A-C. */
    assert_near(tf_heightfield_height_at(hf, 2.5, 5.5), (ha + hc) / 2, 1e-12);
    /* Clamped outside the square. */
    assert_true(tf_heightfield_height_at(hf, -3, -1) == (double)hf->h[0]);
    assert_true(tf_heightfield_height_at(hf, 100, 100) == (double)hf->h[n * n - 1]);
    assert_near(tf_heightfield_height_at(hf, 2.5, -7),
                        tf_heightfield_height_at(hf, 2.5, 0), 0);
    tf_heightfield_free(hf);
}

/* A tilted plane is reproduced exactly by the triangles everywhere. */
static void test_height_at_tilted_plane(void **state)
{
    (void)state;
    const int k = 4, n = 17;
    float h[17 * 17];
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++)
            h[j * n + i] = (float)(0.5 * i - 0.25 * j + 3);
    tf_heightfield *hf = tf_heightfield_from_heights(h, k, 32.0, 2); /* cell = 2 */
    assert_non_null(hf);
    for (int s = 0; s < 500; s++) {
        double x = tf_hash_unit(2 * s) * 32, y = tf_hash_unit(2 * s + 1) * 32;
        assert_near(tf_heightfield_height_at(hf, x, y), 0.25 * x - 0.125 * y + 3, 1e-9);
    }
    assert_true(hf->hmax == 11.0f && hf->hmin == -1.0f);
    tf_heightfield_free(hf);
}

static void test_wrap_takes_ownership_and_checks_arguments(void **state)
{
    (void)state;
    float *h = random_heights(2, 1);
    tf_heightfield *hf = tf_heightfield_wrap(h, 2, 10.0, 1);
    assert_non_null(hf);
    assert_ptr_equal(hf->h, h); /* no copy */
    tf_heightfield_free(hf);    /* frees h too (checked under ASan) */
    tf_heightfield_free(NULL);

    assert_null(tf_heightfield_wrap(random_heights(2, 1), -1, 10.0, 1));
    assert_null(tf_heightfield_wrap(random_heights(2, 1), 2, 0.0, 1));
    assert_null(tf_heightfield_wrap(random_heights(2, 1), 2, -5.0, 1));
    assert_null(tf_heightfield_wrap(NULL, 2, 10.0, 1));
    assert_null(tf_heightfield_from_heights(NULL, 2, 10.0, 1));
    assert_null(tf_heightfield_from_heights((const float[]){0}, 40, 10.0, 1));
}

static void test_thread_count(void **state)
{
    (void)state;
    long online = sysconf(_SC_NPROCESSORS_ONLN);
    assert_int_equal(tf_thread_count(0), online < 1 ? 1 : online);
    assert_int_equal(tf_thread_count(3), 3);
    assert_int_equal(tf_thread_count(1), 1);
    assert_true(tf_thread_count(-2) >= 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_grids_match_brute_force),
        cmocka_unit_test(test_grids_identical_for_any_thread_count),
        cmocka_unit_test(test_height_at_samples_and_triangles),
        cmocka_unit_test(test_height_at_tilted_plane),
        cmocka_unit_test(test_wrap_takes_ownership_and_checks_arguments),
        cmocka_unit_test(test_thread_count),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
