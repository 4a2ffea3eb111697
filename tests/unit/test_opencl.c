/* test_opencl.c: the OpenCL backend (worker/backend_opencl.c + worker/kernels)
 * against the C renderer, on PoCL.
 *
 *   match_c_backend     scenes/default.scene at 160x90, rendered in-process both ways
 *                       (tf_render_rect vs tf_cl_backend_render): PSNR >= 45 dB over linear RGB
 *                       in [0, 1], per-pixel sample counts equal for >= 99% of pixels, alpha
 *                       equal for >= 99%, ray counts within 1%, external rays identical.
 *   one_tile_same_rays  16x16 tasks (one work-item's tile on a CPU device): on PoCL's CPU
 *                       device the kernels trace exactly the C backend's primary and shadow
 *                       rays, no sample more.
 *   rect_invariance     the decomposition invariant on the device: stamps of the image give
 *                       memcmp-identical pixels to the whole-image render.
 *   mixed_backends      an image whose rectangles alternate between the backends (what a render
 *                       with mixed workers assembles) meets the same tolerance.
 *   other_scenes        mesa (water, eroded terrain) and alps (panorama camera, ridged) at
 *                       small sizes: the same tolerance.
 *   smooth_scenes       alps and default with terrain smooth = yes: the same tolerance (and
 *                       the bits on PoCL), each image differing from its flat one.
 *   aa_depths_and_tiny_images   AA depth 0 and 6, a 1x1 image, a 7x3 one: the same.
 *   On PoCL's CPU device the packet kernels compute every sample with the C operations in the
 *   C order, so match_c_backend and other_scenes also demand memcmp-identical pixels there (a
 *   wrong lane mask that touched a few pixels would still pass the tolerance).
 *   bad_device / bad_kernel_dir / bad_rect   one-line errors, no crash.
 *   opened_ahead        a device started on a thread before the terrain exists
 *                       (worker/opencl_ahead.h), then attached: the C pixels, memcmp-identical
 *                       on PoCL; tf_backend_new takes it once (the next backend opens its own);
 *                       a second start while one is pending is refused; an unattached backend
 *                       refuses to render, and attach refuses a procedural terrain and a second
 *                       scene, each in one line.
 *   installed_kernel_dir   the kernels and the C headers they share (make install's flat
 *                       layout, found through TERRAFARM_KERNELS) build and give the C pixels;
 *                       without a shared header the error is one line naming it.
 *   small_batches       a task's pixels in many launches (TERRAFARM_CL_SCRATCH of 64 KB, as
 *                       a one-thread CPU device's 2 MB splits a large stamp): the pixels of
 *                       one launch, memcmp-identical on PoCL.
 *   item_sizes          the kernels built for other work-item sizes (TERRAFARM_CL_ITEMS): a
 *                       GPU's 128 samples a batch and 64 pixels an item, and the smallest, 8
 *                       and 1: the same pixels, memcmp-identical on PoCL.
 *   tuning_refused      a TERRAFARM_CL_ITEMS, _LOCAL or _SCRATCH value out of its range is one
 *                       line on stderr naming it and the range, and the device's own setting
 *                       stays (the C pixels); a good value prints nothing.
 *   cores_shared        N OpenCL worker processes share the cores through PoCL's environment.
 *   basic_device_for_one_core   a share of one core picks PoCL's "basic" device, unless the user
 *                       chose PoCL's devices, a thread count or a device.
 * Every test but cores_shared and basic_device_for_one_core skips (cmocka skip()) with a message when no OpenCL platform
 * exists. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include "worker/backend.h"
#include "worker/backend_opencl.h"
#include "worker/opencl_ahead.h"
#include "installed_kernels.h"
#include "terrain/heightfield.h"
#include "render/render.h"
#include "scene.h"

#define W 160
#define H 90

typedef struct fixture {
    tf_scene *scene;
    tf_heightfield *hf;
    tf_renderer *r;
    tf_cl_backend *cl;
    tf_pixel c_img[W * H];
    tf_render_counts c_counts;
} fixture;

static fixture fx;

static int have_platform(void)
{
    cl_uint n = 0;
    return clGetPlatformIDs(0, NULL, &n) == CL_SUCCESS && n > 0;
}

static void skip_without_opencl(void)
{
    if (!have_platform()) {
        print_message("no OpenCL platform: skipping the OpenCL backend tests\n");
        skip();
    }
}

static int setup(void **state)
{
    (void)state;
    char err[1024], path[4096];
    const char *root = getenv("TF_ROOT");
    snprintf(path, sizeof path, "%s/scenes/default.scene", root ? root : ".");
    fx.scene = tf_scene_load(path, err, sizeof err);
    if (!fx.scene) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    tf_scene_set_size(fx.scene, W, H);
    fx.hf = tf_heightfield_build(fx.scene, 0, err, sizeof err);
    fx.r = fx.hf ? tf_renderer_new(fx.scene, fx.hf, err, sizeof err) : NULL;
    if (!fx.r) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    tf_render_rect(fx.r, (tf_rect){0, 0, W, H}, fx.c_img, &fx.c_counts);
    if (have_platform()) {
        fx.cl = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
        if (!fx.cl) {
            fprintf(stderr, "OpenCL backend: %s\n", err);
            return -1;
        }
    }
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    tf_cl_backend_free(fx.cl);
    tf_renderer_free(fx.r);
    tf_heightfield_free(fx.hf);
    tf_scene_free(fx.scene);
    return 0;
}

static double clamp01(double v) { return v < 0 ? 0 : v > 1 ? 1 : v; }

/* PSNR of b against a over the RGB channels, values clamped to [0, 1], peak 1. */
static double psnr(const tf_pixel *a, const tf_pixel *b, size_t n)
{
    double se = 0;
    for (size_t i = 0; i < n; i++) {
        double d[3] = {clamp01(a[i].r) - clamp01(b[i].r), clamp01(a[i].g) - clamp01(b[i].g),
                       clamp01(a[i].b) - clamp01(b[i].b)};
        se += d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    }
    double mse = se / (3.0 * (double)n);
    return mse > 0 ? 10.0 * log10(1.0 / mse) : INFINITY;
}

