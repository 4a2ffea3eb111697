/* simulate.c: see simulate.h.  The cost map (measure, save, load, integrate over a rectangle),
 * then the simulated workers: one thread per worker, each with its own tuple-space connection,
 * all released together from a start line so the measured wall time starts with a full farm. */
#include "worker/simulate.h"
#include "worker/worker.h"
#include "worker/payloads.h"
#include "clock.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "farmproto.h"
#include "log.h"
#include "linda/tsclient.h"

/* ---- the cost map --------------------------------------------------------------------------- */

/* Cell i of n over a side of `size` pixels covers [cell_edge(i), cell_edge(i + 1)). */
static int cell_edge(int i, int n, int size) { return (int)((int64_t)i * size / n); }

int tf_cost_map_measure(const tf_scene *s, const tf_heightfield *hf, int gw, int gh,
                        tf_cost_map *m, char *err, size_t errlen)
{
    memset(m, 0, sizeof *m);
    if (gw < 1 || gh < 1 || gw > TF_COST_MAP_MAX || gh > TF_COST_MAP_MAX || gw > s->width ||
        gh > s->height) {
        tf_seterr(err, errlen, "cost map grid %dx%d: expected 1..%d cells a side, at most one per "
                 "pixel of the %dx%d image", gw, gh, TF_COST_MAP_MAX, s->width, s->height);
        return -1;
    }
    tf_renderer *r = tf_renderer_new(s, hf, err, errlen);
    if (!r)
        return -1;
    int maxw = cell_edge(1, gw, s->width) + s->width / gw + 1;
    int maxh = cell_edge(1, gh, s->height) + s->height / gh + 1;
    tf_pixel *px = malloc((size_t)maxw * (size_t)maxh * sizeof *px);
    m->density = calloc((size_t)gw * (size_t)gh, sizeof *m->density);
    if (!px || !m->density) {
        tf_seterr(err, errlen, "out of memory measuring the cost map");
        free(px);
        tf_renderer_free(r);
        tf_cost_map_free(m);
        return -1;
    }
    double total_ns = 0;
    for (int j = 0; j < gh; j++)
        for (int i = 0; i < gw; i++) {
            tf_rect c = {cell_edge(i, gw, s->width), cell_edge(j, gh, s->height), 0, 0};
            c.w = cell_edge(i + 1, gw, s->width) - c.x;
            c.h = cell_edge(j + 1, gh, s->height) - c.y;
            int64_t t0 = tf_clock_ns(CLOCK_THREAD_CPUTIME_ID);
            tf_render_rect(r, c, px, NULL);
            double ns = (double)(tf_clock_ns(CLOCK_THREAD_CPUTIME_ID) - t0);
            total_ns += ns;
            m->density[j * gw + i] = ns / ((double)c.w * c.h); /* ns per pixel, for now */
        }
    free(px);
    tf_renderer_free(r);
    m->gw = gw;
    m->gh = gh;
    m->measured_w = s->width;
    m->measured_h = s->height;
    m->pixel_ns = total_ns / ((double)s->width * s->height);
    /* Normalise: density = (ns per pixel in the cell) / (mean ns per pixel), whose
     * area-weighted mean is exactly 1 by construction. */
    for (int k = 0; k < gw * gh; k++)
        m->density[k] = m->pixel_ns > 0 ? m->density[k] / m->pixel_ns : 1.0;
    return 0;
}

int tf_cost_map_save(const char *path, const tf_cost_map *m, char *err, size_t errlen)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        tf_seterr(err, errlen, "%s: cannot write the cost map: %s", path, strerror(errno));
        return -1;
    }
    fprintf(f, "terrafarm-cost-map 1 %d %d %d %d %.1f\n", m->gw, m->gh, m->measured_w,
            m->measured_h, m->pixel_ns);
    for (int j = 0; j < m->gh; j++)
        for (int i = 0; i < m->gw; i++)
            fprintf(f, "%.4f%c", m->density[j * m->gw + i], i + 1 == m->gw ? '\n' : ' ');
    int bad = ferror(f);
    bad |= fclose(f) != 0;
    if (bad) {
        tf_seterr(err, errlen, "%s: cannot write the cost map: %s", path, strerror(errno));
        return -1;
    }
    return 0;
}

