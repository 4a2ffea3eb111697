/* stats.c: see stats.h.  The document is built with jansson (keys in this order). */
#include "coordinator/render/stats.h"

#include <errno.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include "log.h"

/* Seconds rounded to the millisecond, as the file has always shown them. */
static json_t *rounded(double x, double scale)
{
    return json_real((double)(long long)(x * scale + (x < 0 ? -0.5 : 0.5)) / scale);
}
static json_t *seconds(double s) { return rounded(s, 1000.0); }

static double cpu_seconds(const struct rusage *ru)
{
    return (double)ru->ru_utime.tv_sec + ru->ru_utime.tv_usec * 1e-6 +
           (double)ru->ru_stime.tv_sec + ru->ru_stime.tv_usec * 1e-6;
}

/* A worker's column range at its latest take (affinity.h; null without one, as with rows:K)
 * and its takes by where they lay for it: what --affinity on does, or FIFO dealing gives. */
static void affinity_keys(json_t *wo, const tf_worker_stats *w)
{
    json_t *range = json_null();
    if (w->aff_x0 >= 0)
        range = json_pack("[ii]", w->aff_x0, w->aff_x1);
    json_object_set_new(wo, "affinity_range", range ? range : json_null());
    json_object_set_new(wo, "first_choice", json_integer(w->aff_first));
    json_object_set_new(wo, "second_choice", json_integer(w->aff_second));
    json_object_set_new(wo, "elsewhere", json_integer(w->aff_elsewhere));
    json_object_set_new(wo, "range_switches", json_integer(w->aff_switches));
}

/* What was rendered: the image, its tasks and rows. */
static void image_keys(json_t *o, const tf_run_info *run, const tf_farm_stats *st)
{
    json_object_set_new(o, "wall_s", seconds(run->wall_s));
    json_object_set_new(o, "width", json_integer(run->width));
    json_object_set_new(o, "height", json_integer(run->height));
    json_object_set_new(o, "scene", json_string(run->scene ? run->scene : ""));
    json_object_set_new(o, "output", json_string(run->output ? run->output : ""));
    json_object_set_new(o, "tasks", json_string(run->tasks ? run->tasks : ""));
    json_object_set_new(o, "tasks_total", json_integer(st->tasks_total));
    json_object_set_new(o, "tasks_redealt", json_integer(st->tasks_redealt));
    json_object_set_new(o, "tasks_duplicated", json_integer(st->tasks_duplicated));
    json_object_set_new(o, "results_dropped", json_integer(st->results_dropped));
    json_object_set_new(o, "task_failures", json_integer(st->task_failures));
    json_object_set_new(o, "rows_resumed", json_integer(st->rows_resumed));
    json_object_set_new(o, "rows_rendered", json_integer(st->rows_rendered));
}

/* The rays traced and samples taken, in all and per pixel. */
static void ray_keys(json_t *o, const tf_farm_stats *st)
{
    uint64_t rays = st->primary_rays + st->shadow_rays;
    double px = (double)st->pixels;
    json_object_set_new(o, "rays_total", json_integer((json_int_t)rays));
    json_object_set_new(o, "primary_rays", json_integer((json_int_t)st->primary_rays));
    json_object_set_new(o, "shadow_rays", json_integer((json_int_t)st->shadow_rays));
    json_object_set_new(o, "external_rays", json_integer((json_int_t)st->external_rays));
    json_object_set_new(o, "terrain_samples_evaluated",
                        json_integer((json_int_t)st->terrain_samples));
    json_object_set_new(o, "samples_per_pixel_avg", json_real(px > 0 ? st->spp_sum / px : 0.0));
    json_object_set_new(o, "rays_per_pixel_avg",
                        json_real(px > 0 ? (double)st->primary_rays / px : 0.0));
}

/* How the tasks were dealt, and what was set up for the render. */
static void dealing_keys(json_t *o, const tf_run_info *run, const tf_farm_stats *st)
{
    json_object_set_new(o, "max_outstanding_tasks", json_integer(st->max_outstanding_tasks));
    json_object_set_new(o, "watermark", json_integer(st->watermark));
    json_object_set_new(o, "affinity", json_boolean(st->affinity));
    json_object_set_new(o, "max_tuple_bytes", json_integer((json_int_t)st->max_tuple_bytes));
    json_object_set_new(o, "local_workers", json_integer(run->local_workers));
    json_object_set_new(o, "heightfield_s", seconds(run->heightfield_s));
    json_object_set_new(o, "results_refused", json_integer(st->results_refused));
}

/* Every worker's busy time: what verify_cost and workers_per_coordinator_core divide by. */
static double workers_busy_s(const tf_farm_stats *st)
{
    double busy = 0;
    for (int i = 0; i < st->nworkers; i++)
        busy += st->workers[i].busy_s;
    return busy;
}

/* What checking results cost: the pixels of networked workers' results (and with
 * --verify-chunks everyone's), decoded and scanned in the checker thread (part of
 * coordinator_cpu_s, reported apart too), and --verify's check copies. */
