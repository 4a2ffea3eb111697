/* farmapi.c: the standing farm's HTTP JSON API (docs/farm-api.yaml), on libmicrohttpd with a
 * thread per connection (a worker's request for a job is a long poll).  Every request names
 * its caller with a bearer token: the workers' token derived from the farm secret, or a
 * person's token (submitter or admin) found by its hash in the database, or a live paint run's
 * (farm_paint.c: it may only submit).  Each route takes the
 * farm's lock and calls farm_jobs.c or farm_workers.c; bodies are bounded and parsed with
 * jansson; nothing a caller sends is trusted beyond what those functions check.
 *
 * It also serves the farm's web view (web/farm.html, farm.js, farm.css): GET /login?token=T
 * puts a person's token in an HttpOnly SameSite=Strict cookie, which the API then accepts as
 * well as the header; a POST authenticated by the cookie alone must carry the header
 * X-Terrafarm-Request: 1, which no cross-site form can send.  Without a cookie, GET / is a
 * login page with no data. */
#include "coordinator/farm/farm_internal.h"

#include <errno.h>
#include <fcntl.h>
#include <microhttpd.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "datadir.h"
#include "linda/sock.h"
#include "log.h"

#define MAX_BODY ((size_t)96 << 20) /* a 64 MiB height map in base64 and its scene */
#define MAX_WORKER_BODY ((size_t)64 << 10) /* a worker's request is a few hundred bytes */
#define MAX_WEB_FILE (1 << 20)
#define COOKIE "tf_farm_token"
#define NWEB 3

/* How a caller proved who it is. */
enum { AUTH_NONE, AUTH_BEARER, AUTH_COOKIE };

typedef struct web_file {
    const char *url, *name, *type;
    char *data;
    size_t len;
} web_file;

struct farm_http {
    tf_farm *f;
    struct MHD_Daemon *mhd;
    web_file web[NWEB]; /* data NULL: not installed */
};

static const char login_page[] =
    "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
    "<title>terrafarm farm: log in</title><link rel=\"stylesheet\" href=\"/farm.css\"></head>"
    "<body class=\"login\"><main><h1>terrafarm farm</h1>"
    "<p>Log in with a farm token (<code>terrafarm farm --add-token NAME</code> prints one).</p>"
    "<form method=\"get\" action=\"/login\"><input type=\"password\" name=\"token\" "
    "autocomplete=\"off\" placeholder=\"token\" required> <button>Log in</button></form>"
    "</main></body></html>\n";

/* A request being read.  Its caller is known from the headers, before any of the body: a
 * stranger's body is not kept at all, a worker's at most MAX_WORKER_BODY. */
typedef struct request_body {
    char *data;
    size_t len, cap, max;
    int too_large;
    int how;        /* AUTH_*, from the headers */
    farm_caller who;
} request_body;

/* On every answer: no caching, no sniffing, no framing, only our own scripts and styles. */
static void security_headers(struct MHD_Response *r)
{
    MHD_add_response_header(r, "Cache-Control", "no-store");
    MHD_add_response_header(r, "X-Content-Type-Options", "nosniff");
    MHD_add_response_header(r, "X-Frame-Options", "DENY");
    MHD_add_response_header(r, "Referrer-Policy", "no-referrer");
    MHD_add_response_header(r, "Content-Security-Policy",
                            "default-src 'self'; img-src 'self' data:; frame-ancestors 'none'; "
                            "form-action 'self'; base-uri 'none'");
}

static enum MHD_Result send_json(struct MHD_Connection *c, int status, json_t *doc)
{
    char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
    json_decref(doc);
    if (!text)
        text = strdup("{\"error\":\"out of memory\"}"), status = 500;
    struct MHD_Response *r = MHD_create_response_from_buffer(
        status == 204 ? 0 : strlen(text), text, MHD_RESPMEM_MUST_FREE);
    if (!r) {
        free(text);
        return MHD_NO;
    }
    MHD_add_response_header(r, "Content-Type", "application/json");
    security_headers(r);
    if (status == 401)
        MHD_add_response_header(r, "WWW-Authenticate", "Bearer realm=\"terrafarm farm\"");
    enum MHD_Result ok = MHD_queue_response(c, (unsigned)status, r);
    MHD_destroy_response(r);
    return ok;
}

static enum MHD_Result send_error(struct MHD_Connection *c, int status, const char *msg)
{
    return send_json(c, status, json_pack("{s:s}", "error", msg));
}

/* A person's token (found by its hash): 1 and *who, or 0. */
static int person_token(tf_farm *f, const char *token, farm_caller *who)
{
    memset(who, 0, sizeof *who);
    if (!token || !*token || strlen(token) > 256)
        return 0;
    char hash[TF_FARM_TOKEN_HEX];
    tf_farm_token_hash(token, hash);
    return tf_farmdb_token_find(f->db, hash, who->name, sizeof who->name, who->role,
                                sizeof who->role) == 1;
}