static size_t count_equal_spp(const tf_pixel *a, const tf_pixel *b, size_t n)
{
    size_t same = 0;
    for (size_t i = 0; i < n; i++)
        same += a[i].spp == b[i].spp;
    return same;
}

/* The tolerance of docs/contract.md section 4: PSNR >= 45 dB, sample counts and alpha equal for
 * >= 99%. */
static void assert_close_to_c(const tf_pixel *img, const char *what)
{
    size_t n = (size_t)W * H, alpha_same = 0;
    for (size_t i = 0; i < n; i++)
        alpha_same += img[i].a == fx.c_img[i].a;
    double p = psnr(fx.c_img, img, n);
    size_t spp_same = count_equal_spp(fx.c_img, img, n);
    print_message("%s: PSNR %.1f dB, spp equal %zu/%zu, alpha equal %zu/%zu\n", what, p, spp_same,
                  n, alpha_same, n);
    assert_true(p >= 45.0);
    assert_true(spp_same * 100 >= n * 99);
    assert_true(alpha_same * 100 >= n * 99);
}

/* PoCL's CPU device ("pthread-..."): where the kernels must match the C backend to the bit. */
static int on_pocl_cpu(const tf_cl_backend *b)
{
    return strncmp(tf_cl_backend_device(b), "pthread", 7) == 0;
}

