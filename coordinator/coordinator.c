/* coordinator.c: see coordinator.h for the sequence.  tf_coordinator_run is that sequence, one
 * call per step; each step is a function below, in the order they run, sharing one struct
 * render that holds everything a render owns (freed by render_close whatever step failed). */
#include "coordinator/coordinator.h"
#include "clock.h"

#include <errno.h>
#include <malloc.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "linda/auth.h"
#include "image/exrfile.h"
#include "farmproto.h"
#include "terrain/heightfield.h"
#include "terrain/terrain_build.h"
#include "log.h"
#include "image/preview.h"
#include "coordinator/progress.h"
#include "coordinator/rowwriter.h"
#include "linda/proto.h"
#include "linda/sock.h"
#include "heightmap_tuples.h"
#include "scene.h"
#include "coordinator/local_workers.h"
#include "coordinator/output.h"
#include "coordinator/stats.h"
#include "coordinator/supervisor.h"
#include "coordinator/verify.h"
#include "coordinator/worker_role.h"
#include "linda/tsserver.h"
#include "linda/tuplespace.h"
#include "worker/worker.h"

#define DEFAULT_LISTEN "127.0.0.1:7878"
/* Workers' outs are refused once the space holds this much (results wait there for their
 * band, bounded by the watermark; this is the backstop). */
#define MAX_SPACE_BYTES (1024u * 1024u * 1024u)

static volatile sig_atomic_t interrupted;

static void on_signal(int sig) { interrupted = sig; }

void tf_render_opts_init(tf_render_opts *o)
{
    memset(o, 0, sizeof *o);
    o->workers = -1;
    o->backend = "c";
    o->lease_timeout_ms = 15000;
    o->max_task_failures = 3;
    o->fsync_interval_ms = 1000;
    o->pixel = TF_PIXEL_HALF; /* see README: Performance, why half */
    o->preview_interval_ms = 5000;
}

/* Everything one render owns.  A step that fails logs one line, sets status and returns -1. */
typedef struct render {
    const tf_render_opts *o;
    int status;                  /* exit status if a step fails */
    double t_start;
    tf_scene *scene;
    char *output, *preview;
    int nworkers;                /* local workers to fork */
    tf_task_spec spec;
    tf_exr_layout layout;        /* of the output file, from the task shape and --pixel */
    char layout_text[64];
    tf_exr_meta meta;
    tf_output_plan plan;
    int first_row;               /* rows already on disk */
    int first_tiles;             /* and tiles of the next tile row (a tiled resume) */
    const char *listen;
    uint8_t key[TF_KEY_BYTES];
    int have_key;
    tf_heightfield *hf;          /* built before forking, for the local workers */
    double hf_s;
    double setup_cpu_s;          /* CPU time spent before supervising (terrain build included) */
    ts_space *space;
    tf_supervisor *sup;
    ts_server_config cfg;
    ts_role worker_role;         /* every connection's role (worker_role.h) */
    ts_server *srv;
    tf_rowwriter *rows_out;      /* owns the EXR writer once started */
    tf_local_workers lw;
    tf_tasks tasks;
    char tdesc[64];
    int no_workers;              /* supervise() stopped: no worker could run */
} render;

static int step_failed(render *r, int status, const char *msg)
{
    if (msg)
        tf_error("%s", msg);
    r->status = status;
    return -1;
}

static void install_signals(void)
{
    signal(SIGPIPE, SIG_IGN);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}

/* 1a. The scene and the settings that can be refused, before the output is looked at. */
static int load_scene(render *r)
{
    char err[1024];
    const tf_render_opts *o = r->o;
    r->scene = tf_scene_load(o->scene_path, err, sizeof err);
    if (!r->scene)
        return step_failed(r, 2, err);
    if (o->width > 0)
        tf_scene_set_size(r->scene, o->width, o->height);
    r->output = o->output ? strdup(o->output) : tf_output_default_path(o->scene_path);
    r->preview = r->output ? tf_output_preview_path(r->output) : NULL;
    if (!r->output || !r->preview)
        return step_failed(r, 1, "out of memory");
    r->nworkers = o->workers >= 0 ? o->workers : tf_thread_count(0);
    r->spec = o->tasks_given ? o->tasks
                             : tf_task_spec_default(r->scene->width, r->scene->height,
                                                    r->nworkers > 0 ? r->nworkers : 4);
    tf_tasks all;
    tf_tasks_init(&all, r->scene->width, r->scene->height, 0, r->spec);
    if (o->watermark > 0 && o->watermark < all.cols) {
        tf_error("--watermark %d is smaller than the %d tasks of one row band: the first "
                 "band could never be written; use at least %d",
                 o->watermark, all.cols, all.cols);
        return step_failed(r, 2, NULL);
    }
    return 0;
}