/* Who is asking: AUTH_BEARER or AUTH_COOKIE and *who, or AUTH_NONE.  A header, when there is
 * one, decides alone; the cookie holds people's tokens only. */
static int authenticate(tf_farm *f, struct MHD_Connection *c, farm_caller *who)
{
    const char *a = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Authorization");
    if (!a)
        return person_token(f, MHD_lookup_connection_value(c, MHD_COOKIE_KIND, COOKIE), who)
                   ? AUTH_COOKIE : AUTH_NONE;
    if (strncmp(a, "Bearer ", 7))
        return AUTH_NONE;
    const char *token = a + 7;
    memset(who, 0, sizeof *who);
    if (strlen(token) == 64 && sodium_memcmp(token, f->worker_token, 64) == 0) {
        snprintf(who->name, sizeof who->name, "worker");
        snprintf(who->role, sizeof who->role, "worker");
        return AUTH_BEARER;
    }
    return person_token(f, token, who) || farm_paint_caller(f, token, who) ? AUTH_BEARER
                                                                           : AUTH_NONE;
}

/* ---- the web view ---- */

static void web_load(web_file *w, const char *dir)
{
    char p[4200];
    snprintf(p, sizeof p, "%s/%s", dir, w->name);
    FILE *in = fopen(p, "rb");
    w->data = in ? malloc(MAX_WEB_FILE) : NULL;
    w->len = w->data ? fread(w->data, 1, MAX_WEB_FILE, in) : 0;
    if (w->data && (ferror(in) || w->len == MAX_WEB_FILE))
        free(w->data), w->data = NULL;
    if (in)
        fclose(in);
    if (!w->data)
        tf_warn("%s: cannot read it: the farm's web view will lack it", p);
}

/* The page's files: beside the executable in a checkout, PREFIX/share/terrafarm/web once
 * installed, or $TERRAFARM_WEB; a farm without them still serves its API. */
static void web_init(farm_http *h)
{
    static const char *const beside[] = {"/../web", "/../../web", "/../share/terrafarm/web",
                                         NULL};
    static const char *const fixed[] = {"/usr/local/share/terrafarm/web",
                                        "/usr/share/terrafarm/web", NULL};
    h->web[0] = (web_file){"/", "farm.html", "text/html; charset=utf-8", NULL, 0};
    h->web[1] = (web_file){"/farm.js", "farm.js", "text/javascript; charset=utf-8", NULL, 0};
    h->web[2] = (web_file){"/farm.css", "farm.css", "text/css; charset=utf-8", NULL, 0};
    char dir[4096];
    if (tf_datadir_find("TERRAFARM_WEB", beside, fixed, "farm.html", dir, sizeof dir)) {
        tf_warn("no web/farm.html found: the farm serves its API without its web view");
        return;
    }
    for (int i = 0; i < NWEB; i++)
        web_load(&h->web[i], dir);
}

static enum MHD_Result send_page(struct MHD_Connection *c, int status, const char *type,
                                 const void *data, size_t len, const char *cookie)
{
    struct MHD_Response *r =
        MHD_create_response_from_buffer(len, (void *)data, MHD_RESPMEM_MUST_COPY);
    if (!r)
        return MHD_NO;
    MHD_add_response_header(r, "Content-Type", type);
    security_headers(r);
    if (cookie) {
        MHD_add_response_header(r, "Set-Cookie", cookie);
        MHD_add_response_header(r, "Location", "/");
    }
    enum MHD_Result ok = MHD_queue_response(c, (unsigned)status, r);
    MHD_destroy_response(r);
    return ok;
}

/* GET /login?token=T: a known person's token becomes the cookie, and the browser goes to /. */
static enum MHD_Result serve_login(tf_farm *f, struct MHD_Connection *c)
{
    const char *t = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "token");
    farm_caller who;
    if (!person_token(f, t, &who))
        return send_page(c, 401, "text/html; charset=utf-8", login_page, strlen(login_page),
                         NULL);
    char cookie[400];
    snprintf(cookie, sizeof cookie, COOKIE "=%s; Path=/; HttpOnly; SameSite=Strict", t);
    tf_info("%s (%s) logged in to the farm's web view", who.name, who.role);
    return send_page(c, 303, "text/plain", "", 0, cookie);
}

