/* scene.c: loading and parsing a scene (the public API of scene.h; the format reference is
 * scenes/README.md).  The pieces, one concept a file, share scene_impl.h:
 *   scene_keys.c       the key table: sections, keys, types, ranges, defaults
 *   scene_report.c     the parser's one-line error messages
 *   scene_values.c     reading each type of value
 *   scene_ini.c        the callbacks inih calls, a line at a time
 *   scene_check.c      the checks once the whole text is read
 *   scene_canonical.c  the canonical form and its hash
 *   scene_frame.c      the scene of one frame of an [animation]
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
 * Every key is described once in the table SCENE_KEYS (scene_keys.c): its section, name,
 * type, where it lives in tf_scene, its range and its default.  Defaults, parsing, range
 * checks and the canonical form are all driven by that table, so a field cannot be parsed but
 * forgotten in the hash.
 *
 * INVARIANTS (checked clause by clause in debug builds, `make asan`: P1-P3 on the parser's
 * state by scene_assert_parser (scene_check.c) at every line and every error, P4 by
 * scene_assert_values on every scene accepted, P5 by assert_round_trip below):
 *   P1. The first error wins and stops parsing: once `failed` is set the reader returns EOF,
 *       and the error names a line already read (0: a section that is not there).  inih
 *       reports its own syntax errors only through its return value (the first bad line),
 *       and keeps parsing after one, so at the end the earlier of inih's and ours is reported.
 *   P2. Every message is one line "NAME:LINE: key: what is wrong"; bytes quoted from the input
 *       are cut short and non-printable ones replaced, so a message never spans lines.
 *   P3. The parser's state stays within its tables: the section is -1 (before the first
 *       header) or a section; the last key is -1 or a key of that section; a key is set on a
 *       line at or after its section's header; the envelope and the [animation] keys fit
 *       their arrays.
 *   P4. A scene accepted holds, for every number and vector its text set, a value in the
 *       key's range.
 *   P5. The canonical form is itself a valid scene: parse(canonical(s)) has the same canonical
 *       form (the unit tests and the fuzz harness check this too). */
#include "scene.h"

#include <assert.h>
#include <errno.h>
#include <ini.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "scene_impl.h"

#define SCENE_MAX_BYTES (1024 * 1024) /* bound on a scene file / text */

void tf_scene_free(tf_scene *s)
{
    if (!s)
        return;
    free(s->path);
    free(s->text);
    free(s->heightmap);
    free(s->heightmap_name);
    free(s->eroded);
    free(s->eroded_from);
    free(s);
}

int tf_scene_attach_eroded(tf_scene *s, uint8_t *bytes, size_t len, const char *from)
{
    char *copy = strdup(from);
    if (!copy) {
        free(bytes);
        return -1;
    }
    free(s->eroded);
    free(s->eroded_from);
    s->eroded = bytes;
    s->eroded_len = len;
    s->eroded_from = copy;
    s->terrain.eroded_bytes = bytes;
    s->terrain.eroded_len = len;
    s->terrain.eroded_from = copy;
    return 0;
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
    scene_set_defaults(s);
    return s;
}

#ifndef NDEBUG
/* P5: the canonical form parses, to the same canonical form.  Returns 1, so that a call sits
 * inside assert() and vanishes with NDEBUG (as SQLite's assert_pager_state). */
static int assert_round_trip(const tf_scene *s)
{
    static _Thread_local int nested; /* the parse below does not check itself again */
    char *canon = nested ? NULL : tf_scene_canonical(s);
    if (!canon)
        return 1; /* nested, or out of memory: nothing to compare */
    nested = 1;
    tf_scene *again = tf_scene_parse_text("<canonical>", canon, strlen(canon), NULL, 0);
    nested = 0;
    char *canon2 = again ? tf_scene_canonical(again) : NULL;
    assert(again && "P5: the canonical form is a valid scene");
    assert((!canon2 || !strcmp(canon, canon2)) && "P5: it has the same canonical form");
    free(canon2);
    free(canon);
    tf_scene_free(again);
    return 1;
}
#endif

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
    int rc = ini_parse_stream(scene_read_line, &p, scene_on_key, &p);
    if (rc > 0 && (!p.failed || rc < p.err_line))
        scene_report_syntax_error(&p, rc);
    else if (rc < 0 && !p.failed)
        scene_fail_at(&p, p.line, "line: cannot parse (out of memory)");
    if (!p.failed)
        scene_check_semantics(&p);
    assert(scene_assert_parser(&p));
    if (p.failed) {
        tf_scene_free(s);
        return NULL;
    }
    assert(scene_assert_values(&p));
    tf_scene_rehash(s);
    assert(assert_round_trip(s));
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

/* All of f, or its first max + 1 bytes when it is longer (so the caller sees it is too
 * long): malloc'd, its length in *len.  NULL when out of memory. */
static uint8_t *read_at_most(FILE *f, size_t max, size_t *len)
{
    size_t cap = max < (1 << 20) ? max + 1 : 1 << 20;
    uint8_t *buf = malloc(cap);
    *len = 0;
    while (buf) {
        if (*len == cap) {
            if (cap > max)
                break; /* one byte past the bound read: too long */
            size_t grown = cap * 2 > max ? max + 1 : cap * 2;
            uint8_t *b = realloc(buf, grown);
            if (!b) {
                free(buf);
                return NULL;
            }
            buf = b;
            cap = grown;
        }
        size_t got = fread(buf + *len, 1, cap - *len, f);
        *len += got;
        if (got == 0)
            break;
    }
    return buf;
}

/* Read the whole height map file (at most TF_HEIGHTMAP_MAX_BYTES) and attach it. */
static int load_heightmap(tf_scene *s, char *err, size_t errlen)
{
    char *path = resolve_heightmap_path(s->path, s->terrain.file_path);
    if (!path)
        return tf_seterr(err, errlen, "%s: out of memory", s->path);
    int rc = -1;
    uint8_t *buf = NULL;
    size_t len = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        tf_seterr(err, errlen, "%s: height map %s: cannot open: %s", s->path, path,
                  strerror(errno));
    else if (!(buf = read_at_most(f, TF_HEIGHTMAP_MAX_BYTES, &len)))
        tf_seterr(err, errlen, "%s: height map %s: out of memory", s->path, path);
    else if (ferror(f))
        tf_seterr(err, errlen, "%s: height map %s: cannot read: %s", s->path, path,
                  strerror(errno));
    else if (len > TF_HEIGHTMAP_MAX_BYTES)
        tf_seterr(err, errlen, "%s: height map %s: too large (more than %zu MiB)", s->path, path,
                  TF_HEIGHTMAP_MAX_BYTES >> 20);
    else if (len == 0)
        tf_seterr(err, errlen, "%s: height map %s: empty file", s->path, path);
    else {
        rc = tf_scene_attach_heightmap(s, buf, len, path, err, errlen);
        buf = NULL; /* owned by the scene, or freed */
    }
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
