/* bench_trace.c: rays per second of the grid tracer, flat DDA against the max-mipmap hierarchy,
 * measured side by side in one run on the same rays (docs/contract.md section 6, "tracing").
 *
 * Builds an fBm terrain (tf_fbm2) of (2^k+1)^2 samples for each k given (default 10 and 12),
 * puts a pinhole camera a little above one corner looking across the terrain toward the horizon,
 * and shoots one primary ray per pixel, then one shadow ray toward a low sun from every primary
 * hit.  Every ray goes through tf_trace_flat and tf_trace (tf_occluded for shadows); results must
 * agree exactly (the run fails otherwise).  Single threaded, so the figures are per core.
 *
 * Usage: bench_trace [-s WxH] [k ...]
 *        bench_trace --smoke    (16x9 rays over k = 5: for tests/e2e/bench_smoke.sh) */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "render/trace.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* fBm mountains: extent 10 km, about 2 km of relief, features down to the grid spacing. */
static tf_heightfield *build_terrain(int k, double extent)
{
    size_t n = ((size_t)1 << k) + 1;
    float *h = malloc(n * n * sizeof *h);
    if (!h)
        return NULL;
    tf_noise nz;
    tf_noise_init(&nz, 1234);
    const double freq = 3.0 / (double)(n - 1); /* lowest octave: 3 periods across */
    const double octaves = k - 1;              /* up to about two samples per period */
    for (size_t j = 0; j < n; j++)
        for (size_t i = 0; i < n; i++)
            h[j * n + i] = (float)(1000.0 * tf_fbm2(&nz, i * freq, j * freq, 0.85, 2.0, octaves));
    return tf_heightfield_wrap(h, k, extent, 0);
}

typedef struct ray_set {
    int count;
    tf_vec3 *o, *d;
} ray_set;

/* Primary rays of a camera at (0.05 E, 0.05 E), 60 m above the ground, looking along the
 * diagonal, tilted down a little so the horizon sits in the upper part of the image. */
static ray_set primary_rays(const tf_heightfield *hf, int w, int h)
{
    ray_set rs = {w * h, malloc(sizeof(tf_vec3) * w * h), malloc(sizeof(tf_vec3) * w * h)};
    double e = hf->extent, cx = 0.05 * e, cy = 0.05 * e;
    tf_vec3 eye = v3(cx, cy, tf_heightfield_height_at(hf, cx, cy) + 60.0);
    tf_vec3 fwd = v3_norm(v3(1, 1, -0.12));
    tf_vec3 right = v3_norm(v3_cross(fwd, v3(0, 0, 1)));
    tf_vec3 up = v3_cross(right, fwd);
    double half = tan(0.5 * 50.0 * M_PI / 180.0), aspect = (double)w / h;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double sx = ((x + 0.5) / w * 2 - 1) * half * aspect, sy = (1 - (y + 0.5) / h * 2) * half;
            rs.o[y * w + x] = eye;
            rs.d[y * w + x] = v3_norm(v3_add(fwd, v3_add(v3_scale(right, sx), v3_scale(up, sy))));
        }
    return rs;
}

static void free_rays(ray_set *rs)
{
    free(rs->o);
    free(rs->d);
}

