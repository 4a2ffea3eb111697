/* paint_http.c: see paint_http.h. */
#include "coordinator/paint/paint_http.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <jansson.h>
#include <microhttpd.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "clock.h"
#include "coordinator/dashboard/httpauth.h"
#include "coordinator/dashboard/httpd.h"
#include "coordinator/dashboard/livepreview.h"
#include "coordinator/dashboard/webreply.h"
#include "coordinator/paint/paint_raster.h"
#include "coordinator/paint/paint_view.h"
#include "http_client.h"
#include "linda/sock.h"
#include "log.h"

#define MAX_WAIT_MS 2000
#define MAX_CONNECTIONS 32
#define MAX_PER_IP 16

typedef struct web_file {
    const char *url, *name, *type;
    char *data;
    size_t len;
} web_file;

struct tf_paint_http {
    struct MHD_Daemon *mhd;
    tf_paint_http_config cfg;
    char token[TF_HTTP_TOKEN_MAX + 1];
    char farm_token[TF_HTTP_TOKEN_MAX + 1];
    int have_token, have_farm_token, loopback, port;
    web_file files[3];
};

/* ---- reading ---- */

static json_t *status_json(tf_paint_http *h)
{
    tf_paint_status s;
    tf_paint_hub_status(h->cfg.hub, &s);
    const tf_paint_counts *c = &s.counts;
    return json_pack("{s:I,s:i,s:i,s:o,s:{s:I,s:I,s:I,s:I,s:I},s:i,s:b,s:I,s:I,s:I,s:f,s:f,"
                     "s:f,s:b,s:s,s:s,s:i,s:I,s:i,s:f}",
                     "gen", (json_int_t)s.gen, "width", s.width, "height", s.height, "view",
                     tf_paint_view_json(&s.view), "counts", "exact_pixels",
                     (json_int_t)c->exact_pixels, "pixels", (json_int_t)c->pixels, "samples",
                     (json_int_t)c->samples, "queued", (json_int_t)c->queued, "roots_left",
                     (json_int_t)c->roots_left, "workers", s.workers, "paused", s.paused,
                     "results", (json_int_t)s.results, "stale", (json_int_t)s.stale, "refused",
                     (json_int_t)s.refused, "view_age_s", s.view_age_s, "coarse_s", s.coarse_s,
                     "painted_s", s.painted_s, "output_written", s.output_written, "output",
                     s.output, "save", h->cfg.save ? h->cfg.save : "", "outstanding",
                     s.outstanding, "log_bytes", (json_int_t)s.log_bytes, "watchers",
                     s.watchers, "unwatched_s", s.unwatched_s);
}

static int query_i64(struct MHD_Connection *c, const char *key, int64_t lo, int64_t hi,
                     int64_t *out)
{
    const char *v = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, key);
    char *end;
    if (!v)
        return 0;
    errno = 0;
    long long n = strtoll(v, &end, 10);
    if (errno || end == v || *end || n < lo || n > hi)
        return -1;
    *out = n;
    return 0;
}

static enum MHD_Result serve_updates(tf_paint_http *h, struct MHD_Connection *c)
{
    int64_t gen = 0, from = 0, wait = 0;
    if (query_i64(c, "gen", 0, INT64_MAX, &gen) || query_i64(c, "from", 0, INT64_MAX, &from) ||
        query_i64(c, "wait", 0, MAX_WAIT_MS, &wait))
        return tf_web_send_text(c, 400, "gen, from and wait must be whole numbers (wait <= %d)",
                                MAX_WAIT_MS);
    uint8_t *bytes;
    size_t len, end;
    int64_t now;
    if (tf_paint_hub_read(h->cfg.hub, gen, (size_t)from, (int)wait, &bytes, &len, &now, &end))
        return tf_web_send_text(c, 500, "out of memory");
    struct MHD_Response *r = MHD_create_response_from_buffer(len, bytes, MHD_RESPMEM_MUST_FREE);
    if (!r) {
        free(bytes);
        return MHD_NO;
    }
    char g[32], e[32];
    snprintf(g, sizeof g, "%" PRId64, now);
    snprintf(e, sizeof e, "%zu", end);
    MHD_add_response_header(r, "Content-Type", "application/octet-stream");
    MHD_add_response_header(r, "X-Paint-Gen", g);
    MHD_add_response_header(r, "X-Paint-End", e);
    tf_web_headers(r);
    enum MHD_Result ok = MHD_queue_response(c, 200, r);
    MHD_destroy_response(r);
    return ok;
}

