/* directfile.c: see directfile.h. */
#include "directfile.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

void tf_directfile_check(const tf_directfile *f)
{
    assert(f->len < TF_DIRECTFILE_BUF && "W1: a full buffer went out at once");
    assert((!f->direct || f->off % TF_DIRECTFILE_ALIGN == 0) &&
           "W2: the direct path wrote whole blocks only");
    assert((f->err == 0 || f->len == 0) && "W3: nothing buffered after a failure");
    (void)f;
}

void tf_directfile_buffered(tf_directfile *f)
{
    int flags = fcntl(f->fd, F_GETFL);
    if (flags >= 0 && (flags & O_DIRECT))
        (void)fcntl(f->fd, F_SETFL, flags & ~O_DIRECT);
    f->direct = 0;
}

int tf_directfile_create(tf_directfile *f, const char *path)
{
    memset(f, 0, sizeof *f);
    f->fd = -1;
    int flags = O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC;
    if (posix_memalign((void **)&f->buf, TF_DIRECTFILE_ALIGN, TF_DIRECTFILE_BUF) != 0) {
        f->buf = NULL; /* no buffer: every write goes straight to the file, buffered */
    } else {
        f->fd = open(path, flags | O_DIRECT, 0666);
        f->direct = f->fd >= 0;
    }
    if (f->fd < 0 && (errno == EINVAL || !f->buf)) /* a file system without O_DIRECT */
        f->fd = open(path, flags, 0666);
    if (f->fd < 0) {
        int e = errno;
        free(f->buf);
        f->buf = NULL;
        errno = e;
        return -1;
    }
    return 0;
}

/* Write n bytes of p at f->off, resumed after short writes; a direct write refused with EINVAL
 * is done again buffered.  0, or -1 with f->err set. */
static int put(tf_directfile *f, const uint8_t *p, size_t n)
{
    while (n > 0 && !f->err) {
        ssize_t w = pwrite(f->fd, p, n, (off_t)f->off);
        if (w > 0) {
            p += w;
            n -= (size_t)w;
            f->off += (uint64_t)w;
        } else if (w < 0 && errno == EINVAL && f->direct) {
            tf_directfile_buffered(f);
        } else if (w < 0 && errno != EINTR) {
            f->err = errno;
        } else if (w == 0) {
            f->err = EIO;
        }
    }
    return f->err ? -1 : 0;
}

/* Write the buffer's first n bytes and keep the rest (fewer than a block) at its start. */
static int drain(tf_directfile *f, size_t n)
{
    int rc = put(f, f->buf, n);
    if (rc == 0 && n < f->len)
        memmove(f->buf, f->buf + n, f->len - n);
    f->len = rc == 0 ? f->len - n : 0;
    return rc;
}

int tf_directfile_write(tf_directfile *f, const void *p, size_t n)
{
    const uint8_t *src = p;
    if (!f->buf && !f->err)
        put(f, src, n);
    while (f->buf && n > 0 && !f->err) {
        size_t take = TF_DIRECTFILE_BUF - f->len;
        take = take < n ? take : n;
        memcpy(f->buf + f->len, src, take);
        f->len += take;
        src += take;
        n -= take;
        if (f->len == TF_DIRECTFILE_BUF)
            drain(f, f->len);
    }
    tf_directfile_check(f);
    if (f->err)
        errno = f->err;
    return f->err ? -1 : 0;
}

int tf_directfile_close(tf_directfile *f)
{
    if (!f->err && f->len > 0) {
        size_t whole = f->direct ? f->len & ~(size_t)(TF_DIRECTFILE_ALIGN - 1) : f->len;
        if (whole > 0)
            drain(f, whole);
        if (!f->err && f->len > 0) { /* the last part block, through the page cache */
            tf_directfile_buffered(f);
            drain(f, f->len);
        }
    }
    int err = f->err;
    if (close(f->fd) != 0 && !err)
        err = errno;
    f->fd = -1;
    free(f->buf);
    f->buf = NULL;
    errno = err;
    return err ? -1 : 0;
}

void tf_directfile_discard(tf_directfile *f)
{
    if (f->fd >= 0)
        close(f->fd);
    f->fd = -1;
    free(f->buf);
    f->buf = NULL;
}
