/* httpd.c: see httpd.h.  libmicrohttpd with a thread per connection (an event stream blocks its
 * own thread waiting for the next snapshot), a bounded number of connections, and nothing that
 * reaches beyond the hub. */
#include "coordinator/dashboard/httpd.h"

#include <ctype.h>
#include <errno.h>
#include <inttypes.h>
#include <limits.h>
#include <microhttpd.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "clock.h"
#include "datadir.h"
#include "coordinator/dashboard/api.h"
#include "coordinator/dashboard/httpauth.h"
#include "coordinator/dashboard/livepreview.h"
#include "coordinator/dashboard/webreply.h"
#include "linda/sock.h"
#include "log.h"

#define MAX_CONNECTIONS 32
#define MAX_PER_IP 16
#define CONNECTION_TIMEOUT_S 15    /* idle connections are closed */
#define CONNECTION_MEMORY (32 * 1024) /* request line + headers; larger gets 431 from MHD */
#define STREAM_KEEPALIVE_MS 5000

typedef struct web_file {
    const char *name, *type;
    char *data;
    size_t len;
} web_file;

struct tf_httpd {
    struct MHD_Daemon *mhd;
    tf_dash_hub *hub;
    char token[TF_HTTP_TOKEN_MAX + 1];
    int have_token, loopback, port;
    web_file files[3];
    pthread_mutex_t png_lock;      /* the encoded preview, shared by requests */
    uint64_t png_version;
    uint8_t *png;
    size_t png_len;
    pthread_mutex_t streams_lock;  /* event streams that have not yet sent the final state */
    pthread_cond_t streams_done;
    int streams_open;
};


/* ---- the page's files ---------------------------------------------------------------------- */

int tf_web_dir_find(char *dir, size_t len)
{
    static const char *const beside[] = {"/../web", "/../../web", "/../share/terrafarm/web",
                                         NULL};
    static const char *const fixed[] = {"/usr/local/share/terrafarm/web",
                                        "/usr/share/terrafarm/web", NULL};
    return tf_datadir_find("TERRAFARM_WEB", beside, fixed, "index.html", dir, len) == 0 ? 0 : -1;
}

/* ---- who may ask -------------------------------------------------------------------------- */

static int load_file(const char *dir, web_file *f, char *err, size_t errlen)
{
    return tf_web_load_file(dir, f->name, &f->data, &f->len, err, errlen);
}

/* ---- the API ---------------------------------------------------------------------------------- */

static int parse_u64(const char *s, uint64_t *out)
{
    if (!s || !*s)
        return -1;
    uint64_t v = 0;
    for (; *s; s++) {
        if (!isdigit((unsigned char)*s) || v > (UINT64_MAX - 9) / 10)
            return -1;
        v = v * 10 + (uint64_t)(*s - '0');
    }
    *out = v;
    return 0;
}

static enum MHD_Result serve_preview(tf_httpd *h, struct MHD_Connection *c, const tf_snapshot *s)
{
    if (!s->preview_rgba)
        return tf_web_send_text(c, 503, "no preview yet");
    pthread_mutex_lock(&h->png_lock);
    if (!h->png || h->png_version != s->preview_version) {
        uint8_t *png;
        size_t len;
        if (tf_png_encode_rgba(s->preview_rgba, s->preview_w, s->preview_h, &png, &len) == 0) {
            free(h->png);
            h->png = png;
            h->png_len = len;
            h->png_version = s->preview_version;
        }
    }
    enum MHD_Result ok = h->png ? tf_web_send_bytes(c, 200, "image/png", h->png, h->png_len)
                                : tf_web_send_text(c, 500, "cannot encode the preview");
    pthread_mutex_unlock(&h->png_lock);
    return ok;
}

/* The event stream (text/event-stream): every event after Last-Event-ID (or all kept), then
 * each new one as it is published, with a status event per snapshot and a comment now and then
 * to keep the connection alive. */
