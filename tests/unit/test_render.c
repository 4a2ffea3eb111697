/* test_render.c: tf_render_rect (common/render/render.c) on a small synthetic terrain built by hand.
 * The decomposition invariant: the whole image, single rows, single columns, odd stamps (7x5,
 * 13x11) and two threads give memcmp-identical pixels.  Adaptive antialiasing: uniform sky is
 * not subdivided (spp 4, or 5 with its centre probed), a silhouette is; ray counts add up;
 * max_depth 0 never subdivides; Z and alpha; bad settings are refused. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "render/render.h"
#include "render/render_internal.h"

#define W 61
#define H 37
#define K 5
#define SIDE ((1 << K) + 1)

typedef struct fixture {
    tf_scene scene;
    tf_heightfield *hf;
    tf_renderer *r;
    tf_pixel whole[W * H];
    tf_render_counts whole_counts;
} fixture;

static void fill_scene(tf_scene *s)
{
    memset(s, 0, sizeof *s);
    s->width = W;
    s->height = H;
    s->camera.kind = TF_CAMERA_PINHOLE;
    s->camera.position = v3(500, -250, 420);
    s->camera.look_at = v3(500, 600, 300);
    s->camera.up = v3(0, 0, 1);
    s->camera.fov_deg = 55;
    s->sun.azimuth_deg = 150; /* behind-left of the camera's view north: no glow in view */
    s->sun.elevation_deg = 30;
    s->sun.color = v3(1, 0.95, 0.85);
    s->sun.intensity = 3;
    s->sky.zenith = v3(0.15, 0.3, 0.7);
    s->sky.horizon = v3(0.55, 0.65, 0.8);
    s->sky.intensity = 0.8;
    s->terrain.seed = 1234;
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

/* Hills and a ridge over [0, 1000]^2, dropping under the sea in one corner. */
static void fill_heights(float *h)
{
    for (int j = 0; j < SIDE; j++)
        for (int i = 0; i < SIDE; i++) {
            double x = i * 1000.0 / (SIDE - 1), y = j * 1000.0 / (SIDE - 1);
            double z = 160 + 110 * sin(x * 0.011) * cos(y * 0.008) + 0.25 * y -
                       90 * exp(-((x - 200) * (x - 200) + (y - 150) * (y - 150)) / 40000.0);
            h[j * SIDE + i] = (float)z;
        }
}

static int setup(void **state)
{
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    float h[SIDE * SIDE];
    fill_heights(h);
    f->hf = tf_heightfield_from_heights(h, K, 1000.0, 1);
    char err[256];
    f->r = tf_renderer_new(&f->scene, f->hf, err, sizeof err);
    if (!f->r)
        return -1;
    tf_render_rect(f->r, (tf_rect){0, 0, W, H}, f->whole, &f->whole_counts);
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fixture *f = *state;
    tf_renderer_free(f->r);
    tf_heightfield_free(f->hf);
    free(f);
    return 0;
}

/* Render the image as tiles of tw x th (clipped at the edges) into out; sums counts. */
static void render_tiled(const tf_renderer *r, int tw, int th, tf_pixel *out,
                         tf_render_counts *counts)
{
    tf_pixel *tile = malloc(sizeof *tile * (size_t)tw * (size_t)th);
    for (int y = 0; y < H; y += th)
        for (int x = 0; x < W; x += tw) {
            tf_rect rc = {x, y, x + tw <= W ? tw : W - x, y + th <= H ? th : H - y};
            tf_render_rect(r, rc, tile, counts);
            for (int j = 0; j < rc.h; j++)
                memcpy(&out[(y + j) * W + x], &tile[j * rc.w], sizeof *tile * (size_t)rc.w);
        }
    free(tile);
}

static void assert_decomposition_identical(fixture *f, int tw, int th)
{
    tf_pixel *img = calloc(W * H, sizeof *img);
    tf_render_counts c = {0};
    render_tiled(f->r, tw, th, img, &c);
    assert_memory_equal(img, f->whole, sizeof f->whole);
    free(img);
}

static void test_rows_identical_to_whole(void **state) { assert_decomposition_identical(*state, W, 1); }
static void test_columns_identical_to_whole(void **state) { assert_decomposition_identical(*state, 1, H); }
static void test_stamps_7x5_identical_to_whole(void **state) { assert_decomposition_identical(*state, 7, 5); }
static void test_stamps_13x11_identical_to_whole(void **state) { assert_decomposition_identical(*state, 13, 11); }
/* single pixels take no samples from neighbours: the shared edges change no bit */
static void test_single_pixels_identical_to_whole(void **state) { assert_decomposition_identical(*state, 1, 1); }

