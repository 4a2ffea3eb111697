/* farm_jobs.c: what people do with the standing farm's queue: submit a job (its scene and
 * height map as content, checked before it is queued), list and show jobs, and control them
 * (cancel, pause, resume, priority; paint: farm_paint.c).  A submitter sees and controls only
 * its own jobs; an admin all of them; a worker none; a paint run may only submit.  Every
 * answer is JSON with an HTTP status. */
#include "coordinator/farm/farm_internal.h"

#include <ctype.h>
#include <errno.h>
#include <sodium.h>
#include <stdint.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "coordinator/farm/jobrun.h"
#include "coordinator/render/frames.h"
#include "coordinator/render/render_option.h"
#include "log.h"
#include "scene.h"

#define SCENE_TEXT_MAX (1 << 20)

json_t *farm_error(int *status, int code, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    *status = code;
    return json_pack("{s:s}", "error", msg);
}

static int may_see(const farm_caller *who, const tf_job *j)
{
    return !strcmp(who->role, "admin") ||
           (!strcmp(who->role, "submitter") && !strcmp(who->name, j->owner));
}

/* ---- submission ---- */

/* Render options a job may carry: the ones that shape the image and its tasks.  The farm
 * chooses the output, the listening socket, the secret, the workers and the statistics. */
static const char *const allowed_options[] = {"--size", "--tasks", "--pixel", "--verify",
                                              "--frames", "--frame", "--watermark",
                                              "--affinity", "--lease-timeout",
                                              "--wait-workers", NULL};

static int option_allowed(const char *flag)
{
    for (int i = 0; allowed_options[i]; i++)
        if (!strcmp(flag, allowed_options[i]))
            return 1;
    return !strcmp(flag, "--verify-chunks") ? 2 : 0; /* 2: takes no value */
}

static int value_ok(const char *v)
{
    size_t n = strlen(v);
    if (!n || n > 64 || v[0] == '-')
        return 0;
    for (size_t i = 0; i < n; i++)
        if (v[i] <= 0x20 || v[i] >= 0x7f)
            return 0;
    return 1;
}

/* The options array: known flags, each with one plain value that the render takes (parsed
 * into *ro as the render will parse it); 0 or a message in err. */
static int check_options(json_t *opts, tf_render_opts *ro, char *err, size_t errlen)
{
    char why[512];
    tf_render_opts_init(ro);
    if (opts && !json_is_array(opts))
        return tf_seterr(err, errlen, "options: expected an array of strings");
    size_t n = json_array_size(opts);
    for (size_t i = 0; i < n; i++) {
        const char *flag = json_string_value(json_array_get(opts, i));
        int kind = flag ? option_allowed(flag) : 0;
        if (!kind)
            return tf_seterr(err, errlen, "options: '%s' is not a render option a farm job "
                             "may set (allowed: --size --tasks --pixel --verify --verify-chunks "
                             "--frames --frame --watermark --affinity --lease-timeout "
                             "--wait-workers)",
                             flag ? flag : "(not a string)");
        if (kind == 2)
            continue;
        const char *v = ++i < n ? json_string_value(json_array_get(opts, i)) : NULL;
        if (!v || !value_ok(v))
            return tf_seterr(err, errlen, "options: %s needs one plain value", flag);
        if (tf_render_option_set(ro, flag, v, why, sizeof why))
            return tf_seterr(err, errlen, "options: %s", why);
    }
    return 0;
}

/* What the options ask of this scene: the frames it has; the image size. */
static int check_options_with(const tf_render_opts *ro, const tf_scene *s, tf_job *j, char *err,
                              size_t errlen)
{
    char why[512];
    tf_frame_range range = {ro->frame_first, ro->frame_last, ro->frame_step};
    if (ro->frames_given && tf_frame_range_fits(&range, s->animation.frames, j->name, why,
                                                sizeof why))
        return tf_seterr(err, errlen, "options: %s", why);
    j->width = ro->width ? ro->width : s->width;
    j->height = ro->height ? ro->height : s->height;
    return 0;
}

/* 1 to max letters, digits, '.', '_', '-' (and commas when a list); empty when may_be_empty. */
static int name_ok(const char *s, size_t max, int list, int may_be_empty)
{
    size_t n = strlen(s);
    const char *ok = list ? "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-,"
                          : "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-";
    return (n || may_be_empty) && n <= max && strspn(s, ok) == n;
}

