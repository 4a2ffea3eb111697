/* webreply.c: see webreply.h. */
#include "coordinator/dashboard/webreply.h"

#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "coordinator/dashboard/httpauth.h"
#include "linda/sock.h"
#include "log.h"

void tf_web_headers(struct MHD_Response *r)
{
    MHD_add_response_header(r, "Cache-Control", "no-store");
    MHD_add_response_header(r, "X-Content-Type-Options", "nosniff");
    MHD_add_response_header(r, "X-Frame-Options", "DENY");
    MHD_add_response_header(r, "Referrer-Policy", "no-referrer");
    MHD_add_response_header(r, "Content-Security-Policy",
                            "default-src 'self'; img-src 'self' blob: data:; "
                            "frame-ancestors 'none'; form-action 'none'");
}

enum MHD_Result tf_web_send_bytes(struct MHD_Connection *c, unsigned status, const char *type,
                                  const void *data, size_t len)
{
    struct MHD_Response *r =
        MHD_create_response_from_buffer(len, (void *)data, MHD_RESPMEM_MUST_COPY);
    if (!r)
        return MHD_NO;
    MHD_add_response_header(r, "Content-Type", type);
    tf_web_headers(r);
    enum MHD_Result ok = MHD_queue_response(c, status, r);
    MHD_destroy_response(r);
    return ok;
}

enum MHD_Result tf_web_send_text(struct MHD_Connection *c, unsigned status, const char *fmt, ...)
{
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(buf, sizeof buf - 1, fmt, ap);
    va_end(ap);
    if (n < 0)
        n = 0;
    if (n > (int)sizeof buf - 2)
        n = (int)sizeof buf - 2;
    buf[n++] = '\n';
    return tf_web_send_bytes(c, status, "text/plain; charset=utf-8", buf, (size_t)n);
}

enum MHD_Result tf_web_send_json(struct MHD_Connection *c, unsigned status, json_t *doc)
{
    if (!doc)
        return tf_web_send_text(c, 500, "out of memory");
    char *text = json_dumps(doc, JSON_COMPACT);
    json_decref(doc);
    if (!text)
        return tf_web_send_text(c, 500, "out of memory");
    enum MHD_Result ok = tf_web_send_bytes(c, status, "application/json", text, strlen(text));
    free(text);
    return ok;
}

enum MHD_Result tf_web_send_unauthorized(struct MHD_Connection *c)
{
    static const char body[] = "401 unauthorized\n";
    struct MHD_Response *r =
        MHD_create_response_from_buffer(sizeof body - 1, (void *)body, MHD_RESPMEM_PERSISTENT);
    if (!r)
        return MHD_NO;
    MHD_add_response_header(r, "Content-Type", "text/plain; charset=utf-8");
    MHD_add_response_header(r, "WWW-Authenticate", "Bearer realm=\"terrafarm\"");
    tf_web_headers(r);
    enum MHD_Result ok = MHD_queue_response(c, 401, r);
    MHD_destroy_response(r);
    return ok;
}

enum MHD_Result tf_web_send_login(struct MHD_Connection *c, const char *token,
                                  const char *location)
{
    char cookie[TF_HTTP_TOKEN_MAX + 64];
    snprintf(cookie, sizeof cookie, "tf_token=%s; Path=/; SameSite=Strict", token);
    struct MHD_Response *r = MHD_create_response_from_buffer(0, (void *)"", MHD_RESPMEM_PERSISTENT);
    if (!r)
        return MHD_NO;
    MHD_add_response_header(r, "Set-Cookie", cookie);
    MHD_add_response_header(r, "Location", location);
    tf_web_headers(r);
    enum MHD_Result ok = MHD_queue_response(c, 303, r);
    MHD_destroy_response(r);
    return ok;
}

const char *tf_web_header_token(struct MHD_Connection *c)
{
    const char *a = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Authorization");
    if (a && !strncasecmp(a, "Bearer ", 7)) {
        a += 7;
        while (*a == ' ')
            a++;
        return a;
    }
    return MHD_lookup_connection_value(c, MHD_HEADER_KIND, "X-Terrafarm-Token");
}

