/* cmd_worker.c: `terrafarm worker --connect HOST:PORT [-j N]`: the command line of a networked
 * worker.  Its life (connect, fetch the scene, build the terrain, fork N workers) is in
 * worker/networked.c; with --simulate MODEL it joins as synthetic workers (worker/simulate.h). */
#include <getopt.h>
#include <stdint.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "clock.h"
#include "cli/commands.h"
#include "log.h"
#include "worker/farm_worker.h"
#include "worker/owner_presence.h"
#include "worker/networked.h"

static const char usage[] =
    "usage: terrafarm worker --connect HOST:PORT [options]\n"
    "       terrafarm worker --connect http://HOST:PORT --secret-file FILE [farm options]\n"
    "\n"
    "Join a render as a networked worker: fetch the scene from the coordinator, build the\n"
    "terrain, and render tasks until the render is finished.  Given a standing farm\n"
    "(http://, terrafarm farm), serve its jobs one after another until stopped.\n"
    "\n"
    "  -c, --connect HOST:PORT   the coordinator (terrafarm render ... --listen HOST:PORT)\n"
    "                            or http://HOST:PORT, a standing farm (terrafarm farm)\n"
    "      --secret-file FILE    shared secret, if the coordinator requires one\n"
    "      --backend c|opencl|auto  rendering backend (default c; auto: OpenCL if a device\n"
    "                            works, else C with a warning)\n"
    "      --cl-device DEV       OpenCL device: P:D indices or a name substring\n"
    "                            (same as TERRAFARM_CL_DEVICE)\n"
    "  -j, --workers N           worker processes on this machine (default: online CPUs)\n"
    "      --terrain-cache SIZE  each process's budget for evaluated procedural terrain\n"
    "                            (e.g. 64M, 2G; default an eighth of memory, at most 512M)\n"
    "      --timeout T           keep trying to reach the coordinator for T (default 10s; T is\n"
    "                            a number with ms, s, m or h; a bare number is milliseconds)\n"
    "      --simulate MODEL      synthetic workers: sleep each task's modelled cost from the cost\n"
    "                            map MODEL (terrafarm bench SCENE --cost-map MODEL) instead of\n"
    "                            rendering; -j N threads in this process; prints a report line\n"
    "      --pixel-us U          with --simulate: modelled cost of an average pixel (default 50)\n"
    "      --payloads FILE.exr   with --simulate: answer tasks with the packed chunks of this\n"
    "                            finished render (same --tasks and --pixel), as real workers\n"
    "                            would; without it simulated results are encoded black pixels\n"
    "farm options (--connect http://...):\n"
    "      --pool P              serve only jobs of pool P (default: default)\n"
    "      --tags T1,T2          what this machine offers; a job may require tags\n"
    "      --name NAME           the worker's name on the farm (default HOST:PID)\n"
    "      --terrain-memory SIZE keep the terrains of recent jobs within SIZE (default an\n"
    "                            eighth of memory), so returning to a job costs no rebuild\n"
    "      --max-sessions N      leave after serving N jobs (default: stay)\n"
    "      --idle-only           Piranha: take work only while the machine's owner is away, and\n"
    "                            retreat at once (tasks dealt again elsewhere) when the owner\n"
    "                            comes back: the owner's processes using more than\n"
    "                            --cpu-threshold cores, or terminal input in --idle-after\n"
    "      --owner USER          the machine's owner (default: the user running the worker)\n"
    "      --idle-after T        the owner must be away this long before work is taken\n"
    "                            (default 60s)\n"
    "      --cpu-threshold C     the owner's CPU use, in cores, that means present (default 0.25)\n"
    "  -q, --quiet / -v, --verbose\n"
    "  -h, --help\n";

/* --idle-only: the owner watch of a Piranha worker (worker/farm_worker.h) over the presence
 * sampler (worker/owner_presence.h). */
typedef struct piranha {
    int on;
    const char *owner;
    int idle_after_ms;
    double cpu_threshold;
    tf_presence *presence;
} piranha;

static int owner_present(void *ctx, char *why, size_t whylen)
{
    return tf_presence_sample(((piranha *)ctx)->presence, why, whylen);
}

static int run_farm_worker(tf_farm_worker_opts *fo, piranha *pir)
{
    char err[512];
    tf_presence_opts po = {.owner = getuid(), .cpu_threshold = pir->cpu_threshold,
                           .idle_after_s = pir->idle_after_ms / 1000.0, .self_root = getpid()};
    tf_owner_watch watch = {owner_present, pir, 50, pir->idle_after_ms};
    if (pir->on && ((pir->owner && tf_presence_owner_uid(pir->owner, &po.owner, err, sizeof err)) ||
                    !(pir->presence = tf_presence_new(&po, err, sizeof err)))) {
        tf_error("--idle-only: %s", err);
        return TF_EXIT_USAGE;
    }
    if (pir->on) {
        fo->owner = &watch;
        tf_info("idle-only: serving while uid %u is away (CPU <= %.2f cores, no input for %.1f s)",
                (unsigned)po.owner, po.cpu_threshold, po.idle_after_s);
    }
    int rc = tf_farm_worker_run(fo);
    tf_presence_free(pir->presence);
    return rc == 0 ? TF_EXIT_OK : TF_EXIT_FAIL;
}

