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

enum { O_SECRET = 256, O_BACKEND, O_TIMEOUT, O_SIMULATE, O_PIXEL_US, O_CL_DEVICE, O_PAYLOADS,
       O_TERRAIN_CACHE, O_POOL, O_TAGS, O_NAME, O_TERRAIN_MEMORY, O_MAX_SESSIONS, O_IDLE_ONLY,
       O_OWNER, O_IDLE_AFTER, O_CPU_THRESHOLD };

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

/* What the command line asks for. */
typedef struct worker_args {
    const char *connect, *secret, *backend, *model, *payloads;
    double pixel_us;
    size_t terrain_cache;
    int nproc, timeout_ms;
    tf_farm_worker_opts fo; /* --connect http://: a standing farm's options */
    piranha pir;
} worker_args;

/* Option parsers: 0, or -1 after one line naming the flag, its value and what was expected. */
static int int_option(const char *flag, const char *text, long lo, long hi, const char *expect,
                      int *out)
{
    char *end;
    long v = strtol(text, &end, 10);
    if (end == text || *end || v < lo || v > hi) {
        tf_error("%s '%s': expected %s", flag, text, expect);
        return -1;
    }
    *out = (int)v;
    return 0;
}

static int number_option(const char *flag, const char *text, double lo, double hi,
                         const char *expect, double *out)
{
    char *end;
    double v = strtod(text, &end);
    if (end == text || *end || !(v >= lo && v <= hi)) {
        tf_error("%s '%s': expected %s", flag, text, expect);
        return -1;
    }
    *out = v;
    return 0;
}

static int duration_option(const char *flag, const char *text, int64_t lo, const char *expect,
                           int *out_ms)
{
    int64_t ms;
    if (tf_parse_duration_ms(text, &ms) || ms < lo || ms > INT32_MAX) {
        tf_error("%s '%s': expected %s", flag, text, expect);
        return -1;
    }
    *out_ms = (int)ms;
    return 0;
}

static int backend_option(const char *text, const char **out)
{
    if (strcmp(text, "c") && strcmp(text, "opencl") && strcmp(text, "auto")) {
        tf_error("--backend '%s': expected c, opencl or auto", text);
        return -1;
    }
    *out = text;
    return 0;
}

/* The options of a standing farm's worker and of a Piranha (--idle-only). */
static int farm_option(worker_args *wa, int ch, const char *arg)
{
    switch (ch) {
    case O_POOL: wa->fo.pool = arg; return 0;
    case O_TAGS: wa->fo.tags = arg; return 0;
    case O_NAME: wa->fo.name = arg; return 0;
    case O_TERRAIN_MEMORY:
        return tf_parse_byte_size("--terrain-memory", arg, &wa->fo.terrain_memory) ? -1 : 0;
    case O_MAX_SESSIONS:
        return int_option("--max-sessions", arg, 1, INT32_MAX, "a positive integer",
                          &wa->fo.max_sessions);
    case O_IDLE_ONLY: wa->pir.on = 1; return 0;
    case O_OWNER: wa->pir.owner = arg; return 0;
    case O_IDLE_AFTER:
        return duration_option("--idle-after", arg, 0, "a duration (e.g. 1s, 5m)",
                               &wa->pir.idle_after_ms);
    case O_CPU_THRESHOLD:
        return number_option("--cpu-threshold", arg, 0, 4096, "a number of cores >= 0",
                             &wa->pir.cpu_threshold);
    default:
        return -1; /* getopt_long gives no other value */
    }
}

/* One option with a value (or --idle-only) into wa: 0, or -1 after saying why. */
static int worker_option(worker_args *wa, int ch, const char *arg)
{
    switch (ch) {
    case 'c': wa->connect = arg; return 0;
    case O_SECRET: wa->secret = arg; return 0;
    case O_BACKEND: return backend_option(arg, &wa->backend);
    case 'j': return int_option("--workers", arg, 1, 4096, "an integer from 1 to 4096", &wa->nproc);
    case O_TIMEOUT:
        return duration_option("--timeout", arg, 1, "a positive duration (e.g. 10s, 500ms, 2m; "
                               "a bare number is milliseconds)", &wa->timeout_ms);
    case O_SIMULATE: wa->model = arg; return 0;
    case O_PAYLOADS: wa->payloads = arg; return 0;
    case O_TERRAIN_CACHE:
        return tf_parse_byte_size("--terrain-cache", arg, &wa->terrain_cache) ? -1 : 0;
    case O_CL_DEVICE: setenv("TERRAFARM_CL_DEVICE", arg, 1); return 0;
    case O_PIXEL_US:
        return number_option("--pixel-us", arg, 0, 1e9, "a number of microseconds >= 0",
                             &wa->pixel_us);
    default: return farm_option(wa, ch, arg);
    }
}

/* The command line into wa: -1 to go on, or the exit status (--help, or a refusal). */
static int parse_worker_args(worker_args *wa, int argc, char **argv)
{
    *wa = (worker_args){.backend = "c", .pixel_us = 50.0, .timeout_ms = 10000,
                        .pir = {.idle_after_ms = 60000, .cpu_threshold = 0.25}};
    int ch;
    optind = 1;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":c:j:qvh", longopts, NULL)) != -1) {
        if (ch == 'q' || ch == 'v') {
            tf_log_set_level(ch == 'q' ? TF_LOG_WARN : TF_LOG_DEBUG);
        } else if (ch == 'h') {
            fputs(usage, stdout);
            return TF_EXIT_OK;
        } else if (ch == ':') {
            tf_error("worker: option '%s' needs a value", argv[optind - 1]);
            return TF_EXIT_USAGE;
        } else if (ch == '?') {
            tf_error("worker: unknown option '%s' (see terrafarm worker --help)", argv[optind - 1]);
            return TF_EXIT_USAGE;
        } else if (worker_option(wa, ch, optarg)) {
            return TF_EXIT_USAGE;
        }
    }
    if (!wa->connect || optind != argc) {
        tf_error(!wa->connect ? "worker: --connect HOST:PORT is required"
                              : "worker: unexpected argument '%s'",
                 argv[optind]);
        return TF_EXIT_USAGE;
    }
    return -1;
}

int cmd_worker(int argc, char **argv)
{
    worker_args wa;
    int status = parse_worker_args(&wa, argc, argv);
    if (status >= 0)
        return status;
    signal(SIGPIPE, SIG_IGN);
    if (!strncmp(wa.connect, "http://", 7)) { /* a standing farm */
        tf_farm_worker_opts *fo = &wa.fo;
        fo->farm = wa.connect + 7;
        fo->secret_file = wa.secret;
        fo->processes = wa.nproc;
        fo->backend = wa.backend;
        fo->terrain_cache = wa.terrain_cache;
        fo->simulate_model = wa.model;
        fo->pixel_us = wa.pixel_us;
        fo->payloads = wa.payloads;
        return run_farm_worker(fo, &wa.pir);
    }
    tf_networked_opts o = {wa.connect, wa.secret,   wa.timeout_ms, wa.nproc,        wa.backend,
                           wa.model,   wa.pixel_us, wa.payloads,   wa.terrain_cache};
    return tf_networked_worker_run(&o) == 0 ? TF_EXIT_OK : TF_EXIT_FAIL;
}
