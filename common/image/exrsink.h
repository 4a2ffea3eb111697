/* exrsink.h: the output stream of an OpenEXR file being written (exrsink.c): our descriptor,
 * the first errno that hit it, the abandon switch, and the write-behind run, so that
 * (1) tf_exr_sync can fsync it, (2) the first failing write (ENOSPC, EIO, ...) is remembered
 * with its errno and reported as one line naming the file, and (3) tf_exr_abandon can close the
 * file without OpenEXRCore writing another byte: it sets `abandoned`, after which
 * tf_exr_sink_write refuses everything, exactly as if the process had been killed at that
 * instant.  Internal to the files behind exrfile.h.
 *
 * Invariants, after every call that changes a sink (tf_exr_sink_check asserts them clause by
 * clause in the `make asan` build, each failure naming its clause):
 *   E1  (1) a run waits only on an open descriptor: pieces in the run imply fd >= 0;
 *   E2  (2) write_errno is 0 or the first errno, and after it nothing joins the run (the next
 *       flush drops what is there);
 *   E3  (3) an abandoned sink holds no run: what was handed over before went out first;
 *   E4  the run is its pieces: 0 <= niov <= SINK_IOV and run_len is the sum of their lengths
 *       (so an empty run has no pieces, and no bytes);
 *   E5  the copies fit the buffer: len <= SINK_BUFFER, len > 0 only with buf, and len <=
 *       run_len (every copied byte is in the run);
 *   E6  references only while the caller keeps them alive: 0 <= held <= niov, held > 0 only
 *       with hold, and referring only with hold. */
#ifndef TF_EXRSINK_H
#define TF_EXRSINK_H

#include <openexr.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/uio.h>

#define SINK_IOV 64 /* pieces in one run (one pwritev) */

typedef struct tf_exr_sink {
    int fd;
    int write_errno;  /* first failure, 0 if none */
    int abandoned;    /* once set, nothing more reaches the file */
    /* Write-behind: OpenEXRCore writes each chunk as two writes (its small header, its
     * bytes), in increasing offsets.  Contiguous writes gather here as one run of pieces and
     * reach the file in one pwritev when the run is full, before any other write, and on
     * sink_flush (sync, finish, abandon, tf_exr_flush): two syscalls per chunk become one per
     * run.  Small pieces are copied into buf; with `hold` set (tf_exr_hold_chunks), large ones
     * are referenced where they lie, and the caller keeps them alive until the next flush.
     * The file is still always a prefix of what was written, so a kill leaves whole chunks
     * and at most one torn one. */
    uint8_t *buf;
    size_t len;        /* bytes of buf in use */
    uint64_t run_off;  /* file offset of the run's first byte */
    uint64_t run_len;  /* bytes in the run */
    struct iovec iov[SINK_IOV];
    int niov;
    int hold;          /* tf_exr_hold_chunks: the caller keeps its chunks alive to the flush */
    int referring;     /* set only around tf_exr_write_chunk's raw write of the caller's bytes */
    int held;          /* pieces of the run that are references */
} tf_exr_sink;

/* Assert E1-E6 (above) on s, one assert per clause; nothing with NDEBUG. */
void tf_exr_sink_check(const tf_exr_sink *s);
/* Write the run out (pwritev, resumed after a short write).  0, or -1 with write_errno set. */
int tf_exr_sink_flush(tf_exr_sink *s);
/* OpenEXRCore's write function (its user data is the sink). */
int64_t tf_exr_sink_write(exr_const_context_t ctxt, void *userdata, const void *buffer,
                          uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb);

#endif
