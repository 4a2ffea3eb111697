/* cachefile.c: a cache's directories and files (cachefile.h). */
#include "cachefile.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "log.h"

int tf_make_private_dirs(const char *path)
{
    char buf[PATH_MAX];
    if (snprintf(buf, sizeof buf, "%s", path) >= (int)sizeof buf)
        return -1;
    for (char *p = buf + 1; *p; p++) {
        if (*p != '/')
            continue;
        *p = 0;
        if (mkdir(buf, 0700) != 0 && errno != EEXIST)
            return -1;
        *p = '/';
    }
    if (mkdir(buf, 0700) != 0 && errno != EEXIST)
        return -1;
    return access(buf, W_OK) == 0 ? 0 : -1;
}

void tf_cachefile_write(const char *dir, const char *path, const uint8_t *b, size_t len)
{
    char tmp[600];
    snprintf(tmp, sizeof tmp, "%s.%ld.tmp", path, (long)getpid());
    if (tf_make_private_dirs(dir) != 0) {
        tf_warn("%s: cannot create the erosion cache: %s", dir, strerror(errno));
        return;
    }
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    size_t off = 0;
    while (fd >= 0 && off < len) {
        ssize_t w = write(fd, b + off, len - off);
        if (w <= 0)
            break;
        off += (size_t)w;
    }
    int ok = fd >= 0 && off == len && fsync(fd) == 0;
    if (fd >= 0)
        ok = close(fd) == 0 && ok;
    if (!ok || rename(tmp, path) != 0) {
        tf_warn("%s: cannot write the erosion cache entry: %s", path, strerror(errno));
        unlink(tmp);
    }
}

