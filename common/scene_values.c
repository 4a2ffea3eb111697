/* scene_values.c: reading a key's value (scene_impl.h): numbers (decimal only, finite,
 * in range), integers, names, booleans, vectors, the envelope list, the [animation] camera
 * and sun keys, file names and SHA-256 digests, each into its field of tf_scene. */
#include "scene_impl.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#define NUMBER_MAX_CHARS 64 /* longest accepted numeric token */

static int is_blank(const char *s)
{
    while (isspace((unsigned char)*s))
        s++;
    return *s == '\0';
}

/* Length of a decimal number at s (sign, digits, optional fraction, optional exponent), or 0.
 * Only this syntax is accepted: no hex floats, no "inf"/"nan", no locale surprises. */
static size_t scan_decimal(const char *s, int *is_integer)
{
    size_t i = 0, digits = 0;
    *is_integer = 1;
    if (s[i] == '+' || s[i] == '-')
        i++;
    while (isdigit((unsigned char)s[i]))
        i++, digits++;
    if (s[i] == '.') {
        *is_integer = 0;
        i++;
        while (isdigit((unsigned char)s[i]))
            i++, digits++;
    }
    if (digits == 0)
        return 0;
    if (s[i] == 'e' || s[i] == 'E') {
        size_t j = i + 1;
        if (s[j] == '+' || s[j] == '-')
            j++;
        if (isdigit((unsigned char)s[j])) {
            *is_integer = 0;
            while (isdigit((unsigned char)s[j]))
                j++;
            i = j;
        }
    }
    return i;
}

static int looks_like_nan_or_inf(const char *s)
{
    if (*s == '+' || *s == '-')
        s++;
    return strncasecmp(s, "nan", 3) == 0 || strncasecmp(s, "inf", 3) == 0;
}

/* Parse one finite double at *sp, advancing *sp past it.  Returns 0, or -1 after fail_at. */
static int take_double(struct parser *p, const char *key, const char **sp, double *out)
{
    const char *s = *sp;
    char q[64];
    int is_integer;
    size_t n = scan_decimal(s, &is_integer);
    if (n == 0) {
        size_t m = strcspn(s, " \t");
        scene_quote(q, sizeof q, s, m);
        if (looks_like_nan_or_inf(s))
            scene_fail_at(p, p->line, "%s: NaN and infinity are not allowed (got \"%s\")", key, q);
        else
            scene_fail_at(p, p->line, "%s: expected a number, got \"%s\"", key, q);
        return -1;
    }
    if (n > NUMBER_MAX_CHARS) {
        scene_fail_at(p, p->line, "%s: number too long (%zu characters, at most %d)", key, n,
                      NUMBER_MAX_CHARS);
        return -1;
    }
    char buf[NUMBER_MAX_CHARS + 1], *end;
    memcpy(buf, s, n);
    buf[n] = '\0';
    errno = 0;
    double v = strtod(buf, &end);
    if (end != buf + n) { /* only with a locale whose decimal point is not '.' */
        scene_quote(q, sizeof q, buf, n);
        scene_fail_at(p, p->line, "%s: cannot read \"%s\" as a number", key, q);
        return -1;
    }
    if (!isfinite(v)) {
        scene_quote(q, sizeof q, buf, n);
        scene_fail_at(p, p->line, "%s: \"%s\" is not a finite number", key, q);
        return -1;
    }
    if (v == 0)
        v = 0; /* -0 and 0 are the same scene: one canonical spelling */
    *out = v;
    *sp = s + n;
    return 0;
}

/* After the last number of a value only blanks may follow. */
static int expect_end(struct parser *p, const char *key, const char *s)
{
    if (is_blank(s))
        return 0;
    while (isspace((unsigned char)*s))
        s++;
    char q[64];
    scene_quote(q, sizeof q, s, strlen(s));
    scene_fail_at(p, p->line, "%s: trailing junk \"%s\" after the number", key, q);
    return -1;
}

static int check_range(struct parser *p, int key, double v)
{
    const struct key_def *k = &SCENE_KEYS[key];
    int low = k->min_exclusive ? !(v > k->min) : !(v >= k->min);
    if (!low && v <= k->max)
        return 0;
    scene_fail_at(p, p->line, "%s: %.17g is out of range %s%.17g..%.17g", k->name, v,
                  k->min_exclusive ? "above " : "", k->min, k->max);
    return -1;
}

