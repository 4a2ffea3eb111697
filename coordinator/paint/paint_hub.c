/* paint_hub.c: see paint_hub.h. */
#include "coordinator/paint/paint_hub.h"

#include <errno.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"

#define MAX_COMMANDS 64

struct tf_paint_hub {
    pthread_mutex_t lock;
    pthread_cond_t more;    /* the log grew, the view changed or the hub closed */
    int closed;
    int64_t gen;
    tf_paint_bytes log;     /* the current view's display messages */
    char *scene_text;
    tf_paint_status status;
    tf_paint_cmd queue[MAX_COMMANDS];
    int head, count;
    int readers;            /* pages waiting on the log now */
    int64_t last_read_ms;   /* when a page last stopped waiting (or the hub began) */
};

tf_paint_hub *tf_paint_hub_new(int width, int height)
{
    tf_paint_hub *h = calloc(1, sizeof *h);
    if (!h)
        return NULL;
    pthread_mutex_init(&h->lock, NULL);
    pthread_cond_init(&h->more, NULL);
    h->status.width = width;
    h->status.height = height;
    h->status.coarse_s = h->status.painted_s = -1;
    h->last_read_ms = tf_now_ms();
    return h;
}

void tf_paint_hub_close(tf_paint_hub *h)
{
    pthread_mutex_lock(&h->lock);
    h->closed = 1;
    pthread_cond_broadcast(&h->more);
    pthread_mutex_unlock(&h->lock);
}

void tf_paint_hub_free(tf_paint_hub *h)
{
    if (!h)
        return;
    tf_paint_bytes_free(&h->log);
    free(h->scene_text);
    for (int k = 0; k < h->count; k++)
        free(h->queue[(h->head + k) % MAX_COMMANDS].text);
    pthread_cond_destroy(&h->more);
    pthread_mutex_destroy(&h->lock);
    free(h);
}

int tf_paint_hub_begin_view(tf_paint_hub *h, int64_t gen, const char *scene_text)
{
    char *text = strdup(scene_text);
    if (!text)
        return -1;
    pthread_mutex_lock(&h->lock);
    h->gen = gen;
    h->log.len = 0;
    free(h->scene_text);
    h->scene_text = text;
    pthread_cond_broadcast(&h->more);
    pthread_mutex_unlock(&h->lock);
    return 0;
}

int tf_paint_hub_publish(tf_paint_hub *h, const uint8_t *msgs, size_t len)
{
    pthread_mutex_lock(&h->lock);
    int rc = tf_paint_bytes_add(&h->log, msgs, len);
    pthread_cond_broadcast(&h->more);
    pthread_mutex_unlock(&h->lock);
    return rc;
}

void tf_paint_hub_set_status(tf_paint_hub *h, const tf_paint_status *s)
{
    pthread_mutex_lock(&h->lock);
    h->status = *s;
    pthread_mutex_unlock(&h->lock);
}

int tf_paint_hub_next_command(tf_paint_hub *h, tf_paint_cmd *cmd)
{
    pthread_mutex_lock(&h->lock);
    int got = h->count > 0;
    if (got) {
        *cmd = h->queue[h->head];
        h->head = (h->head + 1) % MAX_COMMANDS;
        h->count--;
    }
    pthread_mutex_unlock(&h->lock);
    return got;
}

int tf_paint_hub_command(tf_paint_hub *h, tf_paint_cmd *cmd)
{
    pthread_mutex_lock(&h->lock);
    int rc = h->count < MAX_COMMANDS ? 0 : -1;
    if (rc == 0) {
        h->queue[(h->head + h->count) % MAX_COMMANDS] = *cmd;
        h->count++;
    } else {
        free(cmd->text);
    }
    cmd->text = NULL;
    pthread_mutex_unlock(&h->lock);
    return rc;
}

void tf_paint_hub_status(tf_paint_hub *h, tf_paint_status *s)
{
    pthread_mutex_lock(&h->lock);
    *s = h->status;
    s->log_bytes = (int64_t)h->log.len;
    s->watchers = h->readers;
    s->unwatched_s = h->readers ? 0 : (double)(tf_now_ms() - h->last_read_ms) / 1000.0;
    pthread_mutex_unlock(&h->lock);
}

char *tf_paint_hub_scene_text(tf_paint_hub *h)
{
    pthread_mutex_lock(&h->lock);
    char *text = h->scene_text ? strdup(h->scene_text) : NULL;
    pthread_mutex_unlock(&h->lock);
    return text;
}

int tf_paint_hub_read(tf_paint_hub *h, int64_t gen, size_t from, int wait_ms, uint8_t **out,
                      size_t *len, int64_t *now_gen, size_t *end)
{
    struct timespec deadline = tf_realtime_in(wait_ms);
    pthread_mutex_lock(&h->lock);
    h->readers++;
    while (!h->closed && h->gen == gen && h->log.len <= from)
        if (pthread_cond_timedwait(&h->more, &h->lock, &deadline) == ETIMEDOUT)
            break;
    h->readers--;
    h->last_read_ms = tf_now_ms();
    size_t start = h->gen == gen && from <= h->log.len ? from : 0;
    *len = h->log.len - start;
    *out = malloc(*len + 1);
    if (*out && *len)
        memcpy(*out, h->log.p + start, *len);
    *now_gen = h->gen;
    *end = h->log.len;
    pthread_mutex_unlock(&h->lock);
    return *out ? 0 : -1;
}
