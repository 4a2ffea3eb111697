/* povray_tf_render.c: terrafarm's side of the render-proper timing in bench/povray_compare.sh.
 *
 * Renders SCENE exactly as one worker renders one task covering the whole image: a single
 * tf_render_rect call on one thread (so the only external samples are the one row and column
 * past the image's far edges, as in a real render's border overhead), and reports the CPU time
 * of that call and of the renderer's setup before it (tf_renderer_new: the camera and the
 * shader a worker sets up for its render; CLOCK_THREAD_CPUTIME_ID: robust on a shared
 * machine), next to the camera and shadow rays per pixel.  Terrain synthesis and output are
 * outside the timed span, and so is what a worker finds built with the terrain
 * (tf_render_prepare: the sun's strips, built once by the process that forks the workers),
 * whose CPU time on this thread is printed apart (prepare_cpu_s);
 * POV-Ray's "Trace Time ... CPU-seconds" likewise excludes its parsing and PNG loading.
 * Writes the 8-bit sRGB PNG so the picture can be compared with POV-Ray's.
 *
 *   build/bench/povray_tf_render [--smoke] SCENE OUT.png [WxH]   (--smoke: 16x9 unless WxH)
 *   prints: render_cpu_s=0.123 camera_rays_per_pixel=4.52 shadow_rays_per_pixel=3.9
 *           prepare_cpu_s=0.012 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "terrain/heightfield.h"
#include "image/png_write.h"
#include "image/preview.h"
#include "render/render.h"
#include "scene.h"

static double thread_cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static int write_png(const char *path, const tf_pixel *img, int w, int h)
{
    char err[256];
    tf_png_writer *pw = tf_png_create(path, w, h, 8, 3, err, sizeof err);
    if (!pw) {
        fprintf(stderr, "povray_tf_render: %s\n", err);
        return -1;
    }
    unsigned char *row = malloc((size_t)w * 3);
    if (!row) {
        fprintf(stderr, "povray_tf_render: out of memory for a PNG row\n");
        tf_png_abort(pw);
        return -1;
    }
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            const tf_pixel *p = &img[(size_t)y * (size_t)w + (size_t)x];
            row[3 * x] = tf_srgb8(p->r);
            row[3 * x + 1] = tf_srgb8(p->g);
            row[3 * x + 2] = tf_srgb8(p->b);
        }
        if (tf_png_write_row(pw, row, err, sizeof err) != 0) {
            fprintf(stderr, "povray_tf_render: %s\n", err);
            tf_png_abort(pw);
            free(row);
            return -1;
        }
    }
    free(row);
    if (tf_png_finish(pw, err, sizeof err) != 0) {
        fprintf(stderr, "povray_tf_render: %s\n", err);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    int smoke = argc > 1 && !strcmp(argv[1], "--smoke");
    if (smoke) {
        argv[1] = argv[0];
        argv++;
        argc--;
    }
    if (argc < 3 || argc > 4) {
        fprintf(stderr, "usage: %s [--smoke] SCENE OUT.png [WxH]\n", argv[0]);
        return 2;
    }
    int w = smoke ? 16 : 0, h = smoke ? 9 : 0;
    if (argc == 4 && (sscanf(argv[3], "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0 ||
                      w > 16384 || h > 16384)) {
        fprintf(stderr, "povray_tf_render: bad size '%s' (WxH, each 1..16384)\n", argv[3]);
        return 2;
    }
    char err[512];
    tf_scene *s = tf_scene_load(argv[1], err, sizeof err);
    if (!s) {
        fprintf(stderr, "povray_tf_render: %s\n", err);
        return 1;
    }
    if (w > 0)
        tf_scene_set_size(s, w, h);
    tf_heightfield *hf = tf_heightfield_build(s, 1, err, sizeof err);
    /* what a worker finds built with the terrain (the sun's strips: tf_render_prepare), on
     * this one thread, timed apart */
    double tp = thread_cpu_s();
    if (hf)
        tf_render_prepare(s, hf, 1);
    double prepare = thread_cpu_s() - tp;
    double t0 = thread_cpu_s();
    tf_renderer *r = hf ? tf_renderer_new(s, hf, err, sizeof err) : NULL;
    tf_pixel *img = malloc(sizeof(tf_pixel) * (size_t)s->width * (size_t)s->height);
    if (!hf || !r || !img) {
        fprintf(stderr, "povray_tf_render: %s\n", img ? err : "out of memory for the image");
        return 1;
    }
    tf_render_counts counts = {0};
    tf_render_rect(r, (tf_rect){0, 0, s->width, s->height}, img, &counts);
    double cpu = thread_cpu_s() - t0;
    int rc = write_png(argv[2], img, s->width, s->height);
    double pixels = (double)s->width * (double)s->height;
    printf("render_cpu_s=%.4f camera_rays_per_pixel=%.3f shadow_rays_per_pixel=%.3f "
           "prepare_cpu_s=%.4f\n", cpu, (double)counts.primary_rays / pixels,
           (double)counts.shadow_rays / pixels, prepare);
    free(img);
    tf_renderer_free(r);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return rc ? 1 : 0;
}