typedef struct stream {
    tf_httpd *h;
    int counted;                   /* in h->streams_open */
    int final;                     /* the final state is queued: end after sending it */
    uint64_t last_seq, version;
    char *pending;
    size_t len, off;
} stream;

static int append(stream *st, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static int append(stream *st, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    char *s = NULL;
    int n = vasprintf(&s, fmt, ap);
    va_end(ap);
    if (n < 0)
        return -1;
    char *p = realloc(st->pending, st->len + (size_t)n + 1);
    if (!p) {
        free(s);
        return -1;
    }
    memcpy(p + st->len, s, (size_t)n + 1);
    free(s);
    st->pending = p;
    st->len += (size_t)n;
    return 0;
}

static int append_json(stream *st, uint64_t id, const char *event, json_t *doc)
{
    char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
    json_decref(doc);
    if (!text)
        return -1;
    int rc = id ? append(st, "id: %" PRIu64 "\nevent: %s\ndata: %s\n\n", id, event, text)
                : append(st, "event: %s\ndata: %s\n\n", event, text);
    free(text);
    return rc;
}

static void fill_stream(stream *st)
{
    tf_snapshot *s = tf_hub_acquire(st->h->hub);
    if (!s)
        return;
    st->version = s->version;
    for (int i = 0; i < s->nevents; i++)
        if (s->events[i].seq > st->last_seq) {
            append_json(st, s->events[i].seq, tf_event_kind_name(s->events[i].kind),
                        tf_api_event(s, &s->events[i]));
            st->last_seq = s->events[i].seq;
        }
    append_json(st, 0, "status", tf_api_status(s));
    st->final = s->state != TF_RUN_STARTING && s->state != TF_RUN_RENDERING;
    tf_hub_release(st->h->hub, s);
}

static void stream_uncount(stream *st)
{
    if (!st->counted)
        return;
    st->counted = 0;
    pthread_mutex_lock(&st->h->streams_lock);
    st->h->streams_open--;
    pthread_mutex_unlock(&st->h->streams_lock);
    pthread_cond_broadcast(&st->h->streams_done);
}

static ssize_t stream_read(void *cls, uint64_t pos, char *buf, size_t max)
{
    (void)pos;
    stream *st = cls;
    while (st->off == st->len) {
        if (st->final) { /* the render's end has been sent: the stream is over */
            stream_uncount(st);
            return MHD_CONTENT_READER_END_OF_STREAM;
        }
        free(st->pending);
        st->pending = NULL;
        st->len = st->off = 0;
        int w = tf_hub_wait(st->h->hub, st->version, STREAM_KEEPALIVE_MS);
        if (w < 0)
            return MHD_CONTENT_READER_END_OF_STREAM;
        if (w == 0)
            append(st, ": keepalive\n\n");
        else
            fill_stream(st);
        if (st->len == 0 && w > 0)
            return MHD_CONTENT_READER_END_WITH_ERROR; /* out of memory */
    }
    size_t n = st->len - st->off < max ? st->len - st->off : max;
    memcpy(buf, st->pending + st->off, n);
    st->off += n;
    return (ssize_t)n;
}

static void stream_free(void *cls)
{
    stream *st = cls;
    stream_uncount(st);
    free(st->pending);
    free(st);
}

static enum MHD_Result serve_stream(tf_httpd *h, struct MHD_Connection *c)
{
    stream *st = calloc(1, sizeof *st);
    if (!st)
        return tf_web_send_text(c, 500, "out of memory");
    st->h = h;
    pthread_mutex_lock(&h->streams_lock);
    h->streams_open++;
    pthread_mutex_unlock(&h->streams_lock);
    st->counted = 1;
    const char *last = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Last-Event-ID");
    uint64_t v;
    if (last && parse_u64(last, &v) == 0)
        st->last_seq = v;
    append(st, "retry: 2000\n\n");
    fill_stream(st);
    struct MHD_Response *r =
        MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 4096, stream_read, st, stream_free);
    if (!r) {
        stream_free(st);
        return MHD_NO;
    }
    MHD_add_response_header(r, "Content-Type", "text/event-stream");
    tf_web_headers(r);
    enum MHD_Result ok = MHD_queue_response(c, 200, r);
    MHD_destroy_response(r);
    return ok;
}