static void check_keys(json_t *o, const tf_farm_stats *st)
{
    double busy = workers_busy_s(st), px = (double)st->pixels_checked;
    json_object_set_new(o, "pixels_checked", json_integer((json_int_t)st->pixels_checked));
    json_object_set_new(o, "pixel_check_cpu_s", seconds(st->pixel_check_cpu_s));
    json_object_set_new(o, "pixel_check_ns_per_pixel",
                        rounded(px > 0 ? st->pixel_check_cpu_s * 1e9 / px : 0.0, 100.0));
    json_object_set_new(o, "verify_fraction", rounded(st->verify_fraction, 1e4));
    json_object_set_new(o, "verify_checks", json_integer(st->verify_checks));
    json_object_set_new(o, "verify_mismatches", json_integer(st->verify_mismatches));
    json_object_set_new(o, "workers_excluded", json_integer(st->workers_excluded));
    json_object_set_new(o, "verify_busy_s", seconds(st->verify_busy_s));
    json_object_set_new(o, "verify_cost", rounded(busy > 0 ? st->verify_busy_s / busy : 0.0, 1e4));
}

/* Workers' CPU time, where the coordinator can know it: its forked workers, reaped by now
 * (their render and encoding; the terrain was built before the fork); 0 otherwise.  busy_s is
 * wall time and grows on a loaded machine; CPU time does not. */
static double forked_workers_cpu_s(const tf_farm_stats *st)
{
    int all_forked = st->nworkers > 0;
    for (int i = 0; i < st->nworkers; i++)
        all_forked &= strcmp(st->workers[i].kind, "forked") == 0;
    struct rusage rc;
    return all_forked && getrusage(RUSAGE_CHILDREN, &rc) == 0 ? cpu_seconds(&rc) : 0.0;
}

/* The coordinator's own cost (it alone: workers are other processes).  The render path's CPU,
 * without the terrain build before forking, per rendered pixel and against the workers' time
 * per pixel (how many such workers one coordinator core could feed); then the same for the
 * event loop alone: what a long render costs per pixel, without the per-render start-up
 * (forking local workers) and finish (offset table, the final preview), which a short render
 * pays in full. */
static void coordinator_keys(json_t *o, const tf_run_info *run, const tf_farm_stats *st)
{
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru) != 0)
        return;
    double cpu = cpu_seconds(&ru), render_cpu = cpu - run->setup_cpu_s;
    double px = (double)st->pixels, busy = workers_busy_s(st), wcpu = forked_workers_cpu_s(st);
    double fed = wcpu > 0 ? wcpu : busy, sup = run->supervise_cpu_s;
    json_object_set_new(o, "coordinator_max_rss_kb", json_integer(ru.ru_maxrss));
    json_object_set_new(o, "coordinator_cpu_s", seconds(cpu));
    json_object_set_new(o, "coordinator_render_cpu_s", seconds(render_cpu));
    json_object_set_new(o, "coordinator_cpu_ns_per_pixel",
                        rounded(px > 0 ? render_cpu * 1e9 / px : 0.0, 100.0));
    json_object_set_new(o, "worker_busy_ns_per_pixel",
                        rounded(px > 0 ? busy * 1e9 / px : 0.0, 100.0));
    json_object_set_new(o, "worker_cpu_ns_per_pixel",
                        rounded(px > 0 ? wcpu * 1e9 / px : 0.0, 100.0));
    json_object_set_new(o, "workers_per_coordinator_core",
                        rounded(render_cpu > 0 ? fed / render_cpu : 0.0, 10.0));
    json_object_set_new(o, "coordinator_supervise_cpu_s", seconds(sup));
    json_object_set_new(o, "workers_per_coordinator_core_supervising",
                        rounded(sup > 0 ? fed / sup : 0.0, 10.0));
}

/* One worker's line. */
static json_t *worker_json(const tf_worker_stats *w)
{
    json_t *wo = json_object();
    json_object_set_new(wo, "id", json_integer(w->id));
    /* kind, host and backend come from the worker's hello: not trusted to be UTF-8 */
    json_t *kind = json_string(w->kind);
    json_t *host = json_string(w->host), *backend = json_string(w->backend);
    json_object_set_new(wo, "kind", kind ? kind : json_string("?"));
    json_object_set_new(wo, "host", host ? host : json_string("?"));
    json_object_set_new(wo, "backend", backend ? backend : json_string("?"));
    json_object_set_new(wo, "tasks", json_integer(w->tasks));
    json_object_set_new(wo, "rays", json_integer((json_int_t)w->rays));
    json_object_set_new(wo, "busy_s", seconds(w->busy_s));
    json_object_set_new(wo, "samples_evaluated", json_integer((json_int_t)w->terrain_samples));
    json_object_set_new(wo, "cache_hits", json_integer((json_int_t)w->terrain_hits));
    json_object_set_new(wo, "cache_evictions", json_integer((json_int_t)w->terrain_evictions));
    affinity_keys(wo, w);
    return wo;
}

