/* erosion_farm.c: an erosion run on forked workers through the tuple space (erosion_farm.h):
 * the coordinator's side of common/erosion_tuples.h.
 *
 * Steps: 1. the initial state (every worker inherits it: the scene determines it) and the
 * plan; 2. a tuple space and its server, one forked worker per patch on a socketpair; 3. one
 * ("erode_patch") tuple per patch; 4. serve the space while the workers trade edges, taking
 * their final bands and tallies as they come, each checked; 5. the blob, into the cache. */
#include "coordinator/erosion/erosion_farm.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include "linda/tsclient.h"
#include "linda/tsserver.h"
#include "linda/tuplespace.h"
#include "terrain/eroded.h"
#include "terrain/erosion_run.h"
#include "terrain/erosion_state.h"
#include "terrain/terrain_build.h"
#include "worker/erosion_patch.h"
#include "coordinator/erosion/erosion_role.h"
#include "farmproto.h"
#include "heightmap_tuples.h"
#include "clock.h"
#include "log.h"

typedef struct farm {
    const tf_scene *s;
    const tf_terrain *t;
    const tf_erosion_farm_opts *o;
    tf_erosion_plan plan;
    tf_erosion_model m;
    tf_erosion_state st;       /* the initial state, then the final one, band by band */
    ts_space *space;
    ts_server *srv;
    pid_t *pid;
    int patches;
    int *rows_in;              /* per patch: rows of its final state received */
    int *tallied;
    tf_erosion_tally tally;
    int done;                  /* patches complete */
    tf_erosion_owners owners;  /* which connection took which patch (erosion_role.h) */
    ts_role role;
    int taken;                 /* patches taken so far, and when the last one was */
    double t_all_taken;
    int *left;                 /* per patch: its worker left (check it handed all in) */
    char (*peer)[64];          /* per patch: that worker's name */
} farm;

static void on_take(void *ctx, uint64_t conn, const tf_tuple *t)
{
    farm *f = ctx;
    const char *name = tf_tuple_name(t);
    tf_erosion_owners_take(&f->owners, conn, t);
    if (name && !strcmp(name, "erode_patch") && ++f->taken == f->patches)
        f->t_all_taken = tf_now_s(); /* the erosion's clock: every worker has its patch */
}

/* A connection that leaves holding a patch: its final bands were put before it left (one
 * connection's requests are served in order), so serve() checks, after collecting, that the
 * patch is complete; if not, its neighbours would wait for its edges forever. */
static void on_disconnect(void *ctx, uint64_t conn, const char *peer)
{
    farm *f = ctx;
    int p = tf_erosion_owners_patch(&f->owners, conn);
    if (p < 0)
        return;
    f->left[p] = 1;
    f->owners.conn[p] = 0;
    snprintf(f->peer[p], sizeof f->peer[p], "%s", peer ? peer : "a worker");
}

static int patch_complete(const farm *f, int p)
{
    int i0, i1, j0, j1;
    tf_erosion_patch_rect(&f->plan, p, &i0, &i1, &j0, &j1);
    return f->rows_in[p] == j1 - j0 && f->tallied[p];
}

/* The child: one patch, then leave. */
static void child(farm *f, int fd, int index)
{
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    signal(SIGINT, SIG_IGN);
    signal(SIGPIPE, SIG_IGN);
    char tag[32];
    snprintf(tag, sizeof tag, "erosion worker %d", index);
    tf_log_set_tag(tag);
    ts_client *c = ts_client_from_fd(fd);
    int status = c ? tf_erosion_patch_serve(c, &f->plan, &f->m, &f->st, tag) : 1;
    ts_client_close(c);
    _exit(status);
}

static int spawn(farm *f, int index, char *err, size_t errlen)
{
    int sv[2];
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv))
        return tf_seterr(err, errlen, "socketpair: %s", strerror(errno));
    pid_t pid = fork();
    if (pid < 0) {
        close(sv[0]);
        close(sv[1]);
        return tf_seterr(err, errlen, "fork: %s", strerror(errno));
    }
    if (pid == 0) {
        close(sv[0]);
        child(f, sv[1], index);
    }
    close(sv[1]);
    f->pid[index] = pid;
    char peer[40];
    snprintf(peer, sizeof peer, "erosion worker %d", index);
    if (!ts_server_add_fd(f->srv, sv[0], peer))
        return tf_seterr(err, errlen, "cannot serve erosion worker %d", index);
    return 0;
}

