/* farm_worker.c: see farm_worker.h. */
#include "worker/farm_worker.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include "clock.h"
#include "farm_keys.h"
#include "http_client.h"
#include "linda/auth.h"
#include "linda/sock.h"
#include "linda/tsclient.h"
#include "log.h"
#include "render/render.h"
#include "scene.h"
#include "worker/backend.h"
#include "worker/networked.h"
#include "worker/paint_worker.h"
#include "worker/payloads.h"
#include "worker/simulate.h"
#include "worker/terrain_shelf.h"
#include "worker/worker.h"

#define HEARTBEAT_MS 1000
#define CONNECT_MS 15000
#define MAX_PROCS 256

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

typedef struct farm_worker {
    const tf_farm_worker_opts *o;
    char farm_host[256];
    char token[TF_FARM_TOKEN_HEX];
    uint8_t farm_key[32];
    char name[96];
    tf_terrain_shelf *shelf;
    tf_cost_map map;           /* simulated: the model */
    tf_payloads *payloads;     /* simulated: the recording, or NULL */
    json_t *last;      /* how the last session ended, for the next request */
    int sessions;
    int64_t ended_ms;  /* when the last session's processes were gone (0: none yet) */
} farm_worker;

typedef struct session {
    int64_t job;
    char job_name[128];
    char connect[300];
    uint8_t key[32];
    char terrain[65];
    int paint;         /* a paint job (Raypaint): its processes paint */
} session;

/* ---- talking to the farm ---- */

static json_t *farm_call(farm_worker *fw, const char *path, json_t *body, int timeout_ms,
                         int *code)
{
    char err[1024];
    json_t *a = tf_http_json(fw->o->farm, "POST", path, fw->token, body, tf_now_ms() + timeout_ms,
                             code, err, sizeof err);
    json_decref(body);
    if (!a)
        tf_warn("farm: %s", err);
    return a;
}

/* Ask for a job: 1 and the session, 0 when none came, -1 when the farm cannot be asked. */
static int ask_for_job(farm_worker *fw, session *ss)
{
    const char *keys[16];
    int nk = tf_terrain_shelf_keys(fw->shelf, keys, 16), code = 0;
    json_t *terrains = json_array();
    for (int i = 0; i < nk; i++)
        json_array_append_new(terrains, json_string(keys[i]));
    json_t *req = json_pack("{s:s,s:s,s:s,s:o,s:i}", "name", fw->name, "pool",
                            fw->o->pool ? fw->o->pool : "default", "tags",
                            fw->o->tags ? fw->o->tags : "", "terrains", terrains, "wait_ms",
                            10000);
    if (fw->last)
        json_object_set(req, "last", fw->last);
    json_t *a = farm_call(fw, "/api/workers/next", req, 20000, &code);
    if (!a)
        return -1;
    json_decref(fw->last);
    fw->last = NULL;
    int got = code == 200 && json_integer_value(json_object_get(a, "job")) > 0;
    if (got)
        got = !!(ss->job = json_integer_value(json_object_get(a, "job")));
    const char *nonce = json_string_value(json_object_get(a, "nonce"));
    const char *terrain = json_string_value(json_object_get(a, "terrain"));
    const char *name = json_string_value(json_object_get(a, "name"));
    const char *kind = json_string_value(json_object_get(a, "kind"));
    int port = (int)json_integer_value(json_object_get(a, "port"));
    char secret[TF_FARM_TOKEN_HEX];
    ss->paint = kind && !strcmp(kind, "paint");
    if (got && (!nonce || !terrain || strlen(terrain) != 64 || port <= 0 || port > 65535 ||
                (kind && !ss->paint && strcmp(kind, "render")) ||
                tf_farm_job_secret(fw->farm_key, ss->job, nonce, secret))) {
        tf_warn("farm: a malformed assignment (job %lld); ignored", (long long)ss->job);
        got = 0;
    }
    if (got) {
        snprintf(ss->connect, sizeof ss->connect, strchr(fw->farm_host, ':') ? "[%s]:%d" : "%s:%d",
                 fw->farm_host, port);
        snprintf(ss->terrain, sizeof ss->terrain, "%s", terrain);
        snprintf(ss->job_name, sizeof ss->job_name, "%s", name ? name : "?");
        tf_secret_from_bytes(secret, 64, ss->key);
    }
    json_decref(a);
    return got;
}