/* Camera rays helped by the ray below (tf_trace_coherent) or not, the pixels are the same bits:
 * the fixture's image was rendered with coherence on (the default), this one without. */
static void test_coherence_changes_no_bit(void **state)
{
    fixture *f = *state;
    tf_pixel *img = calloc(W * H, sizeof *img);
    tf_render_counts c = {0};
    tf_render_coherence_force(0);
    render_tiled(f->r, 7, 5, img, &c);
    tf_render_coherence_force(-1);
    assert_memory_equal(img, f->whole, sizeof f->whole);
    free(img);
}

/* Shadow rays whose walks end where the sun's strips prove them clear (render/sun_strips.h) or
 * that walk out of the terrain's box, the pixels are the same bits: the fixture's renderer has
 * the strips (its image is big enough for them), this one does without. */
static void test_sun_strips_change_no_bit(void **state)
{
    fixture *f = *state;
    assert_non_null(f->r->sun_strips);
    assert_ptr_equal(f->r->shader.sun_strips, f->r->sun_strips);
    char err[256];
    tf_renderer *plain = tf_renderer_new(&f->scene, f->hf, err, sizeof err);
    assert_non_null(plain);
    plain->shader.sun_strips = NULL;
    tf_pixel *img = calloc(W * H, sizeof *img);
    tf_render_counts c = {0};
    tf_render_rect(plain, (tf_rect){0, 0, W, H}, img, &c);
    assert_memory_equal(img, f->whole, sizeof f->whole);
    assert_memory_equal(&c, &f->whole_counts, sizeof c);
    free(img);
    tf_renderer_free(plain);
}

/* After tf_render_prepare the strips are kept with the height field: a renderer made then
 * borrows them (builds none, frees none) and renders the same bits; a renderer of another sun
 * builds its own. */
static void test_prepared_strips_are_borrowed(void **state)
{
    fixture *f = *state;
    char err[256];
    tf_heightfield *hf = tf_heightfield_from_heights(f->hf->h, K, f->hf->extent, 1);
    assert_non_null(hf);
    tf_render_prepare(&f->scene, hf, 2);
    assert_non_null(hf->derived);
    tf_renderer *r = tf_renderer_new(&f->scene, hf, err, sizeof err);
    assert_non_null(r);
    assert_null(r->sun_strips);
    assert_ptr_equal(r->shader.sun_strips, hf->derived);
    tf_pixel *img = calloc(W * H, sizeof *img);
    tf_render_counts c = {0};
    tf_render_rect(r, (tf_rect){0, 0, W, H}, img, &c);
    assert_memory_equal(img, f->whole, sizeof f->whole);
    assert_memory_equal(&c, &f->whole_counts, sizeof c);
    tf_scene moved = f->scene;
    moved.sun.azimuth_deg += 10;
    tf_renderer *other = tf_renderer_new(&moved, hf, err, sizeof err);
    assert_non_null(other);
    assert_non_null(other->sun_strips);
    assert_ptr_equal(other->shader.sun_strips, other->sun_strips);
    tf_renderer_free(other);
    tf_renderer_free(r);
    tf_heightfield_free(hf); /* frees the kept strips (make asan: no leak, no double free) */
    free(img);
}

typedef struct thread_job { const tf_renderer *r; tf_pixel *img; int first_row; } thread_job;

static void *render_alternate_rows(void *arg)
{
    thread_job *job = arg;
    for (int y = job->first_row; y < H; y += 2)
        tf_render_rect(job->r, (tf_rect){0, y, W, 1}, &job->img[y * W], NULL);
    return NULL;
}

static void test_two_threads_identical_to_whole(void **state)
{
    fixture *f = *state;
    tf_pixel *img = calloc(W * H, sizeof *img);
    thread_job jobs[2] = {{f->r, img, 0}, {f->r, img, 1}};
    pthread_t t[2];
    for (int i = 0; i < 2; i++)
        assert_int_equal(pthread_create(&t[i], NULL, render_alternate_rows, &jobs[i]), 0);
    for (int i = 0; i < 2; i++)
        pthread_join(t[i], NULL);
    assert_memory_equal(img, f->whole, sizeof f->whole);
    free(img);
}

