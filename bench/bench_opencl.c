/* bench_opencl.c: the C backend against the OpenCL backend on the same cores, in one run
 * (docs/contract.md section 6: "OpenCL on PoCL >= 1.3x the C backend's throughput on the same cores").
 *
 *   C        T threads (T = online CPUs) take stamp tasks off a shared counter and call
 *            tf_render_rect: the throughput of T forked C workers without the farm around them.
 *   OpenCL   one backend (PoCL spreads each kernel over the same T cores) renders the same
 *            stamps one after another, as one OpenCL worker would; then the whole image as a
 *            single task (the launch overhead per task is the difference).
 * The C and OpenCL stamp renders alternate REPEATS times; the ratios printed are the medians
 * of the per-round ratios (each round's C and OpenCL run back to back, so a slow spell of a
 * shared machine hits both), with the spread.
 * Also: the kernel build time cold (a fresh, empty POCL_CACHE_DIR, and terrafarm's own binary
 * cache, TF_OPENCL_CACHE, empty in it) and cached (the same directories again: a binary-cache
 * hit), a fresh worker process's start (the program run again with --start, as a forked
 * worker starts: loading PoCL and LLVM, the backend from the binary cache, the first task;
 * the median of START_RUNS processes), device time per kernel (corners vs adaptive pixels),
 * rays per second, and the image match (PSNR, equal sample counts, bit-identical pixels).
 *
 *   build/bench/bench_opencl SCENE [WxH] [STAMP] [REPEATS]   (defaults: the scene's size, 64, 5)
 *   build/bench/bench_opencl --smoke SCENE   (16x9, stamps of 8, one round, and no cold build:
 *   the kernels come from PoCL's usual cache, so only a machine's first run compiles them) */
#include <ftw.h>
#include <math.h>
#include <pthread.h>
#include <spawn.h>
#include <sys/wait.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include "worker/backend.h"
#include "worker/backend_opencl.h"
#include "terrain/heightfield.h"
#include "render/render.h"
#include "scene.h"

#define MAX_THREADS 64
#define MAX_REPEATS 99
#define START_RUNS 5
#define START_PHASES 3 /* PoCL loaded, backend ready, first task */

extern char **environ;

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU seconds of the whole process (all threads, PoCL's included): robust on a shared machine. */
static double cpu_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

typedef struct job {
    const tf_renderer *r;
    int width, height, stamp, across, total;
    tf_pixel *img;
    atomic_int next;
    tf_render_counts counts[MAX_THREADS];
} job;

typedef struct targ { job *j; int id; } targ;

static tf_rect stamp_rect(const job *j, int k)
{
    int sx = k % j->across, sy = k / j->across;
    tf_rect r = {sx * j->stamp, sy * j->stamp, j->stamp, j->stamp};
    if (r.x + r.w > j->width)
        r.w = j->width - r.x;
    if (r.y + r.h > j->height)
        r.h = j->height - r.y;
    return r;
}

static void paste(tf_pixel *img, int width, tf_rect r, const tf_pixel *src)
{
    for (int y = 0; y < r.h; y++)
        memcpy(&img[(size_t)(r.y + y) * width + r.x], &src[(size_t)y * r.w],
               sizeof *src * (size_t)r.w);
}

static void *c_worker(void *arg)
{
    targ *a = arg;
    job *j = a->j;
    tf_pixel *buf = malloc(sizeof *buf * (size_t)j->stamp * (size_t)j->stamp);
    for (int k; (k = atomic_fetch_add(&j->next, 1)) < j->total;) {
        tf_rect r = stamp_rect(j, k);
        tf_render_rect(j->r, r, buf, &j->counts[a->id]);
        paste(j->img, j->width, r, buf);
    }
    free(buf);
    return NULL;
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Median of v[0..n-1] (sorts v). */
static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, by_value);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

static double clamp01(double v) { return v < 0 ? 0 : v > 1 ? 1 : v; }

static void compare(const tf_pixel *a, const tf_pixel *b, size_t n)
{
    double se = 0;
    size_t spp_same = 0, identical = 0;
    for (size_t i = 0; i < n; i++) {
        double d[3] = {clamp01(a[i].r) - clamp01(b[i].r), clamp01(a[i].g) - clamp01(b[i].g),
                       clamp01(a[i].b) - clamp01(b[i].b)};
        se += d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        spp_same += a[i].spp == b[i].spp;
        identical += !memcmp(&a[i], &b[i], sizeof a[i]);
    }
    double mse = se / (3.0 * (double)n);
    printf("match      PSNR %s%.1f dB, spp equal %.3f%%, bit-identical pixels %.3f%%\n",
           mse > 0 ? "" : "inf (", mse > 0 ? 10 * log10(1 / mse) : 0.0,
           100.0 * (double)spp_same / (double)n, 100.0 * (double)identical / (double)n);
}

static int remove_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw)
{
    (void)st;
    (void)flag;
    (void)ftw;
    return remove(path);
}

