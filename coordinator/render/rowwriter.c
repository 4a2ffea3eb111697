/* rowwriter.c: see rowwriter.h.  A ring of `depth` result tuples between one producer (the
 * supervisor) and one consumer (the writer thread), under one mutex with two condition
 * variables.  INVARIANTS (checked clause by clause by assert_queue() under the mutex, after
 * every put and before every take, in debug builds, `make asan`):
 *   R1. 0 <= head < depth and 0 <= count <= depth;
 *   R2. slots [head, head + count) modulo depth hold the queued results in file order (their
 *       task ids increase), each a result tuple (11 fields), and every other slot is empty:
 *       only the producer touches the slot at head + count, and the thread takes a result out
 *       of the ring, under the mutex, before writing it;
 *   R3. rows_written only grows. */
#include "coordinator/render/rowwriter.h"
#include "clock.h"

#include "farmproto.h"
#include "image/exrencode.h"
#include "image/png_write.h"

#include <assert.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "log.h"

#define HELD_MAX 32 /* results a write may gather (the sink's run: SINK_IOV pieces) */

struct tf_rowwriter {
    tf_exr_writer *w;
    tf_exr_layout layout;
    int depth, fsync_ms, preview_ms;
    int batch;         /* results queued before the producer wakes the thread */
    tf_tuple *slot;
    int head, count;
    double queued_ms;  /* when the queue last became non-empty (the producer's clock) */
    int untimed;       /* the thread waits with no timer: only a signal wakes it */
    int stop;          /* 1: finish after the queue drains */
    int failed;
    char error[512];
    int rows_written;
#ifndef NDEBUG
    int rows_checked;  /* rows_written when the invariants were last checked (R3) */
#endif
    /* the progress preview (writer thread only) */
    char *preview_path;
    tf_preview_grid grid;
    uint8_t *preview;      /* grid.pw * grid.ph * 3, black where nothing is rendered yet */
    int preview_dirty;
    double preview_last;
    double preview_cost_ms;   /* how long the last rewrite took */
    /* written results whose chunks the sink still references (writer thread only): freed at
     * the flush, so that one pwritev carries many results' chunks */
    tf_tuple held[HELD_MAX];
    int nheld;
    pthread_mutex_t mu;
    pthread_cond_t nonempty, nonfull;
    pthread_t thread;
};

/* ---- the preview ---------------------------------------------------------------------------- */

/* Paste the preview share of rectangle r (tf_preview_span, row-major RGB) into the preview. */
static void paste_share(tf_rowwriter *rw, tf_rect r, const uint8_t *share, size_t len)
{
    if (!rw->preview)
        return; /* no preview (its grid is not set up either) */
    int i0, i1, j0, j1;
    tf_preview_span(&rw->grid, rw->layout.width, rw->layout.height, r, &i0, &i1, &j0, &j1);
    size_t line = (size_t)(i1 - i0) * 3;
    if (len != line * (size_t)(j1 - j0))
        return; /* checked by the supervisor; never trusted further */
    for (int j = j0; j < j1; j++)
        memcpy(rw->preview + ((size_t)j * (size_t)rw->grid.pw + (size_t)i0) * 3,
               share + (size_t)(j - j0) * line, line);
    rw->preview_dirty = 1;
}

/* Rewrite the PNG (tf_png_* writes PATH.tmp and renames it into place).  A preview failure
 * only costs the preview: while rendering it is retried at the next interval, silently; a
 * failure of the final one (`last`) is one warning. */
static void write_preview(tf_rowwriter *rw, int last)
{
    char err[512];
    if (!rw->preview || !rw->preview_path)
        return;
    double t0 = tf_now_msf();
    tf_png_writer *png = tf_png_create(rw->preview_path, rw->grid.pw, rw->grid.ph, 8, 3, err,
                                       sizeof err);
    /* Stored, the final one too: a memcpy and two checksums per preview pixel.  Deflating
     * it, even at zlib level 1, cost 15-18 ms of a 1920x640 render's ~70 ms of coordinator CPU
     * (a quarter: bench/README.md, session 5) for a file 2.3x smaller; any PNG tool
     * recompresses it if its size matters. */
    if (png)
        tf_png_fast(png, 0);
    for (int j = 0; png && j < rw->grid.ph; j++)
        if (tf_png_write_row(png, rw->preview + (size_t)j * (size_t)rw->grid.pw * 3, err,
                             sizeof err)) {
            tf_png_abort(png);
            png = NULL;
        }
    if (!png || tf_png_finish(png, err, sizeof err)) {
        if (last)
            tf_warn("preview: %s", err);
        rw->preview_last = tf_now_msf();
        return;
    }
    rw->preview_dirty = 0;
    rw->preview_last = tf_now_msf();
    rw->preview_cost_ms = rw->preview_last - t0;
}