static void match_c_backend(void **state)
{
    (void)state;
    skip_without_opencl();
    static tf_pixel img[W * H];
    tf_render_counts counts = {0};
    char err[1024];
    assert_int_equal(tf_cl_backend_render(fx.cl, (tf_rect){0, 0, W, H}, img, &counts, err,
                                          sizeof err), 0);
    assert_close_to_c(img, "whole image");
    if (on_pocl_cpu(fx.cl))
        assert_memory_equal(img, fx.c_img, sizeof img);
    assert_int_equal(counts.pixels, fx.c_counts.pixels);
    assert_int_equal(counts.external_rays, fx.c_counts.external_rays);
    /* Both backends take a pixel's edge samples from the neighbour that keeps them instead of
     * tracing them again: the C backend from every neighbour before it in the task (render.c's
     * pixel_edge), the kernels from the neighbours in the pixel's work-item, a tile of pixels
     * (packet_render.cl).  So the kernels trace at least C's rays, fewer than one a sample, and
     * at least 3/4 as many fewer as C (1% either way: on a GPU a few pixels may refine
     * differently; a work-item of pixel rows instead of a tile saves 2/3); each sample with its
     * one shadow ray or none. */
    uint64_t c_samples = (uint64_t)(W + 1) * (H + 1);
    for (size_t i = 0; i < (size_t)W * H; i++)
        c_samples += (uint64_t)fx.c_img[i].spp - 4;
    assert_true(fx.c_counts.primary_rays < c_samples);
    const uint64_t taken = c_samples - fx.c_counts.primary_rays;
    print_message("primary rays %llu (C %llu, of %llu samples), shadow rays %llu (C %llu)\n",
                  (unsigned long long)counts.primary_rays,
                  (unsigned long long)fx.c_counts.primary_rays, (unsigned long long)c_samples,
                  (unsigned long long)counts.shadow_rays,
                  (unsigned long long)fx.c_counts.shadow_rays);
    assert_true((double)fx.c_counts.primary_rays <= 1.01 * (double)counts.primary_rays);
    assert_true(counts.primary_rays < c_samples);
    assert_true(4 * (c_samples - counts.primary_rays) >= 3 * taken);
    assert_true((double)fx.c_counts.shadow_rays <= 1.01 * (double)counts.shadow_rays);
    assert_true((double)counts.shadow_rays <= 1.01 * (double)(fx.c_counts.shadow_rays + taken));
    /* Z is the nearest sample's distance: equal wherever the same samples were taken */
    size_t z_close = 0;
    for (size_t i = 0; i < (size_t)W * H; i++)
        z_close += fabs(img[i].z - fx.c_img[i].z) <= 1e-3f * fx.c_img[i].z;
    assert_true(z_close * 100 >= (size_t)W * H * 99);
}

/* A 16x16 task is one work-item's tile on a CPU device (256 pixels an item), so the kernels
 * share every edge sample of it, as render.c shares them across a task: on PoCL's CPU device they
 * must trace exactly the C backend's rays, no sample more (a sample asked ahead that render.c
 * would not trace, or one traced twice, changes no pixel but costs a ray). */
static void one_tile_same_rays(void **state)
{
    (void)state;
    skip_without_opencl();
    if (!on_pocl_cpu(fx.cl))
        skip(); /* a GPU's work-items hold 8x8 tiles; and its rounding may refine otherwise */
    const tf_rect rects[] = {{72, 40, 16, 16}, {0, 0, 16, 16}, {144, 74, 16, 16}};
    for (size_t k = 0; k < sizeof rects / sizeof rects[0]; k++) {
        tf_pixel c_img[16 * 16], cl_img[16 * 16];
        tf_render_counts c = {0}, cl = {0};
        char err[1024];
        tf_render_rect(fx.r, rects[k], c_img, &c);
        assert_int_equal(tf_cl_backend_render(fx.cl, rects[k], cl_img, &cl, err, sizeof err), 0);
        print_message("16x16 at %d,%d: primary rays C %llu, OpenCL %llu; shadow %llu, %llu\n",
                      rects[k].x, rects[k].y, (unsigned long long)c.primary_rays,
                      (unsigned long long)cl.primary_rays, (unsigned long long)c.shadow_rays,
                      (unsigned long long)cl.shadow_rays);
        assert_memory_equal(cl_img, c_img, sizeof c_img);
        assert_true(c.primary_rays > (16 + 1) * (16 + 1)); /* some pixel refined */
        assert_int_equal(cl.primary_rays, c.primary_rays);
        assert_int_equal(cl.shadow_rays, c.shadow_rays);
    }
}

/* Copy rect's pixels (row-major in rect) into the whole-image array dst. */
static void paste(tf_pixel *dst, tf_rect rect, const tf_pixel *src)
{
    for (int y = 0; y < rect.h; y++)
        memcpy(&dst[(size_t)(rect.y + y) * W + rect.x], &src[(size_t)y * rect.w],
               sizeof *src * (size_t)rect.w);
}

static void rect_invariance(void **state)
{
    (void)state;
    skip_without_opencl();
    static tf_pixel whole[W * H], tiled[W * H], part[W * H];
    char err[1024];
    assert_int_equal(tf_cl_backend_render(fx.cl, (tf_rect){0, 0, W, H}, whole, NULL, err,
                                          sizeof err), 0);
    memset(tiled, 0xff, sizeof tiled);
    /* odd stamps that do not divide the image: 37x23 with ragged edges */
    for (int y = 0; y < H; y += 23)
        for (int x = 0; x < W; x += 37) {
            tf_rect r = {x, y, x + 37 <= W ? 37 : W - x, y + 23 <= H ? 23 : H - y};
            assert_int_equal(tf_cl_backend_render(fx.cl, r, part, NULL, err, sizeof err), 0);
            paste(tiled, r, part);
        }
    assert_memory_equal(whole, tiled, sizeof whole);
}

