/* bench_aa.c: adaptive antialiasing versus uniform supersampling (docs/contract.md section 6: "the
 * quality of 16 uniform samples per pixel for <= 1/3 the rays").
 *
 * Renders one scene three ways in one run, on all cores (threads take rows):
 *   reference   256 stratified jittered samples per pixel (tf_render_pixel_uniform, 16x16)
 *   uniform16   16 stratified jittered samples per pixel (4x4)
 *   adaptive    tf_render_rect over 32x32 stamps (the smallest default task of the farm, so
 *               the external corner samples cost what they cost in a real render), at the
 *               scene's threshold and max_depth, then a sweep of thresholds at max_depth 3
 * and prints camera rays per pixel and PSNR against the reference (on the sRGB-encoded image,
 * what a viewer sees), then the ray ratio adaptive / uniform16.
 *
 *   build/bench/bench_aa [--smoke] SCENE [WxH]   (default 160x90: the reference is 256
 *   rays/pixel; --smoke: 16x9 and the scene's threshold only, for tests/e2e/bench_smoke.sh) */
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "terrain/heightfield.h"
#include "image/preview.h"
#include "render/render.h"
#include "render/render_internal.h"
#include "scene.h"

#define MAX_THREADS 64
#define STAMP 32 /* adaptive pass: task side in pixels */

typedef struct pass {
    const tf_renderer *r;
    int width, height;
    int uniform_n;        /* 0 = adaptive (tf_render_rect), else n x n uniform samples */
    tf_pixel *img;
    atomic_int next_row;
    tf_render_counts counts[MAX_THREADS];
} pass;

typedef struct worker_arg { pass *p; int id; } worker_arg;

