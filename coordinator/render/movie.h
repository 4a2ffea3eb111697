/* movie.h: `render --movie FILE.mp4|webm`: after a sequence has rendered, ffmpeg (if it is
 * installed) assembles the frames' PNG previews into a video at the scene's frame rate. */
#ifndef TF_MOVIE_H
#define TF_MOVIE_H

#include <stddef.h>

/* 0 if path ends in .mp4 or .webm (case-insensitive), else -1 with a message. */
int tf_movie_check_name(const char *path, char *err, size_t errlen);
/* 1 if an ffmpeg executable is on PATH. */
int tf_movie_available(void);
/* Encode the n PNGs (in order) at fps into path (H.264 for .mp4, VP9 for .webm; written to
 * PATH.tmp.EXT and renamed into place).  0, or -1 with one line in err. */
int tf_movie_make(const char *path, const char *const *pngs, int n, double fps, char *err,
                  size_t errlen);

#endif
