/* output.c: see output.h. */
#include "coordinator/render/output.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "log.h"

/* out/<scene basename without .scene>.exr */
char *tf_output_default_path(const char *scene_path)
{
    const char *base = strrchr(scene_path, '/');
    base = base ? base + 1 : scene_path;
    size_t len = strlen(base);
    if (len > 6 && !strcmp(base + len - 6, ".scene"))
        len -= 6;
    char *out = malloc(len + 10);
    if (out)
        snprintf(out, len + 10, "out/%.*s.exr", (int)len, base);
    return out;
}

/* FILE.exr -> FILE.png (or FILE.png appended when there is no .exr). */
char *tf_output_preview_path(const char *output)
{
    size_t len = strlen(output);
    char *p = malloc(len + 5);
    if (!p)
        return NULL;
    if (len > 4 && !strcmp(output + len - 4, ".exr"))
        snprintf(p, len + 5, "%.*s.png", (int)(len - 4), output);
    else
        snprintf(p, len + 5, "%s.png", output);
    return p;
}

/* mkdir -p of the directory part of path. */
static int ensure_parent_dir(const char *path, char *err, size_t errlen)
{
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (!slash || slash == dir)
        return 0;
    *slash = '\0';
    for (char *p = dir + 1; *p; p++) {
        if (*p != '/')
            continue;
        *p = '\0';
        mkdir(dir, 0777);
        *p = '/';
    }
    if (mkdir(dir, 0777) && errno != EEXIST) {
        tf_seterr(err, errlen, "%.900s: cannot create directory: %s", dir, strerror(errno));
        return -1;
    }
    return 0;
}

void tf_output_meta(tf_exr_meta *m, const tf_scene *s, const char *scene_path,
                    const tf_exr_layout *l)
{
    memset(m, 0, sizeof *m);
    m->width = s->width;
    m->height = s->height;
    m->tiled = l->tiled;
    m->tile_w = l->tile_w;
    m->tile_h = l->tile_h;
    m->pixel = l->pixel;
    snprintf(m->scene_hash, sizeof m->scene_hash, "%s", s->hash_hex);
    const char *base = strrchr(scene_path, '/');
    snprintf(m->scene_name, sizeof m->scene_name, "%s", base ? base + 1 : scene_path);
    /* Everything besides the scene that decides pixel values: the renderer's version and the
     * channel type of R, G, B, A. */
    snprintf(m->settings, sizeof m->settings, "renderer=terrafarm-%s pixel=%s", TF_VERSION,
             tf_pixel_type_name(l->pixel));
}

int tf_output_existing_layout(const char *output, tf_exr_layout *l)
{
    tf_exr_meta have;
    int64_t chunks = 0;
    int complete = 0;
    char err[1024];
    if (tf_exr_probe_chunks(output, &have, &chunks, &complete, err, sizeof err) != 0)
        return 0;
    *l = tf_exr_meta_layout(&have);
    return 1;
}

/* What is at an output path already: a terrafarm render's metadata and layout, the chunks on
 * disk and the rows they make, and whether it is complete. */
typedef struct found_output {
    tf_exr_meta have;
    tf_exr_layout layout;
    int64_t chunks;
    int rows, complete;
} found_output;

/* 1: nothing there; 0: a terrafarm render, in *f; -1: something else (why in err). */
static int probe_output(const char *output, found_output *f, char *err, size_t errlen)
{
    memset(f, 0, sizeof *f);
    int r = tf_exr_probe_chunks(output, &f->have, &f->chunks, &f->complete, err, errlen);
    f->layout = tf_exr_meta_layout(&f->have);
    if (r == 0)
        f->rows = tf_layout_rows_in_chunks(&f->layout, f->chunks);
    return r;
}

/* A render from the start over what f found (no --resume, or --overwrite): beside a finished
 * render, which is never lost; over a partial one with --overwrite or with no rows; else a
 * refusal naming --resume and --overwrite.  0, or -1 once refused. */
static int plan_fresh(const char *output, const found_output *f, int resume, int overwrite,
                      tf_output_plan *plan)
{
    if (f->complete && !resume) {
        plan->beside = 1;
        snprintf(plan->working, sizeof plan->working, "%s.rendering.tmp", output);
        tf_info("%s: a finished render is there; it is replaced only once the new one is "
                "complete", output);
        return 0;
    }
    if (overwrite) {
        if (!f->complete)
            tf_info("%s: discarding a partial render of %d/%d rows (--overwrite)", output,
                    f->rows, f->have.height);
        return 0;
    }
    if (!f->complete && f->chunks == 0) {
        tf_info("%s: a partial render with no rows is there; it will be replaced", output);
        return 0;
    }
    tf_error("%s holds a partial render (%d of %d rows on disk): use --resume to continue it "
             "or --overwrite to start again",
             output, f->rows, f->have.height);
    return -1;
}

/* --resume: the same image size, scene, settings and layout as the file f found, or one line
 * saying which changed (1). */
static int resume_refused(const char *output, const found_output *f, const tf_exr_meta *want)
{
    const tf_exr_meta *have = &f->have;
    if (have->width != want->width || have->height != want->height) {
        tf_error("%s: cannot resume: image size changed (%dx%d on disk, %dx%d now)", output,
                 have->width, have->height, want->width, want->height);
        return 1;
    }
    if (strcmp(have->scene_hash, want->scene_hash)) {
        tf_error("%s: cannot resume: the scene changed since the partial render (hash %.12s on "
                 "disk, %.12s now)",
                 output, have->scene_hash, want->scene_hash);
        return 1;
    }
    if (strcmp(have->settings, want->settings)) {
        tf_error("%s: cannot resume: render settings changed ('%s' on disk, '%s' now)", output,
                 have->settings, want->settings);
        return 1;
    }
    if (have->tiled == want->tiled && have->pixel == want->pixel &&
        (!have->tiled || (have->tile_w == want->tile_w && have->tile_h == want->tile_h)))
        return 0;
    char a[64], b[64];
    tf_exr_layout want_layout = tf_exr_meta_layout(want);
    tf_exr_layout_format(&f->layout, a, sizeof a);
    tf_exr_layout_format(&want_layout, b, sizeof b);
    tf_error("%s: cannot resume: the file is '%s', this render would write '%s' (resume with the "
             "same --tasks and --pixel, or without --tasks)",
             output, a, b);
    return 1;
}