/* GET /, /farm.js, /farm.css, /login, /logout; -1 (as MHD_Result): not a page. */
static int serve_web(farm_http *h, struct MHD_Connection *c, const char *url)
{
    farm_caller who;
    if (!strcmp(url, "/login"))
        return serve_login(h->f, c);
    if (!strcmp(url, "/logout"))
        return send_page(c, 303, "text/plain", "", 0,
                         COOKIE "=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0");
    if (!strcmp(url, "/") && authenticate(h->f, c, &who) != AUTH_COOKIE)
        return send_page(c, 200, "text/html; charset=utf-8", login_page, strlen(login_page),
                         NULL);
    for (int i = 0; i < NWEB; i++)
        if (!strcmp(url, h->web[i].url))
            return h->web[i].data ? send_page(c, 200, h->web[i].type, h->web[i].data,
                                              h->web[i].len, NULL)
                                  : send_error(c, 404, "the farm's web view is not installed");
    return -1;
}

/* "/api/jobs/ID[/ACTION]": the id and the action (NULL), or -1. */
static int64_t job_route(const char *url, const char **action)
{
    const char *p = url + strlen("/api/jobs/");
    char *end;
    long long id = strtoll(p, &end, 10);
    if (end == p || id <= 0 || (*end && *end != '/'))
        return -1;
    *action = *end ? end + 1 : NULL;
    return id;
}

static enum MHD_Result serve_output(tf_farm *f, struct MHD_Connection *c, const farm_caller *who,
                                    int64_t id)
{
    const char *fr = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "frame");
    char path[4200], err[512];
    pthread_mutex_lock(&f->lock);
    int code = farm_output_path(f, who, id, fr, path, sizeof path, err, sizeof err);
    pthread_mutex_unlock(&f->lock);
    if (code)
        return send_error(c, code, err);
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (fd < 0 || fstat(fd, &st)) {
        if (fd >= 0)
            close(fd);
        return send_error(c, 404, "the job's output is not there");
    }
    struct MHD_Response *r = MHD_create_response_from_fd((uint64_t)st.st_size, fd);
    if (!r) {
        close(fd);
        return MHD_NO;
    }
    MHD_add_response_header(r, "Content-Type", "image/x-exr");
    security_headers(r);
    enum MHD_Result ok = MHD_queue_response(c, 200, r);
    MHD_destroy_response(r);
    return ok;
}

static json_t *farm_summary(tf_farm *f)
{
    json_t *counts = json_object();
    for (int i = 0; i < f->njobs; i++) {
        const char *s = f->jobs[i].state;
        json_object_set_new(counts, s, json_integer(json_integer_value(json_object_get(counts, s)) + 1));
    }
    return json_pack("{s:s,s:o,s:i}", "version", TF_VERSION, "jobs", counts, "workers",
                     f->nworkers);
}

static json_t *caller_json(const farm_caller *who)
{
    return json_pack("{s:s,s:s}", "name", who->name, "role", who->role);
}

static int known_action(const char *a)
{
    return !strcmp(a, "cancel") || !strcmp(a, "pause") || !strcmp(a, "resume") ||
           !strcmp(a, "priority") || !strcmp(a, "paint");
}

/* A JSON route under the lock: the answer and its status. */
static json_t *route(tf_farm *f, const farm_caller *who, const char *method, const char *url,
                     json_t *body, int *status)
{
    const char *action = NULL;
    int post = !strcmp(method, "POST"), get = !strcmp(method, "GET");
    if (get && !strcmp(url, "/api/farm")) {
        json_t *o = farm_summary(f);
        json_object_set_new(o, "caller", caller_json(who));
        return *status = 200, o;
    }
    if (!strcmp(url, "/api/jobs"))
        return post ? farm_submit(f, who, body, status)
               : get ? farm_list(f, who, status)
                     : farm_error(status, 404, "no such route: %s /api/jobs (GET or POST)", method);
    if (!strncmp(url, "/api/jobs/", 10)) {
        int64_t id = job_route(url, &action);
        if (id < 0)
            return farm_error(status, 404, "no such job");
        if (!action && get)
            return farm_show(f, who, id, status);
        if (action && post && known_action(action))
            return farm_control(f, who, id, action, body, status);
        return farm_error(status, 404, "no such route: %s %s (GET /api/jobs/ID, POST "
                          "/api/jobs/ID/ACTION, GET /api/jobs/ID/output)", method, url);
    }
    if (post && !strcmp(url, "/api/workers/next"))
        return farm_worker_next(f, who, body, status);
    if (post && !strcmp(url, "/api/workers/heartbeat"))
        return farm_worker_heartbeat(f, who, body, status);
    if (get && !strcmp(url, "/api/workers"))
        return strcmp(who->role, "admin") ? farm_error(status, 403, "admins only")
                                          : (*status = 200, farm_workers_json(f));
    return farm_error(status, 404, "no such route: %s %s", method, url);
}

