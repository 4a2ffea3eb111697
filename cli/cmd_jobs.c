/* cmd_jobs.c: a person's commands for a standing farm (terrafarm farm): `submit SCENE`, `jobs`,
 * `job ID` (--paint: a paint job of its scene), `cancel ID`, `pause ID`, `resume ID`,
 * `priority ID N`.  Each is one request to the
 * farm's API (docs/farm-api.yaml) with the person's token.  submit sends the scene's text and,
 * for a height map scene, the map's bytes: the farm never opens a path a submitter names. */
#include <getopt.h>
#include <jansson.h>
#include <sodium.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "clock.h"
#include "cli/commands.h"
#include "coordinator/dashboard/httpauth.h"
#include "http_client.h"
#include "log.h"
#include "scene.h"

static const char usage[] =
    "usage: terrafarm submit SCENE [options] [render options]\n"
    "       terrafarm jobs [--json]\n"
    "       terrafarm job ID [--json] [--output FILE.exr [--frame N]] [--paint]\n"
    "       terrafarm cancel|pause|resume ID\n"
    "       terrafarm priority ID N\n"
    "\n"
    "Submit jobs to a standing farm (terrafarm farm) and steer them.\n"
    "\n"
    "      --farm HOST:PORT      the farm's API (default: $TERRAFARM_FARM)\n"
    "      --token-file FILE     your token (terrafarm farm --add-token; default:\n"
    "                            $TERRAFARM_TOKEN_FILE)\n"
    "      --json                print the farm's JSON answer\n"
    "submit:\n"
    "      --name NAME           the job's name (default: the scene file's name)\n"
    "      --priority N          higher first (-1000 to 1000, default 0)\n"
    "      --pool P              only workers of pool P serve it (default: default)\n"
    "      --tags T1,T2          only workers with all these tags serve it\n"
    "      --after ID            start only once job ID is done\n"
    "      --paint               a paint job: the scene coming into focus in the browser on\n"
    "                            the farm's workers (its page: terrafarm job ID --json)\n"
    "      render options: --size --tasks --pixel --verify --verify-chunks --frames --frame\n"
    "                      --watermark --affinity --lease-timeout --wait-workers (as\n"
    "                      terrafarm render; --wait-workers counts worker processes)\n"
    "job:\n"
    "      --output FILE.exr     download the finished output (--frame N: of a sequence)\n"
    "      --paint               open a paint job of job ID's scene; prints its id\n";

typedef struct client {
    const char *farm;
    char token[TF_HTTP_TOKEN_MAX + 1];
    int json;
} client;

static int connect_opts(client *c, const char *farm, const char *token_file)
{
    char err[512];
    c->farm = farm ? farm : getenv("TERRAFARM_FARM");
    if (!token_file)
        token_file = getenv("TERRAFARM_TOKEN_FILE");
    if (!c->farm || !token_file) {
        tf_error("give the farm (--farm HOST:PORT or TERRAFARM_FARM) and your token "
                 "(--token-file FILE or TERRAFARM_TOKEN_FILE)");
        return -1;
    }
    if (!strncmp(c->farm, "http://", 7))
        c->farm += 7;
    if (tf_http_token_load(token_file, c->token, sizeof c->token, err, sizeof err)) {
        tf_error("%s", err);
        return -1;
    }
    return 0;
}

/* One request; the answer, or NULL after one line on stderr. */
static json_t *call(const client *c, const char *method, const char *path, json_t *body)
{
    char err[1024];
    json_t *doc = tf_http_json(c->farm, method, path, c->token, body, tf_now_ms() + 60000, NULL,
                               err, sizeof err);
    json_decref(body);
    if (!doc)
        tf_error("%s", err);
    return doc;
}

/* A string field of the farm's answer, fit for the terminal (tf_printable: "-" when absent). */
static const char *field(json_t *o, const char *key, char *buf, size_t n)
{
    return tf_printable(json_string_value(json_object_get(o, key)), buf, n);
}

static void print_json(json_t *doc)
{
    char *t = json_dumps(doc, JSON_INDENT(2));
    if (t)
        puts(t);
    free(t);
}

/* ---- submit ---- */

static json_t *heightmap_json(const tf_scene *s)
{
    size_t n = sodium_base64_encoded_len(s->heightmap_len, sodium_base64_VARIANT_ORIGINAL);
    char *b64 = malloc(n);
    if (!b64)
        return NULL;
    sodium_bin2base64(b64, n, s->heightmap, s->heightmap_len, sodium_base64_VARIANT_ORIGINAL);
    const char *slash = strrchr(s->heightmap_name, '/');
    json_t *o = json_pack("{s:s,s:s}", "name", slash ? slash + 1 : s->heightmap_name, "base64",
                          b64);
    free(b64);
    return o;
}

