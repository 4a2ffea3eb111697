/* farm_workers.c: what workers do with the standing farm: ask which job to serve (a long
 * poll: the answer comes as soon as a job is servable, its render started if need be), report
 * how their last session ended (a worker whose sessions of one job keep failing is barred from
 * that job for a while, then forgiven), and heartbeat while serving (the answer says whether
 * to stay: a paused, cancelled or finished job, or a higher priority one waiting, sends it
 * away).  Workers are known by the name they give; all of them hold the farm's secret. */
#include "coordinator/farm/farm_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "clock.h"
#include "coordinator/farm/scheduler.h"
#include "log.h"

#define MAX_WAIT_MS 10000
#define FORGET_MS (600 * 1000) /* a worker silent this long is forgotten */

static farm_worker *worker_find(tf_farm *f, const char *name)
{
    for (int i = 0; i < f->nworkers; i++)
        if (!strcmp(f->workers[i].name, name))
            return &f->workers[i];
    if (f->nworkers == f->wcap) {
        int cap = f->wcap ? 2 * f->wcap : 64;
        farm_worker *nw = realloc(f->workers, (size_t)cap * sizeof *nw);
        if (!nw)
            return NULL;
        f->workers = nw;
        f->wcap = cap;
    }
    farm_worker *w = &f->workers[f->nworkers++];
    memset(w, 0, sizeof *w);
    snprintf(w->name, sizeof w->name, "%s", name);
    return w;
}

static void worker_update(farm_worker *w, json_t *req)
{
    const char *pool = json_string_value(json_object_get(req, "pool"));
    const char *tags = json_string_value(json_object_get(req, "tags"));
    json_t *terrains = json_object_get(req, "terrains");
    snprintf(w->pool, sizeof w->pool, "%s", pool && *pool ? pool : "default");
    snprintf(w->tags, sizeof w->tags, "%s", tags ? tags : "");
    w->nterrains = 0;
    for (size_t i = 0; i < json_array_size(terrains) && w->nterrains < FARM_MAX_TERRAINS; i++) {
        const char *t = json_string_value(json_array_get(terrains, i));
        if (t && strlen(t) == 64 && strspn(t, "0123456789abcdef") == 64) /* a terrain key */
            snprintf(w->terrains[w->nterrains++], 65, "%s", t);
    }
    w->seen_ms = tf_now_ms();
}

static void leave_job(tf_farm *f, farm_worker *w)
{
    int i = w->job ? farm_job_index(f, w->job) : -1;
    if (i >= 0)
        f->runs[i].workers--;
    w->job = 0;
}

static void join_job(tf_farm *f, farm_worker *w, int i)
{
    w->job = f->jobs[i].id;
    f->runs[i].workers++;
}

static farm_bar *bar_of(farm_worker *w, int64_t job)
{
    farm_bar *oldest = &w->bars[0];
    for (int i = 0; i < FARM_MAX_BARS; i++) {
        if (w->bars[i].job == job)
            return &w->bars[i];
        if (w->bars[i].until_ms < oldest->until_ms)
            oldest = &w->bars[i];
    }
    memset(oldest, 0, sizeof *oldest);
    oldest->job = job;
    return oldest;
}

/* The worker's last session: done, lost (its render went away), left (told to, or its
 * owner came back), or failed (counts toward a bar). */
static void record_outcome(tf_farm *f, farm_worker *w, json_t *last)
{
    const char *outcome = json_string_value(json_object_get(last, "outcome"));
    json_int_t job = json_integer_value(json_object_get(last, "job"));
    if (!outcome || job <= 0 || job != w->job) /* only the session the farm knows of */
        return;
    w->sessions++;
    w->retreats += !strcmp(outcome, "retreated");
    int i = farm_job_index(f, job);
    if (i >= 0 && !strcmp(outcome, "done") && f->runs[i].pid) /* its render is finishing */
        f->runs[i].closing = 1;
    if (strcmp(outcome, "failed"))
        return;
    farm_bar *b = bar_of(w, job);
    if (++b->failures >= f->o.max_failures) {
        b->failures = 0;
        b->until_ms = tf_now_ms() + f->o.forgive_ms;
        tf_warn("worker %s failed job %lld %d times: barred from it for %d s", w->name,
                (long long)job, f->o.max_failures, f->o.forgive_ms / 1000);
    }
}

static int is_barred(void *ctx, int64_t job)
{
    farm_worker *w = ctx;
    for (int i = 0; i < FARM_MAX_BARS; i++)
        if (w->bars[i].job == job && w->bars[i].until_ms > tf_now_ms())
            return 1;
    return 0;
}

/* The scheduler's view of every job, and of w (terrain pointers into w). */
static tf_sched_job *sched_view(tf_farm *f, farm_worker *w, tf_sched_worker *sw,
                                const char **terrains)
{
    tf_sched_job *v = calloc((size_t)(f->njobs ? f->njobs : 1), sizeof *v);
    for (int i = 0; v && i < f->njobs; i++) {
        v[i].job = &f->jobs[i];
        v[i].workers = f->runs[i].workers;
        v[i].after_state = farm_after_state(f, &f->jobs[i]);
        v[i].closing = f->runs[i].closing;
    }
    for (int i = 0; i < w->nterrains; i++)
        terrains[i] = w->terrains[i];
    *sw = (tf_sched_worker){w->pool, w->tags, terrains, w->nterrains, is_barred, w};
    return v;
}

static int pick_for(tf_farm *f, farm_worker *w)
{
    tf_sched_worker sw;
    const char *terrains[FARM_MAX_TERRAINS];
    tf_sched_job *v = sched_view(f, w, &sw, terrains);
    int i = v ? tf_sched_pick(v, f->njobs, &sw) : -1;
    free(v);
    return i;
}