static void mixed_backends(void **state)
{
    (void)state;
    skip_without_opencl();
    static tf_pixel mixed[W * H], part[W * H];
    char err[1024];
    int k = 0;
    for (int y = 0; y < H; y += 15, k++) {
        tf_rect r = {0, y, W, y + 15 <= H ? 15 : H - y};
        if (k % 2)
            assert_int_equal(tf_cl_backend_render(fx.cl, r, part, NULL, err, sizeof err), 0);
        else
            tf_render_rect(fx.r, r, part, NULL);
        paste(mixed, r, part);
    }
    assert_close_to_c(mixed, "mixed backends");
}

/* Render scenes/NAME.scene at w x h with both backends (AA depth `depth`, or the scene's if
 * negative; terrain smooth as `smooth`, or the scene's if negative); compare.  Returns a
 * checksum of the C image (for telling the modes apart). */
static uint64_t check_scene_mode(const char *name, int w, int h, int depth, int smooth)
{
    char err[1024], path[4096];
    const char *root = getenv("TF_ROOT");
    snprintf(path, sizeof path, "%s/scenes/%s.scene", root ? root : ".", name);
    tf_scene *s = tf_scene_load(path, err, sizeof err);
    assert_non_null(s);
    tf_scene_set_size(s, w, h);
    if (depth >= 0)
        s->antialias.max_depth = depth;
    if (smooth >= 0)
        s->terrain.smooth = smooth;
    tf_scene_rehash(s);
    tf_heightfield *hf = tf_heightfield_build(s, 0, err, sizeof err);
    assert_non_null(hf);
    tf_renderer *r = tf_renderer_new(s, hf, err, sizeof err);
    tf_cl_backend *b = tf_cl_backend_new(s, hf, err, sizeof err);
    assert_non_null(r);
    assert_non_null(b);
    size_t n = (size_t)w * (size_t)h;
    tf_pixel *c = calloc(n, sizeof *c), *g = calloc(n, sizeof *g);
    assert_non_null(c);
    assert_non_null(g);
    tf_render_rect(r, (tf_rect){0, 0, w, h}, c, NULL);
    assert_int_equal(tf_cl_backend_render(b, (tf_rect){0, 0, w, h}, g, NULL, err, sizeof err), 0);
    double p = psnr(c, g, n);
    size_t spp_same = count_equal_spp(c, g, n);
    print_message("%s %dx%d depth %d%s: PSNR %.1f dB, spp equal %zu/%zu\n", name, w, h,
                  s->antialias.max_depth, s->terrain.smooth ? " smooth" : "", p, spp_same, n);
    assert_true(p >= 45.0);
    assert_true(spp_same * 100 >= n * 99);
    if (on_pocl_cpu(b))
        assert_memory_equal(g, c, n * sizeof *c);
    uint64_t sum = 0xcbf29ce484222325ULL; /* FNV-1a */
    for (size_t i = 0; i < n * sizeof *c; i++)
        sum = (sum ^ ((const unsigned char *)c)[i]) * 0x100000001b3ULL;
    free(c);
    free(g);
    tf_cl_backend_free(b);
    tf_renderer_free(r);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return sum;
}

static void check_scene(const char *name, int w, int h, int depth)
{
    check_scene_mode(name, w, h, depth, -1);
}

static void other_scenes(void **state)
{
    (void)state;
    skip_without_opencl();
    check_scene("mesa", 96, 54, -1);
    check_scene("alps", 120, 40, -1);
}

/* Camera rays helped by the records of corner rays below them (packet_render.cl's
 * lower_corner, trace.c's coherence): the same bits where the camera stands low in a valley, its
 * rays meeting slopes near it (the prefix walk before the lower ray vouches) and far off. */
static void coherent_near_terrain(void **state)
{
    (void)state;
    skip_without_opencl();
    check_scene("valley", 160, 90, -1);
}

/* terrain smooth = yes (the sun test and the shadow ray's start by the interpolated normal):
 * the same bits on PoCL.  Each image must differ from its flat one, or the smooth path was
 * not exercised. */
static void smooth_scenes(void **state)
{
    (void)state;
    skip_without_opencl();
    assert_true(check_scene_mode("alps", 120, 40, -1, 1) != check_scene_mode("alps", 120, 40, -1, 0));
    assert_true(check_scene_mode("default", 96, 54, -1, 1) !=
                check_scene_mode("default", 96, 54, -1, 0));
}