int cmd_worker(int argc, char **argv)
{
    enum { O_SECRET = 256, O_BACKEND, O_TIMEOUT, O_SIMULATE, O_PIXEL_US, O_CL_DEVICE, O_PAYLOADS,
           O_TERRAIN_CACHE, O_POOL, O_TAGS, O_NAME, O_TERRAIN_MEMORY, O_MAX_SESSIONS, O_IDLE_ONLY, O_OWNER, O_IDLE_AFTER,
           O_CPU_THRESHOLD };
    static const struct option longopts[] = {
        {"connect", required_argument, NULL, 'c'},
        {"secret-file", required_argument, NULL, O_SECRET},
        {"backend", required_argument, NULL, O_BACKEND},
        {"workers", required_argument, NULL, 'j'},
        {"timeout", required_argument, NULL, O_TIMEOUT},
        {"simulate", required_argument, NULL, O_SIMULATE},
        {"pixel-us", required_argument, NULL, O_PIXEL_US},
        {"payloads", required_argument, NULL, O_PAYLOADS},
        {"cl-device", required_argument, NULL, O_CL_DEVICE},
        {"terrain-cache", required_argument, NULL, O_TERRAIN_CACHE},
        {"pool", required_argument, NULL, O_POOL},
        {"tags", required_argument, NULL, O_TAGS},
        {"name", required_argument, NULL, O_NAME},
        {"terrain-memory", required_argument, NULL, O_TERRAIN_MEMORY},
        {"max-sessions", required_argument, NULL, O_MAX_SESSIONS},
        {"idle-only", no_argument, NULL, O_IDLE_ONLY},
        {"owner", required_argument, NULL, O_OWNER},
        {"idle-after", required_argument, NULL, O_IDLE_AFTER},
        {"cpu-threshold", required_argument, NULL, O_CPU_THRESHOLD},
        {"quiet", no_argument, NULL, 'q'},
        {"verbose", no_argument, NULL, 'v'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    const char *connect = NULL, *secret = NULL, *backend = "c", *model = NULL, *payloads = NULL;
    double pixel_us = 50.0;
    size_t terrain_cache = 0;
    tf_farm_worker_opts fo = {0};
    piranha pir = {.idle_after_ms = 60000, .cpu_threshold = 0.25};
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
        case O_PAYLOADS: payloads = optarg; break;
        case O_TERRAIN_CACHE:
            if (tf_parse_byte_size("--terrain-cache", optarg, &terrain_cache))
                return TF_EXIT_USAGE;
            break;
        case O_POOL: fo.pool = optarg; break;
        case O_TAGS: fo.tags = optarg; break;
        case O_NAME: fo.name = optarg; break;
        case O_TERRAIN_MEMORY:
            if (tf_parse_byte_size("--terrain-memory", optarg, &fo.terrain_memory))
                return TF_EXIT_USAGE;
            break;
        case O_MAX_SESSIONS:
            fo.max_sessions = (int)strtol(optarg, &end, 10);
            if (end == optarg || *end || fo.max_sessions < 1) {
                tf_error("--max-sessions '%s': expected a positive integer", optarg);
                return TF_EXIT_USAGE;
            }
            break;
        case O_IDLE_ONLY: pir.on = 1; break;
        case O_OWNER: pir.owner = optarg; break;
        case O_IDLE_AFTER:
        {
            int64_t ms;
            if (tf_parse_duration_ms(optarg, &ms) || ms < 0 || ms > INT32_MAX) {
                tf_error("--idle-after '%s': expected a duration (e.g. 1s, 5m)", optarg);
                return TF_EXIT_USAGE;
            }
            pir.idle_after_ms = (int)ms;
            break;
        }
        case O_CPU_THRESHOLD:
            pir.cpu_threshold = strtod(optarg, &end);
            if (end == optarg || *end || !(pir.cpu_threshold >= 0 && pir.cpu_threshold <= 4096)) {
                tf_error("--cpu-threshold '%s': expected a number of cores >= 0", optarg);
                return TF_EXIT_USAGE;
            }
            break;
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
    if (!strncmp(connect, "http://", 7)) { /* a standing farm */
        fo.farm = connect + 7;
        fo.secret_file = secret;
        fo.processes = nproc;
        fo.backend = backend;
        fo.terrain_cache = terrain_cache;
        fo.simulate_model = model;
        fo.pixel_us = pixel_us;
        fo.payloads = payloads;
        return run_farm_worker(&fo, &pir);
    }
    tf_networked_opts o = {connect, secret,   timeout_ms, nproc,   backend,
                           model,   pixel_us, payloads,   terrain_cache};
    return tf_networked_worker_run(&o) == 0 ? TF_EXIT_OK : TF_EXIT_FAIL;
}
