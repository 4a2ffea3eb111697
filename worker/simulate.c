/* simulate.c: see simulate.h.  The simulated workers (their cost model is cost_map.c): one
 * thread serves every worker's connection from one event loop, all released together from a
 * start line so the measured wall time starts with a full farm. */
#include "worker/simulate.h"
#include "worker/worker.h"
#include "worker/payloads.h"
#include "clock.h"

#include <errno.h>
#include <inttypes.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "farmproto.h"
#include "image/exrencode.h"
#include "log.h"
#include "linda/tsclient.h"

/* A task served: where it is (the dealing order is by y, then x) and its modelled cost. */
typedef struct sim_task {
    int y, x;
    int64_t cost_ns;
} sim_task;

/* ---- simulated workers: one event loop, many connections -------------------------------------
 * Every worker joins first, one after another, with the blocking client; then the start line:
 * each sends its first take, and one thread serves them all.  A worker is WAITING (its result
 * and its next take are out: ts_out_in_send, collected by ts_out_in_poll when its socket is
 * readable), RENDERING (its modelled cost runs out at `due`), PAUSED (it put back a task that
 * excludes it, and asks again at `due`) or DONE (it saw the stop and put it back, or lost the
 * coordinator).  The RENDERING and PAUSED workers sit in a min-heap of their `due` times, and
 * the loop waits in epoll until the earliest (epoll_pwait2: nanoseconds, as a 4 ms task
 * needs).  A thread per worker, as before, cost the shared cores two wake-ups and four system
 * calls a task (~80 us, more than the coordinator's) and woke a sleeping thread on every reply
 * the coordinator sent. */

enum { W_WAITING, W_RENDERING, W_PAUSED, W_DONE };

typedef struct sim_worker {
    ts_client *client;
    int64_t id;
    int state;
    int64_t due_ns;          /* RENDERING, PAUSED: when its cost (or pause) runs out */
    int64_t asked_ns;        /* WAITING: when its take left */
    int64_t task, cost_ns;   /* RENDERING: the task and its modelled cost */
    tf_rect rect;
    int bounces;             /* excluded tasks taken in a row */
} sim_worker;

typedef struct sim_farm {
    const tf_sim_config *cfg;
    sim_worker *ws;
    int n, live;             /* workers; those not DONE */
    int epfd;
    int *heap;               /* indexes of RENDERING and PAUSED workers, a min-heap on due_ns */
    int nheap;
    tf_tuple tmpl;           /* any task */
    tf_exr_layout layout;
    tf_payload_buf buf;      /* the recorded chunks of the task being returned */
    tf_exr_encoder *enc;     /* without a recording: black pixels, encoded */
    tf_pixel *px;
    size_t px_cap;
    unsigned seed;
    int64_t start_ns, first_stop_ns;
    int joined, failed;
    int64_t tasks, ops;
    double modelled_ns, oversleep_ns;
    float *take_ms;          /* dealing latencies */
    size_t ntake, cap_take;
    sim_task *done;          /* every task served, for the schedule bound */
    size_t ndone, cap_done;
    char error[512];
} sim_farm;

