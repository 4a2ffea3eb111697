/* render_png.c: a look-at-it tool for the renderer core.  Renders a scene in-process on all
 * cores (threads take whole rows from a shared counter; each row is one tf_render_rect, so the
 * image is the same bits whatever the thread count) and writes an 8-bit sRGB PNG (clamp + sRGB
 * curve, tf_srgb8).  Prints rays per pixel and the time.
 *
 *   build/bench/render_png SCENE OUT.png [WxH] [-d MAX_DEPTH] [-t THRESHOLD] [-j THREADS]
 *                          [--smoke]   (--smoke: 16x9, for tests/e2e/bench_smoke.sh) */
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "terrain/heightfield.h"
#include "image/png_write.h"
#include "image/preview.h"
#include "render/render.h"
#include "scene.h"

typedef struct job {
    const tf_renderer *r;
    int width, height;
    tf_pixel *img;
    atomic_int next_row;
    tf_render_counts counts[64];
} job;

typedef struct worker_arg { job *j; int id; } worker_arg;

static void *worker(void *p)
{
    worker_arg *a = p;
    job *j = a->j;
    for (;;) {
        int y = atomic_fetch_add(&j->next_row, 1);
        if (y >= j->height)
            return NULL;
        tf_render_rect(j->r, (tf_rect){0, y, j->width, 1}, &j->img[(size_t)y * j->width],
                       &j->counts[a->id]);
    }
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int write_png(const char *path, const tf_pixel *img, int w, int h)
{
    char err[256];
    tf_png_writer *pw = tf_png_create(path, w, h, 8, 3, err, sizeof err);
    if (!pw) {
        fprintf(stderr, "render_png: %s\n", err);
        return -1;
    }
    unsigned char *row = malloc((size_t)w * 3);
    for (int y = 0; y < h && row; y++) {
        for (int x = 0; x < w; x++) {
            const tf_pixel *p = &img[(size_t)y * w + x];
            row[3 * x] = tf_srgb8(p->r);
            row[3 * x + 1] = tf_srgb8(p->g);
            row[3 * x + 2] = tf_srgb8(p->b);
        }
        if (tf_png_write_row(pw, row, err, sizeof err) != 0) {
            fprintf(stderr, "render_png: %s\n", err);
            tf_png_abort(pw);
            free(row);
            return -1;
        }
    }
    free(row);
    if (tf_png_finish(pw, err, sizeof err) != 0) {
        fprintf(stderr, "render_png: %s\n", err);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s SCENE OUT.png [WxH] [-d MAX_DEPTH] [-t THRESHOLD] [-j THREADS] "
                "[--smoke]\n",
                argv[0]);
        return 2;
    }
    int w = 0, h = 0, depth = -1, threads = 0;
    double threshold = -1;
    for (int i = 3; i < argc; i++) {
        if (!strcmp(argv[i], "-d") && i + 1 < argc)
            depth = atoi(argv[++i]);
        else if (!strcmp(argv[i], "-t") && i + 1 < argc)
            threshold = atof(argv[++i]);
        else if (!strcmp(argv[i], "-j") && i + 1 < argc)
            threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--smoke"))
            w = 16, h = 9;
        else if (sscanf(argv[i], "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0 || w > 65536 ||
                 h > 65536) {
            fprintf(stderr, "render_png: bad argument '%s'\n", argv[i]);
            return 2;
        }
    }
    char err[512];
    tf_scene *s = tf_scene_load(argv[1], err, sizeof err);
    if (!s) {
        fprintf(stderr, "render_png: %s\n", err);
        return 1;
    }
    if (w > 0)
        tf_scene_set_size(s, w, h);
    if (depth >= 0)
        s->antialias.max_depth = depth;
    if (threshold >= 0)
        s->antialias.threshold = threshold;
    threads = tf_thread_count(threads);
    if (threads > 64)
        threads = 64;

    double t0 = now_s();
    tf_heightfield *hf = tf_heightfield_build(s, threads, err, sizeof err);
    if (!hf) {
        fprintf(stderr, "render_png: %s\n", err);
        return 1;
    }
    double t1 = now_s();
    tf_renderer *r = tf_renderer_new(s, hf, err, sizeof err);
    if (!r) {
        fprintf(stderr, "render_png: %s\n", err);
        return 1;
    }
    job *j = calloc(1, sizeof *j);
    j->r = r;
    j->width = s->width;
    j->height = s->height;
    j->img = malloc(sizeof(tf_pixel) * (size_t)s->width * (size_t)s->height);
    if (!j->img) {
        fprintf(stderr, "render_png: out of memory for a %dx%d image\n", s->width, s->height);
        return 1;
    }
    pthread_t tid[64];
    worker_arg args[64];
    for (int i = 0; i < threads; i++) {
        args[i] = (worker_arg){j, i};
        pthread_create(&tid[i], NULL, worker, &args[i]);
    }
    for (int i = 0; i < threads; i++)
        pthread_join(tid[i], NULL);
    double t2 = now_s();

    tf_render_counts total = {0};
    for (int i = 0; i < threads; i++) {
        total.primary_rays += j->counts[i].primary_rays;
        total.shadow_rays += j->counts[i].shadow_rays;
        total.external_rays += j->counts[i].external_rays;
        total.pixels += j->counts[i].pixels;
    }
    int rc = write_png(argv[2], j->img, s->width, s->height);
    printf("%s: %dx%d, max_depth %d, threshold %g, %d threads\n", argv[1], s->width, s->height,
           s->antialias.max_depth, s->antialias.threshold, threads);
    printf("terrain %.2f s, render %.2f s, %.2f camera rays/pixel (%.1f%% external), "
           "%.2f shadow rays/pixel, %.0f camera rays/s\n",
           t1 - t0, t2 - t1, (double)total.primary_rays / total.pixels,
           100.0 * total.external_rays / total.primary_rays,
           (double)total.shadow_rays / total.pixels, total.primary_rays / (t2 - t1));
    free(j->img);
    free(j);
    tf_renderer_free(r);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return rc ? 1 : 0;
}