/* A fresh empty directory for the cold build. */
static int fresh_cache_dir(char *dir, size_t len)
{
    snprintf(dir, len, "%s/tf-bench-pocl-XXXXXX", getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
    return mkdtemp(dir) ? 0 : -1;
}

/* --start SCENE WxH STAMP: as a fresh worker process of `render -j <online CPUs>` (its share
 * of the cores, so PoCL's basic device where that is one core: tf_backend_share_cores), time
 * loading the OpenCL platform (PoCL, LLVM), the backend (device, context, program from the
 * binary cache, the scene and terrain uploaded) and the first task of one stamp; print the
 * wall and CPU seconds of each, the binary cache's answer and the device. */
static int start_child(const char *path, const char *size, int stamp)
{
    char err[1024] = "";
    tf_backend_share_cores("opencl", tf_thread_count(0));
    int w, h, rc = 1;
    tf_scene *s = tf_scene_load(path, err, sizeof err);
    if (s && sscanf(size, "%dx%d", &w, &h) == 2)
        tf_scene_set_size(s, w, h);
    tf_heightfield *hf = s ? tf_heightfield_build(s, 0, err, sizeof err) : NULL;
    tf_pixel *buf = malloc(sizeof *buf * (size_t)stamp * (size_t)stamp);
    tf_cl_backend *cl = NULL;
    double t[START_PHASES + 1], c[START_PHASES + 1];
    if (!hf || !buf)
        goto out;
    cl_platform_id plat;
    cl_uint nplat = 0;
    t[0] = now(), c[0] = cpu_now();
    clGetPlatformIDs(1, &plat, &nplat);
    t[1] = now(), c[1] = cpu_now();
    cl = tf_cl_backend_new(s, hf, err, sizeof err);
    t[2] = now(), c[2] = cpu_now();
    tf_rect r = {0, 0, stamp < s->width ? stamp : s->width, stamp < s->height ? stamp : s->height};
    if (!cl || tf_cl_backend_render(cl, r, buf, NULL, err, sizeof err))
        goto out;
    t[3] = now(), c[3] = cpu_now();
    for (int i = 0; i < START_PHASES; i++)
        printf("%.6f %.6f ", t[i + 1] - t[i], c[i + 1] - c[i]);
    printf("%s %s\n", tf_cl_backend_cache(cl), tf_cl_backend_device(cl));
    rc = 0;
out:
    if (rc)
        fprintf(stderr, "%s\n", err[0] ? err : "out of memory");
    tf_cl_backend_free(cl);
    free(buf);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return rc;
}

/* One fresh process through start_child: its phases' wall and CPU seconds, and its device
 * (device_len bytes).  0 or -1. */
static int start_run(const char *scene, int width, int height, int stamp, double *wall,
                     double *cpu, char *device, size_t device_len)
{
    char size[32], st[16], line[512] = "";
    snprintf(size, sizeof size, "%dx%d", width, height);
    snprintf(st, sizeof st, "%d", stamp);
    char *args[] = {"bench_opencl", "--start", (char *)scene, size, st, NULL};
    int fds[2];
    posix_spawn_file_actions_t fa;
    pid_t pid;
    if (pipe(fds) != 0)
        return -1;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, fds[1], 1);
    posix_spawn_file_actions_addclose(&fa, fds[0]);
    int rc = posix_spawn(&pid, "/proc/self/exe", &fa, NULL, args, environ);
    posix_spawn_file_actions_destroy(&fa);
    close(fds[1]);
    FILE *f = fdopen(fds[0], "r");
    if (!f)
        close(fds[0]);
    else if (!fgets(line, sizeof line, f))
        line[0] = 0;
    if (f)
        fclose(f);
    int status = 0;
    if (rc == 0)
        waitpid(pid, &status, 0);
    int at = 0;
    if (rc != 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0 ||
        sscanf(line, "%lf %lf %lf %lf %lf %lf %*s %n", &wall[0], &cpu[0], &wall[1], &cpu[1],
               &wall[2], &cpu[2], &at) != 6 || at == 0)
        return -1;
    snprintf(device, device_len, "%.*s", (int)strcspn(line + at, "\n"), line + at);
    return 0;
}

