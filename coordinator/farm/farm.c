/* farm.c: the standing farm's life (see farm.h): open the state folder and its database, load
 * the queue, serve the API, and in the main loop start the renders workers wait for, reap the
 * ones that end, and forget workers that went silent; on SIGINT/SIGTERM stop the renders and
 * leave every unfinished job queued for the next farm. */
#include "coordinator/farm/farm_internal.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "cachefile.h"
#include "clock.h"
#include "coordinator/farm/jobrun.h"
#include "coordinator/dashboard/httpauth.h"
#include "http_client.h"
#include "linda/auth.h"
#include "linda/sock.h"
#include "log.h"

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static double unix_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + ts.tv_nsec / 1e9;
}

int farm_job_index(const tf_farm *f, int64_t id)
{
    for (int i = 0; i < f->njobs; i++)
        if (f->jobs[i].id == id)
            return i;
    return -1;
}

int farm_after_state(const tf_farm *f, const tf_job *j)
{
    if (!j->after)
        return 0;
    int k = farm_job_index(f, j->after);
    if (k < 0 || !strcmp(f->jobs[k].state, "done"))
        return 0;
    return !strcmp(f->jobs[k].state, "failed") || !strcmp(f->jobs[k].state, "cancelled") ? 2 : 1;
}

#ifndef NDEBUG
int farm_assert_state(const tf_farm *f)
{
    for (int i = 0; i < f->njobs; i++) {
        const farm_run *r = &f->runs[i];
        assert((!r->pid || r->stopping || !strcmp(f->jobs[i].state, "queued")) &&
               "F1: a render runs only for a queued job, or while being stopped");
        int serving = 0;
        for (int w = 0; w < f->nworkers; w++)
            serving += f->workers[w].job == f->jobs[i].id;
        assert(serving == r->workers && "F3: a job counts exactly its live workers");
    }
    for (int w = 0; w < f->nworkers; w++)
        assert((!f->workers[w].job || farm_job_index(f, f->workers[w].job) >= 0) &&
               "F2: a worker serves only a job that exists");
    return 1;
}
#endif

int farm_set_state(tf_farm *f, int i, const char *state, const char *reason, const char *event)
{
    tf_job j = f->jobs[i];
    snprintf(j.state, sizeof j.state, "%s", state);
    snprintf(j.reason, sizeof j.reason, "%s", reason ? reason : "");
    if (!strcmp(state, "done") || !strcmp(state, "failed") || !strcmp(state, "cancelled"))
        j.finished = unix_now();
    char err[512];
    if (tf_farmdb_update(f->db, &j, event, err, sizeof err)) {
        tf_error("%s", err);
        return -1;
    }
    f->jobs[i] = j;
    pthread_cond_broadcast(&f->changed);
    return 0;
}

int farm_append_job(tf_farm *f, const tf_job *j)
{
    if (f->njobs == f->cap) {
        int cap = f->cap ? 2 * f->cap : 64;
        tf_job *nj = realloc(f->jobs, (size_t)cap * sizeof *nj);
        if (!nj)
            return -1;
        f->jobs = nj;
        farm_run *nr = realloc(f->runs, (size_t)cap * sizeof *nr);
        if (!nr)
            return -1;
        f->runs = nr;
        f->cap = cap;
    }
    f->jobs[f->njobs] = *j;
    memset(&f->runs[f->njobs], 0, sizeof f->runs[0]);
    f->njobs++;
    return 0;
}

void farm_stop_render(tf_farm *f, int i, const char *then)
{
    farm_run *r = &f->runs[i];
    snprintf(r->then, sizeof r->then, "%s", then);
    if (!r->stopping && r->pid > 0)
        kill(r->pid, SIGTERM);
    r->stopping = 1;
}

/* ---- the main loop ---- */

/* The job's dashboard token: derived from its key as every render's is (httpauth.h). */
static void job_dashboard_token(const tf_farm *f, const tf_job *j, char out[TF_FARM_TOKEN_HEX])
{
    char secret[TF_FARM_TOKEN_HEX];
    uint8_t key[32];
    out[0] = 0;
    if (!tf_farm_job_secret(f->key, j->id, j->nonce, secret) &&
        !tf_secret_from_bytes(secret, 64, key))
        tf_http_token_derive(key, out, TF_FARM_TOKEN_HEX);
}

/* A paint page's progress: the share of its view's pixels that are exact, or -1. */
static double painted_percent(json_t *st)
{
    json_t *c = json_object_get(st, "counts");
    json_int_t exact = json_integer_value(json_object_get(c, "exact_pixels"));
    json_int_t all = json_integer_value(json_object_get(c, "pixels"));
    return all > 0 && exact >= 0 && exact <= all ? 100.0 * (double)exact / (double)all : -1;
}

