/* cmd_farm.c: `terrafarm farm --listen HOST:PORT --state DIR --secret-file F`: run a standing
 * farm (coordinator/farm/farm.h); `terrafarm farm --state DIR --add-token NAME --role ROLE`
 * gives a person a token (printed once; the farm keeps only its hash). */
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "cli/commands.h"
#include "coordinator/farm/farm.h"
#include "log.h"

static const char usage[] =
    "usage: terrafarm farm --listen HOST:PORT --state DIR --secret-file FILE [options]\n"
    "       terrafarm farm --state DIR --add-token NAME --role submitter|admin\n"
    "\n"
    "Run a standing farm: a durable queue of jobs (terrafarm submit) served by workers that\n"
    "stay (terrafarm worker --connect http://HOST:PORT --secret-file FILE).  Each running job\n"
    "is a render listening on HOST; its output, the checkpoint, is in DIR/jobs/ID.  Killed,\n"
    "the farm continues every unfinished job when started again on the same DIR.\n"
    "\n"
    "      --listen HOST:PORT    the farm's HTTP API (docs/farm-api.yaml)\n"
    "      --state DIR           the queue (DIR/farm.db, SQLite) and the jobs' folders\n"
    "      --secret-file FILE    the farm secret; every worker holds the same file\n"
    "      --worker-timeout T    a worker silent this long is no longer counted (default 15s)\n"
    "      --max-failures N      failed sessions of a worker on one job before it is barred\n"
    "                            from that job (default 3)\n"
    "      --forgive T           how long such a bar lasts (default 10m)\n"
    "      --paint-idle T        close a paint job whose page nobody has read this long\n"
    "                            (default 10m: it holds its pool's workers)\n"
    "      --add-token NAME      create a person's token, print it and exit\n"
    "      --role ROLE           with --add-token: submitter (own jobs) or admin (all)\n"
    "  -q, --quiet / -v, --verbose\n"
    "  -h, --help\n";

static int parse_ms(const char *flag, const char *text, int *out)
{
    int64_t ms;
    if (tf_parse_duration_ms(text, &ms) || ms < 1 || ms > 86400000LL * 30) {
        tf_error("%s '%s': expected a duration such as 500ms, 15s or 10m", flag, text);
        return -1;
    }
    *out = (int)ms;
    return 0;
}

enum { O_LISTEN = 256, O_STATE, O_SECRET, O_TIMEOUT, O_FAILURES, O_FORGIVE, O_ADD, O_ROLE,
       O_PAINT_IDLE };

static const struct option longopts[] = {
    {"listen", required_argument, NULL, O_LISTEN},
    {"state", required_argument, NULL, O_STATE},
    {"secret-file", required_argument, NULL, O_SECRET},
    {"worker-timeout", required_argument, NULL, O_TIMEOUT},
    {"max-failures", required_argument, NULL, O_FAILURES},
    {"forgive", required_argument, NULL, O_FORGIVE},
    {"paint-idle", required_argument, NULL, O_PAINT_IDLE},
    {"add-token", required_argument, NULL, O_ADD},
    {"role", required_argument, NULL, O_ROLE},
    {"quiet", no_argument, NULL, 'q'},
    {"verbose", no_argument, NULL, 'v'},
    {"help", no_argument, NULL, 'h'},
    {NULL, 0, NULL, 0},
};

/* What the command line asks for: a farm to run, or a token to add (add, role). */
typedef struct farm_args {
    tf_farm_opts o;
    const char *add, *role;
} farm_args;

/* One option into a: 0, or -1 after saying why not. */
static int farm_option(farm_args *a, int ch, const char *arg)
{
    char *end;
    long v;
    switch (ch) {
    case O_LISTEN: a->o.listen = arg; return 0;
    case O_STATE: a->o.state_dir = arg; return 0;
    case O_SECRET: a->o.secret_file = arg; return 0;
    case O_ADD: a->add = arg; return 0;
    case O_ROLE: a->role = arg; return 0;
    case O_TIMEOUT: return parse_ms("--worker-timeout", arg, &a->o.worker_timeout_ms);
    case O_FORGIVE: return parse_ms("--forgive", arg, &a->o.forgive_ms);
    case O_PAINT_IDLE: return parse_ms("--paint-idle", arg, &a->o.paint_idle_ms);
    case O_FAILURES:
        v = strtol(arg, &end, 10);
        if (end == arg || *end || v < 1 || v > 1000) {
            tf_error("--max-failures '%s': expected 1 to 1000", arg);
            return -1;
        }
        a->o.max_failures = (int)v;
        return 0;
    case 'q': tf_log_set_level(TF_LOG_ERROR); return 0;
    case 'v': tf_log_set_level(TF_LOG_DEBUG); return 0;
    default: return -1;
    }
}

/* The command line into a: -1 to go on, or the exit status (--help, or a refusal). */
static int parse_farm_args(farm_args *a, int argc, char **argv)
{
    memset(a, 0, sizeof *a);
    int ch;
    optind = 1;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":qvh", longopts, NULL)) != -1) {
        if (ch == 'h') {
            fputs(usage, stdout);
            return TF_EXIT_OK;
        }
        if (ch == ':' || ch == '?') {
            if (ch == ':')
                tf_error("%s needs a value", argv[optind - 1]);
            else
                tf_error("unknown option '%s' (see terrafarm farm --help)", argv[optind - 1]);
            return TF_EXIT_USAGE;
        }
        if (farm_option(a, ch, optarg))
            return TF_EXIT_USAGE;
    }
    const tf_farm_opts *o = &a->o;
    if (optind < argc || !o->state_dir || (!a->add && (!o->listen || a->role)) ||
        (a->add && !a->role)) {
        fputs(usage, stderr);
        return TF_EXIT_USAGE;
    }
    return -1;
}

int cmd_farm(int argc, char **argv)
{
    farm_args a;
    int status = parse_farm_args(&a, argc, argv);
    if (status >= 0)
        return status;
    if (a.add)
        return tf_farm_add_token(a.o.state_dir, a.add, a.role);
    return tf_farm_run(&a.o);
}
