/* cmd_status.c: `terrafarm status HOST:PORT [--json]`: what a running render's dashboard shows
 * (its /api/status and /api/workers, README "Dashboard and API"), in a terminal or as one JSON
 * document for scripts.  A plain HTTP/1.0 GET over the project's sockets (linda/sock.h); the
 * answer is bounded in size and time and parsed with jansson (http_client.h). */
#include <errno.h>
#include <getopt.h>
#include <jansson.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "clock.h"
#include "cli/commands.h"
#include "coordinator/dashboard/httpauth.h"
#include "http_client.h"
#include "linda/auth.h"
#include "linda/sock.h"
#include "log.h"

static const char usage[] =
    "usage: terrafarm status HOST:PORT [options]\n"
    "\n"
    "Show a running render's progress and workers, from its dashboard (render --http).\n"
    "\n"
    "      --json                one JSON object: the /api/status document plus \"workers\"\n"
    "      --token-file FILE     the dashboard's token (--http-token-file of the render)\n"
    "      --secret-file FILE    the farm secret, to derive the token from it\n"
    "      --print-token         print the token derived from --secret-file (for a browser:\n"
    "                            open http://HOST:PORT/login?token=TOKEN) and exit\n"
    "      --timeout T           give up after this long (default 5s; 500ms, 2m, ...)\n"
    "  -h, --help                this help\n";

/* GET a JSON document; NULL with a message. */
static json_t *get_json(const char *addr, const char *path, const char *token, int64_t deadline,
                        char *err, size_t errlen)
{
    int code = 0;
    json_t *doc = tf_http_json(addr, "GET", path, token, NULL, deadline, &code, err, errlen);
    if (!doc && code == 401) {
        size_t n = strlen(err);
        snprintf(err + n, errlen - n, " (give --token-file or --secret-file)");
    }
    return doc;
}

static double num(json_t *o, const char *key)
{
    json_t *v = json_object_get(o, key);
    return json_is_number(v) ? json_number_value(v) : -1;
}

/* A string of the dashboard's answer, fit for the terminal: control bytes (a worker's host name
 * may carry an escape sequence) as '?', "?" when absent.  Eight may be in use in one printf. */
static const char *str(json_t *o, const char *key)
{
    static char ring[8][1024];
    static unsigned next;
    const char *s = json_string_value(json_object_get(o, key));
    return s ? tf_printable(s, ring[next++ % 8], sizeof ring[0]) : "?";
}

static void duration(char *buf, size_t len, double s)
{
    if (s < 0)
        snprintf(buf, len, "--:--");
    else if (s >= 3600)
        snprintf(buf, len, "%d:%02d:%02d", (int)s / 3600, ((int)s / 60) % 60, (int)s % 60);
    else
        snprintf(buf, len, "%d:%02d", (int)s / 60, (int)s % 60);
}

static void print_human(json_t *st, json_t *workers)
{
    char el[32], eta[32];
    duration(el, sizeof el, num(st, "elapsed_s"));
    duration(eta, sizeof eta, num(st, "eta_s"));
    printf("scene      %s %s (%s) -> %s\n", str(st, "scene"), str(st, "size"), str(st, "tasks"),
           str(st, "output"));
    printf("state      %s  %.1f%%  rows %.0f/%.0f", str(st, "state"), num(st, "percent"),
           num(st, "rows_written"), num(st, "rows_total"));
    if (num(st, "frames_total") >= 0)
        printf("  frame %.0f (%.0f of %.0f frames done)", num(st, "frame"), num(st, "frames_done"),
               num(st, "frames_total"));
    printf("\nelapsed    %s  eta %s\n", el, eta);
    printf("rays/s     %.2f M (recent %.2f M)  samples/pixel %.2f\n", num(st, "rays_per_s") / 1e6,
           num(st, "rays_per_s_recent") / 1e6, num(st, "samples_per_pixel_avg"));
    printf("tasks      %.0f outstanding, watermark %.0f, %.0f re-dealt, %.0f failures\n",
           num(st, "outstanding_tasks"), num(st, "watermark"), num(st, "tasks_redealt"),
           num(st, "task_failures"));
    printf("workers    %.0f connected\n", num(st, "workers_connected"));
    json_t *arr = json_object_get(workers, "workers");
    size_t i;
    json_t *w;
    if (json_array_size(arr))
        printf("  %6s %-9s %-16s %-7s %-7s %6s %6s %9s %5s\n", "id", "kind", "host", "backend",
               "state", "task", "tasks", "Mrays", "busy");
    json_array_foreach(arr, i, w) {
        double task = num(w, "task"), busy = num(w, "busy_fraction");
        char tb[24] = "", bb[16] = "";
        if (task >= 0)
            snprintf(tb, sizeof tb, "%.0f", task);
        if (busy >= 0)
            snprintf(bb, sizeof bb, "%.0f%%", 100 * busy);
        printf("  %6.0f %-9s %-16.16s %-7s %-7s %6s %6.0f %9.2f %5s\n", num(w, "id"), str(w, "kind"),
               str(w, "host"), str(w, "backend"), str(w, "state"), tb, num(w, "tasks"),
               num(w, "rays") / 1e6, bb);
    }
}

