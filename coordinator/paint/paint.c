/* paint.c: `terrafarm paint`, Raypaint as a sequence of steps (paint.h):
 *   1. load the scene; 2. build the terrain once, before any fork; 3. the tuple space, its
 *   server (the paint worker role, paint_role.c) and the first view; 4. fork the workers;
 *   5. the page's HTTP server; 6. paint: serve the space, take results (checked, then drawn),
 *   take the page's commands, deal the best cells up to the watermark, publish the status,
 *   write the painted image when every pixel is exact; 7. stop the workers and close.
 * A view's tasks carry its generation: a new view drops what is dealt of the old one, and a
 * result of an old view is discarded at admission, never drawn. */
#include "coordinator/paint/paint.h"

#include <assert.h>
#include <inttypes.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "coordinator/paint/paint_http.h"
#include "coordinator/paint/paint_hub.h"
#include "coordinator/paint/paint_role.h"
#include "coordinator/paint/paint_view.h"
#include "coordinator/paint/paint_write.h"
#include "coordinator/render/local_workers.h"
#include "farmproto.h"
#include "heightmap_tuples.h"
#include "image/exrlayout.h"
#include "linda/auth.h"
#include "linda/sock.h"
#include "log.h"
#include "render/render.h"
#include "terrain/eroded.h"
#include "terrain/terrain_build.h"
#include "worker/paint_worker.h"

static volatile sig_atomic_t interrupted;
static void on_signal(int sig) { interrupted = sig; }

void tf_paint_opts_init(tf_paint_opts *o)
{
    memset(o, 0, sizeof *o);
    o->workers = -1;
    o->pixel = TF_PIXEL_HALF;
    tf_paint_params_default(&o->params);
}

typedef struct paint {
    const tf_paint_opts *o;
    tf_scene *scene;         /* as loaded: the terrain's, and every view's base */
    tf_scene *view;          /* the view being painted */
    tf_heightfield *hf;
    uint8_t key[TF_KEY_BYTES];
    int have_key, nworkers;
    ts_space *space;
    ts_server *srv;
    tf_paint_role role;      /* the leases: paint_role.h */
    tf_local_workers lw;
    tf_paint_hub *hub;
    tf_paint_http *http;
    tf_paint_tree *tree;
    tf_paint_status st;
    double view_t0;
    float *values;
    size_t values_cap;
    tf_paint_bytes msgs;
    int gate_open;           /* --wait-workers reached (or not asked for) */
} paint;

/* ---- 1-2. the scene and its terrain ---- */

static int load_scene(paint *p)
{
    char err[1024];
    const tf_paint_opts *o = p->o;
    p->scene = tf_scene_load(o->scene_path, err, sizeof err);
    if (!p->scene) {
        tf_error("%s", err);
        return 2;
    }
    if (p->scene->animation.frames > 0) {
        tf_error("%s: an [animation] cannot be painted; paint a still (its camera and sun are "
                 "edited in the page)", o->scene_path);
        return 2;
    }
    if (o->width > 0)
        tf_scene_set_size(p->scene, o->width, o->height);
    p->nworkers = o->workers >= 0 ? o->workers : tf_thread_count(0);
    if (p->nworkers == 0 && !o->listen) {
        tf_error("-j 0 without --listen: nobody would paint");
        return 2;
    }
    return 0;
}

static int build_terrain(paint *p)
{
    char err[1024];
    if (p->scene->terrain.erosion.fluvial_steps > 0) {
        uint8_t *blob;
        size_t len;
        tf_eroded_cache_beside(p->o->output);
        if (tf_terrain_eroded_bytes(&p->scene->terrain, 0, &blob, &len, NULL, err, sizeof err) ||
            tf_scene_attach_eroded(p->scene, blob, len, "the coordinator's erosion")) {
            tf_error("%s", err);
            return 1;
        }
    }
    if (p->nworkers == 0)
        return 0; /* networked workers build their own */
    p->hf = tf_heightfield_build(p->scene, 0, err, sizeof err);
    if (!p->hf) {
        tf_error("%s", err);
        return 1;
    }
    tf_render_prepare(p->scene, p->hf, 0); /* the sun's strips, once for all the workers */
    return 0;
}

