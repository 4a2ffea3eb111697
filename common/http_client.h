/* http_client.h: the farm's one HTTP client: a request with an optional body to a terrafarm
 * HTTP service (a render's dashboard, a standing farm's API), answered as one bounded
 * document within a deadline.  HTTP/1.0 over the project's sockets (linda/sock.h), no
 * keep-alive, no redirects: it talks only to terrafarm's own servers.  JSON answers are
 * parsed with jansson. */
#ifndef TF_HTTP_CLIENT_H
#define TF_HTTP_CLIENT_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>

typedef struct tf_http_answer {
    int code;   /* the HTTP status */
    char *body; /* malloc'd, NUL-terminated */
    size_t len;
} tf_http_answer;

/* Send METHOD path to addr (HOST:PORT) with an optional bearer token and body (ctype, len
 * bytes) and read the whole answer, at most max_answer bytes, before deadline_ms
 * (tf_now_ms() scale).  0 and the answer (free a->body), or -1 with one line in err. */
int tf_http_request(const char *addr, const char *method, const char *path, const char *token,
                    const char *ctype, const void *body, size_t len, int64_t deadline_ms,
                    size_t max_answer, tf_http_answer *a, char *err, size_t errlen);

/* The same for a JSON document: body (may be NULL) is sent as application/json; a 2xx answer
 * must be a JSON object (returned, new reference; *code set).  A 204 answers an empty object.
 * Any other status fails with "ADDR PATH answered CODE: " and tf_http_error_text's line. */
json_t *tf_http_json(const char *addr, const char *method, const char *path, const char *token,
                     json_t *body, int64_t deadline_ms, int *code, char *err, size_t errlen);

/* What an error answer says, fit for one line of a terminal: the "error" string of a JSON
 * object (terrafarm's services answer {"error": "..."}), else the body's first line; at most
 * 300 bytes, every control byte (an escape sequence a hostile server sends) shown as '?'. */
void tf_http_error_text(const char *body, size_t len, char *out, size_t outlen);

#endif
