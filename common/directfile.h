/* directfile.h: a new file written front to back around the page cache where the file system
 * allows (O_DIRECT), for the files the coordinator rewrites while it renders (the progress
 * preview PNG).  On this kind of virtual machine the kernel's copy into fresh page-cache pages
 * costs more than the data is worth (bench/README.md sections 17 and 18); a direct write DMAs
 * from the aligned buffer here instead.
 *
 * Bytes gather in an aligned buffer and leave it as whole blocks through the O_DIRECT
 * descriptor; tf_directfile_close writes the last part block through the same descriptor with
 * O_DIRECT cleared.  A file system that refuses O_DIRECT at open, or a direct write refused
 * with EINVAL (a block larger than TF_DIRECTFILE_ALIGN), leaves the file on buffered writes,
 * even in the middle: the file's bytes are the same either way.
 *
 * Invariants between calls (tf_directfile_check asserts them in the `make asan` build):
 *   W1  buf holds less than TF_DIRECTFILE_BUF bytes: a full buffer went out at once;
 *   W2  on the direct path every write so far was whole blocks: off is a multiple of
 *       TF_DIRECTFILE_ALIGN;
 *   W3  after the first failure (err != 0) nothing more is buffered (len == 0). */
#ifndef TF_DIRECTFILE_H
#define TF_DIRECTFILE_H

#include <stddef.h>
#include <stdint.h>

#define TF_DIRECTFILE_ALIGN 4096          /* a sector of every common disk */
#define TF_DIRECTFILE_BUF (256 * 1024)    /* bytes per write (a multiple of the block) */

typedef struct tf_directfile {
    int fd;
    int direct;    /* fd is O_DIRECT now */
    uint8_t *buf;  /* TF_DIRECTFILE_BUF bytes aligned to TF_DIRECTFILE_ALIGN */
    size_t len;    /* bytes waiting in buf */
    uint64_t off;  /* file offset of buf[0]: bytes already written */
    int err;       /* the first errno, 0 while none */
} tf_directfile;

/* Create (or truncate) path, mode 0666 less the umask.  0, or -1 with errno set (f is then
 * closed). */
int tf_directfile_create(tf_directfile *f, const char *path);
/* Append n bytes.  0, or -1 with errno set to the first failure (later writes fail alike). */
int tf_directfile_write(tf_directfile *f, const void *p, size_t n);
/* Write what is buffered and close.  0, or -1 with errno (the first failure, or close's). */
int tf_directfile_close(tf_directfile *f);
/* Close without writing what is buffered (the caller removes the file); nothing on a file
 * already closed or never created (fd -1). */
void tf_directfile_discard(tf_directfile *f);
/* Leave the direct path now (tests: the buffered path from the start). */
void tf_directfile_buffered(tf_directfile *f);

/* Assert W1-W3 on f, one assert per clause; nothing with NDEBUG. */
void tf_directfile_check(const tf_directfile *f);

#endif
