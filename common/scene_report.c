/* scene_report.c: the parser's error reporting (scene_impl.h): the first error wins, and
 * every message is one line "NAME:LINE: key: what is wrong", input quoted in it cut short
 * with its non-printable bytes replaced. */
#include "scene_impl.h"

#include <assert.h>
#include <ctype.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#define QUOTE_MAX_CHARS 40 /* input quoted in messages is cut to this */

/* Copy at most QUOTE_MAX_CHARS of `src` (n bytes) into out, replacing anything non-printable,
 * so quoted input can never break the one-line message. */
void scene_quote(char *out, size_t outlen, const char *src, size_t n)
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
void scene_fail_at(struct parser *p, int line, const char *fmt, ...)
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
    assert(scene_assert_parser(p));
}

/* inih found a syntax error on line `line`: say what is wrong with it. */
void scene_report_syntax_error(struct parser *p, int line)
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
    scene_quote(q, sizeof q, l, n);
    p->failed = 0; /* inih's error is earlier than ours: it replaces ours */
    scene_fail_at(p, line,
                  "syntax: expected \"key = value\", \"[section]\" or a comment, got \"%s\"", q);
}