/* The edges of the packet kernels: no subdivision at all, the deepest one (a 65 x 65 lattice
 * per pixel, 128-sample batches that fill), and images smaller than a work-item. */
static void aa_depths_and_tiny_images(void **state)
{
    (void)state;
    skip_without_opencl();
    check_scene("default", 33, 17, 0);
    check_scene("default", 40, 24, 6);
    check_scene("default", 1, 1, -1);
    check_scene("valley", 7, 3, -1);
}

static void bad_device(void **state)
{
    (void)state;
    skip_without_opencl();
    char err[1024] = "";
    setenv("TERRAFARM_CL_DEVICE", "no-such-device-xyzzy", 1);
    tf_cl_backend *b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    unsetenv("TERRAFARM_CL_DEVICE");
    assert_null(b);
    assert_non_null(strstr(err, "no-such-device-xyzzy"));
    assert_null(strchr(err, '\n'));
    setenv("TERRAFARM_CL_DEVICE", "7:7", 1);
    b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    unsetenv("TERRAFARM_CL_DEVICE");
    assert_null(b);
    assert_non_null(strstr(err, "matches no OpenCL device"));
}

static void good_device_override(void **state)
{
    (void)state;
    skip_without_opencl();
    char err[1024] = "";
    setenv("TERRAFARM_CL_DEVICE", "0:0", 1);
    tf_cl_backend *b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    unsetenv("TERRAFARM_CL_DEVICE");
    assert_non_null(b);
    assert_string_equal(tf_cl_backend_device(b), tf_cl_backend_device(fx.cl));
    tf_cl_backend_free(b);
}

static void bad_kernel_dir(void **state)
{
    (void)state;
    skip_without_opencl();
    char err[1024] = "";
    setenv("TERRAFARM_KERNELS", "/nonexistent/terrafarm-kernels", 1);
    tf_cl_backend *b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    unsetenv("TERRAFARM_KERNELS");
    assert_null(b);
    assert_non_null(strstr(err, "/nonexistent/terrafarm-kernels"));
    assert_null(strchr(err, '\n'));
}

/* Copy file `from` into directory `dir` under its base name. */
static int copy_into(const char *from, const char *dir)
{
    const char *base = strrchr(from, '/');
    char to[8192];
    snprintf(to, sizeof to, "%s/%s", dir, base ? base + 1 : from);
    FILE *in = fopen(from, "rb"), *out = in ? fopen(to, "wb") : NULL;
    char buf[65536];
    size_t n;
    int ok = in && out;
    while (ok && (n = fread(buf, 1, sizeof buf, in)) > 0)
        ok = fwrite(buf, 1, n, out) == n;
    if (in)
        fclose(in);
    if (out && fclose(out) != 0)
        ok = 0;
    return ok ? 0 : -1;
}


static void installed_kernel_dir(void **state)
{
    (void)state;
    skip_without_opencl();
    const char *root = getenv("TF_ROOT");
    char dir[] = "/tmp/tf-test-kernels-XXXXXX", from[4096], err[1024] = "";
    assert_non_null(mkdtemp(dir));
    size_t nfiles = INSTALLED_KERNEL_FILES;
    for (size_t i = 0; i < nfiles; i++) {
        snprintf(from, sizeof from, "%s/%s", root ? root : ".", installed_kernel_files[i]);
        assert_int_equal(copy_into(from, dir), 0);
    }
    setenv("TERRAFARM_KERNELS", dir, 1);
    tf_cl_backend *b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    if (!b)
        print_message("installed layout: %s\n", err);
    assert_non_null(b);
    enum { RW = 24, RH = 16 };
    tf_pixel img[RW * RH];
    assert_int_equal(tf_cl_backend_render(b, (tf_rect){40, 30, RW, RH}, img, NULL, err,
                                          sizeof err), 0);
    if (on_pocl_cpu(b))
        for (int y = 0; y < RH; y++)
            assert_memory_equal(&img[y * RW], &fx.c_img[(size_t)(30 + y) * W + 40],
                                sizeof img[0] * RW);
    tf_cl_backend_free(b);

    /* without one of the shared headers: one line naming it */
    char gone[4096];
    snprintf(gone, sizeof gone, "%s/sample_math.h", dir);
    assert_int_equal(unlink(gone), 0);
    b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    unsetenv("TERRAFARM_KERNELS");
    assert_null(b);
    print_message("without sample_math.h: %s\n", err);
    assert_non_null(strstr(err, "render/sample_math.h"));
    assert_null(strchr(err, '\n'));
    for (size_t i = 0; i < nfiles; i++) {
        const char *base = strrchr(installed_kernel_files[i], '/') + 1;
        snprintf(gone, sizeof gone, "%s/%s", dir, base);
        unlink(gone);
    }
    rmdir(dir);
}

