/* test_erosion.c: the fluvial erosion model (terrain/erosion.h, erosion_state.h, erosion_run.h).
 * Bedrock + talus + silt + load plus what left at the outlet is conserved to the last quantum,
 * and water changes only by rain, evaporation and outflow; the result is bit-identical for every
 * tile shape, halo and thread count and on every kernel (AVX-512, AVX2, portable), and the same
 * bits as the first kernel's; a lone wet vertex sends the same water to its four neighbours, a
 * flat dry plane only collects rain, and a slope erodes at the top and deposits below. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>
#include <sodium.h>
#include "terrain/erosion.h"
#include "terrain/erosion_run.h"
#include "terrain/erosion_state.h"
#include "terrain/terrain_build.h"
#include "terrain/eroded.h"
#include "erosion_tuples.h"

static tf_erosion_keys keys(int steps)
{
    tf_erosion_keys k = {0};
    k.fluvial_steps = steps;
    k.capacity = 5.0;
    k.deposition = 0.1;
    k.softness = 0.3;
    k.silt_softness = 3.0;
    k.talus_softness = 2.0;
    k.rain = 0.5;
    k.rain_interval = 10;
    k.rain_altitude = 1.0;
    k.creep = 0.02;
    k.evaporation = 0.001;
    k.strata = 7.0;
    k.strata_contrast = 0.6;
    k.hardness_noise = 0.5;
    k.rain_noise = 0.5;
    return k;
}

/* An fBm grid of (2^e + 1)^2 heights. */
static float *fbm_heights(int e)
{
    tf_terrain t = {0};
    t.generator = TF_GEN_FBM;
    t.seed = 5;
    t.size_exp = e;
    t.extent = 1000;
    t.height_scale = 200;
    t.feature_size = 400;
    t.octaves = 6;
    t.H = 0.8;
    t.lacunarity = 2.0;
    char err[256];
    float *h = tf_terrain_heights(&t, 1, NULL, err, sizeof err);
    assert_non_null(h);
    return h;
}

typedef struct {
    tf_erosion_model m;
    tf_erosion_state st;
    tf_erosion_tally tally;
} run;

static void start(run *r, const float *h, int n, const tf_erosion_keys *k)
{
    float lo = h[0], hi = h[0];
    for (size_t i = 0; i < (size_t)n * (size_t)n; i++) {
        lo = h[i] < lo ? h[i] : lo;
        hi = h[i] > hi ? h[i] : hi;
    }
    char err[256];
    memset(r, 0, sizeof *r);
    assert_int_equal(tf_erosion_model_init(&r->m, k, 9, n, lo, hi, err, sizeof err), 0);
    assert_int_equal(tf_erosion_state_from_heights(&r->st, &r->m, k, h), 0);
}

static void go(run *r, int first, int steps, int threads, int halo, int tw, int th)
{
    char err[256];
    tf_erosion_run_opts o = {first, steps, threads, halo, tw, th};
    assert_int_equal(tf_erosion_run(&r->st, &r->m, &o, &r->tally, err, sizeof err), 0);
}

static void assert_same_state(const tf_erosion_state *a, const tf_erosion_state *b)
{
    size_t bytes = (size_t)a->n * (size_t)a->n * 4;
    assert_memory_equal(a->b, b->b, bytes);
    assert_memory_equal(a->t, b->t, bytes);
    assert_memory_equal(a->d, b->d, bytes);
    assert_memory_equal(a->w, b->w, bytes);
    assert_memory_equal(a->s, b->s, bytes);
    assert_memory_equal(a->flow, b->flow, bytes);
}

static void test_mass_conserved(void **state)
{
    (void)state;
    int e = 6, n = 65;
    float *h = fbm_heights(e);
    tf_erosion_keys k = keys(300);
    run r;
    start(&r, h, n, &k);
    int64_t solid0 = tf_erosion_solid(&r.st, n), water0 = tf_erosion_water(&r.st, n);
    go(&r, 0, 300, 2, 8, 0, 0);
    int64_t solid1 = tf_erosion_solid(&r.st, n), water1 = tf_erosion_water(&r.st, n);
    assert_true(r.tally.rain > 0);
    assert_true(r.tally.out_water > 0);
    assert_true(r.tally.evaporated > 0);
    assert_int_equal(solid1 + r.tally.out_load, solid0);
    assert_int_equal(water1 + r.tally.out_water + r.tally.evaporated, water0 + r.tally.rain);
    /* something happened: the ground moved */
    float *after = malloc((size_t)n * n * sizeof *after);
    tf_erosion_heights(&r.st, &r.m, after);
    double moved = 0;
    for (int i = 0; i < n * n; i++)
        moved += fabs((double)after[i] - h[i]);
    assert_true(moved > 1.0);
    free(after);
    tf_erosion_state_free(&r.st);
    free(h);
}

