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
 *       with hold, and referring only with hold.
 * and, for the direct path (tf_exr_sink_go_direct; bench/README.md section 17):
 *   D1  staging only with a direct descriptor: stage_len > 0 implies dfd >= 0 and stage;
 *   D2  a direct descriptor has its block size (align > 0), and the stage starts on a block:
 *       stage_off is a multiple of align;
 *   D3  between calls the stage holds less than a block (every whole block went out);
 *       stage_pending (those bytes are not in the file yet) only with stage_len > 0. */
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
    /* Direct output: with dfd open (the same file, O_DIRECT), a flushed run is copied into
     * `stage`, an aligned buffer that mirrors the file's bytes [stage_off, stage_off +
     * stage_len), and goes out in whole blocks that bypass the page cache (the kernel's copy
     * into it was most of the writer's CPU); the last part block goes out through fd and
     * stays staged, so the next run continues it.  A run elsewhere in the file drops the stage
     * and stages afresh from the block it starts in (read back through dfd). */
    int dfd;           /* the file opened O_DIRECT, or -1: every write goes through fd */
    size_t align;      /* the direct path's block (SINK_ALIGN; a power of two dividing
                        * SINK_STAGE): offsets and lengths of direct writes */
    uint8_t *stage;    /* SINK_STAGE bytes aligned to SINK_ALIGN, or NULL */
    uint64_t stage_off;
    size_t stage_len;
    int stage_pending; /* the staged part block is not in the file yet (tf_exr_sink_flush puts
                        * it there; a run's internal flush leaves it for the next run) */
} tf_exr_sink;

#define SINK_ALIGN 4096             /* the direct path's block: a sector of every common disk */
#define SINK_STAGE (1024 * 1024)    /* bytes staged for one direct write at most */

/* An empty sink on no file (fd and dfd -1). */
void tf_exr_sink_init(tf_exr_sink *s);
/* Open the direct path for s->fd, which was opened from `path`: a regular file that can be
 * opened again O_DIRECT (read-write, for a block's head) and is the same file.  Otherwise, or
 * without memory, everything stays on fd.  Optimisation only: nothing to report. */
void tf_exr_sink_go_direct(tf_exr_sink *s, const char *path);
/* Close both descriptors (fd's close error, if any, is returned as -1 with errno) and free
 * the buffers. */
int tf_exr_sink_close(tf_exr_sink *s);

/* Assert E1-E6 (above) on s, one assert per clause; nothing with NDEBUG. */
void tf_exr_sink_check(const tf_exr_sink *s);
/* Write the run out (pwritev, resumed after a short write; or through the stage), so that
 * every byte handed over is in the file.  0, or -1 with write_errno set. */
int tf_exr_sink_flush(tf_exr_sink *s);
/* The same, except that on the direct path the stage's last part block (under a block, a copy)
 * stays staged, not yet in the file, until the next run continues it or a tf_exr_sink_flush puts
 * it there: the references to the caller's memory end all the same.  Saves a buffered write of
 * that block and, at the next direct write over it, the kernel's writeback and invalidation of
 * its page; a kill loses at most those bytes (a torn last chunk, which a resume renders again). */
int tf_exr_sink_emit(tf_exr_sink *s);
/* OpenEXRCore's write function (its user data is the sink). */
int64_t tf_exr_sink_write(exr_const_context_t ctxt, void *userdata, const void *buffer,
                          uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb);

#endif
