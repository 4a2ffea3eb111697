/* bench_terrain.c: terrain synthesis speed against docs/contract.md section 6's target of <= 5 ns per
 * octave per sample per core for fBm-type terrain.
 *
 * For each of the seven generators it builds the heights (tf_terrain_heights) once on one
 * thread and once on all online CPUs, and prints ns per sample per octave (point generators)
 * or ns per sample (grid generators), per core, with the ratio to the 5 ns target measured in
 * the same run.  Per-core figures use the process's CPU time (CLOCK_PROCESS_CPUTIME_ID), so
 * other load on a shared machine inflates them less than wall time would; the speedup column
 * is wall time.  A plain reference Perlin noise (libm floor, corner loop) is timed alongside
 * as a peer baseline.  Each generator runs in a forked child so one that fails (or is not yet
 * written) is reported and the others still run.
 *
 * Two A/B lines come first, each timed in the same run: the fBm heights on one thread with the
 * row evaluator's scalar noise blend and with its vector one (noise_row.h), and the whole
 * height field of fBm (heights plus max/min grids, what a render builds) on one thread and on
 * all, in wall time.
 *
 * usage: build/bench/bench_terrain [SIZE_EXP] [OCTAVES]     (defaults 10 and 8)
 *        build/bench/bench_terrain --smoke   (33x33 samples, 2 octaves, one build each, few
 *                                             noise calls: for tests/e2e/bench_smoke.sh) */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "bench/bench_stats.h"

#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "terrain/noise_row.h"
#include "scene.h"
#include "terrain/terrain_build.h"

#define TARGET_NS 5.0

/* Builds per measurement (best of) and noise calls per timing; --smoke lowers both. */
static int builds = 3;
static int noise_calls = 4000000;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

typedef struct timing {
    double wall, cpu; /* seconds, best of the repetitions (by wall time) */
} timing;

static tf_terrain bench_terrain(enum tf_generator g, int size_exp, double octaves)
{
    tf_terrain t;
    memset(&t, 0, sizeof t);
    t.generator = g;
    t.seed = 12345;
    t.size_exp = size_exp;
    t.extent = 10000.0;
    t.height_scale = 1000.0;
    t.feature_size = 5000.0;
    t.octaves = octaves;
    t.H = 0.8;
    t.lacunarity = 2.0;
    t.offset = g == TF_GEN_RIDGED ? 1.0 : 0.8;
    t.gain = 2.0;
    t.roughness = 0.8;
    t.envelope_n = 0;
    t.envelope_tolerance = 1.0;
    t.faults = 200;
    t.fault_step = 0.05;
    t.wind_passes = 1;
    t.rain_passes = 1;
    t.erosion_k = 0.5;
    t.sub_M = 1.0;
    t.sub_E = 2.0;
    t.sub_W = 0.3;
    return t;
}

/* What a measurement times: the heights alone, or the whole height field (heights and
 * max/min grids), and with which noise blend ("portable" forces the scalar one). */
typedef struct what {
    int field;
    const char *isa; /* NULL: the best this CPU runs */
} what;

/* One build of t's heights (and grids if w->field); 0, or -1 with the message printed. */
static int build_once(const tf_terrain *t, const what *w, int threads)
{
    char err[256];
    float *h = tf_terrain_heights(t, threads, NULL, err, sizeof err);
    if (!h) {
        fprintf(stderr, "  %s\n", err);
        return -1;
    }
    if (!w->field) {
        free(h);
        return 0;
    }
    tf_heightfield *hf = tf_heightfield_wrap(h, t->size_exp, t->extent, threads);
    tf_heightfield_free(hf);
    return hf ? 0 : -1;
}

/* Best of `reps` builds (by wall time); wall < 0 on failure (message printed). */
static timing time_build(const tf_terrain *t, const what *w, int threads, int reps)
{
    timing best = {-1.0, -1.0};
    for (int r = 0; r < reps; r++) {
        double w0 = now_s(), c0 = tf_bench_process_cpu_s();
        if (build_once(t, w, threads) != 0)
            return (timing){-1.0, -1.0};
        timing now = {now_s() - w0, tf_bench_process_cpu_s() - c0};
        if (best.wall < 0 || now.wall < best.wall)
            best = now;
    }
    return best;
}