static enum MHD_Result serve_get(tf_httpd *h, struct MHD_Connection *c, const char *url)
{
    for (size_t i = 0; i < sizeof h->files / sizeof h->files[0]; i++) {
        const web_file *f = &h->files[i];
        if (!f->data)
            continue;
        if (!strcmp(url + 1, f->name) || (!strcmp(url, "/") && !strcmp(f->name, "index.html")))
            return tf_web_send_bytes(c, 200, f->type, f->data, f->len);
    }
    if (!strcmp(url, "/") || !strcmp(url, "/index.html"))
        return tf_web_send_text(c, 404, "the dashboard's page is not installed (web/index.html); the "
                                 "JSON API is at /api/status");
    if (!strcmp(url, "/api/events/stream"))
        return serve_stream(h, c);
    tf_snapshot *s = tf_hub_acquire(h->hub);
    if (!s)
        return tf_web_send_text(c, 503, "the render is starting");
    enum MHD_Result ok;
    if (!strcmp(url, "/api/status"))
        ok = tf_web_send_json(c, 200, tf_api_status(s));
    else if (!strcmp(url, "/api/workers"))
        ok = tf_web_send_json(c, 200, tf_api_workers(s));
    else if (!strcmp(url, "/api/tasks"))
        ok = tf_web_send_json(c, 200, tf_api_tasks(s));
    else if (!strcmp(url, "/api/history"))
        ok = tf_web_send_json(c, 200, tf_api_history(s));
    else if (!strcmp(url, "/api/preview.png"))
        ok = serve_preview(h, c, s);
    else if (!strcmp(url, "/api/events")) {
        const char *a = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "after");
        uint64_t after = 0;
        if (a && parse_u64(a, &after))
            ok = tf_web_send_text(c, 400, "after=%s: expected an event number", a);
        else
            ok = tf_web_send_json(c, 200, tf_api_events(s, after));
    } else
        ok = tf_web_send_text(c, 404, "no such page: %s", url);
    tf_hub_release(h->hub, s);
    return ok;
}

/* A control asked for by a POST: the command to queue and what to answer, or the refusal
 * (status, detail). */
typedef struct control {
    tf_command cmd;
    const char *ok_msg; /* NULL: no command */
    int status;         /* 0, or the HTTP status of a refusal */
    char detail[160];
} control;

static void refuse(control *ctl, int status, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static void refuse(control *ctl, int status, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ctl->detail, sizeof ctl->detail, fmt, ap);
    va_end(ap);
    ctl->status = status;
}

/* /api/workers/ID/drop: a connected worker's id. */
static void control_drop(const tf_snapshot *s, const char *url, control *ctl)
{
    const char *name = url + 13, *slash = strchr(name, '/');
    char idtext[32];
    uint64_t v;
    if (!slash || strcmp(slash, "/drop") || slash - name >= (long)sizeof idtext) {
        ctl->status = 404;
        return;
    }
    snprintf(idtext, sizeof idtext, "%.*s", (int)(slash - name), name);
    if (parse_u64(idtext, &v) || v > INT64_MAX) {
        refuse(ctl, 400, "worker '%s': expected a worker id", idtext);
        return;
    }
    int64_t id = (int64_t)v;
    int live = 0;
    for (int i = 0; i < s->nworkers; i++)
        live |= s->workers[i].id == id &&
                (s->workers[i].state == TF_WS_BUSY || s->workers[i].state == TF_WS_IDLE);
    if (!live)
        refuse(ctl, 404, "no connected worker %" PRId64, id);
    ctl->cmd = (tf_command){TF_CMD_DROP_WORKER, id};
    ctl->ok_msg = "dropping the worker: its task is dealt again";
}