/* Scanline-block tasks for a resumed scanline file when no --tasks says otherwise: bands of
 * about 64 K pixels. */
static tf_task_spec rows_spec_for(int width)
{
    int k = 65536 / (width > 0 ? width : 1);
    tf_task_spec spec = {TF_TASKS_ROWS, 0, k < 1 ? 1 : k > 64 ? 64 : k};
    return spec;
}

/* The output's layout follows the task shape: stamps are tiles of exactly the stamp (as the
 * tasks clip it to the image), rows a scanline file.  A resume without --tasks (or --pixel)
 * continues the file's own layout. */
static void choose_layout(render *r)
{
    const tf_render_opts *o = r->o;
    int pixel = o->pixel;
    tf_exr_layout have;
    if (o->resume && tf_output_existing_layout(r->output, &have) &&
        have.width == r->scene->width && have.height == r->scene->height) {
        if (!o->tasks_given)
            r->spec = have.tiled ? (tf_task_spec){TF_TASKS_STAMPS, have.tile_w, have.tile_h}
                                 : rows_spec_for(have.width);
        if (!o->pixel_given)
            pixel = have.pixel;
    }
    tf_tasks all;
    tf_tasks_init(&all, r->scene->width, r->scene->height, 0, r->spec);
    r->layout = (tf_exr_layout){r->scene->width, r->scene->height,
                                r->spec.shape == TF_TASKS_STAMPS, 0, 0, pixel};
    if (r->layout.tiled) {
        r->layout.tile_w = all.tw;
        r->layout.tile_h = all.th;
    }
    tf_exr_layout_format(&r->layout, r->layout_text, sizeof r->layout_text);
}

/* 1b. The output: fresh, resume, already complete, or refuse -- before any expensive work. */
static int plan_output(render *r)
{
    choose_layout(r);
    tf_output_meta(&r->meta, r->scene, r->o->scene_path, &r->layout);
    if (tf_output_plan_for(r->output, &r->meta, r->o->resume, r->o->overwrite, &r->plan))
        return step_failed(r, 1, NULL);
    r->first_row = r->plan.resume_rows > 0 ? r->plan.resume_rows : 0;
    r->first_tiles = r->plan.resume_rows >= 0 ? r->plan.resume_tiles : 0;
    return 0;
}

/* 1c. Who may connect: loopback without a secret, anywhere else only with one. */
static int load_secret(render *r)
{
    char err[1024];
    r->listen = r->o->listen ? r->o->listen : DEFAULT_LISTEN;
    if (r->o->secret_file) {
        if (tf_auth_init() || tf_secret_load(r->o->secret_file, r->key, err, sizeof err))
            return step_failed(r, 1, err);
        r->have_key = 1;
    } else if (!tf_listen_is_loopback(r->listen)) {
        tf_error("--listen %s is not a loopback address: networked workers there need "
                 "--secret-file FILE",
                 r->listen);
        return step_failed(r, 2, NULL);
    }
    return 0;
}

/* 2. The terrain, built once before forking so every local worker shares it. */
static int build_terrain(render *r)
{
    char err[1024];
    if (r->nworkers <= 0 && r->scene->terrain.generator == TF_GEN_FILE) {
        /* networked workers build their own, but a height map is decoded here once, so a bad
         * file is one line now rather than a failure on every worker that joins */
        float *h = tf_terrain_heights(&r->scene->terrain, 0, NULL, err, sizeof err);
        if (!h)
            return step_failed(r, 1, err);
        free(h);
    }
    if (r->nworkers <= 0)
        return 0; /* networked workers build their own */
    double t0 = tf_now_s();
    r->hf = tf_heightfield_build(r->scene, 0, err, sizeof err);
    if (!r->hf)
        return step_failed(r, 1, err);
    r->hf_s = tf_now_s() - t0;
    tf_debug("height field %dx%d built in %.2f s", r->hf->n, r->hf->n, r->hf_s);
    return 0;
}

static int put_scene_tuples(ts_space *space, const tf_scene *s, const char *layout)
{
    tf_tuple t;
    tf_tuple_init(&t);
    if (tf_tuple_pack(&t, "ssiiss", "scene", s->text, (int64_t)s->width, (int64_t)s->height,
                      s->hash_hex, layout) ||
        ts_space_out(space, &t) || tf_heightmap_tuples_put(space, s))
        return -1;
    tf_tuple_init(&t);
    if (tf_tuple_pack(&t, "si", "next_worker", (int64_t)1) || ts_space_out(space, &t))
        return -1;
    return 0;
}