static void test_sky_not_subdivided_edges_are(void **state)
{
    fixture *f = *state;
    const tf_pixel *sky = &f->whole[W / 2]; /* top row, centre: open sky */
    assert_true(sky->a == 0.0f);
    /* smooth sky: at most its centre is probed (the gradient may pass the probe's low bar);
     * it is never split */
    assert_true(sky->spp == 4.0f || sky->spp == 5.0f);
    assert_true(sky->z == 1e30f);
    int silhouettes = 0, refined_silhouettes = 0;
    float max_spp = 0;
    for (int i = 0; i < W * H; i++) {
        const tf_pixel *p = &f->whole[i];
        if (p->spp > max_spp)
            max_spp = p->spp;
        if (p->a > 0 && p->a < 1) {
            silhouettes++;
            refined_silhouettes += p->spp > 4;
        }
    }
    assert_true(silhouettes > 10);
    /* near ridges stand out against the sky and get refined; only far ridges, hazed to nearly
     * the sky's colour by the mist, may stay below the contrast threshold */
    assert_true(refined_silhouettes * 4 >= silhouettes * 3);
    /* strong edges go past the first split (9 samples), never past depth 2 (5x5 samples) */
    assert_true(max_spp > 9 && max_spp <= 25);
    const tf_pixel *ground = &f->whole[(H - 1) * W + W / 2];
    assert_true(ground->a == 1.0f && ground->z > 0 && ground->z < 5000);
}

/* primary = corner samples of each rectangle + refinement samples of each pixel, less those a
 * pixel took from a neighbour on their shared edge (render.c's pixel_edge: at most the inner
 * points of its left and bottom edges, 2 (N - 1)).  Returns the samples taken so. */
static uint64_t assert_counts_add_up(const tf_pixel *img, const tf_render_counts *c,
                                     uint64_t corners, uint64_t external, uint64_t pixels)
{
    const uint64_t N = 1u << 2; /* fill_scene's max_depth */
    uint64_t refinement = 0;
    for (int i = 0; i < W * H; i++)
        refinement += (uint64_t)img[i].spp - 4;
    assert_int_equal(c->pixels, pixels);
    assert_int_equal(c->external_rays, external);
    assert_true(c->primary_rays <= corners + refinement);
    assert_true(c->primary_rays + pixels * 2 * (N - 1) >= corners + refinement);
    assert_true(c->shadow_rays > 0 && c->shadow_rays <= c->primary_rays);
    return corners + refinement - c->primary_rays;
}

static void test_counts_add_up(void **state)
{
    fixture *f = *state;
    /* pixels refined across shared edges: some samples were taken, not traced again */
    assert_true(assert_counts_add_up(f->whole, &f->whole_counts, (W + 1) * (H + 1), W + H + 1,
                                     W * H) > 0);
    /* 13x11 stamps: 5 x 4 stamps, clipped to 9 wide and 4 high at the far edges */
    tf_pixel *img = calloc(W * H, sizeof *img);
    tf_render_counts c = {0};
    render_tiled(f->r, 13, 11, img, &c);
    uint64_t corners = 0, external = 0;
    for (int y = 0; y < H; y += 11)
        for (int x = 0; x < W; x += 13) {
            uint64_t w = x + 13 <= W ? 13 : W - x, h = y + 11 <= H ? 11 : H - y;
            corners += (w + 1) * (h + 1);
            external += w + h + 1;
        }
    assert_counts_add_up(img, &c, corners, external, W * H);
    free(img);
    /* a rectangle of one pixel has no neighbour to take samples from */
    img = calloc(1, sizeof *img);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            tf_render_counts one = {0};
            tf_render_rect(f->r, (tf_rect){x, y, 1, 1}, img, &one);
            assert_int_equal(one.primary_rays, (uint64_t)img->spp);
        }
    free(img);
}

static void test_depth_zero_never_subdivides(void **state)
{
    fixture *f = *state;
    tf_scene s = f->scene;
    s.antialias.max_depth = 0;
    char err[256];
    tf_renderer *r = tf_renderer_new(&s, f->hf, err, sizeof err);
    assert_non_null(r);
    tf_pixel *img = calloc(W * H, sizeof *img);
    tf_render_counts c = {0};
    tf_render_rect(r, (tf_rect){0, 0, W, H}, img, &c);
    for (int i = 0; i < W * H; i++)
        assert_true(img[i].spp == 4.0f);
    assert_int_equal(c.primary_rays, (W + 1) * (H + 1));
    /* rows again, for the invariant at depth 0 */
    tf_pixel *rows = calloc(W * H, sizeof *rows);
    render_tiled(r, W, 1, rows, NULL);
    assert_memory_equal(rows, img, sizeof(tf_pixel) * W * H);
    free(rows);
    free(img);
    tf_renderer_free(r);
}

