/* rowwriter.c: see rowwriter.h.  A ring of `depth` chunk buffers between one producer (the
 * supervisor) and one consumer (the writer thread), under one mutex with two condition
 * variables.  INVARIANTS (checked by queue_ok() under the mutex in debug builds, `make asan`):
 *   R1. 0 <= head < depth and 0 <= count <= depth;
 *   R2. slots [head, head + count) modulo depth hold the queued chunks in row order, each of
 *       1..chunk_rows rows, and only the producer touches the slot at head + count;
 *   R3. rows_written only grows. */
#include "coordinator/rowwriter.h"
#include "clock.h"

#include "image/png_write.h"
#include "image/preview.h"

#include <assert.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "log.h"

struct tf_rowwriter {
    tf_exr_writer *w;
    int width, chunk_rows, depth, fsync_ms;
    tf_pixel **slot;
    int *slot_rows;
    int head, count;
    int stop;          /* 1: finish after the queue drains */
    int failed;
    char error[512];
    int rows_written;
    tf_png_writer *png;    /* preview, or NULL */
    uint8_t *rgb;          /* one preview row */
    pthread_mutex_t mu;
    pthread_cond_t nonempty, nonfull;
    pthread_t thread;
};

/* Tone-map rows into the preview; a preview failure only costs the preview. */
static void preview_rows(tf_rowwriter *rw, const tf_pixel *px, int nrows)
{
    char err[512];
    for (int y = 0; rw->png && y < nrows; y++) {
        const tf_pixel *row = px + (size_t)y * (size_t)rw->width;
        for (int x = 0; x < rw->width; x++) {
            rw->rgb[3 * x + 0] = tf_srgb8(row[x].r);
            rw->rgb[3 * x + 1] = tf_srgb8(row[x].g);
            rw->rgb[3 * x + 2] = tf_srgb8(row[x].b);
        }
        if (tf_png_write_row(rw->png, rw->rgb, err, sizeof err)) {
            fprintf(stderr, "terrafarm: warning: preview: %s\n", err);
            tf_png_abort(rw->png);
            rw->png = NULL;
        }
    }
}

#ifndef NDEBUG
/* R1 and R2 (call with rw->mu held). */
static int queue_ok(const tf_rowwriter *rw)
{
    if (rw->head < 0 || rw->head >= rw->depth || rw->count < 0 || rw->count > rw->depth)
        return 0;
    for (int i = 0; i < rw->count; i++) {
        int rows = rw->slot_rows[(rw->head + i) % rw->depth];
        if (rows < 1 || rows > rw->chunk_rows)
            return 0;
    }
    return 1;
}
#endif

static void *writer_main(void *arg)
{
    tf_rowwriter *rw = arg;
    double last_sync = tf_now_msf();
    int dirty = 0;
    char err[512];
    pthread_mutex_lock(&rw->mu);
    for (;;) {
        while (rw->count == 0 && !rw->stop) {
            if (dirty) {
                /* Idle with unsynced rows: wait at most until the next sync is due. */
                double due = last_sync + rw->fsync_ms;
                double wait = due - tf_now_msf();
                if (wait <= 0)
                    break;
                struct timespec ts = tf_realtime_in(wait);
                pthread_cond_timedwait(&rw->nonempty, &rw->mu, &ts);
            } else {
                pthread_cond_wait(&rw->nonempty, &rw->mu);
            }
        }
        assert(queue_ok(rw));
        if (rw->count == 0 && rw->stop)
            break;
        int have = rw->count > 0 && !rw->failed;
        int idx = rw->head, nrows = have ? rw->slot_rows[idx] : 0;
        pthread_mutex_unlock(&rw->mu);

        int rc = 0;
        if (have) {
            rc = tf_exr_write_rows(rw->w, nrows, rw->slot[idx], err, sizeof err);
            dirty = 1;
            if (rc == 0)
                preview_rows(rw, rw->slot[idx], nrows);
        }
        if (rc == 0 && dirty && tf_now_msf() - last_sync >= rw->fsync_ms) {
            rc = tf_exr_sync(rw->w, err, sizeof err);
            last_sync = tf_now_msf();
            dirty = 0;
        }

        pthread_mutex_lock(&rw->mu);
        if (rc != 0 && !rw->failed) {
            rw->failed = 1;
            snprintf(rw->error, sizeof rw->error, "%s", err);
        }
        if (have) {
            if (rc == 0)
                rw->rows_written += nrows;
            rw->head = (rw->head + 1) % rw->depth;
            rw->count--;
            pthread_cond_signal(&rw->nonfull);
        } else if (rw->failed && rw->count > 0) {
            /* after a failure, drop the queue: nothing more may be written past the gap */
            rw->head = (rw->head + rw->count) % rw->depth;
            rw->count = 0;
            pthread_cond_signal(&rw->nonfull);
        }
    }
    pthread_mutex_unlock(&rw->mu);
    return NULL;
}

static void free_rowwriter(tf_rowwriter *rw)
{
    if (!rw)
        return;
    if (rw->slot)
        for (int i = 0; i < rw->depth; i++)
            free(rw->slot[i]);
    free(rw->slot);
    free(rw->slot_rows);
    if (rw->png)
        tf_png_abort(rw->png);
    free(rw->rgb);
    free(rw);
}

typedef struct prefill {
    tf_rowwriter *rw;
    int rows;
} prefill;

static int prefill_row(void *user, int y, const tf_pixel *row)
{
    prefill *p = user;
    if (y >= p->rows)
        return 1; /* stop: the rest will come from the render */
    preview_rows(p->rw, row, 1);
    return 0;
}