/* The picture as the page paints it: the view's messages applied here. */
static enum MHD_Result serve_image(tf_paint_http *h, struct MHD_Connection *c)
{
    tf_paint_status s;
    tf_paint_hub_status(h->cfg.hub, &s);
    uint8_t *bytes, *png = NULL;
    size_t len, end, png_len = 0;
    int64_t now;
    if (tf_paint_hub_read(h->cfg.hub, -1, 0, 0, &bytes, &len, &now, &end))
        return tf_web_send_text(c, 500, "out of memory");
    size_t n = (size_t)s.width * (size_t)s.height;
    uint8_t *rgb = calloc(n, 3), *rgba = malloc(n * 4 + 1);
    int ok = rgb && rgba && tf_paint_raster_apply(rgb, s.width, s.height, bytes, len) == 0;
    for (size_t i = 0; ok && i < n; i++) {
        memcpy(rgba + 4 * i, rgb + 3 * i, 3);
        rgba[4 * i + 3] = 255;
    }
    ok = ok && tf_png_encode_rgba(rgba, s.width, s.height, &png, &png_len) == 0;
    free(bytes);
    free(rgb);
    free(rgba);
    if (!ok)
        return tf_web_send_text(c, 500, "cannot draw the picture");
    enum MHD_Result r = tf_web_send_bytes(c, 200, "image/png", png, png_len);
    free(png);
    return r;
}

static enum MHD_Result serve_get(tf_paint_http *h, struct MHD_Connection *c, const char *url)
{
    for (size_t i = 0; i < sizeof h->files / sizeof h->files[0]; i++)
        if (!strcmp(url, h->files[i].url) || (i == 0 && !strcmp(url, "/")))
            return tf_web_send_bytes(c, 200, h->files[i].type, h->files[i].data, h->files[i].len);
    if (!strcmp(url, "/api/paint/status"))
        return tf_web_send_json(c, 200, status_json(h));
    if (!strcmp(url, "/api/paint/updates"))
        return serve_updates(h, c);
    if (!strcmp(url, "/api/paint/image.png"))
        return serve_image(h, c);
    if (!strcmp(url, "/api/paint/scene")) {
        char *text = tf_paint_hub_scene_text(h->cfg.hub);
        enum MHD_Result r = text ? tf_web_send_bytes(c, 200, "text/plain; charset=utf-8", text,
                                                     strlen(text))
                                 : tf_web_send_text(c, 503, "no view yet");
        free(text);
        return r;
    }
    return tf_web_send_text(c, 404, "no such page");
}

/* ---- controls ---- */

static enum MHD_Result queue(tf_paint_http *h, struct MHD_Connection *c, tf_paint_cmd *cmd)
{
    if (tf_paint_hub_command(h->cfg.hub, cmd))
        return tf_web_send_text(c, 503, "too many controls waiting; try again");
    return tf_web_send_json(c, 202, json_pack("{s:b}", "queued", 1));
}

static enum MHD_Result post_view(tf_paint_http *h, struct MHD_Connection *c, json_t *doc)
{
    char err[512];
    char *text = tf_paint_view_text(h->cfg.base, doc, err, sizeof err);
    if (!text)
        return tf_web_send_text(c, 400, "%s", err);
    tf_paint_cmd cmd = {TF_PAINT_CMD_VIEW, text, {0, 0, 0, 0}};
    return queue(h, c, &cmd);
}

static enum MHD_Result post_interest(tf_paint_http *h, struct MHD_Connection *c, json_t *doc)
{
    tf_paint_status s;
    tf_paint_hub_status(h->cfg.hub, &s);
    json_int_t v[4] = {0, 0, 0, 0};
    static const char *const keys[4] = {"x", "y", "w", "h"};
    int given = 0;
    for (int k = 0; k < 4; k++) {
        json_t *j = json_object_get(doc, keys[k]);
        if (j && (!json_is_integer(j) || json_integer_value(j) < 0 ||
                  json_integer_value(j) > 65536))
            return tf_web_send_text(c, 400, "%s must be a whole number of pixels", keys[k]);
        given += j != NULL;
        v[k] = j ? json_integer_value(j) : 0;
    }
    if (given != 0 && given != 4)
        return tf_web_send_text(c, 400, "an area is x, y, w and h, or nothing to clear it");
    if (v[0] >= s.width || v[1] >= s.height)
        v[2] = 0; /* outside the picture: no area */
    tf_paint_cmd cmd = {TF_PAINT_CMD_INTEREST, NULL, {(int)v[0], (int)v[1], (int)v[2], (int)v[3]}};
    return queue(h, c, &cmd);
}