/* 3. The tuple space, the supervisor and the server (listening) -- before the output is
 *    created, so a busy port cannot cost an old image at the output path. */
static int start_space(render *r)
{
    char err[1024];
    const tf_render_opts *o = r->o;
    tf_tasks_init(&r->tasks, r->scene->width, r->scene->height, r->first_row, r->spec);
    tf_tasks_skip(&r->tasks, r->first_tiles);
    r->space = ts_space_new();
    if (!r->space || put_scene_tuples(r->space, r->scene, r->layout_text))
        return step_failed(r, 1, "out of memory");
    int expected_workers = r->nworkers > 0 ? r->nworkers : 4;
    tf_supervisor_config scfg;
    memset(&scfg, 0, sizeof scfg);
    scfg.width = r->scene->width;
    scfg.height = r->scene->height;
    scfg.first_row = r->first_row;
    scfg.first_tiles = r->first_tiles;
    scfg.layout = r->layout;
    scfg.verify_chunks = o->verify_chunks;
    scfg.verify_fraction = o->verify_fraction;
    scfg.verify_seed = tf_verify_seed(r->scene->hash_hex);
    scfg.spec = r->spec;
    scfg.watermark = o->watermark; /* 0: auto, following the connected workers */
    scfg.expected_workers = expected_workers;
    scfg.max_task_failures = o->max_task_failures;
    scfg.writer = NULL; /* the writer comes once the output exists */
    r->sup = tf_supervisor_new(r->space, &scfg, err, sizeof err);
    if (!r->sup)
        return step_failed(r, 2, err);
    memset(&r->cfg, 0, sizeof r->cfg);
    r->cfg.listen = r->listen;
    r->cfg.key = r->have_key ? r->key : NULL;
    r->cfg.silence_timeout_ms = o->lease_timeout_ms;
    tf_worker_role_init(&r->worker_role, r->sup, &r->tasks);
    r->cfg.role = &r->worker_role;
    r->cfg.max_space_bytes = MAX_SPACE_BYTES;
    ts_server_hooks hooks = tf_supervisor_hooks(r->sup);
    r->srv = ts_server_new(r->space, &r->cfg, &hooks, err, sizeof err);
    if (!r->srv && !o->listen && r->nworkers > 0) {
        /* The default port is taken (another render?): local workers do not need it. */
        r->cfg.listen = "127.0.0.1:0";
        r->srv = ts_server_new(r->space, &r->cfg, &hooks, err, sizeof err);
    }
    if (!r->srv)
        return step_failed(r, 1, err);
    tf_supervisor_attach(r->sup, r->srv);
    return 0;
}

/* 4a. Fork the local workers.  They are forked before the writer thread starts: a child of a
 *    multi-threaded process may inherit a lock some other thread held at the fork (ASan's
 *    allocator's was seen to hang a worker for good), so the coordinator forks while it is
 *    still one thread.  They wait in `in` until the supervisor deals the first task. */
static int start_workers(render *r)
{
    char err[1024];
    if (tf_local_workers_start(&r->lw, r->nworkers, r->srv, r->scene, r->hf, r->o->backend, err,
                               sizeof err))
        return step_failed(r, 1, err);
    return 0;
}

/* 4b. The output file and its writer thread (see start_workers for why it comes second). */
static int open_output(render *r)
{
    char err[1024];
    tf_exr_writer *writer = tf_output_open(r->output, &r->meta, &r->plan, err, sizeof err);
    if (!writer)
        return step_failed(r, 1, err);
    /* Room for two bands of results: handing results to the writer must not block the event
     * loop.  Results are packed chunks, and bands are capped in pixels (tasks.c), so this stays
     * a few MB whatever the image size. */
    tf_rowwriter_config wcfg = {2 * r->tasks.cols + 8, r->o->fsync_interval_ms, r->preview,
                                r->o->preview_interval_ms, r->plan.working};
    r->rows_out = tf_rowwriter_start(writer, &r->layout, &wcfg, err, sizeof err);
    if (!r->rows_out) {
        tf_exr_abandon(writer);
        return step_failed(r, 1, err);
    }
    tf_supervisor_set_writer(r->sup, r->rows_out);
    return 0;
}

static const char *describe_tasks(const tf_task_spec *spec, char *buf, size_t len)
{
    if (spec->shape == TF_TASKS_ROWS)
        snprintf(buf, len, "rows:%d", spec->h);
    else
        snprintf(buf, len, "stamps:%dx%d", spec->w, spec->h);
    return buf;
}