static void *worker(void *arg)
{
    worker_arg *a = arg;
    pass *p = a->p;
    for (;;) {
        int y = atomic_fetch_add(&p->next_row, 1);
        if (y >= p->height)
            return NULL;
        tf_pixel *row = &p->img[(size_t)y * p->width];
        if (p->uniform_n == 0) {
            /* a band of STAMP rows, cut into STAMP-wide stamps; row y leads its band */
            if (y % STAMP != 0)
                continue;
            int h = p->height - y < STAMP ? p->height - y : STAMP;
            tf_pixel stamp[STAMP * STAMP];
            for (int x = 0; x < p->width; x += STAMP) {
                int w = p->width - x < STAMP ? p->width - x : STAMP;
                tf_render_rect(p->r, (tf_rect){x, y, w, h}, stamp, &p->counts[a->id]);
                for (int j = 0; j < h; j++)
                    memcpy(&p->img[(size_t)(y + j) * p->width + x], &stamp[j * w],
                           sizeof(tf_pixel) * (size_t)w);
            }
        } else
            for (int x = 0; x < p->width; x++)
                tf_render_pixel_uniform(p->r, x, y, p->uniform_n, &row[x], &p->counts[a->id]);
    }
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* Run one pass; returns camera rays per pixel, sets *seconds. */
static double run_pass(const tf_renderer *r, int w, int h, int uniform_n, tf_pixel *img,
                       int threads, double *seconds)
{
    pass *p = calloc(1, sizeof *p);
    *p = (pass){.r = r, .width = w, .height = h, .uniform_n = uniform_n, .img = img};
    pthread_t tid[MAX_THREADS];
    worker_arg args[MAX_THREADS];
    double t0 = now_s();
    for (int i = 0; i < threads; i++) {
        args[i] = (worker_arg){p, i};
        pthread_create(&tid[i], NULL, worker, &args[i]);
    }
    for (int i = 0; i < threads; i++)
        pthread_join(tid[i], NULL);
    *seconds = now_s() - t0;
    uint64_t rays = 0;
    for (int i = 0; i < threads; i++)
        rays += p->counts[i].primary_rays;
    free(p);
    return (double)rays / ((double)w * h);
}

/* PSNR in dB of img against ref, both sRGB-encoded to [0, 1] first. */
static double psnr(const tf_pixel *img, const tf_pixel *ref, size_t n)
{
    double se = 0;
    for (size_t i = 0; i < n; i++) {
        const float a[3] = {img[i].r, img[i].g, img[i].b}, b[3] = {ref[i].r, ref[i].g, ref[i].b};
        for (int c = 0; c < 3; c++) {
            double d = (tf_srgb8(a[c]) - tf_srgb8(b[c])) / 255.0;
            se += d * d;
        }
    }
    double mse = se / (3.0 * n);
    return mse > 0 ? 10.0 * log10(1.0 / mse) : INFINITY;
}

int main(int argc, char **argv)
{
    int smoke = argc > 1 && !strcmp(argv[1], "--smoke");
    if (smoke) {
        argv[1] = argv[0];
        argv++;
        argc--;
    }
    if (argc < 2) {
        fprintf(stderr, "usage: %s [--smoke] SCENE [WxH]\n", argv[0]);
        return 2;
    }
    int w = smoke ? 16 : 160, h = smoke ? 9 : 90;
    if (argc > 2 && (sscanf(argv[2], "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0 || w > 4096 ||
                     h > 4096)) {
        fprintf(stderr, "bench_aa: bad size '%s'\n", argv[2]);
        return 2;
    }
    char err[512];
    tf_scene *s = tf_scene_load(argv[1], err, sizeof err);
    if (!s) {
        fprintf(stderr, "bench_aa: %s\n", err);
        return 1;
    }
    tf_scene_set_size(s, w, h);
    int threads = tf_thread_count(0);
    threads = threads > MAX_THREADS ? MAX_THREADS : threads;
    tf_heightfield *hf = tf_heightfield_build(s, threads, err, sizeof err);
    if (!hf) {
        fprintf(stderr, "bench_aa: %s\n", err);
        return 1;
    }
    size_t n = (size_t)w * h;
    tf_pixel *ref = malloc(sizeof *ref * n), *img = malloc(sizeof *img * n);
    if (!ref || !img) {
        fprintf(stderr, "bench_aa: out of memory\n");
        return 1;
    }
    double scene_threshold = s->antialias.threshold;
    tf_renderer *r = tf_renderer_new(s, hf, err, sizeof err);
    if (!r) {
        fprintf(stderr, "bench_aa: %s\n", err);
        return 1;
    }
    printf("bench_aa %s %dx%d, %d threads\n", argv[1], w, h, threads);
    double secs;
    double rpp_ref = run_pass(r, w, h, 16, ref, threads, &secs);
    printf("%-34s %7.2f rays/pixel            %6.2f s\n", "reference (16x16 uniform)", rpp_ref,
           secs);
    double rpp_u = run_pass(r, w, h, 4, img, threads, &secs);
    double psnr_u = psnr(img, ref, n);
    printf("%-34s %7.2f rays/pixel  %6.2f dB  %6.2f s\n", "uniform16 (4x4 stratified)", rpp_u,
           psnr_u, secs);
    tf_renderer_free(r);

    /* the scene's threshold first (the headline), then a sweep to show the trade-off */
    int scene_depth = s->antialias.max_depth;
    const double thresholds[] = {scene_threshold, 0.06, 0.04, 0.03, 0.025, 0.02, 0.015, 0.01};
    double head_rpp = 0, head_psnr = 0;
    size_t sweep = smoke ? 1 : sizeof thresholds / sizeof thresholds[0];
    for (size_t i = 0; i < sweep; i++) {
        s->antialias.max_depth = i == 0 ? scene_depth : 3;
        s->antialias.threshold = thresholds[i];
        r = tf_renderer_new(s, hf, err, sizeof err);
        double rpp = run_pass(r, w, h, 0, img, threads, &secs);
        double q = psnr(img, ref, n);
        char label[64];
        snprintf(label, sizeof label, "adaptive depth %d, threshold %.3g%s",
                 s->antialias.max_depth, thresholds[i], i == 0 ? "*" : "");
        printf("%-34s %7.2f rays/pixel  %6.2f dB  %6.2f s\n", label, rpp, q, secs);
        if (i == 0) {
            head_rpp = rpp;
            head_psnr = q;
        }
        tf_renderer_free(r);
    }
    printf("* scene threshold: adaptive/uniform16 rays = %.3f (target <= 0.333), "
           "PSNR %+.2f dB vs uniform16 (target >= 0)\n",
           head_rpp / rpp_u, head_psnr - psnr_u);
    free(ref);
    free(img);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return 0;
}
