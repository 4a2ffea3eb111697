/* output.h: the coordinator's policy for the file it renders into.  The OpenEXR output is the
 * checkpoint (image/exrfile.h does the file format): before any expensive work the coordinator
 * decides whether to start fresh, resume the rows already on disk, report the render complete,
 * or refuse (a partial render without --resume, a changed scene); then it opens the file so
 * that at every instant the path holds either what was there before or a valid resumable
 * render. */
#ifndef TF_OUTPUT_H
#define TF_OUTPUT_H

#include "image/exrfile.h"
#include "scene.h"

/* out/<scene basename without .scene>.exr, malloc'd. */
char *tf_output_default_path(const char *scene_path);
/* FILE.exr -> FILE.png (FILE.png appended when there is no .exr), malloc'd. */
char *tf_output_preview_path(const char *output);

/* The header attributes a render of scene s writes and a resume compares. */
void tf_output_meta(tf_exr_meta *m, const tf_scene *s, const char *scene_path);

typedef struct tf_output_plan {
    int resume_rows;   /* rows to keep (>= 0), or -1: start a fresh file */
    int complete;      /* 1: the output is already a finished render of this scene */
} tf_output_plan;

/* Decide what to do with whatever is at `output`, following --resume / --overwrite.  0 with
 * *plan filled, or -1 after logging why it refuses.  Touches nothing on disk. */
int tf_output_plan_for(const char *output, const tf_exr_meta *want, int resume, int overwrite,
                       tf_output_plan *plan);

/* Open the output as planned: resume it (checking it still holds plan->resume_rows rows) or
 * create it fresh (parent directories made, header written beside it and renamed into place).
 * A writer, or NULL with one line in err. */
tf_exr_writer *tf_output_open(const char *output, const tf_exr_meta *meta,
                              const tf_output_plan *plan, char *err, size_t errlen);

#endif
