/* animation.c: the splines of an [animation] section and the checks on its keys (see
 * animation.h for the parametrisation).  Everything here is plain double arithmetic on the
 * parsed keys, so every process computes the same camera for the same frame. */
#include "animation.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAXDIM 3
#define KNOT_FLOOR 1e-3 /* smallest centripetal knot step, relative to the largest */

/* A series of n >= 2 values of dimension dim at knots u[0..n-1] (strictly increasing). */
typedef struct series {
    int n, dim;
    double v[TF_ANIM_MAX_KEYS][MAXDIM];
    double u[TF_ANIM_MAX_KEYS];
} series;

/* Value k of the series extended by mirrored phantoms at k = -1 and k = n. */
static void value_at(const series *s, int k, double out[MAXDIM], double *knot)
{
    if (k >= 0 && k < s->n) {
        memcpy(out, s->v[k], sizeof(double) * MAXDIM);
        *knot = s->u[k];
        return;
    }
    int end = k < 0 ? 0 : s->n - 1, next = k < 0 ? 1 : s->n - 2;
    for (int d = 0; d < MAXDIM; d++)
        out[d] = 2 * s->v[end][d] - s->v[next][d];
    *knot = 2 * s->u[end] - s->u[next];
}

/* The segment [u[i], u[i+1]] holding x, clamped to the series. */
static int segment_of(const double *u, int n, double x)
{
    int i = 0;
    while (i < n - 2 && x >= u[i + 1])
        i++;
    return i;
}

static void lerp_into(double out[MAXDIM], const double a[MAXDIM], const double b[MAXDIM],
                      double ta, double tb, double t)
{
    double wa = (tb - t) / (tb - ta), wb = (t - ta) / (tb - ta);
    for (int d = 0; d < MAXDIM; d++)
        out[d] = wa * a[d] + wb * b[d];
}

/* Catmull-Rom by the Barry-Goldman pyramid at parameter x (held at the ends). */
static void catmull_rom(const series *s, double x, double out[MAXDIM])
{
    if (x <= s->u[0]) {
        memcpy(out, s->v[0], sizeof(double) * MAXDIM);
        return;
    }
    if (x >= s->u[s->n - 1]) {
        memcpy(out, s->v[s->n - 1], sizeof(double) * MAXDIM);
        return;
    }
    int i = segment_of(s->u, s->n, x);
    double p[4][MAXDIM], t[4];
    for (int j = 0; j < 4; j++)
        value_at(s, i - 1 + j, p[j], &t[j]);
    if (!memcmp(p[0], p[1], sizeof p[0]) && !memcmp(p[1], p[2], sizeof p[0]) &&
        !memcmp(p[2], p[3], sizeof p[0])) {
        memcpy(out, p[1], sizeof(double) * MAXDIM); /* a constant stays exactly constant */
        return;
    }
    double a1[MAXDIM], a2[MAXDIM], a3[MAXDIM], b1[MAXDIM], b2[MAXDIM];
    lerp_into(a1, p[0], p[1], t[0], t[1], x);
    lerp_into(a2, p[1], p[2], t[1], t[2], x);
    lerp_into(a3, p[2], p[3], t[2], t[3], x);
    lerp_into(b1, a1, a2, t[0], t[2], x);
    lerp_into(b2, a2, a3, t[1], t[3], x);
    lerp_into(out, b1, b2, t[1], t[2], x);
}

/* Centripetal knots for the series' values (u[0] = 0). */
static void centripetal_knots(series *s)
{
    double step[TF_ANIM_MAX_KEYS], largest = 0;
    for (int k = 0; k + 1 < s->n; k++) {
        double d2 = 0;
        for (int d = 0; d < s->dim; d++) {
            double e = s->v[k + 1][d] - s->v[k][d];
            d2 += e * e;
        }
        step[k] = sqrt(sqrt(d2)); /* |dP|^alpha, alpha = 1/2 */
        if (step[k] > largest)
            largest = step[k];
    }
    double least = largest > 0 ? KNOT_FLOOR * largest : 1.0;
    s->u[0] = 0;
    for (int k = 0; k + 1 < s->n; k++)
        s->u[k + 1] = s->u[k] + (step[k] > least ? step[k] : least);
}

