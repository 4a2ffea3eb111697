/* frames.c: see frames.h. */
#include "coordinator/render/frames.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "animation.h"
#include "log.h"

static int parse_frame_number(const char *s, const char **end, int *out)
{
    if (*s < '0' || *s > '9')
        return -1;
    errno = 0;
    char *e;
    long v = strtol(s, &e, 10);
    if (errno || v >= TF_ANIM_MAX_FRAMES)
        return -1;
    *out = (int)v;
    *end = e;
    return 0;
}

int tf_frame_range_parse(const char *flag, const char *text, tf_frame_range *r, char *err,
                         size_t errlen)
{
    const char *s = text, *e;
    r->step = 1;
    if (parse_frame_number(s, &e, &r->first))
        goto bad;
    r->last = r->first;
    if (*e == '-') {
        if (parse_frame_number(e + 1, &e, &r->last))
            goto bad;
        if (*e == ':') {
            if (parse_frame_number(e + 1, &e, &r->step) || r->step < 1)
                goto bad;
        }
    }
    if (*e)
        goto bad;
    if (r->last < r->first)
        return tf_seterr(err, errlen, "%s '%s': the last frame is before the first", flag, text);
    return 0;
bad:
    return tf_seterr(err, errlen, "%s '%s': expected N, A-B or A-B:STEP (frame numbers 0..%d, "
                     "STEP >= 1)", flag, text, TF_ANIM_MAX_FRAMES - 1);
}

int tf_frame_range_fits(const tf_frame_range *r, int scene_frames, const char *what, char *err,
                        size_t errlen)
{
    if (scene_frames <= 0)
        return tf_seterr(err, errlen, "--frame/--frames: %s has no [animation] section: it is a "
                         "still (render it without them)", what);
    if (r->last >= scene_frames)
        return tf_seterr(err, errlen, "--frame/--frames: %s has frames 0..%d; frame %d is not "
                         "one of them", what, scene_frames - 1, r->last);
    return 0;
}

int tf_frame_range_count(const tf_frame_range *r) { return (r->last - r->first) / r->step + 1; }

char *tf_frame_default_pattern(const char *scene_path)
{
    const char *base = strrchr(scene_path, '/');
    base = base ? base + 1 : scene_path;
    size_t len = strlen(base);
    if (len > 6 && !strcmp(base + len - 6, ".scene"))
        len -= 6;
    size_t n = len + sizeof "out/.####.exr";
    char *out = malloc(n);
    if (out)
        snprintf(out, n, "out/%.*s.####.exr", (int)len, base);
    return out;
}

/* The last run of '#': its start and length (0 if none). */
static size_t last_run(const char *p, size_t *start)
{
    size_t n = strlen(p), len = 0;
    for (size_t i = n; i-- > 0;) {
        if (p[i] == '#') {
            size_t j = i;
            while (j > 0 && p[j - 1] == '#')
                j--;
            *start = j;
            len = i - j + 1;
            break;
        }
    }
    return len;
}

int tf_frame_pattern_has_number(const char *pattern)
{
    size_t start;
    return last_run(pattern, &start) > 0;
}

char *tf_frame_output_path(const char *pattern, int frame)
{
    size_t start = 0, run = last_run(pattern, &start);
    if (run == 0)
        return strdup(pattern);
    size_t n = strlen(pattern) + 16;
    char *out = malloc(n);
    if (out)
        snprintf(out, n, "%.*s%0*d%s", (int)start, pattern, (int)run, frame,
                 pattern + start + run);
    return out;
}