int tf_cost_map_load(const char *path, tf_cost_map *m, char *err, size_t errlen)
{
    memset(m, 0, sizeof *m);
    FILE *f = fopen(path, "r");
    if (!f) {
        tf_seterr(err, errlen, "%s: cannot read the cost map: %s", path, strerror(errno));
        return -1;
    }
    int version = 0;
    if (fscanf(f, "terrafarm-cost-map %d %d %d %d %d %lf", &version, &m->gw, &m->gh,
               &m->measured_w, &m->measured_h, &m->pixel_ns) != 6 || version != 1) {
        tf_seterr(err, errlen, "%s: not a terrafarm cost map (expected 'terrafarm-cost-map 1 GW "
                 "GH W H PIXEL_NS' on the first line)", path);
        fclose(f);
        return -1;
    }
    if (m->gw < 1 || m->gh < 1 || m->gw > TF_COST_MAP_MAX || m->gh > TF_COST_MAP_MAX) {
        tf_seterr(err, errlen, "%s: cost map grid %dx%d out of range 1..%d", path, m->gw, m->gh,
                 TF_COST_MAP_MAX);
        fclose(f);
        return -1;
    }
    m->density = malloc((size_t)m->gw * (size_t)m->gh * sizeof *m->density);
    if (!m->density) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        fclose(f);
        return -1;
    }
    for (int k = 0; k < m->gw * m->gh; k++) {
        double d;
        if (fscanf(f, "%lf", &d) != 1 || !isfinite(d) || d < 0) {
            tf_seterr(err, errlen, "%s: cost map cell %d: expected a finite non-negative number",
                     path, k);
            fclose(f);
            tf_cost_map_free(m);
            return -1;
        }
        m->density[k] = d;
    }
    fclose(f);
    return 0;
}

void tf_cost_map_free(tf_cost_map *m)
{
    free(m->density);
    m->density = NULL;
}

/* Overlap of [a0, a1) and [b0, b1), or 0. */
static double overlap(double a0, double a1, double b0, double b1)
{
    double lo = a0 > b0 ? a0 : b0, hi = a1 < b1 ? a1 : b1;
    return hi > lo ? hi - lo : 0.0;
}

double tf_cost_map_rect(const tf_cost_map *m, int image_w, int image_h, tf_rect r)
{
    /* Cell i spans [i * image_w / gw, (i + 1) * image_w / gw) in the target image's pixels:
     * the map is stretched, so its cells need not fall on pixel boundaries. */
    double sx = (double)image_w / m->gw, sy = (double)image_h / m->gh;
    int i0 = (int)(r.x / sx), i1 = (int)ceil((r.x + r.w) / sx);
    int j0 = (int)(r.y / sy), j1 = (int)ceil((r.y + r.h) / sy);
    if (i1 > m->gw)
        i1 = m->gw;
    if (j1 > m->gh)
        j1 = m->gh;
    double sum = 0;
    for (int j = j0 < 0 ? 0 : j0; j < j1; j++) {
        double oy = overlap(r.y, r.y + r.h, j * sy, (j + 1) * sy);
        for (int i = i0 < 0 ? 0 : i0; i < i1; i++)
            sum += m->density[j * m->gw + i] * oy * overlap(r.x, r.x + r.w, i * sx, (i + 1) * sx);
    }
    return sum;
}

/* ---- simulated workers ------------------------------------------------------------------- */

/* A task served: where it is (the dealing order is by y, then x) and its modelled cost. */
typedef struct sim_task {
    int y, x;
    int64_t cost_ns;
} sim_task;

typedef struct sim_shared {
    const tf_sim_config *cfg;
    pthread_cond_t gate;            /* the start line: workers wait here until released */
    pthread_cond_t arrival;         /* the releasing thread waits here for the workers */
    int arrived, released;          /* guarded by lock */
    int64_t start_ns;               /* set by the releasing thread before it opens the gate */
    _Atomic int64_t first_stop_ns;  /* 0 until a worker sees the stop tuple */
    pthread_mutex_t lock;           /* guards everything below */
    int joined, failed;
    int64_t tasks, ops;
    double modelled_ns, oversleep_ns;
    float *take_ms;                 /* dealing latencies of every worker */
    size_t ntake, cap_take;
    sim_task *done;                 /* every task served, for the schedule bound */
    size_t ndone, cap_done;
    char error[512];
} sim_shared;