/* The height map the submission carries (base64), or NULL with *bad set on a malformed one. */
static uint8_t *decode_heightmap(json_t *hm, size_t *len, const char **name, int *bad)
{
    const char *b64 = json_string_value(json_object_get(hm, "base64"));
    *name = json_string_value(json_object_get(hm, "name"));
    *bad = 0;
    if (!hm)
        return NULL;
    size_t n = b64 ? strlen(b64) : 0, cap = n / 4 * 3 + 3;
    uint8_t *out = n ? malloc(cap) : NULL;
    if (!out || sodium_base642bin(out, cap, b64, n, NULL, len, NULL,
                                  sodium_base64_VARIANT_ORIGINAL) || !*len) {
        free(out);
        *bad = 1;
        return NULL;
    }
    return out;
}

/* Parse and check the scene with its height map; fills j's scene facts.  NULL and a message. */
static tf_scene *check_scene(const char *text, uint8_t *hm, size_t hm_len, const char *hm_name,
                             tf_job *j, char *err, size_t errlen)
{
    tf_scene *s = tf_scene_parse_text(j->name, text, strlen(text), err, errlen);
    if (!s) {
        free(hm);
        return NULL;
    }
    int file = s->terrain.generator == TF_GEN_FILE;
    if (file && !hm)
        tf_seterr(err, errlen, "%s: the scene reads a height map (path = %s) but the submission "
                  "carries none: the farm never opens a path a submitter names; terrafarm "
                  "submit sends the file's bytes", j->name, s->terrain.file_path);
    else if (!file && hm)
        tf_seterr(err, errlen, "%s: a height map was sent but the scene's generator is not "
                  "file", j->name);
    else if (s->terrain.erosion.fluvial_steps > 0)
        tf_seterr(err, errlen, "%s: [erosion] scenes are not served by the standing farm yet; "
                  "render them with terrafarm render", j->name);
    else if (!file || !tf_scene_attach_heightmap(s, hm, hm_len, hm_name ? hm_name : "heightmap",
                                                   err, errlen)) {
        hm = NULL; /* owned by the scene now */
        tf_farm_terrain_key(s, j->terrain);
        snprintf(j->scene_hash, sizeof j->scene_hash, "%s", s->hash_hex);
        j->frames = s->animation.frames;
        return s;
    } else
        hm = NULL; /* freed by tf_scene_attach_heightmap */
    free(hm);
    tf_scene_free(s);
    return NULL;
}

/* A paint page's view goes where its paint job is served, unless it names a pool or tags. */
static void paint_defaults(const tf_farm *f, const farm_caller *who, const char **pool,
                           const char **tags)
{
    int i = !strcmp(who->role, "paint") ? farm_job_index(f, who->paint_job) : -1;
    if (i >= 0 && !*pool)
        *pool = f->jobs[i].pool;
    if (i >= 0 && !*tags)
        *tags = f->jobs[i].tags;
}

/* The job's settings from the request: name, priority, pool, tags, after. */
static int read_settings(tf_farm *f, const farm_caller *who, json_t *req, tf_job *j, char *err,
                         size_t errlen)
{
    const char *name = json_string_value(json_object_get(req, "name"));
    const char *pool = json_string_value(json_object_get(req, "pool"));
    const char *tags = json_string_value(json_object_get(req, "tags"));
    json_t *prio = json_object_get(req, "priority"), *after = json_object_get(req, "after");
    paint_defaults(f, who, &pool, &tags);
    snprintf(j->name, sizeof j->name, "%s", name && *name ? name : "job");
    snprintf(j->pool, sizeof j->pool, "%s", pool && *pool ? pool : "default");
    snprintf(j->tags, sizeof j->tags, "%s", tags ? tags : "");
    snprintf(j->owner, sizeof j->owner, "%s", who->name);
    if (strlen(name ? name : "") > 100 || !name_ok(j->name, 100, 0, 0))
        return tf_seterr(err, errlen, "name: 1 to 100 letters, digits, '.', '_' or '-'");
    if ((pool && strlen(pool) > 63) || !name_ok(j->pool, 63, 0, 0))
        return tf_seterr(err, errlen, "pool: 1 to 63 letters, digits, '.', '_' or '-'");
    if ((tags && strlen(tags) > 255) || !name_ok(j->tags, 255, 1, 1))
        return tf_seterr(err, errlen, "tags: a comma list of letters, digits, '.', '_', '-'");
    if (prio && (!json_is_integer(prio) || json_integer_value(prio) < -1000 ||
                 json_integer_value(prio) > 1000))
        return tf_seterr(err, errlen, "priority: an integer from -1000 to 1000");
    j->priority = prio ? (int)json_integer_value(prio) : 0;
    if (after && !json_is_integer(after))
        return tf_seterr(err, errlen, "after: a job id");
    j->after = after ? json_integer_value(after) : 0;
    int k = j->after ? farm_job_index(f, j->after) : 0;
    if (k < 0 || (j->after && !may_see(who, &f->jobs[k])))
        return tf_seterr(err, errlen, "after: no job %lld of yours", (long long)j->after);
    return 0;
}

