/* output.h: the coordinator's policy for the file it renders into.  The OpenEXR output is the
 * checkpoint (image/exrfile.h does the file format): before any expensive work the coordinator
 * decides whether to start fresh, resume the rows already on disk, report the render complete,
 * or refuse (a partial render without --resume, a changed scene); then it opens the file so
 * that at every instant the path holds either what was there before or a valid resumable
 * render.
 *
 * A finished render is never lost: a new render over one (plain or --overwrite) renders
 * beside it, into OUTPUT.rendering.tmp, and replaces it only once complete
 * (tf_output_commit, an atomic rename); until then, and if the new render fails (a full disk,
 * an interrupt), OUTPUT is the finished render it was (tf_output_discard removes the partial
 * file beside it).  Such a render cannot be resumed: it is started again.  A partial render at
 * OUTPUT is continued in place with --resume, or replaced at once with --overwrite. */
#ifndef TF_OUTPUT_H
#define TF_OUTPUT_H

#include "image/exrfile.h"
#include "scene.h"

/* out/<scene basename without .scene>.exr, malloc'd. */
char *tf_output_default_path(const char *scene_path);
/* FILE.exr -> FILE.png (FILE.png appended when there is no .exr), malloc'd. */
char *tf_output_preview_path(const char *output);

/* The header attributes a render of scene s into a file of layout l writes and a resume
 * compares (the pixel type is part of the settings). */
void tf_output_meta(tf_exr_meta *m, const tf_scene *s, const char *scene_path,
                    const tf_exr_layout *l);

typedef struct tf_output_plan {
    int resume_rows;   /* whole rows to keep (>= 0), or -1: start a fresh file */
    int resume_tiles;  /* and, in a tiled file, the tiles of the next tile row on disk */
    int complete;      /* 1: the output is already a finished render of this scene */
    int beside;        /* 1: a finished render is there: render into `working`, then rename */
    char working[4096];/* the file being written (the output itself unless beside) */
} tf_output_plan;

/* With --resume and no --tasks: the layout of a terrafarm render already at `output` (so the
 * resume continues its tiles, whatever the default stamp size would be now).  1 and *l filled
 * if there is one, else 0. */
int tf_output_existing_layout(const char *output, tf_exr_layout *l);

/* Decide what to do with whatever is at `output`, following --resume / --overwrite.  0 with
 * *plan filled, or -1 after logging why it refuses.  Touches nothing on disk. */
int tf_output_plan_for(const char *output, const tf_exr_meta *want, int resume, int overwrite,
                       tf_output_plan *plan);

/* Open the output as planned: resume it (checking it still holds plan->resume_rows rows) or
 * create it fresh (parent directories made, header written beside it and renamed into place).
 * A writer, or NULL with one line in err. */
tf_exr_writer *tf_output_open(const char *output, const tf_exr_meta *meta,
                              const tf_output_plan *plan, char *err, size_t errlen);
/* After the writer finished: a render made beside a finished one replaces it now.  0 or -1
 * with one line in err. */
int tf_output_commit(const char *output, const tf_output_plan *plan, char *err, size_t errlen);
/* After a render that did not finish: a partial file beside a finished render is removed (the
 * finished render stays).  Nothing for other renders. */
void tf_output_discard(const char *output, const tf_output_plan *plan);

#endif
