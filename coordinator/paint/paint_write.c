/* paint_write.c: see paint_write.h. */
#include "coordinator/paint/paint_write.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "image/exrfile.h"
#include "log.h"

static void fill_meta(tf_exr_meta *m, const tf_scene *view, int64_t gen, int pixel_type)
{
    memset(m, 0, sizeof *m);
    m->width = view->width;
    m->height = view->height;
    m->pixel = pixel_type;
    snprintf(m->scene_hash, sizeof m->scene_hash, "%s", view->hash_hex);
    const char *name = strrchr(view->path ? view->path : "", '/');
    snprintf(m->scene_name, sizeof m->scene_name, "%s",
             name ? name + 1 : (view->path ? view->path : ""));
    snprintf(m->settings, sizeof m->settings, "paint view=%" PRId64, gen);
}

int tf_paint_write(const char *path, const tf_scene *view, int64_t gen, const tf_pixel *px,
                   int pixel_type)
{
    char err[1024], tmp[4096];
    tf_exr_meta meta;
    fill_meta(&meta, view, gen, pixel_type);
    if (snprintf(tmp, sizeof tmp, "%s.paint.tmp", path) >= (int)sizeof tmp) {
        tf_error("%s: path too long", path);
        return -1;
    }
    tf_exr_writer *w = tf_exr_create(tmp, &meta, err, sizeof err);
    int rc = !w || tf_exr_write_rows(w, view->height, px, err, sizeof err) ? -1 : 0;
    if (rc == 0) {
        rc = tf_exr_finish(w, err, sizeof err);
        w = NULL;
    }
    if (w)
        tf_exr_abandon(w);
    if (rc == 0 && rename(tmp, path) != 0) {
        snprintf(err, sizeof err, "%s: cannot rename into place: %s", path, strerror(errno));
        rc = -1;
    }
    if (rc != 0) {
        tf_error("%s", err);
        remove(tmp);
        return -1;
    }
    tf_info("painted view %" PRId64 " written to %s", gen, path);
    return 0;
}
