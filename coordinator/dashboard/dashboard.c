/* dashboard.c: see dashboard.h.  Everything here runs in the event-loop thread; the only
 * state shared with the HTTP threads is the hub (snapshot.h). */
#include "coordinator/dashboard/dashboard.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "clock.h"
#include "coordinator/dashboard/httpauth.h"
#include "coordinator/dashboard/httpd.h"
#include "coordinator/render/idmap.h"
#include "coordinator/dashboard/livepreview.h"
#include "farmproto.h"
#include "image/exrfile.h"
#include "linda/sock.h"
#include "log.h"

#define DASH_PUBLISH_MS 200      /* a fresh snapshot at most this often */
#define DASH_WATCHED_S 30.0      /* a reader within this long: snapshots are full */
#define DASH_LINGER_MS 1000      /* at the end, for open event streams to send the final state */
#define PREVIEW_MAX_SIDE 512     /* the live preview's longer side, in pixels */
#define HISTORY_MAX 512          /* throughput samples kept (then halved, interval doubled) */
#define HISTORY_FIRST_INTERVAL_S 0.5
#define RECENT_RATE_WINDOW_S 2.0 /* rays_per_s_recent: over about this long */

typedef struct conn_seen {   /* a connection that spoke: when first and last heard */
    uint64_t conn;
    double first_s, last_s;  /* since the render started */
} conn_seen;

typedef struct worker_seen { /* per worker id, outliving its connection */
    int64_t id;
    double since_s, last_s;
    int dropped;
} worker_seen;

typedef struct conn_owner {  /* connection -> worker id, sorted by conn for bsearch */
    uint64_t conn;
    int64_t worker;
} conn_owner;

struct tf_dashboard {
    tf_dash_hub hub;
    int hub_ok;
    tf_httpd *httpd;
    int listen_fd, port, loopback;
    char host[256];
    char token[TF_HTTP_TOKEN_MAX + 1];
    int have_token;
    char web_dir[4096];
    int have_web;
    tf_events *events;
    tf_livepreview *preview;
    ts_server_hooks inner;
    tf_supervisor *sup;
    ts_server *srv;
    const tf_tasks *tasks;
    conn_seen *conns;
    int nconns, capconns;
    worker_seen *wseen;
    int nwseen, capwseen;
    tf_idmap wseen_index;    /* worker id -> its entry of wseen (capture looks up every worker) */
    tf_snap_sample *hist;
    int nhist;
    double hist_interval_s, hist_last_s;
    double rate_t, rate_prev_t;
    uint64_t rate_rays, rate_prev_rays;
    double last_publish_s;
    uint64_t version;
    tf_run_state state;
    int exit_status;
    int stop_requested;
    char url[300];
    /* static facts */
    double t_start, start_unix_s;
    char scene[512], output[1024], tasks_desc[64];
    int width, height, first_row;
    int frames_total, rows_total, rows_at_start;
    int frame, frames_done;          /* tf_dashboard_frames */
};

static double since_start(const tf_dashboard *d) { return tf_now_s() - d->t_start; }

static void publish(tf_dashboard *d, int rows_written, int block, int full);

/* ---- open ----------------------------------------------------------------------------------- */

static int seed_row(void *user, int y, const tf_pixel *row)
{
    tf_dashboard *d = user;
    if (y >= d->first_row)
        return 1; /* enough: the rest is rendered by this run */
    tf_livepreview_put_row(d->preview, y, row);
    return 0;
}