/* 5a. Say what is rendered and where networked workers may join. */
static void announce(render *r)
{
    char wdesc[32];
    describe_tasks(&r->spec, r->tdesc, sizeof r->tdesc);
    if (r->o->watermark > 0)
        snprintf(wdesc, sizeof wdesc, "%d", r->o->watermark);
    else
        snprintf(wdesc, sizeof wdesc, "auto (%d now)", tf_supervisor_stats(r->sup)->watermark);
    const tf_scene *s = r->scene;
    if (ts_server_port(r->srv) > 0) {
        char host[256], port[32], e[128];
        if (tf_split_hostport(r->cfg.listen, host, sizeof host, port, sizeof port, e, sizeof e))
            snprintf(host, sizeof host, "?");
        tf_info("rendering %s %dx%d: %d tasks (%s, %s), watermark %s, %d local worker%s, "
                "workers may join at %s:%d%s",
                s->path, s->width, s->height, r->tasks.count, r->tdesc, r->layout_text, wdesc,
                r->nworkers,
                r->nworkers == 1 ? "" : "s", host, ts_server_port(r->srv),
                r->have_key ? " (secret required)" : "");
    } else {
        tf_info("rendering %s %dx%d: %d tasks (%s, %s), watermark %s, %d local workers",
                s->path, s->width, s->height, r->tasks.count, r->tdesc, r->layout_text, wdesc,
                r->nworkers);
    }
}

/* 5b. Supervise until every row is on disk, the render is interrupted, or no worker can run. */
static int supervise(render *r)
{
    tf_progress prog;
    tf_progress_init(&prog, r->scene->height, r->first_row, r->o->quiet, tf_now_s());
    double last_wait_note = tf_now_s(), last_reap = 0;
    while (!interrupted && !tf_supervisor_done(r->sup) && !tf_supervisor_error(r->sup)) {
        if (ts_server_run_once(r->srv, 50) < 0) {
            tf_error("event loop failed: %s", strerror(errno));
            break;
        }
        double t = tf_now_s();
        tf_supervisor_step(r->sup, t * 1000.0);
        if (t - last_reap >= 0.05) { /* a waitpid per worker: not at every event */
            tf_local_workers_reap(&r->lw, 1);
            last_reap = t;
        }
        const tf_farm_stats *st = tf_supervisor_stats(r->sup);
        int live = tf_supervisor_live_workers(r->sup);
        tf_progress_update(&prog, t, tf_rowwriter_rows_written(r->rows_out),
                           st->primary_rays + st->shadow_rays, live, 0);
        if (r->nworkers > 0 && r->lw.gave_up == r->nworkers && live == 0) {
            tf_progress_clear(&prog);
            tf_error("no local worker could run (see above) and no networked worker is "
                     "connected; stopping");
            r->no_workers = 1;
            break;
        }
        if (live == 0 && tf_local_workers_alive(&r->lw) == 0 && t - last_wait_note > 30) {
            tf_progress_clear(&prog);
            tf_info("waiting for workers to join (terrafarm worker --connect HOST:%d)",
                    ts_server_port(r->srv));
            last_wait_note = t;
        }
    }
    tf_progress_clear(&prog);
    return tf_supervisor_done(r->sup) ? 0 : -1;
}

/* 5c. A render that did not finish: keep every row already queued, tell how to continue. */
static void stop_unfinished(render *r)
{
    const char *why = tf_supervisor_error(r->sup);
    int rows = tf_supervisor_rows_written(r->sup); /* abandon writes every queued row */
    tf_supervisor_stop_workers(r->sup);
    tf_local_workers_drain(&r->lw, 1.0);
    tf_rowwriter_abandon(r->rows_out);
    r->rows_out = NULL;
    if (r->plan.beside) {
        /* The new render was made beside a finished one, which stays as it was. */
        char err[1024];
        tf_output_discard(r->output, &r->plan);
        if (tf_preview_from_exr(r->output, r->preview, err, sizeof err))
            tf_warn("%s", err);
        if (why)
            tf_error("%s; %s still holds the finished render it held before", why, r->output);
        else
            tf_error("%s: the new render stopped (%d of %d rows); the finished render there is "
                     "kept", r->output, rows, r->scene->height);
    } else if (why)
        tf_error("%s", why);
    else if (r->no_workers)
        tf_error("%d of %d rows are on disk in %s; continue with --resume", rows,
                 r->scene->height, r->output);
    else
        tf_error("interrupted: %d of %d rows are on disk in %s; continue with --resume", rows,
                 r->scene->height, r->output);
    r->status = why || r->no_workers ? 1 : 130;
}