static int should_leave(tf_farm *f, farm_worker *w, int current)
{
    tf_sched_worker sw;
    const char *terrains[FARM_MAX_TERRAINS];
    tf_sched_job *v = sched_view(f, w, &sw, terrains);
    int leave = v ? tf_sched_should_leave(v, f->njobs, current, &sw) : 0;
    free(v);
    return leave;
}

static void deadline_ts(int64_t ms_from_now, struct timespec *ts)
{
    clock_gettime(CLOCK_REALTIME, ts);
    ts->tv_sec += ms_from_now / 1000;
    ts->tv_nsec += (ms_from_now % 1000) * 1000000L;
    if (ts->tv_nsec >= 1000000000L) {
        ts->tv_sec++;
        ts->tv_nsec -= 1000000000L;
    }
}

static json_t *assignment(tf_farm *f, farm_worker *w, int i)
{
    const tf_job *j = &f->jobs[i];
    join_job(f, w, i);
    f->assignments++;
    return json_pack("{s:I,s:s,s:i,s:s,s:s,s:s,s:i,s:s}", "job", (json_int_t)j->id, "name",
                     j->name, "port", f->runs[i].port, "nonce", j->nonce, "terrain", j->terrain,
                     "scene_hash", j->scene_hash, "priority", j->priority, "kind",
                     j->kind[0] ? j->kind : "render");
}

static int worker_name_ok(const char *name)
{
    size_t n = name ? strlen(name) : 0;
    return n && n < 96 && strspn(name, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                       "0123456789._-:@") == n;
}

json_t *farm_worker_next(tf_farm *f, const farm_caller *who, json_t *req, int *status)
{
    const char *name = json_string_value(json_object_get(req, "name"));
    if (strcmp(who->role, "worker"))
        return farm_error(status, 403, "only workers ask for jobs");
    if (!worker_name_ok(name))
        return farm_error(status, 400, "name: 1 to 95 letters, digits, '.', '_', '-', ':', '@'");
    farm_worker *w = worker_find(f, name);
    if (!w)
        return farm_error(status, 500, "out of memory");
    worker_update(w, req);
    record_outcome(f, w, json_object_get(req, "last"));
    leave_job(f, w);
    json_t *wait = json_object_get(req, "wait_ms");
    int64_t wait_ms = json_is_integer(wait) ? json_integer_value(wait) : MAX_WAIT_MS;
    struct timespec until;
    deadline_ts(wait_ms < 0 ? 0 : wait_ms > MAX_WAIT_MS ? MAX_WAIT_MS : wait_ms, &until);
    for (;;) {
        int i = pick_for(f, w);
        if (i >= 0 && f->runs[i].pid && !f->runs[i].stopping) {
            *status = 200;
            return assignment(f, w, i);
        }
        if (i >= 0 && !f->runs[i].pid) {
            f->runs[i].want = 1;
            pthread_cond_broadcast(&f->changed);
        }
        if (f->stop || pthread_cond_timedwait(&f->changed, &f->lock, &until)) {
            *status = 204;
            return json_object();
        }
        w = worker_find(f, name); /* the array may have moved while we waited */
        w->seen_ms = tf_now_ms();
    }
}

json_t *farm_worker_heartbeat(tf_farm *f, const farm_caller *who, json_t *req, int *status)
{
    const char *name = json_string_value(json_object_get(req, "name"));
    json_int_t job = json_integer_value(json_object_get(req, "job"));
    if (strcmp(who->role, "worker"))
        return farm_error(status, 403, "only workers heartbeat");
    if (!worker_name_ok(name))
        return farm_error(status, 400, "name: 1 to 95 letters, digits, '.', '_', '-', ':', '@'");
    farm_worker *w = worker_find(f, name);
    if (!w)
        return farm_error(status, 500, "out of memory");
    w->seen_ms = tf_now_ms();
    int i = farm_job_index(f, job);
    int stay = i >= 0 && f->runs[i].pid && !f->runs[i].stopping && !should_leave(f, w, i);
    if (stay && w->job != job) { /* a farm restarted under a serving worker: count it again */
        leave_job(f, w);
        join_job(f, w, i);
    } else if (!stay) {
        leave_job(f, w);
    }
    *status = 200;
    return json_pack("{s:b}", "stay", stay);
}

void farm_expire_workers(tf_farm *f, int64_t now_ms)
{
    for (int i = 0; i < f->nworkers; i++) {
        farm_worker *w = &f->workers[i];
        if (w->job && now_ms - w->seen_ms > f->o.worker_timeout_ms) {
            tf_info("worker %s silent for %.1f s: no longer counted on job %lld", w->name,
                    (now_ms - w->seen_ms) / 1000.0, (long long)w->job);
            leave_job(f, w);
        }
        if (!w->job && now_ms - w->seen_ms > FORGET_MS) /* gone: forgotten (bars too) */
            f->workers[i--] = f->workers[--f->nworkers];
    }
}

json_t *farm_workers_json(tf_farm *f)
{
    json_t *arr = json_array();
    int64_t now = tf_now_ms();
    for (int i = 0; i < f->nworkers; i++) {
        farm_worker *w = &f->workers[i];
        json_t *o = json_pack("{s:s,s:s,s:s,s:I,s:f,s:I,s:I,s:i}", "name", w->name, "pool",
                              w->pool, "tags", w->tags, "job", (json_int_t)w->job, "seen_s_ago",
                              (now - w->seen_ms) / 1000.0, "sessions", (json_int_t)w->sessions,
                              "retreats", (json_int_t)w->retreats, "terrains", w->nterrains);
        json_array_append_new(arr, o);
    }
    return json_pack("{s:o,s:I}", "workers", arr, "assignments", (json_int_t)f->assignments);
}