/* What the dashboard says of the render from the start: its names, size and clocks. */
static void describe_render(tf_dashboard *d, const tf_dashboard_config *cfg)
{
    d->exit_status = -1;
    d->t_start = cfg->t_start;
    struct timespec now;
    clock_gettime(CLOCK_REALTIME, &now);
    d->start_unix_s = (double)now.tv_sec + now.tv_nsec * 1e-9 - (tf_now_s() - cfg->t_start);
    snprintf(d->scene, sizeof d->scene, "%s", cfg->scene ? cfg->scene : "");
    snprintf(d->output, sizeof d->output, "%s", cfg->output ? cfg->output : "");
    snprintf(d->tasks_desc, sizeof d->tasks_desc, "%s", cfg->tasks_desc ? cfg->tasks_desc : "");
    d->width = cfg->width;
    d->height = cfg->height;
    d->first_row = cfg->first_row;
    d->frames_total = cfg->frames_total;
    d->rows_total = cfg->rows_total > 0 ? cfg->rows_total : cfg->height;
    d->rows_at_start = cfg->rows_at_start;
    d->frame = cfg->frames_total >= 0 ? 0 : -1;
    d->frames_done = cfg->frames_total >= 0 ? 0 : -1;
    d->hist_interval_s = HISTORY_FIRST_INTERVAL_S;
    d->hist_last_s = -1e9;
}

/* The address spec (HOST:PORT) checked, and the token: from the token file, else derived from
 * the farm's key, which an address beyond loopback requires.  0 or -1. */
static int choose_address_and_token(tf_dashboard *d, const tf_dashboard_config *cfg,
                                    const char *spec, char *err, size_t errlen)
{
    char port[32], why[256];
    if (!strncmp(spec, "unix:", 5) ||
        tf_split_hostport(spec, d->host, sizeof d->host, port, sizeof port, why, sizeof why))
        return tf_seterr(err, errlen, "--http %s: expected HOST:PORT (a TCP address) or none",
                         spec);
    d->loopback = tf_listen_is_loopback(spec);
    if (cfg->token_file) {
        if (tf_http_token_load(cfg->token_file, d->token, sizeof d->token, err, errlen))
            return -1;
        d->have_token = 1;
    } else if (!d->loopback) {
        if (!cfg->farm_key)
            return tf_seterr(err, errlen, "--http %s is not a loopback address: the dashboard "
                             "there needs a token (--http-token-file FILE, or --secret-file FILE "
                             "to derive one)", spec);
        if (tf_http_token_derive(cfg->farm_key, d->token, sizeof d->token))
            return tf_seterr(err, errlen, "cannot derive the dashboard token");
        d->have_token = 1;
    }
    return 0;
}

/* The listening socket at spec; where the default address was asked for and its port is taken
 * (another render?), any free port of that host.  0 or -1. */
static int listen_at(tf_dashboard *d, const char *spec, int is_default, char *err,
                     size_t errlen)
{
    d->listen_fd = tf_sock_listen(spec, &d->port, err, errlen);
    if (d->listen_fd < 0 && is_default) {
        char fallback[300];
        snprintf(fallback, sizeof fallback, "%s:0", d->host);
        d->listen_fd = tf_sock_listen(fallback, &d->port, err, errlen);
    }
    if (d->listen_fd < 0) {
        char why[512];
        snprintf(why, sizeof why, "%s", err);
        return tf_seterr(err, errlen, "--http: %s", why);
    }
    return 0;
}

/* The events, the live preview (seeded with the rows a resumed render already has) and the
 * history.  0 or -1. */
static int start_live_state(tf_dashboard *d, const tf_dashboard_config *cfg, char *err,
                            size_t errlen)
{
    d->events = tf_events_new();
    d->preview = tf_livepreview_new(cfg->width, cfg->height, PREVIEW_MAX_SIDE);
    d->hist = calloc(HISTORY_MAX, sizeof *d->hist);
    if (!d->events || !d->preview || !d->hist || tf_hub_init(&d->hub))
        return tf_seterr(err, errlen, "out of memory");
    d->hub_ok = 1;
    tf_livepreview_frame(d->preview, cfg->first_frame); /* so its first results keep the seed */
    if (cfg->resume_exr && cfg->first_row > 0) {
        tf_exr_meta meta;
        int rows = cfg->first_row;
        char e[512];
        if (tf_exr_read_rows(cfg->resume_exr, &meta, &rows, seed_row, d, e, sizeof e) &&
            rows < cfg->first_row)
            tf_debug("dashboard: the resumed rows are not in the live preview: %s", e);
    }
    return 0;
}

