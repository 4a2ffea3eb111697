/* api.c: see api.h. */
#include "coordinator/dashboard/api.h"

#include <math.h>
#include <stdio.h>
#include <time.h>

static json_t *iso_time(double unix_s)
{
    time_t t = (time_t)unix_s;
    struct tm tm;
    char buf[64];
    if (!gmtime_r(&t, &tm))
        return json_null();
    int ms = (int)((unix_s - (double)t) * 1000.0);
    snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900,
             tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, ms < 0 ? 0 : ms % 1000);
    return json_string(buf);
}

/* A string from outside (a worker's hello, a path): JSON wants UTF-8, so other bytes become '?'. */
static json_t *text(const char *s)
{
    json_t *j = json_string(s ? s : "");
    if (j)
        return j;
    char buf[1024];
    size_t n = 0;
    for (; *s && n < sizeof buf - 1; s++)
        buf[n++] = (unsigned char)*s < 0x80 ? *s : '?';
    return json_stringn(buf, n);
}

static json_t *int_or_null(int64_t v) { return v < 0 ? json_null() : json_integer(v); }
static json_t *real_or_null(double v) { return v < 0 || !isfinite(v) ? json_null() : json_real(v); }

json_t *tf_api_status(const tf_snapshot *s)
{
    char size[32];
    snprintf(size, sizeof size, "%dx%d", s->width, s->height);
    double pct = s->rows_total ? 100.0 * s->rows_written / s->rows_total : 100.0;
    json_t *o = json_object();
    json_object_set_new(o, "state", json_string(tf_run_state_name(s->state)));
    json_object_set_new(o, "scene", text(s->scene));
    json_object_set_new(o, "output", text(s->output));
    json_object_set_new(o, "width", json_integer(s->width));
    json_object_set_new(o, "height", json_integer(s->height));
    json_object_set_new(o, "size", json_string(size));
    json_object_set_new(o, "frame", int_or_null(s->frame));
    json_object_set_new(o, "frames_total", int_or_null(s->frames_total));
    json_object_set_new(o, "frames_done", int_or_null(s->frames_done));
    json_object_set_new(o, "rows_written", json_integer(s->rows_written));
    json_object_set_new(o, "rows_total", json_integer(s->rows_total));
    json_object_set_new(o, "rows_resumed", json_integer(s->rows_at_start));
    json_object_set_new(o, "percent", json_real(pct));
    json_object_set_new(o, "started", iso_time(s->start_unix_s));
    json_object_set_new(o, "elapsed_s", json_real(s->elapsed_s));
    json_object_set_new(o, "eta_s", real_or_null(s->eta_s));
    json_object_set_new(o, "rays_total", json_integer((json_int_t)s->rays_total));
    json_object_set_new(o, "rays_per_s", json_real(s->rays_per_s));
    json_object_set_new(o, "rays_per_s_recent", json_real(s->rays_per_s_recent));
    json_object_set_new(o, "samples_per_pixel_avg", json_real(s->spp_avg));
    json_object_set_new(o, "watermark", json_integer(s->watermark));
    json_object_set_new(o, "watermark_min", json_integer(s->watermark_min));
    json_object_set_new(o, "watermark_max", json_integer(s->watermark_max));
    json_object_set_new(o, "outstanding_tasks", json_integer(s->outstanding));
    json_object_set_new(o, "max_outstanding_tasks", json_integer(s->max_outstanding));
    json_object_set_new(o, "tasks", text(s->tasks_desc));
    json_object_set_new(o, "tasks_total", json_integer(s->tasks_total));
    json_object_set_new(o, "tasks_written", json_integer(s->tasks_written));
    json_object_set_new(o, "tasks_redealt", json_integer(s->tasks_redealt));
    json_object_set_new(o, "task_failures", json_integer(s->task_failures));
    json_object_set_new(o, "workers_connected", json_integer(s->live_workers));
    json_object_set_new(o, "workers_seen", json_integer(s->nworkers));
    json_object_set_new(o, "workers_joined", json_integer(s->joined_workers));
    json_object_set_new(o, "exit_status", int_or_null(s->exit_status));
    json_object_set_new(o, "preview_stamps", json_integer(s->preview_stamps));
    json_object_set_new(o, "last_event", json_integer(s->nevents ? (json_int_t)s->events[s->nevents - 1].seq : 0));
    json_object_set_new(o, "version", json_integer((json_int_t)s->version));
    return o;
}

