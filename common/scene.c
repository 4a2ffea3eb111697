/* scene.c: the scene file parser, validator and canonical hash (see scene.h and the format
 * reference in scenes/README.md).
 *
 * How it works.  The whole text is held in memory (tf_scene_load reads the file, bounded, and
 * calls tf_scene_parse_text, so a networked worker that receives the text gets the very same
 * struct and hash).  inih does the INI syntax through ini_parse_stream() with our own reader,
 * which hands inih one physical line per call.  Because of that the reader always knows the
 * current line number and its raw text, which inih (Debian's build has no
 * INI_HANDLER_LINENO) would not tell the handler.  The reader also rejects what inih would
 * silently mangle: NUL bytes, lines longer than inih's buffer (inih would split them and parse
 * the tail as a new line), and section headers (inih does not call the handler for a section,
 * so an empty unknown section would go unnoticed).
 *
 * Every key is described once in the table KEYS below: its section, name, type, where it lives
 * in tf_scene, its range and its default.  Defaults, parsing, range checks and the canonical
 * form are all driven by that table, so a field cannot be parsed but forgotten in the hash.
 *
 * Invariants:
 *   - The first error wins and stops parsing: once `failed` is set the reader returns EOF.
 *     inih reports its own syntax errors only through its return value (the first bad line),
 *     and keeps parsing after one, so at the end the earlier of inih's and ours is reported.
 *   - Every message is one line "NAME:LINE: key: what is wrong"; bytes quoted from the input
 *     are cut short and non-printable ones replaced, so a message never spans lines.
 *   - The canonical form is itself a valid scene: parse(canonical(s)) has the same canonical
 *     form (the unit tests and the fuzz harness check this). */
#include "scene.h"

#include <ctype.h>
#include <errno.h>
#include <inttypes.h>
#include <ini.h>
#include <math.h>
#include <sodium.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include "log.h"

#define SCENE_MAX_BYTES (1024 * 1024) /* bound on a scene file / text */
#define NUMBER_MAX_CHARS 64           /* longest accepted numeric token */
#define QUOTE_MAX_CHARS 40            /* input quoted in messages is cut to this */
#define ENVELOPE_PER_LINE 6           /* canonical form: envelope numbers per line */

_Static_assert(sizeof(enum tf_generator) == sizeof(int), "enums are stored as int");
_Static_assert(sizeof(enum tf_camera_kind) == sizeof(int), "enums are stored as int");

/* ---------------------------------------------------------------------------------------- */
/* The format: sections and keys                                                            */

enum section { SEC_IMAGE, SEC_CAMERA, SEC_SUN, SEC_SKY, SEC_TERRAIN, SEC_MATERIALS, SEC_MIST,
               SEC_ANTIALIAS, SEC_ANIMATION, SEC_COUNT };
static const char *const SECTION_NAMES[SEC_COUNT] = {
    "image", "camera", "sun", "sky", "terrain", "materials", "mist", "antialias", "animation"};

enum key_type {
    KT_INT,       /* int, decimal */
    KT_U64,       /* uint64_t, decimal */
    KT_DOUBLE,    /* finite double */
    KT_VEC3,      /* three finite doubles, "x y z" or "x, y, z" */
    KT_BOOL,      /* int 0/1 from true|false|yes|no|on|off|1|0 */
    KT_GENERATOR, /* enum tf_generator by name */
    KT_CAMERA,    /* enum tf_camera_kind by name */
    KT_ENVELOPE,  /* list of up to TF_ENVELOPE_MAX^2 doubles, may continue on indented lines */
    KT_CAMERA_KEY,/* [animation] camera = FRAME position X Y Z look_at X Y Z [fov F] [up X Y Z];
                   * repeated, one key each; may continue on indented lines */
    KT_SUN_KEY,   /* [animation] sun = FRAME azimuth A elevation E; repeated */
    KT_PATH,      /* char[max] file name without control characters */
    KT_SHA256,    /* char[65]: 64 hex digits, stored in lower case */
    KT_NODATA,    /* enum tf_nodata by name */
    KT_FIRST_ROW, /* enum tf_first_row by name */
};
/* Keys that may be given more than once (each adds to a list) and continue on indented lines. */
static int is_list_type(int type)
{
    return type == KT_ENVELOPE || type == KT_CAMERA_KEY || type == KT_SUN_KEY;
}

struct key_def {
    enum section section;
    const char *name;   /* as written in the canonical form; matched case-insensitively */
    enum key_type type;
    size_t offset;      /* of the field in tf_scene */
    double min, max;    /* inclusive range (each component of a vector, each envelope number) */
    int min_exclusive;  /* 1: the value must be strictly greater than min */
    int required;
    double def[3];      /* default (def[0] for scalars) */
};

#define F(field) offsetof(tf_scene, field)
#define BIG 1e9 /* bound on world coordinates and lengths: far beyond any sensible scene */

