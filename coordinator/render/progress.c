/* progress.c: see progress.h. */
#include "coordinator/render/progress.h"

#include <stdio.h>
#include <unistd.h>

#include "log.h"

void tf_progress_init(tf_progress *p, int rows_total, int rows_at_start, int quiet, double now_s)
{
    p->tty = isatty(STDERR_FILENO);
    p->quiet = quiet || tf_log_get_level() < TF_LOG_INFO;
    p->start_s = now_s;
    p->last_s = now_s;
    p->interval_s = p->tty ? 0.25 : 10.0;
    p->rows_total = rows_total;
    p->rows_at_start = rows_at_start;
    p->shown = 0;
    p->frames_total = p->frames_done = 0;
    p->frame_now = -1;
}

void tf_progress_frames(tf_progress *p, int frames_total, int frames_done)
{
    p->frames_total = frames_total;
    p->frames_done = frames_done;
}

void tf_progress_frame_now(tf_progress *p, int frames_done, int frame_now)
{
    p->frames_done = frames_done;
    p->frame_now = frame_now;
}

static void format_duration(char *buf, size_t len, double s)
{
    if (s < 0 || s > 1e7)
        snprintf(buf, len, "--:--");
    else if (s >= 3600)
        snprintf(buf, len, "%d:%02d:%02d", (int)s / 3600, ((int)s / 60) % 60, (int)s % 60);
    else
        snprintf(buf, len, "%d:%02d", (int)s / 60, (int)s % 60);
}

void tf_progress_update(tf_progress *p, double now_s, int rows_done, uint64_t rays, int workers,
                        int force)
{
    if (p->quiet || (!force && now_s - p->last_s < p->interval_s))
        return;
    p->last_s = now_s;
    double elapsed = now_s - p->start_s;
    int done_now = rows_done - p->rows_at_start;
    int left = p->rows_total - rows_done;
    double eta = done_now > 0 ? elapsed * left / done_now : -1;
    char el[32], et[32];
    format_duration(el, sizeof el, elapsed);
    format_duration(et, sizeof et, eta);
    double pct = p->rows_total ? 100.0 * rows_done / p->rows_total : 100.0;
    double mrays = elapsed > 0 ? (double)rays / elapsed / 1e6 : 0;
    char line[320], frames[64] = "";
    if (p->frames_total > 0 && p->frame_now >= 0)
        snprintf(frames, sizeof frames, "frames %d/%d done, frame %d in flight  ", p->frames_done,
                 p->frames_total, p->frame_now);
    else if (p->frames_total > 0)
        snprintf(frames, sizeof frames, "frames %d/%d done  ", p->frames_done, p->frames_total);
    int n = snprintf(line, sizeof line,
                     "%s%s %d/%d (%5.1f%%)  elapsed %s  eta %s  %.2f Mrays/s  %d worker%s", frames,
                     p->frames_total > 0 ? "sequence rows" : "rows", rows_done, p->rows_total, pct,
                     el, et, mrays, workers, workers == 1 ? "" : "s");
    if (n < 0)
        return;
    if (p->tty) {
        fprintf(stderr, "\r%s\033[K", line);
        fflush(stderr);
        p->shown = 1;
    } else {
        tf_info("%s", line);
    }
}

void tf_progress_clear(tf_progress *p)
{
    if (p->tty && p->shown) {
        fprintf(stderr, "\r\033[K");
        fflush(stderr);
        p->shown = 0;
    }
}
