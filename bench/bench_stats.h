/* bench_stats.h: the timing arithmetic every benchmark shares: the process's CPU time and the
 * median of a run's rounds.  Header only, since every bench/NAME.c is its own program (Makefile:
 * BENCHES), as bench_cpu.h. */
#ifndef TF_BENCH_STATS_H
#define TF_BENCH_STATS_H

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* CPU seconds this process has used, all its threads together. */
static inline double tf_bench_process_cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static inline int tf_bench_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The median of v[0..n-1], v left as it is; NaN when n < 1 or out of memory. */
static inline double tf_bench_median(const double *v, int n)
{
    double *s = n > 0 ? malloc((size_t)n * sizeof *s) : NULL;
    if (!s)
        return NAN;
    memcpy(s, v, (size_t)n * sizeof *s);
    qsort(s, (size_t)n, sizeof *s, tf_bench_cmp_double);
    double m = n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
    free(s);
    return m;
}

#endif