static void farm_fail(sim_farm *f, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void farm_fail(sim_farm *f, const char *fmt, ...)
{
    f->failed++;
    if (f->error[0])
        return;
    va_list ap;
    va_start(ap, fmt);
    tf_vseterr(f->error, sizeof f->error, fmt, ap);
    va_end(ap);
}

/* Append one item of `size` bytes to the growing array *dst; if memory runs out it is dropped
 * (a sample lost from a percentile or the bound, nothing else). */
static void append(void **dst, size_t *n, size_t *cap, const void *item, size_t size)
{
    if (*n == *cap) {
        size_t c = *cap ? 2 * *cap : 256;
        void *p = realloc(*dst, c * size);
        if (!p)
            return;
        *dst = p;
        *cap = c;
    }
    memcpy((char *)*dst + *n * size, item, size);
    (*n)++;
}

/* ---- the heap of due times ---- */

static int64_t due_of(const sim_farm *f, int k) { return f->ws[f->heap[k]].due_ns; }

static void heap_swap(sim_farm *f, int a, int b)
{
    int t = f->heap[a];
    f->heap[a] = f->heap[b];
    f->heap[b] = t;
}

static void heap_push(sim_farm *f, int w)
{
    int k = f->nheap++;
    f->heap[k] = w;
    while (k > 0 && due_of(f, (k - 1) / 2) > due_of(f, k)) {
        heap_swap(f, k, (k - 1) / 2);
        k = (k - 1) / 2;
    }
}

static int heap_pop(sim_farm *f)
{
    int top = f->heap[0];
    f->heap[0] = f->heap[--f->nheap];
    for (int k = 0;;) {
        int l = 2 * k + 1, r = l + 1, m = k;
        if (l < f->nheap && due_of(f, l) < due_of(f, m))
            m = l;
        if (r < f->nheap && due_of(f, r) < due_of(f, m))
            m = r;
        if (m == k)
            break;
        heap_swap(f, k, m);
        k = m;
    }
    return top;
}

/* ---- one worker's steps ---- */

static void worker_done(sim_farm *f, sim_worker *w)
{
    w->state = W_DONE;
    f->live--;
    epoll_ctl(f->epfd, EPOLL_CTL_DEL, ts_client_fd(w->client), NULL);
}

/* Its connection failed: once the stop tuple is out the coordinator may finish and close while
 * a worker still waits, or renders a straggler's duplicate; that is the end, not a failure. */
static void worker_lost(sim_farm *f, sim_worker *w, const char *what)
{
    if (f->first_stop_ns == 0)
        farm_fail(f, "%s: %s", what, ts_client_error(w->client));
    worker_done(f, w);
}

/* Send the result (or NULL) and the next take. */
static void ask(sim_farm *f, sim_worker *w, const tf_tuple *result)
{
    w->asked_ns = tf_now_ns();
    w->state = W_WAITING;
    f->ops++;
    if (ts_out_in_send(w->client, result, &f->tmpl))
        worker_lost(f, w, result ? "cannot deliver a result" : "lost the coordinator");
}

/* A blocking out of a task put back, a failure or the stop: rare, so the loop waits for it. */
static int put(sim_farm *f, sim_worker *w, const tf_tuple *t)
{
    f->ops++;
    if (ts_out(w->client, t) == 0)
        return 0;
    worker_lost(f, w, "lost the coordinator");
    return -1;
}

/* The result of w's task: the recorded chunks that stand in for it, or its black pixels. */
static int pack_result(sim_farm *f, sim_worker *w, tf_tuple *result, char *err, size_t errlen)
{
    tf_chunk_payload pay;
    int64_t spp = 0;
    size_t n = (size_t)w->rect.w * (size_t)w->rect.h;
    if (f->cfg->payloads) {
        if (tf_payloads_for(f->cfg->payloads, &f->layout, w->rect, &f->buf, &pay, &spp, err,
                            errlen))
            return -1;
    } else {
        if (n > f->px_cap) {
            tf_pixel *p = realloc(f->px, n * sizeof *p);
            if (!p)
                return tf_seterr(err, errlen, "out of memory");
            f->px = p;
            f->px_cap = n;
        }
        memset(f->px, 0, n * sizeof *f->px);
        if (tf_exr_encode_rect(f->enc, w->rect, f->px, &pay, err, errlen))
            return -1;
    }
    tf_render_counts counts = {.pixels = (uint64_t)n};
    return tf_result_pack(result, w->task, w->id, &counts, w->cost_ns, spp, &pay);
}

/* w's modelled cost has run out: count the task and return its result with the next take. */
static void finish_task(sim_farm *f, sim_worker *w, int64_t now)
{
    f->oversleep_ns += (double)(now - w->due_ns);
    f->modelled_ns += (double)w->cost_ns;
    f->tasks++;
    sim_task done = {w->rect.y, w->rect.x, w->cost_ns};
    append((void **)&f->done, &f->ndone, &f->cap_done, &done, sizeof done);
    char err[512];
    tf_tuple result;
    tf_tuple_init(&result);
    if (pack_result(f, w, &result, err, sizeof err)) {
        farm_fail(f, "task %" PRId64 ": %s", w->task, err);
        worker_done(f, w);
    } else {
        ask(f, w, &result);
    }
    tf_tuple_clear(&result);
}

/* A task tuple has come: start on it, put it back, or stop. */
static void start_task(sim_farm *f, sim_worker *w, tf_tuple *task, int64_t now)
{
    float wait_ms = (float)((double)(now - w->asked_ns) * 1e-6);
    append((void **)&f->take_ms, &f->ntake, &f->cap_take, &wait_ms, sizeof wait_ms);
    tf_task_msg m;
    const char *bad = NULL;
    if (tf_task_unpack(task, &m)) {
        farm_fail(f, "a malformed task tuple");
        worker_done(f, w);
    } else if (m.id == TF_TASK_STOP) {
        if (f->first_stop_ns == 0)
            f->first_stop_ns = now;
        if (put(f, w, task) == 0) /* so every other worker sees it too */
            worker_done(f, w);
    } else if (tf_task_excludes(&m, w->id)) {
        /* Let a worker that may render it take it; pause at random, as worker.c does. */
        if (put(f, w, task) == 0) {
            w->bounces += w->bounces < 4;
            w->due_ns = now + (int64_t)(30 + rand_r(&f->seed) % (60u << w->bounces)) * 1000000;
            w->state = W_PAUSED;
            heap_push(f, w - f->ws);
        }
    } else if ((bad = tf_task_rect_problem(m.rect, f->cfg->image_w, f->cfg->image_h))) {
        farm_fail(f, "task %" PRId64 " (%dx%d at %d,%d): %s", m.id, m.rect.w, m.rect.h, m.rect.x,
                  m.rect.y, bad);
        worker_done(f, w);
    } else {
        w->bounces = 0;
        w->task = m.id;
        w->rect = m.rect;
        w->cost_ns = (int64_t)(f->cfg->pixel_us * 1000.0 *
                               tf_cost_map_rect(f->cfg->map, f->cfg->image_w, f->cfg->image_h,
                                                m.rect));
        w->due_ns = now + w->cost_ns;
        w->state = W_RENDERING;
        heap_push(f, w - f->ws);
    }
}

static void on_readable(sim_farm *f, sim_worker *w)
{
    if (w->state != W_WAITING)
        return;
    tf_tuple task;
    int rc = ts_out_in_poll(w->client, &task);
    if (rc < 0)
        worker_lost(f, w, "lost the coordinator");
    else if (rc > 0)
        start_task(f, w, &task, tf_now_ns());
    tf_tuple_clear(&task);
}

static void on_due(sim_farm *f, sim_worker *w, int64_t now)
{
    if (w->state == W_RENDERING)
        finish_task(f, w, now);
    else if (w->state == W_PAUSED)
        ask(f, w, NULL);
}

/* ---- the loop ---- */

/* Wait for sockets until the earliest due time (or without end), then serve what is ready. */
static int serve_once(sim_farm *f, struct epoll_event *ev, int nev)
{
    struct timespec ts, *timeout = NULL;
    if (f->nheap > 0) {
        int64_t left = due_of(f, 0) - tf_now_ns();
        if (left < 0)
            left = 0;
        ts = (struct timespec){(time_t)(left / 1000000000), (long)(left % 1000000000)};
        timeout = &ts;
    }
    int ready = epoll_pwait2(f->epfd, ev, nev, timeout, NULL);
    if (ready < 0 && errno != EINTR)
        return -1;
    for (int i = 0; i < ready; i++)
        on_readable(f, &f->ws[ev[i].data.u32]);
    int64_t now = tf_now_ns();
    while (f->nheap > 0 && due_of(f, 0) <= now)
        on_due(f, &f->ws[heap_pop(f)], now);
    return 0;
}

static int farm_serve(sim_farm *f, char *err, size_t errlen)
{
    struct epoll_event ev[256];
    f->start_ns = tf_now_ns();
    for (int i = 0; i < f->n; i++) {
        sim_worker *w = &f->ws[i];
        if (w->state == W_DONE)
            continue;
        struct epoll_event e = {.events = EPOLLIN, .data.u32 = (uint32_t)i};
        if (epoll_ctl(f->epfd, EPOLL_CTL_ADD, ts_client_fd(w->client), &e))
            return tf_seterr(err, errlen, "epoll: %s", strerror(errno));
        ask(f, w, NULL);
    }
    while (f->live > 0)
        if (serve_once(f, ev, 256))
            return tf_seterr(err, errlen, "epoll: %s", strerror(errno));
    return 0;
}

static int cmp_task(const void *a, const void *b)
{
    const sim_task *p = a, *q = b;
    return p->y != q->y ? (p->y > q->y) - (p->y < q->y) : (p->x > q->x) - (p->x < q->x);
}

/* The schedule bound: the makespan of the tasks served (each once), dealt in the coordinator's
 * order to whichever of `workers` is free first, with no cost between tasks -- what a farm with
 * a free coordinator and free network would reach with these tasks.  Its distance to the
 * measured wall time is the coordinator's (and the transport's) share of the loss; its own
 * distance to a perfect 1.0 is the tasks' granularity (the last ones finish alone). */
static double schedule_bound_s(sim_task *t, size_t n, int workers)
{
    if (n == 0 || workers <= 0)
        return 0;
    qsort(t, n, sizeof *t, cmp_task);
    int64_t *heap = calloc((size_t)workers, sizeof *heap); /* min-heap of free times */
    if (!heap)
        return 0;
    int64_t end = 0;
    for (size_t i = 0; i < n; i++) {
        if (i > 0 && t[i].y == t[i - 1].y && t[i].x == t[i - 1].x)
            continue; /* a straggler's duplicate: the work counts once */
        int64_t fin = heap[0] + t[i].cost_ns;
        if (fin > end)
            end = fin;
        heap[0] = fin; /* the earliest free worker takes it; sift the root down */
        for (size_t k = 0, w = (size_t)workers;;) {
            size_t l = 2 * k + 1, r = l + 1, m = k;
            if (l < w && heap[l] < heap[m])
                m = l;
            if (r < w && heap[r] < heap[m])
                m = r;
            if (m == k)
                break;
            int64_t tmp = heap[k];
            heap[k] = heap[m];
            heap[m] = tmp;
            k = m;
        }
    }
    free(heap);
    return (double)end * 1e-9;
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

static void summarise(sim_farm *f, tf_sim_report *rep)
{
    rep->workers = f->joined;
    rep->tasks = f->tasks;
    rep->ops = f->ops;
    int64_t end = f->first_stop_ns;
    rep->wall_s = end > f->start_ns ? (double)(end - f->start_ns) * 1e-9 : 0.0;
    rep->slept_s = f->modelled_ns * 1e-9;
    /* Useful work is the whole image's modelled cost, once: a straggler's duplicate is not. */
    const tf_sim_config *cfg = f->cfg;
    tf_rect all = {0, 0, cfg->image_w, cfg->image_h};
    rep->modelled_s = cfg->pixel_us * 1e-6 *
                      tf_cost_map_rect(cfg->map, cfg->image_w, cfg->image_h, all);
    rep->efficiency = rep->wall_s > 0 && rep->workers > 0
                          ? rep->modelled_s / rep->workers / rep->wall_s
                          : 0.0;
    rep->slept_over_ms = f->tasks ? f->oversleep_ns / (double)f->tasks * 1e-6 : 0.0;
    rep->bound_s = schedule_bound_s(f->done, f->ndone, rep->workers);
    rep->bound_efficiency = rep->bound_s > 0 ? rep->modelled_s / rep->workers / rep->bound_s
                                             : 0.0;
    if (f->ntake == 0)
        return;
    qsort(f->take_ms, f->ntake, sizeof *f->take_ms, cmp_float);
    double sum = 0;
    for (size_t i = 0; i < f->ntake; i++)
        sum += f->take_ms[i];
    rep->take_mean_ms = sum / (double)f->ntake;
    rep->take_p50_ms = f->take_ms[f->ntake / 2];
    rep->take_p99_ms = f->take_ms[(size_t)((double)(f->ntake - 1) * 0.99)];
    rep->take_max_ms = f->take_ms[f->ntake - 1];
}

/* Hundreds of connections need hundreds of descriptors: lift the soft limit to the hard one. */
static void raise_fd_limit(void)
{
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) {
        rl.rlim_cur = rl.rlim_max;
        setrlimit(RLIMIT_NOFILE, &rl);
    }
}

/* ---- the start: connect, join, learn the output's layout ---- */

/* Connect and join every worker, one after another, before the start line: the coordinator's
 * single event loop then sees an orderly queue of handshakes, not a storm.  A worker that
 * cannot join is counted as failed and left out (DONE). */
static int join_all(sim_farm *f, char *err, size_t errlen)
{
    const tf_sim_config *cfg = f->cfg;
    for (int i = 0; i < f->n; i++) {
        sim_worker *w = &f->ws[i];
        char e[512];
        w->client = ts_client_connect(cfg->connect, cfg->key, cfg->timeout_ms, e, sizeof e);
        if (!w->client)
            return tf_seterr(err, errlen, "simulated worker %d of %d: %s", i + 1, f->n, e);
        if (tf_worker_join(w->client, "networked", "simulated", &w->id)) {
            farm_fail(f, "cannot join the render: %s", ts_client_error(w->client));
            w->state = W_DONE;
            continue;
        }
        f->joined++;
        f->live++;
    }
    return 0;
}

/* The output's layout (what a result's chunks must fit), asked by the first worker that joined;
 * then the recording checked against it, or the encoder for black pixels made. */
static int learn_layout(sim_farm *f, char *err, size_t errlen)
{
    int i = 0;
    while (i < f->n && f->ws[i].state == W_DONE)
        i++;
    if (i == f->n)
        return tf_seterr(err, errlen, "no simulated worker could join: %s", f->error);
    if (tf_worker_fetch_layout(f->ws[i].client, &f->layout, err, errlen))
        return -1;
    if (f->cfg->payloads)
        return tf_payloads_fit(f->cfg->payloads, &f->layout, err, errlen);
    f->enc = tf_exr_encoder_new(&f->layout, err, errlen);
    return f->enc ? 0 : -1;
}

static void farm_free(sim_farm *f)
{
    for (int i = 0; i < f->n; i++)
        ts_client_close(f->ws[i].client);
    free(f->ws);
    free(f->heap);
    if (f->epfd >= 0)
        close(f->epfd);
    tf_tuple_clear(&f->tmpl);
    tf_payload_buf_free(&f->buf);
    tf_exr_encoder_free(f->enc);
    free(f->px);
    free(f->take_ms);
    free(f->done);
}

int tf_simulate_run(const tf_sim_config *cfg, tf_sim_report *rep, char *err, size_t errlen)
{
    memset(rep, 0, sizeof *rep);
    if (cfg->workers < 1 || cfg->workers > 4096 || !(cfg->pixel_us >= 0) || !cfg->map ||
        cfg->image_w < 1 || cfg->image_h < 1) {
        tf_seterr(err, errlen, "simulation: need 1..4096 workers, a cost map, pixel cost >= 0");
        return -1;
    }
    raise_fd_limit();
    sim_farm f;
    memset(&f, 0, sizeof f);
    f.cfg = cfg;
    f.n = cfg->workers;
    f.seed = (unsigned)getpid() ^ (unsigned)tf_now_ns();
    f.ws = calloc((size_t)f.n, sizeof *f.ws);
    f.heap = calloc((size_t)f.n, sizeof *f.heap);
    f.epfd = epoll_create1(EPOLL_CLOEXEC);
    int rc = -1;
    if (!f.ws || !f.heap || f.epfd < 0 || tf_task_template(&f.tmpl, TF_TASK_ANY)) {
        tf_seterr(err, errlen, "simulation: cannot start: %s", strerror(errno ? errno : ENOMEM));
        goto out;
    }
    if (join_all(&f, err, errlen) || learn_layout(&f, err, errlen) ||
        farm_serve(&f, err, errlen))
        goto out;
    summarise(&f, rep);
    if (f.failed == 0)
        rc = 0;
    else
        tf_seterr(err, errlen, "%s", f.error);
out:
    farm_free(&f);
    return rc;
}