/* The job's kind from the request ("render" when absent): 0, or -1 and err. */
static int read_kind(json_t *req, json_t *opts, tf_job *j, char *err, size_t errlen)
{
    json_t *k = json_object_get(req, "kind");
    const char *kind = k ? json_string_value(k) : "render";
    if (!kind || (strcmp(kind, "render") && strcmp(kind, "paint")))
        return tf_seterr(err, errlen, "kind: render or paint");
    snprintf(j->kind, sizeof j->kind, "%s", kind);
    return !strcmp(kind, "paint") ? farm_paint_options_ok(opts, err, errlen) : 0;
}

/* Who may submit: people, and a paint run for its job's owner. */
static int may_submit(const farm_caller *who)
{
    return !strcmp(who->role, "submitter") || !strcmp(who->role, "admin") ||
           !strcmp(who->role, "paint");
}

/* The request checked: its settings, options, kind, height map and scene, and the options
 * against the scene.  NULL with the scene in *out (the caller frees it) and the height map's
 * name in *hm_name; else the refusal's document, *status set. */
static json_t *checked_job(tf_farm *f, const farm_caller *who, json_t *req, tf_job *j,
                           tf_scene **out, const char **hm_name, int *status)
{
    char err[1024];
    tf_render_opts ro;
    const char *text = json_string_value(json_object_get(req, "scene"));
    json_t *opts = json_object_get(req, "options");
    if (!text || strlen(text) > SCENE_TEXT_MAX)
        return farm_error(status, 400, "scene: the scene file's text (at most 1 MiB)");
    if (read_settings(f, who, req, j, err, sizeof err) ||
        check_options(opts, &ro, err, sizeof err) || read_kind(req, opts, j, err, sizeof err))
        return farm_error(status, 400, "%s", err);
    size_t hm_len = 0;
    int bad;
    uint8_t *hm = decode_heightmap(json_object_get(req, "heightmap"), &hm_len, hm_name, &bad);
    if (bad)
        return farm_error(status, 400, "heightmap: expected {\"name\": ..., \"base64\": ...}");
    tf_scene *s = check_scene(text, hm, hm_len, *hm_name, j, err, sizeof err);
    if (!s)
        return farm_error(status, 400, "%s", err);
    json_t *refused = NULL;
    if (tf_job_is_paint(j) && j->frames)
        refused = farm_error(status, 400, "%s: an [animation] cannot be painted; paint a still",
                             j->name);
    else if (check_options_with(&ro, s, j, err, sizeof err))
        refused = farm_error(status, 400, "%s", err);
    if (refused)
        tf_scene_free(s);
    else
        *out = s;
    return refused;
}

/* The checked job queued: stored in the database and appended to the farm's jobs.  0, or -1
 * with one line in err. */
static int queue_job(tf_farm *f, tf_job *j, json_t *req, const tf_scene *s, const char *hm_name,
                     char *err, size_t errlen)
{
    const char *text = json_string_value(json_object_get(req, "scene"));
    json_t *opts = json_object_get(req, "options");
    tf_job_content c = {.scene = (char *)text, .scene_len = strlen(text),
                        .heightmap = s->heightmap, .heightmap_len = s->heightmap_len,
                        .heightmap_name = (char *)(hm_name ? hm_name : "heightmap"),
                        .options = opts ? json_dumps(opts, JSON_COMPACT) : strdup("[]")};
    snprintf(j->state, sizeof j->state, "queued");
    snprintf(j->output, sizeof j->output, "%s", tf_job_is_paint(j) ? "painted.exr"
                                               : j->frames ? "frame.####.exr" : "out.exr");
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    j->created = (double)ts.tv_sec + ts.tv_nsec / 1e9;
    int rc = tf_farm_nonce_new(j->nonce) || !c.options ||
             tf_farmdb_insert(f->db, j, &c, err, errlen) || farm_append_job(f, j);
    free(c.options);
    return rc ? -1 : 0;
}