/* Child process: time generator g on one thread and on `cpus`, write the four figures to fd. */
static void measure_child(enum tf_generator g, int size_exp, double octaves, int cpus,
                          const what *w, int fd)
{
    tf_terrain t = bench_terrain(g, size_exp, octaves);
    if (tf_noise_row_force_isa(w->isa) != 0)
        _exit(1);
    timing one = time_build(&t, w, 1, builds);
    timing all = one.wall < 0 || cpus < 1 ? one : time_build(&t, w, cpus, builds);
    char line[128];
    int len = snprintf(line, sizeof line, "%.9f %.9f %.9f %.9f\n", one.wall, one.cpu, all.wall,
                       all.cpu);
    if (write(fd, line, (size_t)len) != len)
        _exit(3);
    _exit(one.wall < 0 || all.wall < 0 ? 1 : 0);
}

/* Time g in a child (cpus 0: one thread only, *all = *one). */
static int measure(enum tf_generator g, int size_exp, double octaves, int cpus, const what *w,
                   timing *one, timing *all)
{
    int fds[2];
    if (pipe(fds) != 0)
        return -1;
    fflush(stdout);
    pid_t pid = fork();
    if (pid < 0)
        return -1;
    if (pid == 0) {
        close(fds[0]);
        measure_child(g, size_exp, octaves, cpus, w, fds[1]);
    }
    close(fds[1]);
    char buf[128] = {0};
    ssize_t got = read(fds[0], buf, sizeof buf - 1);
    close(fds[0]);
    int status = 0;
    waitpid(pid, &status, 0);
    if (got <= 0 || sscanf(buf, "%lf %lf %lf %lf", &one->wall, &one->cpu, &all->wall,
                           &all->cpu) != 4 || one->wall < 0 || all->wall < 0)
        return -1;
    return 0;
}

/* Peer baseline: textbook Perlin noise with libm floor and a loop over corners. */
static double plain_noise2(const tf_noise *nz, double x, double y)
{
    static const double g[8][2] = {{1, 0}, {0.7071, 0.7071}, {0, 1}, {-0.7071, 0.7071},
                                   {-1, 0}, {-0.7071, -0.7071}, {0, -1}, {0.7071, -0.7071}};
    double x0 = floor(x), y0 = floor(y), fx = x - x0, fy = y - y0;
    double wx = fx * fx * fx * (fx * (fx * 6 - 15) + 10);
    double wy = fy * fy * fy * (fy * (fy * 6 - 15) + 10);
    double sum = 0.0;
    for (int c = 0; c < 4; c++) {
        int cx = c & 1, cy = c >> 1;
        int h = nz->perm[nz->perm[((int)x0 + cx) & 255] + (((int)y0 + cy) & 255)] & 7;
        sum += (cx ? wx : 1 - wx) * (cy ? wy : 1 - wy) *
               (g[h][0] * (fx - cx) + g[h][1] * (fy - cy));
    }
    return sum;
}

static double time_noise(int plain, int count)
{
    tf_noise nz;
    tf_noise_init(&nz, 7);
    volatile double sink = 0.0;
    double best = 1e9;
    for (int r = 0; r < 3; r++) {
        double acc = 0.0, t0 = now_s();
        for (int i = 0; i < count; i++) {
            double x = 0.37 + i * 0.013, y = 5.1 + (i & 1023) * 0.021;
            acc += plain ? plain_noise2(&nz, x, y) : tf_noise2(&nz, x, y);
        }
        double dt = now_s() - t0;
        sink += acc;
        if (dt < best)
            best = dt;
    }
    (void)sink;
    return best * 1e9 / count;
}

/* The two A/B lines (see the top of the file); 0, or -1 if a build failed. */
static int print_ab(int size_exp, double octaves, int cpus, double samples)
{
    timing scalar, vec, one, all, unused;
    const char *isa = tf_noise_row_isa();
    if (measure(TF_GEN_FBM, size_exp, octaves, 0, &(what){0, "portable"}, &scalar, &unused) ||
        measure(TF_GEN_FBM, size_exp, octaves, 0, &(what){0, NULL}, &vec, &unused) ||
        measure(TF_GEN_FBM, size_exp, octaves, cpus, &(what){1, NULL}, &one, &all)) {
        printf("A/B builds failed (see above)\n");
        return -1;
    }
    double per = samples * ceil(octaves) * 1e-9;
    printf("fbm heights on 1 thread, noise blend: portable %.2f ns, %s %.2f ns per octave per "
           "sample (CPU; %.2fx)\n", scalar.cpu / per, isa, vec.cpu / per, scalar.cpu / vec.cpu);
    printf("fbm height field (heights + max/min grids), wall: 1 thread %.3f s, %d threads "
           "%.3f s (%.2fx)\n\n", one.wall, cpus, all.wall, one.wall / all.wall);
    return 0;
}