/* Open the preview and feed it the rows already in the file being resumed. */
static void start_preview(tf_rowwriter *rw, int height, const char *png_path, const char *existing)
{
    char err[512];
    rw->rgb = malloc((size_t)rw->width * 3);
    rw->png = rw->rgb ? tf_png_create(png_path, rw->width, height, 8, 3, err, sizeof err) : NULL;
    if (!rw->png) {
        fprintf(stderr, "terrafarm: warning: no preview: %s\n", rw->rgb ? err : "out of memory");
        return;
    }
    if (rw->rows_written > 0 && existing) {
        prefill p = {rw, rw->rows_written};
        tf_exr_meta meta;
        int valid = 0;
        tf_exr_read_rows(existing, &meta, &valid, prefill_row, &p, err, sizeof err);
        if (valid < p.rows && rw->png) {
            fprintf(stderr, "terrafarm: warning: no preview: cannot read back %s\n", existing);
            tf_png_abort(rw->png);
            rw->png = NULL;
        }
    }
}

tf_rowwriter *tf_rowwriter_start(tf_exr_writer *w, int width, int height, int chunk_rows,
                                 int depth, int fsync_interval_ms, const char *preview_png,
                                 const char *existing, char *err, size_t errlen)
{
    tf_rowwriter *rw = calloc(1, sizeof *rw);
    if (!rw)
        goto oom;
    rw->w = w;
    rw->width = width;
    rw->chunk_rows = chunk_rows;
    rw->depth = depth < 1 ? 1 : depth;
    rw->fsync_ms = fsync_interval_ms > 0 ? fsync_interval_ms : 1000;
    rw->rows_written = tf_exr_next_row(w);
    rw->slot = calloc((size_t)rw->depth, sizeof *rw->slot);
    rw->slot_rows = calloc((size_t)rw->depth, sizeof *rw->slot_rows);
    if (!rw->slot || !rw->slot_rows)
        goto oom;
    for (int i = 0; i < rw->depth; i++) {
        rw->slot[i] = malloc((size_t)width * (size_t)chunk_rows * sizeof(tf_pixel));
        if (!rw->slot[i])
            goto oom;
    }
    if (preview_png)
        start_preview(rw, height, preview_png, existing);
    pthread_mutex_init(&rw->mu, NULL);
    pthread_cond_init(&rw->nonempty, NULL);
    pthread_cond_init(&rw->nonfull, NULL);
    if (pthread_create(&rw->thread, NULL, writer_main, rw)) {
        tf_seterr(err, errlen, "cannot start the writer thread");
        free_rowwriter(rw);
        return NULL;
    }
    return rw;
oom:
    tf_seterr(err, errlen, "out of memory for the row writer");
    free_rowwriter(rw);
    return NULL;
}

int tf_rowwriter_put(tf_rowwriter *rw, const void *rows, int nrows)
{
    pthread_mutex_lock(&rw->mu);
    while (rw->count == rw->depth && !rw->failed)
        pthread_cond_wait(&rw->nonfull, &rw->mu);
    if (rw->failed) {
        pthread_mutex_unlock(&rw->mu);
        return -1;
    }
    int idx = (rw->head + rw->count) % rw->depth;
    pthread_mutex_unlock(&rw->mu);
    /* The slot is ours until count covers it: the thread never reads past head + count. */
    memcpy(rw->slot[idx], rows, (size_t)rw->width * (size_t)nrows * sizeof(tf_pixel));
    pthread_mutex_lock(&rw->mu);
    rw->slot_rows[idx] = nrows;
    rw->count++;
    assert(queue_ok(rw));
    pthread_cond_signal(&rw->nonempty);
    pthread_mutex_unlock(&rw->mu);
    return 0;
}

int tf_rowwriter_rows_written(tf_rowwriter *rw)
{
    pthread_mutex_lock(&rw->mu);
    int n = rw->rows_written;
    pthread_mutex_unlock(&rw->mu);
    return n;
}

int tf_rowwriter_error(tf_rowwriter *rw, char *buf, size_t len)
{
    pthread_mutex_lock(&rw->mu);
    int failed = rw->failed;
    if (failed)
        snprintf(buf, len, "%s", rw->error);
    pthread_mutex_unlock(&rw->mu);
    return failed;
}

/* Drain the queue and join the thread. */
static void stop_thread(tf_rowwriter *rw)
{
    pthread_mutex_lock(&rw->mu);
    rw->stop = 1;
    pthread_cond_signal(&rw->nonempty);
    pthread_mutex_unlock(&rw->mu);
    pthread_join(rw->thread, NULL);
    pthread_mutex_destroy(&rw->mu);
    pthread_cond_destroy(&rw->nonempty);
    pthread_cond_destroy(&rw->nonfull);
}

int tf_rowwriter_finish(tf_rowwriter *rw, char *err, size_t errlen)
{
    stop_thread(rw);
    int rc = 0;
    if (rw->failed) {
        tf_seterr(err, errlen, "%s", rw->error);
        tf_exr_abandon(rw->w);
        rc = -1;
    } else if (tf_exr_finish(rw->w, err, errlen)) {
        rc = -1;
    } else if (rw->png) {
        char perr[512];
        if (tf_png_finish(rw->png, perr, sizeof perr))
            fprintf(stderr, "terrafarm: warning: preview: %s\n", perr);
        rw->png = NULL;
    }
    free_rowwriter(rw);
    return rc;
}

void tf_rowwriter_abandon(tf_rowwriter *rw)
{
    stop_thread(rw);
    char err[512];
    if (!rw->failed)
        tf_exr_sync(rw->w, err, sizeof err);
    tf_exr_abandon(rw->w);
    free_rowwriter(rw);
}