/* Heartbeat while serving: 1 to stay, 0 to leave, -1 when the farm did not answer (stay: the
 * job's render is what we serve, the farm may be restarting). */
static int heartbeat(farm_worker *fw, int64_t job)
{
    int code = 0;
    json_t *a = farm_call(fw, "/api/workers/heartbeat",
                          json_pack("{s:s,s:I}", "name", fw->name, "job", (json_int_t)job), 2000,
                          &code);
    if (!a)
        return -1;
    int stay = json_is_true(json_object_get(a, "stay"));
    json_decref(a);
    return stay;
}

static void set_last(farm_worker *fw, int64_t job, const char *outcome)
{
    json_decref(fw->last);
    fw->last = json_pack("{s:I,s:s}", "job", (json_int_t)job, "outcome", outcome);
}

/* ---- one session: a job's terrain, processes, and watching them ---- */

/* Did a connection fail because nothing listens there (ECONNREFUSED's message)? */
static int refused(const char *err) { return strstr(err, "refused") != NULL; }

/* Connect to a job's render.  The farm bound its socket before starting it, so a connection
 * waits in the backlog while the render starts (up to CONNECT_MS for the handshake), and a
 * refused one means the render is gone: no retrying then.  Another failure (the render was
 * stopped with our connection still in its backlog) is tried again only while the farm still
 * sends us to the job: the parent (fw) asks it between tries, so a worker sent to a job that
 * was paused meanwhile moves on at once.  A child (fw NULL) connects right after its parent
 * did, and retries as any networked worker does. */
static ts_client *connect_job(farm_worker *fw, const session *ss, char *err, size_t errlen)
{
    ts_client *c = ts_client_connect(ss->connect, ss->key, CONNECT_MS, err, errlen);
    if (c || refused(err))
        return c;
    if (!fw)
        return tf_networked_connect(ss->connect, ss->key, CONNECT_MS, err, errlen);
    for (int backoff = 250; backoff <= 4000 && heartbeat(fw, ss->job) != 0; backoff *= 2) {
        usleep((useconds_t)backoff * 1000);
        c = ts_client_connect(ss->connect, ss->key, CONNECT_MS, err, errlen);
        if (c || refused(err))
            return c;
    }
    return NULL;
}

/* The job's scene from its render and its terrain (kept or built): the scene, or NULL with
 * *gone set when the render refused the connection (it is not there: our session is lost,
 * not failed, and must not count toward barring us from the job). */
static tf_scene *fetch_job(farm_worker *fw, const session *ss, const tf_heightfield **hf,
                           double *build_s, int *gone)
{
    char err[1024], key[TF_FARM_TOKEN_HEX];
    ts_client *c = connect_job(fw, ss, err, sizeof err);
    *gone = !c && refused(err);
    int kind = TF_SPACE_RENDER, want = ss->paint ? TF_SPACE_PAINT : TF_SPACE_RENDER;
    tf_scene *s = c ? tf_worker_fetch_scene_ex(c, ss->connect, &kind, err, sizeof err) : NULL;
    if (s && (kind != want || tf_farm_terrain_key(s, key) || strcmp(key, ss->terrain)))
        tf_seterr(err, sizeof err, "%s: job %lld's process serves another terrain than the farm "
                  "announced%s", ss->connect, (long long)ss->job,
                  kind != want ? (ss->paint ? " (not a paint)" : " (not a render)") : "");
    else if (s && !(*hf = tf_terrain_shelf_get(fw->shelf, key))) {
        tf_info("job %lld (%s): building its terrain", (long long)ss->job, ss->job_name);
        ts_client_heartbeat(c, TF_WORKER_HEARTBEAT_MS);
        double t0 = tf_now_s();
        tf_heightfield *built = tf_heightfield_build(s, 0, err, sizeof err);
        *build_s = tf_now_s() - t0;
        if (built && fw->o->terrain_cache)
            tf_heightfield_set_cache(built, fw->o->terrain_cache);
        tf_render_prepare(s, built, 0); /* for the job's processes forked from this one */
        if (built)
            tf_terrain_shelf_put(fw->shelf, key, built);
        *hf = built;
    }
    if (c)
        ts_client_close(c);
    if (s && !*hf) {
        tf_scene_free(s);
        s = NULL;
    }
    if (!s)
        tf_error("%s", err);
    return s;
}

