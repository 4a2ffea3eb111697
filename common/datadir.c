/* datadir.c: see datadir.h. */
#include "datadir.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int holds(const char *dir, const char *marker)
{
    char p[PATH_MAX];
    return snprintf(p, sizeof p, "%s/%s", dir, marker) < (int)sizeof p && access(p, R_OK) == 0;
}

int tf_datadir_find(const char *env, const char *const *beside_exe, const char *const *fixed,
                    const char *marker, char *dir, size_t len)
{
    const char *chosen = env ? getenv(env) : NULL;
    if (chosen && *chosen) {
        snprintf(dir, len, "%s", chosen);
        return holds(dir, marker) ? 0 : -2;
    }
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n > 0) {
        exe[n] = 0;
        char *slash = strrchr(exe, '/');
        if (slash)
            *slash = 0;
        for (size_t i = 0; beside_exe && beside_exe[i]; i++)
            if (snprintf(dir, len, "%s%s", exe, beside_exe[i]) < (int)len && holds(dir, marker))
                return 0;
    }
    for (size_t i = 0; fixed && fixed[i]; i++) {
        snprintf(dir, len, "%s", fixed[i]);
        if (holds(dir, marker))
            return 0;
    }
    return -1;
}