/* Collect the body; 1 while more is coming. */
static int collect(request_body *b, const char *data, size_t *size)
{
    if (!*size)
        return 0;
    if (b->len + *size > b->max)
        b->too_large = 1;
    if (!b->too_large && b->len + *size + 1 > b->cap) {
        size_t cap = (b->len + *size + 1) * 2;
        char *nd = realloc(b->data, cap > b->max + 1 ? b->max + 1 : cap);
        if (!nd)
            b->too_large = 1;
        else
            b->data = nd, b->cap = cap > b->max + 1 ? b->max + 1 : cap;
    }
    if (!b->too_large) {
        memcpy(b->data + b->len, data, *size);
        b->len += *size;
        b->data[b->len] = 0;
    }
    *size = 0;
    return 1;
}

/* An API request from who: the job's output, or a JSON route under the lock. */
static enum MHD_Result serve_api(farm_http *h, struct MHD_Connection *c, const farm_caller *who,
                                 const char *method, const char *url, const request_body *b)
{
    const char *action;
    int64_t id = !strncmp(url, "/api/jobs/", 10) ? job_route(url, &action) : -1;
    if (id > 0 && action && !strcmp(action, "output") && !strcmp(method, "GET"))
        return serve_output(h->f, c, who, id);
    json_error_t jerr;
    json_t *body = b->len ? json_loadb(b->data, b->len, JSON_REJECT_DUPLICATES, &jerr) : NULL;
    if (b->len && !json_is_object(body)) {
        json_decref(body);
        return send_error(c, 400, "the body is not a JSON object");
    }
    int status = 500;
    pthread_mutex_lock(&h->f->lock);
    json_t *answer = route(h->f, who, method, url, body, &status);
    pthread_mutex_unlock(&h->f->lock);
    json_decref(body);
    return send_json(c, status, answer);
}

/* A request the cookie alone authenticates may only read, unless it carries a header that no
 * cross-site form can send. */
static int cookie_request_ok(struct MHD_Connection *c, int how, const char *method)
{
    const char *xr = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "X-Terrafarm-Request");
    return how != AUTH_COOKIE || !strcmp(method, "GET") || (xr && !strcmp(xr, "1"));
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url,
                                  const char *method, const char *version,
                                  const char *upload_data, size_t *upload_size, void **con_cls)
{
    (void)version;
    farm_http *h = cls;
    if (!*con_cls) { /* the headers: who is asking decides how much body is kept */
        request_body *nb = calloc(1, sizeof *nb);
        if (!nb)
            return MHD_NO;
        nb->how = authenticate(h->f, c, &nb->who);
        nb->max = nb->how == AUTH_NONE ? 0 : !strcmp(nb->who.role, "worker") ? MAX_WORKER_BODY
                                                                            : MAX_BODY;
        *con_cls = nb;
        return MHD_YES;
    }
    request_body *b = *con_cls;
    if (collect(b, upload_data, upload_size))
        return MHD_YES;
    int page = !strcmp(method, "GET") || !strcmp(method, "HEAD") ? serve_web(h, c, url) : -1;
    if (page >= 0)
        return (enum MHD_Result)page;
    if (b->how == AUTH_NONE)
        return send_error(c, 401, "give a farm token: Authorization: Bearer TOKEN");
    if (b->too_large)
        return send_error(c, 413, "the request body is too large");
    if (!cookie_request_ok(c, b->how, method))
        return send_error(c, 403, "a request authenticated by the cookie must carry the header "
                                  "X-Terrafarm-Request: 1");
    return serve_api(h, c, &b->who, method, url, b);
}

static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls,
                         enum MHD_RequestTerminationCode toe)
{
    (void)cls, (void)c, (void)toe;
    request_body *b = *con_cls;
    if (b)
        free(b->data);
    free(b);
    *con_cls = NULL;
}

farm_http *farm_http_start(tf_farm *f, const char *listen, int *port, char *err, size_t errlen)
{
    int fd = tf_sock_listen(listen, port, err, errlen);
    if (fd < 0)
        return NULL;
    farm_http *h = calloc(1, sizeof *h);
    if (!h) {
        close(fd);
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    h->f = f;
    web_init(h);
    h->mhd = MHD_start_daemon(MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_THREAD_PER_CONNECTION |
                                  MHD_USE_ERROR_LOG,
                              0, NULL, NULL, on_request, h, MHD_OPTION_LISTEN_SOCKET, fd,
                              MHD_OPTION_NOTIFY_COMPLETED, on_completed, h,
                              MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)60,
                              MHD_OPTION_CONNECTION_LIMIT, (unsigned)1024, MHD_OPTION_END);
    if (!h->mhd) {
        close(fd);
        for (int i = 0; i < NWEB; i++)
            free(h->web[i].data);
        free(h);
        tf_seterr(err, errlen, "%s: cannot start the farm's HTTP server", listen);
        return NULL;
    }
    return h;
}

void farm_http_stop(farm_http *h)
{
    if (!h)
        return;
    MHD_stop_daemon(h->mhd);
    for (int i = 0; i < NWEB; i++)
        free(h->web[i].data);
    free(h);
}