/* /api/watermark {"watermark": N}: N within the render's bounds. */
static void control_watermark(const tf_snapshot *s, const tf_web_body *rq, control *ctl)
{
    json_error_t jerr;
    json_t *doc = json_loadb(rq->data, rq->len, JSON_REJECT_DUPLICATES, &jerr);
    json_t *v = doc ? json_object_get(doc, "watermark") : NULL;
    if (!json_is_integer(v)) {
        refuse(ctl, 400, "expected a JSON body {\"watermark\": N}");
    } else if (json_integer_value(v) < s->watermark_min ||
               json_integer_value(v) > s->watermark_max) {
        refuse(ctl, 400,
               "watermark %" JSON_INTEGER_FORMAT " is outside %d (one band of tasks) .. %d",
               json_integer_value(v), s->watermark_min, s->watermark_max);
    } else {
        ctl->cmd = (tf_command){TF_CMD_WATERMARK, (int64_t)json_integer_value(v)};
        ctl->ok_msg = "watermark changing";
    }
    json_decref(doc);
}

/* The control a POST to url asks for, while the render runs. */
static void read_control(const tf_snapshot *s, const char *url, const tf_web_body *rq,
                         control *ctl)
{
    if (s->state != TF_RUN_RENDERING && s->state != TF_RUN_STARTING)
        refuse(ctl, 409, "the render has ended (%s)", tf_run_state_name(s->state));
    else if (!strcmp(url, "/api/stop"))
        *ctl = (control){{TF_CMD_STOP, 0},
                         "stopping: the rows on disk stay; continue with --resume", 0, ""};
    else if (!strncmp(url, "/api/workers/", 13))
        control_drop(s, url, ctl);
    else if (!strcmp(url, "/api/watermark"))
        control_watermark(s, rq, ctl);
    else
        ctl->status = 404;
}

/* POST /api/stop, /api/workers/ID/drop, /api/watermark {"watermark": N}. */
static enum MHD_Result serve_post(tf_httpd *h, struct MHD_Connection *c, const char *url,
                                  tf_web_body *rq)
{
    tf_snapshot *s = tf_hub_acquire(h->hub);
    if (!s)
        return tf_web_send_text(c, 503, "the render is starting");
    control ctl = {{TF_CMD_STOP, 0}, NULL, 0, ""};
    read_control(s, url, rq, &ctl);
    tf_hub_release(h->hub, s);
    if (ctl.status == 404 && !ctl.detail[0])
        return tf_web_send_text(c, 404, "no such control: %s", url);
    if (ctl.status || !ctl.ok_msg)
        return tf_web_send_text(c, ctl.status ? (unsigned)ctl.status : 500, "%s", ctl.detail);
    if (tf_hub_push_command(h->hub, ctl.cmd))
        return tf_web_send_text(c, 503, "too many controls queued; try again");
    json_t *o = json_object();
    json_object_set_new(o, "ok", json_true());
    json_object_set_new(o, "message", json_string(ctl.ok_msg));
    return tf_web_send_json(c, 202, o);
}

static enum MHD_Result handle(void *cls, struct MHD_Connection *c, const char *url,
                              const char *method, const char *version, const char *upload,
                              size_t *upload_size, void **con_cls)
{
    (void)version;
    tf_httpd *h = cls;
    enum MHD_Result ret;
    tf_web_body *rq = tf_web_collect(c, con_cls, upload, upload_size, &ret);
    if (!rq)
        return ret;
    int g = tf_web_gate(c, url, method, h->have_token ? h->token : NULL, h->loopback, &ret);
    return g == TF_WEB_GET    ? serve_get(h, c, url)
           : g == TF_WEB_POST ? serve_post(h, c, url, rq)
                              : ret;
}

static void mhd_log(void *cls, const char *fmt, va_list ap)
{
    (void)cls;
    char buf[512];
    vsnprintf(buf, sizeof buf, fmt, ap);
    size_t n = strlen(buf);
    while (n && buf[n - 1] == '\n')
        buf[--n] = 0;
    tf_debug("dashboard: %s", buf);
}

/* The dashboard's three files, read from web_dir when given (else served from memory).
 * 0, or -1 with one line. */