/* Every tiling, halo and thread count, and every kernel this CPU runs, give the same bits. */
static void test_identical_any_tiling(void **state)
{
    (void)state;
    int e = 6, n = 65;
    float *h = fbm_heights(e);
    tf_erosion_keys k = keys(97);
    run ref;
    start(&ref, h, n, &k);
    go(&ref, 0, 97, 1, 97, n, n); /* one tile, one round */
    struct { int threads, halo, tw, th; const char *isa; } cut[] = {
        {2, 8, 0, 0, NULL},           {1, 1, 7, 13, NULL},       {2, 3, 64, 5, NULL},
        {2, 8, 0, 0, "portable"},     {1, 5, 9, 9, "portable"},  {2, 8, 0, 0, "avx2"},
        {1, 3, 17, 5, "avx2"},        {2, 8, 0, 0, "avx512"},    {1, 2, 33, 3, "avx512"},
    };
    for (size_t c = 0; c < sizeof cut / sizeof cut[0]; c++) {
        if (tf_erosion_force_isa(cut[c].isa) != 0)
            continue; /* this CPU lacks it */
        run r;
        start(&r, h, n, &k);
        go(&r, 0, 40, cut[c].threads, cut[c].halo, cut[c].tw, cut[c].th);
        go(&r, 40, 57, cut[c].threads, cut[c].halo, cut[c].tw, cut[c].th); /* resumed */
        assert_same_state(&r.st, &ref.st);
        assert_memory_equal(&r.tally, &ref.tally, sizeof r.tally);
        tf_erosion_state_free(&r.st);
    }
    tf_erosion_force_isa(NULL);
    tf_erosion_state_free(&ref.st);
    free(h);
}

static uint64_t fnv1a(uint64_t h, const void *p, size_t len)
{
    const unsigned char *c = p;
    for (size_t i = 0; i < len; i++)
        h = (h ^ c[i]) * 1099511628211u;
    return h;
}

/* The kernels this CPU runs, one after another: forces the next from *i on (start at 0) and
 * says 1, or puts the choice back and says 0 once every one was had. */
static int next_kernel(size_t *i)
{
    static const char *const isa[] = {"avx512", "avx2", "portable"};
    while (*i < sizeof isa / sizeof isa[0])
        if (tf_erosion_force_isa(isa[(*i)++]) == 0)
            return 1;
    tf_erosion_force_isa(NULL);
    return 0;
}

/* The kernels may be rewritten for speed, never for results: 97 steps of test 2's reference run
 * give the bits the first kernel gave (commit 87d4353, AVX2 and portable alike), on every
 * kernel this CPU runs. */
static void test_same_bits_as_first_kernel(void **state)
{
    (void)state;
    int n = 65;
    float *h = fbm_heights(6);
    tf_erosion_keys k = keys(97);
    for (size_t i = 0; next_kernel(&i);) {
        run r;
        start(&r, h, n, &k);
        go(&r, 0, 97, 1, 97, n, n);
        size_t bytes = (size_t)n * n * 4;
        uint64_t x = 14695981039346656037u;
        const void *arrays[] = {r.st.b, r.st.t, r.st.d, r.st.w, r.st.s, r.st.flow};
        for (int a = 0; a < 6; a++)
            x = fnv1a(x, arrays[a], bytes);
        assert_int_equal(x, 0x8484e8f08d259ce8u);
        assert_int_equal(r.tally.rain, 1541426989);
        assert_int_equal(r.tally.evaporated, 52769073);
        assert_int_equal(r.tally.out_water, 387751445);
        assert_int_equal(r.tally.out_load, 1358433662);
        tf_erosion_state_free(&r.st);
    }
    free(h);
}

/* Steps 0 .. steps - 1 over all of window win but its one-vertex rim (whatever rows holds: the
 * window's own row buffers, or none). */
static void step_window(const run *r, tf_erosion_window *win, int steps, int garbage)
{
    tf_erosion_rect all = {1, win->v.ny - 1, 1, win->v.nx - 1};
    tf_erosion_tally t = {0};
    for (int s = 0; s < steps; s++) {
        if (garbage && win->v.rows)
            memset(win->v.rows, 0xA5, TF_EROSION_ROWS(win->v.nx) * sizeof(int32_t));
        assert_int_equal(tf_erosion_step(&r->m, &win->v, all, all, s, &t), 0);
    }
}

