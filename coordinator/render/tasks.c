/* tasks.c: see tasks.h. */
#include "coordinator/render/tasks.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "log.h"

static int parse_positive(const char *s, char **end, int *out)
{
    char *e;
    long v = strtol(s, &e, 10);
    if (e == s || v <= 0 || v > 65536)
        return -1;
    *out = (int)v;
    *end = e;
    return 0;
}

int tf_task_spec_parse(const char *text, tf_task_spec *spec, char *err, size_t errlen)
{
    char *end;
    if (!strncmp(text, "rows:", 5)) {
        if (parse_positive(text + 5, &end, &spec->h) == 0 && *end == '\0') {
            spec->shape = TF_TASKS_ROWS;
            spec->w = 0;
            return 0;
        }
    } else if (!strncmp(text, "stamps:", 7)) {
        if (parse_positive(text + 7, &end, &spec->w) == 0 && (*end == 'x' || *end == 'X') &&
            parse_positive(end + 1, &end, &spec->h) == 0 && *end == '\0') {
            spec->shape = TF_TASKS_STAMPS;
            return 0;
        }
    }
    tf_seterr(err, errlen, "--tasks '%s': expected rows:K or stamps:WxH with positive sizes up to 65536",
             text);
    return -1;
}

/* A band (one row of tasks) waits in the tuple space until its last task is done, so its size
 * is the coordinator's memory: keep it under this many pixels whatever the image width.  Not
 * smaller: every task costs the coordinator a round trip, a decode and a check whatever its
 * size, and at 128 K pixels a 3840-wide image got stamps of 128x34 (1140 tasks at 3840x1280)
 * whose per-task costs were a third of the coordinator's CPU (bench/README.md section 12:
 * 512 K pixels, stamps 128x128, 0.68x its CPU for ~10-20 MB more memory at 2048^2-8192^2). */
#define BAND_PIXEL_BUDGET (512 * 1024)

tf_task_spec tf_task_spec_default(int width, int height, int workers)
{
    /* Aim for at least 24 tasks per worker, sides between 32 and 128 pixels.  A 64x64 stamp
     * computes (65 * 65) corner samples for 4096 pixels: 3% extra corner rays, well under 1% of
     * all rays once adaptive subdivision adds its samples.  On very wide images the stamps get
     * flatter (down to 8 rows) so that one band stays within BAND_PIXEL_BUDGET. */
    if (workers < 1)
        workers = 1;
    long pixels = (long)width * height;
    int side = 128;
    while (side > 32 && pixels / ((long)side * side) < 24L * workers)
        side /= 2;
    tf_task_spec s = {TF_TASKS_STAMPS, side, side};
    long band_rows = BAND_PIXEL_BUDGET / (width > 0 ? width : 1);
    if (band_rows < s.h)
        s.h = band_rows < 8 ? 8 : (int)band_rows;
    if (s.w > width)
        s.w = width;
    if (s.h > height)
        s.h = height;
    return s;
}

/* Many workers on small tasks need the deeper pipeline: a worker should find its next task
 * waiting rather than wait for the write front (bench/README.md section 13: 1024 simulated
 * workers on 8x8 stamps made 0.890-0.901 of the modelled work at 4 a worker, 0.894-0.914 at
 * 16, against a bound of 0.946); large tasks keep the floor, their results being large. */
int tf_tasks_auto_ahead(const tf_tasks *t, int workers)
{
    if (workers <= 0)
        return 0;
    long task_px = (long)t->tw * t->th;
    long ahead = TF_AUTO_AHEAD_PIXELS / (task_px > 0 ? task_px : 1);
    if (ahead > (long)TF_AUTO_AHEAD_MAX * workers)
        ahead = (long)TF_AUTO_AHEAD_MAX * workers;
    if (ahead < (long)TF_AUTO_AHEAD_MIN * workers)
        ahead = (long)TF_AUTO_AHEAD_MIN * workers;
    return (int)ahead;
}

void tf_tasks_init(tf_tasks *t, int width, int height, int first_row, tf_task_spec spec)
{
    memset(t, 0, sizeof *t);
    t->width = width;
    t->height = height;
    t->first_row = first_row;
    t->tw = spec.shape == TF_TASKS_ROWS ? width : (spec.w < width ? spec.w : width);
    t->th = spec.h < height ? spec.h : height;
    if (t->th < 1)
        t->th = 1;
    t->cols = (width + t->tw - 1) / t->tw;
    int rows = height - first_row;
    t->bands = rows > 0 ? (rows + t->th - 1) / t->th : 0;
    t->count = t->cols * t->bands;
}

void tf_band_rows(const tf_tasks *t, int band, int *y0, int *rows)
{
    *y0 = t->first_row + band * t->th;
    *rows = t->height - *y0 < t->th ? t->height - *y0 : t->th;
}

void tf_tasks_skip(tf_tasks *t, int n)
{
    if (n < 0 || n >= t->cols || t->count == 0)
        return;
    t->skip = n;
    t->count = t->cols * t->bands - n;
}

tf_rect tf_task_rect(const tf_tasks *t, int id)
{
    int g = id + t->skip;
    int band = g / t->cols, col = g % t->cols;
    tf_rect r;
    r.x = col * t->tw;
    r.w = t->width - r.x < t->tw ? t->width - r.x : t->tw;
    tf_band_rows(t, band, &r.y, &r.h);
    return r;
}