/* The monotone C1 cubic u(f) through (frame[k], knot[k]): Hermite segments with
 * Fritsch-Butland slopes (one-sided secants at the ends). */
static double frame_to_knot(const double *frame, const double *knot, int n, double f)
{
    if (f <= frame[0])
        return knot[0];
    if (f >= frame[n - 1])
        return knot[n - 1];
    int i = segment_of(frame, n, f);
    double slope[2];
    for (int j = 0; j < 2; j++) {
        int k = i + j;
        double h1 = k > 0 ? frame[k] - frame[k - 1] : 0, h2 = k < n - 1 ? frame[k + 1] - frame[k] : 0;
        double d1 = k > 0 ? (knot[k] - knot[k - 1]) / h1 : 0;
        double d2 = k < n - 1 ? (knot[k + 1] - knot[k]) / h2 : 0;
        if (k == 0)
            slope[j] = d2;
        else if (k == n - 1)
            slope[j] = d1;
        else if (d1 <= 0 || d2 <= 0)
            slope[j] = 0;
        else
            slope[j] = 3 * (h1 + h2) / ((2 * h2 + h1) / d1 + (h2 + 2 * h1) / d2);
    }
    double h = frame[i + 1] - frame[i], t = (f - frame[i]) / h;
    double t2 = t * t, t3 = t2 * t;
    return (2 * t3 - 3 * t2 + 1) * knot[i] + (t3 - 2 * t2 + t) * h * slope[0] +
           (-2 * t3 + 3 * t2) * knot[i + 1] + (t3 - t2) * h * slope[1];
}

/* Evaluate a centripetal path (position or look_at) at frame f. */
static tf_vec3 path_at(const tf_animation *a, int which_look_at, double f)
{
    series s;
    double frame[TF_ANIM_MAX_KEYS];
    s.n = a->ncamera;
    s.dim = 3;
    for (int k = 0; k < s.n; k++) {
        tf_vec3 p = which_look_at ? a->camera[k].look_at : a->camera[k].position;
        s.v[k][0] = p.x, s.v[k][1] = p.y, s.v[k][2] = p.z;
        frame[k] = a->camera[k].frame;
    }
    centripetal_knots(&s);
    double out[MAXDIM];
    catmull_rom(&s, frame_to_knot(frame, s.u, s.n, f), out);
    return v3(out[0], out[1], out[2]);
}

void tf_animation_camera_at(const tf_animation *a, double f, tf_vec3 *position,
                            tf_vec3 *look_at, tf_vec3 *up, double *fov_deg)
{
    *position = path_at(a, 0, f);
    *look_at = path_at(a, 1, f);
    series s;
    s.n = a->ncamera;
    s.dim = 3;
    for (int k = 0; k < s.n; k++) {
        s.v[k][0] = a->camera[k].up.x, s.v[k][1] = a->camera[k].up.y;
        s.v[k][2] = a->camera[k].up.z;
        s.u[k] = a->camera[k].frame;
    }
    double out[MAXDIM];
    catmull_rom(&s, f, out);
    *up = v3(out[0], out[1], out[2]);
    for (int k = 0; k < s.n; k++) {
        s.v[k][0] = a->camera[k].fov_deg;
        s.v[k][1] = s.v[k][2] = 0;
    }
    catmull_rom(&s, f, out);
    *fov_deg = out[0];
}

void tf_animation_sun_at(const tf_animation *a, double f, double *azimuth_deg,
                         double *elevation_deg)
{
    series s;
    s.n = a->nsun;
    s.dim = 2;
    for (int k = 0; k < s.n; k++) {
        s.v[k][0] = a->sun[k].azimuth_deg;
        s.v[k][1] = a->sun[k].elevation_deg;
        s.v[k][2] = 0;
        s.u[k] = a->sun[k].frame;
    }
    double out[MAXDIM];
    catmull_rom(&s, f, out);
    *azimuth_deg = out[0];
    *elevation_deg = out[1];
}