int tf_output_plan_for(const char *output, const tf_exr_meta *want, int resume, int overwrite,
                       tf_output_plan *plan)
{
    plan->resume_rows = -1;
    plan->resume_tiles = 0;
    plan->complete = 0;
    plan->beside = 0;
    snprintf(plan->working, sizeof plan->working, "%s", output);
    found_output f;
    char err[1024];
    int r = probe_output(output, &f, err, sizeof err);
    if (r == 1) {
        if (resume)
            tf_info("%s: nothing to resume, starting a fresh render", output);
        return 0;
    }
    if (r < 0) {
        if (overwrite)
            return 0;
        tf_error("%s exists and is not a terrafarm render that can be resumed (%s); use "
                 "--overwrite to replace it",
                 output, err);
        return -1;
    }
    if (!resume || overwrite)
        return plan_fresh(output, &f, resume, overwrite, plan);
    if (resume_refused(output, &f, want))
        return -1;
    if (f.complete) {
        plan->complete = 1;
        return 0;
    }
    plan->resume_rows = f.rows;
    plan->resume_tiles = (int)(f.chunks % tf_layout_chunks_x(&f.layout));
    return 0;
}

/* A fresh output, created atomically.  OpenEXRCore writes a header in many small writes, so a
 * coordinator killed while creating OUTPUT in place would leave an empty or torn header that no
 * later --resume can read.  Instead the header goes to OUTPUT.new.tmp, which is renamed over
 * OUTPUT once whole and then reopened as a resumable render with no rows: at every instant
 * OUTPUT holds what was there before or a valid zero-row partial, never less. */
static tf_exr_writer *create_output(const char *output, const tf_exr_meta *meta, char *err,
                                    size_t errlen)
{
    size_t n = strlen(output) + sizeof ".new.tmp";
    char *tmp = malloc(n);
    if (!tmp) {
        tf_seterr(err, errlen, "%s: out of memory", output);
        return NULL;
    }
    snprintf(tmp, n, "%s.new.tmp", output);
    tf_exr_writer *w = tf_exr_create(tmp, meta, err, errlen);
    if (w) {
        tf_exr_abandon(w); /* closes it, header written, no rows */
        w = NULL;
        if (rename(tmp, output) == 0) {
            int rows_done = -1;
            w = tf_exr_resume(output, meta, &rows_done, err, errlen);
            if (w && rows_done != 0) {
                tf_exr_abandon(w);
                w = NULL;
                tf_seterr(err, errlen, "%s: changed while starting (%d rows, expected 0)", output,
                         rows_done);
            }
        } else {
            tf_seterr(err, errlen, "%s: cannot create: %s", output, strerror(errno));
        }
    }
    remove(tmp); /* gone after the rename; a failed create's leftovers otherwise */
    free(tmp);
    return w;
}


tf_exr_writer *tf_output_open(const char *output, const tf_exr_meta *meta,
                              const tf_output_plan *plan, char *err, size_t errlen)
{
    if (plan->beside) {
        remove(plan->working); /* a leftover of an earlier attempt */
        return tf_exr_create(plan->working, meta, err, errlen);
    }
    if (plan->resume_rows < 0) {
        if (ensure_parent_dir(output, err, errlen))
            return NULL;
        return create_output(output, meta, err, errlen);
    }
    int rows_done = 0;
    tf_exr_writer *w = tf_exr_resume(output, meta, &rows_done, err, errlen);
    tf_exr_layout l = tf_exr_meta_layout(meta);
    int tiles = w ? (int)(tf_exr_next_chunk(w) % tf_layout_chunks_x(&l)) : 0;
    if (w && (rows_done != plan->resume_rows || tiles != plan->resume_tiles)) {
        tf_exr_abandon(w);
        tf_seterr(err, errlen, "%s: changed while starting (%d rows, expected %d)", output,
                  rows_done, plan->resume_rows);
        return NULL;
    }
    if (w && tiles > 0)
        tf_info("resuming %s: %d of %d rows already on disk (and %d tiles of the next tile "
                "row)", output, rows_done, meta->height, tiles);
    else if (w)
        tf_info("resuming %s: %d of %d rows already on disk", output, rows_done, meta->height);
    return w;
}

/* fsync the directory holding path, so a rename in it is durable. */
static void sync_parent_dir(const char *path)
{
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (slash == dir)
        slash[1] = '\0';
    else if (slash)
        *slash = '\0';
    else
        snprintf(dir, sizeof dir, ".");
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd >= 0) {
        fsync(fd);
        close(fd);
    }
}

int tf_output_commit(const char *output, const tf_output_plan *plan, char *err, size_t errlen)
{
    if (!plan->beside)
        return 0;
    if (rename(plan->working, output) != 0)
        return tf_seterr(err, errlen, "%s: cannot replace it with the new render %s: %s", output,
                         plan->working, strerror(errno));
    sync_parent_dir(output);
    return 0;
}

void tf_output_discard(const char *output, const tf_output_plan *plan)
{
    if (!plan->beside)
        return;
    (void)output;
    remove(plan->working);
}