static void serve_in_child(const session *ss, const tf_scene *s, const tf_heightfield *hf,
                           const char *backend, pid_t parent)
{
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent)
        _exit(1);
    signal(SIGTERM, SIG_DFL);
    signal(SIGINT, SIG_DFL);
    char err[1024];
    ts_client *c = connect_job(NULL, ss, err, sizeof err);
    if (!c) {
        tf_error("%s", err);
        _exit(TF_WORKER_EXIT_LOST);
    }
    int status = ss->paint ? tf_paint_worker_loop(c, s, hf, "networked")
                           : tf_worker_loop(c, s, hf, "networked", backend);
    ts_client_close(c);
    _exit(status);
}

static int spawn(const farm_worker *fw, const session *ss, const tf_scene *s,
                 const tf_heightfield *hf, pid_t *pids, int n)
{
    pid_t me = getpid();
    const char *backend = fw->o->backend ? fw->o->backend : "c";
    tf_backend_share_cores(backend, n);
    for (int i = 0; i < n; i++) {
        pids[i] = fork();
        if (pids[i] == 0)
            serve_in_child(ss, s, hf, backend, me);
        if (pids[i] < 0) {
            tf_warn("fork: %s; serving with %d processes", strerror(errno), i);
            return i;
        }
    }
    return n;
}

static void kill_all(pid_t *pids, int n)
{
    for (int i = 0; i < n; i++)
        if (pids[i] > 0)
            kill(pids[i], SIGKILL);
}

/* Reap what ended; the number still running.  *worst: the most telling exit seen. */
static int reap(pid_t *pids, int n, int *worst)
{
    int running = 0;
    for (int i = 0; i < n; i++) {
        int st;
        if (pids[i] <= 0)
            continue;
        if (waitpid(pids[i], &st, WNOHANG) != pids[i]) {
            running++;
            continue;
        }
        pids[i] = 0;
        int code = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
        if (code && (code != TF_WORKER_EXIT_LOST || !*worst))
            *worst = code;
    }
    return running;
}

static int owner_present(const tf_owner_watch *ow, char *why, size_t n)
{
    return ow && ow->present(ow->ctx, why, n) == 1;
}

/* Watch the processes until they end, the farm sends us away, the owner comes back or we are
 * stopped: the session's outcome. */
static const char *watch(farm_worker *fw, const session *ss, pid_t *pids, int n)
{
    const tf_owner_watch *ow = fw->o->owner;
    int interval = ow && ow->interval_ms > 0 ? ow->interval_ms : 50, worst = 0;
    int64_t next_beat = tf_now_ms() + HEARTBEAT_MS;
    char why[256];
    while (reap(pids, n, &worst)) {
        if (g_stop) {
            kill_all(pids, n);
            while (reap(pids, n, &worst))
                usleep(1000);
            return "left";
        }
        if (owner_present(ow, why, sizeof why)) {
            int64_t t0 = tf_now_ms();
            kill_all(pids, n);
            while (reap(pids, n, &worst))
                usleep(1000);
            tf_info("owner back (%s): retreated from job %lld in %lld ms", why,
                    (long long)ss->job, (long long)(tf_now_ms() - t0));
            return "retreated";
        }
        if (tf_now_ms() >= next_beat) {
            next_beat = tf_now_ms() + HEARTBEAT_MS;
            if (heartbeat(fw, ss->job) == 0) {
                kill_all(pids, n);
                while (reap(pids, n, &worst))
                    usleep(1000);
                tf_info("the farm sent us away from job %lld", (long long)ss->job);
                return "left";
            }
        }
        usleep((useconds_t)interval * 1000);
    }
    return !worst ? "done" : worst == TF_WORKER_EXIT_LOST ? "lost" : "failed";
}

