/* paint_watch.c: watch a `terrafarm paint` as a page does -- long-poll its display messages,
 * draw them (coordinator/paint/paint_raster.c, the page's own rule) -- and keep the picture
 * every INTERVAL ms until the view is painted; then print, for each kept picture, its time
 * from the view's start and its PSNR against the painted picture (which is the render's:
 * tests/e2e/paint_browser.sh), and the times to reach 20, 25, 30 and 35 dB.  For
 * bench/paint_progress.sh; the view must not change while it watches.
 *
 *   paint_watch HOST:PORT [INTERVAL_MS] [--resume] [--then-move]
 * With --resume (a paint started --paused) it resumes the paint itself and times everything
 * from then, so its own start-up is not counted.  With --then-move, once painted it posts a new
 * view (the sun turned 10 degrees) as the page does and times the first pixels of the new view
 * and its complete coarse picture ("move_first_ms=... move_coarse_ms=...").
 * Output: "t_s=T psnr_db=P exact=F" lines, then "coarse_s=... painted_s=... t20_s=... t25_s=...
 * t30_s=... t35_s=..." (-1: not reached before painted). */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "coordinator/paint/paint_raster.h"
#include "http_client.h"
#include "log.h"

typedef struct shot {
    double t;
    double exact;
    uint8_t *rgb;
} shot;

static json_t *status(const char *addr)
{
    char err[512];
    json_t *s = tf_http_json(addr, "GET", "/api/paint/status", NULL, NULL, tf_now_ms() + 10000,
                             NULL, err, sizeof err);
    if (!s)
        tf_die(1, "%s", err);
    return s;
}

static double num(json_t *o, const char *k) { return json_number_value(json_object_get(o, k)); }

/* More of the view's messages, drawn: the new end. */
static int64_t pull(const char *addr, int64_t gen, int64_t from, uint8_t *rgb, int w, int h)
{
    char path[128], err[512];
    snprintf(path, sizeof path, "/api/paint/updates?gen=%" PRId64 "&from=%" PRId64 "&wait=20",
             gen, from);
    tf_http_answer a;
    if (tf_http_request(addr, "GET", path, NULL, NULL, NULL, 0, tf_now_ms() + 30000,
                        (size_t)1 << 30, &a, err, sizeof err))
        tf_die(1, "%s", err);
    if (a.code != 200 || tf_paint_raster_apply(rgb, w, h, (uint8_t *)a.body, a.len))
        tf_die(1, "%s: updates answered %d with messages that do not draw", addr, a.code);
    from += (int64_t)a.len;
    free(a.body);
    return from;
}

/* Post a view with the sun turned and time, on the page's terms, its first pixels and its
 * complete coarse picture. */
static void move_and_time(const char *addr, int64_t gen, int64_t end)
{
    char err[512];
    json_t *s = status(addr);
    json_t *view = json_deep_copy(json_object_get(s, "view"));
    json_t *sun = json_object_get(view, "sun");
    json_object_set_new(sun, "azimuth", json_real(fmod(num(sun, "azimuth") + 10, 360)));
    json_decref(s);
    double t0 = tf_now_s(), first = -1, coarse = -1;
    json_t *a = tf_http_json(addr, "POST", "/api/paint/view", "watch", view, tf_now_ms() + 10000,
                             NULL, err, sizeof err);
    json_decref(view);
    if (!a)
        tf_die(1, "%s", err);
    json_decref(a);
    while (coarse < 0) {
        char path[128];
        snprintf(path, sizeof path, "/api/paint/updates?gen=%" PRId64 "&from=%" PRId64 "&wait=5",
                 gen, end);
        tf_http_answer ans;
        if (tf_http_request(addr, "GET", path, NULL, NULL, NULL, 0, tf_now_ms() + 30000,
                            (size_t)1 << 30, &ans, err, sizeof err))
            tf_die(1, "%s", err);
        if (ans.len > 0 && first < 0) /* the old view is painted: these are the new one's */
            first = tf_now_s() - t0;
        free(ans.body);
        s = status(addr);
        int64_t now_gen = (int64_t)num(s, "gen");
        if (first >= 0 && now_gen > gen && num(json_object_get(s, "counts"), "roots_left") == 0)
            coarse = tf_now_s() - t0;
        json_decref(s);
    }
    printf("move_first_ms=%.1f move_coarse_ms=%.1f\n", first * 1000, coarse * 1000);
}

int main(int argc, char **argv)
{
    if (argc < 2)
        tf_die(2, "usage: paint_watch HOST:PORT [INTERVAL_MS]");
    const char *addr = argv[1];
    double interval = argc > 2 ? atof(argv[2]) / 1000.0 : 0.1;
    json_t *s = status(addr);
    int w = (int)num(s, "width"), h = (int)num(s, "height");
    int64_t gen = (int64_t)num(s, "gen"), end = 0;
    double t0 = tf_now_s() - num(s, "view_age_s"); /* the view's start, on our clock */
    json_decref(s);
    int resume = 0, move = 0;
    for (int k = 3; k < argc; k++) {
        resume |= !strcmp(argv[k], "--resume");
        move |= !strcmp(argv[k], "--then-move");
    }
    if (resume) {
        char err[512];
        json_t *a = tf_http_json(addr, "POST", "/api/paint/resume", "watch", NULL,
                                 tf_now_ms() + 10000, NULL, err, sizeof err);
        if (!a)
            tf_die(1, "%s", err);
        json_decref(a);
        t0 = tf_now_s();
    }
    size_t bytes = (size_t)w * (size_t)h * 3, nshots = 0, cap = 16;
    uint8_t *rgb = calloc(bytes, 1);
    shot *shots = malloc(cap * sizeof *shots);
    double next = 0, coarse = -1, painted = -1;
    while (painted < 0) {
        end = pull(addr, gen, end, rgb, w, h);
        s = status(addr);
        json_t *c = json_object_get(s, "counts");
        double exact = num(c, "exact_pixels") / num(c, "pixels");
        if (num(s, "painted_s") >= 0 && (int64_t)num(s, "log_bytes") == end)
            painted = tf_now_s() - t0;
        double t = tf_now_s() - t0;
        if (coarse < 0 && num(json_object_get(s, "counts"), "roots_left") == 0)
            coarse = t; /* drawn: this pull came after the last root's result */
        json_decref(s);
        if (t >= next || painted >= 0) {
            if (nshots == cap)
                shots = realloc(shots, (cap *= 2) * sizeof *shots);
            shots[nshots++] = (shot){t, exact, memcpy(malloc(bytes), rgb, bytes)};
            next = t + interval;
        }
    }
    double reach[4] = {-1, -1, -1, -1};
    for (size_t k = 0; k < nshots; k++) {
        double p = tf_paint_psnr(shots[k].rgb, rgb, bytes);
        printf("t_s=%.3f psnr_db=%.2f exact=%.3f\n", shots[k].t, isinf(p) ? 99.0 : p,
               shots[k].exact);
        for (int q = 0; q < 4; q++)
            if (reach[q] < 0 && p >= 20 + 5 * q)
                reach[q] = shots[k].t;
        free(shots[k].rgb);
    }
    if (move)
        move_and_time(addr, gen, end);
    printf("coarse_s=%.3f painted_s=%.3f t20_s=%.3f t25_s=%.3f t30_s=%.3f t35_s=%.3f\n", coarse,
           painted, reach[0], reach[1], reach[2], reach[3]);
    free(shots);
    free(rgb);
    return 0;
}