/* What the farm asks a running job's page, outside the lock. */
typedef struct progress_probe {
    int64_t id;
    int port, paint;
    char token[TF_FARM_TOKEN_HEX];
    double pct;        /* -1: not known */
    double unwatched;  /* a paint's: since its page was last read; -1: not known */
} progress_probe;

/* One probe's answer (a render that does not answer within 300 ms keeps its last figure). */
static void probe_job(const tf_farm *f, progress_probe *q)
{
    char addr[300], err[256];
    snprintf(addr, sizeof addr, strchr(f->host, ':') ? "[%s]:%d" : "%s:%d", f->host, q->port);
    json_t *st = tf_http_json(addr, "GET", q->paint ? "/api/paint/status" : "/api/status",
                              q->token, NULL, tf_now_ms() + 300, NULL, err, sizeof err);
    json_t *pct = json_object_get(st, "percent"), *idle = json_object_get(st, "unwatched_s");
    q->pct = q->paint ? painted_percent(st) : json_is_number(pct) ? json_number_value(pct) : -1;
    q->unwatched = q->paint && json_is_number(idle) ? json_number_value(idle) : -1;
    json_decref(st);
}

/* A paint job nobody has watched for --paint-idle is closed: it holds its pool's workers. */
static void close_if_unwatched(tf_farm *f, int i, double unwatched_s)
{
    if (unwatched_s * 1000.0 < f->o.paint_idle_ms || strcmp(f->jobs[i].state, "queued"))
        return;
    char why[128];
    snprintf(why, sizeof why, "closed: nobody watched its page for %.0f s", unwatched_s);
    tf_info("job %lld (%s): %s", (long long)f->jobs[i].id, f->jobs[i].name, why);
    if (farm_set_state(f, i, "cancelled", why, "closed unwatched") == 0)
        farm_stop_render(f, i, "cancelled");
}

/* Every running job's progress from its dashboard, asked outside the lock; paint jobs nobody
 * watches closed. */
static void poll_progress(tf_farm *f)
{
    progress_probe q[64];
    int n = 0;
    for (int i = 0; i < f->njobs && n < 64; i++)
        if (f->runs[i].pid && f->runs[i].http_port && !f->runs[i].stopping) {
            q[n] = (progress_probe){.id = f->jobs[i].id, .port = f->runs[i].http_port,
                                    .paint = tf_job_is_paint(&f->jobs[i])};
            memcpy(q[n++].token, f->runs[i].token, sizeof q[0].token);
        }
    pthread_mutex_unlock(&f->lock);
    for (int k = 0; k < n; k++)
        probe_job(f, &q[k]);
    pthread_mutex_lock(&f->lock);
    for (int k = 0; k < n; k++) {
        int i = farm_job_index(f, q[k].id);
        if (i >= 0 && q[k].pct >= 0)
            f->runs[i].percent = q[k].pct;
        if (i >= 0 && q[k].unwatched >= 0 && f->runs[i].pid && !f->runs[i].stopping)
            close_if_unwatched(f, i, q[k].unwatched);
    }
}

/* Write job j's folder and start its render: the pid (0 on failure, err set).  Runs without
 * the farm's lock (the files are fsync'd): j is a copy. */
static pid_t launch(tf_farm *f, const tf_job *j, const char *submit_token, int *port,
                    int *http_port, char *err, size_t errlen)
{
    tf_job_content c;
    pid_t pid = 0;
    tf_jobrun_where at = {f->host, f->api_port, 0, 0};
    if (tf_farmdb_content(f->db, j->id, &c, err, errlen) == 0 &&
        tf_jobrun_prepare(f->o.state_dir, j, &c, f->key, submit_token, err, errlen) == 0)
        pid = tf_jobrun_start(f->exe, f->o.state_dir, j, c.options, &at, err, errlen);
    *port = at.port;
    *http_port = at.http_port;
    tf_job_content_free(&c);
    return pid > 0 ? pid : 0;
}