typedef struct prefill {
    tf_rowwriter *rw;
    int64_t chunks, seen;
    uint8_t *buf;
    size_t cap;
} prefill;

static int prefill_chunk(void *user, tf_rect rect, const tf_pixel *px)
{
    prefill *p = user;
    if (p->seen++ >= p->chunks)
        return 1; /* stop: the rest will come from the render */
    size_t len = 0;
    if (tf_preview_share(&p->rw->grid, p->rw->layout.width, p->rw->layout.height, rect, px,
                         &p->buf, &p->cap, &len))
        return 1;
    paste_share(p->rw, rect, p->buf, len);
    return 0;
}

/* Open the preview and fill it from the chunks already in the file being resumed (this decodes
 * them: a resume's one-time cost, not the render path's). */
static void start_preview(tf_rowwriter *rw, const char *png_path, const char *existing)
{
    rw->grid = tf_preview_grid_for(rw->layout.width, rw->layout.height);
    rw->preview = calloc((size_t)rw->grid.pw * (size_t)rw->grid.ph, 3);
    rw->preview_path = strdup(png_path);
    if (!rw->preview || !rw->preview_path) {
        tf_warn("no preview: out of memory");
        free(rw->preview);
        rw->preview = NULL;
        return;
    }
    int64_t on_disk = tf_exr_next_chunk(rw->w);
    if (on_disk > 0 && existing) {
        prefill p = {rw, on_disk, 0, NULL, 0};
        tf_exr_meta meta;
        int64_t valid = 0;
        char err[512];
        tf_exr_read_chunks(existing, &meta, &valid, prefill_chunk, &p, err, sizeof err);
        free(p.buf);
        if (p.seen < on_disk)
            tf_warn("preview: cannot read back %s; it shows only this run's part", existing);
    }
    rw->preview_dirty = 1;
}

/* ---- the thread ----------------------------------------------------------------------------- */

#ifndef NDEBUG
/* The task id of a queued result (R2 checks their order). */
static int64_t queued_id(const tf_rowwriter *rw, int i)
{
    int64_t id = INT64_MIN;
    tf_tuple_get_int(&rw->slot[(rw->head + i) % rw->depth], 1, &id);
    return id;
}

/* R1-R3, one assert a clause (as SQLite's assert_pager_state; call with rw->mu held).
 * Returns 1, so that a call sits inside assert() and vanishes with NDEBUG. */
static int assert_queue(tf_rowwriter *rw)
{
    assert(rw->head >= 0 && rw->head < rw->depth && "R1: 0 <= head < depth");
    assert(rw->count >= 0 && rw->count <= rw->depth && "R1: 0 <= count <= depth");
    for (int i = 0; i < rw->depth; i++) {
        int queued = (i - rw->head + rw->depth) % rw->depth < rw->count;
        const tf_tuple *t = &rw->slot[i];
        assert((!queued || t->nfields == TF_RESULT_FIELDS) &&
               "R2: every queued slot holds a result tuple");
        assert((queued || t->nfields == 0) && "R2: every slot outside the queue is empty");
    }
    for (int i = 1; i < rw->count; i++)
        assert(queued_id(rw, i - 1) < queued_id(rw, i) &&
               "R2: the queued results are in file order (increasing task ids)");
    assert(rw->rows_written >= rw->rows_checked && "R3: rows_written only grows");
    rw->rows_checked = rw->rows_written;
    return 1;
}
#endif

/* Write one result's chunks, in index order, and paste its preview share. */
static int write_result(tf_rowwriter *rw, const tf_tuple *t, char *err, size_t errlen)
{
    tf_result_msg m;
    if (tf_result_unpack(t, &m))
        return tf_seterr(err, errlen, "internal error: a queued result does not unpack");
    size_t off = 0;
    tf_rect first = {0, 0, 0, 0}, last = {0, 0, 0, 0};
    for (size_t i = 0; i < m.nchunks; i++) {
        tf_chunk_rec c;
        tf_chunk_rec_get(m.index + i * TF_CHUNK_RECORD_BYTES, &c);
        /* The supervisor checked the index; a forked worker's chunks may lie in memory it
         * shares (linda/outbox.h), so the bytes taken stay inside the blob whatever it holds. */
        if (c.packed < 0 || (uint64_t)c.packed > m.chunks_len - off)
            return tf_seterr(err, errlen, "internal error: a queued result's chunks are short");
        int64_t index = tf_layout_chunk_index(&rw->layout, c.cx, c.cy);
        tf_chunk_ref ref = tf_layout_chunk(&rw->layout, index < 0 ? 0 : index);
        if (i == 0)
            first = ref.rect;
        last = ref.rect;
        if (tf_exr_write_chunk(rw->w, c.cx, c.cy, m.chunks + off, (size_t)c.packed, err,
                               errlen))
            return -1;
        off += (size_t)c.packed;
    }
    /* the task's rectangle: its chunks' union (one tile, or full rows) */
    tf_rect r = {first.x, first.y, last.x + last.w - first.x, last.y + last.h - first.y};
    if (m.nchunks > 0)
        paste_share(rw, r, m.preview, m.preview_len);
    return 0;
}