int main(int argc, char **argv)
{
    int smoke = argc == 2 && !strcmp(argv[1], "--smoke");
    int size_exp = smoke ? 5 : argc > 1 ? atoi(argv[1]) : 10;
    double octaves = smoke ? 2.0 : argc > 2 ? atof(argv[2]) : 8.0;
    if (smoke) {
        builds = 1;
        noise_calls = 20000;
    }
    if (size_exp < 1 || size_exp > TF_TERRAIN_MAX_SIZE_EXP || !(octaves >= 1 && octaves <= 32)) {
        fprintf(stderr, "usage: bench_terrain [SIZE_EXP 1..13] [OCTAVES 1..32] | --smoke\n");
        return 2;
    }
    int cpus = (int)sysconf(_SC_NPROCESSORS_ONLN);
    if (cpus < 1)
        cpus = 1;
    long n = (1L << size_exp) + 1;
    double samples = (double)n * (double)n;

    printf("terrain synthesis: %ldx%ld samples, %.1f octaves, %d CPUs; target %.1f ns per "
           "octave per sample per core\n", n, n, octaves, cpus, TARGET_NS);
    double tf_ns = time_noise(0, noise_calls), plain_ns = time_noise(1, noise_calls);
    printf("single 2D noise call: terrafarm %.2f ns, plain Perlin %.2f ns (%.2fx faster)\n\n",
           tf_ns, plain_ns, plain_ns / tf_ns);
    int failures = print_ab(size_exp, octaves, cpus, samples) != 0;
    printf("%-10s %12s %8s %14s %8s %9s\n", "generator", "1 core", "ratio", "all cores/core",
           "ratio", "speedup");

    static const enum tf_generator gens[] = {TF_GEN_FBM, TF_GEN_HETERO, TF_GEN_HYBRID,
                                             TF_GEN_RIDGED, TF_GEN_MIDPOINT, TF_GEN_FAULT,
                                             TF_GEN_SUBDIVIDE};
    static const char *names[] = {"fbm", "hetero", "hybrid", "ridged", "midpoint", "fault",
                                  "subdivide"};
    for (size_t i = 0; i < sizeof gens / sizeof gens[0]; i++) {
        timing one, all;
        int point = gens[i] <= TF_GEN_RIDGED;
        if (measure(gens[i], size_exp, octaves, cpus, &(what){0, NULL}, &one, &all) != 0) {
            printf("%-10s %s\n", names[i], "failed (see above)");
            failures++;
            continue;
        }
        /* CPU ns per sample (per octave for point generators); ratio to the target. */
        double per = samples * (point ? ceil(octaves) : 1.0) * 1e-9;
        double ns1 = one.cpu / per, nsn = all.cpu / per;
        if (point)
            printf("%-10s %9.2f ns %7.2fx %11.2f ns %7.2fx %8.2fx\n", names[i], ns1,
                   ns1 / TARGET_NS, nsn, nsn / TARGET_NS, one.wall / all.wall);
        else /* the 5 ns target is per octave of fBm-type terrain: no ratio for grids */
            printf("%-10s %9.2f ns %8s %11.2f ns %8s %8.2fx   per sample (whole generator)\n",
                   names[i], ns1, "-", nsn, "-", one.wall / all.wall);
    }
    double load[3] = {0};
    if (getloadavg(load, 3) < 1)
        load[0] = -1;
    printf("\nns = CPU ns per sample per octave per core; ratio = ns / %.1f ns target (<= 1.00 "
           "meets it);\nspeedup = wall time on 1 core / wall time on %d cores.  Load average "
           "during the run: %.2f\n", TARGET_NS, cpus, load[0]);
    return failures ? 1 : 0;
}