/* Skip a separator between list elements: blanks with at most one comma.  Returns 1 if a
 * separator was there. */
static int skip_separator(const char **sp)
{
    const char *s = *sp;
    int commas = 0;
    while (isspace((unsigned char)*s) || (*s == ',' && commas == 0)) {
        if (*s == ',')
            commas++;
        s++;
    }
    int moved = s != *sp;
    *sp = s;
    return moved;
}

static int parse_int_value(struct parser *p, int key, const char *value, double *out)
{
    const char *name = SCENE_KEYS[key].name;
    char q[64];
    int is_integer;
    size_t n = scan_decimal(value, &is_integer);
    if (n == 0 || !is_integer) {
        scene_quote(q, sizeof q, value, strcspn(value, " \t"));
        scene_fail_at(p, p->line, "%s: expected an integer, got \"%s\"", name, q);
        return -1;
    }
    if (expect_end(p, name, value + n) < 0)
        return -1;
    errno = 0;
    long long v = strtoll(value, NULL, 10);
    const struct key_def *k = &SCENE_KEYS[key];
    if (errno == ERANGE || v < (long long)k->min || v > (long long)k->max) {
        scene_quote(q, sizeof q, value, n);
        scene_fail_at(p, p->line, "%s: %s is out of range %.0f..%.0f", name, q, k->min, k->max);
        return -1;
    }
    *out = (double)v;
    return 0;
}

static int parse_u64_value(struct parser *p, int key, const char *value, uint64_t *out)
{
    const char *name = SCENE_KEYS[key].name;
    char q[64];
    size_t n = strspn(value, "0123456789");
    if (n == 0 || n > 20) {
        scene_quote(q, sizeof q, value, strcspn(value, " \t"));
        scene_fail_at(p, p->line, "%s: expected an integer 0..18446744073709551615, got \"%s\"",
                      name, q);
        return -1;
    }
    if (expect_end(p, name, value + n) < 0)
        return -1;
    errno = 0;
    unsigned long long v = strtoull(value, NULL, 10);
    if (errno == ERANGE) {
        scene_quote(q, sizeof q, value, n);
        scene_fail_at(p, p->line, "%s: %s is out of range 0..18446744073709551615", name, q);
        return -1;
    }
    *out = (uint64_t)v;
    return 0;
}

/* Match value against a list of names; -1 after fail_at if none matches. */
static int parse_name_value(struct parser *p, int key, const char *value,
                            const char *const *names, int count)
{
    for (int i = 0; i < count; i++)
        if (strcasecmp(value, names[i]) == 0)
            return i;
    char q[64], expected[128] = "";
    scene_quote(q, sizeof q, value, strlen(value));
    for (int i = 0; i < count; i++) {
        strcat(expected, i ? "|" : "");
        strcat(expected, names[i]);
    }
    scene_fail_at(p, p->line, "%s: unknown value \"%s\" (expected %s)", SCENE_KEYS[key].name, q,
                  expected);
    return -1;
}

static int parse_bool_value(struct parser *p, int key, const char *value)
{
    static const char *const names[] = {"false", "true", "no", "yes", "off", "on", "0", "1"};
    int i = parse_name_value(p, key, value, names, 8);
    return i < 0 ? -1 : i % 2;
}

static int parse_vec3_value(struct parser *p, int key, const char *value, tf_vec3 *out)
{
    const char *name = SCENE_KEYS[key].name;
    double c[3];
    const char *s = value;
    for (int i = 0; i < 3; i++) {
        if (i > 0 && !skip_separator(&s)) {
            if (*s == '\0')
                scene_fail_at(p, p->line, "%s: expected 3 numbers \"x y z\", got %d", name, i);
            else
                expect_end(p, name, s);
            return -1;
        }
        if (*s == '\0') {
            scene_fail_at(p, p->line, "%s: expected 3 numbers \"x y z\", got %d", name, i);
            return -1;
        }
        if (take_double(p, name, &s, &c[i]) < 0 || check_range(p, key, c[i]) < 0)
            return -1;
    }
    if (!is_blank(s)) {
        const char *t = s;
        skip_separator(&t);
        int dummy;
        if (scan_decimal(t, &dummy) > 0)
            scene_fail_at(p, p->line, "%s: expected 3 numbers \"x y z\", got more", name);
        else
            expect_end(p, name, s);
        return -1;
    }
    *out = v3(c[0], c[1], c[2]);
    return 0;
}

