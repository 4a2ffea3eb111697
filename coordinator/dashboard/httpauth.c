/* httpauth.c: see httpauth.h. */
#include "coordinator/dashboard/httpauth.h"

#include <errno.h>
#include <sodium.h>
#include <stdio.h>
#include <string.h>

#include "log.h"

static const char token_context[] = "terrafarm dashboard token v1";

int tf_http_token_derive(const uint8_t *key, char *out, size_t outlen)
{
    uint8_t h[32];
    if (outlen < 2 * sizeof h + 1 || sodium_init() < 0 ||
        crypto_generichash(h, sizeof h, (const unsigned char *)token_context,
                           sizeof token_context - 1, key, 32))
        return -1;
    sodium_bin2hex(out, outlen, h, sizeof h);
    sodium_memzero(h, sizeof h);
    return 0;
}

static int token_char_ok(unsigned char c)
{
    return c > 0x20 && c < 0x7f && c != '"' && c != ';' && c != ',' && c != '\\';
}

int tf_http_token_load(const char *path, char *out, size_t outlen, char *err, size_t errlen)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return tf_seterr(err, errlen, "%s: cannot read the dashboard token: %s", path,
                         strerror(errno));
    char line[TF_HTTP_TOKEN_MAX + 64];
    int got = fgets(line, sizeof line, f) != NULL;
    fclose(f);
    if (!got)
        return tf_seterr(err, errlen, "%s: the dashboard token file is empty", path);
    char *a = line, *b = line + strlen(line);
    while (*a == ' ' || *a == '\t')
        a++;
    while (b > a && (b[-1] == '\n' || b[-1] == '\r' || b[-1] == ' ' || b[-1] == '\t'))
        *--b = 0;
    size_t n = (size_t)(b - a);
    if (n < 16 || n > TF_HTTP_TOKEN_MAX || n + 1 > outlen)
        return tf_seterr(err, errlen, "%s: the dashboard token must be 16 to %d characters "
                         "on the first line (it has %zu)", path, TF_HTTP_TOKEN_MAX, n);
    for (size_t i = 0; i < n; i++)
        if (!token_char_ok((unsigned char)a[i]))
            return tf_seterr(err, errlen, "%s: the dashboard token may not contain spaces, "
                             "quotes, ';', ',' or control characters", path);
    memcpy(out, a, n + 1);
    sodium_memzero(line, sizeof line);
    return 0;
}

int tf_http_token_matches(const char *token, const char *given, size_t n)
{
    size_t len = strlen(token);
    return given && n == len && sodium_memcmp(token, given, len) == 0;
}
