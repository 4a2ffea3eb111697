/* progress.c: see progress.h. */
#include "coordinator/progress.h"

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
    char line[256];
    int n = snprintf(line, sizeof line,
                     "rows %d/%d (%5.1f%%)  elapsed %s  eta %s  %.2f Mrays/s  %d worker%s",
                     rows_done, p->rows_total, pct, el, et, mrays, workers, workers == 1 ? "" : "s");
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
