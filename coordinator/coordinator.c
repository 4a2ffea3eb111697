/* coordinator.c: see coordinator.h for the sequence; this file is that sequence, top to bottom. */
#include "coordinator/coordinator.h"
#include "clock.h"

#include <errno.h>
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
#include "log.h"
#include "image/preview.h"
#include "coordinator/progress.h"
#include "coordinator/rowwriter.h"
#include "linda/proto.h"
#include "linda/sock.h"
#include "heightmap_tuples.h"
#include "scene.h"
#include "coordinator/spawn.h"
#include "coordinator/stats.h"
#include "coordinator/supervisor.h"
#include "linda/tsserver.h"
#include "linda/tuplespace.h"
#include "worker/worker.h"

#define DEFAULT_LISTEN "127.0.0.1:7878"
#define MAX_RESPAWNS_PER_WORKER 3

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
}

/* out/<scene basename without .scene>.exr */
static char *default_output(const char *scene_path)
{
    const char *base = strrchr(scene_path, '/');
    base = base ? base + 1 : scene_path;
    size_t len = strlen(base);
    if (len > 6 && !strcmp(base + len - 6, ".scene"))
        len -= 6;
    char *out = malloc(len + 10);
    if (out)
        snprintf(out, len + 10, "out/%.*s.exr", (int)len, base);
    return out;
}

/* FILE.exr -> FILE.png (or FILE.png appended when there is no .exr). */
static char *preview_path(const char *output)
{
    size_t len = strlen(output);
    char *p = malloc(len + 5);
    if (!p)
        return NULL;
    if (len > 4 && !strcmp(output + len - 4, ".exr"))
        snprintf(p, len + 5, "%.*s.png", (int)(len - 4), output);
    else
        snprintf(p, len + 5, "%s.png", output);
    return p;
}

/* mkdir -p of the directory part of path. */
static int ensure_parent_dir(const char *path, char *err, size_t errlen)
{
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (!slash || slash == dir)
        return 0;
    *slash = '\0';
    for (char *p = dir + 1; *p; p++) {
        if (*p != '/')
            continue;
        *p = '\0';
        mkdir(dir, 0777);
        *p = '/';
    }
    if (mkdir(dir, 0777) && errno != EEXIST) {
        tf_seterr(err, errlen, "%.900s: cannot create directory: %s", dir, strerror(errno));
        return -1;
    }
    return 0;
}

static void fill_meta(tf_exr_meta *m, const tf_scene *s, const char *scene_path)
{
    memset(m, 0, sizeof *m);
    m->width = s->width;
    m->height = s->height;
    snprintf(m->scene_hash, sizeof m->scene_hash, "%s", s->hash_hex);
    const char *base = strrchr(scene_path, '/');
    snprintf(m->scene_name, sizeof m->scene_name, "%s", base ? base + 1 : scene_path);
    /* Everything besides the scene that decides pixel values: the renderer's version. */
    snprintf(m->settings, sizeof m->settings, "renderer=terrafarm-%s", TF_VERSION);
}

/* Decide what to do with whatever is at the output path.  Returns 0 and sets *resume_rows
 * (-1: start fresh) or -1 after printing why it refuses.  Touches nothing on disk. */
static int check_output(const tf_render_opts *o, const char *output, const tf_exr_meta *want,
                        int *resume_rows, int *already_complete)
{
    tf_exr_meta have;
    int rows = 0, complete = 0;
    char err[1024];
    *resume_rows = -1;
    *already_complete = 0;
    int r = tf_exr_probe(output, &have, &rows, &complete, err, sizeof err);
    if (r == 1) {
        if (o->resume)
            tf_info("%s: nothing to resume, starting a fresh render", output);
        return 0;
    }
    if (r < 0) {
        if (o->overwrite)
            return 0;
        tf_error("%s exists and is not a terrafarm render that can be resumed (%s); use "
                 "--overwrite to replace it",
                 output, err);
        return -1;
    }
    if (o->overwrite) {
        if (!complete)
            tf_info("%s: discarding a partial render of %d/%d rows (--overwrite)", output, rows,
                    have.height);
        return 0;
    }
    if (!o->resume) {
        if (!complete && rows == 0) {
            tf_info("%s: a partial render with no rows is there; it will be replaced", output);
            return 0;
        }
        if (complete) {
            tf_info("%s: a finished render is there; it will be replaced", output);
            return 0;
        }
        tf_error("%s holds a partial render (%d of %d rows on disk): use --resume to continue it "
                 "or --overwrite to start again",
                 output, rows, have.height);
        return -1;
    }
    /* --resume: the same scene, size and settings, or a clear refusal. */
    if (have.width != want->width || have.height != want->height) {
        tf_error("%s: cannot resume: image size changed (%dx%d on disk, %dx%d now)", output,
                 have.width, have.height, want->width, want->height);
        return -1;
    }
    if (strcmp(have.scene_hash, want->scene_hash)) {
        tf_error("%s: cannot resume: the scene changed since the partial render (hash %.12s on "
                 "disk, %.12s now)",
                 output, have.scene_hash, want->scene_hash);
        return -1;
    }
    if (strcmp(have.settings, want->settings)) {
        tf_error("%s: cannot resume: render settings changed ('%s' on disk, '%s' now)", output,
                 have.settings, want->settings);
        return -1;
    }
    if (complete) {
        *already_complete = 1;
        return 0;
    }
    *resume_rows = rows;
    return 0;
}

