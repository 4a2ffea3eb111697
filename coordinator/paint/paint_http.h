/* paint_http.h: Raypaint's page and API (libmicrohttpd, threads of its own), reading only the
 * hub (paint_hub.h) and writing only commands to it.  The dashboard's rules (dashboard/httpd.h)
 * hold here too: every request is an attacker's bytes, bodies are bounded, on loopback the Host
 * must be loopback, beyond it every request needs the token, and every control (POST) needs
 * the token (or on loopback an X-Terrafarm-Token header) in a header, never a cookie alone.
 *
 *   GET  /, /paint.js, /paint.css      the page (web/paint.*)
 *   GET  /api/paint/status             the view, its progress, the workers (JSON)
 *   GET  /api/paint/updates?gen=G&from=N&wait=MS
 *                                      the view's display messages from byte N (paint_raster.h),
 *                                      waiting up to MS (<= 2000) for some; headers
 *                                      X-Paint-Gen (the view they are of; another than G means
 *                                      start again from 0) and X-Paint-End (the next N)
 *   GET  /api/paint/image.png          the picture as painted so far (what the page shows)
 *   GET  /api/paint/scene              the view's scene file
 *   POST /api/paint/view               {"camera": {...}, "sun": {...}, "mist": {...}}: a new view
 *   POST /api/paint/interest           {"x", "y", "w", "h"} in pixels; {} clears it
 *   POST /api/paint/pause, /resume
 *   POST /api/paint/save               write the view's scene to --save
 *   POST /api/paint/submit             submit it to the standing farm of --farm */
#ifndef TF_PAINT_HTTP_H
#define TF_PAINT_HTTP_H

#include <stddef.h>
#include <stdint.h>

#include "coordinator/paint/paint_hub.h"
#include "scene.h"

typedef struct tf_paint_http_config {
    const char *listen;         /* HOST:PORT; NULL: 127.0.0.1:0 */
    const char *token_file;     /* NULL: derived from key, or none on loopback */
    const uint8_t *key;         /* the farm secret, or NULL */
    const tf_scene *base;       /* the loaded scene (read only) */
    const char *save;           /* --save, or NULL */
    const char *farm;           /* --farm HOST:PORT, or NULL */
    const char *farm_token_file;
    tf_paint_hub *hub;
} tf_paint_http_config;

typedef struct tf_paint_http tf_paint_http;

/* Bind, load the page, start; logs the page's address.  NULL with err. */
tf_paint_http *tf_paint_http_start(const tf_paint_http_config *cfg, char *err, size_t errlen);
int tf_paint_http_port(const tf_paint_http *h);
void tf_paint_http_stop(tf_paint_http *h);

#endif