/* ---- 3. the space, the server, the first view ---- */

static int load_secret(paint *p)
{
    char err[1024];
    if (p->o->secret_file) {
        if (tf_auth_init() || tf_secret_load(p->o->secret_file, p->key, err, sizeof err)) {
            tf_error("%s", err);
            return 1;
        }
        p->have_key = 1;
    } else if (p->o->listen && !tf_listen_is_loopback(p->o->listen)) {
        tf_error("--listen %s is not a loopback address: networked workers there need "
                 "--secret-file FILE", p->o->listen);
        return 2;
    }
    return 0;
}

static int put_scene_tuples(paint *p)
{
    const tf_scene *s = p->scene;
    tf_scene_msg m = {s->text, s->width, s->height, s->hash_hex, TF_PAINT_LAYOUT};
    tf_tuple t;
    if (tf_scene_tuple_pack(&t, &m) || ts_space_out(p->space, &t) ||
        tf_heightmap_tuples_put(p->space, s))
        return -1;
    if (tf_next_worker_pack(&t, 1) || ts_space_out(p->space, &t))
        return -1;
    return 0;
}

static int start_space(paint *p)
{
    char err[1024];
    p->space = ts_space_new();
    p->tree = tf_paint_tree_new(p->scene->width, p->scene->height, &p->o->params);
    p->hub = tf_paint_hub_new(p->scene->width, p->scene->height);
    if (!p->space || !p->tree || !p->hub || put_scene_tuples(p)) {
        tf_error("out of memory");
        return 1;
    }
    tf_paint_role_init(&p->role, p->space, p->scene->width, p->scene->height, &p->o->params);
    p->st.width = p->scene->width;
    p->st.height = p->scene->height;
    snprintf(p->st.output, sizeof p->st.output, "%s", p->o->output ? p->o->output : "");
    ts_server_config cfg = {0};
    cfg.listen = p->o->listen;
    cfg.key = p->have_key ? p->key : NULL;
    cfg.role = &p->role.role;
    cfg.silence_timeout_ms = 15000;
    ts_server_hooks hooks = tf_paint_role_hooks(&p->role);
    p->srv = ts_server_new(p->space, &cfg, &hooks, err, sizeof err);
    if (!p->srv) {
        tf_error("%s", err);
        return 1;
    }
    p->role.srv = p->srv;
    return 0;
}

/* A view's scene: the loaded one with text's camera, sun and mist.  NULL with err. */
static tf_scene *view_scene(const paint *p, const char *text, char *err, size_t errlen)
{
    tf_scene *v = tf_scene_parse_text("<paint view>", text, strlen(text), err, errlen);
    tf_scene *s = v ? tf_scene_at_frame(p->scene, 0) : NULL;
    if (s) {
        tf_scene_set_view(s, v);
        tf_scene_rehash(s);
    } else if (v) {
        tf_seterr(err, errlen, "out of memory");
    }
    tf_scene_free(v);
    return s;
}

/* Begin view gen: its tuple in the space (the last one's out), a fresh tree, the page told. */
static int begin_view(paint *p, const char *text)
{
    char err[1024];
    char *canon = NULL;
    tf_scene *v = view_scene(p, text, err, sizeof err);
    if (!v || !(canon = tf_scene_canonical(v))) {
        tf_warn("a view the page asked for cannot be painted: %s", v ? "out of memory" : err);
        tf_scene_free(v);
        return -1;
    }
    int64_t gen = p->role.gen + 1;
    tf_paint_role_new_view(&p->role, gen, p->tree); /* drops the old view's tasks */
    tf_tuple t;
    int rc = tf_paint_view_pack(&t, gen, canon, v->hash_hex) || ts_space_out(p->space, &t) ||
             tf_paint_tree_reset(p->tree) || tf_paint_hub_begin_view(p->hub, gen, canon);
    tf_paint_tree_set_interest(p->tree, (tf_rect){0, 0, 0, 0});
    p->st.gen = gen;
    tf_paint_view_values_of(v, &p->st.view);
    p->st.coarse_s = p->st.painted_s = -1;
    p->st.output_written = 0;
    p->view_t0 = tf_now_s();
    free(canon);
    tf_scene_free(p->view);
    p->view = v;
    if (rc)
        tf_error("out of memory starting view %" PRId64, gen);
    return rc ? -1 : 0;
}

