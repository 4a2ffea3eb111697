/* scratch_dir.h: a private temporary directory for a cmocka test program that writes files.
 * scratch_dir_make / scratch_dir_remove are group setup and teardown functions;
 * scratch_path(name) gives a path inside it (the last four results stay valid).
 * Header-only (static functions): each test program is its own executable. */
#ifndef TF_SCRATCH_DIR_H
#define TF_SCRATCH_DIR_H

#include <stdio.h>
#include <stdlib.h>

static char scratch_dir[256];

static int scratch_dir_make(void **state)
{
    (void)state;
    snprintf(scratch_dir, sizeof scratch_dir, "%s/tf-test-XXXXXX",
             getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
    return mkdtemp(scratch_dir) ? 0 : -1;
}

static int scratch_dir_remove(void **state)
{
    (void)state;
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", scratch_dir);
    return system(cmd) == 0 ? 0 : -1;
}

static const char *scratch_path(const char *name)
{
    static char buf[4][320];
    static int next;
    char *p = buf[next++ % 4];
    snprintf(p, 320, "%s/%s", scratch_dir, name);
    return p;
}

#endif