/* ---- checks ----------------------------------------------------------------------------- */

/* Order and coverage of one kind of key; frames[k] and lines[k] of n keys. */
static int check_keys(const char *name, const int *frames, const int *lines, int n, int nframes,
                      int *line, char *what, size_t len)
{
    if (n == 0)
        return 0;
    if (n == 1) {
        *line = lines[0];
        snprintf(what, len, "%s: only one key; a path needs at least 2 keys (or none, to keep "
                 "the fixed [%s] values)", name, name);
        return -1;
    }
    for (int k = 1; k < n; k++)
        if (frames[k] <= frames[k - 1]) {
            *line = lines[k];
            snprintf(what, len, "%s: key at frame %d is not after the previous key's frame %d "
                     "(line %d): keys must be in increasing frame order",
                     name, frames[k], frames[k - 1], lines[k - 1]);
            return -1;
        }
    if (frames[0] != 0) {
        *line = lines[0];
        snprintf(what, len, "%s: the first key is at frame %d; it must be at frame 0", name,
                 frames[0]);
        return -1;
    }
    if (frames[n - 1] < nframes - 1) {
        *line = lines[n - 1];
        snprintf(what, len, "%s: the last key is at frame %d, before the last frame %d "
                 "(frames = %d)", name, frames[n - 1], nframes - 1, nframes);
        return -1;
    }
    return 0;
}

/* The key line to blame for frame f: the key that starts f's segment. */
int tf_animation_camera_line(const tf_animation *a, int f)
{
    int k = 0;
    while (k + 1 < a->ncamera && a->camera[k + 1].frame <= f)
        k++;
    return a->camera[k].line;
}

int tf_animation_check(const tf_animation *a, int pinhole, int *line, char *what, size_t len)
{
    int frames[TF_ANIM_MAX_KEYS], lines[TF_ANIM_MAX_KEYS];
    for (int k = 0; k < a->ncamera; k++)
        frames[k] = a->camera[k].frame, lines[k] = a->camera[k].line;
    if (check_keys("camera", frames, lines, a->ncamera, a->frames, line, what, len))
        return -1;
    for (int k = 0; k < a->nsun; k++)
        frames[k] = a->sun[k].frame, lines[k] = a->sun[k].line;
    if (check_keys("sun", frames, lines, a->nsun, a->frames, line, what, len))
        return -1;
    for (int f = 0; a->ncamera >= 2 && f < a->frames; f++) {
        tf_vec3 pos, look, up;
        double fov;
        tf_animation_camera_at(a, f, &pos, &look, &up, &fov);
        tf_vec3 dir = v3_sub(look, pos);
        double dlen = v3_len(dir), ulen = v3_len(up);
        *line = tf_animation_camera_line(a, f);
        if (!(dlen > 0)) {
            snprintf(what, len, "camera: at frame %d look_at meets position (the path of "
                     "look_at crosses the camera's)", f);
            return -1;
        }
        if (!(ulen > 0) || !(v3_len(v3_cross(dir, up)) > 1e-9 * dlen * ulen)) {
            snprintf(what, len, "camera: at frame %d up is zero or parallel to the view "
                     "direction", f);
            return -1;
        }
        if (!(fov > 0) || !(fov < (pinhole ? 180 : 360 + 1e-9))) {
            snprintf(what, len, "camera: at frame %d the interpolated fov %.6g is out of range "
                     "(above 0, %s)", f, fov, pinhole ? "below 180 for a pinhole" : "up to 360");
            return -1;
        }
    }
    for (int f = 0; a->nsun >= 2 && f < a->frames; f++) {
        double az, el;
        tf_animation_sun_at(a, f, &az, &el);
        if (!(el >= -90 && el <= 90)) {
            int k = 0;
            while (k + 1 < a->nsun && a->sun[k + 1].frame <= f)
                k++;
            *line = a->sun[k].line;
            snprintf(what, len, "sun: at frame %d the interpolated elevation %.6g is outside "
                     "-90..90", f, el);
            return -1;
        }
    }
    return 0;
}