/* One kernel's case of the test below: 30 steps on a window with its rows garbled before each
 * step and on one without rows give the same bits, and the rows were written. */
static void window_rows_case(const float *h, int n, const tf_erosion_keys *k)
{
    run r;
    start(&r, h, n, k);
    tf_erosion_window kept, own;
    assert_int_equal(tf_erosion_window_alloc(&kept, 50, 40), 0);
    assert_int_equal(tf_erosion_window_alloc(&own, 50, 40), 0);
    assert_non_null(kept.v.rows);
    free(own.v.rows);
    own.v.rows = NULL; /* each step allocates its own */
    tf_erosion_window_load(&kept, &r.st, 7, 11);
    tf_erosion_window_load(&own, &r.st, 7, 11);
    step_window(&r, &kept, 30, 1);
    step_window(&r, &own, 30, 0);
    size_t bytes = kept.v.stride * (size_t)kept.v.ny * 4;
    assert_memory_equal(kept.v.b, own.v.b, bytes);
    assert_memory_equal(kept.v.t, own.v.t, bytes);
    assert_memory_equal(kept.v.d, own.v.d, bytes);
    assert_memory_equal(kept.v.w, own.v.w, bytes);
    assert_memory_equal(kept.v.s, own.v.s, bytes);
    assert_memory_equal(kept.v.flow, own.v.flow, bytes);
    size_t garbage = 0;
    for (size_t e = 0; e < TF_EROSION_ROWS(kept.v.nx); e++)
        garbage += (uint32_t)kept.v.rows[e] == 0xA5A5A5A5u;
    assert_true(garbage < TF_EROSION_ROWS(kept.v.nx) / 2);
    tf_erosion_window_free(&kept);
    tf_erosion_window_free(&own);
    tf_erosion_state_free(&r.st);
}

/* A window keeps the kernel's row buffers for every step (erosion.h, TF_EROSION_ROWS): the
 * kernel uses them (they no longer hold what they held) and its result does not depend on what
 * they held before a step: the same bits as a step that allocates its own, on every kernel. */
static void test_window_rows_reused_whatever_they_hold(void **state)
{
    (void)state;
    float *h = fbm_heights(6);
    tf_erosion_keys k = keys(30);
    for (size_t i = 0; next_kernel(&i);)
        window_rows_case(h, 65, &k);
    free(h);
}

/* A flat dry plane: the ground never moves; far from the outlet rain stays where it falls. */
static void test_flat_plane(void **state)
{
    (void)state;
    int n = 65;
    float *h = calloc((size_t)n * n, sizeof *h);
    for (int i = 0; i < n * n; i++)
        h[i] = 100.0f;
    tf_erosion_keys k = keys(25);
    k.creep = 0.1;
    k.evaporation = 0;
    k.rain_noise = 0;
    k.rain_altitude = 0;
    run r;
    start(&r, h, n, &k);
    go(&r, 0, 25, 1, 8, 0, 0);
    int32_t rain = (int32_t)r.m.rain_units;
    for (int j = 1; j < n - 1; j++)
        for (int i = 1; i < n - 1; i++) {
            size_t v = (size_t)j * n + i;
            assert_int_equal(r.st.b[v], r.st.b[0]);
            assert_int_equal(r.st.t[v] + r.st.d[v] + r.st.s[v], 0);
            /* the outlet's pull spreads one vertex a step: 25 steps from it, none */
            if (i > 25 && i < n - 26 && j > 25 && j < n - 26)
                assert_int_equal(r.st.w[v], 3 * rain);  /* rain on steps 0, 10, 20 */
        }
    tf_erosion_state_free(&r.st);
    free(h);
}

/* A lone wet vertex on a plane sends equal water to its four neighbours: E1 with H drop w. */
static void test_single_vertex(void **state)
{
    (void)state;
    int n = 9;
    float *h = calloc((size_t)n * n, sizeof *h);
    h[0] = 0; /* range 0..1 */
    h[1] = 1;
    tf_erosion_keys k = keys(1);
    k.rain = 0;
    k.creep = 0;
    k.evaporation = 0;
    run r;
    start(&r, h, n, &k);
    size_t c = 4 * n + 4;
    r.st.w[c] = 1000;
    go(&r, 0, 1, 1, 8, 0, 0);
    /* DW = trunc(min(1000, 1000 / 2) / 4) = 125 to each neighbour */
    assert_int_equal(r.st.w[c], 1000 - 4 * 125);
    assert_int_equal(r.st.w[c - 1], 125);
    assert_int_equal(r.st.w[c + 1], 125);
    assert_int_equal(r.st.w[c - n], 125);
    assert_int_equal(r.st.w[c + n], 125);
    /* capacity 5 * 125 with no load: the flat ground has no drop, so nothing is eroded */
    assert_int_equal(r.st.b[c], r.st.b[c + 2]);
    tf_erosion_state_free(&r.st);
    free(h);
}