static int load_files(tf_httpd *h, const char *web_dir, char *err, size_t errlen)
{
    h->files[0] = (web_file){"index.html", "text/html; charset=utf-8", NULL, 0};
    h->files[1] = (web_file){"dashboard.js", "text/javascript; charset=utf-8", NULL, 0};
    h->files[2] = (web_file){"dashboard.css", "text/css; charset=utf-8", NULL, 0};
    for (size_t i = 0; web_dir && i < sizeof h->files / sizeof h->files[0]; i++)
        if (load_file(web_dir, &h->files[i], err, errlen))
            return -1;
    return 0;
}

/* libmicrohttpd on the listening socket, a thread per connection.  Its threads inherit the
 * signal mask set here: they never take SIGINT or SIGTERM, so an interrupt always reaches the
 * event loop's thread (and wakes its poll). */
static struct MHD_Daemon *start_daemon(tf_httpd *h, int listen_fd)
{
    sigset_t block, old;
    sigemptyset(&block);
    sigaddset(&block, SIGINT);
    sigaddset(&block, SIGTERM);
    sigaddset(&block, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &block, &old);
    struct MHD_Daemon *d = MHD_start_daemon(
        MHD_USE_THREAD_PER_CONNECTION | MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_POLL |
            MHD_USE_ERROR_LOG,
        0, NULL, NULL, handle, h, MHD_OPTION_LISTEN_SOCKET, listen_fd,
        MHD_OPTION_CONNECTION_LIMIT, (unsigned)MAX_CONNECTIONS, MHD_OPTION_PER_IP_CONNECTION_LIMIT,
        (unsigned)MAX_PER_IP, MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)CONNECTION_TIMEOUT_S,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)CONNECTION_MEMORY,
        MHD_OPTION_NOTIFY_COMPLETED, tf_web_request_done, NULL, MHD_OPTION_EXTERNAL_LOGGER, mhd_log,
        NULL, MHD_OPTION_END);
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    return d;
}

tf_httpd *tf_httpd_start(const tf_httpd_config *cfg, char *err, size_t errlen)
{
    tf_httpd *h = calloc(1, sizeof *h);
    if (!h) {
        close(cfg->listen_fd);
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    h->hub = cfg->hub;
    h->loopback = cfg->loopback;
    h->port = cfg->port;
    if (cfg->token) {
        snprintf(h->token, sizeof h->token, "%s", cfg->token);
        h->have_token = 1;
    }
    pthread_mutex_init(&h->png_lock, NULL);
    pthread_mutex_init(&h->streams_lock, NULL);
    pthread_cond_init(&h->streams_done, NULL);
    if (load_files(h, cfg->web_dir, err, errlen) == 0) {
        h->mhd = start_daemon(h, cfg->listen_fd);
        if (h->mhd)
            return h;
        tf_seterr(err, errlen, "cannot start the dashboard's HTTP server on port %d", cfg->port);
    }
    close(cfg->listen_fd);
    tf_httpd_stop(h);
    return NULL;
}

void tf_httpd_linger(tf_httpd *h, int ms)
{
    if (!h)
        return;
    struct timespec deadline = tf_realtime_in(ms);
    pthread_mutex_lock(&h->streams_lock);
    while (h->streams_open > 0)
        if (pthread_cond_timedwait(&h->streams_done, &h->streams_lock, &deadline) == ETIMEDOUT)
            break;
    pthread_mutex_unlock(&h->streams_lock);
}

void tf_httpd_stop(tf_httpd *h)
{
    if (!h)
        return;
    if (h->mhd)
        MHD_stop_daemon(h->mhd); /* closes the listening socket it was given */
    for (size_t i = 0; i < sizeof h->files / sizeof h->files[0]; i++)
        free(h->files[i].data);
    free(h->png);
    pthread_mutex_destroy(&h->png_lock);
    pthread_mutex_destroy(&h->streams_lock);
    pthread_cond_destroy(&h->streams_done);
    free(h);
}