/* What a networked worker reads first: the plan, then the scene (with its height map). */
static int put_plan_and_scene(farm *f)
{
    const tf_erosion_plan *p = &f->plan;
    tf_tuple t;
    tf_tuple_init(&t);
    if (tf_tuple_pack(&t, "siiiiii", "erode_plan", p->job, (int64_t)p->n, (int64_t)p->px,
                      (int64_t)p->py, (int64_t)p->halo, (int64_t)p->steps) ||
        ts_space_out(f->space, &t))
        return -1;
    tf_scene_msg m = {f->s->text, f->s->width, f->s->height, f->s->hash_hex, TF_EROSION_LAYOUT};
    tf_tuple_init(&t);
    if (tf_scene_tuple_pack(&t, &m) || ts_space_out(f->space, &t))
        return -1;
    return tf_heightmap_tuples_put(f->space, f->s);
}

static int deal(farm *f)
{
    if (put_plan_and_scene(f) != 0)
        return -1;
    for (int p = 0; p < f->patches; p++) {
        tf_tuple t;
        tf_tuple_init(&t);
        if (tf_tuple_pack(&t, "sii", "erode_patch", f->plan.job, (int64_t)p) ||
            ts_space_out(f->space, &t))
            return -1;
    }
    return 0;
}

/* A final band of patch p: its place, its size, its values; then into the grid state. */
static int take_band(farm *f, const tf_tuple *got, char *err, size_t errlen)
{
    int64_t p, row, rows;
    const uint8_t *data;
    size_t len;
    if (got->nfields != 6 || tf_tuple_get_int(got, 2, &p) || tf_tuple_get_int(got, 3, &row) ||
        tf_tuple_get_int(got, 4, &rows) || tf_tuple_get_blob(got, 5, &data, &len) || p < 0 ||
        p >= f->patches)
        return tf_seterr(err, errlen, "erosion: malformed final band");
    int i0, i1, j0, j1;
    tf_erosion_patch_rect(&f->plan, (int)p, &i0, &i1, &j0, &j1);
    char from[64];
    snprintf(from, sizeof from, "erosion: patch %d's final band at row %d", (int)p, (int)row);
    if (row != f->rows_in[p] || rows < 1 || row + rows > j1 - j0)
        return tf_seterr(err, errlen, "%s: %d rows where row %d of %d was due", from, (int)rows,
                         f->rows_in[p], j1 - j0);
    if (tf_erosion_block_check(data, len, (int)rows, i1 - i0, from, err, errlen) != 0)
        return -1;
    tf_erosion_view v = {f->st.b, f->st.t, f->st.d, f->st.w, f->st.s, f->st.flow, f->st.soft,
                         (size_t)f->st.n, 0, 0, f->st.n, f->st.n, NULL /* unpacked, not stepped */};
    tf_erosion_rect r = {j0 + (int)row, j0 + (int)(row + rows), i0, i1};
    tf_erosion_block_unpack(&v, r, data);
    f->rows_in[p] += (int)rows;
    f->done += f->rows_in[p] == j1 - j0 && f->tallied[p];
    return 0;
}

static int take_tally(farm *f, const tf_tuple *got, char *err, size_t errlen)
{
    int64_t p, v[4];
    if (got->nfields != 7 || tf_tuple_get_int(got, 2, &p) || p < 0 || p >= f->patches ||
        f->tallied[p])
        return tf_seterr(err, errlen, "erosion: malformed or repeated tally");
    for (int k = 0; k < 4; k++)
        if (tf_tuple_get_int(got, 3 + k, &v[k]) || v[k] < 0)
            return tf_seterr(err, errlen, "erosion: patch %d's tally is malformed", (int)p);
    f->tally.rain += v[0];
    f->tally.evaporated += v[1];
    f->tally.out_water += v[2];
    f->tally.out_load += v[3];
    f->tallied[p] = 1;
    int i0, i1, j0, j1;
    tf_erosion_patch_rect(&f->plan, (int)p, &i0, &i1, &j0, &j1);
    f->done += f->rows_in[p] == j1 - j0;
    return 0;
}