/* Called with the lock held; releases it while the render is launched. */
static void start_render(tf_farm *f, int i)
{
    tf_job copy = f->jobs[i];
    char err[1024] = "", token[TF_FARM_TOKEN_HEX] = "";
    int port = 0, http_port = 0;
    f->runs[i].want = 0;
    if (tf_job_is_paint(&copy) && tf_farm_token_new(token))
        token[0] = 0; /* no token: the page's Submit is refused, the rest works */
    pthread_mutex_unlock(&f->lock);
    pid_t pid = launch(f, &copy, token[0] ? token : NULL, &port, &http_port, err, sizeof err);
    pthread_mutex_lock(&f->lock);
    i = farm_job_index(f, copy.id); /* jobs are only appended: the same index */
    farm_run *r = &f->runs[i];
    tf_job *j = &f->jobs[i];
    if (!pid) {
        tf_error("job %lld: %s", (long long)j->id, err);
        farm_set_state(f, i, "failed", err, "failed to start");
        return;
    }
    r->pid = pid;
    r->port = port;
    r->http_port = http_port;
    job_dashboard_token(f, j, r->token);
    memcpy(r->submit_token, token, sizeof token);
    r->percent = -1;
    if (strcmp(j->state, "queued")) { /* paused or cancelled meanwhile */
        farm_stop_render(f, i, j->state);
        return;
    }
    j->attempts++;
    if (!j->started)
        j->started = unix_now();
    char ev[64];
    const char *what = tf_job_is_paint(j) ? "paint" : "render";
    snprintf(ev, sizeof ev, "%s started (attempt %d)", what, j->attempts);
    farm_set_state(f, i, j->state, j->reason, ev);
    tf_info("job %lld (%s): %s started on port %d", (long long)j->id, j->name, what, r->port);
}

/* A render ended: what it means for its job. */
static void render_ended(tf_farm *f, int i, int status)
{
    farm_run *r = &f->runs[i];
    tf_job *j = &f->jobs[i];
    char why[512];
    r->pid = 0;
    r->port = 0;
    r->http_port = 0;
    r->closing = 0;
    sodium_memzero(r->submit_token, sizeof r->submit_token);
    for (int w = 0; w < f->nworkers; w++) /* its workers are free now */
        if (f->workers[w].job == j->id) {
            f->workers[w].job = 0;
            r->workers--;
        }
    if (r->stopping) { /* the state was stored when we stopped it, unless a restart */
        r->stopping = 0;
        if (strcmp(j->state, r->then))
            farm_set_state(f, i, r->then, j->reason, r->then);
        return;
    }
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0) {
        r->failures = 0;
        farm_set_state(f, i, "done", "", "done");
        tf_info("job %lld (%s): done", (long long)j->id, j->name);
        return;
    }
    tf_jobrun_last_error(f->o.state_dir, j->id, why, sizeof why);
    if (!why[0])
        snprintf(why, sizeof why, "the render %s %d", WIFEXITED(status) ? "exited with" :
                 "was killed by signal", WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status));
    int usage = WIFEXITED(status) && WEXITSTATUS(status) == 2; /* its input is wrong: final */
    if (usage || ++r->failures >= f->o.max_render_attempts) {
        farm_set_state(f, i, "failed", why, "failed");
        tf_error("job %lld (%s) failed: %s", (long long)j->id, j->name, why);
    } else {
        tf_warn("job %lld (%s): render failed (%s); it starts again", (long long)j->id, j->name, why);
        farm_set_state(f, i, "queued", "", "render failed; queued again");
    }
}

static void reap_renders(tf_farm *f)
{
    int status;
    pid_t pid;
    while ((pid = waitpid(-1, &status, WNOHANG)) > 0)
        for (int i = 0; i < f->njobs; i++)
            if (f->runs[i].pid == pid)
                render_ended(f, i, status);
}

/* A job that waits for a failed or cancelled one fails with it. */
static void fail_orphans(tf_farm *f)
{
    for (int i = 0; i < f->njobs; i++)
        if (!strcmp(f->jobs[i].state, "queued") && !f->runs[i].pid &&
            farm_after_state(f, &f->jobs[i]) == 2) {
            char why[128];
            snprintf(why, sizeof why, "job %lld it waits for did not finish",
                     (long long)f->jobs[i].after);
            farm_set_state(f, i, "failed", why, "dependency failed");
        }
}

/* 1 when a worker of job j's pool is serving some job now: its pool is at work. */
static int pool_busy(const tf_farm *f, const tf_job *j)
{
    for (int w = 0; w < f->nworkers; w++)
        if (f->workers[w].job && !strcmp(f->workers[w].pool, j->pool))
            return 1;
    return 0;
}

/* Start the render of the job next in line ahead of any worker, so a worker moving to it
 * finds it listening (a render's start-up is most of a switch between jobs).  At most one
 * render waits without workers at a time, and only for a pool whose workers are at work. */
