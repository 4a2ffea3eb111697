/* isa.c: see isa.h. */
#include "isa.h"

#include <string.h>

int tf_isa_runs(const char *name)
{
    if (!strcmp(name, "portable"))
        return 1;
#if defined(__x86_64__) && defined(__GNUC__) /* as the kernels' headers build them */
    if (!strcmp(name, "avx512"))
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
               __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq");
    if (!strcmp(name, "avx2"))
        return __builtin_cpu_supports("avx2");
#endif
    return 0;
}

/* The name entry i of the table begins with. */
static const char *name_at(const void *table, size_t size, int i)
{
    const char *name;
    memcpy(&name, (const char *)table + (size_t)i * size, sizeof name);
    return name;
}

int tf_isa_find(const void *table, size_t size, int n, const char *name)
{
    int i = 0;
    while (i < n && strcmp(name_at(table, size, i), name))
        i++;
    return i;
}

int tf_isa_choose(const void *table, size_t size, int n, const char *cap)
{
    int i = cap ? tf_isa_find(table, size, n, cap) : 0;
    if (i == n)
        i = 0;
    while (i < n - 1 && !tf_isa_runs(name_at(table, size, i)))
        i++;
    return i;
}