tf_dashboard *tf_dashboard_open(const tf_dashboard_config *cfg, char *err, size_t errlen)
{
    tf_dashboard *d = calloc(1, sizeof *d);
    if (!d) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    d->listen_fd = -1;
    describe_render(d, cfg);
    const char *spec = cfg->http ? cfg->http : TF_DEFAULT_HTTP;
    if (choose_address_and_token(d, cfg, spec, err, errlen))
        goto fail;
    d->have_web = tf_web_dir_find(d->web_dir, sizeof d->web_dir) == 0;
    if (!d->have_web)
        tf_warn("the dashboard's page (web/index.html) was not found beside the executable or "
                "in PREFIX/share/terrafarm/web (set TERRAFARM_WEB): serving the JSON API only");
    if (listen_at(d, spec, !cfg->http, err, errlen) || start_live_state(d, cfg, err, errlen))
        goto fail;
    return d;
fail:
    tf_dashboard_close(d);
    return NULL;
}

/* ---- watching the traffic ---------------------------------------------------------------- */

static int find_conn(const tf_dashboard *d, uint64_t conn)
{
    int lo = 0, hi = d->nconns;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (d->conns[mid].conn < conn)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

static void heard(tf_dashboard *d, uint64_t conn)
{
    double t = since_start(d);
    int i = find_conn(d, conn);
    if (i < d->nconns && d->conns[i].conn == conn) {
        d->conns[i].last_s = t;
        return;
    }
    if (d->nconns == d->capconns) {
        int cap = d->capconns ? 2 * d->capconns : 32;
        conn_seen *n = realloc(d->conns, (size_t)cap * sizeof *n);
        if (!n)
            return; /* the table is for display only */
        d->conns = n;
        d->capconns = cap;
    }
    memmove(&d->conns[i + 1], &d->conns[i], (size_t)(d->nconns - i) * sizeof *d->conns);
    d->conns[i] = (conn_seen){conn, t, t};
    d->nconns++;
}

static worker_seen *seen_worker(tf_dashboard *d, int64_t id)
{
    int64_t at;
    if (id != 0 && tf_idmap_get(&d->wseen_index, (uint64_t)id, &at))
        return &d->wseen[at];
    /* not indexed (new, or the index ran out of memory): once per worker, not per snapshot */
    for (int i = 0; i < d->nwseen; i++)
        if (d->wseen[i].id == id) {
            if (id != 0)
                tf_idmap_put(&d->wseen_index, (uint64_t)id, i);
            return &d->wseen[i];
        }
    if (d->nwseen == d->capwseen) {
        int cap = d->capwseen ? 2 * d->capwseen : 32;
        worker_seen *n = realloc(d->wseen, (size_t)cap * sizeof *n);
        if (!n)
            return NULL;
        d->wseen = n;
        d->capwseen = cap;
    }
    if (id != 0)
        tf_idmap_put(&d->wseen_index, (uint64_t)id, d->nwseen);
    worker_seen *w = &d->wseen[d->nwseen++];
    *w = (worker_seen){id, -1, -1, 0};
    return w;
}

/* Copy what is known of a live worker's connection into its per-id record. */
static void note_worker_conn(tf_dashboard *d, int64_t id, uint64_t conn)
{
    int i = find_conn(d, conn);
    if (i >= d->nconns || d->conns[i].conn != conn)
        return;
    worker_seen *w = seen_worker(d, id);
    if (!w)
        return;
    if (w->since_s < 0)
        w->since_s = d->conns[i].first_s;
    w->last_s = d->conns[i].last_s;
}

static void tap_take(void *ctx, uint64_t conn, const tf_tuple *tuple)
{
    tf_dashboard *d = ctx;
    if (d->inner.on_take)
        d->inner.on_take(d->inner.ctx, conn, tuple);
    heard(d, conn);
}

/* A result the supervisor has just accepted: paste its preview blob (the worker's sRGB preview
 * of the rectangle, farmproto.h) -- no pixel is decoded here.  In a sequence the preview shows
 * the newest frame with results: a result of a later frame starts it afresh, and late results
 * of an earlier one are left out. */
static void draw_result(tf_dashboard *d, const tf_tuple *tuple)
{
    tf_result_msg m;
    tf_rect r;
    int frame;
    if (!d->sup || tf_result_unpack(tuple, &m) || tf_supervisor_last_accepted(d->sup) != m.id ||
        tf_supervisor_task_rect(d->sup, m.id, &r, &frame))
        return; /* refused or dropped by the supervisor: never drawn */
    if (frame < d->preview->frame)
        return;
    tf_livepreview_frame(d->preview, frame);
    tf_livepreview_put_share(d->preview, r, m.preview, m.preview_len);
}

static void tap_out(void *ctx, uint64_t conn, const tf_tuple *tuple)
{
    tf_dashboard *d = ctx;
    if (d->inner.on_out)
        d->inner.on_out(d->inner.ctx, conn, tuple);
    heard(d, conn);
    const char *name = tf_tuple_name(tuple);
    if (name && !strcmp(name, TF_TAG_RESULT))
        draw_result(d, tuple);
}

static void tap_disconnect(void *ctx, uint64_t conn, const char *peer)
{
    tf_dashboard *d = ctx;
    if (d->sup) {
        const tf_farm_stats *st = tf_supervisor_stats(d->sup);
        for (int i = 0; i < st->nworkers; i++)
            if (st->workers[i].conn == conn)
                note_worker_conn(d, st->workers[i].id, conn);
    }
    if (d->inner.on_disconnect)
        d->inner.on_disconnect(d->inner.ctx, conn, peer);
    int i = find_conn(d, conn);
    if (i < d->nconns && d->conns[i].conn == conn) {
        memmove(&d->conns[i], &d->conns[i + 1], (size_t)(d->nconns - i - 1) * sizeof *d->conns);
        d->nconns--;
    }
}

ts_server_hooks tf_dashboard_hooks(tf_dashboard *d, ts_server_hooks inner)
{
    d->inner = inner;
    ts_server_hooks h = {d, tap_take, tap_out, tap_disconnect};
    return h;
}

tf_events *tf_dashboard_events(tf_dashboard *d) { return d ? d->events : NULL; }

void tf_dashboard_attach(tf_dashboard *d, tf_supervisor *sup, ts_server *srv, const tf_tasks *tasks)
{
    d->sup = sup;
    d->srv = srv;
    d->tasks = tasks;
}

const char *tf_dashboard_url(const tf_dashboard *d) { return d ? d->url : ""; }

int tf_dashboard_serve(tf_dashboard *d, char *err, size_t errlen)
{
    tf_httpd_config hc = {d->listen_fd, d->port, d->loopback, d->have_token ? d->token : NULL,
                          d->have_web ? d->web_dir : NULL, &d->hub};
    d->listen_fd = -1; /* the server owns it now, whatever happens */
    d->httpd = tf_httpd_start(&hc, err, errlen);
    if (!d->httpd)
        return -1;
    const char *h = d->host[0] ? d->host : "0.0.0.0";
    int v6 = strchr(h, ':') != NULL;
    snprintf(d->url, sizeof d->url, "http://%s%s%s:%d/", v6 ? "[" : "", h, v6 ? "]" : "",
             d->port);
    tf_info("dashboard at %s%s", d->url,
            d->have_token ? " (token required: Authorization: Bearer, or open /login?token=...)"
                          : "");
    publish(d, d->rows_at_start, 1, 1);
    return 0;
}

/* ---- snapshots ---------------------------------------------------------------------------- */

static int cmp_owner(const void *a, const void *b)
{
    uint64_t x = ((const conn_owner *)a)->conn, y = ((const conn_owner *)b)->conn;
    return x < y ? -1 : x > y;
}

static int64_t owner_of(const conn_owner *owners, int n, uint64_t conn)
{
    conn_owner key = {conn, 0};
    const conn_owner *o = bsearch(&key, owners, (size_t)n, sizeof *owners, cmp_owner);
    return o ? o->worker : -1;
}

static void sample_history(tf_dashboard *d, double t, uint64_t rays, double busy, int rows,
                           int live)
{
    /* the end is always sampled: a render shorter than the interval still has its rate */
    if (t - d->hist_last_s < d->hist_interval_s && d->state < TF_RUN_FINISHED)
        return;
    if (d->nhist == HISTORY_MAX) { /* keep every other sample, sample half as often */
        for (int i = 0; i < HISTORY_MAX / 2; i++)
            d->hist[i] = d->hist[2 * i + 1];
        d->nhist = HISTORY_MAX / 2;
        d->hist_interval_s *= 2;
    }
    d->hist[d->nhist++] = (tf_snap_sample){t, rays, busy, rows, live};
    d->hist_last_s = t;
}

/* What the render is and how far it has come, with the time left (-1: unknown). */
static void capture_progress(const tf_dashboard *d, tf_snapshot *s, int rows_written, double t)
{
    s->state = d->state;
    s->exit_status = d->exit_status;
    memcpy(s->scene, d->scene, sizeof s->scene);
    memcpy(s->output, d->output, sizeof s->output);
    memcpy(s->tasks_desc, d->tasks_desc, sizeof s->tasks_desc);
    s->width = d->width;
    s->height = d->height;
    s->frame = d->frame;
    s->frames_total = d->frames_total;
    s->frames_done = d->frames_done;
    s->preview_frame = d->preview->frame;
    s->rows_written = rows_written;
    s->rows_total = d->rows_total;
    s->rows_at_start = d->rows_at_start;
    s->start_unix_s = d->start_unix_s;
    s->elapsed_s = t;
    int done_now = rows_written - d->rows_at_start;
    s->eta_s = d->state != TF_RUN_RENDERING ? (rows_written >= d->rows_total ? 0 : -1)
               : done_now > 0              ? t * (d->rows_total - rows_written) / done_now
                                           : -1;
    s->first_row = d->first_row;
    if (d->tasks) {
        s->task_w = d->tasks->tw;
        s->task_h = d->tasks->th;
        s->task_cols = d->tasks->cols;
        s->tasks_total = d->tasks->count;
    }
}

/* The farm's totals from the supervisor: rays and their rates (the recent one over about
 * RECENT_RATE_WINDOW_S), samples, the watermark, tasks and workers. */
static void capture_farm_totals(tf_dashboard *d, tf_snapshot *s, const tf_farm_stats *st,
                                double t)
{
    s->tasks_total = st->tasks_total; /* over every frame of a sequence */
    s->rays_total = st->primary_rays + st->shadow_rays;
    s->rays_per_s = t > 0 ? (double)s->rays_total / t : 0;
    if (t - d->rate_t >= RECENT_RATE_WINDOW_S) {
        d->rate_prev_t = d->rate_t;
        d->rate_prev_rays = d->rate_rays;
        d->rate_t = t;
        d->rate_rays = s->rays_total;
    }
    s->rays_per_s_recent = t - d->rate_prev_t > 0.1
                               ? (double)(s->rays_total - d->rate_prev_rays) / (t - d->rate_prev_t)
                               : s->rays_per_s;
    s->spp_avg = st->pixels ? st->spp_sum / (double)st->pixels : 0;
    s->watermark = tf_supervisor_watermark(d->sup);
    s->watermark_min = d->tasks ? d->tasks->cols : 1;
    s->watermark_max = tf_supervisor_watermark_max(d->sup);
    s->outstanding = tf_supervisor_outstanding(d->sup);
    s->max_outstanding = st->max_outstanding_tasks;
    s->tasks_redealt = st->tasks_redealt;
    s->task_failures = st->task_failures;
    s->live_workers = tf_supervisor_live_workers(d->sup);
    s->joined_workers = tf_supervisor_joined_workers(d->sup);
}

/* The worker on each open connection, sorted by connection for owner_of (NULL: out of
 * memory), each connection noted as its worker's; *busy gets every worker's busy time. */
static conn_owner *connection_owners(tf_dashboard *d, const tf_farm_stats *st, int *n,
                                     double *busy)
{
    conn_owner *owners = calloc((size_t)st->nworkers + 1, sizeof *owners);
    *n = 0;
    *busy = 0;
    for (int i = 0; owners && i < st->nworkers; i++) {
        *busy += st->workers[i].busy_s;
        if (st->workers[i].conn) {
            owners[(*n)++] = (conn_owner){st->workers[i].conn, st->workers[i].id};
            note_worker_conn(d, st->workers[i].id, st->workers[i].conn);
        }
    }
    if (owners)
        qsort(owners, (size_t)*n, sizeof *owners, cmp_owner);
    return owners;
}

/* The n outstanding tasks of views: each one's rectangle, frame, and the worker holding it. */
static void capture_tasks(const tf_dashboard *d, tf_snapshot *s, const tf_task_view *views,
                          int n, const conn_owner *owners, int nowners)
{
    for (int i = 0; i < n; i++) {
        tf_snap_task *o = &s->tasks[i];
        o->id = views[i].id;
        if (tf_supervisor_task_rect(d->sup, views[i].id, &o->rect, &o->frame))
            o->rect = (tf_rect){0, 0, 0, 0}, o->frame = -1;
        o->done = views[i].has_result;
        o->worker = views[i].holder_conn ? owner_of(owners, nowners, views[i].holder_conn) : -1;
    }
    s->ntasks = n;
}

/* Every worker the farm has seen: its counts, the task it holds (from the n views), when it
 * was heard, and its state. */
static void capture_workers(tf_dashboard *d, tf_snapshot *s, const tf_farm_stats *st,
                            const tf_task_view *views, int n)
{
    /* connection -> a task it holds (the pairs reused: .worker holds a task id) */
    conn_owner *held = malloc((size_t)(n > 0 ? n : 1) * sizeof *held);
    int nheld = 0;
    for (int i = 0; held && i < n; i++)
        if (views[i].holder_conn && !views[i].has_result)
            held[nheld++] = (conn_owner){views[i].holder_conn, views[i].id};
    if (held)
        qsort(held, (size_t)nheld, sizeof *held, cmp_owner);
    for (int i = 0; i < st->nworkers; i++) {
        const tf_worker_stats *w = &st->workers[i];
        tf_snap_worker *o = &s->workers[i];
        o->id = w->id;
        memcpy(o->kind, w->kind, sizeof o->kind);
        memcpy(o->host, w->host, sizeof o->host);
        memcpy(o->backend, w->backend, sizeof o->backend);
        o->tasks = w->tasks;
        o->rays = w->rays;
        o->busy_s = w->busy_s;
        o->holding = w->conn && held ? owner_of(held, nheld, w->conn) : -1;
        worker_seen *ws = seen_worker(d, w->id);
        o->since_s = ws ? ws->since_s : -1;
        o->last_heard_s = ws ? ws->last_s : -1;
        o->state = !w->conn ? (ws && ws->dropped ? TF_WS_DROPPED : TF_WS_LEFT)
                   : o->holding >= 0 ? TF_WS_BUSY
                                     : TF_WS_IDLE;
    }
    s->nworkers = st->nworkers;
    free(held);
}

/* The supervisor's part of a snapshot: totals always; the lists of tasks and workers only
 * when full (someone reads them), else just the write front. */
static void capture_farm(tf_dashboard *d, tf_snapshot *s, int rows_written, double t, int full)
{
    const tf_farm_stats *st = tf_supervisor_stats(d->sup);
    capture_farm_totals(d, s, st, t);
    int nowners;
    double busy;
    conn_owner *owners = connection_owners(d, st, &nowners, &busy);
    sample_history(d, t, s->rays_total, busy, rows_written, s->live_workers);
    int cap = s->outstanding > 0 ? s->outstanding : 1;
    tf_task_view *views = full ? malloc((size_t)cap * sizeof *views) : NULL;
    s->tasks = full ? malloc((size_t)cap * sizeof *s->tasks) : NULL;
    s->workers = full ? calloc((size_t)st->nworkers + 1, sizeof *s->workers) : NULL;
    if (!full) /* the lists of tasks and workers wait for a reader too */
        tf_supervisor_task_views(d->sup, &s->tasks_written, NULL, 0);
    if (views && s->tasks && s->workers && owners) {
        int64_t write_task = 0;
        int n = tf_supervisor_task_views(d->sup, &write_task, views, cap);
        s->tasks_written = write_task;
        capture_tasks(d, s, views, n, owners, nowners);
        capture_workers(d, s, st, views, n);
    }
    free(views);
    free(owners);
}

/* What only a reader needs, costly to copy: the events, the throughput history and the
 * preview. */
static void capture_for_reader(const tf_dashboard *d, tf_snapshot *s)
{
    s->events = malloc(TF_EVENTS_MAX * sizeof *s->events);
    if (s->events)
        s->nevents = tf_events_since(d->events, 0, s->events, TF_EVENTS_MAX);
    s->samples = malloc((size_t)(d->nhist ? d->nhist : 1) * sizeof *s->samples);
    if (s->samples) {
        memcpy(s->samples, d->hist, (size_t)d->nhist * sizeof *s->samples);
        s->nsamples = d->nhist;
    }
    size_t pbytes = (size_t)d->preview->w * d->preview->h * 4;
    s->preview_rgba = malloc(pbytes);
    if (s->preview_rgba) {
        memcpy(s->preview_rgba, d->preview->rgba, pbytes);
        s->preview_w = d->preview->w;
        s->preview_h = d->preview->h;
        s->preview_version = d->preview->version;
        s->preview_stamps = d->preview->stamps;
    }
}

/* A snapshot of the render now; a partial one (!full: nobody watches) leaves out the lists,
 * the events and the preview. */
static tf_snapshot *capture(tf_dashboard *d, int rows_written, int full)
{
    tf_snapshot *s = calloc(1, sizeof *s);
    if (!s)
        return NULL;
    double t = since_start(d);
    s->version = ++d->version;
    capture_progress(d, s, rows_written, t);
    if (d->sup)
        capture_farm(d, s, rows_written, t, full);
    s->partial = !full;
    if (full)
        capture_for_reader(d, s);
    return s;
}

static void publish(tf_dashboard *d, int rows_written, int block, int full)
{
    tf_snapshot *s = capture(d, rows_written, full);
    if (!s)
        return;
    if (!tf_hub_publish(&d->hub, s, block)) {
        d->version--; /* not seen by anyone: the next one takes its number */
        tf_snapshot_free(s);
        return;
    }
    d->last_publish_s = tf_now_s();
}

/* ---- controls ---------------------------------------------------------------------------- */

static void drop_worker(tf_dashboard *d, int64_t id)
{
    const tf_farm_stats *st = tf_supervisor_stats(d->sup);
    for (int i = 0; i < st->nworkers; i++) {
        if (st->workers[i].id != id || !st->workers[i].conn)
            continue;
        worker_seen *w = seen_worker(d, id);
        if (w)
            w->dropped = 1;
        tf_info("dashboard: dropping worker %" PRId64, id);
        tf_events_add(d->events, TF_EV_CONTROL, id, -1, "worker dropped from the dashboard");
        ts_server_close_conn(d->srv, st->workers[i].conn); /* its tasks are dealt again */
        return;
    }
    tf_events_add(d->events, TF_EV_CONTROL, id, -1, "drop: worker %" PRId64 " is not connected", id);
}

static void run_command(tf_dashboard *d, const tf_command *c)
{
    char err[256];
    switch (c->kind) {
    case TF_CMD_STOP:
        if (!d->stop_requested) {
            tf_info("dashboard: stop requested");
            tf_events_add(d->events, TF_EV_CONTROL, -1, -1, "stop requested from the dashboard");
        }
        d->stop_requested = 1;
        break;
    case TF_CMD_DROP_WORKER:
        drop_worker(d, c->arg);
        break;
    case TF_CMD_WATERMARK:
        if (c->arg > 1 << 30 || tf_supervisor_set_watermark(d->sup, (int)c->arg, err, sizeof err)) {
            tf_events_add(d->events, TF_EV_CONTROL, -1, -1, "watermark not changed: %s", err);
        } else {
            tf_info("dashboard: watermark set to %" PRId64, c->arg);
            tf_events_add(d->events, TF_EV_CONTROL, -1, -1, "watermark set to %" PRId64, c->arg);
        }
        break;
    }
}

void tf_dashboard_frames(tf_dashboard *d, int frame, int frames_done)
{
    if (!d || d->frames_total < 0)
        return;
    d->frame = frame;
    d->frames_done = frames_done;
}

int tf_dashboard_tick(tf_dashboard *d, int rows_written)
{
    if (!d)
        return 0;
    d->state = TF_RUN_RENDERING;
    tf_command cmds[TF_HUB_COMMANDS];
    int n = d->sup ? tf_hub_take_commands(&d->hub, cmds, TF_HUB_COMMANDS) : 0;
    for (int i = 0; i < n; i++)
        run_command(d, &cmds[i]);
    /* A full snapshot only while someone reads them (or one waits for it now): a dashboard
     * nobody watches costs no copies of the preview and the events.  Most turns of the event
     * loop publish nothing: they only look at the request flag, without the hub's lock. */
    int due = n > 0 || (tf_now_s() - d->last_publish_s) * 1000.0 >= DASH_PUBLISH_MS;
    if (!due && !atomic_load(&d->hub.want_full))
        return d->stop_requested;
    int watched = tf_hub_watched(&d->hub, DASH_WATCHED_S);
    if (due || watched == 2)
        publish(d, rows_written, 0, watched > 0);
    return d->stop_requested;
}

void tf_dashboard_end(tf_dashboard *d, tf_run_state state, int exit_status, int rows_written)
{
    if (!d || d->state >= TF_RUN_FINISHED)
        return; /* the first end is the one that counts */
    d->state = state;
    d->exit_status = exit_status;
    tf_events_add(d->events, TF_EV_END, -1, -1, "render %s (exit status %d)",
                  tf_run_state_name(state), exit_status);
    publish(d, rows_written, 1, 1);
}

void tf_dashboard_close(tf_dashboard *d)
{
    if (!d)
        return;
    if (d->state >= TF_RUN_FINISHED)
        tf_httpd_linger(d->httpd, DASH_LINGER_MS); /* pages watching see the end */
    if (d->hub_ok)
        tf_hub_stop(&d->hub);
    tf_httpd_stop(d->httpd);
    if (d->listen_fd >= 0)
        close(d->listen_fd);
    if (d->hub_ok)
        tf_hub_destroy(&d->hub);
    tf_events_free(d->events);
    tf_livepreview_free(d->preview);
    free(d->conns);
    free(d->wseen);
    tf_idmap_free(&d->wseen_index);
    free(d->hist);
    free(d);
}
