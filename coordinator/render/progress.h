/* progress.h: what a user watching a render sees.  On a terminal, one live line rewritten in
 * place (rows written, percent, elapsed, ETA, rays/s, workers connected); otherwise a plain log
 * line every `interval` seconds; a summary at the end.  Quiet mode shows nothing but errors. */
#ifndef TF_PROGRESS_H
#define TF_PROGRESS_H

#include <stdint.h>

typedef struct tf_progress {
    int tty, quiet;
    double start_s, last_s, interval_s;
    int rows_total, rows_at_start;
    int shown;     /* a live line is on screen */
    int frames_total, frames_done, frame_now; /* a sequence (frames_total > 0) */
} tf_progress;

void tf_progress_init(tf_progress *p, int rows_total, int rows_at_start, int quiet, double now_s);
/* A sequence of frames_total frames, frames_done of them complete before the run: the line
 * then starts with the frames done and the frame being written, and rows_total (init) counts
 * the rows of every frame still to finish, so the ETA is the whole sequence's. */
void tf_progress_frames(tf_progress *p, int frames_total, int frames_done);
void tf_progress_frame_now(tf_progress *p, int frames_done, int frame_now);
/* Called often; prints only when due (or when force is set). */
void tf_progress_update(tf_progress *p, double now_s, int rows_done, uint64_t rays, int workers,
                        int force);
/* Erase the live line (before other messages or at the end). */
void tf_progress_clear(tf_progress *p);

#endif