/* Write the view's scene to --save: beside it first, then renamed over it. */
static enum MHD_Result post_save(tf_paint_http *h, struct MHD_Connection *c)
{
    if (!h->cfg.save)
        return tf_web_send_text(c, 409, "nowhere to save: start terrafarm paint with --save FILE");
    char *text = tf_paint_hub_scene_text(h->cfg.hub);
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", h->cfg.save);
    FILE *f = text ? fopen(tmp, "w") : NULL;
    int ok = f && fputs(text, f) >= 0;
    ok = f && fflush(f) == 0 && fsync(fileno(f)) == 0 && ok;
    if (f && fclose(f) != 0)
        ok = 0;
    ok = ok && rename(tmp, h->cfg.save) == 0;
    int e = errno;
    free(text);
    if (!ok) {
        remove(tmp);
        return tf_web_send_text(c, 500, "%s: cannot write: %s", h->cfg.save, strerror(e));
    }
    tf_info("the view's scene was saved to %s", h->cfg.save);
    return tf_web_send_json(c, 200, json_pack("{s:s}", "saved", h->cfg.save));
}

/* The view as a job on the standing farm of --farm. */
static enum MHD_Result post_submit(tf_paint_http *h, struct MHD_Connection *c)
{
    if (!h->cfg.farm)
        return tf_web_send_text(c, 409, "no farm: start terrafarm paint with --farm HOST:PORT, "
                                        "or save the scene and run terrafarm render");
    if (h->cfg.base->heightmap)
        return tf_web_send_text(c, 409, "a height-map scene is submitted with its file: save "
                                        "it and run terrafarm submit");
    char *text = tf_paint_hub_scene_text(h->cfg.hub), err[512];
    json_t *req = json_pack("{s:s,s:s,s:[]}", "scene", text ? text : "", "name", "painted",
                            "options");
    free(text);
    json_t *a = req ? tf_http_json(h->cfg.farm, "POST", "/api/jobs",
                                   h->have_farm_token ? h->farm_token : NULL, req,
                                   tf_now_ms() + 30000, NULL, err, sizeof err)
                    : NULL;
    json_decref(req);
    if (!a)
        return tf_web_send_text(c, 502, "%s", req ? err : "out of memory");
    tf_info("the view was submitted to the farm at %s as job %lld", h->cfg.farm,
            (long long)json_integer_value(json_object_get(a, "id")));
    return tf_web_send_json(c, 200, a);
}

static enum MHD_Result serve_post(tf_paint_http *h, struct MHD_Connection *c, const char *url,
                                  tf_web_body *rq)
{
    json_error_t jerr;
    json_t *doc = rq->len ? json_loadb(rq->data, rq->len, 0, &jerr) : json_object();
    if (!doc || !json_is_object(doc)) {
        json_decref(doc);
        return tf_web_send_text(c, 400, "the body must be a JSON object");
    }
    enum MHD_Result r;
    tf_paint_cmd cmd = {0, NULL, {0, 0, 0, 0}};
    if (!strcmp(url, "/api/paint/view"))
        r = post_view(h, c, doc);
    else if (!strcmp(url, "/api/paint/interest"))
        r = post_interest(h, c, doc);
    else if (!strcmp(url, "/api/paint/pause") || !strcmp(url, "/api/paint/resume")) {
        cmd.kind = !strcmp(url, "/api/paint/pause") ? TF_PAINT_CMD_PAUSE : TF_PAINT_CMD_RESUME;
        r = queue(h, c, &cmd);
    } else if (!strcmp(url, "/api/paint/save"))
        r = post_save(h, c);
    else if (!strcmp(url, "/api/paint/submit"))
        r = post_submit(h, c);
    else
        r = tf_web_send_text(c, 404, "no such control");
    json_decref(doc);
    return r;
}

static enum MHD_Result handle(void *cls, struct MHD_Connection *c, const char *url,
                              const char *method, const char *version, const char *upload,
                              size_t *upload_size, void **con_cls)
{
    (void)version;
    tf_paint_http *h = cls;
    enum MHD_Result ret;
    tf_web_body *rq = tf_web_collect(c, con_cls, upload, upload_size, &ret);
    if (!rq)
        return ret;
    int g = tf_web_gate(c, url, method, h->have_token ? h->token : NULL, h->loopback, &ret);
    return g == TF_WEB_GET    ? serve_get(h, c, url)
           : g == TF_WEB_POST ? serve_post(h, c, url, rq)
                              : ret;
}

/* ---- start and stop ---- */

