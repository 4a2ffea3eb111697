/* bench_cpu.h: what a benchmark prints about the machine it measured on: the CPU model (the
 * first "model name" of /proc/cpuinfo) and the widest x86 vector ISA the CPU runs.  Header
 * only, since every bench/NAME.c is its own program (Makefile: BENCHES); included by the benches
 * that print them, so they all say it the same way. */
#ifndef TF_BENCH_CPU_H
#define TF_BENCH_CPU_H

#include <stdio.h>
#include <string.h>

/* The CPU model into out ("unknown" when /proc/cpuinfo does not say). */
static inline void tf_bench_cpu_model(char *out, size_t len)
{
    snprintf(out, len, "unknown");
    FILE *f = fopen("/proc/cpuinfo", "r");
    char line[256];
    while (f && fgets(line, sizeof line, f))
        if (!strncmp(line, "model name", 10) && strchr(line, ':')) {
            snprintf(out, len, "%s", strchr(line, ':') + 2);
            out[strcspn(out, "\n")] = '\0';
            break;
        }
    if (f)
        fclose(f);
}

/* "avx512" (F), "avx2", "avx", "sse2" or "scalar": the widest vector ISA this CPU runs. */
static inline const char *tf_bench_vector_isa(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f"))
        return "avx512";
    if (__builtin_cpu_supports("avx2"))
        return "avx2";
    if (__builtin_cpu_supports("avx"))
        return "avx";
    if (__builtin_cpu_supports("sse2"))
        return "sse2";
#endif
    return "scalar";
}

#endif