typedef struct sim_worker {
    sim_shared *sh;
    tf_exr_layout layout;
    tf_payload_buf buf;
    ts_client *client;
    pthread_t thread;
    int64_t id;
    int64_t tasks, ops;
    double modelled_ns, oversleep_ns;
    float *take_ms;
    size_t ntake, cap_take;
    sim_task *done;
    size_t ndone, cap_done;
} sim_worker;

static void shared_fail(sim_shared *sh, const char *what, const ts_client *c)
{
    pthread_mutex_lock(&sh->lock);
    sh->failed++;
    if (!sh->error[0])
        snprintf(sh->error, sizeof sh->error, "%s: %s", what, ts_client_error(c));
    pthread_mutex_unlock(&sh->lock);
}

static int sim_join(sim_worker *w)
{
    return tf_worker_join(w->client, "networked", "simulated", &w->id);
}

static void note_latency(sim_worker *w, double ms)
{
    if (w->ntake == w->cap_take) {
        size_t cap = w->cap_take ? 2 * w->cap_take : 256;
        float *n = realloc(w->take_ms, cap * sizeof *n);
        if (!n)
            return; /* a lost sample skews nothing but the percentile's sample size */
        w->take_ms = n;
        w->cap_take = cap;
    }
    w->take_ms[w->ntake++] = (float)ms;
}

/* Sleep until the modelled cost has elapsed from t0; returns the oversleep in ns. */
static int64_t sleep_cost(int64_t t0, int64_t cost_ns)
{
    int64_t until = t0 + cost_ns;
    struct timespec ts = {(time_t)(until / 1000000000), (long)(until % 1000000000)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR)
        ;
    return tf_now_ns() - until;
}

/* The simulated worker's step: sleep the task's modelled cost; its pixels are zero. */
static int sim_render(void *ctx, int frame, tf_rect rect, tf_pixel *px,
                      tf_render_counts *counts, int64_t *busy_ns, char *err, size_t errlen)
{
    (void)frame; /* the simulation's cost map does not move with a camera */
    (void)err;
    (void)errlen;
    sim_worker *w = ctx;
    const tf_sim_config *cfg = w->sh->cfg;
    size_t n = (size_t)rect.w * (size_t)rect.h;
    memset(px, 0, n * sizeof *px);
    double cost = cfg->pixel_us * 1000.0 *
                  tf_cost_map_rect(cfg->map, cfg->image_w, cfg->image_h, rect);
    int64_t cost_ns = (int64_t)cost;
    int64_t t0 = tf_now_ns();
    w->oversleep_ns += (double)sleep_cost(t0, cost_ns);
    w->modelled_ns += (double)cost_ns;
    w->tasks++;
    if (w->ndone == w->cap_done) {
        size_t cap = w->cap_done ? 2 * w->cap_done : 64;
        sim_task *d = realloc(w->done, cap * sizeof *d);
        if (d) {
            w->done = d;
            w->cap_done = cap;
        }
    }
    if (w->ndone < w->cap_done) /* a lost record only weakens the bound */
        w->done[w->ndone++] = (sim_task){rect.y, rect.x, cost_ns};
    *counts = (tf_render_counts){.pixels = (uint64_t)n};
    *busy_ns = cost_ns;
    return 0;
}

/* With a recording: the recorded chunks that stand in for this task's. */
static int sim_payload(void *ctx, tf_rect rect, const tf_pixel *px, tf_chunk_payload *out,
                       int64_t *spp_total, char *err, size_t errlen)
{
    (void)px;
    sim_worker *w = ctx;
    return tf_payloads_for(w->sh->cfg->payloads, &w->layout, rect, &w->buf, out, spp_total, err,
                           errlen);
}

static void sim_on_take(void *ctx, int64_t wait_ns)
{
    note_latency(ctx, (double)wait_ns * 1e-6);
}

static void sim_on_op(void *ctx)
{
    ((sim_worker *)ctx)->ops++;
}

static void sim_on_stop(void *ctx, int64_t t_ns)
{
    sim_worker *w = ctx;
    int64_t zero = 0;
    atomic_compare_exchange_strong(&w->sh->first_stop_ns, &zero, t_ns);
}

