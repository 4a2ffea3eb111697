/* http_client.c: see http_client.h. */
#include "http_client.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "clock.h"
#include "linda/sock.h"
#include "log.h"

/* Write all of buf before the deadline. */
static int send_all(int fd, const char *buf, size_t len, int64_t deadline)
{
    while (len) {
        struct pollfd p = {fd, POLLOUT, 0};
        int64_t left = deadline - tf_now_ms();
        if (left <= 0 || poll(&p, 1, (int)left) <= 0)
            return -1;
        ssize_t n = write(fd, buf, len);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return -1;
        buf += n;
        len -= (size_t)n;
    }
    return 0;
}

/* Read until the peer closes, at most max bytes; malloc'd and NUL-terminated, or NULL. */
static char *read_all(int fd, int64_t deadline, size_t max, size_t *out_len, const char **why)
{
    size_t cap = 65536, len = 0;
    char *buf = malloc(cap + 1);
    while (buf) {
        struct pollfd p = {fd, POLLIN, 0};
        int64_t left = deadline - tf_now_ms();
        if (left <= 0 || poll(&p, 1, (int)left) <= 0) {
            *why = "no complete answer in time";
            break;
        }
        if (len == cap) {
            char *nb = cap < max ? realloc(buf, 2 * cap + 1) : NULL;
            if (!nb) {
                *why = cap < max ? "out of memory" : "the answer is too large";
                break;
            }
            buf = nb;
            cap *= 2;
        }
        ssize_t got = read(fd, buf + len, cap - len);
        if (got < 0 && errno == EINTR)
            continue;
        if (got <= 0) {
            buf[len] = 0;
            *out_len = len;
            return buf;
        }
        len += (size_t)got;
    }
    free(buf);
    if (!buf && !*why)
        *why = "out of memory";
    return NULL;
}

/* Split "HTTP/1.x CODE ...\r\n...\r\n\r\nBODY" in place into a. */
static int parse_answer(char *buf, size_t len, tf_http_answer *a)
{
    char *body = strstr(buf, "\r\n\r\n");
    if (!body || sscanf(buf, "HTTP/1.%*d %d", &a->code) != 1)
        return -1;
    body += 4;
    a->len = len - (size_t)(body - buf);
    memmove(buf, body, a->len + 1);
    a->body = buf;
    return 0;
}

int tf_http_request(const char *addr, const char *method, const char *path, const char *token,
                    const char *ctype, const void *body, size_t len, int64_t deadline,
                    size_t max_answer, tf_http_answer *a, char *err, size_t errlen)
{
    memset(a, 0, sizeof *a);
    char head[1536];
    int n = snprintf(head, sizeof head,
                     "%s %s HTTP/1.0\r\nHost: %s\r\n%s%s%sAccept: application/json\r\n"
                     "Content-Type: %s\r\nContent-Length: %zu\r\nConnection: close\r\n\r\n",
                     method, path, addr, token ? "Authorization: Bearer " : "",
                     token ? token : "", token ? "\r\n" : "", ctype ? ctype : "text/plain",
                     body ? len : 0);
    if (n <= 0 || n >= (int)sizeof head)
        return tf_seterr(err, errlen, "%s: request line too long", addr);
    int fd = tf_sock_connect(addr, deadline, err, errlen);
    if (fd < 0)
        return -1;
    if (send_all(fd, head, (size_t)n, deadline) || (body && send_all(fd, body, len, deadline))) {
        close(fd);
        return tf_seterr(err, errlen, "%s: cannot send the request: %s", addr,
                         errno ? strerror(errno) : "timed out");
    }
    const char *why = NULL;
    size_t got = 0;
    char *buf = read_all(fd, deadline, max_answer, &got, &why);
    close(fd);
    if (!buf)
        return tf_seterr(err, errlen, "%s: %s", addr, why);
    if (parse_answer(buf, got, a)) {
        free(buf);
        return tf_seterr(err, errlen, "%s: not an HTTP answer from a terrafarm service", addr);
    }
    return 0;
}

void tf_http_error_text(const char *body, size_t len, char *out, size_t outlen)
{
    json_t *doc = json_loadb(body, len, 0, NULL);
    const char *text = json_string_value(json_object_get(doc, "error"));
    size_t n = text ? strlen(text) : len;
    if (!text) {
        text = body;
        const char *nl = memchr(body, '\n', len);
        n = nl ? (size_t)(nl - body) : len;
    }
    if (n > 300)
        n = 300;
    if (outlen && n > outlen - 1)
        n = outlen - 1;
    if (outlen) {
        memcpy(out, text, n);
        tf_one_line(out, n);
        out[n] = '\0';
    }
    json_decref(doc);
}

json_t *tf_http_json(const char *addr, const char *method, const char *path, const char *token,
                     json_t *body, int64_t deadline, int *code, char *err, size_t errlen)
{
    char *text = body ? json_dumps(body, JSON_COMPACT) : NULL;
    if (body && !text) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    tf_http_answer a;
    int rc = tf_http_request(addr, method, path, token, "application/json", text,
                             text ? strlen(text) : 0, deadline, 64u << 20, &a, err, errlen);
    free(text);
    if (rc)
        return NULL;
    if (code)
        *code = a.code;
    json_t *doc = NULL;
    if (a.code == 204) {
        doc = json_object();
    } else if (a.code < 200 || a.code > 299) {
        char said[320];
        tf_http_error_text(a.body, a.len, said, sizeof said);
        tf_seterr(err, errlen, "%s %s answered %d: %s", addr, path, a.code, said);
    } else {
        json_error_t jerr;
        doc = json_loadb(a.body, a.len, JSON_REJECT_DUPLICATES, &jerr);
        if (!json_is_object(doc)) {
            json_decref(doc);
            doc = NULL;
            tf_seterr(err, errlen, "%s %s: not a JSON object: %s", addr, path, jerr.text);
        }
    }
    free(a.body);
    return doc;
}