json_t *tf_api_workers(const tf_snapshot *s)
{
    json_t *arr = json_array();
    for (int i = 0; i < s->nworkers; i++) {
        const tf_snap_worker *w = &s->workers[i];
        json_t *o = json_object();
        double until = w->state == TF_WS_LEFT || w->state == TF_WS_DROPPED ? w->last_heard_s
                                                                            : s->elapsed_s;
        double span = w->since_s >= 0 ? until - w->since_s : -1;
        double frac = span > 0.05 ? w->busy_s / span : -1;
        if (frac > 1)
            frac = 1; /* busy_s is measured by the worker, the span by us: clocks differ a hair */
        json_object_set_new(o, "id", json_integer(w->id));
        json_object_set_new(o, "kind", text(w->kind));
        json_object_set_new(o, "host", text(w->host));
        json_object_set_new(o, "backend", text(w->backend));
        json_object_set_new(o, "state", json_string(tf_worker_state_name(w->state)));
        json_object_set_new(o, "task", int_or_null(w->holding));
        json_object_set_new(o, "tasks", json_integer(w->tasks));
        json_object_set_new(o, "rays", json_integer((json_int_t)w->rays));
        json_object_set_new(o, "busy_s", json_real(w->busy_s));
        json_object_set_new(o, "busy_fraction", real_or_null(frac));
        json_object_set_new(o, "connected_since_s", real_or_null(w->since_s));
        json_object_set_new(o, "connected_since",
                            w->since_s >= 0 ? iso_time(s->start_unix_s + w->since_s) : json_null());
        json_object_set_new(o, "last_heard_s", real_or_null(w->last_heard_s));
        json_object_set_new(o, "last_heard_ago_s",
                            w->last_heard_s >= 0 ? json_real(s->elapsed_s - w->last_heard_s)
                                                 : json_null());
        json_array_append_new(arr, o);
    }
    json_t *o = json_object();
    json_object_set_new(o, "workers", arr);
    return o;
}

json_t *tf_api_event(const tf_snapshot *s, const tf_event *e)
{
    json_t *o = json_object();
    json_object_set_new(o, "seq", json_integer((json_int_t)e->seq));
    json_object_set_new(o, "time", iso_time(e->unix_s));
    json_object_set_new(o, "elapsed_s", json_real(e->elapsed_s));
    json_object_set_new(o, "kind", json_string(tf_event_kind_name(e->kind)));
    json_object_set_new(o, "worker", int_or_null(e->worker));
    json_object_set_new(o, "task", int_or_null(e->task));
    /* the text may hold bytes a worker sent (a failure message): keep it valid UTF-8 */
    json_object_set_new(o, "text", text(e->text));
    (void)s;
    return o;
}

json_t *tf_api_events(const tf_snapshot *s, uint64_t after)
{
    json_t *arr = json_array();
    for (int i = 0; i < s->nevents; i++)
        if (s->events[i].seq > after)
            json_array_append_new(arr, tf_api_event(s, &s->events[i]));
    json_t *o = json_object();
    json_object_set_new(o, "events", arr);
    json_object_set_new(o, "last_seq",
                        json_integer(s->nevents ? (json_int_t)s->events[s->nevents - 1].seq : 0));
    return o;
}

json_t *tf_api_tasks(const tf_snapshot *s)
{
    json_t *arr = json_array();
    for (int i = 0; i < s->ntasks; i++) {
        const tf_snap_task *t = &s->tasks[i];
        json_t *o = json_object();
        json_object_set_new(o, "id", json_integer(t->id));
        json_object_set_new(o, "x", json_integer(t->rect.x));
        json_object_set_new(o, "y", json_integer(t->rect.y));
        json_object_set_new(o, "w", json_integer(t->rect.w));
        json_object_set_new(o, "h", json_integer(t->rect.h));
        json_object_set_new(o, "frame", int_or_null(t->frame));
        json_object_set_new(o, "state", json_string(t->done ? "done" : t->worker >= 0 ? "held"
                                                                                   : "queued"));
        json_object_set_new(o, "worker", int_or_null(t->worker));
        json_array_append_new(arr, o);
    }
    json_t *o = json_object();
    json_object_set_new(o, "width", json_integer(s->width));
    json_object_set_new(o, "height", json_integer(s->height));
    json_object_set_new(o, "task_w", json_integer(s->task_w));
    json_object_set_new(o, "task_h", json_integer(s->task_h));
    json_object_set_new(o, "tasks_per_band", json_integer(s->task_cols));
    json_object_set_new(o, "first_row", json_integer(s->first_row));
    json_object_set_new(o, "frame", int_or_null(s->preview_frame));
    json_object_set_new(o, "tasks_total", json_integer(s->tasks_total));
    json_object_set_new(o, "tasks_written", json_integer(s->tasks_written));
    json_object_set_new(o, "rows_written", json_integer(s->rows_written));
    json_object_set_new(o, "outstanding", arr);
    return o;
}

json_t *tf_api_history(const tf_snapshot *s)
{
    json_t *arr = json_array();
    for (int i = 0; i < s->nsamples; i++) {
        const tf_snap_sample *p = &s->samples[i];
        json_t *o = json_object();
        json_object_set_new(o, "t", json_real(p->t));
        json_object_set_new(o, "rays", json_integer((json_int_t)p->rays));
        json_object_set_new(o, "busy_s", json_real(p->busy_s));
        json_object_set_new(o, "rows", json_integer(p->rows));
        json_object_set_new(o, "workers", json_integer(p->workers));
        json_array_append_new(arr, o);
    }
    json_t *o = json_object();
    json_object_set_new(o, "samples", arr);
    return o;
}