/* When the sleeping thread has something to do by itself: the next fsync of written chunks, the
 * next preview, or the write of results queued for half an fsync interval (fewer than a batch:
 * the producer woke nobody).  1e300: nothing. */
static double next_due(const tf_rowwriter *rw, int dirty, double last_sync)
{
    double due = 1e300;
    if (dirty)
        due = last_sync + rw->fsync_ms;
    if (rw->preview_dirty && rw->preview && rw->preview_last + rw->preview_ms < due)
        due = rw->preview_last + rw->preview_ms;
    if (rw->count > 0 && rw->queued_ms + rw->fsync_ms / 2 < due)
        due = rw->queued_ms + rw->fsync_ms / 2;
    return due;
}

/* Sleep (rw->mu held) until a batch is queued, the render stops, or something falls due. */
static void wait_for_work(tf_rowwriter *rw, int dirty, double last_sync)
{
    while (rw->count < rw->batch && !rw->stop) {
        double now = tf_now_msf(), due = next_due(rw, dirty, last_sync);
        if (due == 1e300) {
            rw->untimed = 1;
            pthread_cond_wait(&rw->nonempty, &rw->mu);
            rw->untimed = 0;
            continue;
        }
        if (due - now <= 0)
            return;
        struct timespec ts = tf_realtime_in(due - now);
        pthread_cond_timedwait(&rw->nonempty, &rw->mu, &ts);
    }
}

/* Flush the sink, then free the results it referenced.  0, or -1 with err set. */
static int flush_held(tf_rowwriter *rw, char *err, size_t errlen)
{
    int rc = tf_exr_flush(rw->w, err, errlen);
    for (int i = 0; i < rw->nheld; i++)
        tf_tuple_clear(&rw->held[i]);
    rw->nheld = 0;
    return rc;
}

/* A result just written: kept while the sink references its chunks, else freed.  The write
 * goes out once nothing is queued behind it (or after a failure, or with HELD_MAX kept), so
 * that a farm of small tasks does not pay a system call per task; the file grows by whole
 * results either way.  Returns rc, or the flush's failure. */
static int written(tf_rowwriter *rw, tf_tuple *item, int rc, int more, char *err, size_t errlen)
{
    if (tf_exr_holds_references(rw->w))
        tf_tuple_move(&rw->held[rw->nheld++], item);
    else
        tf_tuple_clear(item);
    if (rc == 0 && more && rw->nheld < HELD_MAX)
        return 0;
    char ferr[512];
    if (flush_held(rw, ferr, sizeof ferr) && rc == 0) {
        snprintf(err, errlen, "%s", ferr);
        return -1;
    }
    return rc;
}

/* Under rw->mu: the oldest queued result moved into item, out of the ring (R2 holds for what
 * stays queued).  1 if there was one to write (none after a failure). */
static int take_next(tf_rowwriter *rw, tf_tuple *item)
{
    tf_tuple_init(item);
    if (rw->count == 0 || rw->failed)
        return 0;
    tf_tuple_move(item, &rw->slot[rw->head]);
    rw->head = (rw->head + 1) % rw->depth;
    if (rw->count-- == rw->depth) /* the producer waits only on a full queue */
        pthread_cond_signal(&rw->nonfull);
    return 1;
}

/* Under rw->mu, after a failure: drop the queue, as nothing more may be written past the gap. */
static void drop_queue(tf_rowwriter *rw)
{
    while (rw->count > 0) {
        tf_tuple_clear(&rw->slot[rw->head]);
        rw->head = (rw->head + 1) % rw->depth;
        rw->count--;
    }
    pthread_cond_signal(&rw->nonfull);
}

/* Outside the lock: write item (if have), sync the file once fsync_ms have passed since the
 * last sync of something written (*dirty), and refresh the preview when it is due.  0, or -1
 * with the failure in err. */