/* An environment variable's value, copied (NULL when unset), and the variable unset; put back
 * with env_give_back. */
static char *env_take(const char *name)
{
    const char *v = getenv(name);
    char *copy = v ? strdup(v) : NULL;
    unsetenv(name);
    return copy;
}

static void env_give_back(const char *name, char *value)
{
    if (value)
        setenv(name, value, 1);
    else
        unsetenv(name);
    free(value);
}

/* tf_backend_share_cores: N OpenCL processes get cores / N PoCL threads each (at least 1), in
 * both of PoCL's variables; the C backend and a single process change nothing, nor does a
 * thread count the user set.  Needs no device. */
static void cores_shared(void **state)
{
    (void)state;
    char *devices = env_take("POCL_DEVICES"), *named = env_take("TERRAFARM_CL_DEVICE");
    unsetenv("POCL_MAX_PTHREAD_COUNT");
    unsetenv("POCL_CPU_MAX_CU_COUNT");
    tf_backend_share_cores("c", 2);
    tf_backend_share_cores("opencl", 1);
    assert_null(getenv("POCL_MAX_PTHREAD_COUNT"));
    assert_null(getenv("POCL_CPU_MAX_CU_COUNT"));
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    char want[24];
    snprintf(want, sizeof want, "%ld", cores / 2 > 1 ? cores / 2 : 1);
    tf_backend_share_cores("auto", 2);
    assert_string_equal(getenv("POCL_MAX_PTHREAD_COUNT"), want);
    assert_string_equal(getenv("POCL_CPU_MAX_CU_COUNT"), want);
    unsetenv("POCL_MAX_PTHREAD_COUNT");
    unsetenv("POCL_CPU_MAX_CU_COUNT");
    tf_backend_share_cores("opencl", 4096); /* more processes than cores: one thread each */
    assert_string_equal(getenv("POCL_MAX_PTHREAD_COUNT"), "1");
    unsetenv("POCL_MAX_PTHREAD_COUNT");
    unsetenv("POCL_CPU_MAX_CU_COUNT");
    setenv("POCL_CPU_MAX_CU_COUNT", "7", 1); /* the user's choice stands */
    tf_backend_share_cores("opencl", 2);
    assert_null(getenv("POCL_MAX_PTHREAD_COUNT"));
    assert_string_equal(getenv("POCL_CPU_MAX_CU_COUNT"), "7");
    unsetenv("POCL_CPU_MAX_CU_COUNT");
    env_give_back("POCL_DEVICES", devices);
    env_give_back("TERRAFARM_CL_DEVICE", named);
}

/* The POCL_DEVICES tf_backend_share_cores leaves for more OpenCL processes than cores (a
 * share of one core each), the thread counts it set cleared again. */
static const char *devices_chosen(void)
{
    unsetenv("POCL_MAX_PTHREAD_COUNT");
    unsetenv("POCL_CPU_MAX_CU_COUNT");
    tf_backend_share_cores("opencl", 4096);
    assert_string_equal(getenv("POCL_MAX_PTHREAD_COUNT"), "1");
    unsetenv("POCL_MAX_PTHREAD_COUNT");
    unsetenv("POCL_CPU_MAX_CU_COUNT");
    return getenv("POCL_DEVICES");
}

/* A share of one core picks PoCL's single-threaded "basic" device, unless the user chose PoCL's
 * devices or named a device; a share of more than one, or a thread count the user set, keeps
 * PoCL's default.  Needs no device. */