static char *default_name(const char *path)
{
    const char *slash = strrchr(path, '/');
    char *name = strdup(slash ? slash + 1 : path);
    char *dot = name ? strrchr(name, '.') : NULL;
    if (dot && dot != name)
        *dot = 0;
    for (char *p = name; p && *p; p++)
        if (!strchr("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-", *p))
            *p = '_';
    return name;
}

/* The request of `submit SCENE`: the scene's text, its height map, settings and options. */
static json_t *submit_request(const char *path, json_t *settings, json_t *options)
{
    char err[1024];
    tf_scene *s = tf_scene_load(path, err, sizeof err);
    if (!s) {
        tf_error("%s", err);
        return NULL;
    }
    json_t *req = json_deep_copy(settings);
    json_object_set_new(req, "scene", json_stringn(s->text, strlen(s->text)));
    json_object_set(req, "options", options);
    if (!json_object_get(req, "name")) {
        char *name = default_name(path);
        json_object_set_new(req, "name", json_string(name ? name : "job"));
        free(name);
    }
    if (s->heightmap)
        json_object_set_new(req, "heightmap", heightmap_json(s));
    tf_scene_free(s);
    return req;
}

static int run_submit(client *c, const char *scene, json_t *settings, json_t *options)
{
    json_t *req = submit_request(scene, settings, options);
    json_t *a = req ? call(c, "POST", "/api/jobs", req) : NULL;
    if (!a)
        return TF_EXIT_FAIL;
    if (c->json)
        print_json(a);
    else
        printf("%lld\n", (long long)json_integer_value(json_object_get(a, "id")));
    json_decref(a);
    return TF_EXIT_OK;
}

/* ---- jobs, job, control ---- */

static int run_jobs(client *c)
{
    json_t *a = call(c, "GET", "/api/jobs", NULL);
    if (!a)
        return TF_EXIT_FAIL;
    if (c->json) {
        print_json(a);
        json_decref(a);
        return TF_EXIT_OK;
    }
    size_t i;
    json_t *j;
    printf("%6s %-20s %-12s %-10s %5s %-10s %7s %s\n", "id", "name", "owner", "state", "prio",
           "pool", "workers", "size");
    json_array_foreach(json_object_get(a, "jobs"), i, j) {
        char name[64], owner[64], state[64], pool[64];
        printf("%6lld %-20.20s %-12.12s %-10s %5lld %-10.10s %7lld %lldx%lld%s\n",
               (long long)json_integer_value(json_object_get(j, "id")),
               field(j, "name", name, sizeof name), field(j, "owner", owner, sizeof owner),
               field(j, "state", state, sizeof state),
               (long long)json_integer_value(json_object_get(j, "priority")),
               field(j, "pool", pool, sizeof pool),
               (long long)json_integer_value(json_object_get(j, "workers")),
               (long long)json_integer_value(json_object_get(j, "width")),
               (long long)json_integer_value(json_object_get(j, "height")),
               json_integer_value(json_object_get(j, "frames")) ? " (sequence)" : "");
    }
    json_decref(a);
    return TF_EXIT_OK;
}

static int parse_id(const char *s, long long *id)
{
    char *end;
    *id = strtoll(s, &end, 10);
    if (end == s || *end || *id <= 0) {
        tf_error("'%s': expected a job id", s);
        return -1;
    }
    return 0;
}

/* GET the output to file (atomically: a temporary file renamed into place). */
static int download(client *c, long long id, int frame, const char *file)
{
    char path[128], err[1024], tmp[4200];
    snprintf(path, sizeof path, "/api/jobs/%lld/output?frame=%d", id, frame);
    tf_http_answer a;
    if (tf_http_request(c->farm, "GET", path, c->token, NULL, NULL, 0, tf_now_ms() + 600000,
                        (size_t)8 << 30, &a, err, sizeof err)) {
        tf_error("%s", err);
        return TF_EXIT_FAIL;
    }
    int rc = TF_EXIT_FAIL;
    snprintf(tmp, sizeof tmp, "%s.download.tmp", file);
    FILE *f = a.code == 200 ? fopen(tmp, "wb") : NULL;
    char said[320];
    if (a.code != 200) {
        tf_http_error_text(a.body, a.len, said, sizeof said);
        tf_error("%s %s answered %d: %s", c->farm, path, a.code, said);
    } else {
        int wrote = f && fwrite(a.body, 1, a.len, f) == a.len;
        wrote = f && fclose(f) == 0 && wrote;
        if (wrote && rename(tmp, file) == 0)
            rc = TF_EXIT_OK;
        else {
            tf_error("%s: cannot write the output", file);
            unlink(tmp);
        }
    }
    free(a.body);
    return rc;
}