static int write_and_sync(tf_rowwriter *rw, tf_tuple *item, int have, int more, int *dirty,
                          double *last_sync, char *err, size_t errlen)
{
    int rc = 0;
    if (have) {
        rc = write_result(rw, item, err, errlen);
        rc = written(rw, item, rc, more, err, errlen);
        *dirty = 1;
    }
    double now = tf_now_msf();
    if (rc == 0 && *dirty && now - *last_sync >= rw->fsync_ms) { /* held results stay alive */
        rc = tf_exr_sync(rw->w, err, errlen);
        *last_sync = tf_now_msf();
        *dirty = 0;
    }
    if (rw->preview_dirty && rw->preview && now - rw->preview_last >= rw->preview_ms)
        write_preview(rw, 0);
    return rc;
}

/* The writer thread: each queued result written in order, until stopped (rowwriter.h). */
static void *writer_main(void *arg)
{
    tf_rowwriter *rw = arg;
    double last_sync = tf_now_msf();
    int dirty = 0, more = 0;
    char err[512];
    pthread_mutex_lock(&rw->mu);
    for (;;) {
        if (!more) /* once awake, the thread drains the queue before it sleeps again */
            wait_for_work(rw, dirty, last_sync);
        assert(assert_queue(rw));
        if (rw->count == 0 && rw->stop)
            break;
        tf_tuple item;
        int have = take_next(rw, &item);
        more = rw->count > 0; /* queued behind this one: their chunks join its write */
        pthread_mutex_unlock(&rw->mu);

        int rc = write_and_sync(rw, &item, have, more, &dirty, &last_sync, err, sizeof err);
        int rows = tf_exr_next_row(rw->w);

        pthread_mutex_lock(&rw->mu);
        if (rc != 0 && !rw->failed) {
            rw->failed = 1;
            snprintf(rw->error, sizeof rw->error, "%s", err);
        }
        if (rows > rw->rows_written)
            rw->rows_written = rows;
        if (!have && rw->failed && rw->count > 0)
            drop_queue(rw);
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
            tf_tuple_clear(&rw->slot[i]);
    for (int i = 0; i < rw->nheld; i++)
        tf_tuple_clear(&rw->held[i]);
    free(rw->slot);
    free(rw->preview);
    free(rw->preview_path);
    free(rw);
}

tf_rowwriter *tf_rowwriter_start(tf_exr_writer *w, const tf_exr_layout *layout,
                                 const tf_rowwriter_config *cfg, char *err, size_t errlen)
{
    tf_rowwriter *rw = calloc(1, sizeof *rw);
    if (!rw)
        goto oom;
    rw->w = w;
    rw->layout = *layout;
    rw->depth = cfg->depth < 1 ? 1 : cfg->depth;
    rw->batch = cfg->batch < 1 ? 1 : cfg->batch > rw->depth ? rw->depth : cfg->batch;
    rw->fsync_ms = cfg->fsync_interval_ms > 0 ? cfg->fsync_interval_ms : 1000;
    rw->preview_ms = cfg->preview_interval_ms > 0 ? cfg->preview_interval_ms : 5000;
    rw->rows_written = tf_exr_next_row(w);
    tf_exr_hold_chunks(w, 1); /* write_result flushes before it frees a result */
    rw->slot = calloc((size_t)rw->depth, sizeof *rw->slot);
    if (!rw->slot)
        goto oom;
    if (cfg->preview_png)
        start_preview(rw, cfg->preview_png, cfg->existing);
    rw->preview_last = tf_now_msf() - rw->preview_ms + 500; /* a first picture soon */
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

int tf_rowwriter_put(tf_rowwriter *rw, tf_tuple *result)
{
    pthread_mutex_lock(&rw->mu);
    while (rw->count == rw->depth && !rw->failed)
        pthread_cond_wait(&rw->nonfull, &rw->mu);
    if (rw->failed) {
        pthread_mutex_unlock(&rw->mu);
        tf_tuple_clear(result);
        return -1;
    }
    int idx = (rw->head + rw->count) % rw->depth;
    tf_tuple_move(&rw->slot[idx], result);
    if (rw->count++ == 0)
        rw->queued_ms = tf_now_msf();
    /* The thread sleeps until a batch is queued or its timer runs out (next_due): one wake-up
     * a batch, not one a result; a thread with no timer must hear of the first one. */
    if (rw->count == rw->batch || (rw->untimed && rw->count == 1))
        pthread_cond_signal(&rw->nonempty);
    assert(assert_queue(rw));
    pthread_mutex_unlock(&rw->mu);
    return 0;
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
    } else {
        write_preview(rw, 1);
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
    if (rw->preview_dirty && !rw->failed)
        write_preview(rw, 0);
    free_rowwriter(rw);
}
