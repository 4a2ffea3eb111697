/* bench_erosion.c: fluvial erosion speed (terrain/erosion.h) against issue 20's target of
 * 0.5 G vertex-steps per second per core on a 4097^2 grid, and Musgrave's own case (200^2
 * vertices, 2000 steps, K_c 5, K_d 0.1, K_s 0.3: 4 hours on an SGI Iris 4D/70 in 1993).
 *
 * Each configuration runs from the same fresh state; A/B pairs alternate (the best ISA, AVX2
 * when the best is AVX-512, then portable, then again) so drift on a shared machine hits
 * all.  Per-core rates divide by the process's CPU time, wall rates by wall time.  Prints the
 * CPU model and the vector ISA.
 *
 * usage: build/bench/bench_erosion [SIZE_EXP] [STEPS]   (defaults 12 and 64: 4097^2 x 64)
 *        build/bench/bench_erosion --smoke               (65^2 x 16, for bench_smoke.sh) */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench/bench_cpu.h"
#include "terrain/erosion.h"
#include "terrain/erosion_run.h"
#include "terrain/erosion_state.h"
#include "terrain/terrain_build.h"

static double clock_s(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static tf_erosion_keys musgrave_keys(int steps)
{
    tf_erosion_keys k = {0};
    k.fluvial_steps = steps;
    k.capacity = 5.0;
    k.deposition = 0.1;
    k.softness = 0.3;
    k.silt_softness = 3.0;
    k.talus_softness = 2.0;
    k.rain = 0.2;
    k.rain_interval = 80;
    k.rain_altitude = 1.0;
    return k;
}

static float *heights(int n_exp)
{
    tf_terrain t = {0};
    t.generator = TF_GEN_FBM;
    t.seed = 7;
    t.size_exp = n_exp;
    t.extent = 10000;
    t.height_scale = 1000;
    t.feature_size = 4000;
    t.octaves = 10;
    t.H = 0.8;
    t.lacunarity = 2.0;
    char err[256];
    float *h = tf_terrain_heights(&t, 0, NULL, err, sizeof err);
    if (!h) {
        fprintf(stderr, "bench_erosion: %s\n", err);
        exit(1);
    }
    return h;
}

typedef struct {
    double wall, cpu;
} timing;

/* steps of erosion on a fresh state of h (n x n) with `threads` threads. */
static timing run_once(const float *h, int n, int steps, int threads, const char *isa, int halo)
{
    tf_erosion_keys k = musgrave_keys(steps);
    float lo = h[0], hi = h[0];
    for (size_t i = 0; i < (size_t)n * (size_t)n; i++) {
        lo = fminf(lo, h[i]);
        hi = fmaxf(hi, h[i]);
    }
    tf_erosion_model m;
    tf_erosion_state st;
    tf_erosion_tally tally = {0};
    char err[256];
    if (tf_erosion_model_init(&m, &k, 1, n, lo, hi, err, sizeof err) ||
        tf_erosion_state_from_heights(&st, &m, &k, h)) {
        fprintf(stderr, "bench_erosion: %s\n", err);
        exit(1);
    }
    tf_erosion_force_isa(isa);
    tf_erosion_run_opts o = {0, steps, threads, halo, 0, 0};
    double w0 = clock_s(CLOCK_MONOTONIC), c0 = clock_s(CLOCK_PROCESS_CPUTIME_ID);
    if (tf_erosion_run(&st, &m, &o, &tally, err, sizeof err) != 0) {
        fprintf(stderr, "bench_erosion: %s\n", err);
        exit(1);
    }
    timing t = {clock_s(CLOCK_MONOTONIC) - w0, clock_s(CLOCK_PROCESS_CPUTIME_ID) - c0};
    tf_erosion_state_free(&st);
    tf_erosion_force_isa(NULL);
    return t;
}

static void report(const char *what, int n, int steps, timing t)
{
    double vs = (double)n * n * steps;
    printf("%-28s %5dx%-5d x %5d steps: %7.3f s wall, %6.3f Gvs/s per core, %6.3f Gvs/s wall\n",
           what, n, n, steps, t.wall, vs / t.cpu * 1e-9, vs / t.wall * 1e-9);
}

int main(int argc, char **argv)
{
    int smoke = argc > 1 && !strcmp(argv[1], "--smoke");
    int e = smoke ? 6 : argc > 1 ? atoi(argv[1]) : 12;
    int steps = smoke ? 16 : argc > 2 ? atoi(argv[2]) : 64;
    int n = (1 << e) + 1;
    char cpu[128];
    tf_bench_cpu_model(cpu, sizeof cpu);
    printf("cpu: %s; erosion kernel: %s\n", cpu, tf_erosion_isa());
    /* the AVX2 kernel too where it is not the best (AVX-512 machines) */
    int avx2 = strcmp(tf_erosion_isa(), "avx2") && tf_erosion_force_isa("avx2") == 0;
    tf_erosion_force_isa(NULL);
    float *h = heights(e);

    double best_ratio = 0;
    for (int rep = 0; rep < (smoke ? 1 : 2); rep++) {
        timing fast = run_once(h, n, steps, 1, NULL, 0);
        timing mid = avx2 ? run_once(h, n, steps, 1, "avx2", 0) : fast;
        timing port = run_once(h, n, steps, 1, "portable", 0);
        report("1 thread, best ISA", n, steps, fast);
        if (avx2)
            report("1 thread, avx2", n, steps, mid);
        report("1 thread, portable", n, steps, port);
        best_ratio = port.cpu / fast.cpu;
    }
    timing two = run_once(h, n, steps, 2, NULL, 0);
    report("2 threads, best ISA", n, steps, two);
    timing halo1 = run_once(h, n, steps, 1, NULL, 1);
    report("1 thread, halo 1 (no blocking)", n, steps, halo1);
    free(h);

    /* Musgrave's case: 200^2 in his dissertation; 201^2 is the nearest grid here. */
    float *small = heights(smoke ? 4 : 8);
    int ns = smoke ? 17 : 257, ms = smoke ? 20 : 2000;
    timing mus = run_once(small, ns, ms, 1, NULL, 0);
    report("Musgrave case (257^2)", ns, ms, mus);
    double scaled = mus.wall * (200.0 * 200.0) / ((double)ns * ns);
    printf("Musgrave 200^2 x 2000 steps: %.3f s (scaled from 257^2) against 4 h: %.0fx\n", scaled,
           4 * 3600.0 / scaled);
    free(small);
    printf("portable/best cpu ratio: %.2f\n", best_ratio);
    return 0;
}