/* The real worker loop (worker.c) with the simulated step. */
static void sim_serve(sim_worker *w)
{
    char err[512];
    const tf_payloads *rec = w->sh->cfg->payloads;
    if (tf_worker_fetch_layout(w->client, &w->layout, err, sizeof err)) {
        shared_fail(w->sh, "cannot read the output layout", w->client);
        return;
    }
    if (rec && tf_payloads_fit(rec, &w->layout, err, sizeof err)) {
        pthread_mutex_lock(&w->sh->lock);
        w->sh->failed++;
        if (!w->sh->error[0])
            snprintf(w->sh->error, sizeof w->sh->error, "%s", err);
        pthread_mutex_unlock(&w->sh->lock);
        return;
    }
    tf_worker_step step = {w, sim_render, rec ? sim_payload : NULL, sim_on_take, sim_on_op,
                           sim_on_stop, w->sh->cfg->image_w, w->sh->cfg->image_h};
    int rc = tf_worker_serve(w->client, w->id, &w->layout, &step);
    tf_payload_buf_free(&w->buf);
    /* Once the stop tuple is out the coordinator may finish and close while this worker still
     * waits, or sleeps on a straggler's duplicate: losing it then is the end of the render,
     * not a failure. */
    if (rc != TF_SERVE_STOPPED && atomic_load(&w->sh->first_stop_ns) == 0)
        shared_fail(w->sh, rc == TF_SERVE_LOST ? "lost the coordinator"
                                               : "cannot deliver a result",
                    w->client);
}

/* Append k items of `size` bytes to the growing array *dst (*n used of *cap); if memory runs
 * out they are dropped (a sample lost from a percentile or the bound, nothing else).  k = 0
 * (a worker that took no task: both arrays still NULL) appends nothing, without a memcpy
 * from or to NULL. */
static void append_all(void **dst, size_t *n, size_t *cap, const void *src, size_t k,
                       size_t size)
{
    if (k == 0)
        return;
    if (*n + k > *cap) {
        size_t c = 2 * (*n + k);
        void *p = realloc(*dst, c * size);
        if (!p)
            return;
        *dst = p;
        *cap = c;
    }
    memcpy((char *)*dst + *n * size, src, k * size);
    *n += k;
}

static void merge(sim_shared *sh, sim_worker *w)
{
    pthread_mutex_lock(&sh->lock);
    sh->tasks += w->tasks;
    sh->ops += w->ops;
    sh->modelled_ns += w->modelled_ns;
    sh->oversleep_ns += w->oversleep_ns;
    append_all((void **)&sh->take_ms, &sh->ntake, &sh->cap_take, w->take_ms, w->ntake,
               sizeof *w->take_ms);
    append_all((void **)&sh->done, &sh->ndone, &sh->cap_done, w->done, w->ndone,
               sizeof *w->done);
    pthread_mutex_unlock(&sh->lock);
    free(w->take_ms);
    w->take_ms = NULL;
    free(w->done);
    w->done = NULL;
}