/* Append the numbers of one line of the envelope list. */
static int add_envelope_numbers(struct parser *p, int key, const char *value)
{
    const int cap = TF_ENVELOPE_MAX * TF_ENVELOPE_MAX;
    const char *s = value;
    while (isspace((unsigned char)*s))
        s++;
    while (*s) {
        double v;
        if (p->envelope_count == cap) {
            scene_fail_at(p, p->line,
                          "envelope: more than %d numbers (at most %dx%d control points)",
                          cap, TF_ENVELOPE_MAX, TF_ENVELOPE_MAX);
            return -1;
        }
        if (take_double(p, "envelope", &s, &v) < 0 || check_range(p, key, v) < 0)
            return -1;
        p->s->terrain.envelope[p->envelope_count++] = v;
        if (!skip_separator(&s) && *s)
            return expect_end(p, "envelope", s);
    }
    return 0;
}

/* ---- [animation] keys: "camera = FRAME field values..." and "sun = FRAME field values..." */

struct key_field {
    const char *name;
    int ncomp;              /* 1 number or 3 (a vector) */
    double *dst;            /* ncomp doubles */
    unsigned char *given;   /* set once read; a field may appear once per key */
    double min, max;
    int min_exclusive;
};

/* Read "name numbers name numbers ..." up to the end of the value into the fields. */
static int read_key_fields(struct parser *p, const char *key, int frame, const char *s,
                           struct key_field *fields, int nfields)
{
    char q[64];
    for (;;) {
        while (isspace((unsigned char)*s) || *s == ',')
            s++;
        if (*s == '\0')
            return 0;
        size_t wl = strspn(s, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_");
        struct key_field *f = NULL;
        for (int i = 0; i < nfields && wl > 0; i++)
            if (strlen(fields[i].name) == wl && strncasecmp(fields[i].name, s, wl) == 0)
                f = &fields[i];
        if (!f) {
            char expected[128] = "";
            for (int i = 0; i < nfields; i++) {
                strcat(expected, i == 0 ? "" : i == nfields - 1 ? " or " : ", ");
                strcat(expected, fields[i].name);
            }
            scene_quote(q, sizeof q, s, wl ? wl : strcspn(s, " \t"));
            scene_fail_at(p, p->line, "%s: expected %s in the key at frame %d, got \"%s\"", key,
                          expected, frame, q);
            return -1;
        }
        if (*f->given) {
            scene_fail_at(p, p->line, "%s: %s given twice in the key at frame %d", key, f->name,
                          frame);
            return -1;
        }
        s += wl;
        for (int c = 0; c < f->ncomp; c++) {
            int sep = skip_separator(&s), is_int;
            if (!sep || scan_decimal(s, &is_int) == 0) {
                if (*s && sep && looks_like_nan_or_inf(s))
                    return take_double(p, key, &s, &f->dst[c]); /* its NaN message */
                scene_fail_at(p, p->line, "%s: %s needs %s in the key at frame %d", key, f->name,
                              f->ncomp == 1 ? "a number" : "3 numbers \"x y z\"", frame);
                return -1;
            }
            double v;
            if (take_double(p, key, &s, &v) < 0)
                return -1;
            int low = f->min_exclusive ? !(v > f->min) : !(v >= f->min);
            if (low || v > f->max) {
                scene_fail_at(p, p->line, "%s: %s %.17g is out of range %s%.17g..%.17g in the "
                              "key at frame %d", key, f->name, v,
                              f->min_exclusive ? "above " : "", f->min, f->max, frame);
                return -1;
            }
            f->dst[c] = v;
        }
        if (*s && !isspace((unsigned char)*s) && *s != ',') {
            scene_quote(q, sizeof q, s, strcspn(s, " \t"));
            scene_fail_at(p, p->line, "%s: trailing junk \"%s\" after %s", key, q, f->name);
            return -1;
        }
        *f->given = 1;
    }
}

/* The frame number that starts a key; advances *sp past it. */
static int read_key_frame(struct parser *p, const char *key, const char **sp, int *frame)
{
    const char *s = *sp;
    char q[64];
    while (isspace((unsigned char)*s))
        s++;
    int is_integer;
    size_t n = scan_decimal(s, &is_integer);
    if (n == 0 || !is_integer || *s == '+' || (s[n] && !isspace((unsigned char)s[n]))) {
        scene_quote(q, sizeof q, s, strcspn(s, " \t"));
        scene_fail_at(p, p->line, "%s: a key starts with its frame number (an integer), got "
                      "\"%s\"", key, q);
        return -1;
    }
    errno = 0;
    long long v = strtoll(s, NULL, 10);
    if (errno == ERANGE || v < 0 || v >= TF_ANIM_MAX_FRAMES) {
        scene_quote(q, sizeof q, s, n);
        scene_fail_at(p, p->line, "%s: frame %s is out of range 0..%d", key, q,
                      TF_ANIM_MAX_FRAMES - 1);
        return -1;
    }
    *frame = (int)v;
    *sp = s + n;
    return 0;
}

/* Start a new [animation] key `name` (one more of *count, at most TF_ANIM_MAX_KEYS): read its
 * frame number at *sp.  The new key's index, or -1 after scene_fail_at. */
static int start_key(struct parser *p, const char *name, int *count, const char **sp,
                     int *frame)
{
    if (*count == TF_ANIM_MAX_KEYS) {
        scene_fail_at(p, p->line, "%s: more than %d keys", name, TF_ANIM_MAX_KEYS);
        return -1;
    }
    if (read_key_frame(p, name, sp, frame) < 0)
        return -1;
    return (*count)++;
}

/* camera = FRAME position X Y Z look_at X Y Z [fov F] [up X Y Z]; an indented continuation
 * line adds fields to the last key. */
int scene_parse_camera_key(struct parser *p, const char *value, int continuation)
{
    tf_animation *a = &p->s->animation;
    const char *s = value;
    if (!continuation) {
        int frame, k = start_key(p, "camera", &a->ncamera, &s, &frame);
        if (k < 0)
            return -1;
        memset(&a->camera[k], 0, sizeof a->camera[k]);
        a->camera[k].frame = frame;
        a->camera[k].line = p->line;
        p->key_has_pos[k] = p->key_has_look[k] = p->key_has_fov[k] = p->key_has_up[k] = 0;
    }
    int k = a->ncamera - 1;
    tf_camera_key *key = &a->camera[k];
    struct key_field fields[] = {
        {"position", 3, &key->position.x, &p->key_has_pos[k], -BIG, BIG, 0},
        {"look_at", 3, &key->look_at.x, &p->key_has_look[k], -BIG, BIG, 0},
        {"fov", 1, &key->fov_deg, &p->key_has_fov[k], 0, 360, 1},
        {"up", 3, &key->up.x, &p->key_has_up[k], -BIG, BIG, 0},
    };
    _Static_assert(offsetof(tf_vec3, y) == sizeof(double) && offsetof(tf_vec3, z) ==
                   2 * sizeof(double), "a tf_vec3 is three consecutive doubles");
    return read_key_fields(p, "camera", key->frame, s, fields, 4);
}

/* sun = FRAME azimuth A elevation E */
int scene_parse_sun_key(struct parser *p, const char *value, int continuation)
{
    tf_animation *a = &p->s->animation;
    const char *s = value;
    if (!continuation) {
        int frame, k = start_key(p, "sun", &a->nsun, &s, &frame);
        if (k < 0)
            return -1;
        memset(&a->sun[k], 0, sizeof a->sun[k]);
        a->sun[k].frame = frame;
        a->sun[k].line = p->line;
        a->sun[k].azimuth_deg = NAN; /* "not given", checked in check_animation */
        a->sun[k].elevation_deg = NAN;
    }
    int k = a->nsun - 1;
    tf_sun_key *key = &a->sun[k];
    unsigned char has_az = !isnan(key->azimuth_deg), has_el = !isnan(key->elevation_deg);
    struct key_field fields[] = {
        {"azimuth", 1, &key->azimuth_deg, &has_az, -360, 360, 0},
        {"elevation", 1, &key->elevation_deg, &has_el, -90, 90, 0},
    };
    return read_key_fields(p, "sun", key->frame, s, fields, 2);
}

/* A file name: no control characters, shorter than the key's buffer.  (inih has already cut
 * a " ;" comment and the blanks at either end, so what is left survives the canonical form.) */
static int parse_path_value(struct parser *p, int key, const char *value, char *out)
{
    const struct key_def *k = &SCENE_KEYS[key];
    size_t n = strlen(value);
    if (n >= (size_t)k->max) {
        scene_fail_at(p, p->line, "%s: too long (%zu bytes, at most %d)", k->name, n,
                      (int)k->max - 1);
        return -1;
    }
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)value[i];
        if (c < 0x20 || c == 0x7f) {
            scene_fail_at(p, p->line, "%s: contains a control character", k->name);
            return -1;
        }
    }
    memcpy(out, value, n + 1);
    return 0;
}

