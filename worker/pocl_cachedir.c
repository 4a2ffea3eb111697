/* pocl_cachedir.c: see pocl_cachedir.h.  The directory is read through one descriptor opened
 * with O_NOFOLLOW, and every entry is examined and removed relative to it (fstatat, unlinkat),
 * so a directory swapped for a link after it was opened is never swept; the prune goes down
 * the same way, one O_NOFOLLOW descriptor a level. */
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

/* Directory `name` (relative to parent; AT_FDCWD for a path), opened for reading without
 * following a link; with `own`, only if it is this user's.  NULL with errno set otherwise. */
static DIR *open_dir(int parent, const char *name, int own)
{
    struct stat st;
    int fd = openat(parent, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    DIR *d = NULL;
    if (fd >= 0 && own && (fstat(fd, &st) != 0 || st.st_uid != geteuid()))
        errno = EPERM;
    else if (fd >= 0)
        d = fdopendir(fd);
    if (!d && fd >= 0) {
        int e = errno;
        close(fd);
        errno = e;
    }
    return d;
}

int tf_pocl_cache_sweep(const char *dir, time_t now, long max_age_s)
{
    DIR *d = open_dir(AT_FDCWD, dir, 0);
    if (!d)
        return -1;
    const int fd = dirfd(d);
    int removed = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL)
        if (is_stale_tempfile(fd, de->d_name, now, max_age_s) && unlinkat(fd, de->d_name, 0) == 0)
            removed++;
    closedir(d); /* closes fd */
    return removed;
}

/* ---------------------------------------------------------------- program directories */

/* How deep below a program directory the removal goes: PoCL 3.1 keeps kernel/variant/file
 * (3 levels); the rest is room for another layout, and a bound on the recursion. */
#define PROGRAM_TREE_DEPTH 8

/* Is name made of PoCL's hash letters (A to P) only, between min and max of them? */
static int is_hash_name(const char *name, size_t min, size_t max)
{
    size_t n = strlen(name);
    if (n < min || n > max)
        return 0;
    for (size_t i = 0; i < n; i++)
        if (name[i] < 'A' || name[i] > 'P')
            return 0;
    return 1;
}

/* Remove directory `name` of parent and everything in it, down to `depth` levels; a link is
 * removed as a name, never followed.  0 when it is gone. */
static int remove_tree(int parent, const char *name, int depth)
{
    DIR *d = depth > 0 ? open_dir(parent, name, 0) : NULL;
    if (!d)
        return -1;
    const int fd = dirfd(d);
    struct dirent *de;
    while ((de = readdir(d)) != NULL) {
        struct stat st;
        if (!strcmp(de->d_name, ".") || !strcmp(de->d_name, "..") ||
            fstatat(fd, de->d_name, &st, AT_SYMLINK_NOFOLLOW) != 0)
            continue;
        if (S_ISDIR(st.st_mode))
            remove_tree(fd, de->d_name, depth - 1);
        else
            unlinkat(fd, de->d_name, 0);
    }
    closedir(d); /* closes fd */
    return unlinkat(parent, name, AT_REMOVEDIR);
}

/* When program directory `name` of bucketfd was last used: its last_accessed file's time, else
 * its own.  -1 when it is not a directory of this user's. */
static time_t program_last_use(int bucketfd, const char *name)
{
    DIR *d = open_dir(bucketfd, name, 1);
    if (!d)
        return -1;
    struct stat st;
    int touched =
        fstatat(dirfd(d), "last_accessed", &st, AT_SYMLINK_NOFOLLOW) == 0 && S_ISREG(st.st_mode);
    if (!touched && fstat(dirfd(d), &st) != 0)
        st.st_mtime = -1;
    closedir(d);
    return st.st_mtime;
}

/* Prune one XX directory of the cache; how many program directories went. */
static int prune_bucket(int parent, const char *bucket, time_t now, long max_idle_s)
{
    DIR *d = open_dir(parent, bucket, 1);
    if (!d)
        return 0;
    const int fd = dirfd(d);
    int removed = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL) {
        if (!is_hash_name(de->d_name, 8, 64))
            continue;
        time_t used = program_last_use(fd, de->d_name);
        if (used >= 0 && used < now - max_idle_s &&
            remove_tree(fd, de->d_name, PROGRAM_TREE_DEPTH) == 0)
            removed++;
    }
    closedir(d); /* closes fd */
    if (removed)
        unlinkat(parent, bucket, AT_REMOVEDIR); /* only if nothing else is left in it */
    return removed;
}

int tf_pocl_cache_prune(const char *dir, time_t now, long max_idle_s)
{
    DIR *d = open_dir(AT_FDCWD, dir, 0);
    if (!d)
        return -1;
    int removed = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL)
        if (is_hash_name(de->d_name, 2, 2))
            removed += prune_bucket(dirfd(d), de->d_name, now, max_idle_s);
    closedir(d); /* closes fd */
    return removed;
}