static void basic_device_for_one_core(void **state)
{
    (void)state;
    char *devices = env_take("POCL_DEVICES"), *named = env_take("TERRAFARM_CL_DEVICE");
    assert_string_equal(devices_chosen(), "basic");
    setenv("POCL_DEVICES", "pthread", 1);
    assert_string_equal(devices_chosen(), "pthread");
    unsetenv("POCL_DEVICES");
    setenv("TERRAFARM_CL_DEVICE", "pthread", 1);
    assert_null(devices_chosen());
    unsetenv("TERRAFARM_CL_DEVICE");
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    tf_backend_share_cores("opencl", 2);
    if (cores / 2 > 1)
        assert_null(getenv("POCL_DEVICES"));
    else
        assert_string_equal(getenv("POCL_DEVICES"), "basic");
    unsetenv("POCL_MAX_PTHREAD_COUNT");
    unsetenv("POCL_CPU_MAX_CU_COUNT");
    unsetenv("POCL_DEVICES");
    setenv("POCL_MAX_PTHREAD_COUNT", "1", 1);
    tf_backend_share_cores("opencl", 4096);
    assert_null(getenv("POCL_DEVICES"));
    unsetenv("POCL_MAX_PTHREAD_COUNT");
    env_give_back("POCL_DEVICES", devices);
    env_give_back("TERRAFARM_CL_DEVICE", named);
}

static void small_batches(void **state)
{
    (void)state;
    skip_without_opencl();
    char err[1024] = "";
    setenv("TERRAFARM_CL_SCRATCH", "65536", 1); /* ~40 pixels a batch: one work-item's */
    tf_cl_backend *b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    unsetenv("TERRAFARM_CL_SCRATCH");
    assert_non_null(b);
    static tf_pixel img[W * H];
    assert_int_equal(tf_cl_backend_render(b, (tf_rect){0, 0, W, H}, img, NULL, err, sizeof err),
                     0);
    assert_close_to_c(img, "one work-item a launch");
    if (on_pocl_cpu(b))
        assert_memory_equal(img, fx.c_img, sizeof img);
    tf_cl_backend_free(b);
}

/* A backend built with TERRAFARM_CL_ITEMS=items renders the C pixels. */
static void check_item_sizes(const char *items)
{
    char err[1024] = "", what[64];
    setenv("TERRAFARM_CL_ITEMS", items, 1);
    tf_cl_backend *b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    unsetenv("TERRAFARM_CL_ITEMS");
    if (!b)
        fprintf(stderr, "TERRAFARM_CL_ITEMS=%s: %s\n", items, err);
    assert_non_null(b);
    static tf_pixel img[W * H];
    assert_int_equal(tf_cl_backend_render(b, (tf_rect){0, 0, W, H}, img, NULL, err, sizeof err),
                     0);
    snprintf(what, sizeof what, "items %s", items);
    assert_close_to_c(img, what);
    if (on_pocl_cpu(b))
        assert_memory_equal(img, fx.c_img, sizeof img);
    tf_cl_backend_free(b);
}

static void item_sizes(void **state)
{
    (void)state;
    skip_without_opencl();
    check_item_sizes("128x64"); /* a GPU's */
    check_item_sizes("8x1");
}

static int lines(const char *s)
{
    int n = 0;
    for (; *s; s++)
        n += *s == '\n';
    return n;
}

/* A backend opened with name=value: what it wrote on stderr, in out. */
static tf_cl_backend *opened_with(const char *name, const char *value, char *out, size_t len)
{
    char err[1024] = "", path[] = "/tmp/tf-test-stderr-XXXXXX";
    int fd = mkstemp(path), saved = dup(2);
    assert_true(fd >= 0 && saved >= 0);
    unlink(path);
    setenv(name, value, 1);
    dup2(fd, 2);
    tf_cl_backend *b = tf_cl_backend_new(fx.scene, fx.hf, err, sizeof err);
    dup2(saved, 2);
    close(saved);
    unsetenv(name);
    ssize_t n = pread(fd, out, len - 1, 0);
    out[n > 0 ? n : 0] = 0;
    close(fd);
    if (!b)
        fprintf(stderr, "%s=%s: %s\n", name, value, err);
    assert_non_null(b);
    return b;
}

static void tuning_refused(void **state)
{
    (void)state;
    skip_without_opencl();
    static const char *const bad[][2] = {
        {"TERRAFARM_CL_ITEMS", "256x512"}, {"TERRAFARM_CL_ITEMS", "12x8"},
        {"TERRAFARM_CL_ITEMS", "64"},      {"TERRAFARM_CL_LOCAL", "0"},
        {"TERRAFARM_CL_LOCAL", "4k"},      {"TERRAFARM_CL_SCRATCH", "-5"},
    };
    char said[2048], want[128];
    static tf_pixel img[W * H];
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        tf_cl_backend *b = opened_with(bad[i][0], bad[i][1], said, sizeof said);
        snprintf(want, sizeof want, "%s=%s ignored: expected", bad[i][0], bad[i][1]);
        if (!strstr(said, want))
            print_message("%s: stderr was \"%s\"\n", want, said);
        assert_non_null(strstr(said, want));
        assert_int_equal(lines(said), 1);
        if (i == 0) { /* the device's own sizes: the C pixels */
            char err[1024] = "";
            assert_int_equal(
                tf_cl_backend_render(b, (tf_rect){0, 0, W, H}, img, NULL, err, sizeof err), 0);
            assert_close_to_c(img, "after a refused setting");
        }
        tf_cl_backend_free(b);
    }
    tf_cl_backend_free(opened_with("TERRAFARM_CL_ITEMS", "128x64", said, sizeof said));
    assert_string_equal(said, ""); /* a good value: not a word */
}