enum { O_JSON = 256, O_TOKEN, O_SECRET, O_PRINT, O_TIMEOUT };

static const struct option longopts[] = {
    {"json", no_argument, NULL, O_JSON},
    {"token-file", required_argument, NULL, O_TOKEN},
    {"secret-file", required_argument, NULL, O_SECRET},
    {"print-token", no_argument, NULL, O_PRINT},
    {"timeout", required_argument, NULL, O_TIMEOUT},
    {"help", no_argument, NULL, 'h'},
    {NULL, 0, NULL, 0},
};

/* What the command line asks for. */
typedef struct status_args {
    int as_json, print_token;
    long timeout_ms;
    const char *token_file, *secret_file;
} status_args;

/* The options into a: -1 to go on, or the exit status (--help, or a refusal). */
static int parse_status_args(status_args *a, int argc, char **argv)
{
    *a = (status_args){.timeout_ms = 5000};
    int c;
    int64_t ms;
    optind = 1;
    opterr = 0;
    while ((c = getopt_long(argc, argv, ":h", longopts, NULL)) != -1) {
        if (c == O_JSON) {
            a->as_json = 1;
        } else if (c == O_PRINT) {
            a->print_token = 1;
        } else if (c == O_TOKEN) {
            a->token_file = optarg;
        } else if (c == O_SECRET) {
            a->secret_file = optarg;
        } else if (c == O_TIMEOUT) {
            if (tf_parse_duration_ms(optarg, &ms) || ms < 1 || ms > 3600000) {
                tf_error("--timeout '%s': expected a duration from 1ms to 1h (e.g. 500ms, 5s)",
                         optarg);
                return TF_EXIT_USAGE;
            }
            a->timeout_ms = (long)ms;
        } else if (c == 'h') {
            fputs(usage, stdout);
            return TF_EXIT_OK;
        } else {
            tf_error(c == ':' ? "status: option '%s' needs a value (see terrafarm status --help)"
                              : "status: unknown option '%s' (see terrafarm status --help)",
                     argv[optind - 1]);
            return TF_EXIT_USAGE;
        }
    }
    return -1;
}

/* The dashboard's token: read from --token-file, or derived from --secret-file.  1 with the
 * token, 0 with neither, -1 when the file cannot give one (said). */
static int load_token(const status_args *a, char *token, size_t len)
{
    char err[1024] = "";
    uint8_t key[TF_KEY_BYTES];
    if (a->token_file) {
        if (tf_http_token_load(a->token_file, token, len, err, sizeof err) == 0)
            return 1;
    } else if (a->secret_file) {
        if (tf_auth_init() != 0)
            snprintf(err, sizeof err, "status: libsodium cannot start");
        else if (tf_secret_load(a->secret_file, key, err, sizeof err) == 0 &&
                 tf_http_token_derive(key, token, len) == 0)
            return 1;
        else if (!err[0])
            snprintf(err, sizeof err, "status: no token can be derived from %s",
                     a->secret_file);
    } else {
        return 0;
    }
    tf_error("%s", err);
    return -1;
}

/* The status and the workers from the dashboard at addr, printed as JSON or as text. */
static int show_status(const status_args *a, const char *addr, const char *tok)
{
    char host[256], port[32], err[1024];
    if (tf_split_hostport(addr, host, sizeof host, port, sizeof port, err, sizeof err)) {
        tf_error("status: %s", err);
        return TF_EXIT_USAGE;
    }
    int64_t deadline = tf_now_ms() + a->timeout_ms;
    json_t *st = get_json(addr, "/api/status", tok, deadline, err, sizeof err);
    json_t *workers = st ? get_json(addr, "/api/workers", tok, deadline, err, sizeof err) : NULL;
    if (!st || !workers) {
        tf_error("status: %s", err);
        json_decref(st);
        return TF_EXIT_FAIL;
    }
    if (a->as_json) {
        json_object_set(st, "workers", json_object_get(workers, "workers"));
        char *text = json_dumps(st, JSON_INDENT(2) | JSON_PRESERVE_ORDER);
        if (text)
            printf("%s\n", text);
        free(text);
    } else {
        print_human(st, workers);
    }
    json_decref(st);
    json_decref(workers);
    return fflush(stdout) == 0 ? TF_EXIT_OK : TF_EXIT_FAIL;
}

int cmd_status(int argc, char **argv)
{
    status_args a;
    int status = parse_status_args(&a, argc, argv);
    if (status >= 0)
        return status;
    char token[TF_HTTP_TOKEN_MAX + 1];
    int have_token = load_token(&a, token, sizeof token);
    if (have_token < 0)
        return TF_EXIT_FAIL;
    if (a.print_token) {
        if (!a.secret_file) {
            tf_error("status: --print-token needs --secret-file FILE");
            return TF_EXIT_USAGE;
        }
        printf("%s\n", token);
        return TF_EXIT_OK;
    }
    if (optind != argc - 1) {
        tf_error("status: expected one HOST:PORT (see terrafarm status --help)");
        return TF_EXIT_USAGE;
    }
    return show_status(&a, argv[optind], have_token ? token : NULL);
}
