/* exrsink.c: the output stream under OpenEXRCore (exrsink.h): every byte of an output file
 * goes through tf_exr_sink_write, a write-behind buffer and pwrite loop on our own descriptor. */
#include "image/exrsink.h"

#include <assert.h>
#include <errno.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>


#define SINK_BUFFER (256 * 1024)
#define SINK_REF_MIN 4096 /* with hold: pieces this large are referenced, not copied */

void tf_exr_sink_check(const tf_exr_sink *s)
{
#ifndef NDEBUG
    uint64_t sum = 0;
    for (int i = 0; i < s->niov && i < SINK_IOV; i++)
        sum += s->iov[i].iov_len;
    assert((s->niov == 0 || s->fd >= 0) && "E1: a run waits only on an open descriptor");
    assert(s->write_errno >= 0 && "E2: write_errno is 0 or an errno");
    assert((!s->abandoned || s->niov == 0) && "E3: an abandoned sink holds no run");
    assert(s->niov >= 0 && s->niov <= SINK_IOV && "E4: at most SINK_IOV pieces in the run");
    assert(s->run_len == sum && "E4: run_len is the sum of the pieces' lengths");
    assert(s->len <= SINK_BUFFER && "E5: the copies fit the buffer");
    assert((s->len == 0 || s->buf) && "E5: copies only with a buffer");
    assert(s->len <= s->run_len && "E5: every copied byte is in the run");
    assert(s->held >= 0 && s->held <= s->niov && "E6: 0 <= held <= niov");
    assert((s->held == 0 || s->hold) && "E6: references only with hold");
    assert((!s->referring || s->hold) && "E6: referring only with hold");
#else
    (void)s;
#endif
}

static int sink_pwrite(tf_exr_sink *s, const uint8_t *p, uint64_t sz, uint64_t offset)
{
    uint64_t done = 0;
    while (done < sz) {
        ssize_t n = pwrite(s->fd, p + done, (size_t)(sz - done), (off_t)(offset + done));
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0) {
            if (!s->write_errno)
                s->write_errno = n < 0 ? errno : EIO;
            return -1;
        }
        done += (uint64_t)n;
    }
    return 0;
}

/* Write the run out (pwritev, resumed after a short write).  0, or -1 with write_errno set. */
int tf_exr_sink_flush(tf_exr_sink *s)
{
    if (s->write_errno) { /* nothing more reaches the file: drop the run and its references */
        s->niov = s->held = 0;
        s->len = 0;
        s->run_len = 0;
        return -1;
    }
    struct iovec *v = s->iov;
    int n = s->niov;
    uint64_t off = s->run_off;
    int rc = 0;
    while (n > 0) {
        ssize_t k = pwritev(s->fd, v, n, (off_t)off);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0) {
            if (!s->write_errno)
                s->write_errno = k < 0 ? errno : EIO;
            rc = -1;
            break;
        }
        off += (uint64_t)k;
        while (n > 0 && (size_t)k >= v->iov_len) {
            k -= (ssize_t)v->iov_len;
            v++;
            n--;
        }
        if (n > 0) {
            v->iov_base = (uint8_t *)v->iov_base + k;
            v->iov_len -= (size_t)k;
        }
    }
    s->niov = 0;
    s->held = 0;
    s->len = 0;
    s->run_len = 0;
    tf_exr_sink_check(s);
    return rc;
}

/* Add a piece to the run (which has room for it: the caller checked). */
static void sink_add(tf_exr_sink *s, const void *p, size_t sz, uint64_t offset)
{
    assert(!s->write_errno && "E2: nothing joins the run after a failure");
    assert(!s->abandoned && "E3: nothing joins the run of an abandoned sink");
    if (s->run_len == 0)
        s->run_off = offset;
    struct iovec *last = s->niov > 0 ? &s->iov[s->niov - 1] : NULL;
    if (last && (const uint8_t *)last->iov_base + last->iov_len == (const uint8_t *)p)
        last->iov_len += sz; /* the buffer's tail, grown by a copy just made */
    else
        s->iov[s->niov++] = (struct iovec){(void *)p, sz};
    s->run_len += sz;
}

/* tf_exr_sink_write's work: the bytes into the run, or straight to the file. */
static int64_t sink_take(tf_exr_sink *s, const void *buffer, uint64_t sz, uint64_t offset)
{
    if (s->abandoned || s->write_errno)
        return -1;
    if (sz > (uint64_t)INT64_MAX || offset > (uint64_t)INT64_MAX - sz) {
        s->write_errno = EFBIG;
        return -1;
    }
    if (sz == 0)
        return 0;
    if (!s->buf)
        s->buf = malloc(SINK_BUFFER); /* without it, every write goes straight through */
    /* Only the caller's packed bytes, never OpenEXRCore's own buffers (the header, the offset
     * table at finish, the encoder's output), which it may free before the flush. */
    int refer = s->referring && sz >= SINK_REF_MIN;
    int fits = refer ? 1 : s->buf && s->len + sz <= SINK_BUFFER;
    if (s->run_len > 0 && (offset != s->run_off + s->run_len || s->niov == SINK_IOV || !fits))
        if (tf_exr_sink_flush(s))
            return -1;
    if (refer) {
        sink_add(s, buffer, (size_t)sz, offset);
        s->held++;
        return (int64_t)sz;
    }
    if (s->buf && s->len + sz <= SINK_BUFFER) {
        memcpy(s->buf + s->len, buffer, (size_t)sz);
        sink_add(s, s->buf + s->len, (size_t)sz, offset);
        s->len += (size_t)sz;
        return (int64_t)sz;
    }
    return sink_pwrite(s, buffer, sz, offset) ? -1 : (int64_t)sz;
}

int64_t tf_exr_sink_write(exr_const_context_t ctxt, void *userdata, const void *buffer,
                          uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctxt;
    (void)error_cb;
    tf_exr_sink *s = userdata;
    int64_t n = sink_take(s, buffer, sz, offset);
    tf_exr_sink_check(s);
    return n;
}
