/* events.h: the farm's event log, a bounded ring of what happened to the render and when
 * (workers joining and leaving, tasks re-dealt, failures, exclusions, controls used from the
 * dashboard).  Fed by a few calls from the supervisor's hooks and the dashboard, in the
 * event-loop thread only: no locks here.  The dashboard (dashboard.h) copies the newest events
 * into each snapshot it publishes for the HTTP threads (/api/events, /api/events/stream).
 *
 * Every event has a sequence number that only grows, so a reader that remembers the last one
 * it saw can ask for what came after; the ring keeps the newest TF_EVENTS_MAX. */
#ifndef TF_EVENTS_H
#define TF_EVENTS_H

#include <stdint.h>

#define TF_EVENTS_MAX 256
#define TF_EVENT_TEXT 160

typedef enum tf_event_kind {
    TF_EV_JOIN,       /* a worker said hello */
    TF_EV_LEAVE,      /* a worker's connection closed */
    TF_EV_REDEAL,     /* a lost task was dealt again */
    TF_EV_FAILURE,    /* a worker failed a task (reported, bad result, or died holding it) */
    TF_EV_EXCLUSION,  /* a worker is no longer dealt a task it keeps failing */
    TF_EV_CONTROL,    /* stop / drop / watermark from the dashboard */
    TF_EV_END,        /* the render finished, failed or was stopped */
} tf_event_kind;

typedef struct tf_event {
    uint64_t seq;            /* 1, 2, 3, ...  */
    double unix_s;           /* wall-clock time (seconds since the epoch) */
    double elapsed_s;        /* since the log was created (the render's start) */
    tf_event_kind kind;
    int64_t worker;          /* -1: none */
    int64_t task;            /* -1: none */
    char text[TF_EVENT_TEXT];
} tf_event;

typedef struct tf_events tf_events;

tf_events *tf_events_new(void);
void tf_events_free(tf_events *ev);
/* Record an event (ev may be NULL: then nothing happens, so callers need not check). */
void tf_events_add(tf_events *ev, tf_event_kind kind, int64_t worker, int64_t task,
                   const char *fmt, ...) __attribute__((format(printf, 5, 6)));
/* Sequence number of the newest event, 0 if none. */
uint64_t tf_events_last_seq(const tf_events *ev);
/* Copy the events with seq > after, oldest first, at most max of the newest; returns the count. */
int tf_events_since(const tf_events *ev, uint64_t after, tf_event *out, int max);
/* "join", "leave", "redeal", ... */
const char *tf_event_kind_name(tf_event_kind kind);

#endif