/* ---- 4-5. the workers and the page ---- */

static int paint_loop(ts_client *c, const tf_scene *s, const tf_heightfield *hf,
                      const char *kind, const char *backend)
{
    (void)backend;
    return tf_paint_worker_loop(c, s, hf, kind);
}

static int start_workers(paint *p)
{
    char err[1024];
    if (tf_local_workers_start_loop(&p->lw, p->nworkers, p->srv, p->scene, p->hf, "c",
                                    paint_loop, err, sizeof err)) {
        tf_error("%s", err);
        return 1;
    }
    return 0;
}

static int start_http(paint *p)
{
    char err[1024];
    tf_paint_http_config hc = {p->o->http, p->o->http_token_file, p->have_key ? p->key : NULL,
                               p->scene, p->o->save, p->o->farm, p->o->farm_token_file, p->hub};
    p->http = tf_paint_http_start(&hc, err, sizeof err);
    if (!p->http) {
        tf_error("%s", err);
        return 1;
    }
    if (p->o->listen)
        tf_info("networked paint workers: terrafarm worker --connect HOST:%d",
                ts_server_port(p->srv));
    return 0;
}

/* ---- 6. painting ---- */

/* Take every result in the space: checked, drawn, or refused (paint_role.h). */
static void take_results(paint *p)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    if (tf_tuple_pack(&tmpl, "sIIIIB", TF_TAG_PAINT_RESULT))
        return;
    for (;;) {
        tf_tuple_init(&got);
        if (ts_space_inp(p->space, &tmpl, &got) != 1)
            break;
        p->msgs.len = 0;
        int used = tf_paint_role_take_result(&p->role, p->tree, &got, p->scene->antialias.max_depth,
                                             &p->values, &p->values_cap, &p->msgs);
        tf_tuple_clear(&got);
        if (used && p->msgs.len && tf_paint_hub_publish(p->hub, p->msgs.p, p->msgs.len))
            tf_warn("out of memory: the page misses part of view %" PRId64, p->role.gen);
    }
    tf_tuple_clear(&tmpl);
}

static void take_commands(paint *p)
{
    tf_paint_cmd cmd;
    while (tf_paint_hub_next_command(p->hub, &cmd)) {
        if (cmd.kind == TF_PAINT_CMD_VIEW)
            begin_view(p, cmd.text);
        else if (cmd.kind == TF_PAINT_CMD_INTEREST)
            tf_paint_tree_set_interest(p->tree, cmd.area);
        else
            p->st.paused = cmd.kind == TF_PAINT_CMD_PAUSE;
        free(cmd.text);
    }
}

/* The view's milestones: its first complete coarse image, every pixel exact (then written). */
static void note_progress(paint *p)
{
    tf_paint_tree_counts(p->tree, &p->st.counts);
    double age = tf_now_s() - p->view_t0;
    if (p->st.coarse_s < 0 && p->st.counts.roots_left == 0)
        p->st.coarse_s = age;
    if (p->st.painted_s < 0 && tf_paint_tree_pixels(p->tree)) {
        p->st.painted_s = age;
        tf_info("view %" PRId64 " painted in %.2f s (first coarse image %.3f s)", p->st.gen,
                age, p->st.coarse_s);
        if (p->o->output)
            p->st.output_written = tf_paint_write(p->o->output, p->view, p->st.gen,
                                                  tf_paint_tree_pixels(p->tree), p->o->pixel) == 0;
    }
}