/* Take whatever finals, tallies and failures are in the space now.  0, or -1 (err set). */
static int collect(farm *f, char *err, size_t errlen)
{
    static const char *const names[3] = {"erode_final", "erode_tally", "erode_failed"};
    static const char *const formats[3] = {"siIIIB", "siIIIII", "siIS"};
    for (int k = 0; k < 3; k++)
        for (;;) {
            tf_tuple tmpl, got;
            tf_tuple_init(&tmpl);
            tf_tuple_init(&got);
            int found = tf_tuple_pack(&tmpl, formats[k], names[k], f->plan.job) == 0 &&
                        ts_space_inp(f->space, &tmpl, &got) == 1;
            const char *why;
            int rc = !found ? 1
                     : k == 0 ? take_band(f, &got, err, errlen)
                     : k == 1 ? take_tally(f, &got, err, errlen)
                     : tf_tuple_get_string(&got, 3, &why) == 0
                         ? tf_seterr(err, errlen, "erosion failed on a worker: %s", why)
                         : tf_seterr(err, errlen, "erosion failed on a worker");
            tf_tuple_clear(&tmpl);
            tf_tuple_clear(&got);
            if (rc < 0)
                return -1;
            if (rc > 0)
                break;
        }
    return 0;
}

/* A worker that left before its patch was in fails the erosion (its neighbours would wait). */
static int check_workers(farm *f, char *err, size_t errlen)
{
    for (int p = 0; p < f->patches; p++) {
        int status;
        if (f->pid[p] > 0 && waitpid(f->pid[p], &status, WNOHANG) == f->pid[p]) {
            f->pid[p] = 0;
            if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
                return tf_seterr(err, errlen, "erosion worker %d died (%s %d) before the "
                                 "erosion finished", p, WIFEXITED(status) ? "exit" : "signal",
                                 WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status));
        }
    }
    return 0;
}

static int serve(farm *f, char *err, size_t errlen)
{
    while (f->done < f->patches) {
        if (ts_server_run_once(f->srv, 100) < 0)
            return tf_seterr(err, errlen, "erosion: the tuple-space server failed");
        if (collect(f, err, errlen) != 0)
            return -1;
        for (int p = 0; p < f->patches; p++)
            if (f->left[p] && !patch_complete(f, p))
                return tf_seterr(err, errlen, "erosion: %s left holding patch %d before handing "
                                 "it in", f->peer[p], p);
        if (f->done < f->patches && check_workers(f, err, errlen) != 0) {
            collect(f, err, errlen); /* a worker's own word on why, if it said */
            return -1;
        }
    }
    return 0;
}

static void stop_workers(farm *f)
{
    for (int p = 0; p < f->patches; p++)
        if (f->pid[p] > 0) {
            kill(f->pid[p], SIGKILL);
            waitpid(f->pid[p], NULL, 0);
        }
}

/* 1. The raw heights' state and the plan. */
static int prepare(farm *f, int workers, int halo, double *extent, char *err, size_t errlen)
{
    int n = (1 << f->t->size_exp) + 1;
    int rc = tf_terrain_erosion_start(f->t, extent, &f->m, &f->st, err, errlen);
    if (rc == 0 && tf_erosion_plan_make(&f->plan, 1, n, workers,
                                        halo > 0 ? halo : TF_EROSION_DEFAULT_HALO,
                                        f->m.steps) != 0)
        rc = tf_seterr(err, errlen, "erosion: a %dx%d grid is too small for %d workers", n, n,
                       workers);
    return rc;
}

/* 2. The server: fds of forked workers, and a listening socket for networked ones. */
static int open_server(farm *f, char *err, size_t errlen)
{
    f->owners.patches = f->patches;
    f->owners.conn = calloc((size_t)f->patches, sizeof *f->owners.conn);
    if (!f->owners.conn)
        return tf_seterr(err, errlen, "out of memory");
    /* the largest tuple: a final band (8 MiB, erosion_patch.c) or an edge */
    size_t edge = tf_erosion_block_bytes(f->plan.halo, f->plan.n);
    tf_erosion_role_init(&f->role, &f->owners, (edge > (9u << 20) ? edge : (9u << 20)) + 4096);
    ts_server_config cfg = {0};
    cfg.listen = f->o->remote > 0 ? f->o->listen : NULL;
    cfg.key = f->o->key;
    cfg.role = &f->role;
    ts_server_hooks hooks = {f, on_take, NULL, on_disconnect};
    f->srv = ts_server_new(f->space, &cfg, &hooks, err, errlen);
    if (f->srv && cfg.listen)
        tf_info("erosion: %d patches (%dx%d), %d networked workers expected at port %d",
                f->patches, f->plan.px, f->plan.py, f->o->remote, ts_server_port(f->srv));
    return f->srv ? 0 : -1;
}

