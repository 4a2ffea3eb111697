/* exrsink.c: the output stream under OpenEXRCore (exrsink.h): every byte of an output file
 * goes through tf_exr_sink_write, a write-behind buffer and pwrite loop on our own descriptor,
 * and on a regular file through an aligned stage written O_DIRECT. */
#include "image/exrsink.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
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
    assert((s->stage_len == 0 || (s->dfd >= 0 && s->stage)) &&
           "D1: staging only with a direct descriptor");
    assert((s->dfd < 0 || s->align > 0) && "D2: a direct descriptor has its block size");
    assert((s->dfd < 0 || s->align == 0 || s->stage_off % s->align == 0) &&
           "D2: the stage starts on a block");
    assert((s->stage_len == 0 || s->stage_len < s->align) && /* D1 holds: align was set */
           "D3: less than a block staged between calls");
    assert((!s->stage_pending || s->stage_len > 0) && "D3: pending only with staged bytes");
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

void tf_exr_sink_init(tf_exr_sink *s)
{
    memset(s, 0, sizeof *s);
    s->fd = s->dfd = -1;
}

void tf_exr_sink_go_direct(tf_exr_sink *s, const char *path)
{
    struct stat a, b;
    if (s->fd < 0 || s->dfd >= 0 || fstat(s->fd, &a) != 0 || !S_ISREG(a.st_mode))
        return;
    int d = open(path, O_RDWR | O_DIRECT | O_CLOEXEC);
    if (d < 0)
        return; /* a file system without O_DIRECT, or no read permission: stay buffered */
    void *stage = NULL;
    if (fstat(d, &b) != 0 || a.st_dev != b.st_dev || a.st_ino != b.st_ino ||
        posix_memalign(&stage, SINK_ALIGN, SINK_STAGE) != 0) {
        close(d); /* the path names another file now: ours stays the only one written */
        return;
    }
    s->dfd = d;
    s->align = SINK_ALIGN;
    s->stage = stage;
    s->stage_off = 0;
    s->stage_len = 0;
    s->stage_pending = 0;
}

int tf_exr_sink_close(tf_exr_sink *s)
{
    int rc = 0;
    if (s->dfd >= 0)
        close(s->dfd);
    if (s->fd >= 0 && close(s->fd) != 0)
        rc = -1;
    s->fd = s->dfd = -1;
    free(s->buf);
    free(s->stage);
    s->buf = s->stage = NULL;
    s->len = s->stage_len = 0;
    s->stage_pending = 0;
    return rc;
}

/* The direct path failed in a way that says "not here" (EINVAL: an alignment this file
 * system refuses): from now on everything goes through fd, and nothing stays staged. */
static void leave_direct(tf_exr_sink *s)
{
    close(s->dfd);
    s->dfd = -1;
}

/* Put [p, p+sz) at offset: through dfd when it is open (p, sz and offset whole blocks),
 * else, or for what the direct path would not take, through fd.  0, or -1 with write_errno. */
static int sink_put(tf_exr_sink *s, const uint8_t *p, uint64_t sz, uint64_t offset)
{
    while (s->dfd >= 0 && sz > 0) {
        ssize_t n = pwrite(s->dfd, p, (size_t)sz, (off_t)offset);
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0 && errno == EINVAL)
            leave_direct(s);
        if (n <= 0 || n % s->align != 0)
            break; /* a failure or a part block (a full disk, a size limit): fd says which */
        p += n;
        sz -= (uint64_t)n;
        offset += (uint64_t)n;
    }
    return sz > 0 ? sink_pwrite(s, p, sz, offset) : 0;
}

/* Empty the stage, its part block put in the file first if it is not there yet. */
static int stage_drop(tf_exr_sink *s)
{
    int rc = s->stage_pending ? sink_pwrite(s, s->stage, s->stage_len, s->stage_off) : 0;
    s->stage_len = 0;
    s->stage_pending = 0;
    return rc;
}

static int pwritev_run(tf_exr_sink *s);

/* Start the stage afresh at `offset`: from its block's start, the bytes before offset read
 * back from the file (zeros past its end). */