static int load_tokens(tf_paint_http *h, const char *spec, char *err, size_t errlen)
{
    const tf_paint_http_config *cfg = &h->cfg;
    h->loopback = tf_listen_is_loopback(spec);
    if (cfg->token_file) {
        if (tf_http_token_load(cfg->token_file, h->token, sizeof h->token, err, errlen))
            return -1;
        h->have_token = 1;
    } else if (cfg->key) {
        if (tf_http_token_derive(cfg->key, h->token, sizeof h->token))
            return tf_seterr(err, errlen, "cannot derive the page's token");
        h->have_token = 1;
    } else if (!h->loopback) {
        return tf_seterr(err, errlen, "--http %s is not a loopback address: the page there needs "
                         "a token (--http-token-file FILE, or --secret-file FILE)", spec);
    }
    const char *ft = cfg->farm_token_file ? cfg->farm_token_file : getenv("TERRAFARM_TOKEN_FILE");
    if (cfg->farm && ft) {
        if (tf_http_token_load(ft, h->farm_token, sizeof h->farm_token, err, errlen))
            return -1;
        h->have_farm_token = 1;
    }
    return 0;
}

static int load_page(tf_paint_http *h, char *err, size_t errlen)
{
    h->files[0] = (web_file){"/paint.html", "paint.html", "text/html; charset=utf-8", NULL, 0};
    h->files[1] = (web_file){"/paint.js", "paint.js", "text/javascript; charset=utf-8", NULL, 0};
    h->files[2] = (web_file){"/paint.css", "paint.css", "text/css; charset=utf-8", NULL, 0};
    char dir[4096];
    if (tf_web_dir_find(dir, sizeof dir))
        return tf_seterr(err, errlen, "the paint page is not installed (web/paint.html): set "
                                      "TERRAFARM_WEB or run make install");
    for (size_t i = 0; i < sizeof h->files / sizeof h->files[0]; i++)
        if (tf_web_load_file(dir, h->files[i].name, &h->files[i].data, &h->files[i].len, err,
                             errlen))
            return -1;
    return 0;
}

static int start_daemon(tf_paint_http *h, int fd, char *err, size_t errlen)
{
    sigset_t block, old; /* the server's threads never take the loop's signals */
    sigemptyset(&block);
    sigaddset(&block, SIGINT);
    sigaddset(&block, SIGTERM);
    sigaddset(&block, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &block, &old);
    h->mhd = MHD_start_daemon(
        MHD_USE_THREAD_PER_CONNECTION | MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_POLL, 0, NULL,
        NULL, handle, h, MHD_OPTION_LISTEN_SOCKET, fd, MHD_OPTION_CONNECTION_LIMIT,
        (unsigned)MAX_CONNECTIONS, MHD_OPTION_PER_IP_CONNECTION_LIMIT, (unsigned)MAX_PER_IP,
        MHD_OPTION_CONNECTION_TIMEOUT, 15u, MHD_OPTION_CONNECTION_MEMORY_LIMIT,
        (size_t)(32 * 1024), MHD_OPTION_NOTIFY_COMPLETED, tf_web_request_done, NULL, MHD_OPTION_END);
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    if (!h->mhd) {
        close(fd);
        return tf_seterr(err, errlen, "cannot start the paint page's server on port %d", h->port);
    }
    return 0;
}

tf_paint_http *tf_paint_http_start(const tf_paint_http_config *cfg, char *err, size_t errlen)
{
    tf_paint_http *h = calloc(1, sizeof *h);
    if (!h) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    h->cfg = *cfg;
    const char *spec = cfg->listen ? cfg->listen : "127.0.0.1:0";
    int fd = -1;
    if (load_tokens(h, spec, err, errlen) || load_page(h, err, errlen) ||
        (fd = tf_sock_listen(spec, &h->port, err, errlen)) < 0 ||
        start_daemon(h, fd, err, errlen)) {
        tf_paint_http_stop(h);
        return NULL;
    }
    tf_info("paint: open http://%s:%d/%s", h->loopback ? "127.0.0.1" : "HOST", h->port,
            h->have_token ? " (token required: open /login?token=...)" : "");
    return h;
}

int tf_paint_http_port(const tf_paint_http *h) { return h->port; }

void tf_paint_http_stop(tf_paint_http *h)
{
    if (!h)
        return;
    if (h->mhd)
        MHD_stop_daemon(h->mhd);
    for (size_t i = 0; i < sizeof h->files / sizeof h->files[0]; i++)
        free(h->files[i].data);
    free(h);
}