static int parse_sha256_value(struct parser *p, int key, const char *value, char *out)
{
    char q[64];
    size_t n = strspn(value, "0123456789abcdefABCDEF");
    if (n != 64 || value[n] != '\0') {
        scene_quote(q, sizeof q, value, strlen(value));
        scene_fail_at(p, p->line, "%s: expected 64 hexadecimal digits, got \"%s\"",
                      SCENE_KEYS[key].name, q);
        return -1;
    }
    for (size_t i = 0; i < 64; i++)
        out[i] = (char)tolower((unsigned char)value[i]);
    out[64] = '\0';
    return 0;
}

/* A KT_INT value into *dst. */
static int set_int(struct parser *p, int key, const char *value, int *dst)
{
    double d;
    if (parse_int_value(p, key, value, &d) < 0)
        return -1;
    *dst = (int)d;
    return 0;
}

/* A KT_DOUBLE value, in its key's range, into *dst. */
static int set_double(struct parser *p, int key, const char *value, double *dst)
{
    const char *s = value;
    double d;
    if (take_double(p, SCENE_KEYS[key].name, &s, &d) < 0 ||
        expect_end(p, SCENE_KEYS[key].name, s) < 0 || check_range(p, key, d) < 0)
        return -1;
    *dst = d;
    return 0;
}