/* Water running down a ramp cuts into its upper part and deposits silt at the foot. */
static void test_ramp_erodes_and_deposits(void **state)
{
    (void)state;
    int n = 33;
    float *h = malloc((size_t)n * n * sizeof *h);
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++)
            h[(size_t)j * n + i] = j < 20 ? (float)(20 - j) : 0.0f; /* falls north to south */
    tf_erosion_keys k = keys(400);
    k.strata = 0;
    k.hardness_noise = 0;
    k.evaporation = 0;
    run r;
    start(&r, h, n, &k);
    int64_t solid0 = tf_erosion_solid(&r.st, n);
    go(&r, 0, 400, 2, 8, 0, 0);
    assert_int_equal(tf_erosion_solid(&r.st, n) + r.tally.out_load, solid0);
    int64_t cut = 0, silt = 0;
    for (int j = 1; j < n - 1; j++)
        for (int i = 1; i < n - 1; i++) {
            size_t v = (size_t)j * n + i;
            int32_t b0 = (int32_t)nearbyint((h[v] - r.m.base) / r.m.q);
            if (j < 18)
                cut += b0 - r.st.b[v];
            else
                silt += r.st.d[v];
        }
    assert_true(cut > 0);
    assert_true(silt > 0);
    tf_erosion_state_free(&r.st);
    free(h);
}

/* A worker's block (an edge or a final band) is refused unless its size and every value are
 * ones an erosion produces. */
static void test_block_check(void **state)
{
    (void)state;
    int n = 17;
    float *h = fbm_heights(4);
    tf_erosion_keys k = keys(30);
    run r;
    start(&r, h, n, &k);
    go(&r, 0, 30, 1, 8, 0, 0);
    tf_erosion_view v = {r.st.b, r.st.t, r.st.d, r.st.w, r.st.s, r.st.flow, r.st.soft,
                         (size_t)n, 0, 0, n, n, NULL};
    tf_erosion_rect rect = {2, 5, 1, 16};
    size_t len = tf_erosion_block_bytes(3, 15);
    uint8_t *b = malloc(len + 4);
    tf_erosion_block_pack(&v, rect, b);
    char err[256];
    assert_int_equal(tf_erosion_block_check(b, len, 3, 15, "peer", err, sizeof err), 0);
    assert_int_equal(tf_erosion_block_check(b, len - 4, 3, 15, "peer", err, sizeof err), -1);
    assert_non_null(strstr(err, "peer: erosion block of"));
    assert_int_equal(tf_erosion_block_check(b, len, 15, 3 + 1, "peer", err, sizeof err), -1);
    size_t count = 3 * 15;
    struct { int field; int32_t value; const char *says; } lie[] = {
        {3, -5, "water = -5"}, {4, -1, "load = -1"}, {1, -7, "talus = -7"},
        {0, 1 << 29, "bedrock"}, {2, INT32_MIN, "silt"},
    };
    for (size_t l = 0; l < sizeof lie / sizeof lie[0]; l++) {
        uint8_t *c = malloc(len);
        memcpy(c, b, len);
        memcpy(c + ((size_t)lie[l].field * count + 7) * 4, &lie[l].value, 4);
        assert_int_equal(tf_erosion_block_check(c, len, 3, 15, "peer", err, sizeof err), -1);
        assert_non_null(strstr(err, lie[l].says));
        free(c);
    }
    float nan = NAN;
    memcpy(b + (5 * count + 3) * 4, &nan, 4);
    assert_int_equal(tf_erosion_block_check(b, len, 3, 15, "peer", err, sizeof err), -1);
    assert_non_null(strstr(err, "flow"));
    free(b);
    tf_erosion_state_free(&r.st);
    free(h);
}

/* An eroded terrain's blob: accepted whole for its own scene only. */
/* A blob's map k (0 heights, 1 water, 2 silt, 3 flow) given v at vertex (i, j), and its
 * checksum made to match, as a coordinator that sends it could. */