static void start_next_ahead(tf_farm *f)
{
    int best = -1;
    for (int i = 0; i < f->njobs; i++) {
        const farm_run *r = &f->runs[i];
        if (r->pid && !r->workers && !r->closing && !r->stopping &&
            !tf_job_is_paint(&f->jobs[i]))
            return; /* one is waiting already (a paint page waits for its person) */
        if (!r->pid && !strcmp(f->jobs[i].state, "queued") && !farm_after_state(f, &f->jobs[i]) &&
            pool_busy(f, &f->jobs[i]) &&
            (best < 0 || f->jobs[i].priority > f->jobs[best].priority))
            best = i;
    }
    if (best >= 0)
        f->runs[best].want = 1;
}

/* A paint job's page opens at once, workers or not: a person is waiting for it.  One whose
 * process keeps failing is failed by render_ended like a render. */
static void start_paint_pages(tf_farm *f)
{
    for (int i = 0; i < f->njobs; i++)
        if (tf_job_is_paint(&f->jobs[i]) && !f->runs[i].pid &&
            !strcmp(f->jobs[i].state, "queued") && !farm_after_state(f, &f->jobs[i]))
            f->runs[i].want = 1;
}

static void main_loop(tf_farm *f)
{
    int64_t next_poll = 0;
    pthread_mutex_lock(&f->lock);
    while (!g_stop) {
        if (tf_now_ms() >= next_poll) {
            next_poll = tf_now_ms() + 1000;
            poll_progress(f);
        }
        reap_renders(f);
        fail_orphans(f);
        start_next_ahead(f);
        start_paint_pages(f);
        for (int i = 0; i < f->njobs; i++)
            if (f->runs[i].want && !f->runs[i].pid && !strcmp(f->jobs[i].state, "queued"))
                start_render(f, i);
        farm_expire_workers(f, tf_now_ms());
        assert(farm_assert_state(f));
        struct timespec until;
        clock_gettime(CLOCK_REALTIME, &until);
        until.tv_nsec += 50 * 1000000L;
        if (until.tv_nsec >= 1000000000L) {
            until.tv_sec++;
            until.tv_nsec -= 1000000000L;
        }
        pthread_cond_timedwait(&f->changed, &f->lock, &until);
    }
    pthread_mutex_unlock(&f->lock);
}

/* Stop every render (SIGTERM, then SIGKILL after 5 s) and wait for them: their jobs stay
 * queued in the database for the next farm. */
static void stop_renders(tf_farm *f)
{
    int64_t deadline = tf_now_ms() + 5000;
    for (int i = 0; i < f->njobs; i++)
        if (f->runs[i].pid > 0)
            kill(f->runs[i].pid, SIGTERM);
    for (int i = 0; i < f->njobs; i++) {
        while (f->runs[i].pid > 0 && waitpid(f->runs[i].pid, NULL, WNOHANG) == 0) {
            if (tf_now_ms() > deadline)
                kill(f->runs[i].pid, SIGKILL);
            usleep(20000);
        }
        f->runs[i].pid = 0;
    }
}

/* ---- setup ---- */

/* One farm per state folder: an exclusive lock on STATE/farm.lock, held for the farm's life. */
static int lock_state(const char *dir)
{
    char path[4200];
    snprintf(path, sizeof path, "%s/farm.lock", dir);
    int fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0) {
        tf_error("%s: cannot open: %s", path, strerror(errno));
        return -1;
    }
    if (flock(fd, LOCK_EX | LOCK_NB)) {
        tf_error("%s: another farm is running on this state folder", dir);
        close(fd);
        return -1;
    }
    return fd;
}

static int open_state(tf_farm *f)
{
    char err[1024], path[4200];
    if (tf_make_private_dirs(f->o.state_dir)) {
        tf_error("%s: cannot create the state folder: %s", f->o.state_dir, strerror(errno));
        return -1;
    }
    snprintf(path, sizeof path, "%s/farm.db", f->o.state_dir);
    f->db = tf_farmdb_open(path, err, sizeof err);
    if (!f->db || tf_farmdb_load(f->db, &f->jobs, &f->njobs, err, sizeof err)) {
        tf_error("%s", err);
        return -1;
    }
    f->cap = f->njobs;
    f->runs = calloc((size_t)(f->njobs ? f->njobs : 1), sizeof *f->runs);
    return f->runs ? 0 : -1;
}

static int load_secret(tf_farm *f)
{
    char err[1024];
    if (!f->o.secret_file) {
        tf_error("farm: --secret-file is required (the workers hold the same file)");
        return -1;
    }
    if (tf_auth_init() || tf_secret_load(f->o.secret_file, f->key, err, sizeof err) ||
        tf_farm_worker_token(f->key, f->worker_token)) {
        tf_error("%s", err);
        return -1;
    }
    return 0;
}