json_t *farm_submit(tf_farm *f, const farm_caller *who, json_t *req, int *status)
{
    if (!may_submit(who))
        return farm_error(status, 403, "a %s may not submit jobs", who->role);
    tf_job j = {0};
    tf_scene *s = NULL;
    const char *hm_name = NULL;
    json_t *refused = checked_job(f, who, req, &j, &s, &hm_name, status);
    if (refused)
        return refused;
    char err[1024] = "";
    int rc = queue_job(f, &j, req, s, hm_name, err, sizeof err);
    tf_scene_free(s);
    if (rc)
        return farm_error(status, 500, "cannot queue the job: %s", err);
    pthread_cond_broadcast(&f->changed);
    tf_info("job %lld (%s, %s) submitted by %s%s, priority %d, pool %s", (long long)j.id,
            j.name, j.kind, who->name, !strcmp(who->role, "paint") ? "'s paint page" : "",
            j.priority, j.pool);
    *status = 201;
    return json_pack("{s:I,s:s,s:s}", "id", (json_int_t)j.id, "kind", j.kind, "state", "queued");
}

/* ---- listing and showing ---- */

static const char *shown_state(const tf_farm *f, int i)
{
    if (f->runs[i].pid && !f->runs[i].stopping)
        return "running";
    if (!strcmp(f->jobs[i].state, "queued") && farm_after_state(f, &f->jobs[i]) == 1)
        return "waiting";
    return f->jobs[i].state;
}

static json_t *job_json(const tf_farm *f, int i)
{
    const tf_job *j = &f->jobs[i];
    json_t *o = json_pack("{s:I,s:s,s:s,s:s,s:i,s:s,s:s,s:i,s:i,s:i,s:i,s:s,s:s,s:i,s:f,s:f,s:f}",
                          "id", (json_int_t)j->id, "name", j->name, "owner", j->owner, "state",
                          shown_state(f, i), "priority", j->priority, "pool", j->pool, "tags",
                          j->tags, "workers", f->runs[i].workers, "width", j->width, "height",
                          j->height, "frames", j->frames, "scene_hash", j->scene_hash,
                          "reason", j->reason, "attempts", j->attempts, "created", j->created,
                          "started", j->started, "finished", j->finished);
    json_object_set_new(o, "kind", json_string(j->kind[0] ? j->kind : "render"));
    if (o && j->after)
        json_object_set_new(o, "after", json_integer(j->after));
    double pct = !strcmp(j->state, "done") ? 100.0 : f->runs[i].pid ? f->runs[i].percent : -1;
    json_object_set_new(o, "percent", pct >= 0 ? json_real(pct) : json_null());
    return o;
}

json_t *farm_list(tf_farm *f, const farm_caller *who, int *status)
{
    if (!strcmp(who->role, "worker"))
        return farm_error(status, 403, "a worker may not list jobs");
    json_t *arr = json_array();
    for (int i = 0; i < f->njobs; i++)
        if (may_see(who, &f->jobs[i]))
            json_array_append_new(arr, job_json(f, i));
    *status = 200;
    return json_pack("{s:o}", "jobs", arr);
}

/* The job at id if who may see it, else -1 and the answer in *answer. */
static int find_visible(tf_farm *f, const farm_caller *who, int64_t id, json_t **answer,
                        int *status)
{
    int i = farm_job_index(f, id);
    if (i < 0 || !may_see(who, &f->jobs[i])) { /* another's job is not said to exist */
        *answer = farm_error(status, 404, "no job %lld of yours", (long long)id);
        return -1;
    }
    return i;
}

json_t *farm_show(tf_farm *f, const farm_caller *who, int64_t id, int *status)
{
    json_t *answer = NULL;
    int i = find_visible(f, who, id, &answer, status);
    if (i < 0)
        return answer;
    json_t *o = job_json(f, i);
    char *h = tf_farmdb_history(f->db, id);
    json_object_set_new(o, "history", json_string(h ? h : ""));
    if (f->runs[i].pid && f->runs[i].http_port) { /* the job's own page, as a render's */
        char url[512];
        snprintf(url, sizeof url, strchr(f->host, ':') ? "http://[%s]:%d/login?token=%s"
                                                       : "http://%s:%d/login?token=%s",
                 f->host, f->runs[i].http_port, f->runs[i].token);
        json_object_set_new(o, "dashboard", json_string(url));
    }
    free(h);
    *status = 200;
    return o;
}

