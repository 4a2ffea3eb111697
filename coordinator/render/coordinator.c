/* coordinator.c: see coordinator.h for the sequence.  tf_coordinator_run is that sequence, one
 * call per step; each step is a function below, in the order they run, sharing one struct
 * render that holds everything a render owns (freed by render_close whatever step failed). */
#include "coordinator/render/coordinator.h"
#include "coordinator/erosion/erosion_film.h"
#include "clock.h"

#include <errno.h>
#include <inttypes.h>
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
#include "terrain/eroded.h"
#include "terrain/heightfield.h"
#include "terrain/terrain_build.h"
#include "log.h"
#include "render/render.h"
#include "image/preview.h"
#include "coordinator/render/progress.h"
#include "coordinator/render/rowwriter.h"
#include "linda/proto.h"
#include "linda/sock.h"
#include "heightmap_tuples.h"
#include "scene.h"
#include "coordinator/dashboard/dashboard.h"
#include "coordinator/render/finisher.h"
#include "coordinator/render/frames.h"
#include "coordinator/render/local_workers.h"
#include "coordinator/render/movie.h"
#include "coordinator/render/on_done.h"
#include "coordinator/render/output.h"
#include "coordinator/render/stats.h"
#include "coordinator/render/supervisor.h"
#include "coordinator/render/verify.h"
#include "coordinator/render/worker_role.h"
#include "worker/backend_opencl.h"
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
    o->affinity = 1;
}

/* One output file: a still's, or one frame's of a sequence. */
typedef struct frame_output {
    int frame;                   /* -1: a still */
    char *output, *preview;
    tf_exr_meta meta;
    tf_output_plan plan;
} frame_output;

/* Everything one render owns.  A step that fails logs one line, sets status and returns -1. */
typedef struct render {
    const tf_render_opts *o;
    int status;                  /* exit status if a step fails */
    double t_start;
    tf_scene *scene;
    int animated;                /* the scene has an [animation]: outputs are frames */
    char *pattern;               /* -o, or its default */
    frame_output *outs;          /* every frame asked for (one for a still), in order */
    int nouts;
    tf_frame_job *jobs;          /* the outputs still to render, in order */
    int *job_out;                /* job -> index in outs */
    int njobs;
    int nworkers;                /* local workers to fork */
    tf_task_spec spec;
    tf_exr_layout layout;        /* of every output file, from the task shape and --pixel */
    char layout_text[64];
    const char *listen;
    uint8_t key[TF_KEY_BYTES];
    int have_key;
    tf_heightfield *hf;          /* built before forking, for the local workers */
    double hf_s;
    double setup_cpu_s;          /* CPU time spent before supervising (terrain build included) */
    double supervise_cpu_s;      /* CPU time in supervise() alone */
    ts_space *space;
    tf_supervisor *sup;
    ts_server_config cfg;
    ts_role worker_role;         /* every connection's role (worker_role.h) */
    ts_server *srv;
    tf_local_workers lw;
    tf_finisher *finisher;       /* finishes each frame's file off the event loop */
    char finish_error[1024];     /* a frame's file could not be finished */
    tf_tasks tasks;
    char tdesc[64];
    int no_workers;              /* supervise() stopped: no worker could run */
    tf_dashboard *dash;          /* --http (NULL with --http none) */
    int stopped;                 /* supervise() stopped: asked to from the dashboard */
    int rows_on_disk;            /* for --on-done */
    char error[1024];            /* the line a failed step printed, for --on-done */
} render;