/* The median start of `runs` fresh worker processes, one line.  0, or -1 when one failed. */
static int report_start(const char *scene, int width, int height, int stamp, int runs)
{
    double wall[START_PHASES][START_RUNS], cpu[START_PHASES][START_RUNS], w[START_PHASES],
        c[START_PHASES];
    char device[256] = "";
    for (int k = 0; k < runs; k++) {
        if (start_run(scene, width, height, stamp, w, c, device, sizeof device)) {
            fprintf(stderr, "a fresh process (bench_opencl --start) could not start the "
                            "backend\n");
            return -1;
        }
        for (int i = 0; i < START_PHASES; i++)
            wall[i][k] = w[i], cpu[i][k] = c[i];
    }
    printf("start      a fresh worker process of render -j %d, wall (CPU): PoCL and LLVM loaded "
           "%.4f s (%.4f), backend ready %.4f s (%.4f), first task %.4f s (%.4f); median of %d; "
           "device %s\n",
           tf_thread_count(0), median(wall[0], runs), median(cpu[0], runs),
           median(wall[1], runs), median(cpu[1], runs), median(wall[2], runs),
           median(cpu[2], runs), runs, device);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc == 5 && !strcmp(argv[1], "--start"))
        return start_child(argv[2], argv[3], atoi(argv[4]) > 0 ? atoi(argv[4]) : 64);
    int smoke = argc == 3 && !strcmp(argv[1], "--smoke");
    char *smoke_argv[] = {argv[0], argv[argc - 1], "16x9", "8", "1", NULL};
    if (smoke) {
        argv = smoke_argv;
        argc = 5;
    }
    if (argc < 2) {
        fprintf(stderr, "usage: %s SCENE [WxH] [STAMP] [REPEATS] | --smoke SCENE\n", argv[0]);
        return 2;
    }
    char err[1024];
    tf_scene *s = tf_scene_load(argv[1], err, sizeof err);
    if (!s) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    int w, h;
    if (argc > 2 && sscanf(argv[2], "%dx%d", &w, &h) == 2)
        tf_scene_set_size(s, w, h);
    int stamp = argc > 3 ? atoi(argv[3]) : 64;
    if (stamp < 1)
        stamp = 64;
    int repeats = argc > 4 ? atoi(argv[4]) : 5;
    if (repeats < 1 || repeats > MAX_REPEATS) {
        fprintf(stderr, "REPEATS: 1 to %d\n", MAX_REPEATS);
        return 2;
    }
    int threads = tf_thread_count(0);
    if (threads > MAX_THREADS)
        threads = MAX_THREADS;
    tf_heightfield *hf = tf_heightfield_build(s, 0, err, sizeof err);
    tf_renderer *r = hf ? tf_renderer_new(s, hf, err, sizeof err) : NULL;
    if (!r) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    size_t n = (size_t)s->width * (size_t)s->height;
    tf_pixel *c_img = calloc(n, sizeof *c_img), *cl_img = calloc(n, sizeof *cl_img);
    tf_pixel *whole = calloc(n, sizeof *whole);
    tf_pixel *buf = malloc(sizeof *buf * (size_t)stamp * (size_t)stamp);
    if (!c_img || !cl_img || !whole || !buf) {
        fprintf(stderr, "out of memory\n");
        return 1;
    }
    printf("scene      %s %dx%d, stamps %dx%d, %d cores\n", argv[1], s->width, s->height, stamp,
           stamp, threads);

    /* kernel build: cold in a fresh cache directory, then cached in the same one */
    char dir[4096];
    const char *user_cache = getenv("POCL_CACHE_DIR");
    char *saved = user_cache ? strdup(user_cache) : NULL;
    const char *user_tf_cache = getenv("TF_OPENCL_CACHE");
    char *saved_tf = user_tf_cache ? strdup(user_tf_cache) : NULL;
    dir[0] = '\0';
    char tf_cache[4096 + 16];
    if (!smoke && fresh_cache_dir(dir, sizeof dir) == 0) {
        setenv("POCL_CACHE_DIR", dir, 1);
        snprintf(tf_cache, sizeof tf_cache, "%s/tf-opencl", dir); /* removed with it */
        setenv("TF_OPENCL_CACHE", tf_cache, 1);
    }
    double t0 = now();
    tf_cl_backend *cold = tf_cl_backend_new(s, hf, err, sizeof err);
    double cold_total = now() - t0;
    if (!cold) {
        fprintf(stderr, "OpenCL backend: %s\n", err);
        return 1;
    }
    double cold_build = tf_cl_backend_build_seconds(cold);
    tf_cl_backend_free(cold);
    t0 = now();
    tf_cl_backend *cl = tf_cl_backend_new(s, hf, err, sizeof err);
    double warm_total = now() - t0;
    if (!cl) {
        fprintf(stderr, "OpenCL backend: %s\n", err);
        return 1;
    }
    printf("device     %s\n", tf_cl_backend_device(cl));
    printf("build      %s %.2f s (backend ready in %.2f s), cached %.3f s (ready in %.3f s; "
           "binary cache %s)\n",
           smoke ? "first (PoCL's cache, --smoke)" : "cold", cold_build, cold_total,
           tf_cl_backend_build_seconds(cl), warm_total, tf_cl_backend_cache(cl));

    /* the first launches compile PoCL's work-group functions (cached on disk too): timed apart */
    t0 = now();
    if (tf_cl_backend_render(cl, (tf_rect){0, 0, stamp < s->width ? stamp : s->width,
                                           stamp < s->height ? stamp : s->height},
                             buf, NULL, err, sizeof err)) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    printf("first task %.3f s (includes PoCL's work-group function compile on a cold cache)\n",
           now() - t0);
    if (report_start(argv[1], s->width, s->height, stamp, smoke ? 1 : START_RUNS))
        return 1;

    /* rounds: C (threads over stamps), then OpenCL (the same stamps one by one) */
    job j = {.r = r, .width = s->width, .height = s->height, .stamp = stamp, .img = c_img};
    j.across = (s->width + stamp - 1) / stamp;
    j.total = j.across * ((s->height + stamp - 1) / stamp);
    double c_wall[MAX_REPEATS], c_cpus[MAX_REPEATS], cl_wall[MAX_REPEATS], cl_cpus[MAX_REPEATS];
    double wall_ratio[MAX_REPEATS], cpu_ratio[MAX_REPEATS];
    double corner_s = 0, pixel_s = 0;
    tf_render_counts cc = {0}, clc = {0};
    for (int round = 0; round < repeats; round++) {
        memset(j.counts, 0, sizeof j.counts);
        atomic_init(&j.next, 0);
        pthread_t tid[MAX_THREADS];
        targ args[MAX_THREADS];
        double cpu0 = cpu_now();
        t0 = now();
        for (int i = 0; i < threads; i++) {
            args[i] = (targ){&j, i};
            pthread_create(&tid[i], NULL, c_worker, &args[i]);
        }
        for (int i = 0; i < threads; i++)
            pthread_join(tid[i], NULL);
        c_wall[round] = now() - t0;
        c_cpus[round] = cpu_now() - cpu0;
        cc = (tf_render_counts){0};
        for (int i = 0; i < threads; i++) {
            cc.primary_rays += j.counts[i].primary_rays;
            cc.shadow_rays += j.counts[i].shadow_rays;
        }

        double corner0, pixel0, corner1, pixel1;
        tf_cl_backend_kernel_seconds(cl, &corner0, &pixel0);
        clc = (tf_render_counts){0};
        cpu0 = cpu_now();
        t0 = now();
        for (int k = 0; k < j.total; k++) {
            tf_rect rr = stamp_rect(&j, k);
            if (tf_cl_backend_render(cl, rr, buf, &clc, err, sizeof err)) {
                fprintf(stderr, "%s\n", err);
                return 1;
            }
            paste(cl_img, s->width, rr, buf);
        }
        cl_wall[round] = now() - t0;
        cl_cpus[round] = cpu_now() - cpu0;
        tf_cl_backend_kernel_seconds(cl, &corner1, &pixel1);
        corner_s += (corner1 - corner0) / repeats;
        pixel_s += (pixel1 - pixel0) / repeats;
        wall_ratio[round] = c_wall[round] / cl_wall[round];
        cpu_ratio[round] = c_cpus[round] / cl_cpus[round];
    }
    /* the first pass apart (PoCL specialises its work-group function for a large grid on first
     * sight), then REPEATS passes: whole_s[1] is their median */
    double whole_s[1 + MAX_REPEATS];
    for (int pass = 0; pass <= repeats; pass++) {
        t0 = now();
        if (tf_cl_backend_render(cl, (tf_rect){0, 0, s->width, s->height}, whole, NULL, err,
                                 sizeof err)) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        whole_s[pass] = now() - t0;
    }
    double c_rays = (double)(cc.primary_rays + cc.shadow_rays);
    double cl_rays = (double)(clc.primary_rays + clc.shadow_rays);
    double c_s = median(c_wall, repeats), cl_s = median(cl_wall, repeats);
    whole_s[1] = median(whole_s + 1, repeats);
    double c_cpu = median(c_cpus, repeats), cl_cpu = median(cl_cpus, repeats);
    printf("rounds     %d (medians below)\n", repeats);
    printf("C          %.3f s  %.2f Mrays/s  (%d threads)\n", c_s, c_rays / c_s * 1e-6, threads);
    printf("OpenCL     %.3f s  %.2f Mrays/s  (stamps; device time: corners %.3f s, pixels "
           "%.3f s, host+launch %.3f s)\n",
           cl_s, cl_rays / cl_s * 1e-6, corner_s, pixel_s, cl_s - corner_s - pixel_s);
    printf("OpenCL     %.3f s  (whole image as one task; %.3f s the first time)\n", whole_s[1],
           whole_s[0]);
    double cpu_r = median(cpu_ratio, repeats), wall_r = median(wall_ratio, repeats);
    printf("CPU time   C %.3f s, OpenCL %.3f s: OpenCL/C throughput per CPU second %.2fx "
           "(rounds %.2f-%.2f)\n",
           c_cpu, cl_cpu, cpu_r, cpu_ratio[0], cpu_ratio[repeats - 1]);
    printf("ratio      OpenCL/C throughput %.2fx with stamps (rounds %.2f-%.2f), %.2fx whole "
           "image (target >= 1.3x)\n",
           wall_r, wall_ratio[0], wall_ratio[repeats - 1], c_s / whole_s[1]);
    compare(c_img, cl_img, n);
    tf_cl_backend_free(cl);
    tf_renderer_free(r);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    free(c_img);
    free(cl_img);
    free(whole);
    free(buf);
    /* the private caches go; the user's POCL_CACHE_DIR and TF_OPENCL_CACHE come back (for
     * anything after us) */
    if (strstr(dir, "tf-bench-pocl-"))
        nftw(dir, remove_entry, 16, FTW_DEPTH | FTW_PHYS);
    if (saved)
        setenv("POCL_CACHE_DIR", saved, 1);
    else
        unsetenv("POCL_CACHE_DIR");
    free(saved);
    if (saved_tf)
        setenv("TF_OPENCL_CACHE", saved_tf, 1);
    else
        unsetenv("TF_OPENCL_CACHE");
    free(saved_tf);
    return 0;
}
