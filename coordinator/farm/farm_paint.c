/* farm_paint.c: Raypaint on the standing farm (docs/paint.md, "On a standing farm").  A paint
 * job is a job of kind "paint": its process is `terrafarm paint` (jobrun.c) instead of a
 * render, the farm's standing workers serve it like any job, and it runs until its owner
 * closes it (cancel).  A person starts one from the web view or the API on a job they may
 * see (POST /api/jobs/ID/paint: the same scene, height map and size, one priority higher, so
 * the workers come to it at once) or submits one directly (kind "paint").
 *
 * The page's Submit queues the painted view as a render job of the paint job's owner.  The
 * paint process proves it may do that with a token of its run alone: random, held in memory
 * only, written to the job's folder for the process, and valid while the run lives.  The
 * caller it makes has the role "paint", which may submit and nothing else (farm_jobs.c); what
 * it submits goes to the paint job's pool and tags unless it names others. */
#include "coordinator/farm/farm_internal.h"

#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "log.h"

/* Render options a paint job keeps: the ones that shape its image. */
static int paint_option(const char *flag)
{
    return flag && (!strcmp(flag, "--size") || !strcmp(flag, "--pixel"));
}

char *farm_paint_options(const char *options)
{
    json_t *in = json_loads(options ? options : "[]", 0, NULL), *out = json_array();
    for (size_t i = 0; i + 1 < json_array_size(in); i++) {
        const char *flag = json_string_value(json_array_get(in, i));
        if (!paint_option(flag))
            continue;
        json_array_append(out, json_array_get(in, i));
        json_array_append(out, json_array_get(in, ++i));
    }
    char *text = json_dumps(out, JSON_COMPACT);
    json_decref(in);
    json_decref(out);
    return text;
}

int farm_paint_options_ok(json_t *opts, char *err, size_t errlen)
{
    for (size_t i = 0; i < json_array_size(opts); i += 2)
        if (!paint_option(json_string_value(json_array_get(opts, i))))
            return tf_seterr(err, errlen, "options: a paint job takes only --size and --pixel");
    return 0;
}

/* The paint job made from job src for who: src's facts, a name, priority and fresh nonce. */
static void paint_job_of(const tf_job *src, const farm_caller *who, int priority, tf_job *j)
{
    memset(j, 0, sizeof *j);
    snprintf(j->name, sizeof j->name, "%.94s-paint", src->name);
    snprintf(j->owner, sizeof j->owner, "%s", who->name);
    snprintf(j->pool, sizeof j->pool, "%s", src->pool);
    snprintf(j->tags, sizeof j->tags, "%s", src->tags);
    snprintf(j->kind, sizeof j->kind, "paint");
    snprintf(j->state, sizeof j->state, "queued");
    snprintf(j->scene_hash, sizeof j->scene_hash, "%s", src->scene_hash);
    snprintf(j->terrain, sizeof j->terrain, "%s", src->terrain);
    snprintf(j->output, sizeof j->output, "painted.exr");
    j->priority = priority;
    j->width = src->width;
    j->height = src->height;
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    j->created = (double)ts.tv_sec + ts.tv_nsec / 1e9;
}

/* The priority asked for in req, or one above src's: 0, or -1 when req's is not valid. */
static int priority_of(json_t *req, const tf_job *src, int *out)
{
    json_t *p = json_object_get(req, "priority");
    if (!p) {
        *out = src->priority < 1000 ? src->priority + 1 : 1000;
        return 0;
    }
    if (!json_is_integer(p) || json_integer_value(p) < -1000 || json_integer_value(p) > 1000)
        return -1;
    *out = (int)json_integer_value(p);
    return 0;
}

/* Store and queue paint job j with src's content (its options cut to the paint's). */
static int queue_paint(tf_farm *f, tf_job *j, int64_t src, char *err, size_t errlen)
{
    tf_job_content c;
    if (tf_farmdb_content(f->db, src, &c, err, errlen))
        return -1;
    char *opts = farm_paint_options(c.options);
    free(c.options);
    c.options = opts;
    int rc = !opts || tf_farm_nonce_new(j->nonce) ||
             tf_farmdb_insert(f->db, j, &c, err, errlen) || farm_append_job(f, j);
    tf_job_content_free(&c);
    return rc ? -1 : 0;
}

json_t *farm_paint_from_job(tf_farm *f, const farm_caller *who, int i, json_t *req, int *status)
{
    const tf_job *src = &f->jobs[i];
    tf_job j;
    int priority;
    char err[512] = "out of memory";
    if (tf_job_is_paint(src))
        return farm_error(status, 409, "job %lld is a paint job already", (long long)src->id);
    if (src->frames)
        return farm_error(status, 409, "job %lld is a sequence: a still is painted, not an "
                          "[animation]", (long long)src->id);
    if (priority_of(req, src, &priority))
        return farm_error(status, 400, "priority: an integer from -1000 to 1000");
    int64_t src_id = src->id;
    paint_job_of(src, who, priority, &j);
    if (queue_paint(f, &j, src_id, err, sizeof err))
        return farm_error(status, 500, "cannot queue the paint job: %s", err);
    pthread_cond_broadcast(&f->changed);
    tf_info("job %lld (%s): paint of job %lld opened by %s", (long long)j.id, j.name,
            (long long)src_id, who->name);
    *status = 201;
    return json_pack("{s:I,s:s,s:s}", "id", (json_int_t)j.id, "kind", "paint", "state", "queued");
}

int farm_paint_caller(tf_farm *f, const char *token, farm_caller *who)
{
    int found = 0;
    if (!token || strlen(token) != 64)
        return 0;
    pthread_mutex_lock(&f->lock);
    for (int i = 0; i < f->njobs && !found; i++) {
        const farm_run *r = &f->runs[i];
        if (!r->pid || r->stopping || !r->submit_token[0] ||
            sodium_memcmp(token, r->submit_token, 64))
            continue;
        snprintf(who->name, sizeof who->name, "%s", f->jobs[i].owner);
        snprintf(who->role, sizeof who->role, "paint");
        who->paint_job = f->jobs[i].id;
        found = 1;
    }
    pthread_mutex_unlock(&f->lock);
    return found;
}
