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

int cmd_farm(int argc, char **argv)
{
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
    tf_farm_opts o = {0};
    const char *add = NULL, *role = NULL;
    int ch;
    optind = 1;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":qvh", longopts, NULL)) != -1) {
        switch (ch) {
        case O_LISTEN: o.listen = optarg; break;
        case O_STATE: o.state_dir = optarg; break;
        case O_SECRET: o.secret_file = optarg; break;
        case O_TIMEOUT:
            if (parse_ms("--worker-timeout", optarg, &o.worker_timeout_ms))
                return TF_EXIT_USAGE;
            break;
        case O_FAILURES:
            o.max_failures = atoi(optarg);
            if (o.max_failures < 1 || o.max_failures > 1000) {
                tf_error("--max-failures '%s': expected 1 to 1000", optarg);
                return TF_EXIT_USAGE;
            }
            break;
        case O_FORGIVE:
            if (parse_ms("--forgive", optarg, &o.forgive_ms))
                return TF_EXIT_USAGE;
            break;
        case O_PAINT_IDLE:
            if (parse_ms("--paint-idle", optarg, &o.paint_idle_ms))
                return TF_EXIT_USAGE;
            break;
        case O_ADD: add = optarg; break;
        case O_ROLE: role = optarg; break;
        case 'q': tf_log_set_level(TF_LOG_ERROR); break;
        case 'v': tf_log_set_level(TF_LOG_DEBUG); break;
        case 'h': fputs(usage, stdout); return TF_EXIT_OK;
        case ':': tf_error("%s needs a value", argv[optind - 1]); return TF_EXIT_USAGE;
        default: tf_error("unknown option '%s' (see terrafarm farm --help)", argv[optind - 1]);
            return TF_EXIT_USAGE;
        }
    }
    if (optind < argc || !o.state_dir || (!add && (!o.listen || role)) || (add && !role)) {
        fputs(usage, stderr);
        return TF_EXIT_USAGE;
    }
    if (add)
        return tf_farm_add_token(o.state_dir, add, role);
    return tf_farm_run(&o);
}