/* 2-4. The space, the workers, the patches, the rounds. */
static int run(farm *f, char *err, size_t errlen)
{
    f->patches = f->plan.px * f->plan.py;
    f->pid = calloc((size_t)f->patches, sizeof *f->pid);
    f->rows_in = calloc((size_t)f->patches, sizeof *f->rows_in);
    f->tallied = calloc((size_t)f->patches, sizeof *f->tallied);
    f->left = calloc((size_t)f->patches, sizeof *f->left);
    f->peer = calloc((size_t)f->patches, sizeof *f->peer);
    f->space = ts_space_new();
    if (!f->pid || !f->rows_in || !f->tallied || !f->left || !f->peer || !f->space)
        return tf_seterr(err, errlen, "out of memory");
    if (open_server(f, err, errlen) != 0)
        return -1;
    for (int p = 0; p < f->o->forked; p++)
        if (spawn(f, p, err, errlen) != 0)
            return -1;
    if (deal(f) != 0)
        return tf_seterr(err, errlen, "out of memory");
    return serve(f, err, errlen);
}

static void farm_free(farm *f)
{
    if (f->pid)
        stop_workers(f);
    ts_server_free(f->srv);
    ts_space_free(f->space);
    free(f->pid);
    free(f->rows_in);
    free(f->tallied);
    free(f->owners.conn);
    free(f->left);
    free(f->peer);
    tf_erosion_state_free(&f->st);
}

/* What the erosion cost and how it was cut (after a successful run). */
static void fill_reports(const farm *f, double t0, tf_erosion_report *rep,
                         tf_erosion_farm_report *fr)
{
    int n = f->m.n;
    /* from the moment every patch has a worker (networked ones join when they join) */
    rep->seconds = tf_now_s() - (f->t_all_taken > 0 ? f->t_all_taken : t0);
    rep->vertex_steps = (double)n * n * f->m.steps;
    rep->tally = f->tally;
    rep->solid_after = tf_erosion_solid(&f->st, n);
    rep->quantum = f->m.q;
    rep->isa = tf_erosion_isa();
    rep->threads = 1;
    *fr = (tf_erosion_farm_report){f->patches, f->o->remote, f->plan.px, f->plan.py,
                                   f->plan.halo,
                                   tf_erosion_plan_edge_bytes(&f->plan) / f->plan.halo};
}

/* 5. The blob of the final state, logged and kept in the cache. */
static int keep(const farm *f, double extent, uint8_t **bytes, size_t *len,
                tf_erosion_report *rep, char *err, size_t errlen)
{
    *bytes = tf_eroded_encode(f->t, &f->st, &f->m, extent, len);
    if (!*bytes)
        return tf_seterr(err, errlen, "out of memory: the eroded terrain");
    char how[64];
    snprintf(how, sizeof how, "%d workers (%d networked), %dx%d patches", f->patches,
             f->o->remote, f->plan.px, f->plan.py);
    tf_eroded_log(f->t, f->m.n, rep, how);
    tf_eroded_to_cache(f->t, *bytes, *len, rep);
    return 0;
}

int tf_erosion_farm(const tf_scene *s, const tf_erosion_farm_opts *o, uint8_t **bytes,
                    size_t *len, tf_erosion_report *rep, tf_erosion_farm_report *fr, char *err,
                    size_t errlen)
{
    const tf_terrain *t = &s->terrain;
    int n = (1 << t->size_exp) + 1;
    memset(rep, 0, sizeof *rep);
    memset(fr, 0, sizeof *fr);
    *bytes = tf_eroded_from_cache(t, n, len, rep);
    if (*bytes)
        return 0;
    farm f = {.s = s, .t = t, .o = o};
    double extent = t->extent;
    int rc = prepare(&f, o->forked + o->remote, o->halo, &extent, err, errlen);
    rep->solid_before = rc == 0 ? tf_erosion_solid(&f.st, n) : 0;
    double t0 = tf_now_s();
    if (rc == 0)
        rc = run(&f, err, errlen);
    if (rc == 0) {
        fill_reports(&f, t0, rep, fr);
        rc = keep(&f, extent, bytes, len, rep, err, errlen);
    }
    farm_free(&f);
    return rc;
}