static void test_bad_settings_refused(void **state)
{
    fixture *f = *state;
    tf_scene s = f->scene;
    char err[256] = "";
    s.antialias.max_depth = TF_AA_MAX_DEPTH + 1;
    assert_null(tf_renderer_new(&s, f->hf, err, sizeof err));
    assert_non_null(strstr(err, "max_depth"));
    s = f->scene;
    s.camera.fov_deg = 0;
    assert_null(tf_renderer_new(&s, f->hf, err, sizeof err));
    assert_non_null(strstr(err, "fov"));
}

static void test_contrast_is_perceptual(void **state)
{
    (void)state;
    assert_true(tf_display_level(0) == 0 && tf_display_level(1) == 1);
    assert_true(tf_display_level(-0.5) == 0);   /* nothing below black shows */
    assert_true(tf_display_level(7.0) == 1);    /* nor anything above white */
    assert_true(fabs(tf_display_level(0.25) - 0.5) < 1e-15);
    for (double v = 0; v < 1; v += 0.01)
        assert_true(tf_display_level(v + 0.01) > tf_display_level(v));
    /* the same absolute step is more visible in the dark */
    assert_true(tf_display_level(0.04) - tf_display_level(0.02) >
                tf_display_level(0.82) - tf_display_level(0.80));
}

/* FNV-1a over the bytes of an image: a fingerprint of every bit of every pixel. */
static uint64_t image_digest(const tf_pixel *img, size_t n)
{
    const unsigned char *b = (const unsigned char *)img;
    uint64_t h = 0xcbf29ce484222325ULL;
    for (size_t i = 0; i < n * sizeof *img; i++)
        h = (h ^ b[i]) * 0x100000001b3ULL;
    return h;
}

/* The fixture rendered with the sun at `elevation` and `azimuth`, its digest. */
static uint64_t digest_with_sun(fixture *f, double azimuth, double elevation)
{
    tf_scene s = f->scene;
    s.sun.azimuth_deg = azimuth;
    s.sun.elevation_deg = elevation;
    char err[256];
    tf_renderer *r = tf_renderer_new(&s, f->hf, err, sizeof err);
    assert_non_null(r);
    tf_pixel *img = calloc(W * H, sizeof *img);
    tf_render_rect(r, (tf_rect){0, 0, W, H}, img, NULL);
    uint64_t d = image_digest(img, (size_t)W * H);
    free(img);
    tf_renderer_free(r);
    return d;
}

/* terrain.smooth = 0 (the default) is the shading of every scene before the key existed, to
 * the bit: the digests were taken from the renderer of the commit before smooth shading, on
 * the fixture with its own sun and with a low one (many triangles near the terminator, where
 * the two modes differ).  A change of the compiler or libm may move them; then check that
 * smooth = 0 still renders what that commit renders, and take them again.  Taken again when
 * the bump's gradient became exact instead of forward differences (session 33): with
 * materials.bump = 0 every scene rendered the same bits before and after that change. */
static void test_flat_shading_unchanged(void **state)
{
    fixture *f = *state;
    uint64_t own = image_digest(f->whole, (size_t)W * H);
    uint64_t low = digest_with_sun(f, 250, 7);
    print_message("digests %016llx %016llx\n", (unsigned long long)own, (unsigned long long)low);
    assert_true(own == 0xa02ff7756d08bfd3ULL);
    assert_true(low == 0xd1f9304de9c18bb8ULL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_contrast_is_perceptual),
        cmocka_unit_test(test_flat_shading_unchanged),
        cmocka_unit_test(test_rows_identical_to_whole),
        cmocka_unit_test(test_columns_identical_to_whole),
        cmocka_unit_test(test_stamps_7x5_identical_to_whole),
        cmocka_unit_test(test_stamps_13x11_identical_to_whole),
        cmocka_unit_test(test_single_pixels_identical_to_whole),
        cmocka_unit_test(test_coherence_changes_no_bit),
        cmocka_unit_test(test_sun_strips_change_no_bit),
        cmocka_unit_test(test_prepared_strips_are_borrowed),
        cmocka_unit_test(test_two_threads_identical_to_whole),
        cmocka_unit_test(test_sky_not_subdivided_edges_are),
        cmocka_unit_test(test_counts_add_up),
        cmocka_unit_test(test_depth_zero_never_subdivides),
        cmocka_unit_test(test_bad_settings_refused),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