/* Simulated: the job's size from its render, then a child running the synthetic workers
 * (their report line on stdout).  0 and the child, or -1. */
static int spawn_simulated(farm_worker *fw, const session *ss, pid_t *pid)
{
    char err[1024];
    ts_client *c = connect_job(fw, ss, err, sizeof err);
    tf_scene *s = c ? tf_worker_fetch_scene(c, ss->connect, err, sizeof err) : NULL;
    tf_exr_layout l;
    int fits = s && (!fw->payloads || (tf_worker_fetch_layout(c, &l, err, sizeof err) == 0 &&
                                       tf_payloads_fit(fw->payloads, &l, err, sizeof err) == 0));
    if (c)
        ts_client_close(c);
    if (!fits) {
        tf_error("%s", err);
        tf_scene_free(s);
        return -1;
    }
    tf_sim_config cfg = {ss->connect, ss->key, CONNECT_MS,
                         fw->o->processes > 0 ? fw->o->processes : 16, fw->o->pixel_us, &fw->map,
                         s->width, s->height, fw->payloads};
    tf_scene_free(s);
    pid_t me = getpid();
    if ((*pid = fork()) == 0) {
        prctl(PR_SET_PDEATHSIG, SIGKILL);
        if (getppid() != me)
            _exit(1);
        tf_sim_report r;
        int rc = tf_simulate_run(&cfg, &r, err, sizeof err);
        printf("simulated job=%lld workers=%d tasks=%lld wall_s=%.3f modelled_s=%.3f "
               "efficiency=%.4f bound_efficiency=%.4f take_p99_ms=%.3f\n", (long long)ss->job,
               r.workers, (long long)r.tasks, r.wall_s, r.modelled_s, r.efficiency,
               r.bound_efficiency, r.take_p99_ms);
        fflush(stdout);
        _exit(rc ? TF_WORKER_EXIT_LOST : 0);
    }
    return *pid > 0 ? 0 : -1;
}

static void serve_simulated(farm_worker *fw, const session *ss)
{
    pid_t pid = 0;
    if (spawn_simulated(fw, ss, &pid)) {
        set_last(fw, ss->job, "failed");
        return;
    }
    const char *outcome = watch(fw, ss, &pid, 1);
    tf_info("job %lld (%s): %s (simulated)", (long long)ss->job, ss->job_name, outcome);
    set_last(fw, ss->job, outcome);
}

static void serve(farm_worker *fw, const session *ss)
{
    if (fw->o->simulate_model && ss->paint) {
        tf_warn("job %lld (%s) paints: a simulated worker serves renders only", (long long)ss->job,
                ss->job_name);
        set_last(fw, ss->job, "failed");
        return;
    }
    if (fw->o->simulate_model) {
        serve_simulated(fw, ss);
        return;
    }
    const tf_heightfield *hf = NULL;
    double build_s = -1;
    int gone = 0;
    tf_scene *s = fetch_job(fw, ss, &hf, &build_s, &gone);
    if (!s) {
        set_last(fw, ss->job, gone ? "lost" : "failed");
        fw->ended_ms = tf_now_ms();
        return;
    }
    int n = fw->o->processes > 0 ? fw->o->processes : tf_thread_count(0);
    pid_t pids[MAX_PROCS] = {0};
    n = spawn(fw, ss, s, hf, pids, n > MAX_PROCS ? MAX_PROCS : n);
    char gap[96] = "";
    if (fw->ended_ms)
        snprintf(gap, sizeof gap, "; %lld ms since the last job", (long long)(tf_now_ms() - fw->ended_ms));
    char terrain[64];
    snprintf(terrain, sizeof terrain, build_s < 0 ? "terrain kept" : "terrain built in %.3f s",
             build_s);
    tf_info("serving job %lld (%s) with %d processes (%s%s)", (long long)ss->job, ss->job_name, n,
            terrain, gap);
    const char *outcome = watch(fw, ss, pids, n);
    fw->ended_ms = tf_now_ms();
    tf_info("job %lld (%s): %s", (long long)ss->job, ss->job_name, outcome);
    set_last(fw, ss->job, outcome);
    tf_scene_free(s);
}