/* A job's history, one event a line, each line fit for the terminal. */
static void print_history(const char *history)
{
    for (const char *line = history; line && *line;) {
        const char *nl = strchr(line, '\n');
        size_t n = nl ? (size_t)(nl - line) : strlen(line);
        char text[512], shown[512];
        snprintf(text, sizeof text, "%.*s", (int)(n < sizeof text ? n : sizeof text - 1), line);
        printf("%s\n", tf_printable(text, shown, sizeof shown));
        line += n + (nl != NULL);
    }
}

static int run_job(client *c, const char *id_text, const char *output, int frame)
{
    long long id;
    if (parse_id(id_text, &id))
        return TF_EXIT_USAGE;
    if (output)
        return download(c, id, frame, output);
    char path[64];
    snprintf(path, sizeof path, "/api/jobs/%lld", id);
    json_t *a = call(c, "GET", path, NULL);
    if (!a)
        return TF_EXIT_FAIL;
    if (c->json) {
        print_json(a);
    } else {
        char name[128], state[64], pool[64], reason[512];
        const char *why = json_string_value(json_object_get(a, "reason"));
        printf("job %lld %s: %s (priority %lld, pool %s, %lld workers)%s%s\n", id,
               field(a, "name", name, sizeof name), field(a, "state", state, sizeof state),
               (long long)json_integer_value(json_object_get(a, "priority")),
               field(a, "pool", pool, sizeof pool),
               (long long)json_integer_value(json_object_get(a, "workers")),
               why && *why ? ": " : "",
               why && *why ? tf_printable(why, reason, sizeof reason) : "");
        print_history(json_string_value(json_object_get(a, "history")));
    }
    json_decref(a);
    return TF_EXIT_OK;
}

static int run_control(client *c, const char *action, char **args, int nargs)
{
    long long id;
    if (nargs != (strcmp(action, "priority") ? 1 : 2) || parse_id(args[0], &id)) {
        fputs(usage, stderr);
        return TF_EXIT_USAGE;
    }
    json_t *body = json_object();
    if (nargs == 2) {
        char *end;
        long p = strtol(args[1], &end, 10);
        if (end == args[1] || *end) {
            tf_error("'%s': expected a priority", args[1]);
            json_decref(body);
            return TF_EXIT_USAGE;
        }
        json_object_set_new(body, "priority", json_integer(p));
    }
    char path[96];
    snprintf(path, sizeof path, "/api/jobs/%lld/%s", id, action);
    json_t *a = call(c, "POST", path, body);
    if (!a)
        return TF_EXIT_FAIL;
    if (c->json)
        print_json(a);
    else if (!strcmp(action, "paint"))
        printf("%lld\n", (long long)json_integer_value(json_object_get(a, "id")));
    else {
        char state[64];
        printf("job %lld: %s, priority %lld\n", id, field(a, "state", state, sizeof state),
               (long long)json_integer_value(json_object_get(a, "priority")));
    }
    json_decref(a);
    return TF_EXIT_OK;
}

/* ---- the command line ---- */

static const char *const render_flags[] = {"size", "tasks", "pixel", "verify", "frames", "frame",
                                           "watermark", "affinity", "lease-timeout",
                                           "wait-workers", NULL};

enum { O_FARM = 256, O_TOKEN, O_JSON, O_NAME, O_PRIORITY, O_POOL, O_TAGS, O_AFTER, O_OUTPUT,
       O_FRAMEOUT, O_VERIFY_CHUNKS, O_PAINT, O_RENDER };

/* The options: the farm's own, then render_flags, passed on to the job's render. */
static void jobs_longopts(struct option *longopts)
{
    static const struct option own[] = {
        {"farm", required_argument, NULL, O_FARM}, {"token-file", required_argument, NULL, O_TOKEN},
        {"json", no_argument, NULL, O_JSON},       {"name", required_argument, NULL, O_NAME},
        {"priority", required_argument, NULL, O_PRIORITY},
        {"pool", required_argument, NULL, O_POOL}, {"tags", required_argument, NULL, O_TAGS},
        {"after", required_argument, NULL, O_AFTER},
        {"output", required_argument, NULL, O_OUTPUT},
        {"verify-chunks", no_argument, NULL, O_VERIFY_CHUNKS},
        {"paint", no_argument, NULL, O_PAINT},
        {"help", no_argument, NULL, 'h'},
    };
    int n = (int)(sizeof own / sizeof own[0]);
    memcpy(longopts, own, sizeof own);
    for (int i = 0; render_flags[i]; i++)
        longopts[n++] = (struct option){render_flags[i], required_argument, NULL, O_RENDER + i};
    longopts[n] = (struct option){NULL, 0, NULL, 0};
}

