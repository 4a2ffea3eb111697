/* exrresume.c: resuming a partial output (exrfile.h).  The valid prefix is copied raw (packed
 * bytes, no recompression) into PATH.resume.tmp under the same header, that file is fsynced,
 * renamed over PATH, and the directory fsynced.  Until the rename PATH is the old partial file;
 * after it, the new one: never less. */
#include "image/exrinternal.h"

#include <errno.h>
#include <fcntl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "log.h"

/* Names what differs between the file's meta and the expected one; 0 if nothing does. */
static int describe_meta_change(const char *path, const tf_exr_meta *have,
                                const tf_exr_meta *want, char *err, size_t errlen)
{
    if (have->width != want->width || have->height != want->height) {
        tf_seterr(err, errlen, "%s: image size changed since the partial render (%dx%d vs %dx%d)",
                 path, have->width, have->height, want->width, want->height);
        return 1;
    }
    if (strcmp(have->scene_hash, want->scene_hash) != 0) {
        tf_seterr(err, errlen, "%s: scene changed since the partial render (hash %.12s... vs "
                 "%.12s...)", path, have->scene_hash, want->scene_hash);
        return 1;
    }
    if (strcmp(have->settings, want->settings) != 0) {
        tf_seterr(err, errlen, "%s: render settings changed since the partial render "
                 "('%.80s' vs '%.80s')", path, have->settings, want->settings);
        return 1;
    }
    tf_exr_layout a = tf_exr_meta_layout(have), b = tf_exr_meta_layout(want);
    if (a.tiled != b.tiled || a.pixel != b.pixel ||
        (a.tiled && (a.tile_w != b.tile_w || a.tile_h != b.tile_h))) {
        char la[64], lb[64];
        tf_exr_layout_format(&a, la, sizeof la);
        tf_exr_layout_format(&b, lb, sizeof lb);
        tf_seterr(err, errlen, "%s: the file's layout changed since the partial render ('%s' "
                  "vs '%s')", path, la, lb);
        return 1;
    }
    return 0;
}

typedef struct raw_copy {
    tf_exr_writer *w;
    char *err;
    size_t errlen;
} raw_copy;

/* Copy one verified chunk's packed bytes into the new file, untouched. */
static int copy_chunk_raw(void *user, const tf_chunk_ref *c, const uint8_t *packed, size_t len,
                          const tf_pixel *px)
{
    (void)px;
    raw_copy *rc = user;
    return tf_exr_write_chunk(rc->w, c->cx, c->cy, packed, len, rc->err, rc->errlen);
}

static int fsync_parent_dir(const char *path, char *err, size_t errlen)
{
    char *dir = strdup(path);
    if (!dir) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        return -1;
    }
    char *slash = strrchr(dir, '/');
    const char *d = slash ? (slash == dir ? "/" : (*slash = '\0', dir)) : ".";
    int fd = open(d, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    int rc = 0;
    if (fd < 0 || fsync(fd) != 0) {
        tf_seterr(err, errlen, "%s: cannot sync directory %s: %s", path, d, strerror(errno));
        rc = -1;
    }
    if (fd >= 0)
        close(fd);
    free(dir);
    return rc;
}

tf_exr_writer *tf_exr_resume(const char *path, const tf_exr_meta *expect, int *rows_done,
                             char *err, size_t errlen)
{
    return tf_exr_resume_prefix(path, expect, INT64_MAX, rows_done, err, errlen);
}

tf_exr_writer *tf_exr_resume_prefix(const char *path, const tf_exr_meta *expect,
                                    int64_t keep_chunks, int *rows_done, char *err, size_t errlen)
{
    tf_exr_reader r;
    int rc = tf_exr_reader_open(&r, path, err, errlen);
    if (rc == 1)
        tf_seterr(err, errlen, "%s: no partial render to resume", path);
    if (rc != 0)
        return NULL;
    if (describe_meta_change(path, &r.meta, expect, err, errlen)) {
        tf_exr_reader_close(&r);
        return NULL;
    }
    size_t plen = strlen(path);
    char *tmp = malloc(plen + sizeof ".resume.tmp");
    if (!tmp) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        tf_exr_reader_close(&r);
        return NULL;
    }
    memcpy(tmp, path, plen);
    memcpy(tmp + plen, ".resume.tmp", sizeof ".resume.tmp");

    tf_exr_writer *w = tf_exr_create(tmp, &r.meta, err, errlen);
    raw_copy copy = {w, err, errlen};
    int64_t good = w ? tf_exr_walk_packed(&r, keep_chunks, copy_chunk_raw, &copy, err, errlen)
                     : -1;
    tf_exr_reader_close(&r);
    if (good < 0 || tf_exr_sync(w, err, errlen) != 0) {
        tf_exr_abandon(w);
        unlink(tmp); /* PATH itself was never touched */
        free(tmp);
        return NULL;
    }
    if (rename(tmp, path) != 0) {
        tf_seterr(err, errlen, "%s: cannot rename %s over it: %s", path, tmp, strerror(errno));
        tf_exr_abandon(w);
        unlink(tmp);
        free(tmp);
        return NULL;
    }
    /* From here PATH is the new file (a valid partial render); the writer keeps its fd. */
    tf_exr_writer_take_path(w, tmp);
    memcpy(tmp, path, plen + 1);
    if (fsync_parent_dir(path, err, errlen) != 0) {
        tf_exr_abandon(w);
        return NULL;
    }
    *rows_done = tf_exr_next_row(w);
    return w;
}