/* Wait until the owner has been away for idle_after_ms (or we are stopped). */
static void wait_for_owner_away(const tf_owner_watch *ow)
{
    char why[256];
    int64_t away_since = -1;
    int interval = ow->interval_ms > 0 ? ow->interval_ms : 50, said = 0;
    while (!g_stop) {
        int64_t now = tf_now_ms();
        if (owner_present(ow, why, sizeof why)) {
            if (!said++)
                tf_info("owner present (%s): waiting", why);
            away_since = -1;
        } else if (away_since < 0) {
            away_since = now;
        } else if (now - away_since >= ow->idle_after_ms) {
            if (said)
                tf_info("owner away for %.1f s: asking for work", (now - away_since) / 1000.0);
            return;
        }
        usleep((useconds_t)interval * 1000);
    }
}

static int setup(farm_worker *fw, const tf_farm_worker_opts *o)
{
    char err[1024], port[32], host[200];
    fw->o = o;
    if (!o->secret_file) {
        tf_error("worker: --secret-file is required to serve a farm (the farm's own secret)");
        return -1;
    }
    if (tf_auth_init() || tf_secret_load(o->secret_file, fw->farm_key, err, sizeof err) ||
        tf_farm_worker_token(fw->farm_key, fw->token) ||
        tf_split_hostport(o->farm, fw->farm_host, sizeof fw->farm_host, port, sizeof port, err,
                          sizeof err)) {
        tf_error("%s", err);
        return -1;
    }
    gethostname(host, sizeof host);
    host[sizeof host - 1] = 0;
    snprintf(fw->name, sizeof fw->name, "%s", o->name ? o->name : "");
    if (!o->name)
        snprintf(fw->name, sizeof fw->name, "%.60s:%d", host, (int)getpid());
    size_t budget = o->terrain_memory;
    if (!budget)
        budget = (size_t)sysconf(_SC_PHYS_PAGES) * (size_t)sysconf(_SC_PAGESIZE) / 8;
    fw->shelf = tf_terrain_shelf_new(budget);
    if (o->simulate_model && (tf_cost_map_load(o->simulate_model, &fw->map, err, sizeof err) ||
                              (o->payloads &&
                               !(fw->payloads = tf_payloads_load(o->payloads, err, sizeof err))))) {
        tf_error("%s", err);
        return -1;
    }
    return fw->shelf ? 0 : -1;
}

int tf_farm_worker_run(const tf_farm_worker_opts *o)
{
    farm_worker fw = {0};
    signal(SIGPIPE, SIG_IGN);
    struct sigaction sa = {.sa_handler = on_signal};
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    if (setup(&fw, o))
        return 1;
    tf_info("worker %s serving the farm at %s (pool %s)", fw.name, o->farm,
            o->pool ? o->pool : "default");
    int backoff = 250;
    while (!g_stop && (!o->max_sessions || fw.sessions < o->max_sessions)) {
        if (o->owner)
            wait_for_owner_away(o->owner);
        session ss = {0};
        int got = g_stop ? 0 : ask_for_job(&fw, &ss);
        if (got < 0) { /* the farm is down or restarting: try again, patiently */
            usleep((useconds_t)backoff * 1000);
            backoff = backoff * 2 > 4000 ? 4000 : backoff * 2;
            continue;
        }
        backoff = 250;
        if (got) {
            serve(&fw, &ss);
            fw.sessions++;
        }
    }
    json_decref(fw.last);
    tf_terrain_shelf_free(fw.shelf);
    if (o->simulate_model)
        tf_cost_map_free(&fw.map);
    tf_payloads_free(fw.payloads);
    return 0;
}
