/* cachefile.c: files of the erosion cache, written whole or not at all (cachefile.h). */
#include "terrain/cachefile.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "log.h"

/* mkdir -p dir (mode 0700 for what it creates).  0, or -1 with errno set. */
static int make_dirs(const char *dir)
{
    char path[400];
    snprintf(path, sizeof path, "%s", dir);
    for (char *p = path + 1; *p; p++)
        if (*p == '/') {
            *p = '\0';
            if (mkdir(path, 0700) != 0 && errno != EEXIST)
                return -1;
            *p = '/';
        }
    return mkdir(path, 0700) != 0 && errno != EEXIST ? -1 : 0;
}

void tf_cachefile_write(const char *dir, const char *path, const uint8_t *b, size_t len)
{
    char tmp[600];
    snprintf(tmp, sizeof tmp, "%s.%ld.tmp", path, (long)getpid());
    if (make_dirs(dir) != 0) {
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

