/* stats.c: see stats.h.  The document is built with jansson (keys in this order). */
#include "coordinator/stats.h"

#include <errno.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include "log.h"

/* Seconds rounded to the millisecond, as the file has always shown them. */
static json_t *seconds(double s) { return json_real((double)(long long)(s * 1000.0 + (s < 0 ? -0.5 : 0.5)) / 1000.0); }

static json_t *stats_doc(const tf_run_info *run, const tf_farm_stats *st)
{
    json_t *o = json_object();
    uint64_t rays = st->primary_rays + st->shadow_rays;
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
    json_object_set_new(o, "rays_total", json_integer((json_int_t)rays));
    json_object_set_new(o, "primary_rays", json_integer((json_int_t)st->primary_rays));
    json_object_set_new(o, "shadow_rays", json_integer((json_int_t)st->shadow_rays));
    json_object_set_new(o, "external_rays", json_integer((json_int_t)st->external_rays));
    json_object_set_new(o, "samples_per_pixel_avg",
                        json_real(st->pixels ? st->spp_sum / (double)st->pixels : 0.0));
    json_object_set_new(o, "rays_per_pixel_avg",
                        json_real(st->pixels ? (double)st->primary_rays / (double)st->pixels : 0.0));
    json_object_set_new(o, "max_outstanding_tasks", json_integer(st->max_outstanding_tasks));
    json_object_set_new(o, "watermark", json_integer(st->watermark));
    json_object_set_new(o, "max_tuple_bytes", json_integer((json_int_t)st->max_tuple_bytes));
    json_object_set_new(o, "local_workers", json_integer(run->local_workers));
    json_object_set_new(o, "heightfield_s", seconds(run->heightfield_s));
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru) == 0) { /* the coordinator alone: workers are other processes */
        json_object_set_new(o, "coordinator_max_rss_kb", json_integer(ru.ru_maxrss));
        json_object_set_new(o, "coordinator_cpu_s",
                            seconds((double)ru.ru_utime.tv_sec + ru.ru_utime.tv_usec * 1e-6 +
                                    (double)ru.ru_stime.tv_sec + ru.ru_stime.tv_usec * 1e-6));
    }
    json_t *workers = json_array();
    for (int i = 0; i < st->nworkers; i++) {
        const tf_worker_stats *w = &st->workers[i];
        json_t *wo = json_object();
        json_object_set_new(wo, "id", json_integer(w->id));
        json_object_set_new(wo, "kind", json_string(w->kind));
        /* host and backend come from the worker's hello: not trusted to be UTF-8 */
        json_t *host = json_string(w->host), *backend = json_string(w->backend);
        json_object_set_new(wo, "host", host ? host : json_string("?"));
        json_object_set_new(wo, "backend", backend ? backend : json_string("?"));
        json_object_set_new(wo, "tasks", json_integer(w->tasks));
        json_object_set_new(wo, "rays", json_integer((json_int_t)w->rays));
        json_object_set_new(wo, "busy_s", seconds(w->busy_s));
        json_array_append_new(workers, wo);
    }
    json_object_set_new(o, "workers", workers);
    return o;
}

#define STATS_FLAGS (JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(10))

/* The layout the file has always had, which line-based tools (grep, sed) rely on: one key per
 * line at the top, one worker object per line ({"id": 1, "kind": "forked", ...}). */
static int dump_stats(FILE *f, json_t *doc)
{
    json_t *workers = json_incref(json_object_get(doc, "workers"));
    json_object_del(doc, "workers");
    char *top = json_dumps(doc, JSON_INDENT(2) | STATS_FLAGS);
    size_t n = top ? strlen(top) : 0;
    int bad = n < 2 || top[n - 1] != '}';
    if (!bad) { /* drop the closing "\n}" and add the workers before it */
        fwrite(top, 1, n - 2, f);
        fputs(",\n  \"workers\": [", f);
        size_t i;
        json_t *w;
        json_array_foreach(workers, i, w) {
            char *line = json_dumps(w, STATS_FLAGS);
            bad |= !line;
            fprintf(f, "%s\n    %s", i ? "," : "", line ? line : "{}");
            free(line);
        }
        fputs(json_array_size(workers) ? "\n  ]\n}\n" : "]\n}\n", f);
    }
    free(top);
    json_decref(workers);
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