/* What the command line asks for. */
typedef struct jobs_args {
    const char *cmd, *farm, *token, *output;
    json_t *settings; /* the job's name, pool, tags, priority, after, kind */
    json_t *options;  /* its render's options, as words */
    client c;
    int frame, paint;
} jobs_args;

/* --priority and --after: integers.  0, or -1 after saying so. */
static int integer_setting(jobs_args *a, const char *name, const char *arg)
{
    char *end;
    long long v = strtoll(arg, &end, 10);
    if (end == arg || *end) {
        tf_error("--%s '%s': expected an integer", name, arg);
        return -1;
    }
    json_object_set_new(a->settings, name, json_integer(v));
    return 0;
}

/* A render option: passed on to the job's render, except `job --frame N`, the frame to fetch. */
static int render_option(jobs_args *a, int i, const char *arg)
{
    char flag[64], *end;
    snprintf(flag, sizeof flag, "--%s", render_flags[i]);
    if (!strcmp(a->cmd, "job") && !strcmp(flag, "--frame")) {
        long v = strtol(arg, &end, 10);
        if (end == arg || *end || v < 0 || v > INT32_MAX) {
            tf_error("--frame '%s': expected a frame number (an integer >= 0)", arg);
            return -1;
        }
        a->frame = (int)v;
        return 0;
    }
    json_array_append_new(a->options, json_string(flag));
    json_array_append_new(a->options, json_string(arg));
    return 0;
}

/* One option into a (longopts[idx] for a long one): 0, or -1 after saying why not. */
static int jobs_option(jobs_args *a, int ch, const char *name, const char *arg)
{
    switch (ch) {
    case O_FARM: a->farm = arg; return 0;
    case O_TOKEN: a->token = arg; return 0;
    case O_JSON: a->c.json = 1; return 0;
    case O_OUTPUT: a->output = arg; return 0;
    case O_NAME: case O_POOL: case O_TAGS:
        json_object_set_new(a->settings, name, json_string(arg));
        return 0;
    case O_PRIORITY: case O_AFTER:
        return integer_setting(a, name, arg);
    case O_VERIFY_CHUNKS:
        json_array_append_new(a->options, json_string("--verify-chunks"));
        return 0;
    case O_PAINT:
        a->paint = 1;
        json_object_set_new(a->settings, "kind", json_string("paint"));
        return 0;
    default:
        return render_option(a, ch - O_RENDER, arg);
    }
}

/* The options into a: -1 to go on, or the exit status (--help, or a refusal). */
static int parse_jobs_args(jobs_args *a, int argc, char **argv)
{
    struct option longopts[32];
    jobs_longopts(longopts);
    int ch, idx = 0;
    optind = 1;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":h", longopts, &idx)) != -1) {
        if (ch == 'h') {
            fputs(usage, stdout);
            return TF_EXIT_OK;
        }
        if (ch == ':') {
            tf_error("%s needs a value", argv[optind - 1]);
            return TF_EXIT_USAGE;
        }
        if (ch == '?') {
            tf_error("unknown option '%s' (see terrafarm %s --help)", argv[optind - 1], a->cmd);
            return TF_EXIT_USAGE;
        }
        if (jobs_option(a, ch, longopts[idx].name, optarg))
            return TF_EXIT_USAGE;
    }
    return -1;
}

/* The command itself, with its arguments (the words after the options). */
static int run_command(jobs_args *a, char **args, int nargs)
{
    const char *cmd = a->cmd;
    if (!strcmp(cmd, "submit") && nargs == 1)
        return run_submit(&a->c, args[0], a->settings, a->options);
    if (!strcmp(cmd, "jobs") && nargs == 0)
        return run_jobs(&a->c);
    if (!strcmp(cmd, "job") && nargs == 1 && a->paint && !a->output)
        return run_control(&a->c, "paint", args, nargs);
    if (!strcmp(cmd, "job") && nargs == 1 && !a->paint)
        return run_job(&a->c, args[0], a->output, a->frame);
    if (!strcmp(cmd, "cancel") || !strcmp(cmd, "pause") || !strcmp(cmd, "resume") ||
        !strcmp(cmd, "priority"))
        return run_control(&a->c, cmd, args, nargs);
    fputs(usage, stderr);
    return TF_EXIT_USAGE;
}

int cmd_jobs(int argc, char **argv)
{
    jobs_args a = {.cmd = argv[0], .settings = json_object(), .options = json_array()};
    int rc = parse_jobs_args(&a, argc, argv);
    if (rc < 0)
        rc = connect_opts(&a.c, a.farm, a.token) ? TF_EXIT_USAGE
                                                 : run_command(&a, argv + optind, argc - optind);
    json_decref(a.settings);
    json_decref(a.options);
    return rc;
}
