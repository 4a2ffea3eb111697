/* networked.c: see networked.h. */
#include "worker/networked.h"

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include "clock.h"
#include "log.h"
#include "render/render.h"
#include "scene.h"
#include "worker/backend.h"
#include "worker/backend_opencl.h"
#include "worker/erosion_patch.h"
#include "worker/opencl_ahead.h"
#include "worker/paint_worker.h"
#include "worker/payloads.h"
#include "linda/auth.h"
#include "linda/tsclient.h"
#include "terrain/heightfield.h"
#include "terrain/terrain.h"
#include "worker/simulate.h"
#include "worker/worker.h"

/* A connection failure that trying again cannot cure: the coordinator refused us (a wrong
 * secret, a refused request), or what answered is not a terrafarm coordinator. */
static int failure_is_final(const char *err)
{
    static const char *final[] = {"refused:", "authentication failed", "requires a secret",
                                  "does not authenticate", "failed to prove",
                                  "not a terrafarm coordinator", "cannot resolve",
                                  "Name or service not known"};
    for (size_t i = 0; i < sizeof final / sizeof final[0]; i++)
        if (strstr(err, final[i]))
            return 1;
    return 0;
}

/* Connect, retrying with backoff (250 ms doubling to 4 s) for at most timeout_ms while the
 * coordinator cannot be reached or turns the connection away unheard: a worker started before
 * its coordinator (a boot script, a batch job, "Connection refused") waits for it, one that
 * lost it (a pause, a partition, a restart) comes back, and one whose address is crowded by
 * failed handshakes (a guesser beside it) tries again.  A final failure (its own wrong secret,
 * answered as such; not a coordinator) ends at once. */
ts_client *tf_networked_connect(const char *hostport, const uint8_t *key, int timeout_ms,
                                char *err, size_t errlen)
{
    int64_t t0 = tf_now_ms();
    int backoff_ms = 250;
    for (;;) {
        int64_t left = timeout_ms - (tf_now_ms() - t0);
        ts_client *c = ts_client_connect(hostport, key, left > 1000 ? (int)left : 1000, err,
                                         errlen);
        if (c || failure_is_final(err))
            return c;
        if (tf_now_ms() - t0 + backoff_ms > timeout_ms)
            return NULL;
        usleep((useconds_t)backoff_ms * 1000);
        backoff_ms = backoff_ms * 2 > 4000 ? 4000 : backoff_ms * 2;
    }
}

/* After a reconnection: is the coordinator still rendering the scene this worker built? */
static int same_render(ts_client *c, const char *connect, const tf_scene *s)
{
    char err[1024];
    tf_scene *now = tf_worker_fetch_scene(c, connect, err, sizeof err);
    if (!now) {
        tf_error("%s", err);
        return 0;
    }
    int same = !strcmp(now->hash_hex, s->hash_hex) && now->width == s->width &&
               now->height == s->height;
    if (!same)
        tf_error("%s now renders another scene (%.12s, %dx%d); leaving", connect, now->hash_hex,
                 now->width, now->height);
    tf_scene_free(now);
    return same;
}

/* One worker process: serve the render, reconnecting (and joining again under a new id) each
 * time the coordinator is lost, until the stop tuple or --timeout without a coordinator.  A
 * result held when the connection broke is not resent: the coordinator dealt its task again
 * when the connection closed.  first: an open connection to start with, or NULL. */
static int run_one(const char *connect, const uint8_t *key, int timeout_ms, const tf_scene *s,
                   const tf_heightfield *hf, const char *backend, int paint, ts_client *first)
{
    char err[1024];
    for (int round = 0;; round++) {
        ts_client *c = round == 0 && first ? first
                                           : tf_networked_connect(connect, key, timeout_ms, err,
                                                               sizeof err);
        if (!c) {
            tf_error("%s%s", round ? "cannot reconnect: " : "", err);
            return 1;
        }
        if (round > 0 && !same_render(c, connect, s)) {
            ts_client_close(c);
            return 1;
        }
        int status = paint ? tf_paint_worker_loop(c, s, hf, "networked")
                           : tf_worker_loop(c, s, hf, "networked", backend);
        ts_client_close(c);
        if (status != TF_WORKER_EXIT_LOST)
            return status;
        tf_info("reconnecting to %s (for up to %.1f s)", connect, timeout_ms / 1000.0);
    }
}

