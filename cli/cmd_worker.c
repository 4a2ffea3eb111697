/* cmd_worker.c: `terrafarm worker --connect HOST:PORT [-j N]`: a networked worker (the tsnet
 * model).  It reads the scene from the coordinator's tuple space, builds the terrain itself
 * (once, on all cores), then runs N worker processes that share it copy-on-write, each with
 * its own connection, until the render is finished.
 *
 * With --simulate MODEL it joins as N synthetic workers instead (worker/simulate.h): threads
 * that sleep each task's modelled cost from a cost map, to measure the coordinator with far
 * more workers than there are cores. */
#include <getopt.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "linda/auth.h"
#include "clock.h"
#include "cli/commands.h"
#include "terrain/heightfield.h"
#include "log.h"
#include "scene.h"
#include "worker/simulate.h"
#include "linda/tsclient.h"
#include "worker/worker.h"

static const char usage[] =
    "usage: terrafarm worker --connect HOST:PORT [options]\n"
    "\n"
    "Join a render as a networked worker: fetch the scene from the coordinator, build the\n"
    "terrain, and render tasks until the render is finished.\n"
    "\n"
    "  -c, --connect HOST:PORT   the coordinator (terrafarm render ... --listen HOST:PORT)\n"
    "      --secret-file FILE    shared secret, if the coordinator requires one\n"
    "      --backend c|opencl|auto  rendering backend (default c; auto: OpenCL if a device\n"
    "                            works, else C with a warning)\n"
    "      --cl-device DEV       OpenCL device: P:D indices or a name substring\n"
    "                            (same as TERRAFARM_CL_DEVICE)\n"
    "  -j, --workers N           worker processes on this machine (default: online CPUs)\n"
    "      --timeout T           keep trying to reach the coordinator for T (default 10s; T is\n"
    "                            a number with ms, s, m or h; a bare number is milliseconds)\n"
    "      --simulate MODEL      synthetic workers: sleep each task's modelled cost from the cost\n"
    "                            map MODEL (terrafarm bench SCENE --cost-map MODEL) instead of\n"
    "                            rendering; -j N threads in this process; prints a report line\n"
    "      --pixel-us U          with --simulate: modelled cost of an average pixel (default 50)\n"
    "  -q, --quiet / -v, --verbose\n"
    "  -h, --help\n";

/* Connect, retrying while the coordinator is not (yet) listening, for at most timeout_ms: a
 * worker started before its coordinator (a boot script, a batch job) simply waits for it.
 * Any other failure (refused secret, bad address) is final at once. */
static ts_client *connect_patiently(const char *hostport, const uint8_t *key, int timeout_ms,
                                    char *err, size_t errlen)
{
    int64_t t0 = tf_now_ms();
    for (;;) {
        ts_client *c = ts_client_connect(hostport, key, timeout_ms, err, errlen);
        if (c || !strstr(err, "Connection refused"))
            return c;
        double waited_ms = (double)(tf_now_ms() - t0);
        if (waited_ms + 250 > timeout_ms)
            return NULL;
        usleep(250 * 1000);
    }
}

static int run_one(const char *connect, const uint8_t *key, int timeout_ms, const tf_scene *s,
                   const tf_heightfield *hf, const char *backend)
{
    char err[1024];
    ts_client *c = connect_patiently(connect, key, timeout_ms, err, sizeof err);
    if (!c) {
        tf_error("%s", err);
        return 1;
    }
    int status = tf_worker_loop(c, s, hf, "networked", backend);
    ts_client_close(c);
    return status;
}

/* --simulate: n synthetic workers on the cost map at path; prints one report line on stdout
 * (key=value pairs, for scripts such as bench/scale_sim.sh). */
static int run_simulated(const char *connect, const uint8_t *key, int timeout_ms,
                         const tf_scene *s, const char *path, int n, double pixel_us)
{
    char err[1024];
    tf_cost_map map;
    if (tf_cost_map_load(path, &map, err, sizeof err)) {
        tf_error("%s", err);
        return TF_EXIT_FAIL;
    }
    tf_info("joining %s as %d simulated workers: %dx%d render, %.1f us per average pixel",
            connect, n, s->width, s->height, pixel_us);
    tf_sim_config cfg = {connect, key, timeout_ms, n, pixel_us, &map, s->width, s->height};
    tf_sim_report r;
    int rc = tf_simulate_run(&cfg, &r, err, sizeof err);
    tf_cost_map_free(&map);
    printf("simulated workers=%d tasks=%lld ops=%lld wall_s=%.3f modelled_s=%.3f "
           "slept_s=%.3f efficiency=%.4f ops_per_s=%.0f take_mean_ms=%.3f take_p50_ms=%.3f "
           "take_p99_ms=%.3f take_max_ms=%.3f oversleep_ms=%.3f\n",
           r.workers, (long long)r.tasks, (long long)r.ops, r.wall_s, r.modelled_s,
           r.slept_s, r.efficiency, r.wall_s > 0 ? (double)r.ops / r.wall_s : 0.0, r.take_mean_ms,
           r.take_p50_ms, r.take_p99_ms, r.take_max_ms, r.slept_over_ms);
    fflush(stdout);
    if (rc) {
        tf_error("%s", err);
        return TF_EXIT_FAIL;
    }
    return TF_EXIT_OK;
}