static int bench_k(int k, int w, int h)
{
    double t_build = now_s();
    tf_heightfield *hf = build_terrain(k, 10000.0);
    if (!hf) {
        fprintf(stderr, "bench_trace: out of memory building k = %d\n", k);
        return 1;
    }
    t_build = now_s() - t_build;
    ray_set prim = primary_rays(hf, w, h);
    tf_hit *hits_flat = malloc(sizeof(tf_hit) * prim.count);
    tf_hit *hits_hier = malloc(sizeof(tf_hit) * prim.count);
    char *hit_flat = calloc(prim.count, 1), *hit_hier = calloc(prim.count, 1);

    double t0 = now_s();
    for (int i = 0; i < prim.count; i++)
        hit_flat[i] = (char)tf_trace_flat(hf, prim.o[i], prim.d[i], 0, INFINITY, &hits_flat[i]);
    double t_flat = now_s() - t0;
    t0 = now_s();
    for (int i = 0; i < prim.count; i++)
        hit_hier[i] = (char)tf_trace(hf, prim.o[i], prim.d[i], 0, INFINITY, &hits_hier[i]);
    double t_hier = now_s() - t0;

    int hits = 0, mismatches = 0;
    for (int i = 0; i < prim.count; i++) {
        hits += hit_hier[i];
        if (hit_flat[i] != hit_hier[i] ||
            (hit_hier[i] && memcmp(&hits_flat[i], &hits_hier[i], sizeof(tf_hit)) != 0))
            mismatches++;
    }

    /* Shadow rays from every hit toward a sun 8 degrees above the horizon. */
    tf_vec3 sun = v3_norm(v3(cos(0.14) * 0.6, cos(0.14) * -0.8, sin(0.14)));
    ray_set shad = {hits, malloc(sizeof(tf_vec3) * (hits + 1)), malloc(sizeof(tf_vec3) * (hits + 1))};
    for (int i = 0, s = 0; i < prim.count; i++)
        if (hit_hier[i]) {
            shad.o[s] = hits_hier[i].p;
            shad.d[s++] = sun;
        }
    const double eps = 1e-3; /* metres: leave the surface we start on */
    int occl_flat = 0, occl_hier = 0;
    t0 = now_s();
    for (int i = 0; i < shad.count; i++)
        occl_flat += tf_trace_flat(hf, shad.o[i], shad.d[i], eps, INFINITY, NULL);
    double s_flat = now_s() - t0;
    t0 = now_s();
    for (int i = 0; i < shad.count; i++)
        occl_hier += tf_occluded(hf, shad.o[i], shad.d[i], eps, INFINITY);
    double s_hier = now_s() - t0;

    printf("k=%d (%dx%d samples, terrain built in %.2f s), %dx%d primary rays, %d hits, %d shadow rays, %d in shadow\n",
           k, hf->n, hf->n, t_build, w, h, hits, shad.count, occl_hier);
    printf("  primary  flat %10.0f rays/s   hierarchy %10.0f rays/s   hierarchy/flat %.2fx\n",
           prim.count / t_flat, prim.count / t_hier, t_flat / t_hier);
    if (shad.count)
        printf("  shadow   flat %10.0f rays/s   hierarchy %10.0f rays/s   hierarchy/flat %.2fx\n",
               shad.count / s_flat, shad.count / s_hier, s_flat / s_hier);
    int bad = mismatches || occl_flat != occl_hier;
    if (bad)
        printf("  MISMATCH: %d primary rays differ, shadows %d vs %d\n", mismatches, occl_flat, occl_hier);

    free_rays(&prim);
    free_rays(&shad);
    free(hits_flat);
    free(hits_hier);
    free(hit_flat);
    free(hit_hier);
    tf_heightfield_free(hf);
    return bad;
}

int main(int argc, char **argv)
{
    int w = 320, h = 200, ks[16], nk = 0;
    for (int a = 1; a < argc; a++) {
        if (strcmp(argv[a], "--smoke") == 0) {
            w = 16;
            h = 9;
            ks[nk++] = 5;
        } else if (strcmp(argv[a], "-s") == 0 && a + 1 < argc) {
            if (sscanf(argv[++a], "%dx%d", &w, &h) != 2 || w < 1 || h < 1 || w > 8192 || h > 8192) {
                fprintf(stderr, "bench_trace: bad size '%s' (want WxH)\n", argv[a]);
                return 2;
            }
        } else {
            char *end;
            long k = strtol(argv[a], &end, 10);
            if (*end || k < 1 || k > 14 || nk == 16) {
                fprintf(stderr, "usage: bench_trace [-s WxH] [k ...] | --smoke   (1 <= k <= 14)\n");
                return 2;
            }
            ks[nk++] = (int)k;
        }
    }
    if (nk == 0) {
        ks[nk++] = 10;
        ks[nk++] = 12;
    }
    int bad = 0;
    for (int i = 0; i < nk; i++)
        bad |= bench_k(ks[i], w, h);
    return bad;
}
