/* datadir.h: where the program finds the data files it ships (the dashboard's page in web/,
 * the OpenCL kernels in worker/kernels/): an environment variable if it is set (an explicit
 * choice wins), else directories relative to the executable (a checkout's bin/, or a test
 * program's build/tests/), else installed absolute ones -- the first holding a marker file.
 * One search for both, so an install layout is described in one place per caller. */
#ifndef TF_DATADIR_H
#define TF_DATADIR_H

#include <stddef.h>

/* Search as above: `env` (may be NULL), then each of `beside_exe` (NULL-terminated, appended
 * to the executable's directory, e.g. "/../web"), then each of `fixed` (NULL-terminated).  The
 * first directory that holds `marker` is written to dir.  0 found; -1 nothing found; -2 the
 * environment variable is set but its directory has no marker (dir holds it). */
int tf_datadir_find(const char *env, const char *const *beside_exe, const char *const *fixed,
                    const char *marker, char *dir, size_t len);

#endif