int cmd_worker(int argc, char **argv)
{
    enum { O_SECRET = 256, O_BACKEND, O_TIMEOUT, O_SIMULATE, O_PIXEL_US, O_CL_DEVICE };
    static const struct option longopts[] = {
        {"connect", required_argument, NULL, 'c'},
        {"secret-file", required_argument, NULL, O_SECRET},
        {"backend", required_argument, NULL, O_BACKEND},
        {"workers", required_argument, NULL, 'j'},
        {"timeout", required_argument, NULL, O_TIMEOUT},
        {"simulate", required_argument, NULL, O_SIMULATE},
        {"pixel-us", required_argument, NULL, O_PIXEL_US},
        {"cl-device", required_argument, NULL, O_CL_DEVICE},
        {"quiet", no_argument, NULL, 'q'},
        {"verbose", no_argument, NULL, 'v'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    const char *connect = NULL, *secret = NULL, *backend = "c", *model = NULL;
    double pixel_us = 50.0;
    int nproc = 0, timeout_ms = 10000, ch;
    char *end;
    optind = 1;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":c:j:qvh", longopts, NULL)) != -1) {
        switch (ch) {
        case 'c': connect = optarg; break;
        case O_SECRET: secret = optarg; break;
        case O_BACKEND:
            if (strcmp(optarg, "c") && strcmp(optarg, "opencl") && strcmp(optarg, "auto")) {
                tf_error("--backend '%s': expected c, opencl or auto", optarg);
                return TF_EXIT_USAGE;
            }
            backend = optarg;
            break;
        case 'j':
            nproc = (int)strtol(optarg, &end, 10);
            if (end == optarg || *end || nproc < 1 || nproc > 4096) {
                tf_error("--workers '%s': expected an integer from 1 to 4096", optarg);
                return TF_EXIT_USAGE;
            }
            break;
        case O_TIMEOUT:
        {
            int64_t ms;
            if (tf_parse_duration_ms(optarg, &ms) || ms < 1 || ms > INT32_MAX) {
                tf_error("--timeout '%s': expected a positive duration (e.g. 10s, 500ms, 2m; a "
                         "bare number is milliseconds)", optarg);
                return TF_EXIT_USAGE;
            }
            timeout_ms = (int)ms;
            break;
        }
        case O_SIMULATE: model = optarg; break;
        case O_CL_DEVICE: setenv("TERRAFARM_CL_DEVICE", optarg, 1); break;
        case O_PIXEL_US:
            pixel_us = strtod(optarg, &end);
            if (end == optarg || *end || !(pixel_us >= 0 && pixel_us <= 1e9)) {
                tf_error("--pixel-us '%s': expected a number of microseconds >= 0", optarg);
                return TF_EXIT_USAGE;
            }
            break;
        case 'q': tf_log_set_level(TF_LOG_WARN); break;
        case 'v': tf_log_set_level(TF_LOG_DEBUG); break;
        case 'h': fputs(usage, stdout); return TF_EXIT_OK;
        case ':':
            tf_error("worker: option '%s' needs a value", argv[optind - 1]);
            return TF_EXIT_USAGE;
        default:
            tf_error("worker: unknown option '%s' (see terrafarm worker --help)", argv[optind - 1]);
            return TF_EXIT_USAGE;
        }
    }
    if (!connect || optind != argc) {
        tf_error(!connect ? "worker: --connect HOST:PORT is required"
                          : "worker: unexpected argument '%s'",
                 argv[optind]);
        return TF_EXIT_USAGE;
    }
    signal(SIGPIPE, SIG_IGN);
    uint8_t key[TF_KEY_BYTES];
    char err[1024];
    if (secret && (tf_auth_init() || tf_secret_load(secret, key, err, sizeof err))) {
        tf_error("%s", err);
        return TF_EXIT_FAIL;
    }
    const uint8_t *k = secret ? key : NULL;

    /* The scene, from the coordinator (tsnet model): the first connection only reads it. */
    ts_client *c = connect_patiently(connect, k, timeout_ms, err, sizeof err);
    if (!c) {
        tf_error("%s", err);
        return TF_EXIT_FAIL;
    }
    tf_scene *s = tf_worker_fetch_scene(c, connect, err, sizeof err);
    if (!s) {
        tf_error("%s", err);
        ts_client_close(c);
        return TF_EXIT_FAIL;
    }
    if (model) {
        ts_client_close(c);
        int status = run_simulated(connect, k, timeout_ms, s, model, nproc ? nproc : 16,
                                   pixel_us);
        tf_scene_free(s);
        return status;
    }
    if (nproc == 0)
        nproc = tf_thread_count(0);
    tf_info("joining %s: %dx%d render of a %s terrain; building the height field", connect,
            s->width, s->height, tf_generator_name(s->terrain.generator));
    ts_client_heartbeat(c, TF_WORKER_HEARTBEAT_MS); /* stay alive while the terrain builds */
    tf_heightfield *hf = tf_heightfield_build(s, 0, err, sizeof err);
    if (!hf) {
        tf_error("%s", err);
        tf_scene_free(s);
        ts_client_close(c);
        return TF_EXIT_FAIL;
    }
    int status = 0;
    if (nproc == 1) {
        status = tf_worker_loop(c, s, hf, "networked", backend);
        ts_client_close(c);
    } else {
        ts_client_close(c);
        pid_t *pids = calloc((size_t)nproc, sizeof *pids);
        if (!pids) {
            tf_error("out of memory");
            return TF_EXIT_FAIL;
        }
        for (int i = 0; i < nproc; i++) {
            pid_t p = fork();
            if (p == 0) {
                prctl(PR_SET_PDEATHSIG, SIGTERM);
                _exit(run_one(connect, k, timeout_ms, s, hf, backend));
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
    }
    if (status == 0)
        tf_info("render finished; worker leaving");
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return status;
}