static void bad_rect(void **state)
{
    (void)state;
    skip_without_opencl();
    tf_pixel px[4];
    char err[1024] = "";
    assert_int_equal(tf_cl_backend_render(fx.cl, (tf_rect){W - 1, 0, 2, 2}, px, NULL, err,
                                          sizeof err), -1);
    assert_non_null(strstr(err, "outside"));
}

static void opened_ahead(void **state)
{
    (void)state;
    skip_without_opencl();
    static tf_pixel img[W * H];
    char err[1024] = "";
    /* started with no scene or terrain in sight, then attached */
    assert_int_equal(tf_opencl_ahead_start(), 0);
    assert_int_equal(tf_opencl_ahead_start(), -1); /* one at a time */
    assert_true(tf_opencl_ahead_pending());
    tf_backend *b = tf_backend_new("opencl", fx.scene, fx.hf, err, sizeof err);
    assert_non_null(b);
    assert_false(tf_opencl_ahead_pending()); /* taken */
    assert_int_equal(tf_backend_render(b, (tf_rect){0, 0, W, H}, img, NULL, err, sizeof err), 0);
    assert_close_to_c(img, "a device opened ahead");
    if (on_pocl_cpu(fx.cl))
        assert_memory_equal(img, fx.c_img, sizeof img);
    tf_backend *again = tf_backend_new("opencl", fx.scene, fx.hf, err, sizeof err);
    assert_non_null(again); /* opened its own */
    tf_backend_free(again);
    tf_backend_free(b);

    /* an opened backend renders nothing until attached, and is attached once */
    tf_cl_backend *cl = tf_cl_backend_open(err, sizeof err);
    assert_non_null(cl);
    assert_int_equal(tf_cl_backend_render(cl, (tf_rect){0, 0, 1, 1}, img, NULL, err, sizeof err),
                     -1);
    assert_non_null(strstr(err, "no scene attached"));
    tf_heightfield proc = *fx.hf;
    proc.proc = (struct tf_procedural *)fx.hf; /* any non-NULL: attach must refuse it unread */
    assert_int_equal(tf_cl_backend_attach(cl, fx.scene, &proc, err, sizeof err), -1);
    assert_non_null(strstr(err, "procedural"));
    assert_int_equal(tf_cl_backend_attach(cl, fx.scene, fx.hf, err, sizeof err), 0);
    assert_int_equal(tf_cl_backend_attach(cl, fx.scene, fx.hf, err, sizeof err), -1);
    assert_non_null(strstr(err, "already"));
    tf_cl_backend_free(cl);

    /* dropped untaken: nothing pending, nothing leaked (make asan) */
    assert_int_equal(tf_opencl_ahead_start(), 0);
    tf_opencl_ahead_drop();
    assert_false(tf_opencl_ahead_pending());
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(match_c_backend), cmocka_unit_test(one_tile_same_rays),
        cmocka_unit_test(rect_invariance),
        cmocka_unit_test(mixed_backends),  cmocka_unit_test(other_scenes),
        cmocka_unit_test(coherent_near_terrain),
        cmocka_unit_test(smooth_scenes),
        cmocka_unit_test(aa_depths_and_tiny_images),
        cmocka_unit_test(bad_device),
        cmocka_unit_test(good_device_override), cmocka_unit_test(bad_kernel_dir),
        cmocka_unit_test(installed_kernel_dir), cmocka_unit_test(bad_rect),
        cmocka_unit_test(small_batches), cmocka_unit_test(item_sizes),
        cmocka_unit_test(tuning_refused),
        cmocka_unit_test(cores_shared),
        cmocka_unit_test(basic_device_for_one_core),
        cmocka_unit_test(opened_ahead),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