static void spoil_blob(uint8_t *b, size_t len, int n, int k, int i, int j, float v)
{
    const size_t header = 8 + 32 + 4 + 8 + 4;
    memcpy(b + header + ((size_t)k * n * n + (size_t)j * n + i) * 4, &v, 4);
    crypto_hash_sha256(b + len - 32, b, len - 32);
}

/* Values no erosion writes are refused although the checksum matches, naming the map and the
 * vertex; the blob as it was still parses. */
static void blob_values_checked(const tf_terrain *t, int n, const uint8_t *b, size_t len)
{
    static const struct { int k; float v; const char *what; } bad[] = {
        {0, NAN, "a height of nan at vertex (3, 5)"},
        {0, INFINITY, "a height of inf at vertex (3, 5)"},
        {1, -0.5f, "a water depth of -0.5 at vertex (3, 5)"},
        {2, NAN, "a silt depth of nan at vertex (3, 5)"},
        {3, -INFINITY, "a flow of -inf at vertex (3, 5)"},
    };
    uint8_t *copy = malloc(len);
    float *out = malloc((size_t)n * n * sizeof *out);
    char err[256];
    for (size_t c = 0; c < sizeof bad / sizeof bad[0]; c++) {
        memcpy(copy, b, len);
        spoil_blob(copy, len, n, bad[c].k, 3, 5, bad[c].v);
        tf_eroded_maps maps = {0};
        assert_int_equal(tf_eroded_parse(t, n, copy, len, "blob", out, &maps, err, sizeof err),
                         -1);
        if (!strstr(err, bad[c].what))
            fail_msg("case %zu: \"%s\" does not say \"%s\"", c, err, bad[c].what);
        assert_null(maps.water);
    }
    memcpy(copy, b, len);
    spoil_blob(copy, len, n, 0, 3, 5, -3e38f); /* finite, if absurd: a height like any other */
    assert_int_equal(tf_eroded_parse(t, n, copy, len, "blob", out, NULL, err, sizeof err), 0);
    free(copy);
    free(out);
}

static void test_blob_checks(void **state)
{
    (void)state;
    int n = 17;
    float *h = fbm_heights(4);
    tf_terrain t = {0};
    t.generator = TF_GEN_FBM;
    t.size_exp = 4;
    t.erosion = keys(20);
    run r;
    start(&r, h, n, &t.erosion);
    r.m.steps = 20;
    go(&r, 0, 20, 1, 8, 0, 0);
    size_t len;
    uint8_t *b = tf_eroded_encode(&t, &r.st, &r.m, 1000.0, &len);
    assert_non_null(b);
    float *out = malloc((size_t)n * n * sizeof *out);
    char err[256];
    tf_eroded_maps maps = {0};
    assert_int_equal(tf_eroded_parse(&t, n, b, len, "blob", out, &maps, err, sizeof err), 0);
    assert_non_null(maps.silt);
    tf_eroded_maps_free(&maps);
    float *want = malloc((size_t)n * n * sizeof *want);
    tf_erosion_heights(&r.st, &r.m, want);
    assert_memory_equal(out, want, (size_t)n * n * sizeof *out);
    blob_values_checked(&t, n, b, len);
    /* another scene's terrain: its key differs */
    tf_terrain other = t;
    other.erosion.softness = 0.31;
    assert_int_equal(tf_eroded_parse(&other, n, b, len, "blob", out, NULL, err, sizeof err), -1);
    assert_non_null(strstr(err, "another scene"));
    /* the wrong size, a damaged byte, a truncated blob */
    assert_int_equal(tf_eroded_parse(&t, 33, b, len, "blob", out, NULL, err, sizeof err), -1);
    assert_int_equal(tf_eroded_parse(&t, n, b, len - 1, "blob", out, NULL, err, sizeof err), -1);
    b[len / 2] ^= 1;
    assert_int_equal(tf_eroded_parse(&t, n, b, len, "blob", out, NULL, err, sizeof err), -1);
    assert_non_null(strstr(err, "blob: eroded terrain damaged"));
    free(b);
    free(out);
    free(want);
    tf_erosion_state_free(&r.st);
    free(h);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mass_conserved),
        cmocka_unit_test(test_identical_any_tiling),
        cmocka_unit_test(test_same_bits_as_first_kernel),
        cmocka_unit_test(test_window_rows_reused_whatever_they_hold),
        cmocka_unit_test(test_flat_plane),
        cmocka_unit_test(test_single_vertex),
        cmocka_unit_test(test_ramp_erodes_and_deposits),
        cmocka_unit_test(test_block_check),
        cmocka_unit_test(test_blob_checks),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