int tf_web_host_ok(struct MHD_Connection *c)
{
    const char *host = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Host");
    if (!host)
        return 0;
    char name[256];
    size_t n = strlen(host);
    if (n >= sizeof name)
        return 0;
    if (host[0] == '[') {
        const char *end = strchr(host, ']');
        if (!end)
            return 0;
        snprintf(name, sizeof name, "%.*s", (int)(end - host - 1), host + 1);
    } else {
        const char *colon = strchr(host, ':');
        snprintf(name, sizeof name, "%.*s", colon ? (int)(colon - host) : (int)n, host);
    }
    return tf_addr_is_loopback(name);
}

int tf_web_load_file(const char *dir, const char *name, char **data, size_t *len, char *err,
                     size_t errlen)
{
    char p[PATH_MAX];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    FILE *in = fopen(p, "rb");
    if (!in)
        return tf_seterr(err, errlen, "%s: %s", p, strerror(errno));
    *data = malloc(TF_WEB_MAX_FILE);
    *len = *data ? fread(*data, 1, TF_WEB_MAX_FILE, in) : 0;
    int bad = !*data || ferror(in) || *len == TF_WEB_MAX_FILE;
    fclose(in);
    if (bad)
        return tf_seterr(err, errlen, "%s: unreadable or larger than %d bytes", p,
                         TF_WEB_MAX_FILE);
    return 0;
}

tf_web_body *tf_web_collect(struct MHD_Connection *c, void **con_cls, const char *upload,
                            size_t *upload_size, enum MHD_Result *ret)
{
    tf_web_body *b = *con_cls;
    *ret = MHD_YES;
    if (!b) {
        if (!(b = calloc(1, sizeof *b))) {
            *ret = MHD_NO;
            return NULL;
        }
        *con_cls = b;
        const char *cl = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Content-Length");
        if (cl && strtoull(cl, NULL, 10) > TF_WEB_MAX_BODY) {
            b->too_big = 1;
            *ret = tf_web_send_text(c, 413, "request body larger than %d bytes", TF_WEB_MAX_BODY);
        }
        return NULL; /* headers are in; the body (if any) follows */
    }
    if (*upload_size) {
        size_t n = *upload_size;
        *upload_size = 0;
        if (b->too_big || b->len + n > TF_WEB_MAX_BODY) {
            b->too_big = 1; /* answer now and close: the rest is not read */
            *ret = tf_web_send_text(c, 413, "request body larger than %d bytes", TF_WEB_MAX_BODY);
            return NULL;
        }
        memcpy(b->data + b->len, upload, n);
        b->len += n;
        return NULL;
    }
    return b->too_big ? NULL : b;
}

void tf_web_request_done(void *cls, struct MHD_Connection *c, void **con_cls,
                         enum MHD_RequestTerminationCode why)
{
    (void)cls, (void)c, (void)why;
    free(*con_cls);
    *con_cls = NULL;
}

static int token_ok(const char *token, const char *given)
{
    return given && tf_http_token_matches(token, given, strlen(given));
}

int tf_web_gate(struct MHD_Connection *c, const char *url, const char *method, const char *token,
                int loopback, enum MHD_Result *ret)
{
    int is_get = !strcmp(method, "GET") || !strcmp(method, "HEAD");
    const char *cookie = MHD_lookup_connection_value(c, MHD_COOKIE_KIND, "tf_token");
    const char *ht = tf_web_header_token(c);
    if (loopback && !tf_web_host_ok(c))
        *ret = tf_web_send_text(c, 403, "the Host header must name a loopback address");
    else if (token && is_get && !strcmp(url, "/login"))
        *ret = token_ok(token, MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "token"))
                   ? tf_web_send_login(c, token, "/")
                   : tf_web_send_unauthorized(c);
    else if (token && !token_ok(token, ht) && !token_ok(token, cookie))
        *ret = tf_web_send_unauthorized(c);
    else if (is_get)
        return TF_WEB_GET;
    else if (strcmp(method, "POST"))
        *ret = tf_web_send_text(c, 405, "method %.20s not allowed", method);
    /* a control: the token in a header (a cookie alone could be a cross-site form); on
     * loopback without a token, a header no plain form can set */
    else if (token ? !token_ok(token, ht) : !ht)
        *ret = tf_web_send_text(c, 403, "controls need the token in a header (Authorization: "
                                        "Bearer TOKEN or X-Terrafarm-Token)");
    else
        return TF_WEB_POST;
    return TF_WEB_ANSWERED;
}
