/* events.c: see events.h. */
#include "coordinator/render/events.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "clock.h"

struct tf_events {
    tf_event ring[TF_EVENTS_MAX];
    uint64_t next_seq; /* seq of the next event; ring[(seq - 1) % MAX] holds event seq */
    double t0;         /* monotonic seconds at creation */
};

tf_events *tf_events_new(void)
{
    tf_events *ev = calloc(1, sizeof *ev);
    if (ev) {
        ev->next_seq = 1;
        ev->t0 = tf_now_s();
    }
    return ev;
}

void tf_events_free(tf_events *ev) { free(ev); }

void tf_events_add(tf_events *ev, tf_event_kind kind, int64_t worker, int64_t task,
                   const char *fmt, ...)
{
    if (!ev)
        return;
    tf_event *e = &ev->ring[(ev->next_seq - 1) % TF_EVENTS_MAX];
    struct timespec now;
    clock_gettime(CLOCK_REALTIME, &now);
    e->seq = ev->next_seq++;
    e->unix_s = (double)now.tv_sec + now.tv_nsec * 1e-9;
    e->elapsed_s = tf_now_s() - ev->t0;
    e->kind = kind;
    e->worker = worker;
    e->task = task;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(e->text, sizeof e->text, fmt, ap);
    va_end(ap);
}

uint64_t tf_events_last_seq(const tf_events *ev) { return ev ? ev->next_seq - 1 : 0; }

int tf_events_since(const tf_events *ev, uint64_t after, tf_event *out, int max)
{
    if (!ev || max <= 0)
        return 0;
    uint64_t last = ev->next_seq - 1;
    uint64_t first = after + 1;
    uint64_t oldest_kept = last >= TF_EVENTS_MAX ? last - TF_EVENTS_MAX + 1 : 1;
    if (first < oldest_kept)
        first = oldest_kept;
    if (last >= first && last - first + 1 > (uint64_t)max)
        first = last - (uint64_t)max + 1;
    int n = 0;
    for (uint64_t s = first; s <= last; s++)
        out[n++] = ev->ring[(s - 1) % TF_EVENTS_MAX];
    return n;
}

const char *tf_event_kind_name(tf_event_kind kind)
{
    static const char *const names[] = {"join", "leave", "redeal", "failure",
                                        "exclusion", "control", "end"};
    return (unsigned)kind < sizeof names / sizeof names[0] ? names[kind] : "?";
}