/* --simulate: n synthetic workers on the cost map at path; prints one report line on stdout
 * (key=value pairs, for scripts such as bench/scale_sim.sh). */
static int run_simulated(const char *connect, const uint8_t *key, int timeout_ms,
                         const tf_scene *s, const char *path, int n, double pixel_us,
                         const char *payloads_path)
{
    char err[1024];
    tf_cost_map map;
    if (tf_cost_map_load(path, &map, err, sizeof err)) {
        tf_error("%s", err);
        return 1;
    }
    tf_payloads *payloads = NULL;
    if (payloads_path && !(payloads = tf_payloads_load(payloads_path, err, sizeof err))) {
        tf_error("%s", err);
        tf_cost_map_free(&map);
        return 1;
    }
    if (!payloads)
        tf_warn("simulated workers without --payloads send encoded black pixels, which compress "
                "to almost nothing: the coordinator's load is not a real farm's");
    tf_info("joining %s as %d simulated workers: %dx%d render, %.1f us per average pixel",
            connect, n, s->width, s->height, pixel_us);
    tf_sim_config cfg = {connect, key, timeout_ms, n, pixel_us, &map, s->width, s->height,
                         payloads};
    tf_sim_report r;
    int rc = tf_simulate_run(&cfg, &r, err, sizeof err);
    tf_cost_map_free(&map);
    tf_payloads_free(payloads);
    printf("simulated workers=%d tasks=%lld ops=%lld wall_s=%.3f modelled_s=%.3f "
           "slept_s=%.3f efficiency=%.4f ops_per_s=%.0f take_mean_ms=%.3f take_p50_ms=%.3f "
           "take_p99_ms=%.3f take_max_ms=%.3f oversleep_ms=%.3f bound_s=%.3f "
           "bound_efficiency=%.4f\n",
           r.workers, (long long)r.tasks, (long long)r.ops, r.wall_s, r.modelled_s,
           r.slept_s, r.efficiency, r.wall_s > 0 ? (double)r.ops / r.wall_s : 0.0, r.take_mean_ms,
           r.take_p50_ms, r.take_p99_ms, r.take_max_ms, r.slept_over_ms, r.bound_s,
           r.bound_efficiency);
    fflush(stdout);
    if (rc) {
        tf_error("%s", err);
        return 1;
    }
    return 0;
}

/* nproc worker processes sharing the scene and the height field copy-on-write, each with its
 * own connection; 0 when every one finished cleanly. */
static int run_processes(int nproc, const char *connect, const uint8_t *key, int timeout_ms,
                         const tf_scene *s, const tf_heightfield *hf, const char *backend,
                         int paint)
{
    pid_t *pids = calloc((size_t)nproc, sizeof *pids);
    if (!pids) {
        tf_error("out of memory");
        return 1;
    }
    int status = 0;
    tf_backend_share_cores(backend, nproc);
    for (int i = 0; i < nproc; i++) {
        pid_t p = fork();
        if (p == 0) {
            prctl(PR_SET_PDEATHSIG, SIGTERM);
            _exit(run_one(connect, key, timeout_ms, s, hf, backend, paint, NULL));
        }
        pids[i] = p;
        if (p < 0)
            tf_warn("fork: cannot start worker process %d", i);
    }
    for (int i = 0; i < nproc; i++) {
        int st;
        if (pids[i] > 0 && waitpid(pids[i], &st, 0) == pids[i] &&
            !(WIFEXITED(st) && WEXITSTATUS(st) == 0))
            status = 1;
    }
    free(pids);
    return status;
}

/* Start the OpenCL device on a thread while the terrain is built (opencl_ahead.h), when this
 * process will render with it itself: one process (more are forked, and OpenCL state must not
 * cross a fork), a render (painting uses the C renderer), and a terrain the kernels trace.
 * 1 if started. */
static int open_device_ahead(const tf_scene *s, const char *backend, int paint, int nproc)
{
    if (paint || nproc != 1 || !backend || (strcmp(backend, "opencl") && strcmp(backend, "auto")))
        return 0;
    if (tf_cl_scene_unsupported(s))
        return 0;
    return tf_opencl_ahead_start() == 0;
}

/* --simulate with --payloads: refuse a recording that cannot stand in for this render's
 * results before joining (its layout from the coordinator on c).  0 if it fits. */
