/* scene_ini.c: the callbacks inih calls (scene_impl.h): a reader that hands inih one
 * physical line at a time, checked (NUL bytes, overlong lines, section headers), and the
 * handler of each "key = value" line and of indented continuation lines. */
#include "scene_impl.h"

#include <assert.h>
#include <ctype.h>
#include <string.h>

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
        scene_fail_at(p, p->line,
                      "syntax: a section header must start at the beginning of the line");
        return;
    }
    const char *close = memchr(l, ']', n);
    if (!close) {
        scene_fail_at(p, p->line, "syntax: section header without a closing ']'");
        return;
    }
    size_t rest = (size_t)(l + n - (close + 1));
    const char *r = close + 1;
    while (rest > 0 && isspace((unsigned char)*r))
        r++, rest--;
    if (rest > 0 && *r != ';' && *r != '#') {
        scene_quote(q, sizeof q, r, rest);
        scene_fail_at(p, p->line, "syntax: unexpected \"%s\" after the section header", q);
        return;
    }
    size_t name_len = (size_t)(close - (l + 1));
    for (int sec = 0; sec < SEC_COUNT; sec++) {
        if (strlen(SCENE_SECTION_NAMES[sec]) == name_len &&
            strncasecmp(SCENE_SECTION_NAMES[sec], l + 1, name_len) == 0) {
            if (p->section_line[sec]) {
                scene_fail_at(p, p->line, "[%s]: duplicate section (first on line %d)",
                              SCENE_SECTION_NAMES[sec], p->section_line[sec]);
                return;
            }
            p->section = sec;
            p->section_line[sec] = p->line;
            p->last_key = -1;
            return;
        }
    }
    scene_quote(q, sizeof q, l + 1, name_len);
    scene_fail_at(p, p->line, "[%s]: unknown section (expected image, camera, sun, sky, "
                  "terrain, materials, mist, antialias or animation)", q);
}

/* fgets-style reader: hands inih one physical line, checked. */
char *scene_read_line(char *buf, int num, void *stream)
{
    struct parser *p = stream;
    assert(scene_assert_parser(p));
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
        scene_fail_at(p, p->line, "line: contains a NUL byte");
        return NULL;
    }
    /* inih needs room for the newline and the terminating NUL; a longer line it would split
     * and parse the tail as another line. */
    size_t max = (size_t)num - 2;
    if (n > max) {
        scene_fail_at(p, p->line, "line: too long (%zu characters, at most %zu)", n, max);
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
    switch (SCENE_KEYS[p->last_key].type) {
    case KT_CAMERA_KEY:
        return scene_parse_camera_key(p, buf, 1) == 0;
    case KT_SUN_KEY:
        return scene_parse_sun_key(p, buf, 1) == 0;
    default:
        return scene_set_value(p, p->last_key, buf) == 0;
    }
}

int scene_on_key(void *user, const char *section, const char *name, const char *value)
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
        if (p->last_key >= 0 && scene_is_list_type(SCENE_KEYS[p->last_key].type))
            return continue_list(p, value);
        if (p->last_key >= 0)
            scene_fail_at(p, p->line, "%s: indented line would continue its value (only "
                          "envelope and [animation] keys may span lines; remove the indentation)",
                          SCENE_KEYS[p->last_key].name);
        else
            scene_fail_at(p, p->line, "syntax: indented line (remove the indentation)");
        return 0;
    }
    if (*name == '\0') {
        scene_fail_at(p, p->line, "syntax: missing key name before '='");
        return 0;
    }
    scene_quote(q, sizeof q, name, strlen(name));
    if (p->section < 0) {
        scene_fail_at(p, p->line, "%s: key outside of any section (start with a header like "
                      "[image])", q);
        return 0;
    }
    int key = scene_find_key((enum section)p->section, name);
    if (key < 0) {
        scene_fail_at(p, p->line, "%s: unknown key in [%s]", q, SCENE_SECTION_NAMES[p->section]);
        return 0;
    }
    if (p->key_line[key] && SCENE_KEYS[key].type != KT_CAMERA_KEY &&
        SCENE_KEYS[key].type != KT_SUN_KEY) {
        scene_fail_at(p, p->line, "%s: duplicate key (first set on line %d)", SCENE_KEYS[key].name,
                      p->key_line[key]);
        return 0;
    }
    p->key_line[key] = p->line;
    p->last_key = key;
    return scene_set_value(p, key, value) == 0;
}
