/* render_option.c: see render_option.h.  One small parser a kind of value; the table at the
 * end says which option takes which. */
#include "coordinator/render/render_option.h"

#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "farmproto.h"
#include "image/exrlayout.h"
#include "log.h"
#include "coordinator/render/frames.h"

static int int_in(const char *flag, const char *s, int lo, int hi, int *out, char *err,
                  size_t errlen)
{
    char *end;
    long v = strtol(s, &end, 10);
    if (end == s || *end || v < lo || v > hi)
        return tf_seterr(err, errlen, "%s '%s': expected an integer from %d to %d", flag, s, lo,
                         hi);
    *out = (int)v;
    return 0;
}

int tf_image_size_parse(const char *flag, const char *text, int *w, int *h, char *err,
                        size_t errlen)
{
    char *end;
    long a = strtol(text, &end, 10);
    if (end == text || (*end != 'x' && *end != 'X'))
        goto bad;
    const char *p = end + 1;
    long b = strtol(p, &end, 10);
    if (end == p || *end || a < 1 || b < 1 || a > 65536 || b > 65536)
        goto bad;
    *w = (int)a;
    *h = (int)b;
    return 0;
bad:
    return tf_seterr(err, errlen, "%s '%s': expected WxH with sides from 1 to 65536", flag, text);
}

static int set_lease(tf_render_opts *o, const char *v, char *err, size_t errlen)
{
    int64_t ms;
    if (tf_parse_duration_ms(v, &ms) || ms < TF_LEASE_MIN_MS || ms > 86400000)
        return tf_seterr(err, errlen, "--lease-timeout '%s': expected a duration from 1s to 24h "
                         "(e.g. 15s, 1500ms, 2m; a bare number is milliseconds)", v);
    o->lease_timeout_ms = (int)ms;
    return 0;
}

static int set_frames(tf_render_opts *o, const char *flag, const char *v, char *err,
                      size_t errlen)
{
    tf_frame_range fr;
    if (o->frames_given)
        return tf_seterr(err, errlen, "render: give --frames or --frame once");
    if (tf_frame_range_parse(flag, v, &fr, err, errlen))
        return -1;
    if (!strcmp(flag, "--frame") && fr.last != fr.first)
        return tf_seterr(err, errlen, "--frame '%s': expected one frame number (--frames takes "
                         "a range)", v);
    o->frames_given = 1;
    o->frame_first = fr.first, o->frame_last = fr.last, o->frame_step = fr.step;
    return 0;
}

static int set_verify(tf_render_opts *o, const char *v, char *err, size_t errlen)
{
    char *end;
    double f = strtod(v, &end);
    if (end == v || *end || !(f >= 0 && f <= 1))
        return tf_seterr(err, errlen, "--verify '%s': expected a fraction from 0 to 1", v);
    o->verify_fraction = f;
    return 0;
}

static int set_word(const char *flag, const char *v, const char *const *words, const char **out,
                    char *err, size_t errlen)
{
    for (int i = 0; words[i]; i++)
        if (!strcmp(v, words[i])) {
            *out = words[i];
            return 0;
        }
    return tf_seterr(err, errlen, "%s '%s': expected %s%s%s%s%s", flag, v, words[0],
                     words[2] ? ", " : " or ", words[1], words[2] ? " or " : "",
                     words[2] ? words[2] : "");
}

static int set_choice(tf_render_opts *o, const char *flag, const char *v, char *err,
                      size_t errlen)
{
    static const char *const on_off[] = {"on", "off", NULL};
    static const char *const backends[] = {"c", "opencl", "auto", NULL};
    static const char *const pixels[] = {"half", "float", NULL};
    const char *word;
    if (!strcmp(flag, "--affinity")) {
        if (set_word(flag, v, on_off, &word, err, errlen))
            return -1;
        o->affinity = !strcmp(word, "on");
    } else if (!strcmp(flag, "--backend")) {
        if (set_word(flag, v, backends, &o->backend, err, errlen))
            return -1;
    } else {
        if (set_word(flag, v, pixels, &word, err, errlen))
            return -1;
        tf_pixel_type_parse(word, &o->pixel);
        o->pixel_given = 1;
    }
    return 0;
}

int tf_render_option_set(tf_render_opts *o, const char *flag, const char *v, char *err,
                         size_t errlen)
{
    if (!strcmp(flag, "--workers"))
        return int_in(flag, v, 0, 4096, &o->workers, err, errlen);
    if (!strcmp(flag, "--wait-workers"))
        return int_in(flag, v, 0, 1 << 20, &o->wait_workers, err, errlen);
    if (!strcmp(flag, "--watermark"))
        return int_in(flag, v, 1, 1 << 20, &o->watermark, err, errlen);
    if (!strcmp(flag, "--preview-interval"))
        return int_in(flag, v, 100, 86400000, &o->preview_interval_ms, err, errlen);
    if (!strcmp(flag, "--size"))
        return tf_image_size_parse(flag, v, &o->width, &o->height, err, errlen);
    if (!strcmp(flag, "--tasks")) {
        if (tf_task_spec_parse(v, &o->tasks, err, errlen))
            return -1;
        o->tasks_given = 1;
        return 0;
    }
    if (!strcmp(flag, "--frames") || !strcmp(flag, "--frame"))
        return set_frames(o, flag, v, err, errlen);
    if (!strcmp(flag, "--verify"))
        return set_verify(o, v, err, errlen);
    if (!strcmp(flag, "--lease-timeout"))
        return set_lease(o, v, err, errlen);
    if (!strcmp(flag, "--affinity") || !strcmp(flag, "--backend") || !strcmp(flag, "--pixel"))
        return set_choice(o, flag, v, err, errlen);
    return 1;
}