static int put_scene_tuples(ts_space *space, const tf_scene *s)
{
    tf_tuple t;
    tf_tuple_init(&t);
    if (tf_tuple_pack(&t, "ssiis", "scene", s->text, (int64_t)s->width, (int64_t)s->height,
                      s->hash_hex) ||
        ts_space_out(space, &t) || tf_heightmap_tuples_put(space, s))
        return -1;
    tf_tuple_init(&t);
    if (tf_tuple_pack(&t, "si", "next_worker", (int64_t)1) || ts_space_out(space, &t))
        return -1;
    return 0;
}

typedef struct local_workers {
    int n;
    pid_t *pid;
    int *respawns;
    int gave_up;       /* workers that could not start or kept dying: not restarted */
} local_workers;

static void reap_workers(local_workers *lw, ts_server *srv, const tf_scene *s,
                         const tf_heightfield *hf, const char *backend, int respawn)
{
    for (int i = 0; i < lw->n; i++) {
        if (lw->pid[i] <= 0)
            continue;
        int status;
        pid_t r = waitpid(lw->pid[i], &status, WNOHANG);
        if (r != lw->pid[i])
            continue;
        lw->pid[i] = 0;
        int clean = WIFEXITED(status) && WEXITSTATUS(status) == 0;
        if (clean || !respawn)
            continue;
        if (WIFEXITED(status) && WEXITSTATUS(status) == TF_WORKER_EXIT_NOSTART) {
            lw->gave_up++; /* it said why; restarting would say it again */
            continue;
        }
        if (WIFSIGNALED(status))
            tf_warn("local worker %d killed by signal %d", i, WTERMSIG(status));
        else
            tf_warn("local worker %d exited with status %d", i, WEXITSTATUS(status));
        if (lw->respawns[i] >= MAX_RESPAWNS_PER_WORKER) {
            lw->gave_up++;
            continue;
        }
        lw->respawns[i]++;
        char err[512];
        pid_t p = tf_spawn_worker(srv, s, hf, backend, i, err, sizeof err);
        if (p > 0) {
            lw->pid[i] = p;
            tf_info("restarted local worker %d", i);
        } else {
            tf_warn("cannot restart local worker %d: %s", i, err);
        }
    }
}

static int workers_alive(const local_workers *lw)
{
    int n = 0;
    for (int i = 0; i < lw->n; i++)
        n += lw->pid[i] > 0;
    return n;
}

/* After the stop tuple: serve the space until the local workers have left (they need it to
 * read the stop tuple), then make sure none is left behind. */
static void drain_workers(local_workers *lw, ts_server *srv, double grace_s)
{
    double until = tf_now_s() + grace_s;
    while (workers_alive(lw) && tf_now_s() < until) {
        ts_server_run_once(srv, 20);
        reap_workers(lw, srv, NULL, NULL, NULL, 0);
    }
    for (int i = 0; i < lw->n; i++)
        if (lw->pid[i] > 0) {
            kill(lw->pid[i], SIGKILL);
            waitpid(lw->pid[i], NULL, 0);
            lw->pid[i] = 0;
        }
}

static const char *describe_tasks(const tf_task_spec *spec, char *buf, size_t len)
{
    if (spec->shape == TF_TASKS_ROWS)
        snprintf(buf, len, "rows:%d", spec->h);
    else
        snprintf(buf, len, "stamps:%dx%d", spec->w, spec->h);
    return buf;
}

/* A fresh output, created atomically.  OpenEXRCore writes a header in many small writes, so a
 * coordinator killed while creating OUTPUT in place would leave an empty or torn header that no
 * later --resume can read.  Instead the header goes to OUTPUT.new.tmp, which is renamed over
 * OUTPUT once whole and then reopened as a resumable render with no rows: at every instant
 * OUTPUT holds what was there before or a valid zero-row partial, never less. */