/* ---- control ---- */

static int finished(const tf_job *j)
{
    return !strcmp(j->state, "done") || !strcmp(j->state, "failed") ||
           !strcmp(j->state, "cancelled");
}

/* Move job i to state (durably), stopping its render if one runs. */
static int move_to(tf_farm *f, int i, const char *state, const char *event)
{
    if (farm_set_state(f, i, state, !strcmp(state, "cancelled") ? "cancelled by request" : "",
                       event))
        return -1;
    if (f->runs[i].pid)
        farm_stop_render(f, i, state);
    return 0;
}

static json_t *set_priority(tf_farm *f, int i, json_t *req, int *status)
{
    json_t *p = json_object_get(req, "priority");
    if (!json_is_integer(p) || json_integer_value(p) < -1000 || json_integer_value(p) > 1000)
        return farm_error(status, 400, "priority: an integer from -1000 to 1000");
    char ev[64];
    snprintf(ev, sizeof ev, "priority %d -> %d", f->jobs[i].priority, (int)json_integer_value(p));
    f->jobs[i].priority = (int)json_integer_value(p);
    if (farm_set_state(f, i, f->jobs[i].state, f->jobs[i].reason, ev))
        return farm_error(status, 500, "cannot store the priority");
    *status = 200;
    return job_json(f, i);
}

json_t *farm_control(tf_farm *f, const farm_caller *who, int64_t id, const char *action,
                     json_t *req, int *status)
{
    json_t *answer = NULL;
    int i = find_visible(f, who, id, &answer, status);
    if (i < 0)
        return answer;
    tf_job *j = &f->jobs[i];
    if (!strcmp(action, "paint")) /* any job's scene may be painted, finished ones too */
        return farm_paint_from_job(f, who, i, req, status);
    if (finished(j))
        return farm_error(status, 409, "job %lld is %s", (long long)id, j->state);
    int rc;
    if (!strcmp(action, "priority"))
        return set_priority(f, i, req, status);
    else if (!strcmp(action, "cancel"))
        rc = move_to(f, i, "cancelled", "cancelled");
    else if (!strcmp(action, "pause") && !strcmp(j->state, "queued"))
        rc = move_to(f, i, "paused", "paused");
    else if (!strcmp(action, "resume") && !strcmp(j->state, "paused"))
        rc = move_to(f, i, "queued", "resumed");
    else if (!strcmp(action, "pause") || !strcmp(action, "resume"))
        return farm_error(status, 409, "job %lld is %s", (long long)id, j->state);
    else
        return farm_error(status, 404, "no action '%s' (cancel, pause, resume, priority, paint)",
                          action);
    if (rc)
        return farm_error(status, 500, "cannot store the job's state");
    *status = 200;
    return job_json(f, i);
}

/* A request's ?frame=: digits only, at most INT32_MAX (NULL: frame 0).  0, or -1. */
static int parse_frame(const char *text, int *frame)
{
    char *end;
    *frame = 0;
    if (!text)
        return 0;
    errno = 0;
    long long v = strtoll(text, &end, 10);
    if (end == text || *end || !isdigit((unsigned char)text[0]) || errno || v > INT32_MAX)
        return -1;
    *frame = (int)v;
    return 0;
}

int farm_output_path(tf_farm *f, const farm_caller *who, int64_t id, const char *frame_text,
                     char *path, size_t n, char *err, size_t errlen)
{
    int i = farm_job_index(f, id), frame = 0;
    if (i < 0 || !may_see(who, &f->jobs[i]))
        return tf_seterr(err, errlen, "no job %lld of yours", (long long)id), 404;
    const tf_job *j = &f->jobs[i];
    if (strcmp(j->state, "done"))
        return tf_seterr(err, errlen, "job %lld is %s, not done", (long long)id,
                         shown_state(f, i)), 409;
    if (j->frames && parse_frame(frame_text, &frame))
        return tf_seterr(err, errlen, "frame '%.40s': expected a frame number (an integer >= 0)",
                         frame_text), 400;
    char *name = j->frames ? tf_frame_output_path(j->output, frame) : strdup(j->output);
    int rc = !name || tf_job_path(f->o.state_dir, id, name, path, n);
    free(name);
    return rc ? (tf_seterr(err, errlen, "out of memory"), 500) : 0;
}
