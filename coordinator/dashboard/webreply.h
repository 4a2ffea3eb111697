/* webreply.h: what every terrafarm web server of one render says and checks the same way (the
 * dashboard, httpd.c; Raypaint's page, coordinator/paint/paint_http.c): the replies with their
 * security headers, the token in a request's headers, the Host check on loopback (DNS
 * rebinding), and a page's static file.  libmicrohttpd's types, nothing of a render's. */
#ifndef TF_WEBREPLY_H
#define TF_WEBREPLY_H

#include <jansson.h>
#include <microhttpd.h>
#include <stddef.h>

#define TF_WEB_MAX_FILE (1 << 20)
#define TF_WEB_MAX_BODY 4096   /* a control's JSON body */

/* A request's body, collected over libmicrohttpd's calls of the access handler (*con_cls). */
typedef struct tf_web_body {
    char data[TF_WEB_MAX_BODY + 1];
    size_t len;
    int too_big;
} tf_web_body;

/* The first calls of an access handler for one request: allocate its body, take the uploaded
 * bytes, answer 413 beyond TF_WEB_MAX_BODY.  Returns the body once the request is whole (the
 * handler answers it), or NULL with *ret what the handler returns now.  Free *con_cls in the
 * completion callback. */
tf_web_body *tf_web_collect(struct MHD_Connection *c, void **con_cls, const char *upload,
                            size_t *upload_size, enum MHD_Result *ret);
/* The completion callback that frees it. */
void tf_web_request_done(void *cls, struct MHD_Connection *c, void **con_cls,
                         enum MHD_RequestTerminationCode why);

/* No caching, no sniffing, no framing, no referrer, only this origin's scripts. */
void tf_web_headers(struct MHD_Response *r);
enum MHD_Result tf_web_send_bytes(struct MHD_Connection *c, unsigned status, const char *type,
                                  const void *data, size_t len);
/* One line of text/plain (a newline added). */
enum MHD_Result tf_web_send_text(struct MHD_Connection *c, unsigned status, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* doc is consumed; NULL answers 500. */
enum MHD_Result tf_web_send_json(struct MHD_Connection *c, unsigned status, json_t *doc);
enum MHD_Result tf_web_send_unauthorized(struct MHD_Connection *c);
/* 303 to location, setting the tf_token cookie to token (a browser's login). */
enum MHD_Result tf_web_send_login(struct MHD_Connection *c, const char *token,
                                  const char *location);

/* The token from "Authorization: Bearer T" or "X-Terrafarm-Token: T", or NULL. */
const char *tf_web_header_token(struct MHD_Connection *c);
/* 1 when the Host header names a loopback address. */
int tf_web_host_ok(struct MHD_Connection *c);

/* Who may ask, the same for every web server of a render (dashboard/httpd.h says why): on
 * loopback the Host must be loopback; with a token (NULL: none, loopback only) GET /login?token=
 * sets the cookie, and every other request needs the token in a header or the cookie; a POST
 * needs it in a header (or on loopback without a token, an X-Terrafarm-Token header of any
 * value).  Returns TF_WEB_GET or TF_WEB_POST for the server to answer, or TF_WEB_ANSWERED with
 * *ret the answer already queued. */
enum { TF_WEB_ANSWERED = 0, TF_WEB_GET, TF_WEB_POST };
int tf_web_gate(struct MHD_Connection *c, const char *url, const char *method, const char *token,
                int loopback, enum MHD_Result *ret);

/* dir/name read whole (at most TF_WEB_MAX_FILE bytes) into *data (malloc'd).  0, or -1 with a
 * message naming the file. */
int tf_web_load_file(const char *dir, const char *name, char **data, size_t *len, char *err,
                     size_t errlen);

#endif