static const struct key_def KEYS[] = {
    {SEC_IMAGE, "width", KT_INT, F(width), 1, 65536, 0, 1, {0}},
    {SEC_IMAGE, "height", KT_INT, F(height), 1, 65536, 0, 1, {0}},

    {SEC_CAMERA, "type", KT_CAMERA, F(camera.kind), 0, 0, 0, 0, {TF_CAMERA_PINHOLE}},
    {SEC_CAMERA, "position", KT_VEC3, F(camera.position), -BIG, BIG, 0, 1, {0}},
    {SEC_CAMERA, "look_at", KT_VEC3, F(camera.look_at), -BIG, BIG, 0, 1, {0}},
    {SEC_CAMERA, "up", KT_VEC3, F(camera.up), -BIG, BIG, 0, 0, {0, 0, 1}},
    {SEC_CAMERA, "fov", KT_DOUBLE, F(camera.fov_deg), 0, 360, 1, 0, {60}},
    {SEC_CAMERA, "vfov", KT_DOUBLE, F(camera.vfov_deg), 0, 179, 0, 0, {0}},

    {SEC_SUN, "azimuth", KT_DOUBLE, F(sun.azimuth_deg), -360, 360, 0, 0, {135}},
    {SEC_SUN, "elevation", KT_DOUBLE, F(sun.elevation_deg), -90, 90, 0, 0, {25}},
    {SEC_SUN, "color", KT_VEC3, F(sun.color), 0, 1000, 0, 0, {1.0, 0.95, 0.85}},
    {SEC_SUN, "intensity", KT_DOUBLE, F(sun.intensity), 0, 1000, 0, 0, {1.0}},

    {SEC_SKY, "zenith", KT_VEC3, F(sky.zenith), 0, 1000, 0, 0, {0.25, 0.45, 0.85}},
    {SEC_SKY, "horizon", KT_VEC3, F(sky.horizon), 0, 1000, 0, 0, {0.75, 0.85, 0.95}},
    {SEC_SKY, "intensity", KT_DOUBLE, F(sky.intensity), 0, 1000, 0, 0, {0.3}},

    {SEC_TERRAIN, "generator", KT_GENERATOR, F(terrain.generator), 0, 0, 0, 1, {0}},
    {SEC_TERRAIN, "seed", KT_U64, F(terrain.seed), 0, 0, 0, 1, {0}},
    {SEC_TERRAIN, "size_exp", KT_INT, F(terrain.size_exp), 1, 13, 0, 0, {9}},
    /* extent: above 0; generator = file also takes 0 (the default there): from the raster */
    {SEC_TERRAIN, "extent", KT_DOUBLE, F(terrain.extent), 0, BIG, 0, 0, {1000}},
    {SEC_TERRAIN, "height_scale", KT_DOUBLE, F(terrain.height_scale), 0, BIG, 0, 0, {200}},
    {SEC_TERRAIN, "feature_size", KT_DOUBLE, F(terrain.feature_size), 0, BIG, 1, 0, {400}},
    {SEC_TERRAIN, "octaves", KT_DOUBLE, F(terrain.octaves), 1, 30, 0, 0, {8}},
    {SEC_TERRAIN, "H", KT_DOUBLE, F(terrain.H), 0, 2, 0, 0, {0.8}},
    {SEC_TERRAIN, "lacunarity", KT_DOUBLE, F(terrain.lacunarity), 1.1, 8, 0, 0, {2.0}},
    {SEC_TERRAIN, "offset", KT_DOUBLE, F(terrain.offset), -10, 10, 0, 0, {0.7}},
    {SEC_TERRAIN, "gain", KT_DOUBLE, F(terrain.gain), 0, 10, 0, 0, {2.0}},
    {SEC_TERRAIN, "roughness", KT_DOUBLE, F(terrain.roughness), 0, 2, 0, 0, {0.8}},
    {SEC_TERRAIN, "envelope_n", KT_INT, F(terrain.envelope_n), 0, TF_ENVELOPE_MAX, 0, 0, {0}},
    {SEC_TERRAIN, "envelope", KT_ENVELOPE, F(terrain.envelope), -1000, 1000, 0, 0, {0}},
    {SEC_TERRAIN, "envelope_tolerance", KT_DOUBLE, F(terrain.envelope_tolerance), 0, 1000, 0, 0,
     {0.1}},
    {SEC_TERRAIN, "faults", KT_INT, F(terrain.faults), 0, 100000, 0, 0, {400}},
    {SEC_TERRAIN, "fault_step", KT_DOUBLE, F(terrain.fault_step), 0, 10, 0, 0, {0.05}},
    {SEC_TERRAIN, "wind_passes", KT_INT, F(terrain.wind_passes), 0, 1000, 0, 0, {1}},
    {SEC_TERRAIN, "rain_passes", KT_INT, F(terrain.rain_passes), 0, 1000, 0, 0, {1}},
    {SEC_TERRAIN, "erosion_k", KT_DOUBLE, F(terrain.erosion_k), 0, 1, 0, 0, {0.5}},
    {SEC_TERRAIN, "sub_M", KT_DOUBLE, F(terrain.sub_M), 0, 1000, 0, 0, {1.0}},
    {SEC_TERRAIN, "sub_E", KT_DOUBLE, F(terrain.sub_E), 1, 10, 1, 0, {2.0}},
    {SEC_TERRAIN, "sub_W", KT_DOUBLE, F(terrain.sub_W), -1000, 1000, 0, 0, {0.3}},
    {SEC_TERRAIN, "thermal_iterations", KT_INT, F(terrain.thermal_iterations), 0, 10000, 0, 0,
     {0}},
    {SEC_TERRAIN, "talus", KT_DOUBLE, F(terrain.talus_deg), 0, 90, 0, 0, {35}},
    {SEC_TERRAIN, "path", KT_PATH, F(terrain.file_path), 0, TF_SCENE_PATH_MAX, 0, 0, {0}},
    {SEC_TERRAIN, "sha256", KT_SHA256, F(terrain.file_sha256), 0, 0, 0, 0, {0}},
    {SEC_TERRAIN, "vertical_scale", KT_DOUBLE, F(terrain.vertical_scale), -BIG, BIG, 0, 0, {1}},
    {SEC_TERRAIN, "vertical_offset", KT_DOUBLE, F(terrain.vertical_offset), -BIG, BIG, 0, 0,
     {0}},
    {SEC_TERRAIN, "nodata", KT_NODATA, F(terrain.nodata), 0, 0, 0, 0, {TF_NODATA_FILL}},
    {SEC_TERRAIN, "first_row", KT_FIRST_ROW, F(terrain.first_row), 0, 0, 0, 0,
     {TF_FIRST_ROW_AUTO}},
    {SEC_TERRAIN, "crop_x", KT_INT, F(terrain.crop_x), 0, 1 << 20, 0, 0, {0}},
    {SEC_TERRAIN, "crop_y", KT_INT, F(terrain.crop_y), 0, 1 << 20, 0, 0, {0}},
    {SEC_TERRAIN, "crop_width", KT_INT, F(terrain.crop_width), 0, 1 << 20, 0, 0, {0}},
    {SEC_TERRAIN, "crop_height", KT_INT, F(terrain.crop_height), 0, 1 << 20, 0, 0, {0}},

    {SEC_MATERIALS, "sea_level", KT_DOUBLE, F(materials.sea_level), -BIG, BIG, 0, 0, {0}},
    {SEC_MATERIALS, "tree_line", KT_DOUBLE, F(materials.tree_line), -BIG, BIG, 0, 0, {80}},
    {SEC_MATERIALS, "snow_line", KT_DOUBLE, F(materials.snow_line), -BIG, BIG, 0, 0, {160}},
    {SEC_MATERIALS, "snow_jitter", KT_DOUBLE, F(materials.snow_jitter), 0, BIG, 0, 0, {20}},
    {SEC_MATERIALS, "rock_slope", KT_DOUBLE, F(materials.rock_slope_deg), 0, 90, 0, 0, {40}},
    {SEC_MATERIALS, "bump", KT_DOUBLE, F(materials.bump), 0, 10, 0, 0, {0.5}},

    {SEC_MIST, "enabled", KT_BOOL, F(mist.enabled), 0, 1, 0, 0, {0}},
    {SEC_MIST, "homogeneous", KT_BOOL, F(mist.homogeneous), 0, 1, 0, 0, {0}},
    {SEC_MIST, "density", KT_DOUBLE, F(mist.density), 0, 1000, 0, 0, {0.0005}},
    {SEC_MIST, "falloff", KT_DOUBLE, F(mist.falloff), 0, BIG, 1, 0, {100}},
    {SEC_MIST, "color", KT_VEC3, F(mist.color), 0, 1000, 0, 0, {0.75, 0.8, 0.9}},
    {SEC_MIST, "extinction", KT_VEC3, F(mist.extinction), 0, 1000, 0, 0, {0.6, 0.8, 1.0}},

    {SEC_ANTIALIAS, "threshold", KT_DOUBLE, F(antialias.threshold), 0, 1000, 0, 0, {0.028}},
    {SEC_ANTIALIAS, "max_depth", KT_INT, F(antialias.max_depth), 0, 6, 0, 0, {3}},

    /* frames is required once the section is there (check_animation) */
    {SEC_ANIMATION, "frames", KT_INT, F(animation.frames), 1, TF_ANIM_MAX_FRAMES, 0, 0, {0}},
    {SEC_ANIMATION, "fps", KT_DOUBLE, F(animation.fps), 0, 1000, 1, 0, {24}},
    {SEC_ANIMATION, "camera", KT_CAMERA_KEY, F(animation), -BIG, BIG, 0, 0, {0}},
    {SEC_ANIMATION, "sun", KT_SUN_KEY, F(animation), -360, 360, 0, 0, {0}},
};
#define KEY_COUNT ((int)(sizeof KEYS / sizeof KEYS[0]))

