/* bench_encode.c: a worker's encoding of its results, packed by libdeflate (image/exrzip.c, what
 * workers do) against OpenEXRCore's own compress step (zlib, what they did before), on the same
 * rendered pixels.  The scene is rendered once in-process on all cores; then every round
 * encodes the whole image as the default 128x128 stamps of a tiled half file, once with each
 * packer, alternating (zlib, libdeflate, zlib, ...), timing the process's CPU.  It checks that
 * both packings of every chunk inflate to the same bytes (so they decode to the same pixels)
 * and that exrcheck (the coordinator's check of a networked worker's result: inflate, undo the
 * predictor, scan for non-finite values) accepts them, timing that check too.
 *
 *   build/bench/bench_encode SCENE [WxH] [ROUNDS]    (defaults: the scene's size, 7 rounds)
 *   build/bench/bench_encode --smoke SCENE           (64x36, 1 round: tests/e2e/bench_smoke.sh)
 *
 * Prints the CPU and vector ISA, each packer's median ns per pixel, MB/s of raw chunk bytes
 * and packed bytes per pixel, the check's median ns per pixel of libdeflate's chunks, and last
 * "libdeflate/zlib encode cpu ratio: R, bytes ratio B". */
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <zlib.h>

#include "bench_cpu.h"
#include "bench_stats.h"
#include "image/exrcheck.h"
#include "image/exrencode.h"
#include "image/exrlayout.h"
#include "render/render.h"
#include "scene.h"
#include "terrain/heightfield.h"

#define STAMP 128
#define MAX_ROUNDS 64

typedef struct job {
    const tf_renderer *r;
    int width, height;
    tf_pixel *img;
    atomic_int next_row;
} job;

static void *render_rows(void *p)
{
    job *j = p;
    for (int y; (y = atomic_fetch_add(&j->next_row, 1)) < j->height;)
        tf_render_rect(j->r, (tf_rect){0, y, j->width, 1}, &j->img[(size_t)y * j->width], NULL);
    return NULL;
}

/* The image's pixels, rendered on every core; NULL with a message on failure. */
static tf_pixel *render_image(const char *path, int w, int h)
{
    char err[512];
    tf_scene *s = tf_scene_load(path, err, sizeof err);
    if (!s) {
        fprintf(stderr, "bench_encode: %s\n", err);
        return NULL;
    }
    tf_scene_set_size(s, w, h);
    tf_heightfield *hf = tf_heightfield_build(s, 0, err, sizeof err);
    tf_renderer *r = hf ? tf_renderer_new(s, hf, err, sizeof err) : NULL;
    tf_pixel *img = r ? calloc((size_t)w * h, sizeof *img) : NULL;
    if (!img) {
        fprintf(stderr, "bench_encode: %s\n", r ? "out of memory" : err);
        return NULL;
    }
    job j = {.r = r, .width = w, .height = h, .img = img};
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    pthread_t t[64];
    int threads = n < 1 ? 1 : n > 64 ? 64 : (int)n;
    for (int i = 0; i < threads; i++)
        pthread_create(&t[i], NULL, render_rows, &j);
    for (int i = 0; i < threads; i++)
        pthread_join(t[i], NULL);
    tf_renderer_free(r);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return img;
}

/* The inflated bytes of each chunk of a payload, appended to *out (the ZIP filter still on:
 * two packings of the same chunk must give the same bytes).  0, or -1 if one does not decode. */
static int inflate_all(const tf_chunk_payload *p, uint8_t **out, size_t *len, size_t *cap)
{
    const uint8_t *at = p->chunks;
    for (size_t i = 0; i < p->nchunks; i++) {
        tf_chunk_rec c;
        tf_chunk_rec_get(p->index + i * TF_CHUNK_RECORD_BYTES, &c);
        size_t need = *len + (size_t)c.unpacked;
        if (need > *cap) {
            uint8_t *grown = realloc(*out, need * 2);
            if (!grown)
                return -1;
            *out = grown;
            *cap = need * 2;
        }
        uLongf got = (uLongf)c.unpacked;
        if (c.packed == c.unpacked)
            memcpy(*out + *len, at, (size_t)c.packed);
        else if (uncompress(*out + *len, &got, at, (uLong)c.packed) != Z_OK ||
                 got != (uLongf)c.unpacked)
            return -1;
        *len += (size_t)c.unpacked;
        at += c.packed;
    }
    return 0;
}

typedef struct side {
    const char *name;
    tf_exr_encoder *enc;
    double ns_px[MAX_ROUNDS];
    double check_ns_px[MAX_ROUNDS]; /* tf_exr_chunk_check of every chunk */
    size_t packed;       /* bytes of the whole image's chunks */
    uint8_t *inflated;   /* the last round's chunks, inflated */
    size_t inflated_len, inflated_cap;
    int refused;         /* chunks exrcheck refused */
} side;

