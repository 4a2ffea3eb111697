/* paint_hub.h: the one place Raypaint's event loop (paint.c) and its HTTP threads
 * (paint_http.c) meet, under one lock.  The loop publishes: the display messages of the view
 * being painted (paint_raster.h), appended in order to that view's log; its status; the scene
 * text of the view.  The HTTP side reads copies of those, waiting (a long poll) for messages
 * past what a page has, and queues commands (a new view, an area of interest, pause) that the
 * loop takes between iterations.  Neither side ever holds the lock while doing work. */
#ifndef TF_PAINT_HUB_H
#define TF_PAINT_HUB_H

#include <stddef.h>
#include <stdint.h>

#include "coordinator/paint/painttree.h"
#include "image/pixel.h"

/* What a page may edit of a view (scene.h's camera, sun and mist). */
typedef struct tf_paint_view_values {
    double position[3], look_at[3], up[3], fov;
    double sun_azimuth, sun_elevation;
    int mist_enabled;
    double mist_density, mist_falloff;
} tf_paint_view_values;

typedef struct tf_paint_status {
    int64_t gen;                /* the view being painted (1, 2, ...) */
    int width, height;
    tf_paint_view_values view;
    tf_paint_counts counts;
    int workers, paused, outstanding; /* outstanding: tasks dealt and not yet answered */
    int64_t log_bytes;          /* the view's display messages so far (filled by the hub) */
    int64_t results, stale, refused;  /* results used; dropped as of an old view; refused */
    double view_age_s;          /* since this view began */
    double coarse_s, painted_s; /* from the view's start to its first complete coarse image,
                                   to every pixel exact; < 0: not yet */
    int output_written;         /* -o: the painted image of this view is on disk */
    char output[256];           /* -o, or empty */
    int watchers;               /* pages waiting for the view's messages now (filled by the hub) */
    double unwatched_s;         /* since a page last read them (0 while one waits; filled by
                                   the hub): a standing farm closes a paint nobody watches */
} tf_paint_status;

enum { TF_PAINT_CMD_VIEW = 1, TF_PAINT_CMD_INTEREST, TF_PAINT_CMD_PAUSE, TF_PAINT_CMD_RESUME };

typedef struct tf_paint_cmd {
    int kind;
    char *text;        /* VIEW: the new view's scene text (the hub owns it while queued) */
    tf_rect area;      /* INTEREST: w == 0 clears it */
} tf_paint_cmd;

typedef struct tf_paint_hub tf_paint_hub;

tf_paint_hub *tf_paint_hub_new(int width, int height);
/* Wakes every waiting reader first. */
void tf_paint_hub_free(tf_paint_hub *h);
/* Shutting down: readers stop waiting. */
void tf_paint_hub_close(tf_paint_hub *h);

/* ---- the event loop ---- */
/* A new view: its log starts empty, with its scene text.  0 or -1 (out of memory). */
int tf_paint_hub_begin_view(tf_paint_hub *h, int64_t gen, const char *scene_text);
/* Append messages of the current view and wake the readers.  0 or -1. */
int tf_paint_hub_publish(tf_paint_hub *h, const uint8_t *msgs, size_t len);
void tf_paint_hub_set_status(tf_paint_hub *h, const tf_paint_status *s);
/* The oldest queued command (1; the caller frees cmd->text), or 0. */
int tf_paint_hub_next_command(tf_paint_hub *h, tf_paint_cmd *cmd);

/* ---- the HTTP threads ---- */
/* Queue a command (the hub takes cmd->text).  0, or -1 when the queue is full. */
int tf_paint_hub_command(tf_paint_hub *h, tf_paint_cmd *cmd);
void tf_paint_hub_status(tf_paint_hub *h, tf_paint_status *s);
/* The current view's scene text (malloc'd), or NULL. */
char *tf_paint_hub_scene_text(tf_paint_hub *h);
/* The current view's messages from byte `from`: waits up to wait_ms while there are none
 * (gen is that of the page: another view answers at once).  *out is malloc'd (*len bytes,
 * possibly 0); *now_gen and *end say which view and where the page is now.  0 or -1. */
int tf_paint_hub_read(tf_paint_hub *h, int64_t gen, size_t from, int wait_ms, uint8_t **out,
                      size_t *len, int64_t *now_gen, size_t *end);

#endif
