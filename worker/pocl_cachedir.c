/* pocl_cachedir.c: see pocl_cachedir.h.  The directory is read through one descriptor opened
 * with O_NOFOLLOW, and every entry is examined and removed relative to it (fstatat, unlinkat),
 * so a directory swapped for a link after it was opened is never swept. */
#include "worker/pocl_cachedir.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cachefile.h"

#define TEMPFILE_PREFIX "tempfile_"
#define TEMPFILE_SUFFIX_LEN 6 /* mkstemp's XXXXXX */

void tf_pocl_cache_dir_choose(char *dir, size_t len)
{
    dir[0] = 0;
    if (getenv("POCL_CACHE_DIR"))
        return;
    const char *xdg = getenv("XDG_CACHE_HOME"), *home = getenv("HOME");
    if (xdg && *xdg && snprintf(dir, len, "%s/terrafarm/pocl", xdg) < (int)len &&
        tf_make_private_dirs(dir) == 0) {
        setenv("POCL_CACHE_DIR", dir, 0);
        return;
    }
    if (home && *home && snprintf(dir, len, "%s/.cache/terrafarm/pocl", home) < (int)len &&
        tf_make_private_dirs(dir) == 0) {
        setenv("POCL_CACHE_DIR", dir, 0);
        return;
    }
    snprintf(dir, len, "/tmp/terrafarm-pocl-%u", (unsigned)getuid());
    if (tf_make_private_dirs(dir) == 0)
        setenv("POCL_CACHE_DIR", dir, 0);
    else
        dir[0] = 0;
}

/* Is name PoCL's temporary file name, tempfile_XXXXXX? */
static int is_tempfile_name(const char *name)
{
    const size_t plen = sizeof TEMPFILE_PREFIX - 1;
    return strncmp(name, TEMPFILE_PREFIX, plen) == 0 &&
           strlen(name) == plen + TEMPFILE_SUFFIX_LEN;
}

/* Is the entry `name` of directory dirfd one of PoCL's temporary files left behind? */
static int is_stale_tempfile(int dirfd, const char *name, time_t now, long max_age_s)
{
    struct stat st;
    if (!is_tempfile_name(name) || fstatat(dirfd, name, &st, AT_SYMLINK_NOFOLLOW) != 0)
        return 0;
    return S_ISREG(st.st_mode) && st.st_uid == geteuid() && st.st_mtime < now - max_age_s;
}

int tf_pocl_cache_sweep(const char *dir, time_t now, long max_age_s)
{
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0)
        return -1;
    DIR *d = fdopendir(fd);
    if (!d) {
        int e = errno;
        close(fd);
        errno = e;
        return -1;
    }
    int removed = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL)
        if (is_stale_tempfile(fd, de->d_name, now, max_age_s) && unlinkat(fd, de->d_name, 0) == 0)
            removed++;
    closedir(d); /* closes fd */
    return removed;
}
