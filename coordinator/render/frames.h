/* frames.h: which frames of an [animation] scene a render covers and where each one goes.
 * `--frames A-B[:STEP]` or `--frame N` choose the frames; the output name is a pattern whose
 * run of '#' is replaced by the zero-padded frame number (out/flyby.####.exr ->
 * out/flyby.0042.exr), default out/<scene>.####.exr; each frame's PNG preview goes beside it. */
#ifndef TF_FRAMES_H
#define TF_FRAMES_H

#include <stddef.h>

typedef struct tf_frame_range {
    int first, last, step; /* first <= last, step >= 1 */
} tf_frame_range;

/* "A-B", "A-B:S" or "N" (a single frame).  0, or -1 with a one-line message naming flag. */
int tf_frame_range_parse(const char *flag, const char *text, tf_frame_range *r, char *err,
                         size_t errlen);
/* Whether a render of a scene with `scene_frames` frames (0: a still) may cover r: 0, or -1
 * with a one-line message naming the scene (`what`). */
int tf_frame_range_fits(const tf_frame_range *r, int scene_frames, const char *what, char *err,
                        size_t errlen);
/* Number of frames in r. */
int tf_frame_range_count(const tf_frame_range *r);

/* out/<scene basename without .scene>.####.exr, malloc'd. */
char *tf_frame_default_pattern(const char *scene_path);
/* 1 if the pattern holds a run of '#' (only the last run counts). */
int tf_frame_pattern_has_number(const char *pattern);
/* The pattern with its last run of '#' replaced by frame, zero-padded to the run's length (or
 * longer if needed); a pattern without '#' is returned as it is.  malloc'd. */
char *tf_frame_output_path(const char *pattern, int frame);

#endif