static const char *const GENERATOR_NAMES[] = {"fbm", "hetero", "hybrid", "ridged",
                                              "midpoint", "fault", "subdivide", "file"};
#define GENERATOR_COUNT ((int)(sizeof GENERATOR_NAMES / sizeof GENERATOR_NAMES[0]))
static const char *const CAMERA_NAMES[] = {"pinhole", "panorama"};
#define CAMERA_COUNT 2
static const char *const NODATA_NAMES[] = {"fill", "sea"};
#define NODATA_COUNT 2
static const char *const FIRST_ROW_NAMES[] = {"auto", "north", "south"};
#define FIRST_ROW_COUNT 3

const char *tf_generator_name(enum tf_generator g)
{
    if ((int)g < 0 || (int)g >= GENERATOR_COUNT)
        return "unknown";
    return GENERATOR_NAMES[g];
}

static int find_key(enum section sec, const char *name)
{
    for (int i = 0; i < KEY_COUNT; i++)
        if (KEYS[i].section == sec && strcasecmp(KEYS[i].name, name) == 0)
            return i;
    return -1;
}

static int key_index_by_name(enum section sec, const char *name)
{
    int i = find_key(sec, name);
    if (i < 0)
        abort(); /* a name in this file that is not in KEYS: a programming error */
    return i;
}

static void *field(tf_scene *s, int key) { return (char *)s + KEYS[key].offset; }
static const void *cfield(const tf_scene *s, int key) { return (const char *)s + KEYS[key].offset; }

/* ---------------------------------------------------------------------------------------- */
/* Parser state and error reporting                                                         */

struct parser {
    const char *name;     /* for messages */
    const char *text;     /* the whole text, len bytes (NUL-terminated copy in s->text) */
    size_t len, pos;      /* pos: start of the next line to hand to inih */
    int line;             /* number of the line last handed to inih (1-based) */
    const char *cur;      /* raw text of that line, without its newline */
    size_t cur_len;
    int section;          /* current section, -1 before the first header */
    int last_key;         /* last key set in the current section (for continuations), or -1 */
    int section_line[SEC_COUNT]; /* line of each section's header, 0 = absent */
    int key_line[KEY_COUNT];     /* line where each key was set, 0 = not set */
    int envelope_count;          /* numbers read into terrain.envelope so far */
    /* fields given in each [animation] camera key (the others default to [camera]'s) */
    unsigned char key_has_fov[TF_ANIM_MAX_KEYS], key_has_up[TF_ANIM_MAX_KEYS];
    unsigned char key_has_pos[TF_ANIM_MAX_KEYS], key_has_look[TF_ANIM_MAX_KEYS];
    tf_scene *s;
    int failed;
    int err_line;
    char *err;
    size_t errlen;
};

/* Copy at most QUOTE_MAX_CHARS of `src` (n bytes) into out, replacing anything non-printable,
 * so quoted input can never break the one-line message. */
static void quote(char *out, size_t outlen, const char *src, size_t n)
{
    size_t k = 0;
    for (size_t i = 0; i < n && k + 4 < outlen; i++) {
        if (i == QUOTE_MAX_CHARS) {
            memcpy(out + k, "...", 3);
            k += 3;
            break;
        }
        unsigned char c = (unsigned char)src[i];
        out[k++] = (c >= 0x20 && c < 0x7f) ? (char)c : '?';
    }
    out[k] = '\0';
}

