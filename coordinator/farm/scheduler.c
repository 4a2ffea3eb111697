/* scheduler.c: see scheduler.h. */
#include "coordinator/farm/scheduler.h"

#include <string.h>

static int list_has(const char *list, const char *item, size_t n)
{
    for (const char *p = list; *p;) {
        const char *comma = strchr(p, ',');
        size_t len = comma ? (size_t)(comma - p) : strlen(p);
        if (len == n && !strncmp(p, item, n))
            return 1;
        p += len + (comma ? 1 : 0);
    }
    return 0;
}

int tf_sched_tags_cover(const char *have, const char *need)
{
    for (const char *p = need; *p;) {
        const char *comma = strchr(p, ',');
        size_t len = comma ? (size_t)(comma - p) : strlen(p);
        if (len && !list_has(have, p, len))
            return 0;
        p += len + (comma ? 1 : 0);
    }
    return 1;
}

static const char *pool_of(const char *p)
{
    return p && *p ? p : "default";
}

int tf_sched_servable(const tf_sched_job *j, const tf_sched_worker *w)
{
    return !strcmp(j->job->state, "queued") && j->after_state == 0 && !j->closing &&
           !strcmp(pool_of(j->job->pool), pool_of(w->pool)) &&
           tf_sched_tags_cover(w->tags ? w->tags : "", j->job->tags) &&
           !(w->barred && w->barred(w->ctx, j->job->id));
}

static int holds_terrain(const tf_sched_worker *w, const char *terrain)
{
    for (int i = 0; i < w->nterrains; i++)
        if (!strcmp(w->terrains[i], terrain))
            return 1;
    return 0;
}

/* Fair share with affinity: the workers a job has, plus one if w must build its terrain. */
static int share_cost(const tf_sched_job *j, const tf_sched_worker *w)
{
    return j->workers + (holds_terrain(w, j->job->terrain) ? 0 : 1);
}

/* 1 when a is a better choice for w than b. */
static int better(const tf_sched_job *a, const tf_sched_job *b, const tf_sched_worker *w)
{
    if (a->job->priority != b->job->priority)
        return a->job->priority > b->job->priority;
    int ca = share_cost(a, w), cb = share_cost(b, w);
    if (ca != cb)
        return ca < cb;
    return a->job->id < b->job->id;
}

int tf_sched_pick(const tf_sched_job *jobs, int n, const tf_sched_worker *w)
{
    int best = -1;
    for (int i = 0; i < n; i++)
        if (tf_sched_servable(&jobs[i], w) && (best < 0 || better(&jobs[i], &jobs[best], w)))
            best = i;
    return best;
}

int tf_sched_should_leave(const tf_sched_job *jobs, int n, int current,
                          const tf_sched_worker *w)
{
    if (current < 0 || current >= n || !tf_sched_servable(&jobs[current], w))
        return 1;
    for (int i = 0; i < n; i++)
        if (i != current && tf_sched_servable(&jobs[i], w) &&
            jobs[i].job->priority > jobs[current].job->priority)
            return 1;
    return 0;
}