/* One frame of a sequence rendered by this run.  wall_s: from its first task dealt to its last
 * row on disk (frames overlap, so these add up to more than the run's wall_s); start_s and
 * done_s are those instants, in seconds since the run started. */
static json_t *frame_json(const tf_frame_stats *fr, double run_start_s)
{
    double wall = fr->done_ms > 0 && fr->start_ms > 0 ? (fr->done_ms - fr->start_ms) / 1e3 : 0;
    json_t *fo = json_object();
    json_object_set_new(fo, "frame", json_integer(fr->frame));
    json_object_set_new(fo, "wall_s", seconds(wall));
    json_object_set_new(fo, "rays_total", json_integer((json_int_t)fr->rays));
    json_object_set_new(fo, "rows_resumed", json_integer(fr->rows_resumed));
    json_object_set_new(fo, "rows_rendered", json_integer(fr->rows_rendered));
    json_object_set_new(fo, "start_s",
                        seconds(fr->start_ms > 0 ? fr->start_ms / 1e3 - run_start_s : 0));
    json_object_set_new(fo, "done_s",
                        seconds(fr->done_ms > 0 ? fr->done_ms / 1e3 - run_start_s : 0));
    return fo;
}

/* A sequence's frames: those rendered now, and those complete before this run. */
static void frame_keys(json_t *o, const tf_run_info *run, const tf_farm_stats *st)
{
    json_t *frames = json_array(), *skipped = json_array();
    for (int i = 0; i < st->nframes; i++)
        json_array_append_new(frames, frame_json(&st->frames[i], run->start_s));
    for (int i = 0; i < run->nskipped; i++)
        json_array_append_new(skipped, json_integer(run->frames_skipped[i]));
    json_object_set_new(o, "frames", frames);
    json_object_set_new(o, "frames_skipped", skipped);
}

static json_t *stats_doc(const tf_run_info *run, const tf_farm_stats *st)
{
    json_t *o = json_object(), *workers = json_array();
    image_keys(o, run, st);
    ray_keys(o, st);
    dealing_keys(o, run, st);
    check_keys(o, st);
    json_object_set_new(o, "layout", json_string(run->layout ? run->layout : ""));
    coordinator_keys(o, run, st);
    for (int i = 0; i < st->nworkers; i++)
        json_array_append_new(workers, worker_json(&st->workers[i]));
    json_object_set_new(o, "workers", workers);
    if (run->sequence)
        frame_keys(o, run, st);
    return o;
}

#define STATS_FLAGS (JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(10))

/* The layout the file has always had, which line-based tools (grep, sed) rely on: one key per
 * line at the top, one object per line inside an array of objects ("workers": [{"id": 1, ...},
 * ...], "frames"), other arrays on one line ("frames_skipped": [1, 2]). */
static int dump_stats(FILE *f, json_t *doc)
{
    const char *key;
    json_t *value;
    int bad = 0, first = 1;
    fputs("{", f);
    json_object_foreach(doc, key, value) {
        json_t *name = json_string(key);
        char *k = name ? json_dumps(name, JSON_ENCODE_ANY) : NULL;
        json_decref(name);
        bad |= !k;
        fprintf(f, "%s\n  %s: ", first ? "" : ",", k ? k : "\"?\"");
        free(k);
        first = 0;
        if (json_is_array(value) && json_array_size(value) > 0 &&
            json_is_object(json_array_get(value, 0))) {
            size_t i;
            json_t *elem;
            fputs("[", f);
            json_array_foreach(value, i, elem) {
                char *line = json_dumps(elem, STATS_FLAGS);
                bad |= !line;
                fprintf(f, "%s\n    %s", i ? "," : "", line ? line : "{}");
                free(line);
            }
            fputs("\n  ]", f);
        } else {
            char *text = json_dumps(value, JSON_ENCODE_ANY | STATS_FLAGS);
            bad |= !text;
            fputs(text ? text : "null", f);
            free(text);
        }
    }
    fputs("\n}\n", f);
    return bad ? -1 : 0;
}

int tf_stats_write(const char *path, const tf_run_info *run, const tf_farm_stats *st, char *err,
                   size_t errlen)
{
    size_t n = strlen(path) + 8;
    char *tmp = malloc(n);
    json_t *doc = stats_doc(run, st);
    if (!tmp || !doc) {
        free(tmp);
        json_decref(doc);
        return tf_seterr(err, errlen, "%s: out of memory", path);
    }
    snprintf(tmp, n, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        tf_seterr(err, errlen, "%s: cannot write statistics: %s", path, strerror(errno));
        free(tmp);
        json_decref(doc);
        return -1;
    }
    int bad = dump_stats(f, doc);
    json_decref(doc);
    bad |= ferror(f);
    bad |= fclose(f) != 0;
    if (bad || rename(tmp, path)) {
        tf_seterr(err, errlen, "%s: cannot write statistics: %s", path,
                  errno ? strerror(errno) : "write failed");
        remove(tmp);
        free(tmp);
        return -1;
    }
    free(tmp);
    return 0;
}