/* A KT_BOOL value into *dst (0 or 1). */
static int set_bool(struct parser *p, int key, const char *value, int *dst)
{
    int i = parse_bool_value(p, key, value);
    if (i < 0)
        return -1;
    *dst = i;
    return 0;
}

/* One of names[0..count) into the enum field at dst: its index. */
static int set_name(struct parser *p, int key, const char *value, const char *const *names,
                    int count, void *dst)
{
    int i = parse_name_value(p, key, value, names, count);
    if (i < 0)
        return -1;
    memcpy(dst, &i, sizeof i);
    return 0;
}

/* Store `value` for SCENE_KEYS[key] in the scene, or fail_at. */
int scene_set_value(struct parser *p, int key, const char *value)
{
    const struct key_def *k = &SCENE_KEYS[key];
    void *dst = scene_field(p->s, key);
    if (k->type != KT_ENVELOPE && *value == '\0') {
        scene_fail_at(p, p->line, "%s: missing value", k->name);
        return -1;
    }
    switch (k->type) {
    case KT_INT:
        return set_int(p, key, value, (int *)dst);
    case KT_U64:
        return parse_u64_value(p, key, value, (uint64_t *)dst);
    case KT_DOUBLE:
        return set_double(p, key, value, (double *)dst);
    case KT_VEC3:
        return parse_vec3_value(p, key, value, (tf_vec3 *)dst);
    case KT_BOOL:
        return set_bool(p, key, value, (int *)dst);
    case KT_GENERATOR:
        return set_name(p, key, value, SCENE_GENERATOR_NAMES, SCENE_GENERATOR_COUNT, dst);
    case KT_CAMERA:
        return set_name(p, key, value, SCENE_CAMERA_NAMES, SCENE_CAMERA_COUNT, dst);
    case KT_ENVELOPE:
        return add_envelope_numbers(p, key, value);
    case KT_CAMERA_KEY:
        return scene_parse_camera_key(p, value, 0);
    case KT_SUN_KEY:
        return scene_parse_sun_key(p, value, 0);
    case KT_PATH:
        return parse_path_value(p, key, value, (char *)dst);
    case KT_SHA256:
        return parse_sha256_value(p, key, value, (char *)dst);
    case KT_NODATA:
        return set_name(p, key, value, SCENE_NODATA_NAMES, SCENE_NODATA_COUNT, dst);
    case KT_FIRST_ROW:
        return set_name(p, key, value, SCENE_FIRST_ROW_NAMES, SCENE_FIRST_ROW_COUNT, dst);
    }
    return -1;
}
