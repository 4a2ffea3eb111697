/* snapshot.c: see snapshot.h. */
#include "coordinator/dashboard/snapshot.h"

#include <errno.h>
#include <stdlib.h>

#include "clock.h"

void tf_snapshot_free(tf_snapshot *s)
{
    if (!s)
        return;
    free(s->workers);
    free(s->tasks);
    free(s->events);
    free(s->samples);
    free(s->preview_rgba);
    free(s);
}

int tf_hub_init(tf_dash_hub *hub)
{
    hub->current = NULL;
    hub->stopping = 0;
    hub->ncmds = 0;
    hub->last_read_s = -1e9;
    atomic_init(&hub->want_full, 0);
    if (pthread_mutex_init(&hub->lock, NULL))
        return -1;
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    /* tf_realtime_in gives CLOCK_REALTIME deadlines: the default clock of a condition. */
    int rc = pthread_cond_init(&hub->changed, &ca);
    pthread_condattr_destroy(&ca);
    if (rc) {
        pthread_mutex_destroy(&hub->lock);
        return -1;
    }
    return 0;
}

void tf_hub_destroy(tf_dash_hub *hub)
{
    if (hub->current && --hub->current->refs == 0)
        tf_snapshot_free(hub->current);
    hub->current = NULL;
    pthread_cond_destroy(&hub->changed);
    pthread_mutex_destroy(&hub->lock);
}

int tf_hub_publish(tf_dash_hub *hub, tf_snapshot *snap, int block)
{
    if (block ? pthread_mutex_lock(&hub->lock) : pthread_mutex_trylock(&hub->lock))
        return 0;
    tf_snapshot *old = hub->current;
    snap->refs = 1;
    hub->current = snap;
    int free_old = old && --old->refs == 0;
    pthread_mutex_unlock(&hub->lock);
    pthread_cond_broadcast(&hub->changed);
    if (free_old)
        tf_snapshot_free(old);
    return 1;
}

int tf_hub_take_commands(tf_dash_hub *hub, tf_command *out, int max)
{
    if (pthread_mutex_trylock(&hub->lock))
        return 0;
    int n = hub->ncmds < max ? hub->ncmds : max;
    for (int i = 0; i < n; i++)
        out[i] = hub->cmds[i];
    for (int i = n; i < hub->ncmds; i++)
        hub->cmds[i - n] = hub->cmds[i];
    hub->ncmds -= n;
    pthread_mutex_unlock(&hub->lock);
    return n;
}

tf_snapshot *tf_hub_acquire(tf_dash_hub *hub)
{
    pthread_mutex_lock(&hub->lock);
    hub->last_read_s = tf_now_s();
    if (hub->current && hub->current->partial && !hub->stopping) {
        atomic_store(&hub->want_full, 1);
        struct timespec deadline = tf_realtime_in(TF_HUB_FULL_WAIT_MS);
        while (hub->current->partial && !hub->stopping &&
               pthread_cond_timedwait(&hub->changed, &hub->lock, &deadline) != ETIMEDOUT)
            ;
    }
    tf_snapshot *s = hub->current;
    if (s)
        s->refs++;
    pthread_mutex_unlock(&hub->lock);
    return s;
}

void tf_hub_release(tf_dash_hub *hub, tf_snapshot *snap)
{
    if (!snap)
        return;
    pthread_mutex_lock(&hub->lock);
    int last = --snap->refs == 0;
    pthread_mutex_unlock(&hub->lock);
    if (last)
        tf_snapshot_free(snap);
}

int tf_hub_watched(tf_dash_hub *hub, double window_s)
{
    if (atomic_exchange(&hub->want_full, 0))
        return 2;
    if (pthread_mutex_trylock(&hub->lock))
        return 1; /* a reader holds it right now */
    int recent = tf_now_s() - hub->last_read_s < window_s;
    pthread_mutex_unlock(&hub->lock);
    return recent;
}

int tf_hub_wait(tf_dash_hub *hub, uint64_t version, int timeout_ms)
{
    struct timespec deadline = tf_realtime_in(timeout_ms);
    pthread_mutex_lock(&hub->lock);
    hub->last_read_s = tf_now_s();
    int rc = 0;
    for (;;) {
        if (hub->stopping) {
            rc = -1;
            break;
        }
        if (hub->current && hub->current->version > version) {
            rc = 1;
            break;
        }
        if (pthread_cond_timedwait(&hub->changed, &hub->lock, &deadline) == ETIMEDOUT)
            break;
    }
    pthread_mutex_unlock(&hub->lock);
    return rc;
}

int tf_hub_push_command(tf_dash_hub *hub, tf_command cmd)
{
    pthread_mutex_lock(&hub->lock);
    int rc = -1;
    if (hub->ncmds < TF_HUB_COMMANDS) {
        hub->cmds[hub->ncmds++] = cmd;
        rc = 0;
    }
    pthread_mutex_unlock(&hub->lock);
    return rc;
}

void tf_hub_stop(tf_dash_hub *hub)
{
    pthread_mutex_lock(&hub->lock);
    hub->stopping = 1;
    pthread_mutex_unlock(&hub->lock);
    pthread_cond_broadcast(&hub->changed);
}

const char *tf_run_state_name(tf_run_state s)
{
    static const char *const names[] = {"starting", "rendering", "finished", "failed",
                                        "interrupted"};
    return (unsigned)s < sizeof names / sizeof names[0] ? names[s] : "?";
}

const char *tf_worker_state_name(tf_worker_state s)
{
    static const char *const names[] = {"idle", "busy", "left", "dropped"};
    return (unsigned)s < sizeof names / sizeof names[0] ? names[s] : "?";
}
