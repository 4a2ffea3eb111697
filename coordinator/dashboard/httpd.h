/* httpd.h: the dashboard's HTTP server (libmicrohttpd), in threads of its own: the page and its
 * static files (web/), the JSON API (api.h), the server-sent event stream and the controls.
 * It reads only snapshots from the hub and writes only commands to it (snapshot.h).
 *
 * Requests are attacker's bytes whatever the address: sizes are bounded (headers by MHD's
 * per-connection memory, bodies by MAX_BODY), connections are limited in number and time, and
 * a malformed request gets a 4xx from MHD or from us and touches nothing else.  With a token
 * every request without it gets 401 and nothing else; controls are POST only and need the
 * token (or, on loopback without a token, an X-Terrafarm-Token header of any value) in a
 * header, which a cross-site form cannot send (CSRF); on loopback the Host header must name a
 * loopback address (DNS rebinding). */
#ifndef TF_HTTPD_H
#define TF_HTTPD_H

#include <stddef.h>

#include "coordinator/dashboard/snapshot.h"

typedef struct tf_httpd tf_httpd;

typedef struct tf_httpd_config {
    int listen_fd;          /* bound and listening; owned by the server from here on */
    int port;
    int loopback;           /* listening on loopback only */
    const char *token;      /* required on every request; NULL: none (loopback only) */
    const char *web_dir;    /* the page's files, or NULL: API only */
    tf_dash_hub *hub;
} tf_httpd_config;

/* The directory of the page's files: $TERRAFARM_WEB, else beside the executable
 * (<exe>/../web in a checkout, <exe>/../share/terrafarm/web installed), else
 * /usr/local/share/terrafarm/web, /usr/share/terrafarm/web.  0, or -1 if none has index.html. */
int tf_web_dir_find(char *dir, size_t len);

/* Load the page's files and start the threads.  NULL with a message in err (the fd is closed). */
tf_httpd *tf_httpd_start(const tf_httpd_config *cfg, char *err, size_t errlen);
/* After the final state is published: wait up to ms for the open event streams to send it
 * (so a page watching learns how the render ended), then return. */
void tf_httpd_linger(tf_httpd *h, int ms);
/* Wake the event streams, stop every thread, close the socket, free (NULL is fine). */
void tf_httpd_stop(tf_httpd *h);

#endif