/* One round of one packer: every stamp of the image encoded; its CPU per pixel in ns_px[k]. */
static int encode_image(side *sd, const tf_exr_layout *l, const tf_pixel *img, int k)
{
    char err[256];
    tf_pixel *stamp = malloc((size_t)STAMP * STAMP * sizeof *stamp);
    uint8_t *scratch = NULL;
    size_t scratch_cap = 0;
    double spent = 0, checking = 0;
    sd->packed = sd->inflated_len = 0;
    for (int y = 0; y < l->height; y += STAMP)
        for (int x = 0; x < l->width; x += STAMP) {
            tf_rect r = {x, y, l->width - x < STAMP ? l->width - x : STAMP,
                         l->height - y < STAMP ? l->height - y : STAMP};
            for (int j = 0; j < r.h; j++)
                memcpy(stamp + (size_t)j * r.w, img + (size_t)(y + j) * l->width + x,
                       (size_t)r.w * sizeof *stamp);
            tf_chunk_payload p;
            double t0 = tf_bench_process_cpu_s();
            int rc = tf_exr_encode_rect(sd->enc, r, stamp, &p, err, sizeof err);
            spent += tf_bench_process_cpu_s() - t0;
            if (rc) {
                fprintf(stderr, "bench_encode: %s: %s\n", sd->name, err);
                free(stamp);
                return -1;
            }
            sd->packed += p.chunks_len;
            const uint8_t *at = p.chunks;
            for (size_t i = 0; i < p.nchunks; i++) {
                tf_chunk_rec c;
                tf_chunk_rec_get(p.index + i * TF_CHUNK_RECORD_BYTES, &c);
                tf_chunk_ref ref = tf_layout_chunk(l, tf_layout_chunk_index(l, c.cx, c.cy));
                t0 = tf_bench_process_cpu_s();
                sd->refused += tf_exr_chunk_check(l, &ref, at, (size_t)c.packed, &scratch,
                                                  &scratch_cap, err, sizeof err) != 0;
                checking += tf_bench_process_cpu_s() - t0;
                at += c.packed;
            }
            if (inflate_all(&p, &sd->inflated, &sd->inflated_len, &sd->inflated_cap))
                sd->refused++;
        }
    free(stamp);
    free(scratch);
    sd->ns_px[k] = spent * 1e9 / ((double)l->width * l->height);
    sd->check_ns_px[k] = checking * 1e9 / ((double)l->width * l->height);
    return 0;
}

int main(int argc, char **argv)
{
    int smoke = argc > 1 && !strcmp(argv[1], "--smoke");
    if (argc < 2 + smoke) {
        fprintf(stderr, "usage: bench_encode SCENE [WxH] [ROUNDS] | --smoke SCENE\n");
        return 2;
    }
    const char *scene = argv[1 + smoke];
    int w = 0, h = 0, rounds = smoke ? 1 : 7;
    if (smoke)
        w = 64, h = 36;
    else if (argc > 2 && sscanf(argv[2], "%dx%d", &w, &h) != 2) {
        fprintf(stderr, "bench_encode: size %s is not WxH\n", argv[2]);
        return 2;
    }
    if (!smoke && argc > 3)
        rounds = atoi(argv[3]);
    if (rounds < 1 || rounds > MAX_ROUNDS) {
        fprintf(stderr, "bench_encode: rounds must be 1..%d\n", MAX_ROUNDS);
        return 2;
    }
    if (w <= 0 || h <= 0) { /* the scene's own size */
        char err[256];
        tf_scene *s = tf_scene_load(scene, err, sizeof err);
        if (!s) {
            fprintf(stderr, "bench_encode: %s\n", err);
            return 1;
        }
        w = s->width, h = s->height;
        tf_scene_free(s);
    }
    tf_pixel *img = render_image(scene, w, h);
    if (!img)
        return 1;
    tf_exr_layout l = {w, h, 1, STAMP, STAMP, TF_PIXEL_HALF};
    char err[256], model[128];
    side sides[2] = {{.name = "zlib (OpenEXRCore)"}, {.name = "libdeflate (exrzip)"}};
    for (int i = 0; i < 2; i++)
        if (!(sides[i].enc = tf_exr_encoder_new(&l, err, sizeof err))) {
            fprintf(stderr, "bench_encode: %s\n", err);
            return 1;
        }
    tf_exr_encoder_use_openexr_zlib(sides[0].enc, 1);
    for (int k = 0; k < rounds; k++)
        for (int i = 0; i < 2; i++)
            if (encode_image(&sides[i], &l, img, k))
                return 1;
    tf_bench_cpu_model(model, sizeof model);
    printf("cpu: %s, isa %s\n", model, tf_bench_vector_isa());
    printf("image: %s %dx%d, tiles %dx%d half, %d rounds alternating\n", scene, w, h, STAMP,
           STAMP, rounds);
    double px = (double)w * h, raw = (double)sides[0].inflated_len;
    for (int i = 0; i < 2; i++) {
        double ns = tf_bench_median(sides[i].ns_px, rounds);
        printf("%-20s %7.1f ns/pixel  %6.0f MB/s  %.2f bytes/pixel  (refused %d)\n",
               sides[i].name, ns, ns > 0 ? raw / (ns * px * 1e-9) / 1e6 : 0.0,
               (double)sides[i].packed / px, sides[i].refused);
    }
    printf("exrcheck of libdeflate's chunks %5.1f ns/pixel\n",
           tf_bench_median(sides[1].check_ns_px, rounds));
    int same = sides[0].inflated_len == sides[1].inflated_len &&
               !memcmp(sides[0].inflated, sides[1].inflated, sides[0].inflated_len);
    int ok = same && !sides[0].refused && !sides[1].refused;
    printf("chunks inflate to the same bytes: %s\n", same ? "yes" : "NO");
    double a = tf_bench_median(sides[0].ns_px, rounds), b = tf_bench_median(sides[1].ns_px, rounds);
    printf("libdeflate/zlib encode cpu ratio: %.3f, bytes ratio %.3f\n", a > 0 ? b / a : 0.0,
           (double)sides[1].packed / (double)sides[0].packed);
    for (int i = 0; i < 2; i++) {
        tf_exr_encoder_free(sides[i].enc);
        free(sides[i].inflated);
    }
    free(img);
    return ok ? 0 : 1;
}