static int step_failed(render *r, int status, const char *msg)
{
    if (msg) {
        tf_error("%s", msg);
        snprintf(r->error, sizeof r->error, "%s", msg);
    }
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

/* The frames asked for and their output names (part of load_scene). */
static int choose_frames(render *r)
{
    const tf_render_opts *o = r->o;
    const tf_animation *a = &r->scene->animation;
    r->animated = a->frames > 0;
    tf_frame_range range = {0, r->animated ? a->frames - 1 : 0, 1};
    if (o->frames_given) {
        char err[512];
        range = (tf_frame_range){o->frame_first, o->frame_last, o->frame_step};
        if (tf_frame_range_fits(&range, a->frames, o->scene_path, err, sizeof err))
            return step_failed(r, 2, err);
    }
    if (o->movie) {
        char err[512];
        if (!r->animated) {
            tf_error("--movie: %s is a still (a movie needs an [animation] section)",
                     o->scene_path);
            return step_failed(r, 2, NULL);
        }
        if (tf_movie_check_name(o->movie, err, sizeof err))
            return step_failed(r, 2, err);
        if (!tf_movie_available()) {
            tf_error("--movie: ffmpeg is not installed (apt-get install ffmpeg); render without "
                     "--movie, or install it first");
            return step_failed(r, 2, NULL);
        }
    }
    r->pattern = o->output ? strdup(o->output)
                 : r->animated ? tf_frame_default_pattern(o->scene_path)
                               : tf_output_default_path(o->scene_path);
    if (!r->pattern)
        return step_failed(r, 1, "out of memory");
    /* r->nouts counts entries of r->outs, which the cleanup and --on-done walk: it is set once
     * they exist, not before a refusal */
    int n = r->animated ? tf_frame_range_count(&range) : 1;
    if (n > 1 && !tf_frame_pattern_has_number(r->pattern)) {
        tf_error("-o %s: a sequence of %d frames needs a run of '#' in the output name for the "
                 "frame number (e.g. out/flyby.####.exr)", r->pattern, n);
        return step_failed(r, 2, NULL);
    }
    r->outs = calloc((size_t)n, sizeof *r->outs);
    if (!r->outs)
        return step_failed(r, 1, "out of memory");
    r->nouts = n;
    for (int i = 0; i < r->nouts; i++) {
        frame_output *fo = &r->outs[i];
        fo->frame = r->animated ? range.first + i * range.step : -1;
        fo->output = r->animated ? tf_frame_output_path(r->pattern, fo->frame) : strdup(r->pattern);
        fo->preview = fo->output ? tf_output_preview_path(fo->output) : NULL;
        if (!fo->output || !fo->preview)
            return step_failed(r, 1, "out of memory");
    }
    return 0;
}

/* 1a. The scene and the settings that can be refused, before the output is looked at. */
static int load_scene(render *r)
{
    char err[1024];
    const tf_render_opts *o = r->o;
    r->scene = o->scene ? o->scene : tf_scene_load(o->scene_path, err, sizeof err);
    if (!r->scene)
        return step_failed(r, 2, err);
    if (o->width > 0)
        tf_scene_set_size(r->scene, o->width, o->height);
    if (choose_frames(r))
        return -1;
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
 * continues the file's own layout (a sequence's: its first frame on disk's; every frame
 * of a sequence has the same layout, and a frame whose file differs is refused). */
static void choose_layout(render *r)
{
    const tf_render_opts *o = r->o;
    int pixel = o->pixel;
    tf_exr_layout have;
    int found = 0;
    for (int i = 0; o->resume && i < r->nouts && !found; i++) /* the first frame on disk */
        found = tf_output_existing_layout(r->outs[i].output, &have);
    if (found && have.width == r->scene->width && have.height == r->scene->height) {
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

/* 1b. Each output: fresh, resume, already complete, or refuse -- before any expensive work.
 *     The outputs not complete become the frame jobs. */
static int plan_output(render *r)
{
    choose_layout(r);
    r->jobs = calloc((size_t)r->nouts, sizeof *r->jobs);
    r->job_out = calloc((size_t)r->nouts, sizeof *r->job_out);
    if (!r->jobs || !r->job_out)
        return step_failed(r, 1, "out of memory");
    /* A sequence says what it found in one line rather than one per frame (refusals, which
     * are errors, still name their frame's file). */
    int level = tf_log_get_level(), many = r->nouts > 1;
    if (many && level > TF_LOG_WARN)
        tf_log_set_level(TF_LOG_WARN);
    int complete = 0, partial = 0, replaced = 0;
    struct stat st;
    for (int i = 0; i < r->nouts; i++) {
        frame_output *fo = &r->outs[i];
        tf_output_meta(&fo->meta, r->scene, r->o->scene_path, &r->layout);
        if (fo->frame >= 0) {
            /* a frame's file names its frame: resuming one into another's file is refused */
            size_t n = strlen(fo->meta.settings);
            snprintf(fo->meta.settings + n, sizeof fo->meta.settings - n, " frame=%d", fo->frame);
        }
        if (tf_output_plan_for(fo->output, &fo->meta, r->o->resume, r->o->overwrite, &fo->plan)) {
            tf_log_set_level(level);
            return step_failed(r, 1, NULL);
        }
        complete += fo->plan.complete;
        if (fo->plan.complete)
            continue;
        replaced += !r->o->resume && fo->plan.resume_rows < 0 && stat(fo->output, &st) == 0;
        partial += fo->plan.resume_rows >= 0;
        r->jobs[r->njobs] = (tf_frame_job){fo->frame,
                                           fo->plan.resume_rows > 0 ? fo->plan.resume_rows : 0,
                                           fo->plan.resume_rows >= 0 ? fo->plan.resume_tiles : 0};
        r->job_out[r->njobs++] = i;
    }
    tf_log_set_level(level);
    if (many && r->o->resume)
        tf_info("resuming the sequence %s: %d of %d frames complete on disk (skipped), %d in "
                "progress (continued row by row), %d to render from the start",
                r->pattern, complete, r->nouts, partial, r->njobs - partial);
    else if (many && replaced > 0)
        tf_info("%d of the %d frames of %s are on disk already and will be rendered again "
                "(--resume keeps the complete ones)", replaced, r->nouts, r->pattern);
    return 0;
}

/* Outputs found complete (nothing to render for them): make sure their previews exist. */
static void previews_of_complete(render *r)
{
    char err[1024];
    struct stat st;
    for (int i = 0; i < r->nouts; i++) {
        frame_output *fo = &r->outs[i];
        if (!fo->plan.complete || (r->animated && stat(fo->preview, &st) == 0))
            continue;
        if (tf_preview_from_exr(fo->output, fo->preview, err, sizeof err))
            tf_warn("%s", err);
    }
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

/* An animated camera whose path dips below the terrain renders the terrain from inside: not
 * an error (the scene parses everywhere, and a networked-only render has no terrain to check
 * against), but worth a warning naming the first such frame and its key's line. */
static void warn_camera_underground(render *r)
{
    const tf_animation *a = &r->scene->animation;
    if (a->ncamera < 2)
        return;
    int first = -1, count = 0;
    double z = 0, ground = 0;
    for (int i = 0; i < r->nouts; i++) {
        tf_vec3 pos, look, up;
        double fov;
        tf_animation_camera_at(a, r->outs[i].frame, &pos, &look, &up, &fov);
        if (pos.x < 0 || pos.y < 0 || pos.x > r->hf->extent || pos.y > r->hf->extent)
            continue;
        double g = tf_heightfield_height_at(r->hf, pos.x, pos.y);
        if (pos.z > g)
            continue;
        if (count++ == 0)
            first = r->outs[i].frame, z = pos.z, ground = g;
    }
    if (count > 0)
        tf_warn("%s:%d: camera: at frame %d%s the camera is below the terrain (z %.1f, ground "
                "%.1f): it sees the terrain from inside", r->o->scene_path,
                tf_animation_camera_line(a, first), first,
                count > 1 ? " and more frames after it" : "", z, ground);
}

static const char *describe_tasks(const tf_task_spec *spec, char *buf, size_t len);
static int render_rows_at_start(const render *r);

/* 1d. The dashboard's socket (--http), before anything slow, so that a busy port is refused
 *     before the output is touched; it serves once the workers are forked (serve_dashboard).
 *     In a sequence its rows count every frame's (frames complete before this run included). */
static int open_dashboard(render *r)
{
    char err[1024];
    const tf_render_opts *o = r->o;
    if (o->http && !strcmp(o->http, "none"))
        return 0;
    describe_tasks(&r->spec, r->tdesc, sizeof r->tdesc);
    const tf_frame_job *first = &r->jobs[0];
    frame_output *fo = &r->outs[r->job_out[0]];
    int h = r->scene->height, rows_at_start = render_rows_at_start(r);
    tf_dashboard_config dc = {o->http, o->http_token_file, r->have_key ? r->key : NULL,
                              r->t_start, r->scene->path, r->nouts == 1 ? fo->output : r->pattern,
                              r->tdesc, r->scene->width, h, first->first_row,
                              first->first_row > 0 ? fo->output : NULL,
                              r->animated ? r->nouts : -1, r->nouts * h, rows_at_start,
                              first->frame};
    r->dash = tf_dashboard_open(&dc, err, sizeof err);
    if (!r->dash)
        return step_failed(r, 2, err);
    tf_dashboard_frames(r->dash, first->frame, r->nouts - r->njobs);
    return 0;
}

/* An [erosion] scene's eroded terrain, once: from the cache beside the output, or eroded here
 * on every core; attached to the scene so the height field below, and every networked worker
 * (through the tuple space), use it instead of eroding again. */
static int erode_once(render *r, char *err, size_t errlen)
{
    tf_eroded_cache_beside(r->pattern);
    uint8_t *blob;
    size_t len;
    if (tf_terrain_eroded_bytes(&r->scene->terrain, 0, &blob, &len, NULL, err, errlen) != 0)
        return -1;
    if (tf_scene_attach_eroded(r->scene, blob, len, "the coordinator's erosion") != 0)
        return tf_seterr(err, errlen, "out of memory");
    return 0;
}

/* 2. The terrain, built once before forking so every local worker shares it. */
static int build_terrain(render *r)
{
    char err[1024];
    const char *why = tf_cl_scene_unsupported(r->scene);
    if (r->nworkers > 0 && why && r->o->backend && !strcmp(r->o->backend, "opencl")) {
        snprintf(err, sizeof err, "--backend opencl: %s; use --backend c or auto", why);
        return step_failed(r, 2, err);
    }
    if (r->scene->terrain.erosion.fluvial_steps > 0 && erode_once(r, err, sizeof err) != 0)
        return step_failed(r, 1, err);
    if (r->nworkers <= 0 && r->scene->terrain.generator == TF_GEN_FILE) {
        /* networked workers build their own, but a height map is decoded here once, so a bad
         * file is one line now rather than a failure on every worker that joins; and a bad
         * scene (status 2), so that a farm does not start the render again */
        float *h = tf_terrain_heights(&r->scene->terrain, 0, NULL, err, sizeof err);
        if (!h)
            return step_failed(r, 2, err);
        free(h);
    }
    if (r->nworkers <= 0)
        return 0; /* networked workers build their own */
    double t0 = tf_now_s();
    r->hf = tf_heightfield_build(r->scene, 0, err, sizeof err);
    if (!r->hf)
        return step_failed(r, 1, err);
    r->hf_s = tf_now_s() - t0;
    if (r->o->terrain_cache) /* the forked workers inherit the budget */
        tf_heightfield_set_cache(r->hf, r->o->terrain_cache);
    t0 = tf_now_s();
    tf_render_prepare(r->scene, r->hf, 0); /* the sun's strips, once for all the workers */
    tf_debug("height field %dx%d built in %.2f s, what its renderers share in %.3f s", r->hf->n,
             r->hf->n, r->hf_s, tf_now_s() - t0);
    warn_camera_underground(r);
    return 0;
}

/* The writer thread of frame output fo over its open file (closed if the thread cannot start). */
static tf_rowwriter *start_frame_writer(render *r, frame_output *fo, tf_exr_writer *writer,
                                        char *err, size_t errlen)
{
    /* Room for two bands of results: handing results to the writer must not block the event
     * loop.  Results are packed chunks, and bands are capped in pixels (tasks.c), so this stays
     * a few MB whatever the image size.  The thread is woken once half of that is queued (or
     * half an fsync interval after the first of them), not for every result; and at least 16
     * times a render, so that a small render's file still grows in steps, not at its end. */
    int batch = r->tasks.cols + 4 < r->tasks.count / 16 ? r->tasks.cols + 4 : r->tasks.count / 16;
    tf_rowwriter_config wcfg = {2 * r->tasks.cols + 8, r->o->fsync_interval_ms, fo->preview,
                                r->o->preview_interval_ms, fo->plan.working, batch};
    tf_rowwriter *w = tf_rowwriter_start(writer, &r->layout, &wcfg, err, errlen);
    if (!w)
        tf_exr_abandon(writer);
    return w;
}

/* Job `job`'s output, opened as planned, and its writer thread. */
static tf_rowwriter *open_frame_writer(void *ctx, int job, char *err, size_t errlen)
{
    render *r = ctx;
    frame_output *fo = &r->outs[r->job_out[job]];
    tf_exr_writer *writer = tf_output_open(fo->output, &fo->meta, &fo->plan, err, errlen);
    return writer ? start_frame_writer(r, fo, writer, err, errlen) : NULL;
}

/* --verify caught a liar whose results are in job `job`'s file: close it as the partial render
 * it is, reopen it through the resume path keeping its first keep_chunks chunks, and start a new
 * writer thread on it. */
static tf_rowwriter *rewind_frame_writer(void *ctx, int job, tf_rowwriter *w, int64_t keep_chunks,
                                         char *err, size_t errlen)
{
    render *r = ctx;
    frame_output *fo = &r->outs[r->job_out[job]];
    tf_rowwriter_abandon(w);
    int rows = 0;
    tf_exr_writer *writer = tf_exr_resume_prefix(fo->plan.working, &fo->meta, keep_chunks, &rows,
                                                 err, errlen);
    if (!writer)
        return NULL;
    if (tf_exr_next_chunk(writer) != keep_chunks) {
        tf_seterr(err, errlen, "%s: cannot take back a liar's chunks: %" PRId64 " chunks verify "
                  "on disk, %" PRId64 " expected", fo->plan.working, tf_exr_next_chunk(writer),
                  keep_chunks);
        tf_exr_abandon(writer);
        return NULL;
    }
    return start_frame_writer(r, fo, writer, err, errlen);
}

/* Every task of job `job` is queued: finish its file (offset table, fsync) and its preview,
 * in a thread of its own (finisher.h). */
static int finish_frame_writer(void *ctx, int job, tf_rowwriter *w, char *err, size_t errlen)
{
    render *r = ctx;
    frame_output *fo = &r->outs[r->job_out[job]];
    return tf_finisher_add(r->finisher, w, fo->output, err, errlen);
}

static int put_scene_tuples(ts_space *space, const tf_scene *s, const char *layout)
{
    tf_scene_msg m = {s->text, s->width, s->height, s->hash_hex, layout};
    tf_tuple t;
    if (tf_scene_tuple_pack(&t, &m) || ts_space_out(space, &t) ||
        tf_heightmap_tuples_put(space, s))
        return -1;
    if (tf_next_worker_pack(&t, 1) || ts_space_out(space, &t))
        return -1;
    return 0;
}

/* The supervisor's settings: the render's frames, layout and the options that steer it. */
static void supervisor_config(render *r, tf_supervisor_config *scfg)
{
    const tf_render_opts *o = r->o;
    memset(scfg, 0, sizeof *scfg);
    scfg->width = r->scene->width;
    scfg->height = r->scene->height;
    scfg->njobs = r->njobs;
    scfg->jobs = r->jobs;
    scfg->hooks = (tf_frame_hooks){r, open_frame_writer, finish_frame_writer, rewind_frame_writer};
    scfg->layout = r->layout;
    scfg->verify_chunks = o->verify_chunks;
    scfg->aa_max_depth = r->scene->antialias.max_depth;
    scfg->verify_fraction = o->verify_fraction;
    scfg->verify_seed = tf_verify_seed();
    scfg->spec = r->spec;
    scfg->watermark = o->watermark; /* 0: auto, following the connected workers */
    scfg->expected_workers = r->nworkers > 0 ? r->nworkers : 4;
    scfg->wait_workers = o->wait_workers;
    scfg->max_task_failures = o->max_task_failures;
    scfg->affinity = o->affinity;
}

/* The server on --listen (or the default port, or any port when only local workers need it),
 * its connections' hooks the supervisor's (watched by the dashboard's, if any). */
static int start_server(render *r, char *err, size_t errlen)
{
    memset(&r->cfg, 0, sizeof r->cfg);
    r->cfg.listen = r->listen;
    r->cfg.key = r->have_key ? r->key : NULL;
    r->cfg.silence_timeout_ms = r->o->lease_timeout_ms;
    tf_worker_role_init(&r->worker_role, r->sup, &r->tasks);
    r->cfg.role = &r->worker_role;
    r->cfg.max_space_bytes = MAX_SPACE_BYTES;
    ts_server_hooks hooks = tf_supervisor_hooks(r->sup);
    if (r->dash) { /* the dashboard watches the traffic (results for its preview) */
        hooks = tf_dashboard_hooks(r->dash, hooks);
        tf_supervisor_set_events(r->sup, tf_dashboard_events(r->dash));
    }
    r->srv = ts_server_new(r->space, &r->cfg, &hooks, err, errlen);
    if (!r->srv && !r->o->listen && r->nworkers > 0) {
        /* The default port is taken (another render?): local workers do not need it. */
        r->cfg.listen = "127.0.0.1:0";
        r->srv = ts_server_new(r->space, &r->cfg, &hooks, err, errlen);
    }
    return r->srv ? 0 : -1;
}

/* 3. The tuple space, the supervisor and the server (listening) -- before the output is
 *    created, so a busy port cannot cost an old image at the output path. */
static int start_space(render *r)
{
    char err[1024];
    tf_tasks_init(&r->tasks, r->scene->width, r->scene->height, r->jobs[0].first_row, r->spec);
    tf_tasks_skip(&r->tasks, r->jobs[0].first_tiles);
    r->space = ts_space_new();
    r->finisher = tf_finisher_new();
    if (!r->space || !r->finisher || put_scene_tuples(r->space, r->scene, r->layout_text))
        return step_failed(r, 1, "out of memory");
    if (r->o->wait_workers > 0)
        tf_info("dealing no task until %d worker%s joined (--wait-workers)", r->o->wait_workers,
                r->o->wait_workers == 1 ? " has" : "s have");
    tf_supervisor_config scfg;
    supervisor_config(r, &scfg);
    r->sup = tf_supervisor_new(r->space, &scfg, err, sizeof err);
    if (!r->sup)
        return step_failed(r, 2, err);
    if (start_server(r, err, sizeof err))
        return step_failed(r, 1, err);
    tf_supervisor_attach(r->sup, r->srv);
    if (r->dash)
        tf_dashboard_attach(r->dash, r->sup, r->srv, &r->tasks);
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

/* 4b. The first output file and its writer thread (see start_workers for why it comes second;
 *     the supervisor opens the other frames' outputs through open_frame_writer as it starts
 *     dealing them). */
static int open_output(render *r)
{
    char err[1024];
    tf_rowwriter *w = open_frame_writer(r, 0, err, sizeof err);
    if (!w)
        return step_failed(r, 1, err);
    tf_supervisor_set_writer(r->sup, 0, w);
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
    char what[160];
    long long tasks = (long long)tf_supervisor_stats(r->sup)->tasks_total;
    if (r->animated)
        snprintf(what, sizeof what, "frames %d..%d (%d to render) %dx%d: %lld tasks", r->outs[0].frame,
                 r->outs[r->nouts - 1].frame, r->njobs, s->width, s->height, tasks);
    else
        snprintf(what, sizeof what, "%dx%d: %lld tasks", s->width, s->height, tasks);
    if (ts_server_port(r->srv) > 0) {
        char host[256], port[32], e[128];
        if (tf_split_hostport(r->cfg.listen, host, sizeof host, port, sizeof port, e, sizeof e))
            snprintf(host, sizeof host, "?");
        tf_info("rendering %s %s (%s, %s), watermark %s, %d local worker%s, workers "
                "may join at %s:%d%s",
                s->path, what, r->tdesc, r->layout_text, wdesc, r->nworkers,
                r->nworkers == 1 ? "" : "s", host, ts_server_port(r->srv),
                r->have_key ? " (secret required)" : "");
    } else {
        tf_info("rendering %s %s (%s, %s), watermark %s, %d local workers", s->path, what,
                r->tdesc, r->layout_text, wdesc, r->nworkers);
    }
}

/* Rows on disk or queued over the whole render (resumed rows included), for the progress line;
 * and the frame being written. */
static int rows_done(const render *r, int *writing_frame)
{
    int h = r->scene->height, done = 0, wj = tf_supervisor_write_job(r->sup);
    for (int j = 0; j < r->njobs; j++)
        done += j < wj ? h : tf_supervisor_rows_written(r->sup, j);
    *writing_frame = wj < r->njobs ? r->jobs[wj].frame : -1;
    return done;
}

/* Rows on disk or queued over every frame asked for (those complete before this run
 * included), for the dashboard; and the frame being written. */
static int render_rows(const render *r, int *writing_frame)
{
    int rows = (r->nouts - r->njobs) * r->scene->height + rows_done(r, writing_frame);
    if (*writing_frame < 0 && r->animated) /* every frame is written: the last one was */
        *writing_frame = r->jobs[r->njobs - 1].frame;
    return rows;
}

/* The same before the first task is dealt: what earlier runs left on disk. */
static int render_rows_at_start(const render *r)
{
    int rows = (r->nouts - r->njobs) * r->scene->height;
    for (int j = 0; j < r->njobs; j++)
        rows += r->jobs[j].first_row;
    return rows;
}

/* 4c. The dashboard's HTTP threads, after the fork (see start_workers: the coordinator forks
 *     while it is one thread). */
static int serve_dashboard(render *r)
{
    char err[1024];
    if (r->dash && tf_dashboard_serve(r->dash, err, sizeof err))
        return step_failed(r, 1, err);
    return 0;
}

/* 5b. Supervise until every row is on disk, the render is interrupted, or no worker can run. */
static int supervise(render *r)
{
    tf_progress prog;
    int frame_now, h = r->scene->height;
    tf_progress_init(&prog, r->njobs * h, rows_done(r, &frame_now), r->o->quiet, tf_now_s());
    if (r->animated)
        tf_progress_frames(&prog, r->nouts, r->nouts - r->njobs);
    double last_wait_note = tf_now_s(), last_reap = 0;
    while (!interrupted && !tf_supervisor_done(r->sup) && !tf_supervisor_error(r->sup) &&
           !r->finish_error[0]) {
        if (ts_server_run_once(r->srv, tf_supervisor_wait_ms(r->sup)) < 0) {
            tf_error("event loop failed: %s", strerror(errno));
            break;
        }
        double t = tf_now_s();
        tf_supervisor_step(r->sup, t * 1000.0);
        tf_finisher_reap(r->finisher, r->finish_error, sizeof r->finish_error);
        if (t - last_reap >= 0.2) { /* a system call: not at every event */
            tf_local_workers_reap(&r->lw, 1);
            last_reap = t;
        }
        const tf_farm_stats *st = tf_supervisor_stats(r->sup);
        int live = tf_supervisor_live_workers(r->sup);
        int rows = rows_done(r, &frame_now);
        if (r->animated)
            tf_progress_frame_now(&prog, r->nouts - r->njobs + st->frames_done, frame_now);
        tf_progress_update(&prog, t, rows, st->primary_rays + st->shadow_rays, live, 0);
        if (r->dash) {
            int frame_written;
            int all_rows = render_rows(r, &frame_written);
            tf_dashboard_frames(r->dash, frame_written, r->nouts - r->njobs + st->frames_done);
            if (tf_dashboard_tick(r->dash, all_rows)) {
                r->stopped = 1;
                break;
            }
        }
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
    return tf_supervisor_done(r->sup) && !r->finish_error[0] ? 0 : -1;
}

/* Outputs rendered beside a finished render (output.h, "never lose a finished output"): after
 * a render that did not finish, each partial file beside one is removed and the preview of the
 * kept render rebuilt; returns how many.  After one that finished, each replaces its old file. */
static int discard_beside(render *r)
{
    int n = 0;
    for (int i = 0; i < r->nouts; i++) {
        frame_output *fo = &r->outs[i];
        if (!fo->plan.beside)
            continue;
        char err[1024];
        tf_output_discard(fo->output, &fo->plan);
        if (tf_preview_from_exr(fo->output, fo->preview, err, sizeof err))
            tf_warn("%s", err);
        fo->plan.beside = 0;
        n++;
    }
    return n;
}

static int commit_beside(render *r, char *err, size_t errlen)
{
    for (int i = 0; i < r->nouts; i++) {
        frame_output *fo = &r->outs[i];
        if (fo->plan.beside && tf_output_commit(fo->output, &fo->plan, err, errlen))
            return -1;
        fo->plan.beside = 0;
    }
    return 0;
}

/* 5c. A render that did not finish: keep every row already queued, tell how to continue. */
static void stop_unfinished(render *r)
{
    const char *why = tf_supervisor_error(r->sup);
    int wj = tf_supervisor_write_job(r->sup);
    int rows = wj < r->njobs ? tf_supervisor_rows_written(r->sup, wj) : 0;
    tf_supervisor_stop_workers(r->sup);
    tf_local_workers_drain(&r->lw, 1.0);
    /* abandon writes every queued row of every output still open, and keeps it resumable */
    tf_rowwriter *open[64];
    int jobs[64], n;
    while ((n = tf_supervisor_take_open_writers(r->sup, open, jobs, 64)) > 0)
        for (int i = 0; i < n; i++)
            tf_rowwriter_abandon(open[i]);
    /* frames whose every row was queued are finished all the same */
    if (!r->finish_error[0])
        tf_finisher_wait(r->finisher, r->finish_error, sizeof r->finish_error);
    if (!why && r->finish_error[0])
        why = r->finish_error;
    int kept = discard_beside(r);
    const char *where = wj < r->njobs ? r->outs[r->job_out[wj]].output : "?";
    char frames[128] = "";
    if (r->animated)
        snprintf(frames, sizeof frames, "%d of %d frames done, ",
                 r->nouts - r->njobs + tf_supervisor_stats(r->sup)->frames_done, r->nouts);
    int fw;
    r->rows_on_disk = render_rows(r, &fw);
    tf_dashboard_frames(r->dash, fw, r->nouts - r->njobs + tf_supervisor_stats(r->sup)->frames_done);
    if (why)
        snprintf(r->error, sizeof r->error, "%s", why);
    if (why && kept)
        tf_error("%s; the finished render at the output was kept as it was", why);
    else if (kept)
        tf_error("the new render stopped (%d of %d rows in %s); the finished render there is kept",
                 rows, r->scene->height, where);
    else if (why)
        tf_error("%s", why);
    else if (r->stopped)
        tf_error("stopped from the dashboard: %s%d of %d rows are on disk in %s; continue with "
                 "--resume", frames, rows, r->scene->height, where);
    else if (r->no_workers)
        tf_error("%s%d of %d rows are on disk in %s; continue with --resume", frames, rows,
                 r->scene->height, where);
    else
        tf_error("interrupted: %s%d of %d rows are on disk in %s; continue with --resume", frames,
                 rows, r->scene->height, where);
    r->status = why || r->no_workers ? 1 : 130;
    tf_dashboard_end(r->dash, r->status == 130 ? TF_RUN_INTERRUPTED : TF_RUN_FAILED, r->status,
                     r->rows_on_disk);
}

/* The frames rendered (or complete before) as a movie: --movie, once all are on disk. */
static int make_movie(render *r)
{
    if (!r->o->movie)
        return 0;
    char err[1024];
    const char **pngs = calloc((size_t)r->nouts, sizeof *pngs);
    if (!pngs)
        return step_failed(r, 1, "out of memory");
    for (int i = 0; i < r->nouts; i++)
        pngs[i] = r->outs[i].preview;
    int rc = tf_movie_make(r->o->movie, pngs, r->nouts, r->scene->animation.fps, err, sizeof err);
    free(pngs);
    if (rc)
        return step_failed(r, 1, err);
    tf_info("wrote %s: %d frames at %.6g fps", r->o->movie, r->nouts, r->scene->animation.fps);
    return 0;
}

/* Networked workers given time to read the stop tuple: one that is finishing a task (a
 * straggler's copy, a spot check) takes it when it asks for the next; at most 5 s, and only
 * while a worker that joined is still connected. */
static void let_workers_leave(render *r)
{
    for (int i = 0; i < 250 && ts_server_conn_count(r->srv) > 0 &&
                    (i < 10 || tf_supervisor_live_workers(r->sup) > 0);
         i++)
        ts_server_run_once(r->srv, 20);
}

/* The summary line: what was written, how fast, how many tasks. */
static void say_written(const render *r, double wall)
{
    const tf_farm_stats *st = tf_supervisor_stats(r->sup);
    uint64_t rays = st->primary_rays + st->shadow_rays;
    char what[1024];
    if (r->animated && r->nouts > 1)
        snprintf(what, sizeof what, "%d frames %s .. %s (%d rendered now)", r->nouts,
                 r->outs[0].output, r->outs[r->nouts - 1].output, r->njobs);
    else
        snprintf(what, sizeof what, "%s", r->outs[0].output);
    tf_info("wrote %s (%dx%d) and %s in %.2f s: %.2f Mrays/s, %.2f samples/pixel, %lld tasks, "
            "%lld re-dealt",
            what, r->scene->width, r->scene->height,
            r->animated && r->nouts > 1 ? "their previews" : r->outs[0].preview, wall,
            wall > 0 ? rays / wall / 1e6 : 0,
            st->pixels ? st->spp_sum / (double)st->pixels : 0, (long long)st->tasks_total,
            (long long)st->tasks_redealt);
}

/* --stats: the run's statistics to their file.  0, or -1 with one line in err. */
static int write_stats(const render *r, double wall, char *err, size_t errlen)
{
    int *skipped = calloc((size_t)r->nouts + 1, sizeof *skipped), nskipped = 0;
    if (!skipped)
        return tf_seterr(err, errlen, "out of memory");
    for (int i = 0; i < r->nouts; i++) /* frames already complete before this run */
        if (r->outs[i].plan.complete)
            skipped[nskipped++] = r->outs[i].frame;
    tf_run_info run = {wall, r->scene->width, r->scene->height, r->scene->path, r->pattern,
                       r->tdesc, r->nworkers, r->hf_s, r->setup_cpu_s, r->supervise_cpu_s,
                       r->layout_text, r->t_start, r->animated, skipped, nskipped};
    int bad = tf_stats_write(r->o->stats_path, &run, tf_supervisor_stats(r->sup), err, errlen);
    free(skipped);
    return bad;
}

/* 6. Finish: the workers, the summary, the statistics, the movie (each output was finished
 *    by the supervisor the moment its last row was queued). */
static int finish(render *r)
{
    char err[1024];
    tf_supervisor_stop_workers(r->sup);
    if (tf_finisher_wait(r->finisher, err, sizeof err)) {
        if (discard_beside(r))
            snprintf(err + strlen(err), sizeof err - strlen(err),
                     "; the finished render at the output was kept as it was");
        return step_failed(r, 1, err);
    }
    if (commit_beside(r, err, sizeof err))
        return step_failed(r, 1, err);
    tf_local_workers_drain(&r->lw, 5.0);
    let_workers_leave(r);
    double wall = tf_now_s() - r->t_start;
    say_written(r, wall);
    if (r->o->stats_path && write_stats(r, wall, err, sizeof err))
        return step_failed(r, 1, err);
    if (make_movie(r))
        return -1;
    r->status = 0;
    r->rows_on_disk = r->nouts * r->scene->height;
    tf_dashboard_frames(r->dash, r->outs[r->nouts - 1].frame, r->nouts);
    tf_dashboard_end(r->dash, TF_RUN_FINISHED, 0, r->rows_on_disk);
    return 0;
}

/* 7. --on-done: the outcome, to a command of the user's.  The dashboard keeps serving the
 *    final state while it runs (the command may ask it); it is forked and exec'd at once, so
 *    the HTTP threads do not matter to it. */
static void run_on_done(render *r)
{
    if (!r->o->on_done)
        return;
    /* a still's output and preview; a sequence's -o pattern and its last frame's preview */
    const char *output = r->nouts == 1 ? r->outs[0].output : r->pattern;
    const char *preview = r->nouts > 0 ? r->outs[r->nouts - 1].preview : NULL;
    tf_outcome out = {r->status == 0 ? "ok" : r->status == 130 ? "interrupted" : "failed",
                      r->status, output, preview, r->o->scene_path, r->o->stats_path,
                      r->status == 0 ? "" : r->error, tf_dashboard_url(r->dash),
                      r->scene ? r->scene->width : 0, r->scene ? r->scene->height : 0,
                      r->rows_on_disk, tf_now_s() - r->t_start};
    tf_on_done_run(r->o->on_done, &out);
}

static void render_close(render *r)
{
    if (r->status != 0)
        for (int i = 0; i < r->nouts; i++)
            if (r->outs[i].plan.beside)
                remove(r->outs[i].plan.working); /* a step failed before the render ran */
    if (r->lw.pid && r->srv)
        tf_local_workers_drain(&r->lw, 0);
    if (r->sup) {
        tf_rowwriter *open[64];
        int jobs[64], n;
        while ((n = tf_supervisor_take_open_writers(r->sup, open, jobs, 64)) > 0)
            for (int i = 0; i < n; i++)
                tf_rowwriter_abandon(open[i]);
    }
    tf_finisher_free(r->finisher);
    tf_local_workers_free(&r->lw);
    ts_server_free(r->srv);
    tf_dashboard_close(r->dash); /* after the server: its hooks (the dashboard's taps) run to
                                  * the last connection closed */
    tf_supervisor_free(r->sup);
    ts_space_free(r->space);
    tf_heightfield_free(r->hf);
    tf_scene_free(r->scene);
    for (int i = 0; i < r->nouts; i++) {
        free(r->outs[i].output);
        free(r->outs[i].preview);
    }
    free(r->outs);
    free(r->jobs);
    free(r->job_out);
    free(r->pattern);
}

static int render_run(const tf_render_opts *o)
{
    render r;
    memset(&r, 0, sizeof r);
    r.o = o;
    r.status = 1;
    r.t_start = tf_now_s();
    install_signals();

    if (load_scene(&r) || plan_output(&r))
        goto out;
    if (r.njobs == 0) {
        if (r.animated && r.nouts > 1)
            tf_info("all %d frames (%s .. %s) are already complete: nothing to render", r.nouts,
                    r.outs[0].output, r.outs[r.nouts - 1].output);
        else
            tf_info("%s is already complete: nothing to render", r.outs[0].output);
        previews_of_complete(&r);
        r.status = make_movie(&r) ? r.status : 0;
        r.rows_on_disk = r.nouts * r.scene->height;
        goto out;
    }
    previews_of_complete(&r);
    r.rows_on_disk = render_rows_at_start(&r);
    if (load_secret(&r) || open_dashboard(&r) || build_terrain(&r))
        goto out;
    /* all threads of this process; the forked workers are other processes */
    r.setup_cpu_s = (double)tf_clock_ns(CLOCK_PROCESS_CPUTIME_ID) * 1e-9;
    /* Results (tens to hundreds of KB each) come and go all render long: keep them on the
     * heap rather than let glibc mmap and munmap each one (measured: 8% of the coordinator's
     * render-path CPU went to munmap).  The space holds a bounded number of them (the
     * watermark), so the heap stays bounded too. */
    mallopt(M_MMAP_THRESHOLD, 64 << 20);
    mallopt(M_TRIM_THRESHOLD, 128 << 20);
    if (start_space(&r) || start_workers(&r) || open_output(&r) || serve_dashboard(&r))
        goto out;
    announce(&r);
    double cpu0 = (double)tf_clock_ns(CLOCK_PROCESS_CPUTIME_ID) * 1e-9;
    int supervised = supervise(&r);
    r.supervise_cpu_s = (double)tf_clock_ns(CLOCK_PROCESS_CPUTIME_ID) * 1e-9 - cpu0;
    if (supervised != 0) {
        stop_unfinished(&r);
        goto out;
    }
    finish(&r);
out:
    if (r.status != 0)
        tf_dashboard_end(r.dash, TF_RUN_FAILED, r.status, r.rows_on_disk);
    run_on_done(&r); /* the dashboard still shows the final state meanwhile */
    render_close(&r);
    return r.status;
}

int tf_coordinator_run(const tf_render_opts *o)
{
    if (o->scene)
        return render_run(o);
    char err[1024];
    tf_scene *s = tf_scene_load(o->scene_path, err, sizeof err);
    if (!s) /* the render's own steps say why, and run --on-done */
        return render_run(o);
    if (s->animation.erosion_steps > 0)
        return tf_erosion_film_run(o, s);
    tf_render_opts loaded = *o;
    loaded.scene = s;
    return render_run(&loaded);
}