/* Record the first error: "NAME:LINE: what" (what starts with the key). */
static void fail_at(struct parser *p, int line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static void fail_at(struct parser *p, int line, const char *fmt, ...)
{
    if (p->failed)
        return;
    p->failed = 1;
    p->err_line = line;
    if (!p->err || p->errlen == 0)
        return;
    char what[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(what, sizeof what, fmt, ap);
    va_end(ap);
    snprintf(p->err, p->errlen, "%s:%d: %s", p->name, line, what);
}

/* ---------------------------------------------------------------------------------------- */
/* Values                                                                                   */

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
        quote(q, sizeof q, s, m);
        if (looks_like_nan_or_inf(s))
            fail_at(p, p->line, "%s: NaN and infinity are not allowed (got \"%s\")", key, q);
        else
            fail_at(p, p->line, "%s: expected a number, got \"%s\"", key, q);
        return -1;
    }
    if (n > NUMBER_MAX_CHARS) {
        fail_at(p, p->line, "%s: number too long (%zu characters, at most %d)", key, n,
                NUMBER_MAX_CHARS);
        return -1;
    }
    char buf[NUMBER_MAX_CHARS + 1], *end;
    memcpy(buf, s, n);
    buf[n] = '\0';
    errno = 0;
    double v = strtod(buf, &end);
    if (end != buf + n) { /* only with a locale whose decimal point is not '.' */
        quote(q, sizeof q, buf, n);
        fail_at(p, p->line, "%s: cannot read \"%s\" as a number", key, q);
        return -1;
    }
    if (!isfinite(v)) {
        quote(q, sizeof q, buf, n);
        fail_at(p, p->line, "%s: \"%s\" is not a finite number", key, q);
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
    quote(q, sizeof q, s, strlen(s));
    fail_at(p, p->line, "%s: trailing junk \"%s\" after the number", key, q);
    return -1;
}

static int check_range(struct parser *p, int key, double v)
{
    const struct key_def *k = &KEYS[key];
    int low = k->min_exclusive ? !(v > k->min) : !(v >= k->min);
    if (!low && v <= k->max)
        return 0;
    fail_at(p, p->line, "%s: %.17g is out of range %s%.17g..%.17g", k->name, v,
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
    const char *name = KEYS[key].name;
    char q[64];
    int is_integer;
    size_t n = scan_decimal(value, &is_integer);
    if (n == 0 || !is_integer) {
        quote(q, sizeof q, value, strcspn(value, " \t"));
        fail_at(p, p->line, "%s: expected an integer, got \"%s\"", name, q);
        return -1;
    }
    if (expect_end(p, name, value + n) < 0)
        return -1;
    errno = 0;
    long long v = strtoll(value, NULL, 10);
    if (errno == ERANGE || v < (long long)KEYS[key].min || v > (long long)KEYS[key].max) {
        quote(q, sizeof q, value, n);
        fail_at(p, p->line, "%s: %s is out of range %.0f..%.0f", name, q, KEYS[key].min,
                KEYS[key].max);
        return -1;
    }
    *out = (double)v;
    return 0;
}

static int parse_u64_value(struct parser *p, int key, const char *value, uint64_t *out)
{
    const char *name = KEYS[key].name;
    char q[64];
    size_t n = strspn(value, "0123456789");
    if (n == 0 || n > 20) {
        quote(q, sizeof q, value, strcspn(value, " \t"));
        fail_at(p, p->line, "%s: expected an integer 0..18446744073709551615, got \"%s\"", name, q);
        return -1;
    }
    if (expect_end(p, name, value + n) < 0)
        return -1;
    errno = 0;
    unsigned long long v = strtoull(value, NULL, 10);
    if (errno == ERANGE) {
        quote(q, sizeof q, value, n);
        fail_at(p, p->line, "%s: %s is out of range 0..18446744073709551615", name, q);
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
    quote(q, sizeof q, value, strlen(value));
    for (int i = 0; i < count; i++) {
        strcat(expected, i ? "|" : "");
        strcat(expected, names[i]);
    }
    fail_at(p, p->line, "%s: unknown value \"%s\" (expected %s)", KEYS[key].name, q, expected);
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
    const char *name = KEYS[key].name;
    double c[3];
    const char *s = value;
    for (int i = 0; i < 3; i++) {
        if (i > 0 && !skip_separator(&s)) {
            if (*s == '\0')
                fail_at(p, p->line, "%s: expected 3 numbers \"x y z\", got %d", name, i);
            else
                expect_end(p, name, s);
            return -1;
        }
        if (*s == '\0') {
            fail_at(p, p->line, "%s: expected 3 numbers \"x y z\", got %d", name, i);
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
            fail_at(p, p->line, "%s: expected 3 numbers \"x y z\", got more", name);
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
            fail_at(p, p->line, "envelope: more than %d numbers (at most %dx%d control points)",
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
            quote(q, sizeof q, s, wl ? wl : strcspn(s, " \t"));
            fail_at(p, p->line, "%s: expected %s in the key at frame %d, got \"%s\"", key,
                    expected, frame, q);
            return -1;
        }
        if (*f->given) {
            fail_at(p, p->line, "%s: %s given twice in the key at frame %d", key, f->name, frame);
            return -1;
        }
        s += wl;
        for (int c = 0; c < f->ncomp; c++) {
            int sep = skip_separator(&s), is_int;
            if (!sep || scan_decimal(s, &is_int) == 0) {
                if (*s && sep && looks_like_nan_or_inf(s))
                    return take_double(p, key, &s, &f->dst[c]); /* its NaN message */
                fail_at(p, p->line, "%s: %s needs %s in the key at frame %d", key, f->name,
                        f->ncomp == 1 ? "a number" : "3 numbers \"x y z\"", frame);
                return -1;
            }
            double v;
            if (take_double(p, key, &s, &v) < 0)
                return -1;
            int low = f->min_exclusive ? !(v > f->min) : !(v >= f->min);
            if (low || v > f->max) {
                fail_at(p, p->line, "%s: %s %.17g is out of range %s%.17g..%.17g in the key at "
                        "frame %d", key, f->name, v, f->min_exclusive ? "above " : "", f->min,
                        f->max, frame);
                return -1;
            }
            f->dst[c] = v;
        }
        if (*s && !isspace((unsigned char)*s) && *s != ',') {
            quote(q, sizeof q, s, strcspn(s, " \t"));
            fail_at(p, p->line, "%s: trailing junk \"%s\" after %s", key, q, f->name);
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
        quote(q, sizeof q, s, strcspn(s, " \t"));
        fail_at(p, p->line, "%s: a key starts with its frame number (an integer), got \"%s\"", key,
                q);
        return -1;
    }
    errno = 0;
    long long v = strtoll(s, NULL, 10);
    if (errno == ERANGE || v < 0 || v >= TF_ANIM_MAX_FRAMES) {
        quote(q, sizeof q, s, n);
        fail_at(p, p->line, "%s: frame %s is out of range 0..%d", key, q, TF_ANIM_MAX_FRAMES - 1);
        return -1;
    }
    *frame = (int)v;
    *sp = s + n;
    return 0;
}

/* camera = FRAME position X Y Z look_at X Y Z [fov F] [up X Y Z]; an indented continuation
 * line adds fields to the last key. */
static int parse_camera_key(struct parser *p, const char *value, int continuation)
{
    tf_animation *a = &p->s->animation;
    const char *s = value;
    if (!continuation) {
        int frame;
        if (a->ncamera == TF_ANIM_MAX_KEYS) {
            fail_at(p, p->line, "camera: more than %d keys", TF_ANIM_MAX_KEYS);
            return -1;
        }
        if (read_key_frame(p, "camera", &s, &frame) < 0)
            return -1;
        int k = a->ncamera++;
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
static int parse_sun_key(struct parser *p, const char *value, int continuation)
{
    tf_animation *a = &p->s->animation;
    const char *s = value;
    if (!continuation) {
        int frame;
        if (a->nsun == TF_ANIM_MAX_KEYS) {
            fail_at(p, p->line, "sun: more than %d keys", TF_ANIM_MAX_KEYS);
            return -1;
        }
        if (read_key_frame(p, "sun", &s, &frame) < 0)
            return -1;
        int k = a->nsun++;
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
    const struct key_def *k = &KEYS[key];
    size_t n = strlen(value);
    if (n >= (size_t)k->max) {
        fail_at(p, p->line, "%s: too long (%zu bytes, at most %d)", k->name, n, (int)k->max - 1);
        return -1;
    }
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)value[i];
        if (c < 0x20 || c == 0x7f) {
            fail_at(p, p->line, "%s: contains a control character", k->name);
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
        quote(q, sizeof q, value, strlen(value));
        fail_at(p, p->line, "%s: expected 64 hexadecimal digits, got \"%s\"", KEYS[key].name, q);
        return -1;
    }
    for (size_t i = 0; i < 64; i++)
        out[i] = (char)tolower((unsigned char)value[i]);
    out[64] = '\0';
    return 0;
}

/* Store `value` for KEYS[key] in the scene, or fail_at. */
static int set_value(struct parser *p, int key, const char *value)
{
    const struct key_def *k = &KEYS[key];
    void *dst = field(p->s, key);
    double d;
    int i;
    if (k->type != KT_ENVELOPE && *value == '\0') {
        fail_at(p, p->line, "%s: missing value", k->name);
        return -1;
    }
    switch (k->type) {
    case KT_INT:
        if (parse_int_value(p, key, value, &d) < 0)
            return -1;
        *(int *)dst = (int)d;
        return 0;
    case KT_U64:
        return parse_u64_value(p, key, value, (uint64_t *)dst);
    case KT_DOUBLE: {
        const char *s = value;
        if (take_double(p, k->name, &s, &d) < 0 || expect_end(p, k->name, s) < 0 ||
            check_range(p, key, d) < 0)
            return -1;
        *(double *)dst = d;
        return 0;
    }
    case KT_VEC3:
        return parse_vec3_value(p, key, value, (tf_vec3 *)dst);
    case KT_BOOL:
        if ((i = parse_bool_value(p, key, value)) < 0)
            return -1;
        *(int *)dst = i;
        return 0;
    case KT_GENERATOR:
        if ((i = parse_name_value(p, key, value, GENERATOR_NAMES, GENERATOR_COUNT)) < 0)
            return -1;
        memcpy(dst, &i, sizeof i);
        return 0;
    case KT_CAMERA:
        if ((i = parse_name_value(p, key, value, CAMERA_NAMES, CAMERA_COUNT)) < 0)
            return -1;
        memcpy(dst, &i, sizeof i);
        return 0;
    case KT_ENVELOPE:
        return add_envelope_numbers(p, key, value);
    case KT_CAMERA_KEY:
        return parse_camera_key(p, value, 0);
    case KT_SUN_KEY:
        return parse_sun_key(p, value, 0);
    case KT_PATH:
        return parse_path_value(p, key, value, (char *)dst);
    case KT_SHA256:
        return parse_sha256_value(p, key, value, (char *)dst);
    case KT_NODATA:
        if ((i = parse_name_value(p, key, value, NODATA_NAMES, NODATA_COUNT)) < 0)
            return -1;
        memcpy(dst, &i, sizeof i);
        return 0;
    case KT_FIRST_ROW:
        if ((i = parse_name_value(p, key, value, FIRST_ROW_NAMES, FIRST_ROW_COUNT)) < 0)
            return -1;
        memcpy(dst, &i, sizeof i);
        return 0;
    }
    return -1;
}

static void set_defaults(tf_scene *s)
{
    for (int key = 0; key < KEY_COUNT; key++) {
        const struct key_def *k = &KEYS[key];
        void *dst = field(s, key);
        int i = (int)k->def[0];
        switch (k->type) {
        case KT_INT:
        case KT_BOOL:
            *(int *)dst = i;
            break;
        case KT_U64:
            *(uint64_t *)dst = (uint64_t)k->def[0];
            break;
        case KT_DOUBLE:
            *(double *)dst = k->def[0];
            break;
        case KT_VEC3:
            *(tf_vec3 *)dst = v3(k->def[0], k->def[1], k->def[2]);
            break;
        case KT_GENERATOR:
        case KT_CAMERA:
        case KT_NODATA:
        case KT_FIRST_ROW:
            memcpy(dst, &i, sizeof i);
            break;
        case KT_ENVELOPE:
        case KT_CAMERA_KEY:
        case KT_SUN_KEY:
            break; /* calloc'd: all zero, no keys */
        case KT_PATH:
        case KT_SHA256:
            break; /* calloc'd: all zero, the empty string */
        }
    }
}

/* ---------------------------------------------------------------------------------------- */
/* inih callbacks                                                                           */

/* The raw line without a UTF-8 BOM (inih skips one at the start of line 1). */
static const char *line_start(const struct parser *p, size_t *len)
{
    const char *l = p->cur;
    *len = p->cur_len;
    if (p->line == 1 && *len >= 3 && memcmp(l, "\xEF\xBB\xBF", 3) == 0) {
        l += 3;
        *len -= 3;
    }
    return l;
}

/* Section headers are handled here, not in the handler: inih does not call the handler for a
 * header, and an empty unknown section must still be an error.  inih takes a line as a header
 * exactly when its first character is '[' (indented, it could be a continuation line). */
static void check_section_header(struct parser *p)
{
    size_t n;
    const char *l = line_start(p, &n);
    size_t i = 0;
    while (i < n && isspace((unsigned char)l[i]))
        i++;
    if (i == n || l[i] != '[')
        return;
    char q[64];
    if (i > 0) {
        fail_at(p, p->line, "syntax: a section header must start at the beginning of the line");
        return;
    }
    const char *close = memchr(l, ']', n);
    if (!close) {
        fail_at(p, p->line, "syntax: section header without a closing ']'");
        return;
    }
    size_t rest = (size_t)(l + n - (close + 1));
    const char *r = close + 1;
    while (rest > 0 && isspace((unsigned char)*r))
        r++, rest--;
    if (rest > 0 && *r != ';' && *r != '#') {
        quote(q, sizeof q, r, rest);
        fail_at(p, p->line, "syntax: unexpected \"%s\" after the section header", q);
        return;
    }
    size_t name_len = (size_t)(close - (l + 1));
    for (int sec = 0; sec < SEC_COUNT; sec++) {
        if (strlen(SECTION_NAMES[sec]) == name_len &&
            strncasecmp(SECTION_NAMES[sec], l + 1, name_len) == 0) {
            if (p->section_line[sec]) {
                fail_at(p, p->line, "[%s]: duplicate section (first on line %d)",
                        SECTION_NAMES[sec], p->section_line[sec]);
                return;
            }
            p->section = sec;
            p->section_line[sec] = p->line;
            p->last_key = -1;
            return;
        }
    }
    quote(q, sizeof q, l + 1, name_len);
    fail_at(p, p->line,
            "[%s]: unknown section (expected image, camera, sun, sky, terrain, materials, mist, "
            "antialias or animation)", q);
}

/* fgets-style reader: hands inih one physical line, checked. */
static char *read_line(char *buf, int num, void *stream)
{
    struct parser *p = stream;
    if (p->failed || p->pos >= p->len || num < 3)
        return NULL;
    const char *start = p->text + p->pos;
    size_t avail = p->len - p->pos;
    const char *nl = memchr(start, '\n', avail);
    size_t n = nl ? (size_t)(nl - start) : avail;
    p->line++;
    p->cur = start;
    p->cur_len = n;
    p->pos += nl ? n + 1 : n;
    if (memchr(start, '\0', n)) {
        fail_at(p, p->line, "line: contains a NUL byte");
        return NULL;
    }
    /* inih needs room for the newline and the terminating NUL; a longer line it would split
     * and parse the tail as another line. */
    size_t max = (size_t)num - 2;
    if (n > max) {
        fail_at(p, p->line, "line: too long (%zu characters, at most %zu)", n, max);
        return NULL;
    }
    check_section_header(p);
    if (p->failed)
        return NULL;
    memcpy(buf, start, n);
    buf[n] = '\n';
    buf[n + 1] = '\0';
    return buf;
}

/* inih strips inline comments (" ;") from key lines but not from continuation lines. */
static int continue_list(struct parser *p, const char *value)
{
    char buf[512];
    size_t n = strlen(value);
    if (n >= sizeof buf) /* cannot happen: value is part of a line inih accepted */
        n = sizeof buf - 1;
    memcpy(buf, value, n);
    buf[n] = '\0';
    for (size_t i = 1; i < n; i++)
        if (buf[i] == ';' && isspace((unsigned char)buf[i - 1])) {
            buf[i] = '\0';
            break;
        }
    switch (KEYS[p->last_key].type) {
    case KT_CAMERA_KEY:
        return parse_camera_key(p, buf, 1) == 0;
    case KT_SUN_KEY:
        return parse_sun_key(p, buf, 1) == 0;
    default:
        return set_value(p, p->last_key, buf) == 0;
    }
}

static int on_key(void *user, const char *section, const char *name, const char *value)
{
    struct parser *p = user;
    (void)section; /* our own p->section, set by the reader, is the same section */
    if (p->failed)
        return 1;
    size_t n;
    const char *l = line_start(p, &n);
    char q[64];
    if (n > 0 && isspace((unsigned char)l[0])) {
        /* inih passes an indented line as a continuation of the previous key's value */
        if (p->last_key >= 0 && is_list_type(KEYS[p->last_key].type))
            return continue_list(p, value);
        if (p->last_key >= 0)
            fail_at(p, p->line, "%s: indented line would continue its value (only envelope and "
                    "[animation] keys may span lines; remove the indentation)",
                    KEYS[p->last_key].name);
        else
            fail_at(p, p->line, "syntax: indented line (remove the indentation)");
        return 0;
    }
    if (*name == '\0') {
        fail_at(p, p->line, "syntax: missing key name before '='");
        return 0;
    }
    quote(q, sizeof q, name, strlen(name));
    if (p->section < 0) {
        fail_at(p, p->line, "%s: key outside of any section (start with a header like [image])",
                q);
        return 0;
    }
    int key = find_key((enum section)p->section, name);
    if (key < 0) {
        fail_at(p, p->line, "%s: unknown key in [%s]", q, SECTION_NAMES[p->section]);
        return 0;
    }
    if (p->key_line[key] && KEYS[key].type != KT_CAMERA_KEY && KEYS[key].type != KT_SUN_KEY) {
        fail_at(p, p->line, "%s: duplicate key (first set on line %d)", KEYS[key].name,
                p->key_line[key]);
        return 0;
    }
    p->key_line[key] = p->line;
    p->last_key = key;
    return set_value(p, key, value) == 0;
}

/* ---------------------------------------------------------------------------------------- */
/* Checks once the whole text is read                                                       */

/* Line to blame for a key: where it was set, else its section header, else 0. */
static int blame_line(const struct parser *p, int key)
{
    return p->key_line[key] ? p->key_line[key] : p->section_line[KEYS[key].section];
}

/* Keys that an animated camera or sun replaces: not required, and not allowed, when animated. */
static int replaced_by_animation(const tf_scene *s, int key)
{
    const struct key_def *k = &KEYS[key];
    if (k->section == SEC_CAMERA && s->animation.ncamera > 0)
        return !strcmp(k->name, "position") || !strcmp(k->name, "look_at");
    if (k->section == SEC_SUN && s->animation.nsun > 0)
        return !strcmp(k->name, "azimuth") || !strcmp(k->name, "elevation");
    return 0;
}

static void check_required(struct parser *p)
{
    for (int key = 0; key < KEY_COUNT && !p->failed; key++) {
        const struct key_def *k = &KEYS[key];
        if (replaced_by_animation(p->s, key)) {
            if (p->key_line[key])
                fail_at(p, p->key_line[key], "%s: the %s is animated by [animation] %s keys; "
                        "give %s in those keys instead", k->name, SECTION_NAMES[k->section],
                        SECTION_NAMES[k->section], k->name);
            continue;
        }
        if (!k->required || p->key_line[key])
            continue;
        if (p->section_line[k->section])
            fail_at(p, p->section_line[k->section], "%s: missing required key in [%s]", k->name,
                    SECTION_NAMES[k->section]);
        else
            fail_at(p, 0, "%s: missing required key (no [%s] section)", k->name,
                    SECTION_NAMES[k->section]);
    }
}

/* envelope_n and the envelope list must agree; envelope_n may be left out and is then the
 * side of the square list. */
static void check_envelope(struct parser *p)
{
    int kn = key_index_by_name(SEC_TERRAIN, "envelope_n");
    int kl = key_index_by_name(SEC_TERRAIN, "envelope");
    tf_terrain *t = &p->s->terrain;
    int count = p->envelope_count;
    if (t->envelope_n == 1) {
        fail_at(p, blame_line(p, kn), "envelope_n: must be 0 (no envelope) or 2..%d",
                TF_ENVELOPE_MAX);
        return;
    }
    if (!p->key_line[kl]) {
        if (t->envelope_n > 0)
            fail_at(p, blame_line(p, kn), "envelope: missing (envelope_n = %d needs %d numbers)",
                    t->envelope_n, t->envelope_n * t->envelope_n);
        return;
    }
    if (!p->key_line[kn]) {
        int side = 2;
        while (side < TF_ENVELOPE_MAX && side * side < count)
            side++;
        if (side * side != count) {
            fail_at(p, p->key_line[kl], "envelope: %d numbers is not a square grid of 2x2..%dx%d "
                    "control points", count, TF_ENVELOPE_MAX, TF_ENVELOPE_MAX);
            return;
        }
        t->envelope_n = side;
        return;
    }
    if (count != t->envelope_n * t->envelope_n)
        fail_at(p, p->key_line[kl], "envelope: expected %d numbers (envelope_n = %d), got %d",
                t->envelope_n * t->envelope_n, t->envelope_n, count);
}

static void check_camera(struct parser *p)
{
    const tf_scene *s = p->s;
    int kpos = key_index_by_name(SEC_CAMERA, "position");
    int kup = key_index_by_name(SEC_CAMERA, "up");
    int kfov = key_index_by_name(SEC_CAMERA, "fov");
    tf_vec3 dir = v3_sub(s->camera.look_at, s->camera.position);
    double dlen = v3_len(dir), ulen = v3_len(s->camera.up);
    if (!(dlen > 0)) {
        fail_at(p, blame_line(p, kpos), "look_at: must differ from position");
        return;
    }
    if (!(ulen > 0) || !(v3_len(v3_cross(dir, s->camera.up)) > 1e-9 * dlen * ulen)) {
        fail_at(p, blame_line(p, kup), "up: must be non-zero and not parallel to the view "
                "direction (look_at - position)");
        return;
    }
    if (s->camera.kind == TF_CAMERA_PINHOLE && !(s->camera.fov_deg < 180))
        fail_at(p, blame_line(p, kfov), "fov: %.17g is out of range for a pinhole camera "
                "(above 0, below 180)", s->camera.fov_deg);
}

/* [animation]: frames given, every key complete (fov and up default to [camera]'s), the keys
 * in order and every frame's camera and sun well defined (animation.c); then the [camera] and
 * [sun] fields take frame 0's values. */
static void check_animation(struct parser *p)
{
    tf_scene *s = p->s;
    tf_animation *a = &s->animation;
    int kframes = key_index_by_name(SEC_ANIMATION, "frames");
    if (!p->section_line[SEC_ANIMATION])
        return;
    if (!p->key_line[kframes]) {
        fail_at(p, p->section_line[SEC_ANIMATION], "frames: missing required key in [animation]");
        return;
    }
    for (int k = 0; k < a->ncamera; k++) {
        tf_camera_key *key = &a->camera[k];
        if (!p->key_has_pos[k] || !p->key_has_look[k]) {
            fail_at(p, key->line, "camera: the key at frame %d needs %s", key->frame,
                    !p->key_has_pos[k] ? "a position" : "a look_at");
            return;
        }
        if (!p->key_has_fov[k])
            key->fov_deg = s->camera.fov_deg;
        if (!p->key_has_up[k])
            key->up = s->camera.up;
    }
    for (int k = 0; k < a->nsun; k++)
        if (isnan(a->sun[k].azimuth_deg) || isnan(a->sun[k].elevation_deg)) {
            fail_at(p, a->sun[k].line, "sun: the key at frame %d needs %s", a->sun[k].frame,
                    isnan(a->sun[k].azimuth_deg) ? "an azimuth" : "an elevation");
            return;
        }
    int line = 0;
    char what[400];
    if (tf_animation_check(a, s->camera.kind == TF_CAMERA_PINHOLE, &line, what, sizeof what)) {
        fail_at(p, line, "%s", what);
        return;
    }
    tf_scene_apply_frame(s, 0);
}

/* generator = file needs a path, and its extent defaults to 0 (from the raster); every other
 * generator needs an extent above 0. */
static void check_terrain_file(struct parser *p)
{
    tf_terrain *t = &p->s->terrain;
    int kext = key_index_by_name(SEC_TERRAIN, "extent");
    int kgen = key_index_by_name(SEC_TERRAIN, "generator");
    if (t->generator == TF_GEN_FILE) {
        if (!t->file_path[0])
            fail_at(p, blame_line(p, kgen), "path: missing (generator = file needs the height "
                    "map's file name)");
        else if (!p->key_line[kext])
            t->extent = 0;
        return;
    }
    if (!(t->extent > 0))
        fail_at(p, blame_line(p, kext), "extent: %.17g is out of range above 0..%.17g (0, from "
                "the raster, is only for generator = file)", t->extent, BIG);
}

static void check_semantics(struct parser *p)
{
    check_required(p);
    if (!p->failed)
        check_envelope(p);
    if (!p->failed)
        check_terrain_file(p);
    if (!p->failed)
        check_animation(p);
    if (!p->failed)
        check_camera(p);
}

/* inih found a syntax error on line `line`: say what is wrong with it. */
static void report_syntax_error(struct parser *p, int line)
{
    const char *l = p->text, *end = p->text + p->len;
    for (int i = 1; i < line && l < end; i++) {
        const char *nl = memchr(l, '\n', (size_t)(end - l));
        l = nl ? nl + 1 : end;
    }
    const char *nl = memchr(l, '\n', (size_t)(end - l));
    size_t n = nl ? (size_t)(nl - l) : (size_t)(end - l);
    while (n > 0 && isspace((unsigned char)*l))
        l++, n--;
    char q[64];
    quote(q, sizeof q, l, n);
    p->failed = 0; /* inih's error is earlier than ours: it replaces ours */
    fail_at(p, line, "syntax: expected \"key = value\", \"[section]\" or a comment, got \"%s\"", q);
}

/* ---------------------------------------------------------------------------------------- */
/* Public API                                                                               */

void tf_scene_free(tf_scene *s)
{
    if (!s)
        return;
    free(s->path);
    free(s->text);
    free(s->heightmap);
    free(s->heightmap_name);
    free(s);
}

static tf_scene *scene_new(const char *name, const char *text, size_t len)
{
    tf_scene *s = calloc(1, sizeof *s);
    if (!s)
        return NULL;
    s->path = strdup(name);
    s->text = malloc(len + 1);
    if (!s->path || !s->text) {
        tf_scene_free(s);
        return NULL;
    }
    memcpy(s->text, text, len);
    s->text[len] = '\0';
    s->text_len = len;
    set_defaults(s);
    return s;
}

tf_scene *tf_scene_parse_text(const char *name, const char *text, size_t len, char *err,
                              size_t errlen)
{
    if (!name)
        name = "<string>";
    if (len > SCENE_MAX_BYTES) {
        tf_seterr(err, errlen, "%s: too large (%zu bytes, at most %d)", name, len, SCENE_MAX_BYTES);
        return NULL;
    }
    if (!text) { /* no text at all: an empty scene (which then lacks its required keys) */
        text = "";
        len = 0;
    }
    tf_scene *s = scene_new(name, text, len);
    if (!s) {
        tf_seterr(err, errlen, "%s: out of memory", name);
        return NULL;
    }
    struct parser p = {.name = name, .text = s->text, .len = len, .section = -1,
                       .last_key = -1, .s = s, .err = err, .errlen = errlen};
    int rc = ini_parse_stream(read_line, &p, on_key, &p);
    if (rc > 0 && (!p.failed || rc < p.err_line))
        report_syntax_error(&p, rc);
    else if (rc < 0 && !p.failed)
        fail_at(&p, p.line, "line: cannot parse (out of memory)");
    if (!p.failed)
        check_semantics(&p);
    if (p.failed) {
        tf_scene_free(s);
        return NULL;
    }
    tf_scene_rehash(s);
    return s;
}

static void sha256_hex(const uint8_t *data, size_t len, char out[65])
{
    static const char hex[] = "0123456789abcdef";
    uint8_t h[32];
    crypto_hash_sha256(h, data, len);
    for (int i = 0; i < 32; i++) {
        out[2 * i] = hex[h[i] >> 4];
        out[2 * i + 1] = hex[h[i] & 15];
    }
    out[64] = '\0';
}

int tf_scene_attach_heightmap(tf_scene *s, uint8_t *bytes, size_t len, const char *name,
                              char *err, size_t errlen)
{
    char hex[65];
    if (sodium_init() < 0)
        (void)0; /* as in tf_scene_rehash: hashing needs no entropy */
    sha256_hex(bytes, len, hex);
    tf_terrain *t = &s->terrain;
    if (t->file_sha256[0] && strcmp(t->file_sha256, hex)) {
        free(bytes);
        return tf_seterr(err, errlen, "%s: height map %s has SHA-256 %.16s..., but the scene "
                         "pins sha256 = %.16s...", s->path, name, hex, t->file_sha256);
    }
    char *copy = strdup(name);
    if (!copy) {
        free(bytes);
        return tf_seterr(err, errlen, "%s: out of memory", s->path);
    }
    free(s->heightmap);
    free(s->heightmap_name);
    s->heightmap = bytes;
    s->heightmap_len = len;
    s->heightmap_name = copy;
    memcpy(t->file_sha256, hex, sizeof hex);
    t->file_bytes = bytes;
    t->file_len = len;
    t->file_name = copy;
    t->file_sea_level = s->materials.sea_level;
    tf_scene_rehash(s);
    return 0;
}

/* The height map's path: absolute as written, else relative to the scene file's folder.
 * malloc'd, or NULL on out of memory. */
static char *resolve_heightmap_path(const char *scene_path, const char *file_path)
{
    const char *slash = strrchr(scene_path, '/');
    if (file_path[0] == '/' || !slash)
        return strdup(file_path);
    size_t dir = (size_t)(slash - scene_path) + 1, n = strlen(file_path);
    char *out = malloc(dir + n + 1);
    if (out) {
        memcpy(out, scene_path, dir);
        memcpy(out + dir, file_path, n + 1);
    }
    return out;
}

/* Read the whole height map file (at most TF_HEIGHTMAP_MAX_BYTES) and attach it. */
static int load_heightmap(tf_scene *s, char *err, size_t errlen)
{
    char *path = resolve_heightmap_path(s->path, s->terrain.file_path);
    if (!path)
        return tf_seterr(err, errlen, "%s: out of memory", s->path);
    int rc = -1;
    uint8_t *buf = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) {
        tf_seterr(err, errlen, "%s: height map %s: cannot open: %s", s->path, path,
                  strerror(errno));
        goto out;
    }
    size_t cap = 1 << 20, len = 0;
    buf = malloc(cap);
    while (buf) {
        if (len == cap) {
            if (cap > TF_HEIGHTMAP_MAX_BYTES) /* read one byte past the bound: too large */
                break;
            size_t grown = cap * 2 > TF_HEIGHTMAP_MAX_BYTES ? TF_HEIGHTMAP_MAX_BYTES + 1 : cap * 2;
            uint8_t *b = realloc(buf, grown);
            if (!b) {
                free(buf);
                buf = NULL;
                break;
            }
            buf = b;
            cap = grown;
        }
        size_t got = fread(buf + len, 1, cap - len, f);
        len += got;
        if (got == 0)
            break;
    }
    if (!buf) {
        tf_seterr(err, errlen, "%s: height map %s: out of memory", s->path, path);
        goto out;
    }
    if (ferror(f)) {
        tf_seterr(err, errlen, "%s: height map %s: cannot read: %s", s->path, path,
                  strerror(errno));
        goto out;
    }
    if (len > TF_HEIGHTMAP_MAX_BYTES) {
        tf_seterr(err, errlen, "%s: height map %s: too large (more than %zu MiB)", s->path, path,
                  TF_HEIGHTMAP_MAX_BYTES >> 20);
        goto out;
    }
    if (len == 0) {
        tf_seterr(err, errlen, "%s: height map %s: empty file", s->path, path);
        goto out;
    }
    rc = tf_scene_attach_heightmap(s, buf, len, path, err, errlen);
    buf = NULL; /* owned by the scene, or freed */
out:
    if (f)
        fclose(f);
    free(buf);
    free(path);
    return rc;
}

tf_scene *tf_scene_load(const char *path, char *err, size_t errlen)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        tf_seterr(err, errlen, "%s: cannot open: %s", path, strerror(errno));
        return NULL;
    }
    /* read at most one byte past the bound, so "too large" needs no trust in the file size */
    char *buf = malloc(SCENE_MAX_BYTES + 1);
    if (!buf) {
        fclose(f);
        tf_seterr(err, errlen, "%s: out of memory", path);
        return NULL;
    }
    size_t n = fread(buf, 1, SCENE_MAX_BYTES + 1, f);
    int read_error = ferror(f) ? errno : 0;
    fclose(f);
    tf_scene *s = NULL;
    if (read_error)
        tf_seterr(err, errlen, "%s: cannot read: %s", path, strerror(read_error));
    else if (n > SCENE_MAX_BYTES)
        tf_seterr(err, errlen, "%s: too large (more than %d bytes)", path, SCENE_MAX_BYTES);
    else
        s = tf_scene_parse_text(path, buf, n, err, errlen);
    free(buf);
    if (s && s->terrain.generator == TF_GEN_FILE && load_heightmap(s, err, errlen) != 0) {
        tf_scene_free(s);
        return NULL;
    }
    return s;
}

void tf_scene_set_size(tf_scene *s, int width, int height)
{
    s->width = width;
    s->height = height;
    tf_scene_rehash(s);
}

/* ---------------------------------------------------------------------------------------- */
/* Canonical form                                                                           */

struct strbuf {
    char *data;
    size_t len, cap;
    int oom;
};

static void sb_printf(struct strbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_printf(struct strbuf *b, const char *fmt, ...)
{
    if (b->oom)
        return;
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        /* an empty buffer is NULL: no offset may be added to it (UB even when zero) */
        char *end = b->data ? b->data + b->len : NULL;
        int n = vsnprintf(end, b->cap - b->len, fmt, ap);
        va_end(ap);
        if (n < 0) {
            b->oom = 1;
            return;
        }
        if ((size_t)n < b->cap - b->len) {
            b->len += (size_t)n;
            return;
        }
        size_t cap = (b->cap + (size_t)n + 1) * 2;
        char *d = realloc(b->data, cap);
        if (!d) {
            b->oom = 1;
            return;
        }
        b->data = d;
        b->cap = cap;
    }
}

/* The envelope in rows of envelope_n numbers, at most ENVELOPE_PER_LINE per line; lines after
 * the first are indented continuation lines (every line stays far below inih's limit). */
static void canonical_envelope(struct strbuf *b, const tf_terrain *t)
{
    int n = t->envelope_n, count = n * n;
    sb_printf(b, "envelope =");
    for (int i = 0, on_line = 0; i < count; i++, on_line++) {
        if (i > 0 && (i % n == 0 || on_line == ENVELOPE_PER_LINE)) {
            sb_printf(b, "\n   ");
            on_line = 0;
        }
        sb_printf(b, " %.17g", t->envelope[i]);
    }
    sb_printf(b, "\n");
}

static void canonical_key(struct strbuf *b, const tf_scene *s, int key)
{
    const struct key_def *k = &KEYS[key];
    const void *src = cfield(s, key);
    int i;
    switch (k->type) {
    case KT_INT:
        sb_printf(b, "%s = %d\n", k->name, *(const int *)src);
        break;
    case KT_U64:
        sb_printf(b, "%s = %" PRIu64 "\n", k->name, *(const uint64_t *)src);
        break;
    case KT_DOUBLE:
        sb_printf(b, "%s = %.17g\n", k->name, *(const double *)src);
        break;
    case KT_VEC3: {
        const tf_vec3 *v = src;
        sb_printf(b, "%s = %.17g %.17g %.17g\n", k->name, v->x, v->y, v->z);
        break;
    }
    case KT_BOOL:
        sb_printf(b, "%s = %s\n", k->name, *(const int *)src ? "true" : "false");
        break;
    case KT_GENERATOR:
        memcpy(&i, src, sizeof i);
        sb_printf(b, "%s = %s\n", k->name, tf_generator_name((enum tf_generator)i));
        break;
    case KT_CAMERA:
        memcpy(&i, src, sizeof i);
        sb_printf(b, "%s = %s\n", k->name, (i >= 0 && i < CAMERA_COUNT) ? CAMERA_NAMES[i] : "?");
        break;
    case KT_ENVELOPE:
        if (s->terrain.envelope_n > 0)
            canonical_envelope(b, &s->terrain);
        break;
    case KT_CAMERA_KEY:
        for (int j = 0; j < s->animation.ncamera; j++) {
            const tf_camera_key *c = &s->animation.camera[j];
            sb_printf(b, "camera = %d position %.17g %.17g %.17g\n", c->frame, c->position.x,
                      c->position.y, c->position.z);
            sb_printf(b, "    look_at %.17g %.17g %.17g\n", c->look_at.x, c->look_at.y,
                      c->look_at.z);
            sb_printf(b, "    up %.17g %.17g %.17g fov %.17g\n", c->up.x, c->up.y, c->up.z,
                      c->fov_deg);
        }
        break;
    case KT_SUN_KEY:
        for (int j = 0; j < s->animation.nsun; j++)
            sb_printf(b, "sun = %d azimuth %.17g elevation %.17g\n", s->animation.sun[j].frame,
                      s->animation.sun[j].azimuth_deg, s->animation.sun[j].elevation_deg);
        break;
    case KT_PATH:
    case KT_SHA256:
        if (*(const char *)src) /* an empty value is not written: the key is absent */
            sb_printf(b, "%s = %s\n", k->name, (const char *)src);
        break;
    case KT_NODATA:
        memcpy(&i, src, sizeof i);
        sb_printf(b, "%s = %s\n", k->name, (i >= 0 && i < NODATA_COUNT) ? NODATA_NAMES[i] : "?");
        break;
    case KT_FIRST_ROW:
        memcpy(&i, src, sizeof i);
        sb_printf(b, "%s = %s\n", k->name,
                  (i >= 0 && i < FIRST_ROW_COUNT) ? FIRST_ROW_NAMES[i] : "?");
        break;
    }
}

char *tf_scene_canonical(const tf_scene *s)
{
    struct strbuf b = {0};
    sb_printf(&b, "; terrafarm canonical scene, format 1\n");
    for (int sec = 0; sec < SEC_COUNT; sec++) {
        if (sec == SEC_ANIMATION && s->animation.frames == 0)
            continue; /* a still: no section, and the hash of every still scene is unchanged */
        sb_printf(&b, "[%s]\n", SECTION_NAMES[sec]);
        for (int key = 0; key < KEY_COUNT; key++)
            if (KEYS[key].section == (enum section)sec && !replaced_by_animation(s, key))
                canonical_key(&b, s, key);
    }
    if (b.oom) {
        free(b.data);
        return NULL;
    }
    return b.data;
}

void tf_scene_rehash(tf_scene *s)
{
    static const char hex[] = "0123456789abcdef";
    /* sodium_init is idempotent and thread-safe; crypto_hash_sha256 needs no state from it,
     * so a failure (no entropy source) does not matter here */
    if (sodium_init() < 0)
        (void)0;
    char *c = tf_scene_canonical(s);
    if (c) {
        crypto_hash_sha256(s->hash, (const unsigned char *)c, strlen(c));
        free(c);
    } else {
        memset(s->hash, 0, sizeof s->hash); /* out of memory: an all-zero hash matches nothing real */
    }
    for (int i = 0; i < 32; i++) {
        s->hash_hex[2 * i] = hex[s->hash[i] >> 4];
        s->hash_hex[2 * i + 1] = hex[s->hash[i] & 15];
    }
    s->hash_hex[64] = '\0';
}