static void *sim_thread(void *arg)
{
    sim_worker *w = arg;
    sim_shared *sh = w->sh;
    int ok = sim_join(w) == 0;
    if (!ok)
        shared_fail(sh, "cannot join the render", w->client);
    else {
        pthread_mutex_lock(&sh->lock);
        sh->joined++;
        pthread_mutex_unlock(&sh->lock);
    }
    /* Every worker, joined or not, reaches the start line; run_workers opens it.  An arrival
     * wakes only the releasing thread: a broadcast on the gate would wake every worker already
     * waiting, half a million futex calls for 1024 workers. */
    pthread_mutex_lock(&sh->lock);
    sh->arrived++;
    pthread_cond_signal(&sh->arrival);
    while (!sh->released)
        pthread_cond_wait(&sh->gate, &sh->lock);
    pthread_mutex_unlock(&sh->lock);
    if (ok)
        sim_serve(w);
    merge(sh, w);
    return NULL;
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

static void summarise(sim_shared *sh, tf_sim_report *rep)
{
    rep->workers = sh->joined;
    rep->tasks = sh->tasks;
    rep->ops = sh->ops;
    int64_t end = atomic_load(&sh->first_stop_ns);
    rep->wall_s = end > sh->start_ns ? (double)(end - sh->start_ns) * 1e-9 : 0.0;
    rep->slept_s = sh->modelled_ns * 1e-9;
    /* Useful work is the whole image's modelled cost, once: a straggler's duplicate is not. */
    const tf_sim_config *cfg = sh->cfg;
    tf_rect all = {0, 0, cfg->image_w, cfg->image_h};
    rep->modelled_s = cfg->pixel_us * 1e-6 *
                      tf_cost_map_rect(cfg->map, cfg->image_w, cfg->image_h, all);
    rep->efficiency = rep->wall_s > 0 && rep->workers > 0
                          ? rep->modelled_s / rep->workers / rep->wall_s
                          : 0.0;
    rep->slept_over_ms = sh->tasks ? sh->oversleep_ns / (double)sh->tasks * 1e-6 : 0.0;
    rep->bound_s = schedule_bound_s(sh->done, sh->ndone, rep->workers);
    rep->bound_efficiency = rep->bound_s > 0 ? rep->modelled_s / rep->workers / rep->bound_s
                                             : 0.0;
    if (sh->ntake == 0)
        return;
    qsort(sh->take_ms, sh->ntake, sizeof *sh->take_ms, cmp_float);
    double sum = 0;
    for (size_t i = 0; i < sh->ntake; i++)
        sum += sh->take_ms[i];
    rep->take_mean_ms = sum / (double)sh->ntake;
    rep->take_p50_ms = sh->take_ms[sh->ntake / 2];
    rep->take_p99_ms = sh->take_ms[(size_t)((double)(sh->ntake - 1) * 0.99)];
    rep->take_max_ms = sh->take_ms[sh->ntake - 1];
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

/* Connect every worker from this thread, one after another, before any thread starts: the
 * coordinator's single event loop then sees an orderly queue of handshakes, not a storm. */
static int connect_all(const tf_sim_config *cfg, sim_worker *ws, char *err, size_t errlen)
{
    for (int i = 0; i < cfg->workers; i++) {
        char e[512];
        ws[i].client = ts_client_connect(cfg->connect, cfg->key, cfg->timeout_ms, e, sizeof e);
        if (!ws[i].client) {
            tf_seterr(err, errlen, "simulated worker %d of %d: %s", i + 1, cfg->workers, e);
            return -1;
        }
    }
    return 0;
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
    sim_shared sh;
    memset(&sh, 0, sizeof sh);
    sh.cfg = cfg;
    sim_worker *ws = calloc((size_t)cfg->workers, sizeof *ws);
    if (!ws) {
        tf_seterr(err, errlen, "out of memory");
        return -1;
    }
    int rc = -1;
    int started = 0;
    pthread_mutex_init(&sh.lock, NULL);
    pthread_cond_init(&sh.gate, NULL);
    pthread_cond_init(&sh.arrival, NULL);
    if (connect_all(cfg, ws, err, errlen))
        goto out;
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    pthread_attr_setstacksize(&attr, 256 * 1024); /* a worker's frames are small; 1024 fit */
    for (; started < cfg->workers; started++) {
        ws[started].sh = &sh;
        if (pthread_create(&ws[started].thread, &attr, sim_thread, &ws[started])) {
            tf_seterr(err, errlen, "cannot start simulated worker thread %d of %d", started + 1,
                     cfg->workers);
            break;
        }
    }
    pthread_attr_destroy(&attr);
    /* Open the start line once every started worker has joined (or failed to). */
    pthread_mutex_lock(&sh.lock);
    while (sh.arrived < started)
        pthread_cond_wait(&sh.arrival, &sh.lock);
    sh.start_ns = tf_now_ns();
    sh.released = 1;
    pthread_cond_broadcast(&sh.gate);
    pthread_mutex_unlock(&sh.lock);
    for (int i = 0; i < started; i++)
        pthread_join(ws[i].thread, NULL);
    summarise(&sh, rep);
    if (started == cfg->workers && sh.failed == 0)
        rc = 0;
    else if (sh.error[0])
        tf_seterr(err, errlen, "%s", sh.error);
out:
    for (int i = 0; i < cfg->workers; i++)
        ts_client_close(ws[i].client);
    free(ws);
    free(sh.take_ms);
    free(sh.done);
    pthread_cond_destroy(&sh.gate);
    pthread_cond_destroy(&sh.arrival);
    pthread_mutex_destroy(&sh.lock);
    return rc;
}
