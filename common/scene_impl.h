/* scene_impl.h: what the scene files (scene.c, scene_*.c) share and nothing else includes:
 * the key table (scene_keys.c), the parser's state and its error reporting (scene_report.c),
 * and the entry points of the value readers (scene_values.c), the inih callbacks
 * (scene_ini.c) and the checks (scene_check.c).  The public API is scene.h. */
#ifndef TF_SCENE_IMPL_H
#define TF_SCENE_IMPL_H

#include <stddef.h>
#include <stdint.h>

#include "scene.h"

_Static_assert(sizeof(enum tf_generator) == sizeof(int), "enums are stored as int");
_Static_assert(sizeof(enum tf_camera_kind) == sizeof(int), "enums are stored as int");

#define BIG 1e9 /* bound on world coordinates and lengths: far beyond any sensible scene */

/* ---- the format: sections and keys (scene_keys.c) ------------------------------------- */

enum section { SEC_IMAGE, SEC_CAMERA, SEC_SUN, SEC_SKY, SEC_TERRAIN, SEC_MATERIALS, SEC_MIST,
               SEC_ANTIALIAS, SEC_ANIMATION, SEC_EROSION, SEC_COUNT };
extern const char *const SCENE_SECTION_NAMES[SEC_COUNT];

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
int scene_is_list_type(int type);

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

#define SCENE_KEY_COUNT 87 /* entries of SCENE_KEYS */
extern const struct key_def SCENE_KEYS[SCENE_KEY_COUNT];
/* 1 if the canonical form leaves key out: a key added to the format after its first version
 * (terrain smooth) while it is at its default, so every scene that does not set it keeps its
 * hash, and a render of it started before the key existed still resumes. */
int scene_key_silent(const tf_scene *s, int key);

#define SCENE_GENERATOR_COUNT 8
#define SCENE_CAMERA_COUNT 2
#define SCENE_NODATA_COUNT 2
#define SCENE_FIRST_ROW_COUNT 3
extern const char *const SCENE_GENERATOR_NAMES[SCENE_GENERATOR_COUNT];
extern const char *const SCENE_CAMERA_NAMES[SCENE_CAMERA_COUNT];
extern const char *const SCENE_NODATA_NAMES[SCENE_NODATA_COUNT];
extern const char *const SCENE_FIRST_ROW_NAMES[SCENE_FIRST_ROW_COUNT];

/* The key `name` of section sec (case-insensitive), or -1. */
int scene_find_key(enum section sec, const char *name);
/* The same for a name this program spells: aborts if it is not in the table. */
int scene_key_index(enum section sec, const char *name);
/* The field of s that key fills. */
void *scene_field(tf_scene *s, int key);
const void *scene_cfield(const tf_scene *s, int key);
/* Keys that an animated camera or sun replaces: not required, and not allowed, when animated. */
int scene_replaced_by_animation(const tf_scene *s, int key);
/* Every key of s at its default. */
void scene_set_defaults(tf_scene *s);

/* ---- parser state and error reporting (scene_report.c) -------------------------------- */

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
    int key_line[SCENE_KEY_COUNT]; /* line where each key was set, 0 = not set */
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

/* Copy at most a few dozen bytes of `src` (n bytes) into out, replacing anything
 * non-printable, so quoted input can never break the one-line message. */
void scene_quote(char *out, size_t outlen, const char *src, size_t n);
/* Record the first error: "NAME:LINE: what" (what starts with the key). */
void scene_fail_at(struct parser *p, int line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* inih found a syntax error on line `line`: say what is wrong with it. */
void scene_report_syntax_error(struct parser *p, int line);

/* ---- values (scene_values.c) ---------------------------------------------------------- */

/* Store `value` for SCENE_KEYS[key] in the scene: 0, or -1 after scene_fail_at. */
int scene_set_value(struct parser *p, int key, const char *value);
/* An [animation] camera or sun key, or (continuation) more fields of the last one. */
int scene_parse_camera_key(struct parser *p, const char *value, int continuation);
int scene_parse_sun_key(struct parser *p, const char *value, int continuation);

/* ---- inih callbacks (scene_ini.c) ----------------------------------------------------- */

/* ini_parse_stream's reader: one physical line of p (the stream), checked; NULL at the end or
 * after the first error. */
char *scene_read_line(char *buf, int num, void *stream);
/* ini_parse_stream's handler (user is the parser). */
int scene_on_key(void *user, const char *section, const char *name, const char *value);

/* ---- checks once the whole text is read (scene_check.c) ------------------------------- */

void scene_check_semantics(struct parser *p);

#ifndef NDEBUG
/* The invariants of scene.c, one assert a clause; each returns 1, so that a call sits inside
 * assert() and vanishes with NDEBUG.  P1-P3: the parser's state. */
int scene_assert_parser(const struct parser *p);
/* P4: the values of a scene the parser accepted. */
int scene_assert_values(const struct parser *p);
#endif

#endif