static int setup(tf_farm *f, const tf_farm_opts *o)
{
    f->o = *o;
    if (!f->o.worker_timeout_ms)
        f->o.worker_timeout_ms = 15000;
    if (!f->o.max_failures)
        f->o.max_failures = 3;
    if (!f->o.forgive_ms)
        f->o.forgive_ms = 600000;
    if (!f->o.max_render_attempts)
        f->o.max_render_attempts = 3;
    if (!f->o.paint_idle_ms)
        f->o.paint_idle_ms = 600000;
    char port[32], err[256];
    if (tf_split_hostport(o->listen, f->host, sizeof f->host, port, sizeof port, err,
                          sizeof err)) {
        tf_error("--listen %s: %s", o->listen, err);
        return -1;
    }
    ssize_t n = readlink("/proc/self/exe", f->exe, sizeof f->exe - 1);
    if (n <= 0) {
        tf_error("cannot find this program (/proc/self/exe): %s", strerror(errno));
        return -1;
    }
    f->exe[n] = 0;
    pthread_mutex_init(&f->lock, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_cond_init(&f->changed, &ca);
    return load_secret(f) || open_state(f) ? -1 : 0;
}

static int count_state(const tf_farm *f, const char *state)
{
    int n = 0;
    for (int i = 0; i < f->njobs; i++)
        n += !strcmp(f->jobs[i].state, state);
    return n;
}

int tf_farm_run(const tf_farm_opts *o)
{
    tf_farm *f = calloc(1, sizeof *f);
    char err[1024];
    int lock_fd = -1, rc = 1, port = 0;
    farm_http *http = NULL;
    signal(SIGPIPE, SIG_IGN);
    struct sigaction sa = {.sa_handler = on_signal};
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    if (!f || tf_make_private_dirs(o->state_dir) || (lock_fd = lock_state(o->state_dir)) < 0 ||
        setup(f, o))
        goto out;
    if (!(http = farm_http_start(f, o->listen, &port, err, sizeof err))) {
        tf_error("%s", err);
        goto out;
    }
    f->api_port = port;
    tf_info("farm on http://%s%s%s:%d: %d jobs queued, %d paused, %d done (state %s)",
            strchr(f->host, ':') ? "[" : "", f->host, strchr(f->host, ':') ? "]" : "", port,
            count_state(f, "queued"), count_state(f, "paused"), count_state(f, "done"),
            o->state_dir);
    main_loop(f);
    pthread_mutex_lock(&f->lock);
    f->stop = 1; /* long polls answer now */
    pthread_cond_broadcast(&f->changed);
    pthread_mutex_unlock(&f->lock);
    tf_info("farm stopping: unfinished jobs stay queued in %s", o->state_dir);
    rc = 0;
out:
    farm_http_stop(http);
    if (f) {
        stop_renders(f);
        tf_farmdb_close(f->db);
        free(f->jobs);
        free(f->runs);
        free(f->workers);
        free(f);
    }
    if (lock_fd >= 0)
        close(lock_fd);
    return rc;
}

int tf_farm_add_token(const char *state_dir, const char *name, const char *role)
{
    char err[1024], path[4200], token[TF_FARM_TOKEN_HEX], hash[TF_FARM_TOKEN_HEX];
    if (strcmp(role, "submitter") && strcmp(role, "admin")) {
        tf_error("--role '%s': expected submitter or admin", role);
        return 1;
    }
    if (!name[0] || strlen(name) > 63 || strspn(name, "abcdefghijklmnopqrstuvwxyz"
                                              "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-@") !=
                                           strlen(name)) {
        tf_error("token name '%s': 1 to 63 letters, digits, '.', '_', '-' or '@'", name);
        return 1;
    }
    if (tf_make_private_dirs(state_dir)) {
        tf_error("%s: cannot create the state folder: %s", state_dir, strerror(errno));
        return 1;
    }
    snprintf(path, sizeof path, "%s/farm.db", state_dir);
    tf_farmdb *db = tf_farmdb_open(path, err, sizeof err);
    int rc = !db || tf_farm_token_new(token);
    if (!rc) {
        tf_farm_token_hash(token, hash);
        rc = tf_farmdb_token_add(db, name, role, hash, err, sizeof err) != 0;
    }
    tf_farmdb_close(db);
    if (rc) {
        tf_error("%s", err);
        return 1;
    }
    printf("%s\n", token);
    return 0;
}