static int stage_restart(tf_exr_sink *s, uint64_t offset)
{
    if (stage_drop(s))
        return -1;
    s->stage_off = offset - offset % s->align;
    s->stage_len = (size_t)(offset - s->stage_off);
    s->stage_pending = 0;
    if (s->stage_len == 0)
        return 0;
    ssize_t n;
    do
        n = pread(s->dfd, s->stage, s->align, (off_t)s->stage_off);
    while (n < 0 && errno == EINTR);
    if (n < 0 && errno == EINVAL) {
        leave_direct(s);
        s->stage_len = 0;
        return 0;
    }
    if (n < 0 && !s->write_errno)
        s->write_errno = errno;
    if (n < 0)
        return -1;
    if ((size_t)n < s->stage_len)
        memset(s->stage + n, 0, s->stage_len - (size_t)n);
    return 0;
}

/* Append [p, p+sz) to the stage, writing it out whenever it is full. */
static int stage_append(tf_exr_sink *s, const uint8_t *p, size_t sz)
{
    while (sz > 0) {
        size_t k = SINK_STAGE - s->stage_len < sz ? SINK_STAGE - s->stage_len : sz;
        memcpy(s->stage + s->stage_len, p, k);
        s->stage_len += k;
        p += k;
        sz -= k;
        if (s->stage_len == SINK_STAGE) {
            if (sink_put(s, s->stage, SINK_STAGE, s->stage_off))
                return -1;
            s->stage_off += SINK_STAGE;
            s->stage_len = 0;
        }
    }
    return 0;
}

/* The stage's whole blocks out; its part block kept for the next run, and with `settle` put in
 * the file too (through fd). */
static int stage_settle(tf_exr_sink *s, int settle)
{
    size_t whole = s->stage_len - s->stage_len % s->align;
    if (whole && sink_put(s, s->stage, whole, s->stage_off))
        return -1;
    size_t part = s->stage_len - whole;
    memmove(s->stage, s->stage + whole, part);
    s->stage_off += whole;
    s->stage_len = part;
    s->stage_pending = part > 0;
    if ((settle || s->dfd < 0) && s->stage_pending) {
        if (sink_pwrite(s, s->stage, part, s->stage_off))
            return -1;
        s->stage_pending = 0;
    }
    return 0;
}

/* The run through the stage (dfd open): appended where the stage ends, or the stage started
 * afresh where the run starts. */
static int stage_run(tf_exr_sink *s, int settle)
{
    if (s->run_off != s->stage_off + s->stage_len && stage_restart(s, s->run_off))
        return -1;
    if (s->dfd < 0)
        return pwritev_run(s);
    for (int i = 0; i < s->niov; i++)
        if (stage_append(s, s->iov[i].iov_base, s->iov[i].iov_len))
            return -1;
    return stage_settle(s, settle);
}

/* The run through fd: one pwritev, resumed after a short write. */
static int pwritev_run(tf_exr_sink *s)
{
    struct iovec *v = s->iov;
    int n = s->niov;
    uint64_t off = s->run_off;
    while (n > 0) {
        ssize_t k = pwritev(s->fd, v, n, (off_t)off);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0) {
            if (!s->write_errno)
                s->write_errno = k < 0 ? errno : EIO;
            return -1;
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
    return 0;
}

/* The run out, and with `settle` the stage's part block too; the run left empty. */
static int sink_emit(tf_exr_sink *s, int settle)
{
    int rc = 0;
    if (s->write_errno) /* nothing more reaches the file: drop the run and its references */
        rc = -1;
    else if (s->dfd >= 0 && s->stage)
        rc = s->niov ? stage_run(s, settle) : stage_settle(s, settle);
    else if (s->niov)
        rc = pwritev_run(s);
    if (s->dfd < 0 || rc != 0) /* left the direct path, or failed: the stage means nothing */
        s->stage_len = 0, s->stage_pending = 0;
    s->niov = 0;
    s->held = 0;
    s->len = 0;
    s->run_len = 0;
    tf_exr_sink_check(s);
    return rc;
}

int tf_exr_sink_flush(tf_exr_sink *s) { return sink_emit(s, 1); }

int tf_exr_sink_emit(tf_exr_sink *s) { return sink_emit(s, 0); }

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
        if (sink_emit(s, 0))
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
    if (stage_drop(s)) /* this write bypasses the stage, which may overlap it */
        return -1;
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