/* 6. Finish: the file, the workers, the summary, the statistics. */
static int finish(render *r)
{
    char err[1024];
    tf_supervisor_stop_workers(r->sup);
    int finished = tf_rowwriter_finish(r->rows_out, err, sizeof err);
    r->rows_out = NULL;
    if (finished) {
        tf_output_discard(r->output, &r->plan);
        if (r->plan.beside)
            snprintf(err + strlen(err), sizeof err - strlen(err),
                     "; %s still holds the finished render it held before", r->output);
        return step_failed(r, 1, err);
    }
    if (tf_output_commit(r->output, &r->plan, err, sizeof err))
        return step_failed(r, 1, err);
    tf_local_workers_drain(&r->lw, 5.0);
    /* Let networked workers read the stop tuple: one that is finishing a task (a straggler's
     * copy, a spot check) takes it when it asks for the next; at most 5 s, and only while a
     * worker that joined is still connected. */
    for (int i = 0; i < 250 && ts_server_conn_count(r->srv) > 0 &&
                    (i < 10 || tf_supervisor_live_workers(r->sup) > 0);
         i++)
        ts_server_run_once(r->srv, 20);
    double wall = tf_now_s() - r->t_start;
    const tf_farm_stats *st = tf_supervisor_stats(r->sup);
    uint64_t rays = st->primary_rays + st->shadow_rays;
    tf_info("wrote %s (%dx%d) and %s in %.2f s: %.2f Mrays/s, %.2f samples/pixel, %lld tasks, "
            "%lld re-dealt",
            r->output, r->scene->width, r->scene->height, r->preview, wall,
            wall > 0 ? rays / wall / 1e6 : 0,
            st->pixels ? st->spp_sum / (double)st->pixels : 0, (long long)st->tasks_total,
            (long long)st->tasks_redealt);
    if (r->o->stats_path) {
        tf_run_info run = {wall, r->scene->width, r->scene->height, r->scene->path, r->output,
                           r->tdesc, r->nworkers, r->hf_s, r->setup_cpu_s, r->layout_text};
        if (tf_stats_write(r->o->stats_path, &run, st, err, sizeof err))
            return step_failed(r, 1, err);
    }
    r->status = 0;
    return 0;
}

static void render_close(render *r)
{
    if (r->plan.beside && r->status != 0)
        remove(r->plan.working); /* a step failed before the render ran */
    if (r->lw.pid && r->srv)
        tf_local_workers_drain(&r->lw, 0);
    if (r->rows_out)
        tf_rowwriter_abandon(r->rows_out);
    tf_local_workers_free(&r->lw);
    ts_server_free(r->srv);
    tf_supervisor_free(r->sup);
    ts_space_free(r->space);
    tf_heightfield_free(r->hf);
    tf_scene_free(r->scene);
    free(r->output);
    free(r->preview);
}

int tf_coordinator_run(const tf_render_opts *o)
{
    render r;
    memset(&r, 0, sizeof r);
    r.o = o;
    r.status = 1;
    r.t_start = tf_now_s();
    install_signals();

    if (load_scene(&r) || plan_output(&r))
        goto out;
    if (r.plan.complete) {
        char err[1024];
        tf_info("%s is already complete: nothing to render", r.output);
        if (tf_preview_from_exr(r.output, r.preview, err, sizeof err))
            tf_warn("%s", err);
        r.status = 0;
        goto out;
    }
    if (load_secret(&r) || build_terrain(&r))
        goto out;
    /* all threads of this process; the forked workers are other processes */
    r.setup_cpu_s = (double)tf_clock_ns(CLOCK_PROCESS_CPUTIME_ID) * 1e-9;
    /* Results (tens to hundreds of KB each) come and go all render long: keep them on the
     * heap rather than let glibc mmap and munmap each one (measured: 8% of the coordinator's
     * render-path CPU went to munmap).  The space holds a bounded number of them (the
     * watermark), so the heap stays bounded too. */
    mallopt(M_MMAP_THRESHOLD, 64 << 20);
    mallopt(M_TRIM_THRESHOLD, 128 << 20);
    if (start_space(&r) || start_workers(&r) || open_output(&r))
        goto out;
    announce(&r);
    if (supervise(&r) != 0) {
        stop_unfinished(&r);
        goto out;
    }
    finish(&r);
out:
    render_close(&r);
    return r.status;
}
