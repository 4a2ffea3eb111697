/* bench_trace.c: rays per second of the grid tracer, flat DDA against the max-mipmap hierarchy,
 * measured side by side in one run on the same rays (docs/contract.md section 6, "tracing").
 *
 * Builds an fBm terrain (tf_fbm2) of (2^k+1)^2 samples for each k given (default 10 and 12),
 * puts a pinhole camera a little above one corner looking across the terrain toward the horizon,
 * and shoots one primary ray per pixel, then one shadow ray toward a low sun from every primary
 * hit.  Every ray goes through tf_trace_flat and tf_trace (tf_occluded for shadows); results must
 * agree exactly (the run fails otherwise).  Single threaded, so the figures are per core.
 *
 * Then the packet tracer (trace_packet.h) against single rays on the same rays, for every ISA
 * the CPU runs (portable forced too): single and packet runs alternate, ROUNDS times (the best
 * of each kept), hits compared bit for bit; Mrays/s per core and packet/single per ISA, with
 * the CPU's model.  With --render SCENE, a whole tf_render_rect of the scene (grid terrains;
 * its own size, or -s WxH) with packets on and off, alternating, best of ROUNDS each.
 *
 * Usage: bench_trace [-s WxH] [-r ROUNDS] [k ...]
 *        bench_trace --render SCENE [-s WxH] [-r ROUNDS]
 *        bench_trace --smoke    (16x9 rays over k = 5: for tests/e2e/bench_smoke.sh) */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "render/trace.h"
#include "render/trace_packet.h"
#include "render/render.h"
#include "render/render_internal.h"
#include "scene.h"

static int rounds = 3; /* -r: A/B rounds of the packet comparisons */

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

/* The CPU's model name, from /proc/cpuinfo. */
static const char *cpu_model(void)
{
    static char model[128] = "unknown CPU";
    FILE *f = fopen("/proc/cpuinfo", "r");
    char line[256];
    while (f && fgets(line, sizeof line, f)) {
        char *colon = strchr(line, ':');
        if (!strncmp(line, "model name", 10) && colon) {
            snprintf(model, sizeof model, "%s", colon + 2);
            model[strcspn(model, "\n")] = 0;
            break;
        }
    }
    if (f)
        fclose(f);
    return model;
}

/* One timed pass over the rays: single rays (tf_trace / tf_occluded) or packets. */
static double pass(const tf_heightfield *hf, const ray_set *rs, const double *tmin,
                   const double *tmax, int packets, int shadow, unsigned char *found, tf_hit *hits)
{
    double t0 = now_s();
    if (packets && shadow)
        tf_occluded_packets(hf, rs->count, rs->o, rs->d, tmin, tmax, found);
    else if (packets)
        tf_trace_packets(hf, rs->count, rs->o, rs->d, tmin, tmax, found, hits);
    else
        for (int i = 0; i < rs->count; i++)
            found[i] = (unsigned char)(shadow ? tf_occluded(hf, rs->o[i], rs->d[i], tmin[i], tmax[i])
                                              : tf_trace(hf, rs->o[i], rs->d[i], tmin[i], tmax[i],
                                                         &hits[i]));
    return now_s() - t0;
}

/* Single against packets on the same rays, alternating, best of `rounds`; 1 on a mismatch. */
static int packet_ab(const tf_heightfield *hf, const ray_set *rs, double tmin0, int shadow,
                     const char *what)
{
    int n = rs->count, bad = 0;
    double *tmin = malloc(sizeof(double) * (n + 1)), *tmax = malloc(sizeof(double) * (n + 1));
    unsigned char *f1 = calloc(n + 1, 1), *f2 = calloc(n + 1, 1);
    tf_hit *h1 = calloc(n + 1, sizeof(tf_hit)), *h2 = calloc(n + 1, sizeof(tf_hit));
    for (int i = 0; i < n; i++)
        tmin[i] = tmin0, tmax[i] = INFINITY;
    double best_single = INFINITY, best_packet = INFINITY;
    for (int r = 0; r < rounds; r++) {
        best_single = fmin(best_single, pass(hf, rs, tmin, tmax, 0, shadow, f1, h1));
        best_packet = fmin(best_packet, pass(hf, rs, tmin, tmax, 1, shadow, f2, h2));
        for (int i = 0; i < n; i++)
            bad |= f1[i] != f2[i] || (!shadow && f1[i] && memcmp(&h1[i], &h2[i], sizeof(tf_hit)));
    }
    printf("  %-7s  %-8s %2d lanes   single %7.3f Mrays/s   packet %7.3f Mrays/s   packet/single %.2fx%s\n",
           what, tf_trace_packet_isa(), tf_trace_packet_lanes(), n / best_single * 1e-6,
           n / best_packet * 1e-6, best_single / best_packet, bad ? "   MISMATCH" : "");
    free(tmin), free(tmax), free(f1), free(f2), free(h1), free(h2);
    return bad;
}

