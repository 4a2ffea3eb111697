/* cachefile.h: the files of terrafarm's caches (the erosion cache, the OpenCL program cache):
 * their directories made private, and entries written atomically. */
#ifndef TF_CACHEFILE_H
#define TF_CACHEFILE_H

#include <stddef.h>
#include <stdint.h>

/* mkdir -p path, each directory it makes mode 0700; 0 if it then exists and is writable, else
 * -1 (errno set). */
int tf_make_private_dirs(const char *path);

/* Write entry `path` in cache directory dir (made as above) atomically: a temporary file
 * beside it, fsync, rename, mode 0600.  A failure costs only the cache: it is logged as a
 * warning and the caller goes on without it. */
void tf_cachefile_write(const char *dir, const char *path, const uint8_t *b, size_t len);

#endif