static int payloads_fit_render(ts_client *c, const char *path)
{
    char err[1024];
    tf_exr_layout l;
    tf_payloads *rec = tf_worker_fetch_layout(c, &l, err, sizeof err) == 0
                           ? tf_payloads_load(path, err, sizeof err)
                           : NULL;
    int fits = rec && tf_payloads_fit(rec, &l, err, sizeof err) == 0;
    tf_payloads_free(rec);
    if (!fits)
        tf_error("%s", err);
    return fits ? 0 : -1;
}

/* --simulate: the synthetic workers in place of real ones (c, the scene's connection, is
 * closed first). */
static int serve_simulated(const tf_networked_opts *o, const uint8_t *key, ts_client *c,
                           const tf_scene *s, int paint)
{
    if (paint)
        tf_error("%s paints (terrafarm paint): --simulate serves renders only", o->connect);
    const int refused = paint || (o->payloads && payloads_fit_render(c, o->payloads));
    ts_client_close(c);
    if (refused)
        return 1;
    return run_simulated(o->connect, key, o->timeout_ms, s, o->simulate_model,
                         o->processes ? o->processes : 16, o->pixel_us, o->payloads);
}

/* A render or a paint: the height field built (the OpenCL device started alongside where this
 * process renders with it), then one worker on c, or the processes asked for on connections of
 * their own (c closed). */
static int serve_render(const tf_networked_opts *o, const uint8_t *key, ts_client *c,
                        const tf_scene *s, int paint)
{
    char err[1024];
    int nproc = o->processes ? o->processes : tf_thread_count(0);
    tf_info("joining %s: %dx%d render of a %s terrain; building the height field", o->connect,
            s->width, s->height, tf_generator_name(s->terrain.generator));
    ts_client_heartbeat(c, TF_WORKER_HEARTBEAT_MS); /* stay alive while the terrain builds */
    if (open_device_ahead(s, o->backend, paint, nproc))
        tf_debug("OpenCL: starting the device while the terrain is built");
    tf_heightfield *hf = tf_heightfield_build(s, 0, err, sizeof err);
    if (!hf) {
        tf_error("%s", err);
        tf_opencl_ahead_drop();
        ts_client_close(c);
        return 1;
    }
    if (o->terrain_cache)
        tf_heightfield_set_cache(hf, o->terrain_cache);
    tf_render_prepare(s, hf, 0); /* once, on all cores, for the processes forked below */
    int status;
    if (nproc == 1) {
        status = run_one(o->connect, key, o->timeout_ms, s, hf, o->backend, paint, c);
    } else {
        ts_client_close(c);
        status = run_processes(nproc, o->connect, key, o->timeout_ms, s, hf, o->backend, paint);
    }
    if (status == 0)
        tf_info("%s finished; worker leaving", paint ? "painting" : "render");
    tf_opencl_ahead_drop(); /* not taken: the worker ended before making its backend */
    tf_heightfield_free(hf);
    return status;
}

int tf_networked_worker_run(const tf_networked_opts *o)
{
    signal(SIGPIPE, SIG_IGN);
    uint8_t key[TF_KEY_BYTES];
    char err[1024];
    if (o->secret_file &&
        (tf_auth_init() || tf_secret_load(o->secret_file, key, err, sizeof err))) {
        tf_error("%s", err);
        return 1;
    }
    const uint8_t *k = o->secret_file ? key : NULL;
    /* The scene, from the coordinator (tsnet model): the first connection only reads it. */
    ts_client *c = tf_networked_connect(o->connect, k, o->timeout_ms, err, sizeof err);
    int kind = TF_SPACE_RENDER;
    tf_scene *s = c ? tf_worker_fetch_scene_ex(c, o->connect, &kind, err, sizeof err) : NULL;
    if (!s) {
        tf_error("%s", err);
        if (c)
            ts_client_close(c);
        return 1;
    }
    int status;
    if (kind == TF_SPACE_EROSION) { /* the coordinator runs an erosion: serve one patch of it */
        status = tf_erosion_networked(c, s, o->connect, TF_WORKER_HEARTBEAT_MS);
        ts_client_close(c);
    } else if (o->simulate_model) {
        status = serve_simulated(o, k, c, s, kind == TF_SPACE_PAINT);
    } else {
        status = serve_render(o, k, c, s, kind == TF_SPACE_PAINT);
    }
    tf_scene_free(s);
    return status;
}