/* packet_ab for primary and shadow rays on every ISA the CPU runs. */
static int packets_every_isa(const tf_heightfield *hf, const ray_set *prim, const ray_set *shad,
                             double eps)
{
    static const char *const isas[] = {"avx512", "avx2", "portable"};
    int bad = 0;
    printf("  packets on %s, best of %d alternating rounds, per core:\n", cpu_model(), rounds);
    for (int k = 0; k < 3; k++) {
        if (tf_trace_packet_force_isa(isas[k]) != 0)
            continue;
        bad |= packet_ab(hf, prim, 0, 0, "primary");
        if (shad->count)
            bad |= packet_ab(hf, shad, eps, 1, "shadow");
    }
    tf_trace_packet_force_isa(NULL);
    return bad;
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
    int packets_bad = packets_every_isa(hf, &prim, &shad, eps);
    printf("  primary  flat %10.0f rays/s   hierarchy %10.0f rays/s   hierarchy/flat %.2fx\n",
           prim.count / t_flat, prim.count / t_hier, t_flat / t_hier);
    if (shad.count)
        printf("  shadow   flat %10.0f rays/s   hierarchy %10.0f rays/s   hierarchy/flat %.2fx\n",
               shad.count / s_flat, shad.count / s_hier, s_flat / s_hier);
    int bad = mismatches || occl_flat != occl_hier || packets_bad;
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

/* One whole tf_render_rect of the image, packets on or off; its time. */
static double render_once(const tf_renderer *r, int w, int h, int packets, tf_pixel *out)
{
    tf_render_coherence_force(0); /* coherent samples are traced one at a time, not in packets */
    tf_trace_packets_force(packets);
    double t0 = now_s();
    tf_render_rect(r, (tf_rect){0, 0, w, h}, out, NULL);
    double t = now_s() - t0;
    tf_trace_packets_force(-1);
    tf_render_coherence_force(-1);
    return t;
}

/* --render: the scene's whole image, packets on and off alternating, best of `rounds`. */
static int bench_render(const char *path, int w, int h)
{
    char err[512];
    tf_scene *s = tf_scene_load(path, err, sizeof err);
    tf_heightfield *hf = s ? tf_heightfield_build(s, 1, err, sizeof err) : NULL;
    if (!hf) {
        fprintf(stderr, "bench_trace: %s\n", err);
        return 1;
    }
    if (w > 0)
        tf_scene_set_size(s, w, h);
    tf_renderer *r = tf_renderer_new(s, hf, err, sizeof err);
    if (!r) {
        fprintf(stderr, "bench_trace: %s\n", err);
        return 1;
    }
    size_t n = (size_t)s->width * (size_t)s->height;
    tf_pixel *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
    double off = INFINITY, on = INFINITY;
    int same = 1;
    for (int k = 0; k < rounds; k++) {
        off = fmin(off, render_once(r, s->width, s->height, 0, a));
        on = fmin(on, render_once(r, s->width, s->height, 1, b));
        same &= memcmp(a, b, n * sizeof *a) == 0;
    }
    printf("render %s %dx%d on %s, %s packets (%d lanes), best of %d, one core:\n", path,
           s->width, s->height, cpu_model(), tf_trace_packet_isa(), tf_trace_packet_lanes(), rounds);
    printf("  tf_render_rect  packets off %.2f s   on %.2f s   off/on %.2fx   pixels %s\n", off, on,
           off / on, same ? "identical" : "DIFFER");
    free(a), free(b);
    tf_renderer_free(r);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return !same;
}

int main(int argc, char **argv)
{
    int w = 320, h = 200, ks[16], nk = 0, sized = 0;
    const char *scene = NULL;
    for (int a = 1; a < argc; a++) {
        if (strcmp(argv[a], "--smoke") == 0) {
            w = 16;
            h = 9;
            ks[nk++] = 5;
            rounds = 1;
        } else if (strcmp(argv[a], "--render") == 0 && a + 1 < argc) {
            scene = argv[++a];
        } else if (strcmp(argv[a], "-r") == 0 && a + 1 < argc) {
            rounds = atoi(argv[++a]);
            if (rounds < 1 || rounds > 100) {
                fprintf(stderr, "bench_trace: bad round count '%s'\n", argv[a]);
                return 2;
            }
        } else if (strcmp(argv[a], "-s") == 0 && a + 1 < argc) {
            if (sscanf(argv[++a], "%dx%d", &w, &h) != 2 || w < 1 || h < 1 || w > 8192 || h > 8192) {
                fprintf(stderr, "bench_trace: bad size '%s' (want WxH)\n", argv[a]);
                return 2;
            }
            sized = 1;
        } else {
            char *end;
            long k = strtol(argv[a], &end, 10);
            if (*end || k < 1 || k > 14 || nk == 16) {
                fprintf(stderr, "usage: bench_trace [-s WxH] [-r ROUNDS] [k ...] | --render SCENE [-s WxH] [-r ROUNDS] | --smoke   (1 <= k <= 14)\n");
                return 2;
            }
            ks[nk++] = (int)k;
        }
    }
    if (scene)
        return bench_render(scene, sized ? w : 0, sized ? h : 0);
    if (nk == 0) {
        ks[nk++] = 10;
        ks[nk++] = 12;
    }
    int bad = 0;
    for (int i = 0; i < nk; i++)
        bad |= bench_k(ks[i], w, h);
    return bad;
}
