/* stats.c: see stats.h. */
#include "coordinator/stats.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include "log.h"

/* JSON string with the escapes RFC 8259 requires. */
static void json_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (; s && *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\')
            fprintf(f, "\\%c", c);
        else if (c < 0x20)
            fprintf(f, "\\u%04x", c);
        else
            fputc(c, f);
    }
    fputc('"', f);
}

int tf_stats_write(const char *path, const tf_run_info *run, const tf_farm_stats *st, char *err,
                   size_t errlen)
{
    size_t n = strlen(path) + 8;
    char *tmp = malloc(n);
    if (!tmp) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        return -1;
    }
    snprintf(tmp, n, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        tf_seterr(err, errlen, "%s: cannot write statistics: %s", path, strerror(errno));
        free(tmp);
        return -1;
    }
    uint64_t rays = st->primary_rays + st->shadow_rays;
    fprintf(f, "{\n  \"wall_s\": %.3f,\n  \"width\": %d,\n  \"height\": %d,\n", run->wall_s,
            run->width, run->height);
    fprintf(f, "  \"scene\": ");
    json_string(f, run->scene);
    fprintf(f, ",\n  \"output\": ");
    json_string(f, run->output);
    fprintf(f, ",\n  \"tasks\": ");
    json_string(f, run->tasks);
    fprintf(f,
            ",\n  \"tasks_total\": %lld,\n  \"tasks_redealt\": %lld,\n"
            "  \"tasks_duplicated\": %lld,\n  \"results_dropped\": %lld,\n"
            "  \"task_failures\": %lld,\n",
            (long long)st->tasks_total, (long long)st->tasks_redealt,
            (long long)st->tasks_duplicated, (long long)st->results_dropped,
            (long long)st->task_failures);
    fprintf(f, "  \"rows_resumed\": %d,\n  \"rows_rendered\": %d,\n", st->rows_resumed,
            st->rows_rendered);
    fprintf(f,
            "  \"rays_total\": %llu,\n  \"primary_rays\": %llu,\n  \"shadow_rays\": %llu,\n"
            "  \"external_rays\": %llu,\n",
            (unsigned long long)rays, (unsigned long long)st->primary_rays,
            (unsigned long long)st->shadow_rays, (unsigned long long)st->external_rays);
    fprintf(f, "  \"samples_per_pixel_avg\": %.4f,\n",
            st->pixels ? st->spp_sum / (double)st->pixels : 0.0);
    fprintf(f, "  \"rays_per_pixel_avg\": %.4f,\n",
            st->pixels ? (double)st->primary_rays / (double)st->pixels : 0.0);
    fprintf(f, "  \"max_outstanding_tasks\": %d,\n  \"watermark\": %d,\n", st->max_outstanding_tasks,
            st->watermark);
    fprintf(f, "  \"max_tuple_bytes\": %zu,\n", st->max_tuple_bytes);
    fprintf(f, "  \"local_workers\": %d,\n  \"heightfield_s\": %.3f,\n", run->local_workers,
            run->heightfield_s);
    fprintf(f, "  \"results_refused\": %lld,\n", (long long)st->results_refused);
    double busy = 0;
    for (int i = 0; i < st->nworkers; i++)
        busy += st->workers[i].busy_s;
    fprintf(f, "  \"verify_fraction\": %.4f,\n  \"verify_checks\": %lld,\n"
               "  \"verify_mismatches\": %lld,\n  \"workers_excluded\": %lld,\n"
               "  \"verify_busy_s\": %.3f,\n  \"verify_cost\": %.4f,\n  \"layout\": ",
            st->verify_fraction, (long long)st->verify_checks, (long long)st->verify_mismatches,
            (long long)st->workers_excluded, st->verify_busy_s,
            busy > 0 ? st->verify_busy_s / busy : 0.0);
    json_string(f, run->layout);
    fprintf(f, ",\n");
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru) == 0) { /* the coordinator alone: workers are other processes */
        double cpu = (double)ru.ru_utime.tv_sec + ru.ru_utime.tv_usec * 1e-6 +
                     (double)ru.ru_stime.tv_sec + ru.ru_stime.tv_usec * 1e-6;
        /* The render path's cost, without the terrain build before forking: per rendered pixel,
         * and against the workers' render time per pixel (how many such workers one
         * coordinator core could feed). */
        double render_cpu = cpu - run->setup_cpu_s;
        double busy = 0;
        for (int i = 0; i < st->nworkers; i++)
            busy += st->workers[i].busy_s;
        double px = (double)st->pixels;
        fprintf(f, "  \"coordinator_max_rss_kb\": %ld,\n  \"coordinator_cpu_s\": %.3f,\n",
                ru.ru_maxrss, cpu);
        fprintf(f, "  \"coordinator_render_cpu_s\": %.3f,\n", render_cpu);
        fprintf(f, "  \"coordinator_cpu_ns_per_pixel\": %.2f,\n",
                px > 0 ? render_cpu * 1e9 / px : 0.0);
        fprintf(f, "  \"worker_busy_ns_per_pixel\": %.2f,\n", px > 0 ? busy * 1e9 / px : 0.0);
        /* Workers' CPU time, where the coordinator can know it: its forked workers, reaped by
         * now (their render and encoding; the terrain was built before the fork).  busy_s is
         * wall time and grows on a loaded machine; CPU time does not. */
        struct rusage rc;
        int all_forked = st->nworkers > 0;
        for (int i = 0; i < st->nworkers; i++)
            all_forked &= strcmp(st->workers[i].kind, "forked") == 0;
        double wcpu = 0;
        if (all_forked && getrusage(RUSAGE_CHILDREN, &rc) == 0)
            wcpu = (double)rc.ru_utime.tv_sec + rc.ru_utime.tv_usec * 1e-6 +
                   (double)rc.ru_stime.tv_sec + rc.ru_stime.tv_usec * 1e-6;
        fprintf(f, "  \"worker_cpu_ns_per_pixel\": %.2f,\n", px > 0 ? wcpu * 1e9 / px : 0.0);
        /* how many workers one coordinator core feeds: workers' CPU (else busy time) per
         * coordinator render-path CPU second */
        fprintf(f, "  \"workers_per_coordinator_core\": %.1f,\n",
                render_cpu > 0 ? (wcpu > 0 ? wcpu : busy) / render_cpu : 0.0);
    }
    fprintf(f, "  \"workers\": [");
    for (int i = 0; i < st->nworkers; i++) {
        const tf_worker_stats *w = &st->workers[i];
        fprintf(f, "%s\n    {\"id\": %lld, \"kind\": ", i ? "," : "", (long long)w->id);
        json_string(f, w->kind);
        fprintf(f, ", \"host\": ");
        json_string(f, w->host);
        fprintf(f, ", \"backend\": ");
        json_string(f, w->backend);
        fprintf(f, ", \"tasks\": %lld, \"rays\": %llu, \"busy_s\": %.3f}", (long long)w->tasks,
                (unsigned long long)w->rays, w->busy_s);
    }
    fprintf(f, "%s]", st->nworkers ? "\n  " : "");
    if (run->sequence) {
        /* one object per frame rendered by this run (wall_s: from its first task dealt to its
         * last row on disk; frames overlap, so these add up to more than wall_s; start_s and
         * done_s are those instants, in seconds since the run started) */
        fprintf(f, ",\n  \"frames\": [");
        for (int i = 0; i < st->nframes; i++) {
            const tf_frame_stats *fr = &st->frames[i];
            double wall = fr->done_ms > 0 && fr->start_ms > 0 ? (fr->done_ms - fr->start_ms) / 1e3
                                                              : 0;
            fprintf(f, "%s\n    {\"frame\": %d, \"wall_s\": %.3f, \"rays_total\": %llu, "
                    "\"rows_resumed\": %d, \"rows_rendered\": %d, \"start_s\": %.3f, "
                    "\"done_s\": %.3f}", i ? "," : "", fr->frame, wall,
                    (unsigned long long)fr->rays, fr->rows_resumed, fr->rows_rendered,
                    fr->start_ms > 0 ? fr->start_ms / 1e3 - run->start_s : 0,
                    fr->done_ms > 0 ? fr->done_ms / 1e3 - run->start_s : 0);
        }
        fprintf(f, "%s],\n  \"frames_skipped\": [", st->nframes ? "\n  " : "");
        for (int i = 0; i < run->nskipped; i++)
            fprintf(f, "%s%d", i ? ", " : "", run->frames_skipped[i]);
        fprintf(f, "]");
    }
    fprintf(f, "\n}\n");
    int bad = ferror(f);
    bad |= fclose(f) != 0;
    if (bad || rename(tmp, path)) {
        tf_seterr(err, errlen, "%s: cannot write statistics: %s", path, strerror(errno));
        remove(tmp);
        free(tmp);
        return -1;
    }
    free(tmp);
    return 0;
}
