/* cachefile.h: a cache entry written atomically: a temporary file beside it, fsync, rename, mode
 * 0600, the directory created (0700) as needed.  A failure costs only the cache: it is logged
 * as a warning and the caller goes on without it. */
#ifndef TF_CACHEFILE_H
#define TF_CACHEFILE_H

#include <stddef.h>
#include <stdint.h>

void tf_cachefile_write(const char *dir, const char *path, const uint8_t *b, size_t len);

#endif
