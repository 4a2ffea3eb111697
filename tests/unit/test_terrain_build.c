/* test_terrain_build.c: the height-field build (common/terrain/terrain_build.c): tf_terrain_heights and
 * tf_heightfield_build.
 *
 * The decomposition invariant starts here: heights must be bit-identical whatever the thread
 * count.  Also: samples sit where heightfield.h says, scaled by height_scale; grid generators
 * are scaled the same way; bad sizes and out-of-memory are one-line errors, never crashes. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "terrain/fractal.h"
#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "terrain/terrain.h"
#include "terrain/terrain_build.h"

static tf_terrain terrain(enum tf_generator g, int size_exp)
{
    tf_terrain t;
    memset(&t, 0, sizeof t);
    t.generator = g;
    t.seed = 7;
    t.size_exp = size_exp;
    t.extent = 2000.0;
    t.height_scale = 250.0;
    t.feature_size = 700.0;
    t.octaves = 9.5;
    t.H = 0.8;
    t.lacunarity = 2.0;
    t.offset = g == TF_GEN_RIDGED ? 1.0 : 0.7;
    t.gain = 2.0;
    t.roughness = 0.8;
    return t;
}

static const enum tf_generator point_gens[] = {TF_GEN_FBM, TF_GEN_HETERO, TF_GEN_HYBRID,
                                               TF_GEN_RIDGED};

static void test_threaded_build_equals_single_threaded(void **state)
{
    (void)state;
    char err[256];
    for (size_t g = 0; g < 4; g++) {
        tf_terrain t = terrain(point_gens[g], 7);
        size_t bytes = (size_t)129 * 129 * sizeof(float);
        float *one = tf_terrain_heights(&t, 1, NULL, err, sizeof err);
        assert_non_null(one);
        static const int counts[] = {2, 3, 4, 7, 200};
        for (size_t c = 0; c < sizeof counts / sizeof counts[0]; c++) {
            float *many = tf_terrain_heights(&t, counts[c], NULL, err, sizeof err);
            assert_non_null(many);
            assert_memory_equal(one, many, bytes);
            free(many);
        }
        free(one);
    }
}

static void test_samples_are_scaled_points_on_the_grid(void **state)
{
    (void)state;
    char err[256];
    tf_terrain t = terrain(TF_GEN_HYBRID, 5);
    int n = 33;
    double cell = t.extent / (n - 1);
    float *h = tf_terrain_heights(&t, 2, NULL, err, sizeof err);
    assert_non_null(h);
    tf_noise nz;
    tf_noise_init(&nz, t.seed);
    for (int j = 0; j < n; j += 3)
        for (int i = 0; i < n; i += 5) {
            float want = (float)(t.height_scale *
                                 tf_terrain_point(&t, &nz, (double)i * cell, (double)j * cell));
            assert_true(h[j * n + i] == want);
        }
    free(h);
}

static void test_grid_generator_is_scaled(void **state)
{
    (void)state;
    char err[256];
    tf_terrain t = terrain(TF_GEN_MIDPOINT, 5);
    int n = 33;
    float *raw = malloc((size_t)n * n * sizeof *raw);
    assert_non_null(raw);
    assert_int_equal(tf_gen_midpoint(raw, 5, &t, 1, err, sizeof err), 0);
    float *h = tf_terrain_heights(&t, 1, NULL, err, sizeof err);
    assert_non_null(h);
    int nonzero = 0;
    for (int i = 0; i < n * n; i++) {
        assert_true(h[i] == (float)((double)raw[i] * t.height_scale));
        nonzero += raw[i] != 0.0f;
    }
    assert_true(nonzero > n * n / 2);
    free(raw);
    free(h);
}

static void test_build_wraps_heights(void **state)
{
    (void)state;
    char err[256];
    tf_scene s;
    memset(&s, 0, sizeof s);
    s.terrain = terrain(TF_GEN_RIDGED, 6);
    float *h = tf_terrain_heights(&s.terrain, 1, NULL, err, sizeof err);
    assert_non_null(h);
    tf_heightfield *hf = tf_heightfield_build(&s, 3, err, sizeof err);
    assert_non_null(hf);
    assert_int_equal(hf->n, 65);
    assert_true(hf->extent == s.terrain.extent);
    assert_memory_equal(hf->h, h, (size_t)65 * 65 * sizeof(float));
    float lo = h[0], hi = h[0];
    for (int i = 1; i < 65 * 65; i++) {
        lo = fminf(lo, h[i]);
        hi = fmaxf(hi, h[i]);
    }
    assert_true(hf->hmin == lo && hf->hmax == hi);
    tf_heightfield_free(hf);
    free(h);
}

static void test_bad_parameters_are_one_line_errors(void **state)
{
    (void)state;
    char err[256];
    tf_terrain t = terrain(TF_GEN_FBM, 0);
    assert_null(tf_terrain_heights(&t, 1, NULL, err, sizeof err));
    assert_non_null(strstr(err, "size_exp"));
    assert_null(strchr(err, '\n'));
    t.size_exp = 14;
    assert_null(tf_terrain_heights(&t, 1, NULL, err, sizeof err));
    assert_non_null(strstr(err, "size_exp"));
    t.size_exp = 4;
    t.feature_size = 0.0;
    assert_null(tf_terrain_heights(&t, 1, NULL, err, sizeof err));
    assert_non_null(strstr(err, "feature_size"));
    t.feature_size = 100.0;
    t.extent = -1.0;
    assert_null(tf_terrain_heights(&t, 1, NULL, err, sizeof err));
    assert_non_null(strstr(err, "extent"));
    /* Heights that overflow float are refused, not passed on to the tracer as inf. */
    t.extent = 1000.0;
    t.height_scale = 1e300;
    assert_null(tf_terrain_heights(&t, 1, NULL, err, sizeof err));
    assert_non_null(strstr(err, "non-finite"));
}

/* size_exp 13 needs 268 MB: with the address space capped below that, the build must report
 * out of memory in one line.  Run in a child so the cap does not outlive the test. */
static void test_out_of_memory_is_reported(void **state)
{
    (void)state;
#if defined(__SANITIZE_ADDRESS__)
    skip(); /* ASan reserves terabytes of shadow address space: RLIMIT_AS cannot be used */
#endif
    int fds[2];
    assert_int_equal(pipe(fds), 0);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        close(fds[0]);
        struct rlimit lim = {150u << 20, 150u << 20};
        char err[256] = "";
        int ok = setrlimit(RLIMIT_AS, &lim) == 0;
        tf_terrain t = terrain(TF_GEN_FBM, 13);
        float *h = ok ? tf_terrain_heights(&t, 1, NULL, err, sizeof err) : NULL;
        ssize_t w = write(fds[1], err, strlen(err));
        (void)w;
        _exit(ok && h == NULL ? 0 : 1);
    }
    close(fds[1]);
    char msg[256] = {0};
    ssize_t got = read(fds[0], msg, sizeof msg - 1);
    close(fds[0]);
    int status = 0;
    waitpid(pid, &status, 0);
    assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
    assert_true(got > 0);
    assert_non_null(strstr(msg, "out of memory"));
    assert_non_null(strstr(msg, "8193x8193"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_threaded_build_equals_single_threaded),
        cmocka_unit_test(test_samples_are_scaled_points_on_the_grid),
        cmocka_unit_test(test_grid_generator_is_scaled),
        cmocka_unit_test(test_build_wraps_heights),
        cmocka_unit_test(test_bad_parameters_are_one_line_errors),
        cmocka_unit_test(test_out_of_memory_is_reported),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