static void publish_status(paint *p)
{
    p->st.view_age_s = tf_now_s() - p->view_t0;
    p->st.workers = p->role.workers;
    p->st.outstanding = p->role.nleases;
    p->st.results = p->role.results;
    p->st.stale = p->role.stale;
    p->st.refused = p->role.refused;
    tf_paint_hub_set_status(p->hub, &p->st);
}

static int painted_and_done(const paint *p)
{
    return p->o->until_painted && p->st.painted_s >= 0 &&
           (!p->o->output || p->st.output_written);
}

/* --wait-workers: 1 once that many workers have said hello; it stays open after (a worker
 * leaving later does not stop the dealing), as terrafarm render's. */
static int workers_gate_open(paint *p)
{
    if (!p->gate_open && p->role.workers >= p->o->wait_workers)
        p->gate_open = 1;
    return p->gate_open;
}

static int paint_run_loop(paint *p)
{
    int status = 0;
    while (!interrupted && !painted_and_done(p)) {
        if (ts_server_run_once(p->srv, 10) < 0) {
            tf_error("the tuple-space server failed");
            status = 1;
            break;
        }
        take_results(p);
        take_commands(p);
        if (!p->st.paused && workers_gate_open(p))
            tf_paint_role_deal(&p->role, p->tree);
        tf_local_workers_reap(&p->lw, 1);
        note_progress(p);
        assert(tf_paint_tree_check(p->tree) && tf_paint_role_check(&p->role));
        publish_status(p);
        if (p->o->output && p->st.painted_s >= 0 && !p->st.output_written && p->o->until_painted) {
            status = 1; /* it said why */
            break;
        }
    }
    return status;
}

/* ---- 7. the end ---- */

/* The stop task, then the space served until every worker has read it and left (networked
 * ones too: closing on them would send them reconnecting), for at most a few seconds. */
static void stop_workers(paint *p)
{
    tf_tuple t;
    if (tf_paint_task_pack(&t, TF_PAINT_STOP, TF_PAINT_STOP, NULL, 0) == 0)
        ts_space_out(p->space, &t);
    double until = tf_now_s() + 3.0;
    while (p->role.workers > 0 && tf_now_s() < until) {
        ts_server_run_once(p->srv, 20);
        tf_local_workers_reap(&p->lw, 0);
    }
    tf_local_workers_drain(&p->lw, 2.0);
}

static void paint_close(paint *p)
{
    if (p->hub)
        tf_paint_hub_close(p->hub);
    tf_paint_http_stop(p->http);
    if (p->srv)
        stop_workers(p);
    tf_local_workers_free(&p->lw);
    ts_server_free(p->srv); /* its disconnects still reach the role */
    tf_paint_role_free(&p->role);
    ts_space_free(p->space);
    tf_paint_hub_free(p->hub);
    tf_paint_tree_free(p->tree);
    tf_paint_bytes_free(&p->msgs);
    free(p->values);
    tf_heightfield_free(p->hf);
    tf_scene_free(p->view);
    tf_scene_free(p->scene);
}

int tf_paint_run(const tf_paint_opts *o)
{
    const char *why = tf_paint_params_problem(&o->params);
    if (why) {
        tf_error("paint: %s", why);
        return 2;
    }
    signal(SIGPIPE, SIG_IGN);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    paint p = {.o = o};
    p.st.paused = o->paused;
    int rc = load_scene(&p);
    if (!rc)
        rc = load_secret(&p);
    if (!rc)
        rc = build_terrain(&p);
    if (!rc)
        rc = start_space(&p);
    if (!rc)
        rc = begin_view(&p, p.scene->text) ? 1 : 0;
    if (!rc)
        rc = start_workers(&p);
    if (!rc)
        rc = start_http(&p);
    if (!rc)
        rc = paint_run_loop(&p);
    paint_close(&p);
    return rc;
}