static tf_exr_writer *create_output(const char *output, const tf_exr_meta *meta, char *err,
                                    size_t errlen)
{
    size_t n = strlen(output) + sizeof ".new.tmp";
    char *tmp = malloc(n);
    if (!tmp) {
        tf_seterr(err, errlen, "%s: out of memory", output);
        return NULL;
    }
    snprintf(tmp, n, "%s.new.tmp", output);
    tf_exr_writer *w = tf_exr_create(tmp, meta, err, errlen);
    if (w) {
        tf_exr_abandon(w); /* closes it, header written, no rows */
        w = NULL;
        if (rename(tmp, output) == 0) {
            int rows_done = -1;
            w = tf_exr_resume(output, meta, &rows_done, err, errlen);
            if (w && rows_done != 0) {
                tf_exr_abandon(w);
                w = NULL;
                tf_seterr(err, errlen, "%s: changed while starting (%d rows, expected 0)", output,
                         rows_done);
            }
        } else {
            tf_seterr(err, errlen, "%s: cannot create: %s", output, strerror(errno));
        }
    }
    remove(tmp); /* gone after the rename; a failed create's leftovers otherwise */
    free(tmp);
    return w;
}

int tf_coordinator_run(const tf_render_opts *o)
{
    double t_start = tf_now_s();
    char err[1024];
    int status = 1;
    tf_scene *scene = NULL;
    tf_heightfield *hf = NULL;
    ts_space *space = NULL;
    ts_server *srv = NULL;
    tf_supervisor *sup = NULL;
    tf_exr_writer *writer = NULL;
    tf_rowwriter *rows_out = NULL; /* owns writer once started */
    char *output = NULL, *preview = NULL;
    local_workers lw = {0, NULL, NULL, 0};
    tf_progress prog;

    signal(SIGPIPE, SIG_IGN);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    scene = tf_scene_load(o->scene_path, err, sizeof err);
    if (!scene) {
        tf_error("%s", err);
        status = 2;
        goto out;
    }
    if (o->width > 0)
        tf_scene_set_size(scene, o->width, o->height);
    output = o->output ? strdup(o->output) : default_output(o->scene_path);
    preview = output ? preview_path(output) : NULL;
    if (!output || !preview) {
        tf_error("out of memory");
        goto out;
    }

    /* Settings that can be refused are refused before the output is looked at. */
    int nworkers = o->workers >= 0 ? o->workers : tf_thread_count(0);
    tf_task_spec spec = o->tasks_given ? o->tasks
                                       : tf_task_spec_default(scene->width, scene->height,
                                                              nworkers > 0 ? nworkers : 4);
    {
        tf_tasks all;
        tf_tasks_init(&all, scene->width, scene->height, 0, spec);
        if (o->watermark > 0 && o->watermark < all.cols) {
            tf_error("--watermark %d is smaller than the %d tasks of one row band: the first "
                     "band could never be written; use at least %d",
                     o->watermark, all.cols, all.cols);
            status = 2;
            goto out;
        }
    }

    /* 1. The output: fresh, resume, or refuse -- before any expensive work. */
    tf_exr_meta meta;
    fill_meta(&meta, scene, o->scene_path);
    int resume_rows, already_complete;
    if (check_output(o, output, &meta, &resume_rows, &already_complete))
        goto out;
    if (already_complete) {
        tf_info("%s is already complete: nothing to render", output);
        if (tf_preview_from_exr(output, preview, err, sizeof err))
            tf_warn("%s", err);
        status = 0;
        goto out;
    }

    const char *listen = o->listen ? o->listen : DEFAULT_LISTEN;
    uint8_t key[TF_KEY_BYTES];
    int have_key = 0;
    if (o->secret_file) {
        if (tf_auth_init() || tf_secret_load(o->secret_file, key, err, sizeof err)) {
            tf_error("%s", err);
            goto out;
        }
        have_key = 1;
    } else if (!tf_listen_is_loopback(listen)) {
        tf_error("--listen %s is not a loopback address: networked workers there need "
                 "--secret-file FILE",
                 listen);
        status = 2;
        goto out;
    }

    int first_row = resume_rows > 0 ? resume_rows : 0;
    tf_tasks tasks;
    tf_tasks_init(&tasks, scene->width, scene->height, first_row, spec);
    int watermark = o->watermark; /* 0: auto, following the connected workers */
    int expected_workers = nworkers > 0 ? nworkers : 4;

    /* 2. The terrain, built once before forking so every local worker shares it. */
    double hf_s = 0;
    if (nworkers > 0) {
        double t0 = tf_now_s();
        hf = tf_heightfield_build(scene, 0, err, sizeof err);
        if (!hf) {
            tf_error("%s", err);
            goto out;
        }
        hf_s = tf_now_s() - t0;
        tf_debug("height field %dx%d built in %.2f s", hf->n, hf->n, hf_s);
    }

    /* 3. The tuple space, the supervisor and the server (listening) -- before the output is
     *    created, so a busy port cannot cost an old image at the output path. */
    space = ts_space_new();
    if (!space || put_scene_tuples(space, scene)) {
        tf_error("out of memory");
        goto out;
    }
    tf_supervisor_config scfg = {scene->width,     scene->height,        first_row, spec,
                                 watermark,         expected_workers,     o->max_task_failures,
                                 NULL /* the writer comes once the output exists */};
    sup = tf_supervisor_new(space, &scfg, err, sizeof err);
    if (!sup) {
        tf_error("%s", err);
        status = 2;
        goto out;
    }
    ts_server_config cfg;
    memset(&cfg, 0, sizeof cfg);
    cfg.listen = listen;
    cfg.key = have_key ? key : NULL;
    cfg.silence_timeout_ms = o->lease_timeout_ms;
    ts_server_hooks hooks = tf_supervisor_hooks(sup);
    srv = ts_server_new(space, &cfg, &hooks, err, sizeof err);
    if (!srv && !o->listen && nworkers > 0) {
        /* The default port is taken (another render?): local workers do not need it. */
        cfg.listen = "127.0.0.1:0";
        srv = ts_server_new(space, &cfg, &hooks, err, sizeof err);
    }
    if (!srv) {
        tf_error("%s", err);
        goto out;
    }
    tf_supervisor_attach(sup, srv);

    /* 4. The output file, then the local workers. */
    if (resume_rows >= 0) {
        int rows_done = 0;
        writer = tf_exr_resume(output, &meta, &rows_done, err, sizeof err);
        if (writer && rows_done != first_row) {
            tf_error("%s: changed while starting (%d rows, expected %d)", output, rows_done,
                     first_row);
            goto out;
        }
        if (writer)
            tf_info("resuming %s: %d of %d rows already on disk", output, rows_done,
                    scene->height);
    } else {
        if (ensure_parent_dir(output, err, sizeof err)) {
            tf_error("%s", err);
            goto out;
        }
        writer = create_output(output, &meta, err, sizeof err);
    }
    if (!writer) {
        tf_error("%s", err);
        goto out;
    }
    /* Room for two bands of rows: handing a finished band to the writer must not block the
     * event loop (every worker waiting for a reply would wait for the compression).  Bands are
     * capped in pixels (tasks.c), so this stays a few MB whatever the image size. */
    int queue_rows = 2 * tasks.th + 8;
    int queue_chunks = queue_rows / tf_exr_chunk_rows() > 2 ? queue_rows / tf_exr_chunk_rows() : 2;
    rows_out = tf_rowwriter_start(writer, scene->width, scene->height, tf_exr_chunk_rows(),
                                  queue_chunks,
                                  o->fsync_interval_ms, preview, output, err, sizeof err);
    if (!rows_out) {
        tf_error("%s", err);
        goto out;
    }
    writer = NULL;
    tf_supervisor_set_writer(sup, rows_out);

    lw.n = nworkers;
    lw.pid = calloc((size_t)(nworkers > 0 ? nworkers : 1), sizeof *lw.pid);
    lw.respawns = calloc((size_t)(nworkers > 0 ? nworkers : 1), sizeof *lw.respawns);
    if (!lw.pid || !lw.respawns) {
        tf_error("out of memory");
        goto out;
    }
    for (int i = 0; i < nworkers; i++) {
        lw.pid[i] = tf_spawn_worker(srv, scene, hf, o->backend, i, err, sizeof err);
        if (lw.pid[i] < 0) {
            lw.pid[i] = 0;
            tf_error("%s", err);
            goto out;
        }
    }
    char tdesc[64], wdesc[32];
    describe_tasks(&spec, tdesc, sizeof tdesc);
    if (watermark > 0)
        snprintf(wdesc, sizeof wdesc, "%d", watermark);
    else
        snprintf(wdesc, sizeof wdesc, "auto (%d now)", tf_supervisor_stats(sup)->watermark);
    if (ts_server_port(srv) > 0) {
        char host[256], port[32];
        char e[128];
        if (tf_split_hostport(cfg.listen, host, sizeof host, port, sizeof port, e, sizeof e))
            snprintf(host, sizeof host, "?");
        tf_info("rendering %s %dx%d: %d tasks (%s), watermark %s, %d local worker%s, workers "
                "may join at %s:%d%s",
                scene->path, scene->width, scene->height, tasks.count, tdesc, wdesc, nworkers,
                nworkers == 1 ? "" : "s", host, ts_server_port(srv),
                have_key ? " (secret required)" : "");
    } else {
        tf_info("rendering %s %dx%d: %d tasks (%s), watermark %s, %d local workers", scene->path,
                scene->width, scene->height, tasks.count, tdesc, wdesc, nworkers);
    }

    /* 5. Supervise until every row is on disk. */
    tf_progress_init(&prog, scene->height, first_row, o->quiet, tf_now_s());
    double last_wait_note = tf_now_s();
    int no_workers = 0;
    while (!interrupted && !tf_supervisor_done(sup) && !tf_supervisor_error(sup)) {
        if (ts_server_run_once(srv, 50) < 0) {
            tf_error("event loop failed: %s", strerror(errno));
            break;
        }
        double t = tf_now_s();
        tf_supervisor_step(sup, t * 1000.0);
        reap_workers(&lw, srv, scene, hf, o->backend, 1);
        const tf_farm_stats *st = tf_supervisor_stats(sup);
        int live = tf_supervisor_live_workers(sup);
        tf_progress_update(&prog, t, tf_rowwriter_rows_written(rows_out),
                           st->primary_rays + st->shadow_rays, live, 0);
        if (nworkers > 0 && lw.gave_up == nworkers && live == 0) {
            tf_progress_clear(&prog);
            tf_error("no local worker could run (see above) and no networked worker is "
                     "connected; stopping");
            no_workers = 1;
            break;
        }
        if (live == 0 && workers_alive(&lw) == 0 && t - last_wait_note > 30) {
            tf_progress_clear(&prog);
            tf_info("waiting for workers to join (terrafarm worker --connect HOST:%d)",
                    ts_server_port(srv));
            last_wait_note = t;
        }
    }
    tf_progress_clear(&prog);

    if (!tf_supervisor_done(sup)) {
        const char *why = tf_supervisor_error(sup);
        int rows = tf_supervisor_rows_written(sup); /* abandon writes every queued row */
        tf_supervisor_stop_workers(sup);
        drain_workers(&lw, srv, 1.0);
        tf_rowwriter_abandon(rows_out);
        rows_out = NULL;
        if (why)
            tf_error("%s", why);
        else if (no_workers)
            tf_error("%d of %d rows are on disk in %s; continue with --resume", rows,
                     scene->height, output);
        else
            tf_error("interrupted: %d of %d rows are on disk in %s; continue with --resume", rows,
                     scene->height, output);
        status = why || no_workers ? 1 : 130;
        goto out;
    }

    /* 6. Finish: the file, the workers, the preview, the statistics. */
    tf_supervisor_stop_workers(sup);
    int finished = tf_rowwriter_finish(rows_out, err, sizeof err);
    rows_out = NULL;
    if (finished) {
        tf_error("%s", err);
        goto out;
    }
    drain_workers(&lw, srv, 5.0);
    for (int i = 0; i < 10 && ts_server_conn_count(srv) > 0; i++)
        ts_server_run_once(srv, 20); /* let networked workers read the stop tuple */
    double wall = tf_now_s() - t_start;
    const tf_farm_stats *st = tf_supervisor_stats(sup);
    uint64_t rays = st->primary_rays + st->shadow_rays;
    tf_info("wrote %s (%dx%d) and %s in %.2f s: %.2f Mrays/s, %.2f samples/pixel, %lld tasks, "
            "%lld re-dealt",
            output, scene->width, scene->height, preview, wall, wall > 0 ? rays / wall / 1e6 : 0,
            st->pixels ? st->spp_sum / (double)st->pixels : 0, (long long)st->tasks_total,
            (long long)st->tasks_redealt);
    if (o->stats_path) {
        tf_run_info run = {wall, scene->width, scene->height, scene->path, output, tdesc,
                           nworkers, hf_s};
        if (tf_stats_write(o->stats_path, &run, st, err, sizeof err)) {
            tf_error("%s", err);
            goto out;
        }
    }
    status = 0;

out:
    if (lw.pid && srv)
        drain_workers(&lw, srv, 0);
    if (rows_out)
        tf_rowwriter_abandon(rows_out);
    if (writer)
        tf_exr_abandon(writer);
    free(lw.pid);
    free(lw.respawns);
    ts_server_free(srv);
    tf_supervisor_free(sup);
    ts_space_free(space);
    tf_heightfield_free(hf);
    tf_scene_free(scene);
    free(output);
    free(preview);
    return status;
}
